//! `sdem localize`: one scan against another.

use crate::attitude_args::{attitude_sigma, attitudes_of, AttitudeFlags, Attitudes};
use crate::output::{
    elapsed_ms, estimate_label, pose_line, print_doubts, print_json, with_doubt_messages, Outcome,
};
use crate::parse::{
    fmt_number, heading_window_degrees, numbers, positive_count, positive_degrees, positive_metres,
    resolution_degrees, usage_error,
};
use anyhow::{bail, Context, Result};
use sdem::cost::{CostConfig, CostModel};
use sdem::geometry::{Attitude, AttitudeSigma};
use sdem::localize::{
    HeadingWindow, Localization, LocalizeOptions, OffsetPrior, SearchMode, SearchWindow,
};
use sdem::sdem::{Sdem, SdemConfig};
use sdem::search::{MAX_GRID_CANDIDATES, MAX_MATCHED_HEADING_STEP_DEG};
use sdem::slam::{is_lidar, Near};
use sdem::Scan;
use sdem_io::Dataset;
use std::path::PathBuf;
use std::time::Instant;

mod report;

use report::{make_report, print_text, Settings};

/// Arguments of `sdem localize`.
#[derive(clap::Args)]
pub struct Args {
    /// The dataset folder (scans/, optional attitude.csv, sensor.toml and poses_truth.txt).
    /// With attitude.csv the heading is searched over 3σ of the two readings' difference (σ
    /// from attitude.csv's σ columns, sensor.toml's attitude_sigma_*_deg, or 0.5° roll/pitch and
    /// 3.5° heading). Without it the attitude is unknown: roll, pitch and heading are searched
    /// (or give --assume-level). With --map: the scan file to relocalize (as --scan).
    #[arg(required_unless_present = "map")]
    dataset: Option<PathBuf>,
    /// Index of the reference scan (the map).
    #[arg(long, required_unless_present = "map")]
    reference: Option<usize>,
    /// Index of the scan to localize.
    #[arg(long, required_unless_present = "map")]
    query: Option<usize>,
    /// Relocalize a scan in a saved map instead: the folder `sdem slam` wrote (OUT or OUT/map).
    /// The search then uses the map's own settings (its config.toml). Without --near or
    /// --prior, the nodes whose places look most like the scan are searched over every heading
    /// (`sdem localize --map DIR SCAN`); the answer is the best match with no doubt, unless
    /// another place compares almost as well; else the scan is not found (exit status 1),
    /// with the candidates tried.
    #[arg(long, conflicts_with_all = ["reference", "query"])]
    map: Option<PathBuf>,
    /// With --map: the scan file to relocalize (any point-cloud format sdem reads); or give it
    /// as the first argument.
    #[arg(long, requires = "map", conflicts_with = "dataset")]
    scan: Option<PathBuf>,
    /// With --map: the gyro/compass reading of the scan, roll,pitch,yaw in degrees, held to
    /// attitude.csv's bounds (roll and pitch within ±360°, yaw within ±1e6°) [default: none:
    /// with --near or --prior the scan is taken as level and the heading searched within the
    /// map's heading_half_no_prior_deg (15°); without them the tilt and the heading are
    /// searched]. Without --near or --prior every heading is searched (the surfaces' heading
    /// hypotheses) whatever the reading says.
    #[arg(
        long,
        requires = "map",
        allow_hyphen_values = true,
        value_name = "R,P,Y",
        value_parser = parse_attitude
    )]
    attitude: Option<[f64; 3]>,
    /// How far the attitude readings can be off, standard deviations in degrees:
    /// ROLL_PITCH,YAW (e.g. 0.5,20 for a compass near steel). Overrides attitude.csv's and
    /// sensor.toml's σ for both scans (with --map: for --attitude). The heading is searched over
    /// 3σ of the two readings' difference; a match that tilts the scans beyond 3σ of roll and
    /// pitch is a doubt [default: attitude.csv's σ columns, else sensor.toml's
    /// attitude_sigma_roll_pitch_deg / attitude_sigma_yaw_deg, else 0.5,3.5].
    #[arg(long, allow_hyphen_values = true, value_name = "RP,YAW", value_parser = attitude_sigma)]
    attitude_sigma_deg: Option<AttitudeSigma>,
    /// Without attitude.csv: take both scans as level (roll = pitch = yaw = 0, with the σ of
    /// sensor.toml or --attitude-sigma-deg) instead of searching their attitude. For a scanner
    /// known to stand level; faster than the search, wrong when it is not level.
    #[arg(long, conflicts_with = "map")]
    assume_level: bool,
    /// With --map: where the scan was taken, roughly, x,y,z in metres in the map's frame, each
    /// within ±1e6 m [default: the nodes whose place descriptors look most like the scan's].
    #[arg(
        long,
        requires = "map",
        allow_hyphen_values = true,
        value_name = "X,Y,Z",
        value_parser = parse_near
    )]
    near: Option<[f64; 3]>,
    /// Candidate window: query origin minus reference origin on world axes, metres, as
    /// x0:x1,y0:y1,z0:z1 [default: the paper's -0.5:0.5,-0.3:0.6,-0.1:0.1].
    #[arg(long, allow_hyphen_values = true, value_parser = parse_window, conflicts_with = "map")]
    window: Option<SearchWindow>,
    /// A prediction of the offset (odometry), x,y,z,sigma in metres: weighed into the cost as one
    /// more point off by the truncation at one sigma, so it decides only what the scans leave
    /// open (the position along a featureless corridor). With --map: the predicted position in
    /// the map's frame; it centres the search as --near does, and along a direction the scan
    /// leaves free the position is the prediction's, as in `sdem slam`. Each coordinate within
    /// ±1e6 m [default: none].
    #[arg(
        long,
        allow_hyphen_values = true,
        conflicts_with = "near",
        value_name = "X,Y,Z,SIGMA",
        value_parser = parse_prior
    )]
    prior: Option<OffsetPrior>,
    /// Grid step of the search, metres, at most the window's longest side (with --map: the
    /// map's own) [default: 0.01; a LiDAR's derived from its scan].
    #[arg(
        long,
        allow_hyphen_values = true,
        conflicts_with = "map",
        value_parser = positive_metres
    )]
    step: Option<f64>,
    /// Score every candidate of the window (the paper's search; slow): at most 4,000,000
    /// candidates, about a minute on 2 cores (see --max-candidates). Same as `--search
    /// exhaustive`; another --search with it is refused.
    #[arg(long, conflicts_with = "map")]
    exhaustive: bool,
    /// With the exhaustive search: score up to this many candidates instead of 4,000,000 (the
    /// paper's window with the default heading window is 6–10 million: two minutes or more).
    #[arg(
        long,
        value_name = "N",
        allow_hyphen_values = true,
        conflicts_with = "map",
        value_parser = positive_count
    )]
    max_candidates: Option<usize>,
    /// Which search: exact branch-and-bound (projective cost), the exhaustive oracle (as
    /// --exhaustive), or the coarse-to-fine heuristic [default: branch-and-bound, or exhaustive
    /// with --exhaustive].
    #[arg(long, value_enum, conflicts_with = "map")]
    search: Option<Search>,
    /// Which form of the paper's eq. (1): query points looked up in the reference S-DEM
    /// (projective), or the paper's z-buffered virtual S-DEM (virtual; not with branch-and-bound).
    #[arg(long, value_enum, default_value_t = Cost::Projective, conflicts_with = "map")]
    cost: Cost,
    /// Override the heading window: search ± this many degrees around the two compass readings'
    /// difference, whatever their σ (0 trusts the compass; 180 is a full turn). Needs attitude
    /// readings (attitude.csv, or --assume-level) [default: 3σ of the readings' difference].
    #[arg(
        long,
        allow_hyphen_values = true,
        conflicts_with = "map",
        value_name = "DEG",
        value_parser = heading_window_degrees
    )]
    heading_window: Option<f64>,
    /// Heading step, degrees [default: matched to the scan's extent and --step].
    #[arg(long, allow_hyphen_values = true, value_parser = positive_degrees)]
    heading_step: Option<f64>,
    /// Skip the search for the runner-up outside the peak (a few per cent of the time with
    /// branch-and-bound; with --exhaustive it scores the grid again, once more for each slope of
    /// the optimum passed over); a distant place that scores almost as well then raises no
    /// `runner_up` doubt.
    #[arg(long)]
    no_runner_up: bool,
    /// The least share of the query's compared cells a candidate must share with the
    /// reference to count (`CostConfig::min_overlap_fraction`), from 0 to 1; at least 100 cells
    /// all the same. Lower it for scans that see little in common (a long step, a half-blocked
    /// scanner): a match that shares little still comes with its doubts [default: 0.2; with
    /// --map: the map's own].
    #[arg(
        long,
        value_name = "FRACTION",
        allow_hyphen_values = true,
        value_parser = overlap_fraction
    )]
    min_overlap: Option<f64>,
    /// S-DEM cell size, degrees [default: matched to the scanner's angular step in the
    /// dataset's sensor.toml, as `sdem slam` matches it; without one, to the reference scan's
    /// sampling, 0.5° at the finest] (with --map: the map's own).
    #[arg(
        long,
        allow_hyphen_values = true,
        conflicts_with = "map",
        value_parser = resolution_degrees
    )]
    resolution: Option<f64>,
    /// Derive the S-DEM grid from the reference scan and the search's step, truncation and
    /// refinement from its S-DEM (`SdemConfig::for_scan`, `LocalizeOptions::for_scan`) instead
    /// of the tilting SICK's defaults; --window, --heading-window and the other search flags
    /// still apply. Without it they are derived all the same for a spinning or solid-state
    /// LiDAR's scans (as `sdem slam` chooses them) when the dataset has no sensor.toml and
    /// neither --step nor --resolution is given.
    #[arg(long, conflicts_with_all = ["step", "resolution", "map"])]
    match_scan: bool,
    /// Take a result with doubts as the best guess: exit status 0 instead of 3. The output
    /// still labels it doubtful (`"trusted": false` with its doubts).
    #[arg(long)]
    accept_doubtful: bool,
    /// Print one JSON object instead of text.
    #[arg(long)]
    json: bool,
}

