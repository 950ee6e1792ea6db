//! `sdem bench --suite real-geometry`: sdem's accuracy on real surfaces, with exact truth.
//!
//! Each real scan (the 3DTK scans and three KITTI frames in `../shared/data`, or the files
//! given with `--scan`) becomes a surface model ([`sdem_sim::reviews::SurfaceModel`]) seen again
//! from seeded poses near where it was taken, as its scanner would see it
//! ([`sdem_sim::reviews::review_pairs`]): a reference view from the scan's own origin and a
//! query view from a known origin, heading and tilt. sdem localizes the query against the
//! reference through the library's root API with the views' attitude readings; small_gicp's
//! GICP (the peers' `register_pair.py`) registers the same clouds from identity. The report
//! gives both errors per scan, sdem's over GICP's on each view, the targets met, and the NEES
//! of the covariance sdem reports.

use super::print::figure;
use super::{Common, SuiteArgs};
use crate::bench_peers::{self, PeerResult, PeerSettings, Peers};
use crate::output::{elapsed_ms, print_json};
use anyhow::{bail, Context, Result};
use sdem::geometry::{pose_error, Vec3};
use sdem::{LocalizeOptions, SearchWindow};
use sdem_sim::benchmark::{nees, share_below, summarize, Stats, CHI2_95_3, CHI2_95_6};
use sdem_sim::reviews::{
    review_pairs, ModelConfig, Review, ReviewConfig, ReviewScanner, SurfaceModel,
};
use serde::Serialize;
use std::path::{Path, PathBuf};
use std::time::Instant;

/// Re-views per scan [default], and with `--quick`.
const REVIEWS: (usize, usize) = (50, 3);
/// The 3DTK scans re-viewed by default (all; scan000 alone with `--quick`).
const THREEDTK_SCANS: [&str; 3] = ["scan000.3d", "scan001.3d", "scan002.3d"];
/// The KITTI frames re-viewed by default (the first alone with `--quick`).
const KITTI_FRAMES: [&str; 3] = ["000000.bin", "000007.bin", "000015.bin"];
/// The targets: on every re-view a translation error at most this multiple of GICP's on the
/// same query …
const TARGET_RATIO: f64 = 1.2;
/// … or this, millimetres, whichever is larger …
const TARGET_FLOOR_MM: f64 = 1.0;
/// … and a rotation error at most this, degrees.
const TARGET_ROTATION_DEG: f64 = 0.05;
/// Re-views made at once (each holds two views in memory).
const CHUNK: usize = 4;
/// The peers' method run.
const GICP: &str = "small_gicp_gicp";

/// A real scan to re-view.
struct Source {
    label: String,
    path: PathBuf,
    points: Vec<Vec3>,
    scanner: ReviewScanner,
    model: ModelConfig,
}

/// One re-view's outcome.
#[derive(Debug, Clone, Serialize)]
struct ReviewRecord {
    scan: String,
    index: usize,
    truth_translation_m: f64,
    truth_rotation_deg: f64,
    reference_points: usize,
    query_points: usize,
    time_ms: f64,
    translation_error_mm: Option<f64>,
    rotation_error_deg: Option<f64>,
    trusted: bool,
    doubts: Vec<&'static str>,
    error: Option<String>,
    /// NEES of sdem's covariance over the six axes and over the translation.
    nees: Option<f64>,
    nees_translation: Option<f64>,
    /// [`sdem::localize::Diagnostics::seen_through_fraction`] at sdem's pose.
    seen_through_fraction: Option<f64>,
    gicp_translation_error_mm: Option<f64>,
    gicp_rotation_error_deg: Option<f64>,
    gicp_error: Option<String>,
    /// The target on this view: max(1.2 × GICP's error, 1 mm).
    bound_mm: Option<f64>,
    /// Both targets met (translation within the bound, rotation within 0.05°); `None` without
    /// GICP's error.
    within_target: Option<bool>,
}

