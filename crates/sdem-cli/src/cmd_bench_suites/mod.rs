//! `sdem bench --suite unlevelled|compass-noise|lidar`: sdem on scans as they come in the
//! field, through the library's root API only (`sdem::Scan::from_points`, `sdem::localize`),
//! with the peers on the same pairs in the same run.
//!
//! - `unlevelled`: seeded pairs of the tilting scanner in the rubble void, the ditch, a
//!   corridor and an open hall ([`SuiteConfig::unlevelled`]): the query up to 1 m away, roll and
//!   pitch up to ±30°, any heading, no attitude on either scan.
//! - `compass-noise`: the same pairs, each scan with a reading off by σ 2° in roll and pitch and
//!   σ 20° in heading, and that σ stated ([`SuiteConfig::compass_noise`]).
//! - `lidar`: KITTI frames i → i+1 and i → i+2 without a guess ([`crate::bench_kitti`]), and
//!   simulated spinning-LiDAR pairs in a street and a hall ([`SuiteConfig::spinning_lidar`]).
//!
//! Each part reports the success rate (within 2 cm and 0.5°; 3 cm and 0.3° for LiDAR), the
//! errors' and times' median and 95th percentile, how many results were trusted and how many
//! flagged, and how many wrong poses were reported as trusted (the target is none); then the
//! peers' success rates and median times on a subset, and sdem's median time over theirs.

use crate::bench_kitti::{self, Kitti};
use crate::bench_peers::{self, MethodReport, PeerResult, PeerSettings, Peers};
use crate::output::{elapsed_ms, print_json};
use anyhow::{Context, Result};
use nalgebra::Point3;
use print::print_report;
use sdem::geometry::{pose_error, Attitude, Pose, PoseRecord, Vec3};
use sdem::{LocalizeOptions, Scan, SdemConfig, SearchWindow};
use sdem_sim::benchmark::{summarize, Stats};
use sdem_sim::suites::{Readings, SuiteConfig, SuiteGenerator, SuiteSensor};
use serde::Serialize;
use std::collections::BTreeMap;
use std::ops::Range;
use std::path::{Path, PathBuf};
use std::time::Instant;

mod flags;
mod print;
mod real_geometry;
mod routes;

use flags::scale_args;
pub use flags::{check_flags, Common, Suite, SuiteArgs};

/// Simulated pairs per suite [default], and with `--quick`.
const SIMULATED_PAIRS: (usize, usize) = (200, 8);
/// Simulated spinning-LiDAR pairs [default], and with `--quick`.
const LIDAR_PAIRS: (usize, usize) = (20, 4);
/// KITTI pairs with `--quick` (all of them otherwise).
const QUICK_KITTI_PAIRS: usize = 4;
/// Pairs given to the peers in each simulated part [default], and with `--quick`.
const PEER_PAIRS: (usize, usize) = (20, 4);
/// Success for the simulated tilting-scanner pairs: metres, degrees.
const SIMULATED_SUCCESS: (f64, f64) = (0.02, 0.5);
/// Success for LiDAR pairs: metres, degrees.
const LIDAR_SUCCESS: (f64, f64) = (0.03, 0.3);
/// The LiDAR pairs' search grid, metres (the refinement goes below it).
const LIDAR_STEP_M: f64 = 0.05;
/// The KITTI pairs' window: the car moves 0.86 m a frame, 1.72 m in two; ±0.3 m in height.
const KITTI_WINDOW_HALF_M: [f64; 3] = [2.0, 2.0, 0.3];
/// Pairs simulated at once (each holds two scans in memory).
const CHUNK: usize = 8;

/// One pair as sdem and the peers get it.
struct Case {
    index: usize,
    group: String,
    /// Which pair, in words: the scene, or the frames.
    label: String,
    reference: Vec<Point3<f64>>,
    query: Vec<Point3<f64>>,
    reference_attitude: Option<Attitude>,
    query_attitude: Option<Attitude>,
    truth: Pose,
    overlap: Option<f64>,
    query_tilt_deg: Option<f64>,
}

