//! The rotation between two scans when one of them cannot be levelled from its own surfaces
//! (no floor or ceiling in view) and has no reliable attitude reading, or when no heading
//! matches at the levels the surfaces gave (searched then within a few degrees of them).
//!
//! The orientations of the surfaces a scan sees do not depend on where it was taken: a wall faces
//! its way from any origin. Each scan's surface normals, weighted by the area they stand for,
//! form an *extended Gaussian image* (Horn 1984); the rotation that best lays the query's image
//! on the reference's is the rotation between the scans, up to the symmetries of the scene.
//! Makadia, Patterson & Daniilidis (CVPR 2006) correlate such images over all of SO(3) with
//! spherical harmonics; here the rotations a robot can have (a tilt within a bound, any heading)
//! are searched directly, the heading by shifting longitude columns, coarse first and then fine
//! around the best peaks.
//!
//! The result is a handful of [`RotationHypothesis`]es, best first. None of them is trusted on
//! its own: each is searched exactly over the translation window and a few degrees of heading
//! ([`crate::localize::localize`], eq. 1's cost), the best comparison wins, and a different
//! rotation that compares almost as well is a doubt ([`crate::Doubt::AnotherRotation`]).

use super::{RotationPrior, MIN_ORIENTED_CELLS};
use crate::doubt::Doubt;
use crate::error::{Error, Result};
use crate::geometry::{Attitude, Vec3};
use crate::level::oriented_cells;
use crate::localize::{
    localize, localize_below, HeadingWindow, Localization, LocalizeOptions, SearchWindow,
};
use crate::scan::input::Scan;
use crate::sdem::Sdem;
use nalgebra::Rotation3;
use rayon::prelude::*;
use std::borrow::Cow;
use std::f64::consts::PI;

/// One candidate rotation between the two levelled frames, with how well the surface
/// orientations agree under it (a correlation score, larger is better; only comparable between
/// hypotheses of one pair).
#[derive(Debug, Clone, PartialEq)]
pub struct RotationHypothesis {
    /// `reference_level_from_query_level`.
    pub rotation: Rotation3<f64>,
    /// The correlation of the two extended Gaussian images under `rotation`.
    pub score: f64,
}

/// Coarse stage: lattice step and kernel width of the reference image, radians.
const COARSE_STEP: f64 = 4.0 * PI / 180.0;
const COARSE_KERNEL: f64 = 7.0 * PI / 180.0;
/// Fine stage: lattice step and kernel width.
const FINE_STEP: f64 = 1.0 * PI / 180.0;
const FINE_KERNEL: f64 = 2.5 * PI / 180.0;
/// Two hypotheses closer than this are one.
const DISTINCT: f64 = 10.0 * PI / 180.0;
/// The coarse search compares at most this many of the query's directions (the heaviest).
const MAX_COARSE_DIRECTIONS: usize = 300;
/// The query's image keeps its heaviest directions up to this share of the total weight.
const KEPT_WEIGHT: f64 = 0.98;
/// … and at most this many.
const MAX_DIRECTIONS: usize = 700;

/// The rotation hypotheses between two S-DEMs (each in its own levelled frame), best first, at
/// most `count`, none scoring below `min_relative_score` × the best.
///
/// # Errors
/// [`Error::NoSurfaces`] when a scan shows too few surfaces whose orientation can be measured
/// ([`MIN_ORIENTED_CELLS`]).
pub fn rotation_hypotheses(
    reference: &Sdem,
    query: &Sdem,
    prior: &RotationPrior,
    count: usize,
    min_relative_score: f64,
) -> Result<Vec<RotationHypothesis>> {
    let normals = |sdem: &Sdem| -> Vec<(Vec3, f64)> {
        (oriented_cells(sdem).into_iter())
            .map(|c| (-c.normal, c.area))
            .collect()
    };
    let (reference_normals, query_normals) = rayon::join(|| normals(reference), || normals(query));
    for (which, normals) in [("reference", &reference_normals), ("query", &query_normals)] {
        if normals.len() < MIN_ORIENTED_CELLS {
            return Err(Error::NoSurfaces { which });
        }
    }
    let (coarse_table, fine_table) = rayon::join(
        || SphereTable::new(&reference_normals, COARSE_STEP, COARSE_KERNEL),
        || SphereTable::new(&reference_normals, FINE_STEP, FINE_KERNEL),
    );
    let mut coarse_query = compact(&query_normals, COARSE_STEP);
    coarse_query.truncate(MAX_COARSE_DIRECTIONS);
    let fine_query = compact(&query_normals, FINE_STEP);
    let peaks = coarse_peaks(&coarse_table, &coarse_query, prior, 3 * count);
    let mut refined: Vec<RotationHypothesis> = peaks
        .par_iter()
        .map(|peak| refine_peak(&fine_table, &fine_query, peak, prior))
        .collect();
    refined.sort_by(|a, b| b.score.total_cmp(&a.score));
    let best = refined.first().map_or(0.0, |h| h.score);
    let mut kept: Vec<RotationHypothesis> = Vec::new();
    for h in refined {
        if kept.len() == count || h.score < min_relative_score * best {
            break;
        }
        if kept
            .iter()
            .all(|k| k.rotation.angle_to(&h.rotation) > DISTINCT)
        {
            kept.push(h);
        }
    }
    Ok(kept)
}

