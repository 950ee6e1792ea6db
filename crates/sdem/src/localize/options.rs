//! The options of a localization ([`LocalizeOptions`]): the search, its cost, the refinement
//! and the thresholds of the doubts, their defaults, those matched to a scan, and their checks.

use crate::cost::{CostConfig, CostModel};
use crate::error::{Error, Result};
use crate::refine::RefineConfig;
use crate::sdem::Sdem;
use crate::search::{HeadingWindow, SearchWindow};
use serde::{Deserialize, Serialize};

/// Which search runs over the window.
#[derive(Debug, Clone, Copy, PartialEq, Eq, Serialize, Deserialize)]
#[serde(rename_all = "snake_case")]
pub enum SearchMode {
    /// Every candidate of the grid (the paper's method; the oracle).
    Exhaustive,
    /// Exact branch-and-bound (projective cost only).
    BranchAndBound,
    /// A pyramid of coarser grids, keeping the best candidates at each level, then a descent to a
    /// local minimum on the full grid (a heuristic; any cost).
    CoarseToFine,
}

/// Everything a localization needs besides the two S-DEMs.
#[derive(Debug, Clone, PartialEq, Serialize, Deserialize)]
#[serde(default, deny_unknown_fields)]
pub struct LocalizeOptions {
    /// The candidate translations.
    pub window: SearchWindow,
    /// Grid step, metres (paper: 1 cm).
    pub step_m: f64,
    /// The candidate headings around the compass reading.
    pub heading: HeadingWindow,
    /// Which search.
    pub mode: SearchMode,
    /// The cost.
    pub cost: CostConfig,
    /// Refine the grid optimum: robust 6-DoF point-to-plane refinement ([`crate::refine`]),
    /// falling back to a quadratic fit of the grid costs around the optimum.
    pub refine: bool,
    /// Settings of the 6-DoF refinement.
    pub refinement: RefineConfig,
    /// Exhaustive search: the most candidates it scores. A larger grid is refused before any
    /// is scored ([`Error::TooManyCandidates`]); see [`MAX_EXHAUSTIVE_CANDIDATES`].
    pub max_exhaustive_candidates: usize,
    /// Coarse-to-fine: spacing of the coarsest level, metres (rounded down to step · 2^k).
    pub coarse_step_m: f64,
    /// Coarse-to-fine: candidates kept at each level.
    pub keep: usize,
    /// Search again outside the peak's neighbourhood for the runner-up cost: branch-and-bound
    /// goes on from what its first search set aside (a few per cent of its time); the other
    /// modes score the grid again, once more for each slope of the optimum passed over.
    pub runner_up: bool,
    /// The peak's neighbourhood: candidates whose translation lies within this of the optimum's,
    /// metres.
    pub peak_radius_m: f64,
    /// The match is `ambiguous` when the runner-up's cost is below this multiple of the best.
    pub ambiguous_cost_ratio: f64,
    /// … or when the weakest translational direction's standard deviation exceeds this multiple
    /// of the strongest's (the cost is flat along it, as in a featureless corridor).
    pub ambiguous_sigma_ratio: f64,
    /// … or when, half the peak radius from the optimum, the cost rises along some principal
    /// direction by less than this fraction of its rise along the steepest.
    pub ambiguous_rise_ratio: f64,
    /// … or when fewer than this fraction of the query's points found their reference point
    /// after refinement: too little in common to trust (the fault bench's wrong answers matched
    /// 14–21 %).
    pub min_trusted_inlier_fraction: f64,
    /// … or when fewer than this fraction of the refinement's matched points lie on surfaces
    /// facing along its least certain direction ([`Refinement::support`](crate::refine::Refinement::support)): nothing but normal
    /// noise fixes the position along it (a featureless pipe).
    pub min_trusted_support: f64,
}

impl Default for LocalizeOptions {
    fn default() -> Self {
        Self {
            window: SearchWindow::paper(),
            step_m: 0.01,
            heading: HeadingWindow::default(),
            mode: SearchMode::BranchAndBound,
            cost: CostConfig::default(),
            refine: true,
            refinement: RefineConfig::default(),
            max_exhaustive_candidates: MAX_EXHAUSTIVE_CANDIDATES,
            coarse_step_m: 0.08,
            keep: 8,
            runner_up: true,
            peak_radius_m: 0.1,
            ambiguous_cost_ratio: 1.1,
            ambiguous_sigma_ratio: 10.0,
            ambiguous_rise_ratio: 0.05,
            min_trusted_inlier_fraction: 0.25,
            min_trusted_support: MIN_TRUSTED_SUPPORT,
        }
    }
}