/// One pair's outcome, as the JSON lists it.
#[derive(Debug, Clone, Serialize)]
struct PairRecord {
    index: usize,
    group: String,
    label: String,
    /// The truth's translation, metres, and rotation, degrees.
    truth_translation_m: f64,
    truth_rotation_deg: f64,
    #[serde(skip_serializing_if = "Option::is_none")]
    query_tilt_deg: Option<f64>,
    #[serde(skip_serializing_if = "Option::is_none")]
    overlap: Option<f64>,
    time_ms: f64,
    translation_error_m: Option<f64>,
    rotation_error_deg: Option<f64>,
    /// sdem's `reference_from_query`.
    estimate: Option<PoseRecord>,
    /// Within the part's success thresholds.
    correct: bool,
    /// sdem returned a pose without doubts.
    trusted: bool,
    doubts: Vec<&'static str>,
    error: Option<String>,
    /// Eq. (1) at the estimate and at the truth (`sdem::cost_at`, the search's cost), m²;
    /// `None` where the scans share too few cells at that pose to compare.
    cost_at_estimate: Option<f64>,
    cost_at_truth: Option<f64>,
    /// [`sdem::localize::Diagnostics::seen_through_fraction`] at the estimate.
    seen_through_fraction: Option<f64>,
}

impl PairRecord {
    /// A wrong pose that the scans themselves favour: eq. (1) is lower at the estimate than at
    /// the truth, or the truth shares too few cells to be compared at all. No search over
    /// this cost can find such a pair's truth; only a doubt can save it.
    fn scans_favour_wrong(&self) -> bool {
        !self.correct
            && self.estimate.is_some()
            && match (self.cost_at_estimate, self.cost_at_truth) {
                (Some(estimate), Some(truth)) => estimate <= truth,
                (_, None) => true,
                (None, Some(_)) => false,
            }
    }
}

/// What a set of pairs came to.
#[derive(Debug, Clone, Serialize)]
struct TallyReport {
    group: String,
    pairs: usize,
    /// Within the success thresholds (trusted or not).
    succeeded: usize,
    success_rate: f64,
    /// Returned without doubts.
    trusted: usize,
    /// Returned with doubts, or an error: the caller knows not to trust them.
    flagged: usize,
    /// An error instead of a pose (counted in `flagged`).
    errors: usize,
    /// Wrong poses (beyond the thresholds) reported as trusted: the target is 0.
    wrong_trusted: usize,
    /// Wrong poses flagged (doubts or an error): caught.
    wrong_flagged: usize,
    /// Right poses flagged all the same: false alarms.
    correct_flagged: usize,
    /// Wrong poses the scans themselves favour over the truth (eq. 1 lower at the estimate,
    /// or the truth not comparable): failures of the data and the cost, not of the search.
    wrong_favoured_by_scans: usize,
    /// Errors count as infinitely wrong.
    translation_error_mm: Stats,
    rotation_error_deg: Stats,
    /// Every pair's time, errors included.
    time_ms: Stats,
    /// How often each kind of doubt was raised.
    doubt_kinds: BTreeMap<&'static str, usize>,
}

/// The peers on a part's subset.
#[derive(Debug, Clone, Serialize)]
struct PeersReport {
    available: bool,
    /// Why they did not run, when they did not.
    reason: Option<String>,
    /// The subset: the first `pairs` pairs of the part.
    pairs: usize,
    subset: String,
    settings: Option<PeerSettings>,
    /// sdem on the same subset.
    sdem_success_rate: Option<f64>,
    sdem_time_ms: Option<Stats>,
    methods: Vec<MethodReport>,
    /// The global peer with the lowest median time, and sdem's median over its.
    fastest_global: Option<String>,
    sdem_time_ratio_to_fastest_global: Option<f64>,
    /// Every method's result on every pair of the subset, in the order of the subset.
    per_pair: Vec<Vec<PeerResult>>,
}

/// One part of a suite.
#[derive(Debug, Clone, Serialize)]
struct PartReport {
    part: String,
    what: String,
    available: bool,
    /// Why the part did not run, when it did not.
    reason: Option<String>,
    success_translation_m: f64,
    success_rotation_deg: f64,
    window: Option<SearchWindow>,
    step_m: f64,
    /// False where the truth itself is doubted (KITTI's first frames, by its README): the
    /// part's wrong poses are not counted in the report's total, and the peers' agreement is
    /// the check.
    truth_reliable: bool,
    /// The recipe of the simulated pairs.
    config: Option<serde_json::Value>,
    all: Option<TallyReport>,
    by_group: Vec<TallyReport>,
    peers: Option<PeersReport>,
    /// The text lists every pair.
    #[serde(skip)]
    list_pairs: bool,
    records: Vec<PairRecord>,
}