/// A clap value parser for `--min-overlap`: a share from 0 to 1.
fn overlap_fraction(text: &str) -> Result<f64, String> {
    crate::parse::number_in(
        text,
        0.0..=1.0,
        "a share of the compared cells from 0 to 1 (0.2: a fifth)",
    )
}

/// The `--search` values.
#[derive(Clone, Copy, clap::ValueEnum)]
enum Search {
    BranchAndBound,
    Exhaustive,
    CoarseToFine,
}

/// The `--cost` values.
#[derive(Clone, Copy, clap::ValueEnum)]
enum Cost {
    Projective,
    Virtual,
}

/// Parses `x0:x1,y0:y1,z0:z1`.
pub fn parse_window(text: &str) -> Result<SearchWindow, String> {
    let parts: Vec<&str> = text.split(',').collect();
    if parts.len() != 3 {
        return Err(format!(
            "expected three ranges x0:x1,y0:y1,z0:z1 in metres, got {} in '{text}'",
            parts.len()
        ));
    }
    let mut window = SearchWindow {
        min: [0.0; 3],
        max: [0.0; 3],
    };
    for (axis, part) in parts.iter().enumerate() {
        let name = ["x", "y", "z"][axis];
        let (lo, hi) = part
            .split_once(':')
            .ok_or_else(|| format!("range {name} '{part}' must be min:max"))?;
        let parse = |s: &str| {
            s.trim()
                .parse::<f64>()
                .ok()
                .filter(|v| v.is_finite())
                .ok_or_else(|| format!("range {name}: '{s}' is not a finite number of metres"))
        };
        window.min[axis] = parse(lo)?;
        window.max[axis] = parse(hi)?;
    }
    window.validate().map_err(|e| e.to_string())?;
    Ok(window)
}

