//! Localization when the attitude of one scan or both is unknown or uncertain: no gyro, a
//! robot lying on rubble beyond what its gyro was trusted for, a compass near steel, other
//! people's recordings.
//!
//! The paper levels every scan by its gyro and compass and searches only the position (and
//! here a few degrees of heading). Without a reading, three more angles are unknown; with a gyro
//! and no compass (readings whose headings' three σ cover a half turn), one. They are found in
//! two steps (a gyro's reading stands for the first), each of which keeps the exact search as
//! the judge:
//!
//! 1. **Level each scan by its own surfaces** ([`crate::level`]): floors and ceilings face
//!    along the vertical wherever the scan was taken, and walls stand across it, so the
//!    vertical is measured to a fraction of a degree in rooms, corridors, halls, ditches and
//!    streets. A reading with a σ is the prior for this measurement: the surfaces' vertical
//!    is looked for within three σ of it. After this only the heading and the position are
//!    left, as in the paper.
//! 2. **Heading hypotheses from surface orientations** ([`crate::level::heading_hypotheses`]):
//!    the orientations of walls do not depend on where the scans were taken, so correlating
//!    the two levelled extended Gaussian images over heading gives the few headings the scene
//!    allows (four in a rectangular room; often one where the clutter breaks the symmetry).
//!    Each is searched **exactly** over the caller's translation window and ±[`HYPOTHESIS_HEADING_DEG`]
//!    of heading (branch and bound, the same minimum as the exhaustive search over that
//!    window), later hypotheses only below the cost the best one found (they end as soon as
//!    nothing in their window can compete). The best comparison (eq. 1) wins; another heading
//!    comparing within the ambiguity ratio is the doubt [`crate::Doubt::AnotherRotation`].
//!
//! 3. **Levelled again by the points** (`Relevel`): two real scans levelled each by its own
//!    floor can be degrees apart. Where the 6-DoF refinement of the best hypothesis fails, it
//!    is rerun allowed to move further, its rotation levels the query, and the exact search
//!    runs again at that attitude. Where no hypothesis matches at all and a scan has no
//!    reading, tilt and heading are searched together near the two levels (`tilted`).
//!
//! What is exact is the search within each hypothesis's window. The hypotheses themselves
//! come from the surfaces and can miss: a result then has a poor cost and comes out with
//! doubts (`few_inliers`, `runner_up`, …), never as a trusted wrong pose. A scan that shows no
//! floor or ceiling cannot be levelled this way and goes to `tilted`'s search over tilt and
//! heading together.

mod tilted;

pub use tilted::{rotation_hypotheses, RotationHypothesis};

use crate::doubt::Doubt;
use crate::error::{Error, Result};
use crate::geometry::{wrap_pi, Attitude, Vec3};
pub use crate::level::MIN_ORIENTED_CELLS;
use crate::level::{
    heading_hypotheses, level_from_cells, oriented_cells, rotated, OrientedCell, LEVEL_TOLERANCE,
};
use crate::localize::{localize, localize_below, HeadingWindow, Localization, LocalizeOptions};
use crate::scan::input::Scan;
use crate::sdem::{Sdem, SdemConfig, SCAN_ELEVATION_MARGIN_DEG};
use crate::search::matched_heading_step;
use nalgebra::Rotation3;
use std::f64::consts::{FRAC_PI_2, PI};

/// The largest tilt from level a scan without an attitude reading may have, radians: roll and
/// pitch each within ±30° (a robot lying on rubble; hand-held and vehicle scanners are well
/// within it) tilt the sensor's z axis by up to 41.4°.
pub const MAX_UNKNOWN_TILT: f64 = 41.5 * PI / 180.0;

/// Which rotations `reference_level_from_query_level` may be: a tilt (the angle between the
/// two levelled frames' z axes) up to `max_tilt`, and a heading within `heading_half_range`
/// of zero (π: any heading). Radians.
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct RotationPrior {
    /// The largest tilt between the two levelled frames, radians.
    pub max_tilt: f64,
    /// The heading's half range around zero, radians (π: a full turn).
    pub heading_half_range: f64,
}