#[derive(Debug, Clone, Serialize)]
struct Report {
    suite: &'static str,
    threads: usize,
    seed: u64,
    quick: bool,
    /// Wrong poses reported as trusted over every part whose truth is reliable: the target
    /// is 0.
    wrong_trusted: usize,
    parts: Vec<PartReport>,
}

/// What one part runs.
struct PartSpec<'a> {
    name: String,
    what: String,
    count: usize,
    options: LocalizeOptions,
    /// See [`PartReport::truth_reliable`].
    truth_reliable: bool,
    /// The S-DEM grid and the search's scale derived from each pair's reference scan
    /// (`SdemConfig::for_scan`, `LocalizeOptions::for_scan`; the window and heading kept), as
    /// for a LiDAR; otherwise the tilting SICK's defaults.
    match_scan: bool,
    success: (f64, f64),
    peer_count: usize,
    peer_settings: PeerSettings,
    /// How the first pairs, which the peers get, spread over the part.
    subset_spread: &'static str,
    /// The text lists every pair (few pairs, each worth reading).
    list_pairs: bool,
    config: Option<serde_json::Value>,
    make: Box<dyn FnMut(Range<usize>) -> Result<Vec<Case>> + 'a>,
}

/// Runs `sdem bench --suite`, its flags checked by [`check_flags`].
pub fn run(args: &SuiteArgs, common: &Common, say: &dyn Fn(&str)) -> Result<()> {
    let suite = args.suite.context("no --suite given")?;
    if suite == Suite::Scale {
        return crate::cmd_bench_scale::run(&scale_args(args, common)?, say);
    }
    let peers = bench_peers::find(args.peers.as_deref())?;
    if suite == Suite::Routes {
        let only = routes::parse_routes(&args.routes)?;
        return routes::run(&only, args.kitti.as_deref(), &peers, common, say);
    }
    let mut parts = Vec::new();
    match suite {
        Suite::Routes => unreachable!("the routes suite returned above"),
        Suite::Unlevelled | Suite::CompassNoise => {
            let config = if suite == Suite::Unlevelled {
                SuiteConfig::unlevelled()
            } else {
                SuiteConfig::compass_noise()
            };
            let spec = simulated_spec(suite.name(), config, args, common)?;
            parts.push(run_part(spec, &peers, common.json, say)?);
        }
        Suite::RealGeometry => return real_geometry::run(args, common, &peers, say),
        Suite::Lidar => {
            let kitti = match &args.kitti {
                Some(dir) => Ok(Kitti::read(dir)?),
                None => {
                    let dir = bench_kitti::default_folder();
                    if dir.exists() {
                        say(&format!("kitti: reading {} ...", bench_peers::shown(&dir)));
                        Ok(Kitti::read(&dir)?)
                    } else {
                        Err(format!(
                            "no KITTI folder at {} (--kitti DIR names one)",
                            bench_peers::shown(&dir)
                        ))
                    }
                }
            };
            parts.push(match kitti {
                Ok(kitti) => run_part(kitti_spec(&kitti, args, common), &peers, common.json, say)?,
                Err(reason) => unavailable("kitti", reason),
            });
            let spec = simulated_spec(
                "simulated-lidar",
                SuiteConfig::spinning_lidar(),
                args,
                common,
            )?;
            parts.push(run_part(spec, &peers, common.json, say)?);
            let spec = simulated_spec(
                "simulated-solid-state",
                SuiteConfig::solid_state_lidar(),
                args,
                common,
            )?;
            parts.push(run_part(spec, &peers, common.json, say)?);
        }
        Suite::Scale => unreachable!("the scale suite runs on its own, above"),
    }
    let report = Report {
        suite: suite.name(),
        threads: rayon::current_num_threads(),
        seed: common.seed,
        quick: common.quick,
        wrong_trusted: parts
            .iter()
            .filter(|p| p.truth_reliable)
            .filter_map(|p| p.all.as_ref())
            .map(|a| a.wrong_trusted)
            .sum(),
        parts,
    };
    if common.json {
        return print_json(&report);
    }
    print_report(&report);
    Ok(())
}