/// The farthest `--prior` and `--near` may put a position on any axis, metres: 1,000 km from
/// the reference scan (or the map's origin) is beyond any map a robot makes, so a larger number
/// is a mistake (millimetres, a georeferenced coordinate), which the search would only answer
/// with "no candidate in the window matches".
const MAX_POSITION_M: f64 = 1e6;

/// Refuses a coordinate beyond ±[`MAX_POSITION_M`].
fn check_position(xyz: [f64; 3]) -> Result<[f64; 3], String> {
    match xyz.iter().find(|v| v.abs() > MAX_POSITION_M) {
        Some(v) => Err(format!(
            "{} m lies beyond ±{} m (1,000 km, farther than any map reaches): is it in \
             millimetres, or a georeferenced coordinate?",
            fmt_number(*v),
            fmt_number(MAX_POSITION_M)
        )),
        None => Ok(xyz),
    }
}

/// Parses `--prior x,y,z,sigma` (metres).
fn parse_prior(text: &str) -> Result<OffsetPrior, String> {
    let [x, y, z, sigma_m] = numbers(text, "x,y,z,sigma in metres")?;
    let prior = OffsetPrior {
        offset: check_position([x, y, z])?,
        sigma_m,
    };
    prior.validate().map_err(|e| e.to_string())?;
    Ok(prior)
}