/// The rotations a pair of scans may differ by, from their attitude readings: a scan without
/// one may be tilted up to [`MAX_UNKNOWN_TILT`] and have any heading; readings allow three
/// standard deviations of their difference. `None` when both readings are good enough for the
/// levelled search alone (roll and pitch within `level_tolerance` at three σ).
pub fn rotation_prior(
    reference: Option<&Attitude>,
    query: Option<&Attitude>,
    level_tolerance: f64,
) -> Option<RotationPrior> {
    let tilt = |a: Option<&Attitude>| a.map_or(MAX_UNKNOWN_TILT, |a| 3.0 * a.sigma.roll_pitch);
    match (reference, query) {
        (Some(r), Some(q)) => {
            let tilt = 3.0 * r.sigma.roll_pitch.hypot(q.sigma.roll_pitch);
            (tilt > level_tolerance).then(|| RotationPrior {
                max_tilt: tilt,
                heading_half_range: (3.0 * r.sigma.yaw.hypot(q.sigma.yaw)).min(PI),
            })
        }
        _ => Some(RotationPrior {
            max_tilt: tilt(reference) + tilt(query),
            heading_half_range: PI,
        }),
    }
}

/// When no heading matches at the levels of two scans levelled by their surfaces, the rotation
/// is searched within this tilt of them, degrees.
const FALLBACK_TILT_DEG: f64 = 8.0;

/// At most this many heading hypotheses are searched.
const MAX_HEADINGS: usize = 6;
/// Each heading hypothesis is searched over ± this, degrees: the correlation's peaks lie
/// within ±0.5° of the truth on the scenes measured; the rest is the margin for a blunt peak
/// (an optimum on this window's edge is searched again centred on it). ±2° found the same 25
/// of 40 `unlevelled` pairs in 1.3–1.5 times the time.
pub const HYPOTHESIS_HEADING_DEG: f64 = 1.2;
/// Rotations searched only to be ranked or judged, not to give the pose, are searched on a grid
/// this coarse, metres (or the caller's step, if coarser): 4 cm is within the 5 cm truncation,
/// so the compared points that match still count as matching.
const SCREENING_STEP_M: f64 = 0.04;
/// Two rotations farther apart than this are different answers, for the doubts
/// [`Doubt::AnotherRotation`] and [`Doubt::UnrefutedRotation`].
const OTHER_ROTATION: f64 = 5.0 * PI / 180.0;

/// A scan as the global search sees it: its oriented cells (sensor frame) and the attitude
/// that levels it, when one is known.
struct Levelled {
    cells: Vec<OrientedCell>,
    /// The reading, or the vertical of the surfaces (with the reading's heading).
    attitude: Option<Attitude>,
    /// Whether the scan came with no attitude reading.
    unread: bool,
}

/// The attitude that levels `scan`: its reading when that is certain enough to level the
/// search alone; else the vertical of its surfaces, looked for within three σ of the reading
/// (within [`MAX_UNKNOWN_TILT`] of the sensor's z axis without one), keeping the reading's
/// heading; else the reading, or nothing.
fn levelled(scan: &Scan) -> Levelled {
    let reading = scan.attitude().copied();
    // The S-DEM is levelled by the reading (as level without one): its cells back in the
    // sensor frame.
    let sensor_from_sdem = reading.map_or_else(Rotation3::identity, |a| a.rotation().inverse());
    let cells = rotated(&oriented_cells(scan.sdem()), &sensor_from_sdem);
    if let Some(a) = reading {
        if 3.0 * a.sigma.roll_pitch <= LEVEL_TOLERANCE / 2.0 {
            return Levelled {
                cells,
                attitude: Some(a),
                unread: false,
            };
        }
    }
    let (expected_up, max_tilt) = match reading {
        Some(a) => (
            a.rotation().inverse() * Vec3::z(),
            (3.0 * a.sigma.roll_pitch).min(MAX_UNKNOWN_TILT),
        ),
        None => (Vec3::z(), MAX_UNKNOWN_TILT),
    };
    let from_surfaces = level_from_cells(&cells, &expected_up, max_tilt).map(|l| {
        let yaw = reading.map_or(0.0, |a| a.yaw);
        let yaw_sigma = reading.map_or(PI, |a| a.sigma.yaw);
        Attitude::new(l.attitude.roll, l.attitude.pitch, yaw)
            .with_sigma_deg(l.sigma.to_degrees(), yaw_sigma.to_degrees())
    });
    Levelled {
        cells,
        unread: reading.is_none(),
        attitude: from_surfaces.or(reading),
    }
}