/// What a set of re-views came to.
#[derive(Debug, Clone, Serialize)]
struct Summary {
    group: String,
    reviews: usize,
    /// Errors (no pose) count as infinitely wrong.
    translation_error_mm: Stats,
    rotation_error_deg: Stats,
    time_ms: Stats,
    trusted: usize,
    errors: usize,
    gicp_translation_error_mm: Option<Stats>,
    gicp_rotation_error_deg: Option<Stats>,
    /// sdem's error over GICP's, per view.
    ratio: Option<Stats>,
    /// Views meeting both targets, and views where GICP's error is known.
    within_target: usize,
    compared: usize,
    within_rotation: usize,
    /// sdem's median error no larger than GICP's.
    median_no_worse: Option<bool>,
    nees: Stats,
    nees_translation: Stats,
    /// The share of views whose NEES lies below the χ² 95 % quantile (0.95 when honest).
    nees_below_95: f64,
    nees_translation_below_95: f64,
}

#[derive(Debug, Clone, Serialize)]
struct ScanReport {
    scan: String,
    path: String,
    points: usize,
    /// The scan's angular step, degrees (the model's).
    step_deg: f64,
    scanner: String,
    config: ReviewConfig,
    window: SearchWindow,
    step_m: f64,
    summary: Summary,
}

#[derive(Debug, Clone, Serialize)]
struct Report {
    suite: &'static str,
    threads: usize,
    seed: u64,
    quick: bool,
    peers: Option<String>,
    gicp_settings: Vec<(String, PeerSettings)>,
    skipped: Vec<String>,
    scans: Vec<ScanReport>,
    all: Summary,
    records: Vec<ReviewRecord>,
}

/// Runs `sdem bench --suite real-geometry`.
pub(super) fn run(
    args: &SuiteArgs,
    common: &Common,
    peers: &std::result::Result<Peers, String>,
    say: &dyn Fn(&str),
) -> Result<()> {
    let (paths, skipped) = if args.scans.is_empty() {
        default_scans(common.quick)
    } else {
        (args.scans.clone(), Vec::new())
    };
    if paths.is_empty() {
        bail!(
            "no scan to re-view: {} (--scan FILE names one)",
            skipped.join("; ")
        );
    }
    let count = common
        .pairs
        .unwrap_or(if common.quick { REVIEWS.1 } else { REVIEWS.0 });
    let peers = match (peers, args.peer_pairs) {
        (_, Some(0)) => Err("--peer-pairs 0".to_string()),
        (Ok(p), _) => Ok(p),
        (Err(why), _) => Err(why.clone()),
    };
    let temp = super::TempFolder(
        std::env::temp_dir().join(format!("sdem-bench-real-geometry-{}", std::process::id())),
    );
    let (mut scans, mut records, mut gicp_settings) = (Vec::new(), Vec::new(), Vec::new());
    for path in &paths {
        let source = read_source(path)?;
        say(&format!(
            "{}: {} points, modelling and re-viewing {count} times ...",
            source.label,
            source.points.len()
        ));
        let (report, mut scan_records, settings) =
            run_scan(&source, count, common, &peers, &temp.0)?;
        gicp_settings.push((source.label.clone(), settings));
        scans.push(report);
        records.append(&mut scan_records);
    }
    let report = Report {
        suite: "real-geometry",
        threads: rayon::current_num_threads(),
        seed: common.seed,
        quick: common.quick,
        peers: peers.as_ref().err().cloned(),
        gicp_settings,
        skipped,
        all: summarize_records("all", &records),
        scans,
        records,
    };
    if common.json {
        return print_json(&report);
    }
    print_report(&report);
    Ok(())
}

/// The default scans that exist beside the repository, and why any are missing.
fn default_scans(quick: bool) -> (Vec<PathBuf>, Vec<String>) {
    let data = Path::new(env!("CARGO_MANIFEST_DIR")).join("../../../shared/data");
    let take = if quick { 1 } else { 3 };
    let mut found = Vec::new();
    let mut skipped = Vec::new();
    let threedtk = THREEDTK_SCANS.iter().map(|f| data.join("3dtk-dat").join(f));
    let kitti = (KITTI_FRAMES.iter()).map(|f| data.join("kitti-00-first16/velodyne").join(f));
    for path in threedtk.take(take).chain(kitti.take(take)) {
        if path.is_file() {
            found.push(path);
        } else {
            skipped.push(format!("no {}", bench_peers::shown(&path)));
        }
    }
    (found, skipped)
}