/// The search's step without --step (a LiDAR's is derived from its scan), metres.
const DEFAULT_STEP_M: f64 = 0.01;

/// Parses `--near x,y,z` (metres).
fn parse_near(text: &str) -> Result<[f64; 3], String> {
    check_position(numbers(text, "x,y,z in metres")?)
}

/// Refuses (a usage error) a `--step` longer than every side of the search window (`window`,
/// or the paper's when `None`): the grid would hold the window's lowest corner alone. A window
/// that is a single point holds one candidate at any step.
fn check_step_fits_window(step: f64, window: Option<&SearchWindow>) -> Result<()> {
    let given = window.copied();
    let window = given.unwrap_or_else(SearchWindow::paper);
    let longest = (0..3)
        .map(|axis| window.max[axis] - window.min[axis])
        .fold(0.0, f64::max);
    if longest > 0.0 && step > longest * (1.0 + 1e-9) {
        // To the micrometre: 0.6 − (−0.3) is 0.8999999999999999.
        let longest = fmt_number((longest * 1e6).round() / 1e6);
        let which = match given {
            Some(_) => format!("--window {}", window_text(&window)),
            None => format!("the default --window {}, the paper's", window_text(&window)),
        };
        return Err(usage_error(
            "localize",
            format!(
                "--step {} m is longer than the search window's longest side, {longest} m \
                 ({which}): the grid would hold its lowest corner alone; give a --step of at \
                 most {longest} m, or a larger --window",
                fmt_number(step)
            ),
        ));
    }
    Ok(())
}

/// Refuses (a usage error, before any file is read) a search grid that the window and the step
/// alone make too large: an axis of more than [`sdem::search::MAX_AXIS_STEPS`] positions, more
/// candidates than any search takes ([`MAX_GRID_CANDIDATES`]), or, for the exhaustive search,
/// more than its limit (`--max-candidates`, or 4,000,000). The candidates are counted at the
/// fewest headings the flags allow: one, or those of `--heading-window` at `--heading-step` (at
/// the coarsest step matched to a scan, [`MAX_MATCHED_HEADING_STEP_DEG`], without it). The
/// search counts them again once the scans are read, and refuses the whole grid then.
fn check_grid_size(args: &Args, mode: SearchMode) -> Result<()> {
    let window = args.window.unwrap_or_else(SearchWindow::paper);
    let step = args.step.unwrap_or(DEFAULT_STEP_M);
    let [x, y, z] = window.positions(step).map_err(|e| {
        usage_error(
            "localize",
            format!(
                "--window {} at --step {} m: {e}",
                window_text(&window),
                fmt_number(step)
            ),
        )
    })?;
    let headings = match args.heading_window {
        Some(half_range_deg) => {
            let step_deg = args.heading_step.unwrap_or(MAX_MATCHED_HEADING_STEP_DEG);
            let heading = HeadingWindow {
                half_range_deg,
                step_deg: Some(step_deg),
            };
            heading.samples(step_deg.to_radians()).len()
        }
        None => 1,
    };
    let candidates = (x * y * z).saturating_mul(headings);
    let limit = match mode {
        SearchMode::Exhaustive => (args.max_candidates)
            .unwrap_or(LocalizeOptions::default().max_exhaustive_candidates)
            .min(MAX_GRID_CANDIDATES),
        _ => MAX_GRID_CANDIDATES,
    };
    if candidates > limit {
        let at_least = args.heading_window.is_none() || args.heading_step.is_none();
        return Err(too_many_candidates(
            (candidates, at_least),
            [x, y, z, headings],
            limit,
            mode,
        ));
    }
    Ok(())
}

