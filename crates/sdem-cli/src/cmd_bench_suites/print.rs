//! `sdem bench --suite`'s text: per part, a row per scene (or kind of pair) and one for all,
//! the wrong poses reported as trusted, the errors, and the peers beside sdem.

use super::{PairRecord, PartReport, PeersReport, Report};
use crate::bench_peers;

/// Prints the report as text.
pub(super) fn print_report(report: &Report) {
    println!(
        "sdem bench --suite {} ({} threads, seed {}{})",
        report.suite,
        report.threads,
        report.seed,
        if report.quick { ", quick" } else { "" }
    );
    for part in &report.parts {
        println!();
        print_part(part);
    }
    println!();
    println!(
        "WRONG POSES REPORTED AS TRUSTED, all parts with a reliable truth: {} (target 0)",
        report.wrong_trusted
    );
}

fn print_part(part: &PartReport) {
    println!("{}:", part.part);
    if !part.available {
        println!(
            "  not run: {}",
            part.reason.as_deref().unwrap_or("unavailable")
        );
        return;
    }
    println!("  {}", part.what);
    if let Some(w) = &part.window {
        println!(
            "  search: window x {:.2}..{:.2}, y {:.2}..{:.2}, z {:.2}..{:.2} m at {} cm, heading as \
             sdem::localize sets it from the readings; success: ≤ {} cm and ≤ {}°",
            w.min[0],
            w.max[0],
            w.min[1],
            w.max[1],
            w.min[2],
            w.max[2],
            part.step_m * 100.0,
            part.success_translation_m * 100.0,
            part.success_rotation_deg
        );
    }
    println!(
        "  {:<16} {:>5} {:>8} {:>7} {:>7} {:>13} {:>9} {:>9} {:>8} {:>8} {:>7} {:>7}",
        "",
        "pairs",
        "success",
        "trusted",
        "flagged",
        "WRONG+TRUSTED",
        "median mm",
        "p95 mm",
        "median °",
        "p95 °",
        "med ms",
        "p95 ms"
    );
    let rows = part.by_group.iter().chain(part.all.iter());
    for t in rows {
        println!(
            "  {:<16} {:>5} {:>7.1}% {:>7} {:>7} {:>13} {:>9} {:>9} {:>8} {:>8} {:>7.0} {:>7.0}",
            t.group,
            t.pairs,
            t.success_rate * 100.0,
            t.trusted,
            t.flagged,
            t.wrong_trusted,
            figure(t.translation_error_mm.median, 2),
            figure(t.translation_error_mm.p95, 1),
            figure(t.rotation_error_deg.median, 3),
            figure(t.rotation_error_deg.p95, 2),
            t.time_ms.median,
            t.time_ms.p95
        );
    }
    if let Some(all) = &part.all {
        if !part.truth_reliable {
            println!(
                "  this part's truth is doubted by its own README (up to ~0.18 m a frame off at \
                 the start): its errors and WRONG+TRUSTED measure the truth as much as sdem; the \
                 peers' agreement with sdem is the check, and the total leaves it out"
            );
        }
        println!(
            "  wrong poses reported as trusted: {} of {} (target 0); wrong and flagged: {}; right \
             but flagged: {}; errors (no pose): {}; wrong poses the scans favour over the truth \
             (eq. 1 lower there, or the truth not comparable): {}",
            all.wrong_trusted,
            all.pairs,
            all.wrong_flagged,
            all.correct_flagged,
            all.errors,
            all.wrong_favoured_by_scans
        );
        if !all.doubt_kinds.is_empty() {
            let kinds: Vec<String> = all
                .doubt_kinds
                .iter()
                .map(|(k, n)| format!("{k} {n}"))
                .collect();
            println!("  doubts raised: {}", kinds.join(", "));
        }
    }
    for r in part.records.iter().filter(|r| r.trusted && !r.correct) {
        println!(
            "  WRONG+TRUSTED pair {} ({}): {} cm, {}°",
            r.index,
            r.group,
            figure(r.translation_error_m.unwrap_or(f64::NAN) * 100.0, 1),
            figure(r.rotation_error_deg.unwrap_or(f64::NAN), 2)
        );
    }
    if part.list_pairs {
        print_pairs(part);
    }
    let errors: Vec<&PairRecord> = part.records.iter().filter(|r| r.error.is_some()).collect();
    for r in errors.iter().take(5) {
        println!(
            "  error, pair {} ({}): {}",
            r.index,
            r.group,
            r.error.as_deref().unwrap_or("")
        );
    }
    if errors.len() > 5 {
        println!("  ... {} more errors (see --json)", errors.len() - 5);
    }
    if let Some(peers) = &part.peers {
        print_peers(peers);
    }
}

