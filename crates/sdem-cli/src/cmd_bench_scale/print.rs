//! The scale suite's text.

use super::{Report, RouteReport, SizeReport};

pub(super) fn print_report(report: &Report) {
    println!(
        "sdem bench --suite scale ({} threads, seed {}): sdem slam's loop on long simulated \
         routes, odometry, compass σ {}°",
        report.threads, report.seed, report.compass_sigma_deg
    );
    if let Some(flat) = &report.flat {
        println!();
        println!("Laps of a room ({} laps):", flat.laps);
        let fourth = match (flat.fourth_lap_median_ms, flat.fourth_over_first) {
            (Some(m), Some(r)) => format!(", fourth lap {m:.0} ms ({r:.2}x the first)"),
            _ => String::new(),
        };
        println!(
            "   median time per stop: first lap {:.0} ms{fourth}, last lap {:.0} ms ({:.2}x)",
            flat.first_lap_median_ms, flat.last_lap_median_ms, flat.last_over_first
        );
        if let Some(last) = flat.last_over_first_cpu {
            let fourth = (flat.fourth_over_first_cpu)
                .map_or(String::new(), |f| format!("fourth lap {f:.2}x the first, "));
            println!("   CPU time per stop: {fourth}last lap {last:.2}x the first");
        }
    }
    for route in &report.routes {
        print_route(route);
    }
    if let Some(plot) = &report.plot {
        println!();
        println!("time per stop against stop number: {}", plot.display());
    }
}

fn print_route(route: &RouteReport) {
    println!();
    println!(
        "{}: {} stops in {} laps; loop closures {} accepted, {} rejected; {} doubtful, {} failed",
        route.route,
        route.stops,
        route.laps,
        route.loop_closures_accepted,
        route.loop_closures_rejected,
        route.doubtful_stops,
        route.failed_stops.len()
    );
    println!(
        "   {:>6}  {:>17}  {:>9}  {:>9}  {:>17}  {:>17}  {:>9}  {:>13}  {:>12}",
        "nodes",
        "per stop med/p95",
        "CPU med",
        "localize",
        "closure med/p95",
        "solve med/max",
        "peak mem",
        "disk (save)",
        "ATE rms/max"
    );
    for s in &route.sizes {
        print_size(s);
    }
    println!(
        "   settled after the last stop (every node fused into the voxel map, as before a save): \
         {:.1} s, {} voxels; peak memory with it {}",
        route.settle_ms / 1e3,
        route.fused_voxels,
        route
            .peak_memory_settled_mib
            .map_or("-".to_string(), |m| format!("{m:.0} MiB"))
    );
}

fn print_size(s: &SizeReport) {
    let pair = |a: f64, b: f64| {
        if a.is_finite() {
            format!("{a:.0} / {b:.0} ms")
        } else {
            "-".to_string()
        }
    };
    println!(
        "   {:>6}  {:>17}  {:>9}  {:>6.0} ms  {:>17}  {:>17}  {:>9}  {:>13}  {:>12}",
        s.nodes,
        pair(s.time_per_stop_ms.median, s.time_per_stop_ms.p95),
        s.cpu_per_stop_ms
            .as_ref()
            .map_or("-".to_string(), |c| format!("{:.0} ms", c.median)),
        s.localize_ms.median,
        pair(s.loop_closure_ms.median, s.loop_closure_ms.p95),
        pair(s.solve_ms.median, s.solve_ms.max),
        s.peak_memory_mib
            .map_or("-".to_string(), |m| format!("{m:.0} MiB")),
        format!("{:.0} MiB ({:.0} ms)", s.map_on_disk_mib, s.save_ms),
        format!("{:.2}/{:.2} cm", s.ate_rmse_m * 100.0, s.ate_max_m * 100.0)
    );
}