/// The usage error of a search over more candidates than it takes: `candidates` (and whether
/// it is a lower bound, counted before the scans are read), the grid (positions along x, y and
/// z, and headings), the limit, and the flags that shrink it.
fn too_many_candidates(
    (candidates, at_least): (usize, bool),
    [x, y, z, headings]: [usize; 4],
    limit: usize,
    mode: SearchMode,
) -> anyhow::Error {
    let some = if at_least { "at least " } else { "" };
    let grid = match (at_least, headings) {
        // The headings are not known before the scans are read.
        (true, 1) => format!(
            "at least {candidates} candidates ({x} × {y} × {z} positions, each at every heading \
             searched)"
        ),
        _ => format!(
            "{some}{candidates} candidates ({x} × {y} × {z} positions × {some}{headings} \
             headings)"
        ),
    };
    let message = if mode == SearchMode::Exhaustive && limit < MAX_GRID_CANDIDATES {
        let raise = match at_least {
            true => format!("--max-candidates (to {candidates} or more; "),
            false => format!("--max-candidates {candidates} ("),
        };
        format!(
            "the exhaustive search (--exhaustive, --search exhaustive) would score {grid}, more \
             than its limit of {limit}: give a smaller --window, a coarser --step or a narrower \
             --heading-window, raise the limit with {raise}about 15 s a million candidates on 2 \
             cores), or leave the search to the default branch-and-bound, which finds the same \
             minimum"
        )
    } else {
        format!(
            "the search grid would hold {grid}, more than the {limit} any search takes: give a \
             smaller --window, a coarser --step or a narrower --heading-window"
        )
    };
    usage_error("localize", message)
}

/// A window as `--window` takes it: `x0:x1,y0:y1,z0:z1`.
fn window_text(window: &SearchWindow) -> String {
    (0..3)
        .map(|axis| {
            let (lo, hi) = (window.min[axis], window.max[axis]);
            format!("{}:{}", fmt_number(lo), fmt_number(hi))
        })
        .collect::<Vec<_>>()
        .join(",")
}

/// Parses `--attitude roll,pitch,yaw` (degrees), held to the bounds of an attitude.csv reading
/// ([`sdem_io::attitude_reading_problem`]).
fn parse_attitude(text: &str) -> Result<[f64; 3], String> {
    let [roll, pitch, yaw] = numbers(text, "roll,pitch,yaw in degrees")?;
    match sdem_io::attitude_reading_problem(roll, pitch, yaw) {
        Some(why) => Err(why),
        None => Ok([roll, pitch, yaw]),
    }
}

/// `sdem localize --map DIR --scan FILE`: relocalizes a scan in a saved map.
fn run_map(args: &Args, map: &std::path::Path) -> Result<Outcome> {
    // The flags first, then the files.
    let sigma = args.attitude_sigma_deg;
    let attitude = match args.attitude {
        Some([r, p, y]) => {
            let reading = Attitude::from_degrees(r, p, y);
            Some(Attitude {
                sigma: sigma.unwrap_or(reading.sigma),
                ..reading
            })
        }
        None if sigma.is_some() => {
            return Err(usage_error(
                "localize",
                "--attitude-sigma-deg describes the --attitude reading; give --attitude R,P,Y too",
            ));
        }
        None => None,
    };
    let near = match (args.near, args.prior) {
        (Some(position), _) => Some(Near {
            position: sdem::geometry::Vec3::from(position),
            sigma_m: None,
        }),
        (None, Some(prior)) => Some(Near {
            position: sdem::geometry::Vec3::from(prior.offset),
            sigma_m: Some(prior.sigma_m),
        }),
        (None, None) => None,
    };
    let folder = sdem_io::saved_map_folder(map);
    let Some(scan) = args.scan.as_ref().or(args.dataset.as_ref()) else {
        return Err(usage_error(
            "localize",
            "--map needs the scan to relocalize: --map DIR SCAN (or --scan SCAN)",
        ));
    };
    let mut saved = crate::output::load_saved_map(&folder)?;
    let points = sdem_io::read_points(scan)?;
    // The map's own search settings (its config.toml), not this command's --step; the least
    // overlap may be lowered (or raised) for this scan.
    if let Some(fraction) = args.min_overlap {
        saved.config.localize.cost.min_overlap_fraction = fraction;
    }
    let found = saved.relocalize(&points, attitude, near, None);
    let found = match found {
        Err(sdem::Error::NotFound { tried }) => bail!(
            "{} is not found in the map {}: no place matches it with confidence; tried {}",
            scan.display(),
            folder.display(),
            tried_words(&tried)
        ),
        other => {
            other.with_context(|| format!("{} in the map {}", scan.display(), folder.display()))?
        }
    };
    let outcome = Outcome::of(found.trusted, args.accept_doubtful);
    if args.json {
        let value = serde_json::to_value(&found).context("cannot encode the result as JSON")?;
        print_json(&with_doubt_messages(value, &found.doubts))?;
        return Ok(outcome);
    }
    let pose = found.world_from_sensor;
    println!("{} in the map {}:", scan.display(), folder.display());
    println!("  {}  {}", estimate_label(found.trusted), pose_line(&pose));
    let refined = (found.diagnostics.refined_inlier_fraction).map_or(String::new(), |f| {
        format!(", {:.0} % at the refined pose", f * 100.0)
    });
    println!(
        "  matched node {} (cost {:.3e} m², {:.0} % of the cells within the truncation{refined}) \
         in {:.0} ms",
        found.node_id,
        found.cost,
        found.diagnostics.inlier_fraction * 100.0,
        found.time.as_secs_f64() * 1e3
    );
    if found.segment != 0 {
        println!(
            "  in map segment {}, whose place in the world is not known: the pose is in its frame",
            found.segment
        );
    }
    for (node, why) in &found.tried {
        println!("  node {node} did not match: {why}");
    }
    print_doubts("  ", &found.doubts);
    print_accepted(found.trusted, args.accept_doubtful);
    Ok(outcome)
}