/// Localizes `query` against `reference` when their rotation is not known well enough for the
/// levelled search (see the module's text).
///
/// # Errors
/// As [`crate::localize::localize`], and [`Error::NoSurfaces`] when neither the surfaces nor
/// the readings give a rotation to search.
pub fn localize_unlevelled(
    reference: &Scan,
    query: &Scan,
    options: &LocalizeOptions,
    prior: &RotationPrior,
) -> Result<Localization> {
    let start = std::time::Instant::now();
    let (r, q) = rayon::join(|| levelled(reference), || levelled(query));
    let levelled_by_surfaces = |l: &Levelled| {
        l.attitude
            .is_some_and(|a| a.sigma.roll_pitch <= LEVEL_TOLERANCE / 3.0)
    };
    let mut found = if levelled_by_surfaces(&r) && levelled_by_surfaces(&q) {
        let (ra, qa) = (r.attitude.expect("levelled"), q.attitude.expect("levelled"));
        let grid = grid_for_tilt(reference.sdem().config(), tilt_of(&ra).max(tilt_of(&qa)));
        match search_headings(
            reference, &r.cells, &ra, query, &q.cells, &qa, &grid, options, prior,
        ) {
            // No heading matched at the surfaces' levelling: the levels may be degrees apart
            // (a floor's σ says tenths), too far for any candidate to share enough cells. The
            // rotation is searched over tilt and heading together, within
            // [`FALLBACK_TILT_DEG`] of the two levels. Only where a scan has no reading: a
            // reading bounds its level to its σ. The loop's searches of places give the place
            // no reading where one of its nodes has none (a run without readings); there each
            // place that does not match pays for this search too (about 250 ms a pair on the
            // `unlevelled` suite).
            Err(e) if e.is_no_match() && (r.unread || q.unread) => {
                let near_levels = RotationPrior {
                    max_tilt: FALLBACK_TILT_DEG.to_radians().min(prior.max_tilt),
                    heading_half_range: prior.heading_half_range,
                };
                tilted::localize_tilted(
                    reference,
                    Some(&ra),
                    query,
                    Some(&qa),
                    options,
                    &near_levels,
                )
                .map_err(|_| e)?
            }
            other => other?,
        }
    } else {
        let residual = RotationPrior {
            max_tilt: match (r.attitude, q.attitude) {
                (Some(ra), Some(qa)) => 3.0 * ra.sigma.roll_pitch.hypot(qa.sigma.roll_pitch),
                _ => prior.max_tilt,
            }
            .min(prior.max_tilt),
            heading_half_range: prior.heading_half_range,
        };
        tilted::localize_tilted(
            reference,
            r.attitude.as_ref(),
            query,
            q.attitude.as_ref(),
            options,
            &residual,
        )?
    };
    found.time = start.elapsed();
    Ok(found)
}

/// The angle between a scan's z axis and the vertical under `attitude`, radians.
fn tilt_of(attitude: &Attitude) -> f64 {
    (attitude.rotation() * Vec3::z()).angle(&Vec3::z())
}

/// A grid that holds a scan's directions once it is levelled by a tilt of up to `tilt`
/// (radians). [`SdemConfig::for_scan`] measures a scan's band of elevations in its sensor's
/// frame and widens it by [`SCAN_ELEVATION_MARGIN_DEG`] for the tilt its attitude reading
/// brings; a scan levelled by its surfaces may be tilted far more (a spinning LiDAR tilted 30°
/// would lose most of its ground on one side and its rooftops on the other), so the band is
/// widened by the tilt beyond the margin. `config` itself where the margin covers it or the
/// band is the whole sphere already.
fn grid_for_tilt(config: &SdemConfig, tilt: f64) -> SdemConfig {
    let beyond = tilt.to_degrees() - SCAN_ELEVATION_MARGIN_DEG;
    if beyond <= 0.0 {
        return config.clone();
    }
    SdemConfig {
        elevation_min_deg: (config.elevation_min_deg - beyond).floor().max(-90.0),
        elevation_max_deg: (config.elevation_max_deg + beyond).ceil().min(90.0),
        ..config.clone()
    }
}

