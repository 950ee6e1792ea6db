//! Probe: stop I of a route (ROUTE, SEED) against stop I-1, window ±W (heading ±H) centred at
//! the truth offset moved by (DX, DY); grid and refined error, refinement, σ, doubts.
use sdem::localize::LocalizeOptions;
use sdem::sdem::SdemConfig;
use sdem::search::{HeadingWindow, SearchWindow};
use sdem_sim::benchmark::{localize_pair, BenchPair};
use sdem_sim::routes::{route, RouteConfig, RouteKind};

fn env<T: std::str::FromStr>(k: &str, d: T) -> T {
    std::env::var(k)
        .ok()
        .and_then(|s| s.parse().ok())
        .unwrap_or(d)
}

fn main() {
    let kind: RouteKind = std::env::var("ROUTE")
        .unwrap_or("long-steps".into())
        .parse()
        .unwrap();
    let seed: u64 = env("SEED", 1);
    let i: usize = env("I", 2);
    let w: f64 = env("W", 0.32);
    let h: f64 = env("H", 3.0);
    let iters: usize = env("IT", 30);
    let drawn = route(kind, seed, &RouteConfig::default()).unwrap();
    let run = &drawn.run;
    let (a, b) = (&run.stops[i - 1], &run.stops[i]);
    let truth = a.world_from_sensor.inverse() * b.world_from_sensor;
    let off = b.world_from_sensor.translation.vector - a.world_from_sensor.translation.vector;
    let pair = BenchPair {
        reference_points: a.sweep.points_in_sensor(),
        reference_attitude: a.sweep.mean_attitude(),
        query_points: b.sweep.points_in_sensor(),
        query_attitude: b.sweep.mean_attitude(),
        truth,
        compass_error_deg: 0.0,
        world_from_reference: a.world_from_sensor,
        world_from_query: b.world_from_sensor,
        reference_stop: 0,
    };
    for dx in [-0.1, -0.05, 0.0, 0.05, 0.1] {
        let c = off + sdem::geometry::Vec3::new(dx + env("DX", 0.0), env("DY", 0.0), 0.0);
        let mut o = LocalizeOptions {
            window: SearchWindow::around(&c, [w, w, 0.3]),
            ..Default::default()
        };
        o.refinement.max_iterations = iters;
        o.heading = HeadingWindow {
            half_range_deg: h,
            step_deg: None,
        };
        let r = localize_pair(&pair, &SdemConfig::default(), &o).unwrap();
        let l = &r.localization;
        let g = l.grid_offset - off;
        let rf = l.refinement.as_ref();
        println!(
            "centre dx {dx:+.2}: grid err ({:+.3},{:+.3},{:+.3}) refined err {:.2} cm {:.2} deg it {:?} conv {:?} cost {:.3e} inl {:.0}% sigma {:?} flat {:?} doubts {:?}",
            g.x, g.y, g.z,
            r.translation_error_m * 100.0, r.rotation_error_deg,
            rf.map(|r| r.iterations), rf.map(|r| r.converged),
            l.cost, l.diagnostics.inlier_fraction * 100.0,
            l.diagnostics.weakest_sigma_m.map(|s| (s * 1000.0).round() / 10.0),
            l.diagnostics.flat_direction,
            l.doubts.iter().map(|d| d.kind()).collect::<Vec<_>>()
        );
    }
}