/// The candidates a relocalization tried, in words: `node N (why); …`, each node once (its
/// first search; a place is searched again wider, or over a full turn), with the count of
/// searches when there were more.
fn tried_words(tried: &[(usize, String)]) -> String {
    if tried.is_empty() {
        return "no node (none shares enough of the scan's place)".to_string();
    }
    let mut seen = std::collections::HashSet::new();
    let mut words: Vec<String> = (tried.iter())
        .filter(|(node, _)| seen.insert(*node))
        .map(|(node, why)| format!("node {node} ({why})"))
        .collect();
    if tried.len() > words.len() {
        words.push(format!(
            "{} searches in all, some nodes' places again wider",
            tried.len()
        ));
    }
    words.join("; ")
}

/// Says that a doubtful result was taken as the best guess, when `--accept-doubtful` asked.
fn print_accepted(trusted: bool, accept_doubtful: bool) {
    if !trusted && accept_doubtful {
        println!("  taken as the best guess (--accept-doubtful)");
    }
}

/// Runs `sdem localize`: done, or done with doubts (exit status 3) when the result is not
/// trusted and `--accept-doubtful` was not given.
pub fn run(args: Args) -> Result<Outcome> {
    if let Some(map) = args.map.clone() {
        return run_map(&args, &map);
    }
    // clap's `requires = "map"` is not enforced beside the positional DATASET: checked here.
    for (given, flag) in [
        (args.near.is_some(), "--near"),
        (args.attitude.is_some(), "--attitude"),
        (args.scan.is_some(), "--scan"),
    ] {
        if given {
            return Err(usage_error(
                "localize",
                format!(
                    "{flag} is for relocalizing a scan in a saved map (--map DIR SCAN); a pair \
                     of a dataset's scans takes its readings from attitude.csv and its window \
                     from --window or --prior"
                ),
            ));
        }
    }
    let (Some(dataset_path), Some(reference_index), Some(query_index)) =
        (args.dataset.clone(), args.reference, args.query)
    else {
        bail!("give DATASET --reference I --query J, or --map DIR SCAN");
    };
    let search = search_of(&args)?;
    // Checked before anything is read, at the default step unless --step is given (a LiDAR's
    // derived step is coarser, so its grid is smaller); --match-scan's step comes from the scan.
    if !args.match_scan {
        check_step_fits_window(args.step.unwrap_or(DEFAULT_STEP_M), args.window.as_ref())?;
        check_grid_size(&args, search.0)?;
    }
    let dataset = Dataset::open(&dataset_path)?;
    for (flag, index) in [("--reference", reference_index), ("--query", query_index)] {
        if index >= dataset.len() {
            bail!(
                "{flag} {index} is out of range: {} has {}",
                dataset_path.display(),
                sdem_io::scans_numbered(dataset.len())
            );
        }
    }
    // The settings: derived from the reference scan with --match-scan, or for a LiDAR's scans
    // when no sensor model, step or resolution says otherwise (as `sdem slam` chooses them);
    // else the sensor model's grid, a resolution given, or the tilting SICK's defaults on a grid
    // matched to the reference scan (with --step too). The reference scan is read once here
    // when its points decide the settings.
    let unasked_grid = args.resolution.is_none() && dataset.sensor.is_none();
    let unasked = unasked_grid && args.step.is_none();
    let reference_points = if args.match_scan || unasked_grid {
        Some(dataset.load_scan(reference_index)?)
    } else {
        None
    };
    let settings = match &reference_points {
        _ if args.match_scan => Settings::Derived,
        Some(points) if unasked && is_lidar(points) => Settings::DerivedForLidar,
        _ if dataset.sensor.is_some() => Settings::Sensor,
        Some(_) => Settings::MatchedGrid,
        None => Settings::Default,
    };
    let (sdem_config, config) =
        if let (true, Some(points)) = (settings.derived(), &reference_points) {
            let attitude = dataset
                .attitude_or_level(reference_index)
                .unwrap_or_default();
            let grid = SdemConfig::for_scan(points);
            let matched = LocalizeOptions::for_scan(&Sdem::from_points(points, &attitude, &grid)?);
            let step = matched.step_m;
            (grid, localize_config(&args, search, matched, step))
        } else {
            // The grid `sdem slam` builds for this dataset: a scanner sampling finer than 1° (a
            // nodding SICK at 0.5°) leaves most of a 1° cell's returns unused, and its map's pairs
            // come out differently on the coarser grid. Without a sensor model, the grid matched
            // to the reference scan's sampling (as `sdem slam` matches it to the first scan's).
            let matched = match (&dataset.sensor, &reference_points) {
                (Some(sensor), _) => Some(sensor.matched_sdem_resolution_deg()),
                (None, Some(points)) => Some(SdemConfig::default_for_scan(points).resolution_deg),
                (None, None) => None,
            };
            let grid = SdemConfig {
                resolution_deg: args.resolution.or(matched).unwrap_or(1.0),
                ..Default::default()
            };
            (
                grid,
                localize_config(
                    &args,
                    search,
                    LocalizeOptions::default(),
                    args.step.unwrap_or(DEFAULT_STEP_M),
                ),
            )
        };
    let pair = (reference_index, query_index);
    let attitudes = attitudes_of(&dataset, &dataset_path, pair, &attitude_flags(&args))?;
    let (found, time_ms) = localize_scans(
        &dataset,
        pair,
        reference_points,
        &attitudes,
        (&sdem_config, &config),
    )?;
    let truth = dataset
        .truth
        .as_ref()
        .map(|t| t[reference_index].inverse() * t[query_index]);
    let report = make_report(
        pair,
        &found,
        &attitudes,
        (&config, sdem_config.resolution_deg, settings),
        time_ms,
        truth.as_ref(),
    );
    let outcome = Outcome::of(found.trusted, args.accept_doubtful);
    if args.json {
        print_json(&report)?;
        return Ok(outcome);
    }
    print_text(&report, &found, truth.as_ref(), &config);
    print_doubts("  ", &found.doubts);
    print_accepted(found.trusted, args.accept_doubtful);
    Ok(outcome)
}