/// The query's normals gathered on a latitude–longitude lattice of step `step`: per lattice
/// cell the weighted mean direction and the total weight, heaviest first, keeping
/// [`KEPT_WEIGHT`] of the weight and at most [`MAX_DIRECTIONS`] directions.
fn compact(normals: &[(Vec3, f64)], step: f64) -> Vec<(Vec3, f64)> {
    let lattice = Lattice::new(step);
    let mut sums = vec![(Vec3::zeros(), 0.0); lattice.len()];
    for (n, w) in normals {
        let (row, col) = lattice.cell_of(n);
        let s = &mut sums[row * lattice.cols + col];
        s.0 += n * *w;
        s.1 += w;
    }
    let mut kept: Vec<(Vec3, f64)> = sums
        .into_iter()
        .filter(|s| s.1 > 0.0 && s.0.norm() > 1e-12)
        .map(|(v, w)| (v.normalize(), w))
        .collect();
    kept.sort_by(|a, b| b.1.total_cmp(&a.1));
    let total: f64 = kept.iter().map(|k| k.1).sum();
    let mut sum = 0.0;
    let mut end = 0;
    while end < kept.len() && end < MAX_DIRECTIONS && sum < KEPT_WEIGHT * total {
        sum += kept[end].1;
        end += 1;
    }
    kept.truncate(end);
    kept
}

/// A latitude–longitude lattice on the unit sphere: rows from the south pole up, columns from
/// longitude −π eastwards, both `step` wide.
#[derive(Debug, Clone, Copy)]
struct Lattice {
    step: f64,
    rows: usize,
    cols: usize,
}

impl Lattice {
    fn new(step: f64) -> Self {
        Self {
            step,
            rows: (PI / step).round() as usize,
            cols: (2.0 * PI / step).round() as usize,
        }
    }

    fn len(&self) -> usize {
        self.rows * self.cols
    }

    fn cell_of(&self, n: &Vec3) -> (usize, usize) {
        let lat = n.z.clamp(-1.0, 1.0).asin();
        let lon = n.y.atan2(n.x);
        let row = (((lat + PI / 2.0) / self.step) as usize).min(self.rows - 1);
        let col = (((lon + PI) / self.step) as usize).min(self.cols - 1);
        (row, col)
    }

    fn center(&self, row: usize, col: usize) -> (f64, f64) {
        (
            -PI / 2.0 + (row as f64 + 0.5) * self.step,
            -PI + (col as f64 + 0.5) * self.step,
        )
    }
}

/// The reference's image smoothed by a von Mises–Fisher kernel of width `kernel`, sampled at
/// the centres of a lattice.
struct SphereTable {
    lattice: Lattice,
    values: Vec<f32>,
}