/// Reads a real scan: 3DTK's `.3d` within its scanner's ranges, KITTI's `.bin` re-viewed by an
/// HDL-64E, any other point file by a scanner like the one that took it.
fn read_source(path: &Path) -> Result<Source> {
    let points = sdem_io::read_points(path)
        .with_context(|| format!("cannot read the scan {}", path.display()))?;
    let extension = path
        .extension()
        .map(|e| e.to_string_lossy().to_lowercase())
        .unwrap_or_default();
    let mut model = ModelConfig::default();
    if extension == "3d" {
        model.min_range_m = sdem_io::UOS_MIN_RANGE_M;
        model.max_range_m = sdem_io::UOS_MAX_RANGE_M;
    }
    let kept: Vec<Vec3> = (points.iter())
        .filter(|p| (model.min_range_m..=model.max_range_m).contains(&p.norm()))
        .copied()
        .collect();
    let scanner = if extension == "bin" {
        ReviewScanner::hdl64e()
    } else {
        ReviewScanner::like(&kept)
    };
    // The folder names the data set; KITTI's frames lie one deeper, in velodyne/.
    let folder = |p: Option<&Path>| {
        p.and_then(|p| p.file_name())
            .map(|p| p.to_string_lossy().to_string())
            .unwrap_or_default()
    };
    let mut parent = folder(path.parent());
    if parent == "velodyne" {
        parent = folder(path.parent().and_then(Path::parent));
    }
    let name = path
        .file_name()
        .map(|n| n.to_string_lossy().to_string())
        .unwrap_or_default();
    Ok(Source {
        label: if parent.is_empty() {
            name
        } else {
            format!("{parent}/{name}")
        },
        path: path.to_path_buf(),
        points: kept,
        scanner,
        model,
    })
}

/// Re-views one scan `count` times, localizes each with sdem and GICP.
fn run_scan(
    source: &Source,
    count: usize,
    common: &Common,
    peers: &std::result::Result<&Peers, String>,
    temp: &Path,
) -> Result<(ScanReport, Vec<ReviewRecord>, PeerSettings)> {
    let model = SurfaceModel::new(&source.points, &source.model)
        .with_context(|| format!("{}: cannot model the scan", source.label))?;
    let config = ReviewConfig::for_scanner(source.scanner.clone());
    let spinning = matches!(config.scanner, ReviewScanner::Spinning(_));
    let window = SearchWindow::around(&Vec3::zeros(), config.displacement_half_m);
    let options = LocalizeOptions {
        window,
        step_m: if spinning {
            super::LIDAR_STEP_M
        } else {
            common.step
        },
        ..Default::default()
    };
    let settings = PeerSettings {
        repeat: 1,
        ..if spinning {
            PeerSettings::lidar()
        } else {
            PeerSettings::indoor()
        }
    };
    let bar = crate::progress::bar(count as u64, common.json, &source.label);
    let mut records = Vec::with_capacity(count);
    let mut start = 0;
    while start < count {
        let end = (start + CHUNK).min(count);
        let reviews = review_pairs(&model, &config, common.seed, start..end)
            .with_context(|| format!("{}: cannot re-view", source.label))?;
        for review in &reviews {
            let mut record = localize_review(&source.label, review, &options, &config.scanner);
            if let Ok(peers) = peers {
                gicp(peers, review, &settings, temp, &mut record)?;
            }
            records.push(record);
            bar.inc(1);
        }
        start = end;
    }
    bar.finish_and_clear();
    let report = ScanReport {
        scan: source.label.clone(),
        path: bench_peers::shown(&source.path),
        points: source.points.len(),
        step_deg: model.step_deg(),
        scanner: config.scanner.describe(),
        window,
        step_m: options.step_m,
        summary: summarize_records(&source.label, &records),
        config,
    };
    Ok((report, records, settings))
}