/// The search and its cost from the flags, checked (a usage error when they do not fit
/// together), before anything is read.
fn search_of(args: &Args) -> Result<(SearchMode, CostModel)> {
    let mode = match (args.exhaustive, args.search) {
        (true, Some(other @ (Search::BranchAndBound | Search::CoarseToFine))) => {
            // The exhaustive search would run and --search go unheeded.
            let name = clap::ValueEnum::to_possible_value(&other)
                .map(|v| v.get_name().to_string())
                .unwrap_or_default();
            return Err(usage_error(
                "localize",
                format!(
                    "--exhaustive and --search {name} ask for two different searches \
                     (--exhaustive is --search exhaustive); give one of them"
                ),
            ));
        }
        (true, _) | (_, Some(Search::Exhaustive)) => SearchMode::Exhaustive,
        (false, None | Some(Search::BranchAndBound)) => SearchMode::BranchAndBound,
        (false, Some(Search::CoarseToFine)) => SearchMode::CoarseToFine,
    };
    let model = match args.cost {
        Cost::Projective => CostModel::Projective,
        Cost::Virtual => CostModel::VirtualSdem,
    };
    if args.max_candidates.is_some() && mode != SearchMode::Exhaustive {
        return Err(usage_error(
            "localize",
            "--max-candidates limits the exhaustive search; give --exhaustive (or --search \
             exhaustive) with it, or leave it out",
        ));
    }
    if mode == SearchMode::BranchAndBound && model == CostModel::VirtualSdem {
        return Err(usage_error(
            "localize",
            "--cost virtual needs --search exhaustive or --search coarse-to-fine; the exact \
             branch-and-bound search bounds the projective cost only",
        ));
    }
    Ok((mode, model))
}