impl SphereTable {
    fn new(normals: &[(Vec3, f64)], step: f64, kernel: f64) -> Self {
        let lattice = Lattice::new(step);
        let directions = compact(normals, step);
        let kappa = 1.0 / (kernel * kernel);
        let reach = 3.0 * kernel;
        let cos_reach = reach.cos();
        let cols = lattice.cols as i64;
        let values: Vec<f32> = (0..lattice.rows)
            .into_par_iter()
            .flat_map_iter(|row| {
                let (lat, _) = lattice.center(row, 0);
                let mut line = vec![0f64; lattice.cols];
                for (m, w) in &directions {
                    let m_lat = m.z.clamp(-1.0, 1.0).asin();
                    if (m_lat - lat).abs() > reach {
                        continue;
                    }
                    // Two directions `reach` apart differ in longitude by at most about
                    // reach / cos(latitude), at the latitude nearer the pole.
                    let c = lat.cos().min(m_lat.cos());
                    let span = if c * PI > reach {
                        ((reach / c) / lattice.step).ceil() as i64 + 1
                    } else {
                        cols
                    };
                    let (_, m_col) = lattice.cell_of(m);
                    let (first, last) = if 2 * span + 1 >= cols {
                        (0, cols - 1)
                    } else {
                        (m_col as i64 - span, m_col as i64 + span)
                    };
                    for col in first..=last {
                        let col = col.rem_euclid(cols) as usize;
                        let (_, lon) = lattice.center(row, col);
                        let c = crate::geometry::direction(lon, lat).dot(m);
                        if c > cos_reach {
                            line[col] += w * (kappa * (c - 1.0)).exp();
                        }
                    }
                }
                line.into_iter().map(|v| v as f32)
            })
            .collect();
        Self { lattice, values }
    }

    /// The score of the query's directions, already rotated, for each heading shift of `shift`
    /// columns, `shifts` being the column offsets asked for.
    fn heading_scores(&self, rotated: &[(Vec3, f64)], shifts: &[i64], scores: &mut [f64]) {
        scores.iter_mut().for_each(|s| *s = 0.0);
        let cols = self.lattice.cols as i64;
        for (m, w) in rotated {
            let (row, col) = self.lattice.cell_of(m);
            let line = &self.values[row * self.lattice.cols..(row + 1) * self.lattice.cols];
            for (s, &k) in scores.iter_mut().zip(shifts) {
                *s += w * line[(col as i64 + k).rem_euclid(cols) as usize] as f64;
            }
        }
    }

    /// The score of the query's directions under `rotation`.
    fn score(&self, query: &[(Vec3, f64)], rotation: &Rotation3<f64>) -> f64 {
        query
            .iter()
            .map(|(n, w)| {
                let (row, col) = self.lattice.cell_of(&(rotation * n));
                w * self.values[row * self.lattice.cols + col] as f64
            })
            .sum()
    }
}

/// A peak of the coarse search: roll and pitch of the tilt, and the heading, radians.
#[derive(Debug, Clone, Copy)]
struct Peak {
    roll: f64,
    pitch: f64,
    yaw: f64,
    score: f64,
}

impl Peak {
    fn rotation(&self) -> Rotation3<f64> {
        Attitude::new(self.roll, self.pitch, self.yaw).rotation()
    }
}

/// The coarse search over tilts within the prior and every heading shift within it: the best
/// `count` distinct peaks.
fn coarse_peaks(
    table: &SphereTable,
    query: &[(Vec3, f64)],
    prior: &RotationPrior,
    count: usize,
) -> Vec<Peak> {
    let step = table.lattice.step;
    let m = (prior.max_tilt / step).ceil() as i64;
    let tilts: Vec<(f64, f64)> = (-m..=m)
        .flat_map(|i| (-m..=m).map(move |j| (i as f64 * step, j as f64 * step)))
        .filter(|&(roll, pitch)| {
            let z = Attitude::new(roll, pitch, 0.0).rotation() * Vec3::z();
            z.z.clamp(-1.0, 1.0).acos() <= prior.max_tilt + step / 2.0
        })
        .collect();
    let cols = table.lattice.cols as i64;
    let half = if prior.heading_half_range >= PI - 1e-9 {
        cols / 2
    } else {
        (prior.heading_half_range / step).ceil() as i64
    };
    let shifts: Vec<i64> = if 2 * half + 1 >= cols {
        (0..cols).map(|k| k - cols / 2).collect()
    } else {
        (-half..=half).collect()
    };
    let mut all: Vec<Peak> = tilts
        .par_iter()
        .flat_map_iter(|&(roll, pitch)| {
            let tilt = Attitude::new(roll, pitch, 0.0).rotation();
            let rotated: Vec<(Vec3, f64)> = query.iter().map(|(n, w)| (tilt * n, *w)).collect();
            let mut scores = vec![0.0; shifts.len()];
            table.heading_scores(&rotated, &shifts, &mut scores);
            // Only the headings that beat their neighbours: a peak, not its slopes.
            let n = scores.len();
            let local: Vec<Peak> = (0..n)
                .filter(|&k| {
                    let (l, r) = if n == cols as usize {
                        (scores[(k + n - 1) % n], scores[(k + 1) % n])
                    } else {
                        (
                            if k > 0 { scores[k - 1] } else { f64::MIN },
                            if k + 1 < n { scores[k + 1] } else { f64::MIN },
                        )
                    };
                    scores[k] >= l && scores[k] >= r && scores[k] > 0.0
                })
                .map(|k| Peak {
                    roll,
                    pitch,
                    yaw: shifts[k] as f64 * step,
                    score: scores[k],
                })
                .collect();
            local
        })
        .collect();
    all.sort_by(|a, b| b.score.total_cmp(&a.score));
    let mut kept: Vec<Peak> = Vec::new();
    for p in all {
        if kept.len() == count {
            break;
        }
        let r = p.rotation();
        if kept.iter().all(|k| k.rotation().angle_to(&r) > DISTINCT) {
            kept.push(p);
        }
    }
    kept
}