/// sdem on one re-view through the root API, with the views' readings
/// ([`sdem_sim::reviews::localize_review`]).
fn localize_review(
    label: &str,
    review: &Review,
    options: &LocalizeOptions,
    scanner: &ReviewScanner,
) -> ReviewRecord {
    let start = Instant::now();
    let found =
        sdem_sim::reviews::localize_review(review, scanner, true, options.window, options.step_m);
    let time_ms = elapsed_ms(start);
    let mut record = ReviewRecord {
        scan: label.to_string(),
        index: review.index,
        truth_translation_m: review.truth.translation.vector.norm(),
        truth_rotation_deg: review.truth.rotation.angle().to_degrees(),
        reference_points: review.reference_points.len(),
        query_points: review.query_points.len(),
        time_ms,
        translation_error_mm: None,
        rotation_error_deg: None,
        trusted: false,
        doubts: Vec::new(),
        error: None,
        nees: None,
        nees_translation: None,
        seen_through_fraction: None,
        gicp_translation_error_mm: None,
        gicp_rotation_error_deg: None,
        gicp_error: None,
        bound_mm: None,
        within_target: None,
    };
    match found {
        Ok(found) => {
            let (t, r) = pose_error(&review.truth, &found.reference_from_query);
            record.translation_error_mm = Some(t * 1e3);
            record.rotation_error_deg = Some(r.to_degrees());
            record.trusted = found.trusted;
            record.doubts = found.doubts.iter().map(|d| d.kind()).collect();
            let consistency = (found.covariance.as_ref())
                .and_then(|c| nees(&review.truth, &found.reference_from_query, c));
            record.nees = consistency.map(|c| c.0);
            record.nees_translation = consistency.map(|c| c.1);
            record.seen_through_fraction = Some(found.diagnostics.seen_through_fraction);
        }
        Err(e) => record.error = Some(e.to_string()),
    }
    record
}

/// GICP from identity on the same clouds (reference = target, query = source), into `record`.
fn gicp(
    peers: &Peers,
    review: &Review,
    settings: &PeerSettings,
    temp: &Path,
    record: &mut ReviewRecord,
) -> Result<()> {
    let dir = temp.join(format!("{}-{:04}", sanitized(&record.scan), review.index));
    std::fs::create_dir_all(&dir).with_context(|| format!("cannot create {}", dir.display()))?;
    bench_peers::write_cloud(&dir.join("reference.ply"), &review.reference_points)?;
    bench_peers::write_cloud(&dir.join("query.ply"), &review.query_points)?;
    bench_peers::write_transform(&dir.join("truth.txt"), &review.truth)?;
    let result: Option<PeerResult> = peers.run_methods(&dir, settings, &[GICP]).pop();
    let _ = std::fs::remove_dir_all(&dir);
    let Some(result) = result else {
        return Ok(());
    };
    record.gicp_error = result.error;
    // register_pair.py rounds its errors to 0.1 mm: the pose it returns is scored here.
    if let Some(estimate) = result.estimate.as_ref().map(sdem::geometry::Pose::from) {
        let (t, r) = pose_error(&review.truth, &estimate);
        record.gicp_translation_error_mm = Some(t * 1e3);
        record.gicp_rotation_error_deg = Some(r.to_degrees());
    }
    if let Some(g) = record.gicp_translation_error_mm {
        let bound = (TARGET_RATIO * g).max(TARGET_FLOOR_MM);
        record.bound_mm = Some(bound);
        record.within_target = Some(
            record.translation_error_mm.is_some_and(|t| t <= bound)
                && record
                    .rotation_error_deg
                    .is_some_and(|r| r <= TARGET_ROTATION_DEG),
        );
    }
    Ok(())
}

/// `label` as a file name.
fn sanitized(label: &str) -> String {
    label
        .chars()
        .map(|c| if c.is_ascii_alphanumeric() { c } else { '_' })
        .collect()
}