/// Both scans levelled: the heading hypotheses of their surfaces, each searched exactly over
/// the window and ±[`HYPOTHESIS_HEADING_DEG`], the best kept; a different heading within the
/// ambiguity ratio of its cost is a doubt.
#[allow(clippy::too_many_arguments)]
fn search_headings(
    reference: &Scan,
    reference_cells: &[OrientedCell],
    reference_level: &Attitude,
    query: &Scan,
    query_cells: &[OrientedCell],
    query_level: &Attitude,
    config: &SdemConfig,
    options: &LocalizeOptions,
    prior: &RotationPrior,
) -> Result<Localization> {
    let (reference_sdem, hypotheses) = rayon::join(
        || Sdem::from_points(reference.points_in_sensor(), reference_level, config),
        || {
            let r = rotated(reference_cells, &reference_level.rotation());
            let q = rotated(query_cells, &query_level.rotation());
            with_turned(
                heading_hypotheses(&r, &q, prior.heading_half_range, MAX_HEADINGS),
                prior.heading_half_range,
            )
        },
    );
    let reference_sdem = reference_sdem?;
    if hypotheses.is_empty() {
        return Err(Error::NoSurfaces { which: "query" });
    }
    let heading = HeadingWindow {
        half_range_deg: HYPOTHESIS_HEADING_DEG,
        step_deg: options.heading.step_deg,
    };
    let turned = |h: f64| {
        let a = Attitude::new(query_level.roll, query_level.pitch, query_level.yaw + h)
            .with_sigma_deg(
                query_level.sigma.roll_pitch.to_degrees(),
                HYPOTHESIS_HEADING_DEG / 3.0,
            );
        Sdem::from_points(query.points_in_sensor(), &a, config)
    };
    let full = LocalizeOptions {
        heading,
        ..options.clone()
    };
    // The hypotheses in the order of their correlation; the first searched in full, each later
    // one only for a cost below what could still win or rival the best.
    let screening = LocalizeOptions {
        refine: false,
        runner_up: false,
        ..full.clone()
    };
    let mut best: Option<(f64, Localization)> = None;
    // Every other hypothesis that found a match: its heading and what it found.
    let mut others: Vec<(f64, Localization)> = Vec::new();
    let mut first_error = None;
    for &(h, _) in &hypotheses {
        let query_sdem = match turned(h) {
            Ok(s) => s,
            Err(e) => {
                first_error.get_or_insert(e);
                continue;
            }
        };
        let outcome = match &best {
            None => localize(&reference_sdem, &query_sdem, &full).map(Some),
            Some((_, b)) => localize_below(
                &reference_sdem,
                &query_sdem,
                &screening,
                options.ambiguous_cost_ratio * b.cost,
            ),
        };
        match outcome {
            Ok(None) => {}
            Ok(Some(found)) => match best.take() {
                Some(b) if found.cost >= b.1.cost => {
                    others.push((h, found));
                    best = Some(b);
                }
                Some(b) => {
                    // Better than the best so far: searched in full, the old best a rival.
                    others.push(b);
                    let found = localize(&reference_sdem, &query_sdem, &full)?;
                    best = Some((h, found));
                }
                None => best = Some((h, found)),
            },
            Err(e) => {
                first_error.get_or_insert(e);
            }
        }
    }
    let Some((mut best_heading, mut found)) = best else {
        return Err(first_error.unwrap_or(Error::NoSurfaces { which: "query" }));
    };
    // A hypothesis's heading window is ours, not the caller's: an optimum on its edge means
    // the correlation's peak was blunt, so the search is centred on it and run again.
    let widest = turned(best_heading).map_or(f64::INFINITY, |q| {
        (heading
            .samples(matched_heading_step(&q, full.step_m))
            .into_iter())
        .fold(0.0f64, |m, h| m.max(h.abs()))
    });
    if found.grid_heading.abs() >= widest - 1e-9 {
        let centred = wrap_pi(best_heading + found.grid_heading);
        if let Ok(again) = turned(centred).and_then(|q| localize(&reference_sdem, &q, &full)) {
            if again.cost <= found.cost {
                others.push((best_heading, std::mem::replace(&mut found, again)));
                best_heading = centred;
            }
        }
    }
    // A hypothesis whose optimum the other scan saw through loses to one it did not see
    // through ([`crate::free_space`]; the same rule as a runner-up's in one search). Where none
    // does, the optimum's quarter and half turns are screened too: a hall or a ditch looks
    // alike turned so, and the surfaces' correlation may not have proposed the true one.
    let search_full = |h: f64| turned(h).and_then(|q| localize(&reference_sdem, &q, &full));
    let seen_through =
        found.diagnostics.seen_through_fraction >= crate::localize::SEEN_THROUGH_TO_RECHECK;
    let mut swapped = seen_through
        .then(|| not_seen_through(&found, &others, search_full))
        .flatten();
    if seen_through && swapped.is_none() {
        let found_heading = wrap_pi(best_heading + found.heading_correction);
        let cap = options.ambiguous_cost_ratio * found.cost;
        for turn in [FRAC_PI_2, -FRAC_PI_2, PI] {
            let h = wrap_pi(found_heading + turn);
            let near_one = (others.iter())
                .any(|(g, _)| wrap_pi(g - h).abs() <= 2.0 * HYPOTHESIS_HEADING_DEG.to_radians());
            if h.abs() > prior.heading_half_range || near_one {
                continue;
            }
            if let Ok(Some(f)) =
                turned(h).and_then(|q| localize_below(&reference_sdem, &q, &screening, cap))
            {
                others.push((h, f));
            }
        }
        swapped = not_seen_through(&found, &others, search_full);
    }
    if let Some((heading, again)) = swapped {
        others.push((best_heading, std::mem::replace(&mut found, again)));
        best_heading = heading;
    }
    // Rivals were searched at the surfaces' levelling: they are judged against the best cost
    // found there, not against the cost of a search levelled again by the points.
    let rival_base = found.cost;
    let relevel = Relevel {
        reference_sdem: &reference_sdem,
        reference_level,
        query_level,
        query,
        options: &full,
        prior,
    };
    // What the scans saw through still refutes the cheaper rotation after a re-levelling, whose
    // doubts are its own.
    let refuted = (found.doubts.iter())
        .find(|d| matches!(d, Doubt::SeenThrough { .. }))
        .cloned();
    if let Some((heading, again)) = relevel.run(&found) {
        others.push((best_heading, std::mem::replace(&mut found, again)));
        best_heading = heading;
        if let Some(doubt) = refuted {
            if !(found.doubts.iter()).any(|d| matches!(d, Doubt::SeenThrough { .. })) {
                found.doubts.push(doubt);
            }
        }
    }
    let found_heading = wrap_pi(best_heading + found.heading_correction);
    // A scanner that sees part of the way round, turned round, sees what the other did not:
    // the half turn is judged by what the scans show where they overlap ([`unrefuted`]). If no
    // hypothesis near it found a match (eq. 1 counts what only one scan sees as a mismatch, so
    // the cap above leaves it out), it is searched for the best match there is, on the
    // screening grid. Where either scan sees all round, turning the query round loses nothing
    // of what the two can share, and eq. (1) judged the half turn already.
    let half_turn = wrap_pi(found_heading + PI);
    let judged = (others.iter())
        .any(|(h, _)| wrap_pi(h - half_turn).abs() <= 2.0 * HYPOTHESIS_HEADING_DEG.to_radians());
    let partial_fields = || !sees_all_round(reference.sdem()) && !sees_all_round(query.sdem());
    if half_turn.abs() <= prior.heading_half_range && !judged && partial_fields() {
        let coarse = LocalizeOptions {
            step_m: screening.step_m.max(SCREENING_STEP_M),
            ..screening.clone()
        };
        let cap = options.cost.max_match_cost();
        if let Ok(Some(turned_found)) =
            turned(half_turn).and_then(|q| localize_below(&reference_sdem, &q, &coarse, cap))
        {
            others.push((half_turn, turned_found));
        }
    }
    let rivals: Vec<(f64, &Localization)> = others
        .iter()
        .map(|(h, f)| (wrap_pi(h + f.heading_correction - found_heading).abs(), f))
        .collect();
    let rival = (rivals.iter())
        .filter(|(angle, f)| {
            *angle > OTHER_ROTATION && f.cost < options.ambiguous_cost_ratio * rival_base
        })
        .min_by(|a, b| a.1.cost.total_cmp(&b.1.cost));
    if let Some(&(angle, f)) = rival {
        found.doubts.push(Doubt::AnotherRotation {
            angle_deg: angle.to_degrees(),
            cost: f.cost,
            best_cost: rival_base,
        });
    } else if let Some(doubt) = unrefuted(&found, rivals.iter().copied()) {
        found.doubts.push(doubt);
    }
    found.diagnostics.ambiguous |= found.doubts.iter().any(Doubt::is_ambiguity);
    found.trusted = found.doubts.is_empty();
    Ok(found)
}