/// A coarse peak refined on the fine table by a pattern search: the best of the 26
/// neighbours in (roll, pitch, heading) is taken while one improves, then the step halves, from
/// 2° down to 0.25°, staying within the prior.
fn refine_peak(
    table: &SphereTable,
    query: &[(Vec3, f64)],
    peak: &Peak,
    prior: &RotationPrior,
) -> RotationHypothesis {
    let within = |p: &Peak| {
        let z = Attitude::new(p.roll, p.pitch, 0.0).rotation() * Vec3::z();
        z.z.clamp(-1.0, 1.0).acos() <= prior.max_tilt + COARSE_STEP
    };
    let mut best = *peak;
    best.score = table.score(query, &best.rotation());
    let mut step = 2.0 * FINE_STEP;
    while step >= FINE_STEP / 4.0 - 1e-12 {
        let mut moved = true;
        let mut moves = 0;
        while moved && moves < 8 {
            moved = false;
            moves += 1;
            let center = best;
            for i in -1..=1 {
                for j in -1..=1 {
                    for l in -1..=1 {
                        if i == 0 && j == 0 && l == 0 {
                            continue;
                        }
                        let candidate = Peak {
                            roll: center.roll + i as f64 * step,
                            pitch: center.pitch + j as f64 * step,
                            yaw: center.yaw + l as f64 * step,
                            score: 0.0,
                        };
                        if !within(&candidate) {
                            continue;
                        }
                        let score = table.score(query, &candidate.rotation());
                        if score > best.score {
                            best = Peak { score, ..candidate };
                            moved = true;
                        }
                    }
                }
            }
        }
        step /= 2.0;
    }
    RotationHypothesis {
        rotation: best.rotation(),
        score: best.score,
    }
}

/// At most this many rotation hypotheses are verified by the exact search.
const MAX_HYPOTHESES: usize = 10;
/// … none scoring below this share of the best hypothesis's correlation.
const MIN_RELATIVE_SCORE: f64 = 0.4;
/// Each hypothesis is searched over this heading range around it, degrees: the fine
/// correlation's peaks lie within ±1° of the truth on the scenes measured, and the rest is the
/// margin for a blunt peak.
const HYPOTHESIS_HEADING_DEG: f64 = 5.0;
/// The final search, levelled by the refined rotation, covers this heading range, degrees.
const FINAL_HEADING_DEG: f64 = 1.0;

