//! The rotation between two scans when the attitude of one or both is unknown or uncertain.
//!
//! The orientations of the surfaces a scan sees do not depend on where it was taken: a floor faces
//! up, a wall faces its way, from any origin. Each scan's surface normals, weighted by the area
//! they stand for, form an *extended Gaussian image* (Horn 1984); the rotation that best lays the
//! query's image on the reference's is the rotation between the scans, up to the symmetries of
//! the scene (a rectangular room looks the same turned by 180°). Makadia, Patterson & Daniilidis
//! (CVPR 2006) correlate such images over all of SO(3) with spherical harmonics; here the
//! rotations a robot can have (a tilt within a bound, any heading) are searched directly, the
//! heading by shifting longitude columns, coarse first and then fine around the best peaks.
//!
//! The result is a handful of [`RotationHypothesis`]es, best first. None of them is trusted on
//! its own: [`crate::scan::localize`] runs the exact translation and heading search
//! ([`crate::localize::localize`], eq. 1's cost) once per hypothesis and keeps the one whose
//! comparison of the two S-DEMs is best, and a different rotation that compares almost as well
//! is a doubt ([`crate::Doubt::AnotherRotation`]).

use crate::doubt::Doubt;
use crate::error::{Error, Result};
use crate::geometry::{Attitude, Vec3};
use crate::localize::{
    localize, localize_below, HeadingWindow, Localization, LocalizeOptions, SearchWindow,
};
use crate::scan::Scan;
use crate::sdem::Sdem;
use nalgebra::Rotation3;
use rayon::prelude::*;
use std::borrow::Cow;
use std::f64::consts::PI;

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

/// The fewest cells with a measured surface orientation a scan needs for its rotation to be
/// found from them.
pub const MIN_ORIENTED_CELLS: usize = 50;

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
    let (reference_normals, query_normals) =
        rayon::join(|| surface_normals(reference), || surface_normals(query));
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

/// The sensor's tilt estimated from its own scan when it has no attitude reading: the "up"
/// within [`MAX_UNKNOWN_TILT`] of the sensor's z axis that floors (facing up) and ceilings
/// (facing down) agree on best, as an attitude with zero heading. `None` when the scan shows
/// too few measurable surfaces.
pub fn estimated_tilt(sdem: &Sdem) -> Option<Attitude> {
    let normals = surface_normals(sdem);
    if normals.len() < MIN_ORIENTED_CELLS {
        return None;
    }
    let table = SphereTable::new(&normals, COARSE_STEP / 2.0, COARSE_KERNEL);
    let step = FINE_STEP;
    let m = (MAX_UNKNOWN_TILT / step).ceil() as i64;
    let mut best: Option<(f64, Attitude)> = None;
    for i in -m..=m {
        for j in -m..=m {
            let tilt = Attitude::new(i as f64 * step, j as f64 * step, 0.0);
            // `up` in the sensor frame is the levelled z axis taken back.
            let up = tilt.rotation().inverse() * Vec3::z();
            if up.z.clamp(-1.0, 1.0).acos() > MAX_UNKNOWN_TILT {
                continue;
            }
            // Normals point away from the sensor: a floor's down, a ceiling's up.
            let score = table.at(&-up) + table.at(&up);
            if best.as_ref().is_none_or(|b| score > b.0) {
                best = Some((score, tilt));
            }
        }
    }
    best.filter(|b| b.0 > 0.0).map(|b| b.1)
}