/// Among the other hypotheses' optima (heading, match), the cheapest whose returns the other
/// scan saw through far less than `found`'s (seen through by
/// [`crate::localize::SEEN_THROUGH_TO_RECHECK`] or more: the caller's check), searched in full
/// by `search` at its heading, when the full search keeps the difference; with
/// [`Doubt::SeenThrough`] naming `found`.
fn not_seen_through(
    found: &Localization,
    others: &[(f64, Localization)],
    search: impl Fn(f64) -> Result<Localization>,
) -> Option<(f64, Localization)> {
    let better = |f: &Localization| {
        crate::localize::seen_through_less(
            f.diagnostics.seen_through_fraction,
            found.diagnostics.seen_through_fraction,
        )
    };
    let &(heading, _) = (others.iter())
        .filter(|(_, f)| better(f))
        .min_by(|a, b| a.1.cost.total_cmp(&b.1.cost))?;
    let mut again = search(heading).ok()?;
    if !better(&again) {
        return None;
    }
    crate::localize::prefer_to_seen_through(&mut again, found);
    Some((heading, again))
}

/// The refinement may move the pose this far from the grid's optimum, metres and degrees, when
/// it is run again to level the scans by the points ([`Relevel`]).
const RELEVEL_MAX_TRANSLATION_M: f64 = 0.5;
const RELEVEL_MAX_ROTATION_DEG: f64 = 10.0;
/// … and pair points this far apart, metres (half a degree of tilt is 26 cm at 30 m).
const RELEVEL_MAX_CORRESPONDENCE_M: f64 = 0.5;
/// The σ of roll and pitch of a query levelled by the points, degrees.
const RELEVEL_SIGMA_DEG: f64 = 0.1;