/// What `records` came to, as `group`.
fn summarize_records(group: &str, records: &[ReviewRecord]) -> Summary {
    let values = |f: &dyn Fn(&ReviewRecord) -> Option<f64>| -> Vec<f64> {
        records.iter().map(|r| f(r).unwrap_or(f64::NAN)).collect()
    };
    let compared: Vec<&ReviewRecord> = records
        .iter()
        .filter(|r| r.gicp_translation_error_mm.is_some())
        .collect();
    let gicp = |f: &dyn Fn(&ReviewRecord) -> Option<f64>| -> Option<Stats> {
        (!compared.is_empty()).then(|| {
            summarize(
                &compared
                    .iter()
                    .map(|r| f(r).unwrap_or(f64::NAN))
                    .collect::<Vec<_>>(),
            )
        })
    };
    let translation = summarize(&values(&|r| r.translation_error_mm));
    let gicp_translation = gicp(&|r| r.gicp_translation_error_mm);
    let ratio = gicp(&|r| Some(r.translation_error_mm? / r.gicp_translation_error_mm?.max(1e-9)));
    let median_no_worse = gicp_translation.map(|g| {
        let mine = summarize(
            &compared
                .iter()
                .map(|r| r.translation_error_mm.unwrap_or(f64::NAN))
                .collect::<Vec<_>>(),
        );
        mine.median <= g.median
    });
    let nees_all = values(&|r| r.nees);
    let nees_translation = values(&|r| r.nees_translation);
    Summary {
        group: group.to_string(),
        reviews: records.len(),
        translation_error_mm: translation,
        rotation_error_deg: summarize(&values(&|r| r.rotation_error_deg)),
        time_ms: summarize(&records.iter().map(|r| r.time_ms).collect::<Vec<_>>()),
        trusted: records.iter().filter(|r| r.trusted).count(),
        errors: records.iter().filter(|r| r.error.is_some()).count(),
        gicp_translation_error_mm: gicp_translation,
        gicp_rotation_error_deg: gicp(&|r| r.gicp_rotation_error_deg),
        ratio,
        within_target: compared
            .iter()
            .filter(|r| r.within_target == Some(true))
            .count(),
        compared: compared.len(),
        within_rotation: records
            .iter()
            .filter(|r| {
                r.rotation_error_deg
                    .is_some_and(|d| d <= TARGET_ROTATION_DEG)
            })
            .count(),
        median_no_worse,
        nees_below_95: share_below(&nees_all, CHI2_95_6).unwrap_or(0.0),
        nees_translation_below_95: share_below(&nees_translation, CHI2_95_3).unwrap_or(0.0),
        nees: summarize(&nees_all),
        nees_translation: summarize(&nees_translation),
    }
}

/// Prints the report as text.
fn print_report(report: &Report) {
    println!(
        "sdem bench --suite real-geometry ({} threads, seed {}{})",
        report.threads,
        report.seed,
        if report.quick { ", quick" } else { "" }
    );
    println!(
        "  real scans seen again from seeded poses: a reference from the scan's origin, a query \
         from a known origin, heading and tilt near it; sdem with the views' attitude readings, \
         GICP (small_gicp, from identity) on the same clouds"
    );
    for s in &report.skipped {
        println!("  skipped: {s}");
    }
    if let Some(why) = &report.peers {
        println!("  GICP: not run ({why})");
    }
    for scan in &report.scans {
        println!();
        println!(
            "{} ({} points, {:.2}° steps):",
            scan.scan, scan.points, scan.step_deg
        );
        println!("  re-viewed by {}", scan.scanner);
        let c = &scan.config;
        println!(
            "  query within ±{:?} m, turned up to {}°, tilted up to {}°, compass off by up to \
             {}°; {:.0} % of returns dropped; sdem's search at {} cm",
            c.displacement_half_m,
            c.yaw_spread_deg,
            c.tilt_max_deg,
            c.compass_error_max_deg,
            c.drop_fraction * 100.0,
            scan.step_m * 100.0
        );
    }
    println!();
    print_header();
    for scan in &report.scans {
        print_row(&scan.summary);
    }
    print_row(&report.all);
    println!();
    print_targets(&report.all);
    print_misses(&report.records);
}