/// A part that could not run.
fn unavailable(part: &str, reason: String) -> PartReport {
    PartReport {
        part: part.to_string(),
        what: String::new(),
        available: false,
        reason: Some(reason),
        success_translation_m: LIDAR_SUCCESS.0,
        success_rotation_deg: LIDAR_SUCCESS.1,
        window: None,
        step_m: LIDAR_STEP_M,
        truth_reliable: true,
        config: None,
        all: None,
        by_group: Vec::new(),
        peers: None,
        list_pairs: false,
        records: Vec::new(),
    }
}

/// The simulated pairs of `config` as a part.
fn simulated_spec<'a>(
    name: &str,
    config: SuiteConfig,
    args: &SuiteArgs,
    common: &Common,
) -> Result<PartSpec<'a>> {
    let lidar = matches!(config.sensor, SuiteSensor::Spinning(_));
    let (default, quick) = if lidar { LIDAR_PAIRS } else { SIMULATED_PAIRS };
    let count = common
        .pairs
        .unwrap_or(if common.quick { quick } else { default });
    let peer_default = if common.quick {
        PEER_PAIRS.1
    } else {
        PEER_PAIRS.0
    };
    let step_m = if lidar { LIDAR_STEP_M } else { common.step };
    let options = LocalizeOptions {
        window: config.search_window(),
        step_m,
        ..Default::default()
    };
    let what = describe(&config, count, common.seed);
    let json_config = serde_json::to_value(&config).context("cannot encode the suite's recipe")?;
    let generator = SuiteGenerator::new(common.seed, config)?;
    Ok(PartSpec {
        name: name.to_string(),
        truth_reliable: true,
        match_scan: lidar,
        what,
        count,
        options,
        success: if lidar {
            LIDAR_SUCCESS
        } else {
            SIMULATED_SUCCESS
        },
        peer_count: args.peer_pairs.unwrap_or(peer_default).min(count),
        peer_settings: if lidar {
            PeerSettings::lidar()
        } else {
            PeerSettings::indoor()
        },
        subset_spread: "every scene in turn",
        list_pairs: false,
        config: Some(json_config),
        make: Box::new(move |range: Range<usize>| {
            let pairs = generator.pairs(range)?;
            Ok(pairs
                .into_iter()
                .map(|p| Case {
                    index: p.index,
                    group: p.scene.name().to_string(),
                    label: p.scene.name().to_string(),
                    query_tilt_deg: Some(p.query_tilt_deg()),
                    overlap: Some(p.overlap),
                    reference: points(&p.reference_points),
                    query: points(&p.query_points),
                    reference_attitude: p.reference_attitude,
                    query_attitude: p.query_attitude,
                    truth: p.truth,
                })
                .collect())
        }),
    })
}

/// The KITTI pairs as a part.
fn kitti_spec<'a>(kitti: &'a Kitti, args: &SuiteArgs, common: &Common) -> PartSpec<'a> {
    let pairs = kitti.pairs();
    let limit = common.pairs.unwrap_or(if common.quick {
        QUICK_KITTI_PAIRS
    } else {
        pairs.len()
    });
    let count = limit.min(pairs.len());
    let (first, last) = (kitti.numbers[0], kitti.numbers[kitti.numbers.len() - 1]);
    let what = format!(
        "{count} pairs of real KITTI frames {first}–{last} from {} (Velodyne, moving car, scans \
         not de-skewed): frames i → i+1 (0.86 m) and i → i+2 (1.72 m) interleaved, no attitude, \
         no guess; truth: KITTI's GPS/INS poses through calib.txt's Tr (the data's README: the \
         first frames' truth may be off by up to 0.18 m a frame)",
        bench_peers::shown(&kitti.folder)
    );
    PartSpec {
        name: "kitti".into(),
        truth_reliable: false,
        match_scan: true,
        what,
        count,
        options: LocalizeOptions {
            window: SearchWindow::around(&Vec3::zeros(), KITTI_WINDOW_HALF_M),
            step_m: LIDAR_STEP_M,
            ..Default::default()
        },
        success: LIDAR_SUCCESS,
        peer_count: args.peer_pairs.unwrap_or(count).min(count),
        peer_settings: PeerSettings::lidar(),
        subset_spread: "i → i+1 and i → i+2 interleaved",
        list_pairs: true,
        config: None,
        make: Box::new(move |range: Range<usize>| {
            Ok(range
                .map(|index| {
                    let pair = pairs[index];
                    Case {
                        index,
                        group: format!("kitti i→i+{}", pair.query - pair.reference),
                        label: format!(
                            "frames {}→{}",
                            kitti.numbers[pair.reference], kitti.numbers[pair.query]
                        ),
                        reference: points(&kitti.frames[pair.reference]),
                        query: points(&kitti.frames[pair.query]),
                        reference_attitude: None,
                        query_attitude: None,
                        truth: kitti.truth(pair),
                        overlap: None,
                        query_tilt_deg: None,
                    }
                })
                .collect())
        }),
    }
}