/// Localizes `query` against `reference` when a scan could be levelled neither by its reading
/// nor by its surfaces, or no heading matched at the levels found (`prior` then narrowed to a
/// few degrees of tilt about them): the rotation hypotheses of [`rotation_hypotheses`], each searched
/// exactly over the translation window and a few degrees of heading around it; the best
/// comparison (eq. 1) wins and is searched again, levelled by its refined rotation, with the
/// caller's options. A different rotation comparing within the ambiguity ratio is the doubt
/// [`Doubt::AnotherRotation`].
///
/// `reference_level` and `query_level` are the attitudes that level each scan where one is
/// known (a reading, or the vertical of its surfaces), `None` where not. A reference without
/// one keeps its sensor frame, whose z axis need not be vertical, so the window's height is
/// widened to its largest half-size.
///
/// # Errors
/// As [`crate::localize::localize`], and [`Error::NoSurfaces`].
pub(super) fn localize_tilted(
    reference: &Scan,
    reference_level: Option<&Attitude>,
    query: &Scan,
    query_level: Option<&Attitude>,
    options: &LocalizeOptions,
    prior: &RotationPrior,
) -> Result<Localization> {
    let start = std::time::Instant::now();
    // The query is turned by its level and then by a hypothesis tilted up to the prior's.
    let tilt = |a: Option<&Attitude>| a.map_or(0.0, super::tilt_of);
    let grid = super::grid_for_tilt(
        reference.sdem().config(),
        tilt(reference_level).max(tilt(query_level) + prior.max_tilt),
    );
    let sdem_of = |scan, level| sdem_on(scan, level, &grid);
    let (reference_sdem, reference_rotation, window) = match reference_level {
        Some(a) => (sdem_of(reference, Some(a))?, a.rotation(), options.window),
        None => (
            sdem_of(reference, None)?,
            Rotation3::identity(),
            upright_free(&options.window),
        ),
    };
    let (query_sdem, query_rotation) = match query_level {
        Some(a) => (sdem_of(query, Some(a))?, a.rotation()),
        None => (sdem_of(query, None)?, Rotation3::identity()),
    };
    let hypotheses = rotation_hypotheses(
        &reference_sdem,
        &query_sdem,
        prior,
        MAX_HYPOTHESES,
        MIN_RELATIVE_SCORE,
    )?;
    let found = verify(
        Verifying {
            reference_sdem: &reference_sdem,
            reference_level: reference_rotation,
            window: &window,
            query,
            query_level: query_rotation,
            options,
        },
        &hypotheses,
    )?;
    Ok(finish(found, start))
}

/// `scan`'s own S-DEM, or one levelled by `level` (as level without one) on `grid` where it is
/// levelled or `grid` is not the scan's own (widened).
fn sdem_on<'s>(
    scan: &'s Scan,
    level: Option<&Attitude>,
    grid: &crate::sdem::SdemConfig,
) -> Result<Cow<'s, Sdem>> {
    Ok(match level {
        None if grid == scan.sdem().config() => Cow::Borrowed(scan.sdem()),
        _ => Cow::Owned(Sdem::from_points(
            scan.points_in_sensor(),
            level.unwrap_or(&Attitude::default()),
            grid,
        )?),
    })
}

/// The result with the whole call's time.
fn finish(mut found: Localization, start: std::time::Instant) -> Localization {
    found.time = start.elapsed();
    found
}

/// What the verification of rotation hypotheses works on.
struct Verifying<'a> {
    /// The reference's S-DEM, levelled by `reference_level`.
    reference_sdem: &'a Sdem,
    reference_level: Rotation3<f64>,
    /// The translation window, in the reference's levelled frame.
    window: &'a SearchWindow,
    query: &'a Scan,
    /// The rotation the hypotheses' query frame is levelled by.
    query_level: Rotation3<f64>,
    options: &'a LocalizeOptions,
}

