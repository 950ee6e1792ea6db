//! `sdem bench`: speed and accuracy figures from one run on fixed seeded scenes.
//!
//! 1. Exact search against the oracle: the paper's experiment (its room, the scan after moving
//!    (22, 36, 5) cm), the paper's window at 1 cm with the compass trusted, searched once
//!    exhaustively and several times by branch-and-bound; times, ratio, and whether both return
//!    the same grid candidate with the same cost.
//! 2. Accuracy and time over seeded pairs in the simulated collapsed building
//!    ([`sdem_sim::benchmark::bench_pairs`]): the query anywhere within ±0.5 m (±0.1 m in height) of
//!    the reference, turned up to ±15°, tilted up to ±3°, its compass off by up to ±10°; 5 mm
//!    range noise. Each is localized with the ±10° heading search, refinement and diagnostics,
//!    and again with the compass ignored (a full turn of heading searched).
//! 3. The pose graph's optimization on a 1,000-node synthetic loop.

use crate::bench_tally::Tally;
use crate::output::{elapsed_ms, print_json};
use crate::parse::{positive_count, positive_metres};
use anyhow::{Context, Result};
use sdem::geometry::Vec3;
use sdem::localize::{localize, HeadingWindow, LocalizeOptions, SearchMode, SearchWindow};
use sdem::sdem::SdemConfig;
use sdem_sim::benchmark::{
    bench_pairs, localize_config, localize_pair, paper_pair, share_below, summarize, BenchPair,
    PairConfig, Stats, CHI2_95_6, PAPER_MOVE_M,
};
use serde::Serialize;
use std::time::Instant;

/// Arguments of `sdem bench`.
#[derive(clap::Args)]
pub struct Args {
    /// A short run: a smaller window for the oracle comparison and 10 pairs.
    #[arg(long)]
    quick: bool,
    /// Number of seeded pairs for the accuracy figures [default: 50, or 10 with --quick].
    #[arg(long, allow_hyphen_values = true, value_parser = positive_count)]
    pairs: Option<usize>,
    /// Seed of the pairs' scene.
    #[arg(long, default_value_t = 1)]
    seed: u64,
    /// Grid step of the pairs' search, metres (the refinement goes below it) [default: 0.02].
    #[arg(long, allow_hyphen_values = true, value_parser = positive_metres)]
    step: Option<f64>,
    /// Print one JSON object instead of text.
    #[arg(long)]
    json: bool,
    /// Measure localization under the faults of a disaster site instead (compass, gyro drift,
    /// dust, missing returns, tilt, moved rubble, a walking person, and all together): success
    /// rate and errors per fault on seeded pairs [pairs per fault: default 100, 10 with --quick].
    #[arg(long)]
    faults: bool,
    /// With --faults: only these cases (none, all, or a fault's name; repeat the flag).
    #[arg(long = "case", value_name = "CASE", requires = "faults", value_parser = crate::cmd_bench_faults::case_parser())]
    cases: Vec<crate::cmd_bench_faults::Case>,
    /// `--suite` and its flags.
    #[command(flatten)]
    suites: crate::cmd_bench_suites::SuiteArgs,
}

impl Args {
    /// `--step`, or its default.
    fn step(&self) -> f64 {
        self.step.unwrap_or(sdem_sim::benchmark::PAIRS_STEP_M)
    }

    fn fault_args(&self) -> crate::cmd_bench_faults::FaultArgs {
        crate::cmd_bench_faults::FaultArgs {
            pairs: self.pairs.unwrap_or(if self.quick { 10 } else { 100 }),
            seed: self.seed,
            step: self.step(),
            json: self.json,
            cases: self.cases.clone(),
        }
    }
}

#[derive(Serialize)]
struct ExactReport {
    scene: &'static str,
    window: SearchWindow,
    step_m: f64,
    heading_window_deg: f64,
    candidates: usize,
    exhaustive_ms: f64,
    branch_and_bound_ms: Stats,
    ratio: f64,
    identical: bool,
    exhaustive_cost: f64,
    branch_and_bound_cost: f64,
    candidates_scored: usize,
    boxes_bounded: usize,
    search_points: usize,
}