/// What [`Relevel::run`] needs: the reference levelled by its surfaces, the query's levelling
/// by its surfaces (the heading of none of the hypotheses), the options of the hypotheses' full
/// search and the rotation prior.
struct Relevel<'a> {
    reference_sdem: &'a Sdem,
    reference_level: &'a Attitude,
    query_level: &'a Attitude,
    query: &'a Scan,
    options: &'a LocalizeOptions,
    prior: &'a RotationPrior,
}

impl Relevel<'_> {
    /// The pose found again with the query levelled by the points, when the refinement of
    /// `found` failed. Two scans levelled each by its own surfaces can be degrees apart (real
    /// floors are seldom flat, and two views see different parts of them: 0.6–6.8° where this
    /// mended a re-view of a real scan), which at a scan's range moves the grid's optimum
    /// centimetres to decimetres; the refinement, which corrects the tilt, then moves further
    /// than it is trusted to move from the grid, or pairs too few points, and is refused. Here
    /// it is run again from the grid's optimum allowed to pair and move further
    /// ([`relaxed_refinement`]); its rotation levels the query, and the exact search runs
    /// again over the whole window at that attitude where eq. (1) at the refined pose beats
    /// the first answer's grid optimum. Taken when its own refinement stays within the usual
    /// bounds, its cost is no higher than the first answer's and its heading within the
    /// prior's. Returns the query's heading from `query_level` (as a hypothesis's heading is)
    /// and what the search found; its doubts are its own.
    fn run(&self, found: &Localization) -> Option<(f64, Localization)> {
        let options = self.options;
        if !options.refine || !refinement_failed(found) {
            return None;
        }
        let config = self.reference_sdem.config();
        let query_attitude = |f: &Localization| {
            let level_from_query = self.reference_level.rotation()
                * f.reference_from_query.rotation.to_rotation_matrix();
            Attitude::from_rotation(&level_from_query)
        };
        let at = |a: &Attitude| {
            let a = a.with_sigma_deg(RELEVEL_SIGMA_DEG, HYPOTHESIS_HEADING_DEG / 3.0);
            Sdem::from_points(self.query.points_in_sensor(), &a, config).ok()
        };
        // The grid's optimum again (a search of the steps around it), refined allowed further.
        let relaxed = LocalizeOptions {
            window: crate::search::SearchWindow::around(&found.grid_offset, [options.step_m; 3]),
            refinement: relaxed_refinement(&options.refinement),
            runner_up: false,
            ..options.clone()
        };
        let first = localize(self.reference_sdem, &at(&query_attitude(found))?, &relaxed).ok()?;
        first.refinement.as_ref()?;
        let levelled = query_attitude(&first);
        let query_sdem = at(&levelled)?;
        // The search runs again only where eq. (1) at the refined pose already beats the first
        // answer's grid optimum (on the `unlevelled` suite the refinement failed on 25 of 200
        // pairs, all wrong ones, most of them rotations the scans favour over the truth).
        let mut correlator =
            crate::cost::Correlator::new(self.reference_sdem, &query_sdem, &options.cost).ok()?;
        if correlator.evaluate(&first.offset, 0.0)?.cost >= found.cost {
            return None;
        }
        let again = localize(self.reference_sdem, &query_sdem, options).ok()?;
        let turned = levelled.rotation() * self.query_level.rotation().inverse();
        let heading = Attitude::from_rotation(&turned).yaw;
        let within_prior = wrap_pi(heading + again.heading_correction).abs()
            <= self.prior.heading_half_range + HYPOTHESIS_HEADING_DEG.to_radians();
        (!refinement_failed(&again) && again.cost <= found.cost && within_prior)
            .then_some((heading, again))
    }
}