/// The hypotheses searched exactly: each on a coarse grid over the window and a few degrees of
/// heading, ranked by eq. 1's cost; the best searched again at the caller's step and refined;
/// and the result searched once more, levelled by its refined rotation, with the caller's
/// options. A different rotation comparing within the ambiguity ratio is a doubt.
fn verify(v: Verifying, hypotheses: &[RotationHypothesis]) -> Result<Localization> {
    let Verifying {
        reference_sdem,
        reference_level,
        window,
        query,
        query_level,
        options,
    } = v;
    let window = *window;
    let levelled = |rotation: &Rotation3<f64>| {
        let attitude = Attitude::from_rotation(&(rotation * query_level))
            .with_sigma_deg(FINAL_HEADING_DEG, FINAL_HEADING_DEG);
        Sdem::from_points(query.points_in_sensor(), &attitude, reference_sdem.config())
    };
    let around_hypothesis = HeadingWindow {
        half_range_deg: HYPOTHESIS_HEADING_DEG,
        step_deg: None,
    };
    // Every hypothesis searched exactly on a coarse grid: the cost of eq. 1 ranks them. Only
    // one that could win, or rival the best within the ambiguity ratio, matters, so the search
    // of the others stops as soon as nothing in their window can.
    let screening = LocalizeOptions {
        window,
        step_m: options.step_m.max(super::SCREENING_STEP_M),
        heading: around_hypothesis,
        refine: false,
        runner_up: false,
        ..options.clone()
    };
    let mut screened: Vec<(Sdem, Localization)> = Vec::new();
    let mut first_error = None;
    let mut cap = f64::INFINITY;
    for h in hypotheses {
        let outcome = levelled(&h.rotation).and_then(|q| {
            let found = localize_below(reference_sdem, &q, &screening, cap)?;
            Ok(found.map(|f| (q, f)))
        });
        match outcome {
            Ok(None) => {}
            Ok(Some((q, found))) => {
                cap = cap.min(options.ambiguous_cost_ratio * found.cost);
                screened.push((q, found));
            }
            Err(e) => {
                first_error.get_or_insert(e);
            }
        }
    }
    let level_rotation = |found: &Localization| -> Rotation3<f64> {
        reference_level
            * found.reference_from_query.rotation.to_rotation_matrix()
            * query_level.inverse()
    };
    screened.sort_by(|a, b| a.1.cost.total_cmp(&b.1.cost));
    let Some((best_query, best)) = screened.first() else {
        return Err(first_error.unwrap_or(Error::NoSurfaces { which: "query" }));
    };
    let best_cost = best.cost;
    // The winner searched at the caller's step around its coarse optimum and refined in 6-DoF:
    // the refinement takes out what the correlation left of the tilt.
    let refining = LocalizeOptions {
        window: SearchWindow::around(&best.grid_offset, [screening.step_m; 3]),
        heading: around_hypothesis,
        runner_up: false,
        ..options.clone()
    };
    let refined = localize(reference_sdem, best_query, &refining)?;
    // Searched again, levelled by the refined rotation, with the caller's options, so that
    // the diagnostics (runner-up, shape of the cost) are those of the levelled search.
    let final_options = LocalizeOptions {
        window,
        heading: HeadingWindow {
            half_range_deg: FINAL_HEADING_DEG,
            step_deg: None,
        },
        ..options.clone()
    };
    let mut best_rotation = level_rotation(&refined);
    let mut found = localize(reference_sdem, &levelled(&best_rotation)?, &final_options)?;
    // A refinement that fails from the hypothesis's rotation (a few degrees off, so the grid's
    // optimum is centimetres off and far points pair with nothing) is run again allowed to
    // pair and move further ([`super::relaxed_refinement`]); its rotation is kept when the
    // search levelled by it refines within the usual bounds and compares better.
    if refining.refine && super::refinement_failed(&refined) {
        let relaxed = LocalizeOptions {
            refinement: super::relaxed_refinement(&options.refinement),
            ..refining.clone()
        };
        let again = localize(reference_sdem, best_query, &relaxed)
            .ok()
            .filter(|r| r.refinement.is_some())
            .map(|r| level_rotation(&r))
            .and_then(|rotation| {
                let f = localize(reference_sdem, &levelled(&rotation).ok()?, &final_options);
                Some((rotation, f.ok()?))
            });
        if let Some((rotation, f)) = again {
            if !super::refinement_failed(&f) && f.cost <= found.cost {
                (best_rotation, found) = (rotation, f);
            }
        }
    }
    let rivals =
        (screened[1..].iter()).map(|(_, f)| (level_rotation(f).angle_to(&best_rotation), f));
    let rival = (rivals.clone())
        .filter(|(angle, _)| *angle > super::OTHER_ROTATION)
        .find(|(_, f)| f.cost < options.ambiguous_cost_ratio * best_cost);
    if let Some((angle, f)) = rival {
        found.doubts.push(Doubt::AnotherRotation {
            angle_deg: angle.to_degrees(),
            cost: f.cost,
            best_cost,
        });
    } else if let Some(doubt) = super::unrefuted(&found, rivals) {
        found.doubts.push(doubt);
    }
    found.diagnostics.ambiguous |= found.doubts.iter().any(Doubt::is_other_rotation);
    found.trusted = found.doubts.is_empty();
    Ok(found)
}