#[derive(Serialize)]
struct PairsReport {
    count: usize,
    seed: u64,
    step_m: f64,
    heading_window_deg: f64,
    window: SearchWindow,
    translation_error_mm: Stats,
    rotation_error_deg: Stats,
    time_ms: Stats,
    success_rate_2cm: f64,
    /// Localizations without a doubt.
    trusted: usize,
    /// The normalized estimation error squared (six axes) of the reported covariance: a χ² with
    /// 6 degrees of freedom (median 5.3) when the covariance is honest.
    nees: Option<Stats>,
    /// The share of them below χ²₆'s 95 % bound, 12.59 (0.95 when honest).
    nees_below_95: Option<f64>,
    failures: Vec<String>,
}

#[derive(Serialize)]
struct Report {
    threads: usize,
    /// The paper's window, compass trusted.
    exact: ExactReport,
    /// The paper's window with the default heading search.
    exact_heading: ExactReport,
    pairs: PairsReport,
    /// The same pairs with the compass ignored: a full turn of heading searched.
    pairs_no_compass: PairsReport,
    pose_graph: PoseGraphReport,
}

/// The pose graph's optimization on a 1,000-node synthetic loop.
#[derive(Serialize)]
struct PoseGraphReport {
    nodes: usize,
    edges: usize,
    time_ms: f64,
    iterations: usize,
    ate_before_m: f64,
    ate_after_m: f64,
}

/// The exact search against the exhaustive oracle on the paper's pair at 1 cm: the paper's
/// window (a smaller one with `quick`), heading searched within `±heading_deg` of the compass.
fn exact_vs_exhaustive(quick: bool, heading_deg: f64, say: &dyn Fn(&str)) -> Result<ExactReport> {
    let (r, q) = paper_pair()?;
    let window = if quick {
        SearchWindow::around(&Vec3::from(PAPER_MOVE_M), [0.15, 0.15, 0.05])
    } else {
        SearchWindow::paper()
    };
    let heading = HeadingWindow {
        half_range_deg: heading_deg,
        step_deg: None,
    };
    let base = LocalizeOptions {
        window,
        step_m: 0.01,
        heading,
        refine: false,
        runner_up: false,
        ..Default::default()
    };
    // The oracle is what this bench measures: no limit on its candidates (12 million with
    // ±10° of heading, about a minute).
    let exhaustive_config = LocalizeOptions {
        mode: SearchMode::Exhaustive,
        max_exhaustive_candidates: usize::MAX,
        ..base.clone()
    };
    say(&format!(
        "exact search, heading ±{heading_deg}°: the exhaustive oracle over the window ..."
    ));
    let start = Instant::now();
    let oracle = localize(&r, &q, &exhaustive_config).context("exhaustive search")?;
    let exhaustive_ms = elapsed_ms(start);
    let repeats = if quick { 3 } else { 5 };
    let mut times = Vec::new();
    let mut fast = None;
    for i in 0..repeats {
        say(&format!(
            "exact search, heading ±{heading_deg}°: branch-and-bound, run {} of {repeats} ...",
            i + 1
        ));
        let start = Instant::now();
        let found = localize(&r, &q, &base).context("branch-and-bound search")?;
        times.push(elapsed_ms(start));
        fast = Some(found);
    }
    let fast = fast.expect("at least one run");
    let bnb = summarize(&times);
    Ok(ExactReport {
        scene: "paper room, scan after moving (22, 36, 5) cm",
        window,
        step_m: 0.01,
        heading_window_deg: heading_deg,
        candidates: oracle.candidates_total,
        exhaustive_ms,
        ratio: exhaustive_ms / bnb.median,
        branch_and_bound_ms: bnb,
        identical: fast.grid_index == oracle.grid_index && fast.cost == oracle.cost,
        exhaustive_cost: oracle.cost,
        branch_and_bound_cost: fast.cost,
        candidates_scored: fast.candidates_evaluated,
        boxes_bounded: fast.nodes_bounded,
        search_points: sdem::cost::search_points_of(&q, &base.cost).len(),
    })
}

/// The seeded pairs of `args`, simulated once for every heading window measured.
fn seeded_pairs(args: &Args, say: &dyn Fn(&str)) -> Result<Vec<BenchPair>> {
    let count = args.pairs.unwrap_or(if args.quick { 10 } else { 50 });
    say(&format!("pairs: simulating {count} seeded pairs ..."));
    Ok(bench_pairs(args.seed, count, &PairConfig::default())?)
}