fn points(v: &[Vec3]) -> Vec<Point3<f64>> {
    v.iter().map(|p| Point3::from(*p)).collect()
}

/// The simulated pairs' recipe in words.
fn describe(config: &SuiteConfig, count: usize, seed: u64) -> String {
    let scenes: Vec<&str> = config.scenes.iter().map(|s| s.name()).collect();
    let sensor = match &config.sensor {
        SuiteSensor::Tilting(s) => format!(
            "the tilting LRF ({}° × {}° steps, front half field of view, {} m, {} mm range noise)",
            s.tilt_step_deg,
            s.pan_step_deg,
            s.usable_range_m(),
            s.range_noise_m * 1e3
        ),
        SuiteSensor::Spinning(l) => format!(
            "a {} LiDAR ({} rings {}°..{}°, {}° azimuth step over {}°, {} m, {} mm range noise)",
            if l.azimuth_fov_deg >= 360.0 {
                "spinning"
            } else {
                "solid-state"
            },
            l.rings,
            l.elevation_min_deg,
            l.elevation_max_deg,
            l.azimuth_step_deg,
            l.azimuth_fov_deg,
            l.max_range_m,
            l.range_noise_m * 1e3
        ),
    };
    let readings = match config.readings {
        Readings::None => "no attitude on either scan".to_string(),
        Readings::Noisy {
            roll_pitch_sigma_deg,
            yaw_sigma_deg,
        } => format!(
            "each scan with an attitude reading off by N(0, {roll_pitch_sigma_deg}°) in roll and \
             pitch and N(0, {yaw_sigma_deg}°) in heading, that σ stated"
        ),
    };
    format!(
        "{count} seeded pairs (seed {seed}) in {} in turn, {sensor}: the query up to {} m from \
         the reference ({} m in height), its roll and pitch each within ±{}°, any heading; the \
         reference's roll and pitch within ±{}°, any heading; ≥ {:.0} % of the query's beams \
         seen by the reference; {readings}",
        scenes.join(", "),
        config.step_max_m,
        config.step_z_max_m,
        config.query_tilt_max_deg,
        config.reference_tilt_max_deg,
        config.min_overlap * 100.0
    )
}

/// Deletes the peers' temporary folder when dropped.
struct TempFolder(PathBuf);

impl Drop for TempFolder {
    fn drop(&mut self) {
        let _ = std::fs::remove_dir_all(&self.0);
    }
}

/// Localizes every pair of `spec` with sdem (writing the peers' subset to a temporary folder on
/// the way), then runs the peers on the subset.
fn run_part(
    mut spec: PartSpec<'_>,
    peers: &std::result::Result<Peers, String>,
    json: bool,
    say: &dyn Fn(&str),
) -> Result<PartReport> {
    let peer_count = match peers {
        Ok(_) => spec.peer_count,
        Err(_) => 0,
    };
    let temp = TempFolder(std::env::temp_dir().join(format!(
        "sdem-bench-{}-{}",
        spec.name,
        std::process::id()
    )));
    say(&format!("{}: {} pairs ...", spec.name, spec.count));
    let bar = crate::progress::bar(spec.count as u64, json, &format!("{}: pairs", spec.name));
    let mut records = Vec::with_capacity(spec.count);
    let mut start = 0;
    while start < spec.count {
        let end = (start + CHUNK).min(spec.count);
        let cases = (spec.make)(start..end)
            .with_context(|| format!("{}: cannot make pairs {start}..{end}", spec.name))?;
        for case in &cases {
            records.push(localize_case(
                case,
                &spec.options,
                spec.match_scan,
                spec.success,
            ));
            if case.index < peer_count {
                write_peer_pair(&temp.0, case)?;
            }
            bar.inc(1);
        }
        start = end;
    }
    bar.finish_and_clear();
    let peers_report = match peers {
        Err(reason) => PeersReport::absent(reason.clone()),
        Ok(_) if peer_count == 0 => PeersReport::absent("--peer-pairs 0".into()),
        Ok(peers) => run_peers(peers, &spec, &records[..peer_count], &temp.0, json, say),
    };
    let mut groups: Vec<String> = records.iter().map(|r| r.group.clone()).collect();
    groups.dedup();
    groups.sort();
    groups.dedup();
    let by_group = groups
        .iter()
        .map(|g| tally(g, records.iter().filter(|r| &r.group == g)))
        .collect();
    Ok(PartReport {
        part: spec.name.clone(),
        what: spec.what.clone(),
        available: true,
        reason: None,
        success_translation_m: spec.success.0,
        success_rotation_deg: spec.success.1,
        window: Some(spec.options.window),
        step_m: spec.options.step_m,
        truth_reliable: spec.truth_reliable,
        config: spec.config.take(),
        all: Some(tally("all", records.iter())),
        by_group,
        peers: Some(peers_report),
        list_pairs: spec.list_pairs,
        records,
    })
}