/// `refinement` allowed to pair points and move as far as [`Relevel`] allows.
fn relaxed_refinement(refinement: &crate::refine::RefineConfig) -> crate::refine::RefineConfig {
    crate::refine::RefineConfig {
        max_translation_m: refinement.max_translation_m.max(RELEVEL_MAX_TRANSLATION_M),
        max_rotation_deg: refinement.max_rotation_deg.max(RELEVEL_MAX_ROTATION_DEG),
        max_correspondence_m: (refinement.max_correspondence_m).max(RELEVEL_MAX_CORRESPONDENCE_M),
        ..refinement.clone()
    }
}

/// Whether `found`'s refinement failed.
fn refinement_failed(found: &Localization) -> bool {
    (found.doubts.iter()).any(|d| matches!(d, Doubt::RefinementFailed { .. }))
}

/// Sectors of azimuth this wide, degrees, each holding a return, make a scan that sees all
/// round ([`sees_all_round`]): a spinning LiDAR does, a front-half or forward-looking scanner
/// leaves half or more of them empty.
const ROUND_SECTOR_DEG: f64 = 10.0;

/// Whether `scan` has a return in every [`ROUND_SECTOR_DEG`] sector of azimuth.
fn sees_all_round(scan: &Sdem) -> bool {
    let sectors = (360.0 / ROUND_SECTOR_DEG).round() as usize;
    let mut seen = vec![false; sectors];
    for &cell in scan.cells() {
        let (azimuth, _) = scan.grid().cell_center(cell as usize);
        let sector = (azimuth.to_degrees().rem_euclid(360.0) / ROUND_SECTOR_DEG) as usize;
        seen[sector.min(sectors - 1)] = true;
    }
    seen.into_iter().all(|s| s)
}