/// The window with its height widened to its largest half-size, around the same centre.
fn upright_free(window: &SearchWindow) -> SearchWindow {
    let half = (0..3)
        .map(|i| (window.max[i] - window.min[i]) / 2.0)
        .fold(0.0, f64::max);
    let center = (window.min[2] + window.max[2]) / 2.0;
    SearchWindow {
        min: [window.min[0], window.min[1], center - half],
        max: [window.max[0], window.max[1], center + half],
    }
}

#[cfg(test)]
mod tests {
    use super::*;
    use crate::sdem::SdemConfig;

    /// A box room with a pillar, seen from `origin`, as points of the sensor frame rotated by
    /// `sensor_from_world`.
    fn room_scan(origin: Vec3, sensor_from_world: &Rotation3<f64>) -> Vec<Vec3> {
        let mut points = Vec::new();
        let (lo, hi) = (Vec3::new(-3.0, -2.0, -0.5), Vec3::new(4.0, 2.5, 2.0));
        for i in 0..=600 {
            for j in 0..=240 {
                let az = -PI + i as f64 * (2.0 * PI / 600.0);
                let el = -PI / 2.0 + j as f64 * (PI / 240.0);
                let d = crate::geometry::direction(az, el);
                let mut t = f64::INFINITY;
                for k in 0..3 {
                    if d[k].abs() > 1e-9 {
                        let bound = if d[k] > 0.0 { hi[k] } else { lo[k] };
                        t = t.min((bound - origin[k]) / d[k]);
                    }
                }
                // A pillar: an axis-aligned box that occludes.
                let (plo, phi) = (Vec3::new(1.0, 0.5, -0.5), Vec3::new(1.6, 1.2, 2.0));
                let (mut t0, mut t1) = (0.0f64, f64::INFINITY);
                for k in 0..3 {
                    if d[k].abs() < 1e-12 {
                        if origin[k] < plo[k] || origin[k] > phi[k] {
                            t1 = -1.0;
                        }
                        continue;
                    }
                    let (a, b) = ((plo[k] - origin[k]) / d[k], (phi[k] - origin[k]) / d[k]);
                    t0 = t0.max(a.min(b));
                    t1 = t1.min(a.max(b));
                }
                if t0 <= t1 && t0 > 0.0 {
                    t = t.min(t0);
                }
                points.push(sensor_from_world * (d * t));
            }
        }
        points
    }

    #[test]
    fn finds_a_tilt_and_heading_among_its_hypotheses() {
        let config = SdemConfig::default();
        let level = Attitude::default();
        let reference = Sdem::from_points(
            &room_scan(Vec3::new(0.0, 0.0, 0.5), &Rotation3::identity()),
            &level,
            &config,
        )
        .unwrap();
        let truth = Attitude::from_degrees(12.0, -20.0, 65.0).rotation();
        let query = Sdem::from_points(
            &room_scan(Vec3::new(0.6, -0.4, 0.7), &truth.inverse()),
            &level,
            &config,
        )
        .unwrap();
        let prior = RotationPrior {
            max_tilt: 30f64.to_radians(),
            heading_half_range: PI,
        };
        let hypotheses = rotation_hypotheses(&reference, &query, &prior, 6, 0.3).unwrap();
        assert!(!hypotheses.is_empty());
        let nearest = hypotheses
            .iter()
            .map(|h| h.rotation.angle_to(&truth).to_degrees())
            .fold(f64::INFINITY, f64::min);
        assert!(
            nearest < 2.0,
            "nearest hypothesis {nearest:.2}° from the truth"
        );
    }

    #[test]
    fn no_surfaces_no_hypotheses() {
        let config = SdemConfig::default();
        // Isolated points: no cell has neighbours, so no normal.
        let points: Vec<Vec3> = (0..200)
            .map(|i| crate::geometry::direction(i as f64 * 0.2, (i % 7) as f64 * 0.2 - 0.6) * 3.0)
            .collect();
        let s = Sdem::from_points(&points, &Attitude::default(), &config).unwrap();
        let prior = RotationPrior {
            max_tilt: 0.5,
            heading_half_range: PI,
        };
        assert!(matches!(
            rotation_hypotheses(&s, &s, &prior, 4, 0.3),
            Err(Error::NoSurfaces { which: "reference" })
        ));
    }
}