/// sdem on one pair through the root API: both scans built (side by side), then localized.
fn localize_case(
    case: &Case,
    options: &LocalizeOptions,
    match_scan: bool,
    success: (f64, f64),
) -> PairRecord {
    let start = Instant::now();
    let mut options = options.clone();
    let result = (|| -> sdem::Result<(Scan, Scan, sdem::Localization)> {
        let grid = if match_scan {
            SdemConfig::for_scan(&case.reference)
        } else {
            SdemConfig::default()
        };
        let (reference, query) = rayon::join(
            || Scan::with_grid(&case.reference, case.reference_attitude, &grid),
            || Scan::with_grid(&case.query, case.query_attitude, &grid),
        );
        let (reference, query) = (reference?, query?);
        if match_scan {
            options = LocalizeOptions {
                window: options.window,
                heading: options.heading,
                ..LocalizeOptions::for_scan(reference.sdem())
            };
        }
        let found = sdem::localize(&reference, &query, &options)?;
        Ok((reference, query, found))
    })();
    let time_ms = elapsed_ms(start);
    let mut record = PairRecord {
        index: case.index,
        group: case.group.clone(),
        label: case.label.clone(),
        truth_translation_m: case.truth.translation.vector.norm(),
        truth_rotation_deg: case.truth.rotation.angle().to_degrees(),
        query_tilt_deg: case.query_tilt_deg,
        overlap: case.overlap,
        time_ms,
        translation_error_m: None,
        rotation_error_deg: None,
        estimate: None,
        correct: false,
        trusted: false,
        doubts: Vec::new(),
        error: None,
        cost_at_estimate: None,
        cost_at_truth: None,
        seen_through_fraction: None,
    };
    match result {
        Ok((reference, query, found)) => {
            let cost = |pose: &sdem::Pose| {
                sdem::cost_at(&reference, &query, pose, &options.cost)
                    .ok()
                    .flatten()
                    .map(|c| c.cost)
            };
            record.cost_at_estimate = cost(&found.reference_from_query);
            record.cost_at_truth = cost(&case.truth);
            let (t, r) = pose_error(&case.truth, &found.reference_from_query);
            let r = r.to_degrees();
            record.translation_error_m = Some(t);
            record.rotation_error_deg = Some(r);
            record.estimate = Some(PoseRecord::from(&found.reference_from_query));
            record.correct = t <= success.0 && r <= success.1;
            record.trusted = found.trusted;
            record.doubts = found.doubts.iter().map(|d| d.kind()).collect();
            record.seen_through_fraction = Some(found.diagnostics.seen_through_fraction);
        }
        Err(e) => record.error = Some(e.to_string()),
    }
    record
}