/// The share of the compared points that the match puts beyond the truncation: where the
/// scans overlap, how much they contradict it (1 where none compared).
fn mismatch(found: &Localization) -> f64 {
    (1.0 - found.diagnostics.shared_inlier_fraction()).max(0.0)
}

/// [`Doubt::UnrefutedRotation`] for the rival (each with its angle from `found`'s rotation,
/// radians) that overlaps most among those more than [`OTHER_ROTATION`] away that overlap less
/// than `found` and contradict no more of their compared points: eq. (1) ranked them lower
/// only for what the scans do not both see.
fn unrefuted<'a>(
    found: &Localization,
    rivals: impl Iterator<Item = (f64, &'a Localization)>,
) -> Option<Doubt> {
    let best_overlap = found.diagnostics.overlap_fraction;
    let best_mismatch = mismatch(found);
    rivals
        .filter(|(angle, f)| {
            *angle > OTHER_ROTATION
                && f.diagnostics.overlap_fraction < best_overlap
                && mismatch(f) <= best_mismatch
        })
        .max_by(|a, b| {
            (a.1.diagnostics.overlap_fraction).total_cmp(&b.1.diagnostics.overlap_fraction)
        })
        .map(|(angle, f)| Doubt::UnrefutedRotation {
            angle_deg: angle.to_degrees(),
            overlap_fraction: f.diagnostics.overlap_fraction,
            best_overlap_fraction: best_overlap,
        })
}

/// The hypotheses, and after them each one's half turn where the headings allow it and it is
/// not there already: a scanner that sees the front half of the sphere, turned round, sees the
/// other half of a room whose walls correlate best a half turn off.
fn with_turned(hypotheses: Vec<(f64, f64)>, half_range: f64) -> Vec<(f64, f64)> {
    let mut all = hypotheses.clone();
    for &(h, score) in hypotheses.iter().take(2) {
        let turned = wrap_pi(h + PI);
        if turned.abs() <= half_range
            && all
                .iter()
                .all(|(g, _)| wrap_pi(g - turned).abs() > 2.0 * HYPOTHESIS_HEADING_DEG.to_radians())
        {
            all.push((turned, score));
        }
    }
    all
}

#[cfg(test)]
mod tests {
    use super::*;

    /// A scan's band of elevations (a LiDAR's, measured in its own frame with a 5° margin) is
    /// widened by a levelled tilt beyond the margin, on both sides, to whole degrees and never
    /// past the poles; within the margin, or on the whole sphere, the grid is the same.
    #[test]
    fn a_lidar_band_is_widened_by_a_tilt_beyond_its_margin() {
        let band = SdemConfig {
            elevation_min_deg: -30.0,
            elevation_max_deg: 8.0,
            ..SdemConfig::default()
        };
        assert_eq!(grid_for_tilt(&band, 4f64.to_radians()), band);
        let widened = grid_for_tilt(&band, 20f64.to_radians());
        assert_eq!(
            (widened.elevation_min_deg, widened.elevation_max_deg),
            (-45.0, 23.0)
        );
        assert_eq!(widened.resolution_deg, band.resolution_deg);
        let far = grid_for_tilt(&band, 80f64.to_radians());
        assert_eq!(
            (far.elevation_min_deg, far.elevation_max_deg),
            (-90.0, 83.0)
        );
        let sphere = SdemConfig::default();
        assert_eq!(grid_for_tilt(&sphere, 40f64.to_radians()), sphere);
    }

    /// The tilt of an attitude is the angle its rotation turns the vertical by, whatever the
    /// heading.
    #[test]
    fn the_tilt_of_an_attitude_ignores_its_heading() {
        let level = Attitude::new(0.0, 0.0, 2.0);
        assert!(tilt_of(&level) < 1e-12);
        let rolled = Attitude::new(0.3, 0.0, 0.0);
        assert!((tilt_of(&rolled) - 0.3).abs() < 1e-12);
        let turned = Attitude::new(0.3, 0.0, 1.4);
        assert!((tilt_of(&turned) - 0.3).abs() < 1e-12);
    }
}