impl LocalizeOptions {
    /// The options matched to a scan's scale: the search's step and truncation, the compared
    /// points and the refinement derived from the S-DEM (`scan`, the reference or a typical scan
    /// of the sensor, built on [`crate::sdem::SdemConfig::for_scan`]'s grid), the rest as
    /// [`LocalizeOptions::default`]. Set the window and the heading window afterwards.
    ///
    /// `c` is the side of a cell at the median range of the scan's boundary points (0.5° at
    /// 9 m: 7.8 cm for a Velodyne HDL-64E on a street; 1° at 1–2.5 m: 1.3–4.4 cm for the tilting
    /// SICK in rubble):
    /// * **step** `2c`, within 2–25 cm: a candidate moves a typical point by about two cells,
    ///   the scan's own angular sampling; the heading step follows it
    ///   ([`HeadingWindow::step_deg`]). The exact search is exact at that step; the refinement
    ///   goes below it, and may move up to two steps (`refinement.max_translation_m`) and pair
    ///   points up to one step apart (`refinement.max_correspondence_m`);
    /// * **truncation** `τ` twice the step (at least 5 cm): a LiDAR's returns 10–40 m away scatter
    ///   by centimetres about their cells' planes, and with τ = 5 cm three quarters of a KITTI
    ///   pair's compared points were mismatches even at the truth;
    /// * the **peak's radius** two steps (the runner-up lies beyond the grid optimum's
    ///   neighbours), the **search cubes** from the step up;
    /// * the **refinement** on at most [`REFINE_POINTS`] evenly spread query points, converged at
    ///   0.1 mm or after 15 iterations.
    ///
    /// Measured on KITTI 00 (frames 0→1, 5→6, 10→11, 14→15, ±1 m, ±5°, ±30 cm of height, no
    /// guess; `cargo run --release -p sdem-cli --example lidar_pairs`): the same poses to a few
    /// millimetres as with every point refined, in 31–39 ms a pair (both S-DEMs included) on 2
    /// cores, against 1.0–2.1 s with the defaults (1 cm steps, τ = 5 cm, 1° cells); a step of
    /// `c` and τ = 3`c` gave the same poses in 1.6 times the time. On the simulated SICK pairs
    /// of `sdem bench` they are safe but coarser than the defaults (20 pairs: median 0.95 mm
    /// against 0.77 mm, largest 3.8 mm against 3.6 mm): the defaults stay the tilting SICK's.
    ///
    /// # Example
    /// ```
    /// use nalgebra::Point3;
    /// use sdem::sdem::Sdem;
    /// use sdem::{Attitude, LocalizeOptions, SdemConfig};
    /// // Walls 10 m around, seen by 32 lasers 1° apart.
    /// let points: Vec<Point3<f64>> = (0..32)
    ///     .flat_map(|laser| (0..1800).map(move |k| (laser, k)))
    ///     .map(|(laser, k)| {
    ///         let (el, az) = (((laser as f64) - 20.0).to_radians(), (k as f64 * 0.2).to_radians());
    ///         let r = 10.0 / el.cos();
    ///         Point3::new(r * el.cos() * az.cos(), r * el.cos() * az.sin(), r * el.sin())
    ///     })
    ///     .collect();
    /// let grid = SdemConfig::for_scan(&points);
    /// let coords: Vec<_> = points.iter().map(|p| p.coords).collect();
    /// let scan = Sdem::from_points(&coords, &Attitude::default(), &grid)?;
    /// let options = LocalizeOptions::for_scan(&scan);
    /// assert!((options.step_m - 0.25).abs() < 1e-9); // 1° at 10 m is 17 cm: 2c, capped
    /// assert_eq!(options.cost.truncation_m, 2.0 * options.step_m);
    /// # Ok::<(), sdem::Error>(())
    /// ```
    pub fn for_scan(scan: &Sdem) -> Self {
        let default = Self::default();
        let step = (2.0 * scan_footprint_m(scan)).clamp(MIN_STEP_M, MAX_STEP_M);
        let step = (step * 1000.0).round() / 1000.0;
        Self {
            step_m: step,
            cost: CostConfig {
                truncation_m: (2.0 * step).max(default.cost.truncation_m),
                search_voxel_m: default.cost.search_voxel_m.max(step),
                ..default.cost.clone()
            },
            refinement: RefineConfig {
                max_translation_m: default.refinement.max_translation_m.max(2.0 * step),
                max_correspondence_m: default.refinement.max_correspondence_m.max(step),
                max_points: REFINE_POINTS,
                converged_step: 1e-4,
                max_iterations: 15,
                ..default.refinement.clone()
            },
            peak_radius_m: default.peak_radius_m.max(2.0 * step),
            ..default
        }
    }
}

/// Default of [`LocalizeOptions::max_exhaustive_candidates`]: about a minute of the oracle on
/// 2 cores with the runner-up search, which scores the grid a second time (and once more for each
/// slope of the optimum it passes over, up to four). On a simulated pair
/// comparing 1,426 points (`sdem localize`), one pass scored 140,000–180,000 candidates a
/// second, and 2,895,165 candidates with the runner-up took 62 s on a machine busy with other
/// work; a pair comparing fewer points scores faster. The paper's window at 1 cm with the
/// compass trusted is 193,011 candidates; ±2 m by ±10 cm at 1 cm with ±10° of heading in 1°
/// steps, 71 million.
pub const MAX_EXHAUSTIVE_CANDIDATES: usize = 4_000_000;

/// Default of [`LocalizeOptions::min_trusted_support`].
pub const MIN_TRUSTED_SUPPORT: f64 = 0.01;