/// The surface normal at each known cell of an S-DEM whose neighbours two cells away on both
/// axes lie on the same surface, pointing away from the sensor, with the area of surface the
/// cell stands for (its footprint at its range over the cosine of incidence, capped) as weight.
fn surface_normals(sdem: &Sdem) -> Vec<(Vec3, f64)> {
    const SPAN: i64 = 2;
    let spec = sdem.grid();
    let (n_az, n_el) = (spec.azimuth_cells() as i64, spec.elevation_cells() as i64);
    let res = spec.resolution();
    let full_circle = (n_az as f64 * res - 2.0 * PI).abs() < 1e-6;
    let mut index = vec![u32::MAX; spec.len()];
    for (i, &c) in sdem.cells().iter().enumerate() {
        index[c as usize] = i as u32;
    }
    let points = sdem.points();
    let point_at = |e: i64, a: i64| -> Option<Vec3> {
        if e < 0 || e >= n_el {
            return None;
        }
        let a = if full_circle {
            a.rem_euclid(n_az)
        } else if a < 0 || a >= n_az {
            return None;
        } else {
            a
        };
        let i = index[(e * n_az + a) as usize];
        (i != u32::MAX).then(|| {
            let p = points[i as usize];
            Vec3::new(p[0] as f64, p[1] as f64, p[2] as f64)
        })
    };
    (sdem.cells().par_iter().zip(points.par_iter()))
        .filter_map(|(&cell, p)| {
            let (e, a) = (cell as i64 / n_az, cell as i64 % n_az);
            let p = Vec3::new(p[0] as f64, p[1] as f64, p[2] as f64);
            let range = p.norm();
            // Neighbours on the same surface: their range within a spread that a surface seen
            // at up to ~80° of incidence keeps over two cells.
            let near = |q: Option<Vec3>| {
                q.filter(|q| (q.norm() - range).abs() < 0.02 + 0.25 * range * SPAN as f64 * res)
            };
            let along = near(point_at(e, a + SPAN))? - near(point_at(e, a - SPAN))?;
            let across = near(point_at(e + SPAN, a))? - near(point_at(e - SPAN, a))?;
            let n = along.cross(&across);
            let len = n.norm();
            if len < 1e-12 {
                return None;
            }
            let ray = p / range;
            let mut n = n / len;
            if n.dot(&ray) < 0.0 {
                n = -n;
            }
            let (_, el) = spec.cell_center(cell as usize);
            let incidence = n.dot(&ray).max(0.3);
            let area = range * range * res * res * el.cos() / incidence;
            Some((n, area))
        })
        .collect()
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

    /// The table's value in direction `n`.
    fn at(&self, n: &Vec3) -> f64 {
        let (row, col) = self.lattice.cell_of(n);
        self.values[row * self.lattice.cols + col] as f64
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

/// The largest tilt from level a scan without an attitude reading may have, radians (30°: a
/// robot lying on rubble; a hand-held or vehicle scanner is within it).
pub const MAX_UNKNOWN_TILT: f64 = 30.0 * PI / 180.0;

/// At most this many rotation hypotheses are verified by the exact search.
const MAX_HYPOTHESES: usize = 10;
/// … none scoring below this share of the best hypothesis's correlation.
const MIN_RELATIVE_SCORE: f64 = 0.4;
/// Each hypothesis is searched over this heading range around it, degrees: the fine
/// correlation's peaks lie within ±1° of the truth on the scenes measured, and the rest is the
/// margin for a blunt peak.
const HYPOTHESIS_HEADING_DEG: f64 = 5.0;
/// The hypotheses are ranked by an exact search on a grid this coarse, metres (or the
/// caller's step, if coarser).
const SCREENING_STEP_M: f64 = 0.04;
/// The final search, levelled by the refined rotation, covers this heading range, degrees.
const FINAL_HEADING_DEG: f64 = 1.0;
/// Two rotations farther apart than this are different answers, for the doubt
/// [`Doubt::AnotherRotation`].
const OTHER_ROTATION: f64 = 5.0 * PI / 180.0;

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

/// Localizes `query` against `reference` when their rotation is not known well enough for the
/// levelled search: the rotation hypotheses of [`rotation_hypotheses`], each searched exactly
/// over the translation window and a few degrees of heading around it; the best comparison
/// (eq. 1) wins and is searched again, levelled by its refined rotation, with the caller's
/// options. A different rotation comparing within the ambiguity ratio is the doubt
/// [`Doubt::AnotherRotation`].
///
/// When the reference's attitude is unknown its levelled frame is its sensor frame, whose z
/// axis need not be vertical, so the window's height is widened to its largest half-size.
///
/// # Errors
/// As [`crate::localize::localize`], and [`Error::NoSurfaces`].
pub fn localize_unlevelled(
    reference: &Scan,
    query: &Scan,
    options: &LocalizeOptions,
    prior: &RotationPrior,
) -> Result<Localization> {
    let start = std::time::Instant::now();
    // Without a reading the reference is levelled by its own estimated tilt, so the window's
    // height means height, give or take what the estimate may miss.
    let (reference_sdem, reference_level, window) = match reference.attitude() {
        Some(a) => (
            Cow::Borrowed(reference.sdem()),
            a.rotation(),
            options.window,
        ),
        None => match estimated_tilt(reference.sdem()) {
            Some(tilt) => (
                Cow::Owned(Sdem::from_points(
                    reference.points_in_sensor(),
                    &tilt,
                    reference.sdem().config(),
                )?),
                tilt.rotation(),
                tilt_margin(&options.window),
            ),
            None => (
                Cow::Borrowed(reference.sdem()),
                Rotation3::identity(),
                upright_free(&options.window),
            ),
        },
    };
    let reference_sdem: &Sdem = &reference_sdem;
    let searched = |query_sdem: &Sdem, query_level: Rotation3<f64>, prior: &RotationPrior| {
        let hypotheses = rotation_hypotheses(
            reference_sdem,
            query_sdem,
            prior,
            MAX_HYPOTHESES,
            MIN_RELATIVE_SCORE,
        )?;
        verify(
            Verifying {
                reference_sdem,
                reference_level,
                window: &window,
                query,
                query_level,
                options,
            },
            &hypotheses,
        )
    };
    // A query without a reading is levelled by its own estimated tilt first: then only what
    // the two estimates may miss is left of the tilt, and the surfaces decide the heading. If
    // that does not give a trusted match, the whole prior is searched.
    let estimate = query
        .attitude()
        .is_none()
        .then(|| estimated_tilt(query.sdem()))
        .flatten();
    let mut first = None;
    if let Some(tilt) = estimate {
        let query_sdem = Sdem::from_points(query.points_in_sensor(), &tilt, query.sdem().config())?;
        let reference_tilt = match reference.attitude() {
            Some(a) => 3.0 * a.sigma.roll_pitch,
            None => TILT_ESTIMATE_ERROR,
        };
        let near_level = RotationPrior {
            max_tilt: (reference_tilt + TILT_ESTIMATE_ERROR).min(prior.max_tilt),
            heading_half_range: prior.heading_half_range,
        };
        match searched(&query_sdem, tilt.rotation(), &near_level) {
            Ok(found) if found.trusted => return Ok(finish(found, start)),
            outcome => first = Some(outcome),
        }
    }
    let query_level = query
        .attitude()
        .map_or_else(Rotation3::identity, Attitude::rotation);
    let found = match (searched(query.sdem(), query_level, prior), first) {
        (Ok(found), Some(Ok(earlier))) if !found.trusted && earlier.cost < found.cost => earlier,
        (Err(_), Some(Ok(earlier))) => earlier,
        (outcome, _) => outcome?,
    };
    Ok(finish(found, start))
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
        Sdem::from_points(query.points_in_sensor(), &attitude, query.sdem().config())
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
        step_m: options.step_m.max(SCREENING_STEP_M),
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
    let best_rotation = level_rotation(&refined);
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
    let mut found = localize(reference_sdem, &levelled(&best_rotation)?, &final_options)?;
    let rival = screened[1..]
        .iter()
        .filter(|(_, f)| level_rotation(f).angle_to(&best_rotation) > OTHER_ROTATION)
        .find(|(_, f)| f.cost < options.ambiguous_cost_ratio * best_cost);
    if let Some((_, f)) = rival {
        found.doubts.push(Doubt::AnotherRotation {
            angle_deg: level_rotation(f).angle_to(&best_rotation).to_degrees(),
            cost: f.cost,
            best_cost,
        });
        found.diagnostics.ambiguous = true;
    }
    found.trusted = found.doubts.is_empty();
    Ok(found)
}

/// How far off a tilt estimated from the scan may be, for the window's margin (radians, 5°).
const TILT_ESTIMATE_ERROR: f64 = 5.0 * PI / 180.0;

/// The window with its height widened by what a tilt error of [`TILT_ESTIMATE_ERROR`] turns
/// its horizontal extent into.
fn tilt_margin(window: &SearchWindow) -> SearchWindow {
    let horizontal = (0..2)
        .flat_map(|i| [window.min[i].abs(), window.max[i].abs()])
        .fold(0.0, f64::max);
    let margin = horizontal * TILT_ESTIMATE_ERROR.sin();
    SearchWindow {
        min: [window.min[0], window.min[1], window.min[2] - margin],
        max: [window.max[0], window.max[1], window.max[2] + margin],
    }
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
