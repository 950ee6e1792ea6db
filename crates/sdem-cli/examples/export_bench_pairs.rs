//! Writes the benchmark's seeded scan pairs to a folder, for the peers' registration scripts
//! (`../shared/peers/register_pair.py`, run by `scripts/peers.sh`).
//!
//! ```sh
//! cargo run --release -p sdem-cli --example export_bench_pairs -- --out /tmp/pairs --count 50 --seed 1
//! ```
//!
//! Writes, for each pair `i`:
//! ```text
//! OUT/pair_000/reference.ply   the reference scan, points in its sensor frame (the target)
//! OUT/pair_000/query.ply       the query scan, points in its sensor frame (the source)
//! OUT/pair_000/truth.txt       true reference_from_query = T_target_source, 4x4, row-major
//! OUT/pair_000/guess.txt       the truth moved 0.2 m and turned 5° (a seeded odometry guess), 4x4
//! OUT/pairs.jsonl              one line per pair: truth, guess, compass error, point counts
//! OUT/sdem.jsonl               with --localize: sdem's estimate, error and time per pair
//! ```
//! The clouds are the raw scans in their own sensor frames, not levelled by the attitude
//! readings, so the truth is the full relative pose (roll, pitch and yaw included).

use rand::SeedableRng;
use rand_chacha::ChaCha8Rng;
use sdem::geometry::{Pose, PoseRecord};
use sdem::sdem::SdemConfig;
use sdem_sim::benchmark::{
    bench_pairs, localize_config, localize_pair, perturbed, success_rate, summarize, PairConfig,
};
use std::path::{Path, PathBuf};
use std::time::Instant;

const USAGE: &str = "usage: export_bench_pairs --out DIR [--count N (50)] [--seed N (1)] \
[--compass-error-max-deg D (10)] [--guess-m M (0.2)] [--guess-deg D (5)] [--localize]";

/// Mixed into the seed of the guesses' random stream.
const GUESS_SALT: u64 = 0x6e55_0000_0000_0001;

struct Args {
    out: PathBuf,
    count: usize,
    seed: u64,
    compass_error_max_deg: f64,
    guess_m: f64,
    guess_deg: f64,
    localize: bool,
}

fn parse_args() -> Result<Args, String> {
    let mut args = Args {
        out: PathBuf::new(),
        count: 50,
        seed: 1,
        compass_error_max_deg: 10.0,
        guess_m: 0.2,
        guess_deg: 5.0,
        localize: false,
    };
    let mut out = None;
    let mut it = std::env::args().skip(1);
    while let Some(flag) = it.next() {
        if flag == "--localize" {
            args.localize = true;
            continue;
        }
        if flag == "-h" || flag == "--help" {
            return Err(USAGE.into());
        }
        let value = it
            .next()
            .ok_or_else(|| format!("{flag} needs a value\n{USAGE}"))?;
        let bad = |e: &dyn std::fmt::Display| format!("{flag} {value}: {e}\n{USAGE}");
        match flag.as_str() {
            "--out" => out = Some(PathBuf::from(&value)),
            "--count" => args.count = value.parse().map_err(|e| bad(&e))?,
            "--seed" => args.seed = value.parse().map_err(|e| bad(&e))?,
            "--compass-error-max-deg" => {
                args.compass_error_max_deg = value.parse().map_err(|e| bad(&e))?
            }
            "--guess-m" => args.guess_m = value.parse().map_err(|e| bad(&e))?,
            "--guess-deg" => args.guess_deg = value.parse().map_err(|e| bad(&e))?,
            _ => return Err(format!("unknown flag {flag}\n{USAGE}")),
        }
    }
    args.out = out.ok_or_else(|| format!("--out is required\n{USAGE}"))?;
    Ok(args)
}

/// A 4x4 row-major matrix, one row a line, shortest round-trip decimals.
fn matrix_text(pose: &Pose) -> String {
    let m = pose.to_homogeneous();
    let mut text = String::new();
    for r in 0..4 {
        let row: Vec<String> = (0..4).map(|c| format!("{}", m[(r, c)])).collect();
        text.push_str(&row.join(" "));
        text.push('\n');
    }
    text
}

fn write_text(path: &Path, text: &str) -> sdem_io::Result<()> {
    sdem_io::write_atomic(path, |w| w.write_all(text.as_bytes()))
}

