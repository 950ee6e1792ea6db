//! `sdem bench --faults`: localization under the faults of a disaster site.
//!
//! For each case (no fault, each [`Fault`] alone, all together) the same number of seeded pairs
//! ([`sdem_sim::faults::fault_pairs`]) are localized as the robot would in the field
//! ([`sdem_sim::faults::localize_config`]: ±0.15 m around the odometry prior, headings within ±25°
//! of the compass) and scored against the truth: success rate (error < 2 cm), translation and
//! rotation errors, time, and how many failures the diagnostics flagged (`ambiguous`, or an
//! error) so the robot knows not to trust them.

use crate::bench_tally::Tally;
use crate::output::print_json;
use anyhow::Result;
use sdem::doubt::Doubt;
use sdem::sdem::SdemConfig;
use sdem_sim::benchmark::Stats;
use sdem_sim::faults::{fault_pairs, localize_fault_pair, Fault, FaultConfig};
use serde::Serialize;
use std::collections::BTreeMap;

/// What `sdem bench --faults` runs.
pub struct FaultArgs {
    /// Pairs per case.
    pub pairs: usize,
    /// Seed of the scene and the pairs.
    pub seed: u64,
    /// Grid step of the search, metres.
    pub step: f64,
    /// One JSON object instead of text.
    pub json: bool,
    /// Only these cases (empty: all).
    pub cases: Vec<Case>,
}

/// One case: a set of faults.
#[derive(Serialize)]
struct CaseReport {
    case: String,
    what: String,
    pairs: usize,
    success_rate_2cm: f64,
    translation_error_mm: Stats,
    rotation_error_deg: Stats,
    time_ms: Stats,
    /// Failures (≥ 2 cm) that the diagnostics flagged `ambiguous`: the robot knows not to trust them.
    failures_flagged: usize,
    /// Successes flagged `ambiguous` all the same (false alarms).
    successes_flagged: usize,
    /// Why the successes were flagged: reason kind → count (a success may have several).
    false_alarm_reasons: BTreeMap<&'static str, usize>,
    failures: Vec<String>,
}

#[derive(Serialize)]
struct Report {
    threads: usize,
    seed: u64,
    step_m: f64,
    window_half_m: [f64; 3],
    heading_half_range_deg: f64,
    odometry_error_fraction: f64,
    cases: Vec<CaseReport>,
}

/// One case of `--case`: its name and the faults injected together.
#[derive(Debug, Clone, PartialEq)]
pub struct Case {
    /// `none`, a fault's name, or `all`.
    pub name: &'static str,
    /// The faults injected.
    pub faults: Vec<Fault>,
}

/// Every case, in the order the bench runs them: `none`, each fault alone, `all`.
fn all_cases() -> Vec<Case> {
    let alone = Fault::ALL.iter().map(|&f| Case {
        name: f.name(),
        faults: vec![f],
    });
    std::iter::once(Case {
        name: "none",
        faults: Vec::new(),
    })
    .chain(alone)
    .chain(std::iter::once(Case {
        name: "all",
        faults: Fault::ALL.to_vec(),
    }))
    .collect()
}

/// The parser of `--case`, for clap: one of the cases' names (anything else is a usage error
/// listing them, as in `--help`), as its [`Case`]. The names are the cases', so every name
/// clap takes is a case; were one not, clap would refuse it as a usage error too.
pub fn case_parser() -> impl clap::builder::TypedValueParser<Value = Case> {
    use clap::builder::TypedValueParser;
    let cases = all_cases();
    let names: Vec<&'static str> = cases.iter().map(|c| c.name).collect();
    clap::builder::PossibleValuesParser::new(names).try_map(move |name| {
        (cases.iter().find(|c| c.name == name).cloned()).ok_or_else(|| format!("no case {name}"))
    })
}

/// The cases to run: those `--case` chose, in its order, or every one.
fn cases(selected: &[Case]) -> Vec<Case> {
    if selected.is_empty() {
        return all_cases();
    }
    selected.to_vec()
}