/// What `records` came to, as `group`.
fn tally<'a>(group: &str, records: impl Iterator<Item = &'a PairRecord>) -> TallyReport {
    let records: Vec<&PairRecord> = records.collect();
    let count = |f: &dyn Fn(&PairRecord) -> bool| records.iter().filter(|r| f(r)).count();
    let mut doubt_kinds = BTreeMap::new();
    for kind in records.iter().flat_map(|r| r.doubts.iter()) {
        *doubt_kinds.entry(*kind).or_insert(0) += 1;
    }
    let pairs = records.len();
    let succeeded = count(&|r| r.correct);
    let trusted = count(&|r| r.trusted);
    TallyReport {
        group: group.to_string(),
        pairs,
        succeeded,
        success_rate: if pairs == 0 {
            0.0
        } else {
            succeeded as f64 / pairs as f64
        },
        trusted,
        flagged: pairs - trusted,
        errors: count(&|r| r.error.is_some()),
        wrong_trusted: count(&|r| r.trusted && !r.correct),
        wrong_flagged: count(&|r| !r.trusted && !r.correct),
        correct_flagged: count(&|r| !r.trusted && r.correct),
        wrong_favoured_by_scans: count(&|r| r.scans_favour_wrong()),
        translation_error_mm: summarize(
            &records
                .iter()
                .map(|r| r.translation_error_m.map_or(f64::NAN, |t| t * 1e3))
                .collect::<Vec<_>>(),
        ),
        rotation_error_deg: summarize(
            &records
                .iter()
                .map(|r| r.rotation_error_deg.unwrap_or(f64::NAN))
                .collect::<Vec<_>>(),
        ),
        time_ms: summarize(&records.iter().map(|r| r.time_ms).collect::<Vec<_>>()),
        doubt_kinds,
    }
}

/// Writes `case` for the peers: `DIR/pair_NNN/{reference.ply, query.ply, truth.txt}`.
fn write_peer_pair(temp: &Path, case: &Case) -> Result<()> {
    let dir = pair_folder(temp, case.index);
    std::fs::create_dir_all(&dir).with_context(|| format!("cannot create {}", dir.display()))?;
    let coords = |p: &[Point3<f64>]| p.iter().map(|p| p.coords).collect::<Vec<Vec3>>();
    bench_peers::write_cloud(&dir.join("reference.ply"), &coords(&case.reference))?;
    bench_peers::write_cloud(&dir.join("query.ply"), &coords(&case.query))?;
    bench_peers::write_transform(&dir.join("truth.txt"), &case.truth)
}

fn pair_folder(temp: &Path, index: usize) -> PathBuf {
    temp.join(format!("pair_{index:04}"))
}

impl PeersReport {
    fn absent(reason: String) -> Self {
        Self {
            available: false,
            reason: Some(reason),
            pairs: 0,
            subset: String::new(),
            settings: None,
            sdem_success_rate: None,
            sdem_time_ms: None,
            methods: Vec::new(),
            fastest_global: None,
            sdem_time_ratio_to_fastest_global: None,
            per_pair: Vec::new(),
        }
    }
}

/// The peers on the pairs of `subset` (the part's first pairs, written to `temp`).
fn run_peers(
    peers: &Peers,
    spec: &PartSpec<'_>,
    subset: &[PairRecord],
    temp: &Path,
    json: bool,
    say: &dyn Fn(&str),
) -> PeersReport {
    say(&format!(
        "{}: the peers on the first {} pairs ...",
        spec.name,
        subset.len()
    ));
    let bar = crate::progress::bar(subset.len() as u64, json, &format!("{}: peers", spec.name));
    let results: Vec<Vec<PeerResult>> = subset
        .iter()
        .map(|r| {
            let result = peers.run_pair(&pair_folder(temp, r.index), &spec.peer_settings);
            bar.inc(1);
            result
        })
        .collect();
    bar.finish_and_clear();
    let sdem_time = summarize(&subset.iter().map(|r| r.time_ms).collect::<Vec<_>>());
    let sdem_estimates: Vec<Option<Pose>> = subset
        .iter()
        .map(|r| r.estimate.as_ref().map(Pose::from))
        .collect();
    let methods = bench_peers::summarize_methods(
        &results,
        &sdem_estimates,
        spec.success.0,
        spec.success.1,
        sdem_time.median,
    );
    let fastest = methods
        .iter()
        .filter(|m| m.global && m.time_ms.count > 0 && m.ran == m.pairs)
        .min_by(|a, b| a.time_ms.median.total_cmp(&b.time_ms.median));
    PeersReport {
        available: true,
        reason: None,
        pairs: subset.len(),
        subset: format!(
            "pairs 0–{} of {} ({})",
            subset.len().saturating_sub(1),
            spec.count,
            spec.subset_spread
        ),
        settings: Some(spec.peer_settings),
        sdem_success_rate: Some(
            subset.iter().filter(|r| r.correct).count() as f64 / subset.len().max(1) as f64,
        ),
        sdem_time_ms: Some(sdem_time),
        fastest_global: fastest.map(|m| m.label.clone()),
        sdem_time_ratio_to_fastest_global: fastest.and_then(|m| m.sdem_time_ratio),
        methods,
        per_pair: results,
    }
}
