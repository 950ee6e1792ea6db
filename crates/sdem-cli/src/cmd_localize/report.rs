//! `sdem localize`'s report of one pair: what `--json` writes, and the text printed from it.

use crate::attitude_args::{attitude_assumption, AttitudeAssumption, AttitudeKind, Attitudes};
use crate::output::{doubts_json, estimate_label, pose_line};
use sdem::cost::CostModel;
use sdem::geometry::{pose_error, Pose, PoseRecord};
use sdem::localize::{
    Diagnostics, Localization, LocalizeOptions, RefineOutcome, RefinementSummary, SearchMode,
};
use serde::Serialize;
use serde_json::Value;

/// Where a pair's grid and search scale came from (`settings` in the JSON).
#[derive(Debug, Clone, Copy, PartialEq, Eq, Serialize)]
#[serde(rename_all = "snake_case")]
pub(crate) enum Settings {
    /// The tilting SICK's defaults (and `--step`, `--resolution`).
    Default,
    /// The grid the dataset's `sensor.toml` matches.
    Sensor,
    /// Derived from the reference scan, as `--match-scan` asks.
    Derived,
    /// Derived from the reference scan, a LiDAR's, without being asked.
    DerivedForLidar,
    /// The tilting SICK's defaults on cells matched to the reference scan's sampling (no
    /// sensor model, no LiDAR; [`sdem::SdemConfig::default_for_scan`]).
    MatchedGrid,
}

impl Settings {
    /// Whether the grid and the search's scale come from the reference scan.
    pub(crate) fn derived(self) -> bool {
        matches!(self, Self::Derived | Self::DerivedForLidar)
    }

    /// The words the text output uses.
    fn text(self) -> &'static str {
        match self {
            Self::Default => "the tilting SICK's defaults",
            Self::Sensor => "the sensor.toml's grid",
            Self::Derived => "derived from the reference scan",
            Self::DerivedForLidar => "derived from the reference scan, a LiDAR's",
            Self::MatchedGrid => "the tilting SICK's defaults, cells matched to the reference scan",
        }
    }
}

#[derive(Serialize)]
pub(super) struct Report {
    reference: usize,
    query: usize,
    reference_from_query: PoseRecord,
    /// What was assumed about the two scans' attitudes and how far the search went.
    attitude: AttitudeAssumption,
    heading_correction_deg: f64,
    cost: f64,
    rms_m: f64,
    overlap: usize,
    candidates_total: usize,
    candidates_evaluated: usize,
    nodes_bounded: usize,
    search: SearchMode,
    cost_model: CostModel,
    /// The S-DEM grid's cell size, degrees.
    resolution_deg: f64,
    /// Where the grid and the search's scale came from.
    settings: Settings,
    on_window_edge: bool,
    refined: RefineOutcome,
    refinement: RefinementSummary,
    diagnostics: Diagnostics,
    /// No doubt: the pose can be used as it is.
    trusted: bool,
    /// Every reason not to trust the pose: its `kind`, its figures and a `message`.
    doubts: Vec<Value>,
    time_ms: f64,
    #[serde(skip_serializing_if = "Option::is_none")]
    truth: Option<PoseRecord>,
    #[serde(skip_serializing_if = "Option::is_none")]
    error_m: Option<f64>,
    #[serde(skip_serializing_if = "Option::is_none")]
    error_deg: Option<f64>,
}

/// The report of one localization, with its errors against `truth` (`reference_from_query`)
/// when the dataset has it.
pub(super) fn make_report(
    (reference, query): (usize, usize),
    found: &Localization,
    attitudes: &Attitudes,
    (config, resolution_deg, settings): (&LocalizeOptions, f64, Settings),
    time_ms: f64,
    truth: Option<&Pose>,
) -> Report {
    let errors = truth.map(|t| pose_error(t, &found.reference_from_query));
    Report {
        reference,
        query,
        reference_from_query: PoseRecord::from(&found.reference_from_query),
        attitude: attitude_assumption(attitudes),
        heading_correction_deg: found.heading_correction.to_degrees(),
        cost: found.cost,
        rms_m: found.cost.sqrt(),
        overlap: found.overlap,
        candidates_total: found.candidates_total,
        candidates_evaluated: found.candidates_evaluated,
        nodes_bounded: found.nodes_bounded,
        search: config.mode,
        cost_model: config.cost.model,
        resolution_deg,
        settings,
        on_window_edge: found.on_window_edge,
        refined: found.refined,
        refinement: RefinementSummary::new(found.refined, found.refinement.as_ref()),
        diagnostics: found.diagnostics.clone(),
        trusted: found.trusted,
        doubts: doubts_json(&found.doubts),
        time_ms,
        truth: truth.map(PoseRecord::from),
        error_m: errors.map(|e| e.0),
        error_deg: errors.map(|e| e.1.to_degrees()),
    }
}