/// `pairs` localized with the heading searched within `±heading_deg` of the compass.
fn accuracy(args: &Args, pairs: &[BenchPair], heading_deg: f64) -> PairsReport {
    let count = pairs.len();
    let mut config = LocalizeOptions {
        step_m: args.step(),
        ..localize_config(&PairConfig::default())
    };
    config.heading.half_range_deg = heading_deg;
    let sdem_config = SdemConfig::default();
    let (mut tally, mut failures) = (Tally::default(), Vec::new());
    let (mut trusted, mut nees) = (0, Vec::new());
    let bar = crate::progress::bar(
        count as u64,
        args.json,
        &format!("pairs localized, heading ±{heading_deg}°"),
    );
    for (i, pair) in pairs.iter().enumerate() {
        bar.inc(1);
        match localize_pair(pair, &sdem_config, &config) {
            Ok(result) => {
                trusted += usize::from(result.localization.trusted);
                nees.extend(result.localization.covariance.as_ref().and_then(|c| {
                    sdem_sim::benchmark::nees(&pair.truth, &result.estimate, c).map(|n| n.0)
                }));
                if tally.record(Some(&result)) {
                    failures.push(format!(
                        "pair {i}: error {:.1} mm, {:.2}°",
                        result.translation_error_m * 1e3,
                        result.rotation_error_deg
                    ));
                }
            }
            Err(e) => {
                tally.record(None);
                failures.push(format!("pair {i}: {e}"));
            }
        }
    }
    bar.finish_and_clear();
    PairsReport {
        count,
        seed: args.seed,
        step_m: args.step(),
        heading_window_deg: config.heading.half_range_deg,
        window: config.window,
        translation_error_mm: tally.translation_error_mm(),
        rotation_error_deg: tally.rotation_error_deg(),
        time_ms: tally.time_ms(),
        success_rate_2cm: tally.success_rate(),
        trusted,
        nees_below_95: share_below(&nees, CHI2_95_6),
        nees: (!nees.is_empty()).then(|| summarize(&nees)),
        failures,
    }
}

fn print_exact(e: &ExactReport) {
    let heading = if e.heading_window_deg > 0.0 {
        format!("heading ±{}°", e.heading_window_deg)
    } else {
        "compass trusted".to_string()
    };
    println!(
        "   window x {:.2}..{:.2}, y {:.2}..{:.2}, z {:.2}..{:.2} m at {} cm, {heading}: {} \
         candidates, {} query points compared",
        e.window.min[0],
        e.window.max[0],
        e.window.min[1],
        e.window.max[1],
        e.window.min[2],
        e.window.max[2],
        e.step_m * 100.0,
        e.candidates,
        e.search_points
    );
    println!("     exhaustive        {:>10.0} ms", e.exhaustive_ms);
    println!(
        "     branch-and-bound  {:>10.1} ms median of {} (scored {} candidates, bounded {} boxes)",
        e.branch_and_bound_ms.median,
        e.branch_and_bound_ms.count,
        e.candidates_scored,
        e.boxes_bounded
    );
    println!("     ratio             {:>10.0}x", e.ratio);
    println!(
        "     same minimum      {} (cost {:.6e} vs {:.6e})",
        if e.identical { "yes" } else { "NO" },
        e.branch_and_bound_cost,
        e.exhaustive_cost
    );
}

/// Runs `sdem bench`.
pub fn run(args: Args) -> Result<()> {
    let quiet = args.json;
    let say = move |m: &str| {
        if !quiet {
            eprintln!("  {m}");
        }
    };
    if args.faults {
        return crate::cmd_bench_faults::run(&args.fault_args(), &say);
    }
    if let Some(suite) = args.suites.suite {
        let (pairs, step) = (args.pairs.is_some(), args.step.is_some());
        crate::cmd_bench_suites::check_flags(&args.suites, suite, pairs, step)?;
        if suite == crate::cmd_bench_suites::Suite::Scale {
            crate::cmd_bench_scale::check_sizes(&args.suites.sizes)?;
            // Before the suite runs: a saved picture is never written over without --force.
            let (plot, force) = (args.suites.plot(), args.suites.force);
            crate::output::check_output_file(&plot, "--plot", force)?;
        }
        let common = crate::cmd_bench_suites::Common {
            quick: args.quick,
            pairs: args.pairs,
            seed: args.seed,
            step: args.step(),
            json: args.json,
        };
        return crate::cmd_bench_suites::run(&args.suites, &common, &say);
    }
    let report = measure(&args, &say)?;
    if args.json {
        return print_json(&report);
    }
    print_report(&report);
    Ok(())
}