fn print_header() {
    println!(
        "{:<22} {:>4} {:>20} {:>20} {:>12} {:>12} {:>8} {:>8} {:>12} {:>7}",
        "",
        "n",
        "sdem mm med/p95/max",
        "GICP mm med/p95/max",
        "ratio med/max",
        "sdem ° med/max",
        "target",
        "trusted",
        "NEES6 med/<95%",
        "med ms"
    );
}

fn print_row(s: &Summary) {
    let triple = |t: &Stats| {
        format!(
            "{}/{}/{}",
            figure(t.median, 2),
            figure(t.p95, 2),
            figure(t.max, 2)
        )
    };
    let gicp = s
        .gicp_translation_error_mm
        .as_ref()
        .map_or("-".into(), triple);
    let ratio = s.ratio.as_ref().map_or("-".into(), |r| {
        format!("{}/{}", figure(r.median, 2), figure(r.max, 2))
    });
    println!(
        "{:<22} {:>4} {:>20} {:>20} {:>12} {:>12} {:>8} {:>8} {:>12} {:>7.0}",
        s.group,
        s.reviews,
        triple(&s.translation_error_mm),
        gicp,
        ratio,
        format!(
            "{}/{}",
            figure(s.rotation_error_deg.median, 3),
            figure(s.rotation_error_deg.max, 3)
        ),
        format!("{}/{}", s.within_target, s.compared),
        s.trusted,
        format!(
            "{}/{:.0}%",
            figure(s.nees.median, 1),
            s.nees_below_95 * 100.0
        ),
        s.time_ms.median
    );
}

fn print_targets(all: &Summary) {
    println!(
        "targets: on every re-view ≤ max({TARGET_RATIO} × GICP's error, {TARGET_FLOOR_MM} mm) \
         and ≤ {TARGET_ROTATION_DEG}°: {} of {} met ({} of {} within {TARGET_ROTATION_DEG}°); \
         median no worse than GICP's: {}",
        all.within_target,
        all.compared,
        all.within_rotation,
        all.reviews,
        match all.median_no_worse {
            Some(true) => "yes",
            Some(false) => "NO",
            None => "-",
        }
    );
    println!(
        "covariance: NEES = eᵀ Σ⁻¹ e of the estimate's error e (translation and rotation vector \
         of estimate⁻¹ · truth, query axes) under sdem's reported covariance Σ; honest: median \
         ≈ 5.3 (χ², 6 axes) with 95 % below {CHI2_95_6}: median {}, mean {}, {:.0} % below; \
         translation alone (median ≈ 2.4, 95 % below {CHI2_95_3}): median {}, {:.0} % below",
        figure(all.nees.median, 1),
        figure(all.nees.mean, 1),
        all.nees_below_95 * 100.0,
        figure(all.nees_translation.median, 1),
        all.nees_translation_below_95 * 100.0
    );
}

/// The re-views that missed a target, worst first (ten at most).
fn print_misses(records: &[ReviewRecord]) {
    let mut missed: Vec<&ReviewRecord> = records
        .iter()
        .filter(|r| r.within_target == Some(false) || r.error.is_some())
        .collect();
    missed.sort_by(|a, b| {
        let excess = |r: &ReviewRecord| {
            r.translation_error_mm.unwrap_or(f64::INFINITY) / r.bound_mm.unwrap_or(1.0)
        };
        excess(b).total_cmp(&excess(a))
    });
    for r in missed.iter().take(10) {
        match &r.error {
            Some(e) => println!("  missed: {} #{}: error: {e}", r.scan, r.index),
            None => println!(
                "  missed: {} #{}: {} mm {}° (GICP {} mm {}°, bound {} mm){}",
                r.scan,
                r.index,
                figure(r.translation_error_mm.unwrap_or(f64::NAN), 2),
                figure(r.rotation_error_deg.unwrap_or(f64::NAN), 3),
                figure(r.gicp_translation_error_mm.unwrap_or(f64::NAN), 2),
                figure(r.gicp_rotation_error_deg.unwrap_or(f64::NAN), 3),
                figure(r.bound_mm.unwrap_or(f64::NAN), 2),
                if r.trusted { "" } else { ", flagged" }
            ),
        }
    }
    if missed.len() > 10 {
        println!("  ... {} more (see --json)", missed.len() - 10);
    }
}