/// Prints `report` as text: the estimate, the attitude assumed, the fit and the search (the
/// doubts and the verdict follow, as for a relocalization).
pub(super) fn print_text(
    report: &Report,
    found: &Localization,
    truth: Option<&Pose>,
    config: &LocalizeOptions,
) {
    print_estimate(report, found, truth);
    println!("  attitude: {}", report.attitude.summary);
    print_fit(report, &found.diagnostics, config);
    print_search(report, config);
}

/// Prints the estimate, the truth and the error, and the heading correction and refinement.
fn print_estimate(report: &Report, found: &Localization, truth: Option<&Pose>) {
    println!(
        "scan {} in the frame of scan {}:",
        report.query, report.reference
    );
    println!(
        "  {}  {}",
        estimate_label(found.trusted),
        pose_line(&found.reference_from_query)
    );
    if let Some(t) = truth {
        println!("  truth     {}", pose_line(t));
    }
    if let (Some(e_m), Some(e_deg)) = (report.error_m, report.error_deg) {
        println!("  error     {:.2} cm, {:.3}°", e_m * 100.0, e_deg);
    }
    let how = match found.refined {
        sdem::localize::RefineOutcome::None => "not asked (the grid optimum)",
        sdem::localize::RefineOutcome::SixDof => "6-DoF",
        sdem::localize::RefineOutcome::Quadratic => {
            "by a quadratic fit of the grid's costs (the 6-DoF refinement failed)"
        }
        sdem::localize::RefineOutcome::Failed => "failed (the grid optimum)",
    };
    let refined = match (report.refinement.iterations, report.refinement.converged) {
        (Some(n), Some(true)) => format!("{how}, {n} iterations"),
        (Some(n), _) => format!("{how}, stopped at its limit of {n} iterations still moving"),
        _ => how.to_string(),
    };
    let to = match report.attitude.source {
        AttitudeKind::Unknown => None,
        AttitudeKind::AssumedLevel => Some("the headings assumed (--assume-level)"),
        AttitudeKind::Readings => Some("the compass"),
    };
    match to {
        None => println!("  refined: {refined}"),
        Some(to) => println!(
            "  heading correction {:+.2}° to {to}; refined: {refined}",
            report.heading_correction_deg
        ),
    }
}

/// Prints how well the scans fit: the cost and overlap, the runner-up, the weakest direction.
fn print_fit(report: &Report, d: &Diagnostics, config: &LocalizeOptions) {
    println!(
        "  cost {:.3e} m² (rms {:.2} cm) over {} cells ({:.0} % of the query, {:.0} % within \
         {} cm)",
        report.cost,
        report.rms_m * 100.0,
        report.overlap,
        d.overlap_fraction * 100.0,
        d.inlier_fraction * 100.0,
        config.cost.truncation_m * 100.0
    );
    let past_slopes = match d.runner_up_slopes_passed {
        0 => String::new(),
        1 => ", past one slope of the optimum".to_string(),
        n => format!(", past {n} slopes of the optimum"),
    };
    match (d.runner_up_cost, d.runner_up_cost_at_least) {
        (Some(r), _) => println!(
            "  runner-up outside {:.0} cm{past_slopes}: cost {:.3e} m² ({:.2}× the best)",
            config.peak_radius_m * 100.0,
            r,
            r / report.cost
        ),
        (None, Some(at_least)) => println!(
            "  no candidate outside {:.0} cm{past_slopes}, off the optimum's own slopes, costs \
             less than {:.3e} m² ({:.2}× the best)",
            config.peak_radius_m * 100.0,
            at_least,
            at_least / report.cost
        ),
        (None, None) => {}
    }
    // A failed refinement leaves no covariance to read σ from (NaN): say nothing then.
    let finite = |v: Option<f64>| v.filter(|v| v.is_finite());
    if let (Some(v), Some(w), Some(s)) = (
        d.weakest_direction,
        finite(d.weakest_sigma_m),
        finite(d.strongest_sigma_m),
    ) {
        println!(
            "  weakest direction ({:.2}, {:.2}, {:.2}): σ {:.2} mm (strongest {:.2} mm)",
            v[0],
            v[1],
            v[2],
            w * 1e3,
            s * 1e3
        );
    }
}

/// Prints the search's effort.
fn print_search(report: &Report, config: &LocalizeOptions) {
    println!(
        "  {} of {} candidates scored, {} boxes bounded, in {:.0} ms ({}, S-DEM cells {:.3}°, {})",
        report.candidates_evaluated,
        report.candidates_total,
        report.nodes_bounded,
        report.time_ms,
        match config.mode {
            SearchMode::Exhaustive => "exhaustive search",
            SearchMode::BranchAndBound => "exact branch-and-bound search",
            SearchMode::CoarseToFine => "coarse-to-fine search",
        },
        report.resolution_deg,
        report.settings.text()
    );
}