/// The smallest step [`LocalizeOptions::for_scan`] derives, metres (`sdem bench`'s, for the
/// tilting SICK in rubble).
pub const MIN_STEP_M: f64 = 0.02;

/// The largest step [`LocalizeOptions::for_scan`] derives, metres.
pub const MAX_STEP_M: f64 = 0.25;

/// At most this many query points are refined with [`LocalizeOptions::for_scan`]'s options while
/// the estimate moves by more than a millimetre an update, before every point is
/// ([`RefineConfig::max_points`]). On re-views of KITTI frames (`sdem bench --suite
/// real-geometry`) the sample alone left 3.6–4.4 mm of error (median), every point from the grid
/// optimum on 0.4–0.8 mm in 1.5–2 times the refinement's time, the sample then every point
/// 0.56–0.72 mm in about 1.15 times it; 1,000 points were too few to pair 200 (the refinement
/// failed).
pub const REFINE_POINTS: usize = 3000;

/// The side of a cell at the median range of a scan's boundary points, metres.
pub fn scan_footprint_m(scan: &Sdem) -> f64 {
    crate::sdem::median_range(scan.points()) * scan.grid().resolution()
}

impl LocalizeOptions {
    /// Rejects a configuration [`localize`](super::localize) cannot run: an invalid cost, refinement or heading
    /// window, branch-and-bound with a cost other than the projective one, or a step that is
    /// not a positive number. [`localize`](super::localize) checks it on every call; a caller that holds the
    /// options longer (a configuration file, the loop) can check them once up front.
    ///
    /// # Errors
    /// [`Error::Invalid`], naming the setting.
    pub fn validate(&self) -> Result<()> {
        validate(self)
    }
}

/// See [`LocalizeOptions::validate`].
fn validate(config: &LocalizeOptions) -> Result<()> {
    config.cost.validate()?;
    config.refinement.validate()?;
    config.heading.validate()?;
    if config.mode == SearchMode::BranchAndBound && config.cost.model != CostModel::Projective {
        return Err(Error::Invalid(
            "the branch-and-bound search needs the projective cost; use the exhaustive or \
             coarse-to-fine search with the virtual-S-DEM cost"
                .into(),
        ));
    }
    if !(config.step_m.is_finite() && config.step_m > 0.0) {
        return Err(Error::Invalid(format!(
            "search step (step_m) {} m must be a positive number",
            config.step_m
        )));
    }
    // The doubts' thresholds: a NaN or a ratio out of range would silence a doubt (a NaN
    // ambiguity ratio left a KITTI pair's runner-up unflagged, the pose trusted).
    let in_range = |name: &str, value: f64, lo: f64, hi: f64| {
        if (lo..=hi).contains(&value) {
            Ok(())
        } else if hi == f64::MAX {
            Err(Error::Invalid(format!(
                "{name} = {value} must be a finite number of at least {lo}"
            )))
        } else {
            Err(Error::Invalid(format!(
                "{name} = {value} must lie in {lo}..={hi}"
            )))
        }
    };
    in_range(
        "ambiguous_cost_ratio",
        config.ambiguous_cost_ratio,
        1.0,
        f64::MAX,
    )?;
    in_range(
        "ambiguous_sigma_ratio",
        config.ambiguous_sigma_ratio,
        1.0,
        f64::MAX,
    )?;
    in_range(
        "ambiguous_rise_ratio",
        config.ambiguous_rise_ratio,
        0.0,
        1.0,
    )?;
    in_range(
        "min_trusted_inlier_fraction",
        config.min_trusted_inlier_fraction,
        0.0,
        1.0,
    )?;
    in_range("min_trusted_support", config.min_trusted_support, 0.0, 1.0)?;
    in_range("peak_radius_m", config.peak_radius_m, 0.0, f64::MAX)?;
    if config.mode == SearchMode::CoarseToFine && config.keep == 0 {
        return Err(Error::Invalid(
            "keep = 0: the coarse-to-fine search keeps at least 1 candidate a level".into(),
        ));
    }
    if let Some(prior) = &config.cost.prior {
        // Every candidate lies many σ from the prediction: the two contradict each other, and
        // the search would only return the window's edge nearest the prediction.
        let (lo, hi) = (config.window.min, config.window.max);
        let outside = (0..3)
            .map(|a| {
                (lo[a] - prior.offset[a])
                    .max(prior.offset[a] - hi[a])
                    .max(0.0)
            })
            .map(|d| d * d)
            .sum::<f64>()
            .sqrt();
        if outside > PRIOR_OUTSIDE_SIGMAS * prior.sigma_m && outside > config.step_m {
            return Err(Error::Invalid(format!(
                "the prediction (prior) at ({:.3}, {:.3}, {:.3}) m lies {outside:.3} m outside \
                 the search window, more than {PRIOR_OUTSIDE_SIGMAS} of its σ ({} m): centre \
                 the window on it, or widen it",
                prior.offset[0], prior.offset[1], prior.offset[2], prior.sigma_m
            )));
        }
    }
    Ok(())
}

/// A prediction this many of its σ outside the search window contradicts it ([`validate`]).
const PRIOR_OUTSIDE_SIGMAS: f64 = 5.0;