/// The search's settings from the arguments, with the checked search and cost of
/// [`search_of`], over `base` (the defaults, or the ones matched to the scan) with grid step
/// `step`.
fn localize_config(
    args: &Args,
    (mode, model): (SearchMode, CostModel),
    base: LocalizeOptions,
    step: f64,
) -> LocalizeOptions {
    LocalizeOptions {
        window: args.window.unwrap_or_else(SearchWindow::paper),
        step_m: step,
        // Without --heading-window, sdem::localize sets the range from the readings' σ (or
        // searches the whole rotation); the step is ours.
        heading: HeadingWindow {
            half_range_deg: args
                .heading_window
                .unwrap_or(HeadingWindow::default().half_range_deg),
            step_deg: args.heading_step,
        },
        mode,
        cost: CostConfig {
            model,
            prior: args.prior,
            min_overlap_fraction: (args.min_overlap).unwrap_or(base.cost.min_overlap_fraction),
            ..base.cost.clone()
        },
        runner_up: !args.no_runner_up,
        max_exhaustive_candidates: (args.max_candidates).unwrap_or(base.max_exhaustive_candidates),
        ..base
    }
}

/// The attitude flags.
fn attitude_flags(args: &Args) -> AttitudeFlags {
    AttitudeFlags {
        sigma: args.attitude_sigma_deg,
        assume_level: args.assume_level,
        heading_window_deg: args.heading_window,
    }
}

/// Reads scan `index` of the dataset: its points in the sensor frame.
fn load_points(dataset: &Dataset, index: usize) -> Result<Vec<nalgebra::Point3<f64>>> {
    Ok(dataset
        .load_scan(index)?
        .into_iter()
        .map(nalgebra::Point3::from)
        .collect())
}

/// Scan `index` of the dataset as a [`Scan`] with its attitude (checked: finite points and
/// attitude, enough points in the S-DEM; a scan that fills no cell is refused saying why, as
/// `localize --map` refuses it).
fn make_scan(
    dataset: &Dataset,
    index: usize,
    points: &[nalgebra::Point3<f64>],
    attitude: Option<Attitude>,
    sdem_config: &SdemConfig,
) -> Result<Scan> {
    let path = &dataset.scan_paths[index];
    Scan::with_grid(points, attitude, sdem_config)
        .with_context(|| format!("scan {index} ({})", path.display()))
}

/// Localizes scan `query` of the dataset against scan `reference` with `attitudes`; returns the
/// result and the time it took (building the two S-DEMs and the search), milliseconds.
///
/// With `--heading-window` the S-DEM-level search runs with that heading range (what
/// `sdem::localize` runs with 3σ of the readings' difference); otherwise `sdem::localize`,
/// which searches the heading over the readings' σ, or the whole rotation when the attitude is
/// unknown.
fn localize_scans(
    dataset: &Dataset,
    (reference_index, query_index): (usize, usize),
    reference_points: Option<Vec<sdem::geometry::Vec3>>,
    attitudes: &Attitudes,
    (sdem_config, config): (&SdemConfig, &LocalizeOptions),
) -> Result<(Localization, f64)> {
    let reference_points = match reference_points {
        Some(points) => points.into_iter().map(nalgebra::Point3::from).collect(),
        None => load_points(dataset, reference_index)?,
    };
    let query_points = load_points(dataset, query_index)?;
    let start = Instant::now();
    // The two S-DEMs side by side, as `sdem bench` builds a pair's.
    let (reference, query) = rayon::join(
        || {
            let attitude = attitudes.reference;
            make_scan(
                dataset,
                reference_index,
                &reference_points,
                attitude,
                sdem_config,
            )
        },
        || {
            make_scan(
                dataset,
                query_index,
                &query_points,
                attitudes.query,
                sdem_config,
            )
        },
    );
    let (reference, query) = (reference?, query?);
    let found = match attitudes.heading_window_deg {
        Some(_) => sdem::localize::localize(reference.sdem(), query.sdem(), config),
        None => sdem::localize(&reference, &query, config),
    };
    let found = match found {
        Err(sdem::Error::TooManyCandidates {
            candidates,
            grid,
            limit,
        }) => {
            return Err(too_many_candidates(
                (candidates, false),
                grid,
                limit,
                SearchMode::Exhaustive,
            ))
        }
        other => {
            other.with_context(|| format!("scan {query_index} against scan {reference_index}"))?
        }
    };
    Ok((found, elapsed_ms(start)))
}