fn run(args: &Args) -> Result<(), Box<dyn std::error::Error>> {
    let config = PairConfig {
        compass_error_max_deg: args.compass_error_max_deg,
        ..Default::default()
    };
    let start = Instant::now();
    let pairs = bench_pairs(args.seed, args.count, &config)?;
    eprintln!(
        "{} pairs simulated (seed {}) in {:.1} s",
        pairs.len(),
        args.seed,
        start.elapsed().as_secs_f64()
    );
    std::fs::create_dir_all(&args.out).map_err(|e| sdem_io::Error::io(&args.out, e))?;
    let mut guess_rng = ChaCha8Rng::seed_from_u64(args.seed ^ GUESS_SALT);
    let mut index_lines = String::new();
    for (i, pair) in pairs.iter().enumerate() {
        let dir = args.out.join(format!("pair_{i:03}"));
        std::fs::create_dir_all(&dir).map_err(|e| sdem_io::Error::io(&dir, e))?;
        sdem_io::write_points_ply(&dir.join("reference.ply"), &pair.reference_points)?;
        sdem_io::write_points_ply(&dir.join("query.ply"), &pair.query_points)?;
        write_text(&dir.join("truth.txt"), &matrix_text(&pair.truth))?;
        let guess = perturbed(&pair.truth, args.guess_m, args.guess_deg, &mut guess_rng);
        write_text(&dir.join("guess.txt"), &matrix_text(&guess))?;
        let line = serde_json::json!({
            "pair": i,
            "seed": args.seed,
            "reference_stop": pair.reference_stop,
            "truth": PoseRecord::from(&pair.truth),
            "guess": PoseRecord::from(&guess),
            "compass_error_deg": pair.compass_error_deg,
            "reference_points": pair.reference_points.len(),
            "query_points": pair.query_points.len(),
        });
        index_lines.push_str(&line.to_string());
        index_lines.push('\n');
    }
    write_text(&args.out.join("pairs.jsonl"), &index_lines)?;
    eprintln!(
        "wrote {} pairs to {} ({:.1} s in all)",
        pairs.len(),
        args.out.display(),
        start.elapsed().as_secs_f64()
    );
    if args.localize {
        localize_all(args, &config, &pairs)?;
    }
    Ok(())
}

/// Runs sdem on every pair (the default search over the pairs' window) and writes sdem.jsonl.
fn localize_all(
    args: &Args,
    config: &PairConfig,
    pairs: &[sdem_sim::benchmark::BenchPair],
) -> Result<(), Box<dyn std::error::Error>> {
    let localize = localize_config(config);
    let sdem_config = SdemConfig::default();
    let mut lines = String::new();
    let (mut translation, mut rotation, mut times) = (Vec::new(), Vec::new(), Vec::new());
    for (i, pair) in pairs.iter().enumerate() {
        let line = match localize_pair(pair, &sdem_config, &localize) {
            Ok(r) => {
                translation.push(r.translation_error_m);
                rotation.push(r.rotation_error_deg);
                times.push(r.time_ms);
                serde_json::json!({
                    "pair": i,
                    "method": "sdem",
                    "time_ms": r.time_ms,
                    "trans_err_m": r.translation_error_m,
                    "rot_err_deg": r.rotation_error_deg,
                    "compass_error_deg": pair.compass_error_deg,
                    "estimate": PoseRecord::from(&r.estimate),
                    "candidates": r.localization.candidates_evaluated,
                    "on_window_edge": r.localization.on_window_edge,
                })
            }
            Err(e) => {
                translation.push(f64::NAN);
                rotation.push(f64::NAN);
                serde_json::json!({
                    "pair": i, "method": "sdem", "error": e.to_string(),
                    "compass_error_deg": pair.compass_error_deg,
                })
            }
        };
        lines.push_str(&line.to_string());
        lines.push('\n');
    }
    write_text(&args.out.join("sdem.jsonl"), &lines)?;
    let (t, r, ms) = (
        summarize(&translation),
        summarize(&rotation),
        summarize(&times),
    );
    eprintln!(
        "sdem: median {:.0} ms; translation median {:.2} cm, p95 {:.2} cm; rotation median {:.3}°, \
         p95 {:.3}°; success (< 2 cm) {:.0} %",
        ms.median,
        100.0 * t.median,
        100.0 * t.p95,
        r.median,
        r.p95,
        100.0 * success_rate(&translation, 0.02)
    );
    Ok(())
}

fn main() {
    let args = match parse_args() {
        Ok(a) => a,
        Err(message) => {
            eprintln!("export_bench_pairs: {message}");
            std::process::exit(2);
        }
    };
    if let Err(e) = run(&args) {
        eprintln!("export_bench_pairs: error: {e}");
        std::process::exit(1);
    }
}