/// Runs the three measurements: the exact search twice, the seeded pairs with and without the
/// compass, and the pose graph.
fn measure(args: &Args, say: &dyn Fn(&str)) -> Result<Report> {
    let exact = exact_vs_exhaustive(args.quick, 0.0, say)?;
    // The default heading window; --quick narrows it so the oracle stays short.
    let heading_deg = if args.quick {
        3.0
    } else {
        HeadingWindow::default().half_range_deg
    };
    let exact_heading = exact_vs_exhaustive(args.quick, heading_deg, say)?;
    let seeded = seeded_pairs(args, say)?;
    let pairs = accuracy(args, &seeded, HeadingWindow::default().half_range_deg);
    let pairs_no_compass = accuracy(args, &seeded, 180.0);
    say("pose graph: optimizing a 1,000-node loop ...");
    let graph = sdem_sim::pose_graphs::bench_1000_nodes()?;
    Ok(Report {
        threads: rayon::current_num_threads(),
        exact,
        exact_heading,
        pairs,
        pairs_no_compass,
        pose_graph: PoseGraphReport {
            nodes: graph.nodes,
            edges: graph.edges,
            time_ms: graph.time_ms,
            iterations: graph.report.iterations,
            ate_before_m: graph.ate_before_m,
            ate_after_m: graph.ate_after_m,
        },
    })
}

/// Prints the report as text.
fn print_report(report: &Report) {
    println!("sdem bench ({} threads)", report.threads);
    println!();
    println!("1. Exact search against the exhaustive oracle (the paper's pair)");
    for e in [&report.exact, &report.exact_heading] {
        print_exact(e);
    }
    print_pairs(&report.pairs, &report.pairs_no_compass);
    let g = &report.pose_graph;
    println!();
    println!(
        "3. Pose graph: {} nodes, {} edges (a drifting loop, 3 closures): {:.0} ms, {} iterations; \
         ATE {:.2} m -> {:.2} m",
        g.nodes, g.edges, g.time_ms, g.iterations, g.ate_before_m, g.ate_after_m
    );
}

/// Prints part 2: the seeded pairs with the compass (`p`) and without (`n`).
fn print_pairs(p: &PairsReport, n: &PairsReport) {
    println!();
    println!(
        "2. {} seeded pairs (seed {}): motion within ±0.5 m, compass off by up to 10°; search at {} cm, heading ±{}°",
        p.count,
        p.seed,
        p.step_m * 100.0,
        p.heading_window_deg
    );
    println!(
        "   translation error  median {:.2} mm, 95th percentile {:.2} mm, max {:.2} mm",
        p.translation_error_mm.median, p.translation_error_mm.p95, p.translation_error_mm.max
    );
    println!(
        "   rotation error     median {:.3}°, 95th percentile {:.3}°, max {:.3}°",
        p.rotation_error_deg.median, p.rotation_error_deg.p95, p.rotation_error_deg.max
    );
    println!(
        "   time per localization  median {:.0} ms, 95th percentile {:.0} ms",
        p.time_ms.median, p.time_ms.p95
    );
    println!(
        "   success (< 2 cm)   {:.1} %, {} of {} trusted",
        p.success_rate_2cm * 100.0,
        p.trusted,
        p.count
    );
    if let (Some(nees), Some(below)) = (&p.nees, p.nees_below_95) {
        println!(
            "   NEES (6 axes)      median {:.1}, 95th percentile {:.1}, {:.0} % below 12.59 \
             (5.3 and 95 % when the covariance is honest)",
            nees.median,
            nees.p95,
            below * 100.0
        );
    }
    for f in &p.failures {
        println!("   failed: {f}");
    }
    println!(
        "   no compass at all (heading ±{}°): time median {:.0} ms, 95th percentile {:.0} ms; \
         error median {:.2} mm; success {:.1} %",
        n.heading_window_deg,
        n.time_ms.median,
        n.time_ms.p95,
        n.translation_error_mm.median,
        n.success_rate_2cm * 100.0
    );
    for f in &n.failures {
        println!("   failed without the compass: {f}");
    }
}