fn run_case(
    name: &str,
    faults: &[Fault],
    args: &FaultArgs,
    config: &FaultConfig,
    say: &dyn Fn(&str),
) -> Result<CaseReport> {
    say(&format!("{name}: simulating {} pairs ...", args.pairs));
    let pairs = fault_pairs(args.seed, args.pairs, faults, config)?;
    let sdem_config = SdemConfig::default();
    let (mut tally, mut failures) = (Tally::default(), Vec::new());
    let (mut failures_flagged, mut successes_flagged) = (0, 0);
    let mut false_alarm_reasons = BTreeMap::new();
    let bar = crate::progress::bar(pairs.len() as u64, args.json, &format!("{name}: localized"));
    for (i, pair) in pairs.iter().enumerate() {
        bar.inc(1);
        match localize_fault_pair(pair, &sdem_config, config) {
            Ok(result) => {
                let d = &result.localization.diagnostics;
                let doubts = || {
                    result
                        .localization
                        .doubts
                        .iter()
                        .filter(|d| d.is_ambiguity())
                };
                if tally.record(Some(&result)) {
                    failures_flagged += usize::from(d.ambiguous);
                    failures.push(format!(
                        "pair {i}: error {:.1} mm, {:.2}°, {:.0} % of points matched, {} ({})",
                        result.translation_error_m * 1e3,
                        result.rotation_error_deg,
                        d.inlier_fraction * 100.0,
                        if d.ambiguous {
                            let why: Vec<String> = doubts().map(ToString::to_string).collect();
                            format!("flagged: {}", why.join("; "))
                        } else {
                            "not flagged".to_string()
                        },
                        pair.injected
                    ));
                } else if d.ambiguous {
                    successes_flagged += 1;
                    for doubt in doubts() {
                        *false_alarm_reasons.entry(reason_kind(doubt)).or_insert(0) += 1;
                    }
                }
            }
            Err(e) => {
                tally.record(None);
                failures_flagged += 1;
                failures.push(format!("pair {i}: {e}"));
            }
        }
    }
    bar.finish_and_clear();
    Ok(CaseReport {
        case: name.to_string(),
        what: describe(faults, config),
        pairs: pairs.len(),
        success_rate_2cm: tally.success_rate(),
        translation_error_mm: tally.translation_error_mm(),
        rotation_error_deg: tally.rotation_error_deg(),
        time_ms: tally.time_ms(),
        failures_flagged,
        successes_flagged,
        false_alarm_reasons,
        failures,
    })
}

/// What a case's faults do, in words.
fn describe(faults: &[Fault], config: &FaultConfig) -> String {
    if faults.is_empty() {
        "no fault".to_string()
    } else if faults.len() == Fault::ALL.len() {
        "every fault at once".to_string()
    } else {
        faults
            .iter()
            .map(|f| f.describe(config))
            .collect::<Vec<_>>()
            .join("; ")
    }
}

/// A short name for a kind of doubt about a match, for the false alarms' tally.
fn reason_kind(doubt: &Doubt) -> &'static str {
    match doubt {
        Doubt::RunnerUp { .. } | Doubt::AnotherRotation { .. } | Doubt::SeenThrough { .. } => {
            "runner-up close"
        }
        Doubt::RefinementFailed { .. } => "refinement failed",
        Doubt::FlatCovariance { .. } | Doubt::FlatCost { .. } | Doubt::Unconstrained { .. } => {
            "flat cost"
        }
        Doubt::FewInliers { .. } => "thin match",
        Doubt::OnWindowEdge | Doubt::TakenFromPrediction { .. } | Doubt::PriorConflict { .. } => {
            "other"
        }
        Doubt::AttitudeCorrected { .. } => "attitude corrected",
        Doubt::UnrefutedRotation { .. } => "rotation undecided",
        Doubt::FreeSpaceConflict { .. } => "free space",
    }
}

/// Runs `sdem bench --faults`.
pub fn run(args: &FaultArgs, say: &dyn Fn(&str)) -> Result<()> {
    let config = FaultConfig {
        step_m: args.step,
        ..FaultConfig::default()
    };
    let mut reports = Vec::new();
    for case in cases(&args.cases) {
        reports.push(run_case(case.name, &case.faults, args, &config, say)?);
    }
    let report = Report {
        threads: rayon::current_num_threads(),
        seed: args.seed,
        step_m: config.step_m,
        window_half_m: config.window_half_m,
        heading_half_range_deg: config.heading_half_range_deg,
        odometry_error_fraction: config.odometry_error_fraction,
        cases: reports,
    };
    if args.json {
        return print_json(&report);
    }
    print_text(&report, &config);
    Ok(())
}

/// Prints the report as text: one row per case, then every failure.
fn print_text(report: &Report, config: &FaultConfig) {
    println!(
        "sdem bench --faults ({} threads, seed {}): window ±{} m around the odometry prior \
         ({} % error), heading ±{}° around the compass, grid {} cm",
        report.threads,
        report.seed,
        config.window_half_m[0],
        config.odometry_error_fraction * 100.0,
        config.heading_half_range_deg,
        config.step_m * 100.0
    );
    println!();
    println!(
        "{:<11} {:>5} {:>9} {:>8} {:>10} {:>10} {:>10} {:>10} {:>9}  what",
        "case",
        "pairs",
        "success",
        "flagged",
        "median mm",
        "p95 mm",
        "max mm",
        "median °",
        "time ms"
    );
    for c in &report.cases {
        let failed = c.pairs - (c.success_rate_2cm * c.pairs as f64).round() as usize;
        println!(
            "{:<11} {:>5} {:>8.1}% {:>8} {:>10.2} {:>10.2} {:>10.1} {:>10.3} {:>9.0}  {}",
            c.case,
            c.pairs,
            c.success_rate_2cm * 100.0,
            format!("{}/{failed}", c.failures_flagged),
            c.translation_error_mm.median,
            c.translation_error_mm.p95,
            c.translation_error_mm.max,
            c.rotation_error_deg.median,
            c.time_ms.median,
            c.what
        );
    }
    println!(
        "flagged: the failures (error of 2 cm or more) the diagnostics marked ambiguous, or that \
         ended in an error, of all the failures"
    );
    for c in &report.cases {
        for f in &c.failures {
            println!("{} failed: {f}", c.case);
        }
    }
}