/// One line per pair: sdem's errors and verdict, and the peers' errors on it.
fn print_pairs(part: &PartReport) {
    let peers = part.peers.as_ref().map_or(&[][..], |p| &p.per_pair[..]);
    for (i, r) in part.records.iter().enumerate() {
        let sdem = match (&r.error, r.translation_error_m, r.rotation_error_deg) {
            (Some(_), _, _) => "error".to_string(),
            (None, Some(t), Some(d)) => format!(
                "{:6.1} cm {:5.2}° {}",
                t * 100.0,
                d,
                if r.trusted { "trusted" } else { "flagged" }
            ),
            _ => "-".to_string(),
        };
        let mut line = format!("  {:<14} sdem {sdem:<24} {:6.0} ms", r.label, r.time_ms);
        for p in peers.get(i).into_iter().flatten() {
            let name = bench_peers::short_label(&p.method);
            match (p.translation_error_m, p.rotation_error_deg) {
                (Some(t), Some(d)) => {
                    line.push_str(&format!("  | {name} {:.1} cm {:.2}°", t * 100.0, d))
                }
                _ => line.push_str(&format!("  | {name} failed")),
            }
        }
        println!("{line}");
    }
}

fn print_peers(peers: &PeersReport) {
    if !peers.available {
        println!(
            "  peers: not run ({})",
            peers.reason.as_deref().unwrap_or("absent")
        );
        return;
    }
    println!(
        "  peers on {}, same clouds (reference = target, query = source), median of {} runs each:",
        peers.subset,
        peers.settings.map_or(1, |s| s.repeat)
    );
    println!(
        "    {:<32} {:>5} {:>8} {:>9} {:>8} {:>10} {:>10}",
        "method", "pairs", "success", "median ms", "p95 ms", "sdem/peer", "as sdem"
    );
    if let (Some(rate), Some(time)) = (peers.sdem_success_rate, peers.sdem_time_ms) {
        println!(
            "    {:<32} {:>5} {:>7.1}% {:>9.0} {:>8.0}",
            "sdem (the same pairs)",
            peers.pairs,
            rate * 100.0,
            time.median,
            time.p95
        );
    }
    for m in &peers.methods {
        let ratio = m
            .sdem_time_ratio
            .map_or("-".to_string(), |r| format!("{r:.2}x"));
        println!(
            "    {:<32} {:>5} {:>7.1}% {:>9} {:>8} {:>10} {:>10}",
            m.label,
            m.pairs,
            m.success_rate * 100.0,
            figure(m.time_ms.median, 0),
            figure(m.time_ms.p95, 0),
            ratio,
            format!("{}/{}", m.agrees_with_sdem, m.pairs)
        );
        if m.ran < m.pairs {
            println!(
                "      failed to run on {} pair(s): {}",
                m.pairs - m.ran,
                m.first_error.as_deref().unwrap_or("")
            );
        }
    }
    match (
        &peers.fastest_global,
        peers.sdem_time_ratio_to_fastest_global,
    ) {
        (Some(name), Some(ratio)) => println!(
            "    sdem's median time is {ratio:.2}x that of the fastest global peer ({name})"
        ),
        _ => println!("    no global peer ran on every pair"),
    }
    println!(
        "    (\"as sdem\": pairs where the method's pose lies within the success thresholds of \
         sdem's)"
    );
}

/// A figure with `decimals`; `inf` where a pair without a pose (an error) reaches it, `-` for
/// none.
pub(super) fn figure(value: f64, decimals: usize) -> String {
    if value.is_finite() {
        format!("{value:.decimals$}")
    } else if value == f64::INFINITY {
        "inf".to_string()
    } else {
        "-".to_string()
    }
}
