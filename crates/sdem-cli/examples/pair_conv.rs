//! Probe: the 50 bench pairs (seed 1), timed; prints the median over ROUNDS rounds.
use sdem::sdem::SdemConfig;
use sdem_sim::benchmark::{bench_pairs, localize_config, localize_pair, PairConfig};

fn main() {
    let rounds: usize = std::env::var("ROUNDS")
        .ok()
        .and_then(|s| s.parse().ok())
        .unwrap_or(3);
    let count: usize = std::env::var("PAIRS")
        .ok()
        .and_then(|s| s.parse().ok())
        .unwrap_or(50);
    let config = PairConfig::default();
    let pairs = bench_pairs(1, count, &config).unwrap();
    let mut options = localize_config(&config);
    if let Some(n) = std::env::var("IT").ok().and_then(|s| s.parse().ok()) {
        options.refinement.max_iterations = n;
    }
    let grid = SdemConfig::default();
    let mut times = Vec::new();
    let mut errs = Vec::new();
    let mut cands = 0usize;
    for round in 0..rounds {
        for pair in &pairs {
            let r = localize_pair(pair, &grid, &options).unwrap();
            times.push(r.time_ms);
            if round == 0 {
                errs.push(r.translation_error_m * 1e3);
                cands += r.localization.candidates_evaluated;
                if let Some(f) = r.localization.refinement.as_ref() {
                    if std::env::var("CONV").is_ok() {
                        println!(
                            "pair it {} conv {} err {:.3} mm",
                            f.iterations,
                            f.converged,
                            r.translation_error_m * 1e3
                        );
                    }
                }
            }
        }
    }
    times.sort_by(f64::total_cmp);
    errs.sort_by(f64::total_cmp);
    let sum: f64 = errs.iter().sum();
    println!(
        "median {:.2} ms  candidates {}  err median {:.4} max {:.4} sum {:.6} mm",
        times[times.len() / 2],
        cands,
        errs[errs.len() / 2],
        errs[errs.len() - 1],
        sum
    );
}
