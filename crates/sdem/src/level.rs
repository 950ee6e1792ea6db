//! Which way is up, from a scan's own surfaces, for scans without a gyro.
//!
//! Floors face up and ceilings down wherever a scan is taken, and in a building, a street or a
//! corridor most other surfaces (walls, facades, pillars) stand vertical. A scan's surface
//! normals, weighted by the area each stands for, therefore cluster along the vertical and
//! along the horizon. [`level_from_surfaces`] finds the vertical within a bound of the sensor's
//! z axis that the horizontal surfaces agree on, then refines it so that the horizontal
//! surfaces are as level, and the vertical ones as upright, as they can be together (the
//! largest eigenvector of the difference of their scatter matrices; the Manhattan-world
//! assumption of Coughlan & Yuille 1999, relaxed: only floors and ceilings are required).
//!
//! The estimate is a measurement: it comes with the share of the oriented area that supports
//! it and an uncertainty, and a second vertical that the surfaces support almost as well (a
//! large tilted slab in rubble) is returned as a rival, not hidden.

use crate::geometry::{Attitude, Vec3};
use crate::sdem::{patch_moments, Sdem};
use nalgebra::{Matrix3, Rotation3, SymmetricEigen};
use rayon::prelude::*;
use std::f64::consts::PI;

/// The fewest cells with a measured surface orientation a scan needs for its rotation to be
/// found from them.
pub const MIN_ORIENTED_CELLS: usize = 50;

/// Roll and pitch readings whose difference is within this at three standard deviations are
/// taken as they are: the levelled search and the 6-DoF refinement absorb such a tilt. Beyond
/// it, the rotation is searched ([`crate::global`]). Radians (3°: the default readings, 0.5°
/// each, stay levelled).
pub const LEVEL_TOLERANCE: f64 = 3.0 * PI / 180.0;

/// A cell's surface: its unit normal (pointing towards the sensor) and the area it stands
/// for, square metres.
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct OrientedCell {
    /// The unit normal, in the S-DEM's frame, facing the sensor.
    pub normal: Vec3,
    /// The area of surface the cell stands for: its footprint at its range over the cosine of
    /// the incidence angle (capped at 1/[`MIN_INCIDENCE_COSINE`]), m².
    pub area: f64,
}

/// Incidence cosines below this count as this in a cell's area: a floor seen at a grazing
/// angle stands for much surface, but its normal is the least certain.
pub const MIN_INCIDENCE_COSINE: f64 = 0.2;

/// The plane through each known cell of an S-DEM and its neighbours within two cells, where
/// they lie on one surface.
///
/// A neighbour belongs to the cell's surface when it lies within the distance that a surface
/// seen at up to ~80° of incidence spreads the beams over (six times their spacing at that
/// range) plus 2 cm of noise: a floor seen at a grazing angle keeps its neighbours, a step or
/// an occlusion boundary loses them. The plane is fitted by principal components and kept
/// only when the patch is flat (its thinnest spread below a fifth of the next) and spans two
/// directions: corners, edges and blobs have no normal.
pub fn oriented_cells(sdem: &Sdem) -> Vec<OrientedCell> {
    const K: i64 = 2;
    let spec = sdem.grid();
    let res = spec.resolution();
    let mut index = vec![u32::MAX; spec.len()];
    for (i, &c) in sdem.cells().iter().enumerate() {
        index[c as usize] = i as u32;
    }
    let points = sdem.points();
    sdem.cells()
        .par_iter()
        .zip(points.par_iter())
        .filter_map(|(&cell, p)| {
            let centre = Vec3::new(p[0] as f64, p[1] as f64, p[2] as f64);
            let range = centre.norm();
            if range < 1e-6 {
                return None;
            }
            let reach = 6.0 * K as f64 * res * range + 0.02;
            let patch = patch_moments(spec, &index, points, (cell, &centre), K, reach);
            let cov = patch.covariance(8)?;
            let eigen = SymmetricEigen::new(cov);
            let mut order = [0usize, 1, 2];
            order.sort_by(|&i, &j| eigen.eigenvalues[i].total_cmp(&eigen.eigenvalues[j]));
            let (thin, mid) = (
                eigen.eigenvalues[order[0]].max(0.0),
                eigen.eigenvalues[order[1]],
            );
            if mid <= 1e-10 || thin > 0.04 * mid {
                return None;
            }
            let ray = centre / range;
            let mut normal: Vec3 = eigen.eigenvectors.column(order[0]).into_owned();
            if normal.dot(&ray) > 0.0 {
                normal = -normal;
            }
            let incidence = (-normal.dot(&ray)).max(MIN_INCIDENCE_COSINE);
            let (_, el) = spec.cell_center(cell as usize);
            let area = range * range * res * res * el.cos() / incidence;
            Some(OrientedCell { normal, area })
        })
        .collect()
}

/// The vertical found in a scan, as the attitude that levels it (roll and pitch; the heading
/// is not observable and is zero).
#[derive(Debug, Clone, PartialEq)]
pub struct Levelling {
    /// The attitude whose rotation takes the scan's frame to a level one (yaw zero), with
    /// [`Attitude::sigma`]'s roll/pitch set to [`Self::sigma`].
    pub attitude: Attitude,
    /// "Up" in the scan's frame (a unit vector).
    pub up: Vec3,
    /// The share of the oriented area lying on horizontal surfaces (within 5° of level).
    pub horizontal_share: f64,
    /// The share lying on vertical surfaces (within 5° of upright).
    pub vertical_share: f64,
    /// The standard deviation of the estimate, radians: the spread of the horizontal
    /// surfaces' normals over the square root of their effective count, and never below
    /// [`MIN_SIGMA`] (a floor is not perfectly level).
    pub sigma: f64,
    /// Other verticals the surfaces support (more than 10° away, scoring at least
    /// [`RIVAL_SHARE`] of the best), best first: a large slab tilted like a floor.
    pub rivals: Vec<Vec3>,
}

/// The smallest standard deviation a levelling from the scan claims, radians (0.5°). The
/// spread of the normals over their count says how well the surfaces agree, not how level
/// they are: real floors slope and sag, and which of them a view sees moves its vertical.
/// Measured on real scans seen again from 30 poses each, both views tilted up to 30° (the
/// probe behind `examples/real_unlevelled`): the two views' levels of one scene disagree by
/// 0.59° median (1.14° at the 90th percentile; KITTI frame 0) and 0.78–1.05° (3DTK scans 0
/// and 2), where the spread claimed 0.2° each, about 0.28° for the pair; 0.5° each is about
/// 0.7° for the pair. Simulated scenes' floors level a scan to 0.01–0.2°.
pub const MIN_SIGMA: f64 = 0.5 * PI / 180.0;
/// A second vertical scoring at least this share of the best is a rival.
pub const RIVAL_SHARE: f64 = 0.5;
/// The least share of the oriented area on horizontal surfaces for a levelling.
pub const MIN_HORIZONTAL_SHARE: f64 = 0.05;

/// The direction of gravity in a scan, from its own surfaces (see the module's text).
///
/// # Arguments
/// * `sdem` — the scan (its frame is the one the returned attitude levels).
/// * `expected_up` — where up is expected in that frame (a unit vector; +z when nothing is
///   known).
/// * `max_tilt` — the largest angle between `expected_up` and up, radians.
///
/// # Returns
/// `None` when the scan shows too few oriented cells, or horizontal surfaces on less than
/// [`MIN_HORIZONTAL_SHARE`] of its oriented area within `max_tilt`.
pub fn level_from_surfaces(sdem: &Sdem, expected_up: &Vec3, max_tilt: f64) -> Option<Levelling> {
    level_from_cells(&oriented_cells(sdem), expected_up, max_tilt)
}

/// [`level_from_surfaces`] on cells already oriented.
pub fn level_from_cells(
    cells: &[OrientedCell],
    expected_up: &Vec3,
    max_tilt: f64,
) -> Option<Levelling> {
    if cells.len() < MIN_ORIENTED_CELLS {
        return None;
    }
    let total: f64 = cells.iter().map(|c| c.area).sum();
    let compact = compact_axial(cells, 2f64.to_radians());
    let peaks = vertical_peaks(&compact, expected_up, max_tilt);
    let (best_up, best_score) = *peaks.first()?;
    let up = refine_up(cells, best_up);
    if up.angle(expected_up) > max_tilt + KERNEL {
        return None;
    }
    let rivals: Vec<Vec3> = peaks[1..]
        .iter()
        .filter(|(_, s)| *s >= RIVAL_SHARE * best_score)
        .map(|(u, _)| refine_up(cells, *u))
        .filter(|u| u.angle(&up) > 10f64.to_radians())
        .collect();
    let (cos_h, sin_v) = (5f64.to_radians().cos(), 5f64.to_radians().sin());
    let (mut horizontal, mut vertical) = (0.0, 0.0);
    // The spread of the horizontal normals about `up`, over the effective number of cells.
    let (mut sum_w2, mut sum_angle2) = (0.0, 0.0);
    for c in cells {
        let d = c.normal.dot(&up).abs();
        if d > cos_h {
            let angle = d.min(1.0).acos();
            horizontal += c.area;
            sum_w2 += c.area * c.area;
            sum_angle2 += c.area * angle * angle;
        } else if d < sin_v {
            vertical += c.area;
        }
    }
    if horizontal < MIN_HORIZONTAL_SHARE * total {
        return None;
    }
    let effective = (horizontal * horizontal / sum_w2).max(1.0);
    let sigma = ((sum_angle2 / horizontal).sqrt() / effective.sqrt()).max(MIN_SIGMA);
    Some(Levelling {
        attitude: attitude_levelling(&up).with_sigma_deg(sigma.to_degrees(), 180.0),
        up,
        horizontal_share: horizontal / total,
        vertical_share: vertical / total,
        sigma,
        rivals,
    })
}

/// The attitude (roll, pitch, zero heading) whose rotation takes `up` to +z.
pub fn attitude_levelling(up: &Vec3) -> Attitude {
    let rotation = Rotation3::rotation_between(up, &Vec3::z())
        .unwrap_or_else(|| Rotation3::from_axis_angle(&Vec3::x_axis(), PI));
    let a = Attitude::from_rotation(&rotation);
    Attitude::new(a.roll, a.pitch, 0.0)
}

/// Normals folded onto the upper hemisphere (a floor's and a ceiling's count alike) and
/// gathered on a latitude–longitude lattice of `step`: per lattice cell the weighted mean
/// direction and the total area.
fn compact_axial(cells: &[OrientedCell], step: f64) -> Vec<(Vec3, f64)> {
    let rows = (PI / 2.0 / step).ceil() as usize;
    let cols = (2.0 * PI / step).round() as usize;
    let mut sums = vec![(Vec3::zeros(), 0.0); rows * cols];
    for c in cells {
        let n = if c.normal.z < 0.0 {
            -c.normal
        } else {
            c.normal
        };
        let lat = n.z.clamp(0.0, 1.0).asin();
        let lon = n.y.atan2(n.x);
        let row = ((lat / step) as usize).min(rows - 1);
        let col = (((lon + PI) / step) as usize).min(cols - 1);
        let s = &mut sums[row * cols + col];
        s.0 += n * c.area;
        s.1 += c.area;
    }
    sums.into_iter()
        .filter(|s| s.1 > 0.0 && s.0.norm() > 1e-12)
        .map(|(v, w)| (v.normalize(), w))
        .collect()
}

/// Kernel width of the vertical's score, radians (4°).
const KERNEL: f64 = 4.0 * PI / 180.0;

/// Candidate verticals within `max_tilt` (+ a kernel's margin) of `expected_up`, every ~3°,
/// scored by the area of surfaces facing along them (an axial von Mises–Fisher kernel of
/// [`KERNEL`]); the local maxima, best first.
fn vertical_peaks(compact: &[(Vec3, f64)], expected_up: &Vec3, max_tilt: f64) -> Vec<(Vec3, f64)> {
    let cap = (max_tilt + KERNEL).min(PI / 2.0);
    let spacing = 3f64.to_radians();
    let to_expected = Rotation3::rotation_between(&Vec3::z(), expected_up)
        .unwrap_or_else(|| Rotation3::from_axis_angle(&Vec3::x_axis(), PI));
    let candidates: Vec<Vec3> = cap_directions(cap, spacing)
        .into_iter()
        .map(|u| to_expected * u)
        .collect();
    let kappa = 1.0 / (2.0 * KERNEL * KERNEL);
    let cos_cut = (3.0 * KERNEL).cos();
    let scores: Vec<f64> = candidates
        .par_iter()
        .map(|u| {
            compact
                .iter()
                .map(|(n, w)| {
                    let c = n.dot(u).abs();
                    if c > cos_cut {
                        w * (kappa * (c * c - 1.0)).exp()
                    } else {
                        0.0
                    }
                })
                .sum()
        })
        .collect();
    // Local maxima: no candidate within 1.8 spacings scores more.
    let reach = (1.8 * spacing).cos();
    let mut peaks: Vec<(Vec3, f64)> = (0..candidates.len())
        .filter(|&i| scores[i] > 0.0)
        .filter(|&i| {
            (0..candidates.len()).all(|j| {
                j == i
                    || candidates[i].dot(&candidates[j]) < reach
                    || scores[j] < scores[i]
                    || (scores[j] == scores[i] && j > i)
            })
        })
        .map(|i| (candidates[i], scores[i]))
        .collect();
    peaks.sort_by(|a, b| b.1.total_cmp(&a.1));
    peaks.truncate(4);
    peaks
}

/// Directions within `cap` of +z, about `spacing` apart (a Fibonacci spiral on the cap).
fn cap_directions(cap: f64, spacing: f64) -> Vec<Vec3> {
    let n = ((2.0 * PI * (1.0 - cap.cos()) / (spacing * spacing)).ceil() as usize).max(1);
    let golden = PI * (3.0 - 5f64.sqrt());
    (0..n)
        .map(|i| {
            let z = 1.0 - (1.0 - cap.cos()) * (i as f64 + 0.5) / n as f64;
            let r = (1.0 - z * z).max(0.0).sqrt();
            let phi = golden * i as f64;
            Vec3::new(r * phi.cos(), r * phi.sin(), z)
        })
        .collect()
}

/// `up` refined: the horizontal surfaces (normals within a shrinking angle of it) made as
/// level, and the vertical ones (normals within that angle of the horizon) as upright, as
/// they can be together: the largest eigenvector of the difference of their area-weighted
/// scatter matrices, thrice, with 8°, 5° and 3°.
fn refine_up(cells: &[OrientedCell], up: Vec3) -> Vec3 {
    let mut up = up;
    for deg in [8.0f64, 5.0, 3.0] {
        let (cos_h, sin_v) = (deg.to_radians().cos(), deg.to_radians().sin());
        let mut scatter = Matrix3::zeros();
        let mut horizontal = 0.0;
        for c in cells {
            let d = c.normal.dot(&up).abs();
            if d > cos_h {
                scatter += c.area * c.normal * c.normal.transpose();
                horizontal += c.area;
            } else if d < sin_v {
                scatter -= c.area * c.normal * c.normal.transpose();
            }
        }
        if horizontal <= 0.0 {
            break;
        }
        let eigen = SymmetricEigen::new(scatter);
        let i = eigen.eigenvalues.imax();
        let mut next: Vec3 = eigen.eigenvectors.column(i).into_owned();
        if next.dot(&up) < 0.0 {
            next = -next;
        }
        up = next.normalize();
    }
    up
}

/// Rotation about the vertical that lays the query's levelled surfaces on the reference's,
/// from their orientations alone (which do not depend on where the scans were taken): the
/// circular correlation over heading of the two levelled extended Gaussian images, in bands of
/// elevation, after Makadia, Patterson & Daniilidis (CVPR 2006) restricted to the one free
/// angle left once both scans are level. Floors and ceilings carry no heading and are left
/// out.
///
/// # Arguments
/// * `reference`, `query` — oriented cells, each in its scan's levelled frame.
/// * `half_range` — the headings searched, ±radians around zero (π: a full turn).
/// * `count` — at most this many hypotheses.
///
/// # Returns
/// The local maxima of the correlation scoring at least [`MIN_HEADING_SHARE`] of the best,
/// best first: `(heading, score)`, the heading being the query's levelled frame's yaw in the
/// reference's (radians in [−π, π)). Empty when either scan shows no surface off the vertical.
pub fn heading_hypotheses(
    reference: &[OrientedCell],
    query: &[OrientedCell],
    half_range: f64,
    count: usize,
) -> Vec<(f64, f64)> {
    let (r, q) = rayon::join(|| heading_image(reference), || heading_image(query));
    let bins = HEADING_BINS as i64;
    let shifts: Vec<i64> = if half_range >= PI - 1e-9 {
        (0..bins).collect()
    } else {
        let m = (half_range / (2.0 * PI / bins as f64)).ceil() as i64;
        (-m..=m).collect()
    };
    // score(k): query's bin a turned by k bins lands on the reference's bin a + k.
    let scores: Vec<f64> = shifts
        .par_iter()
        .map(|&k| {
            (0..ELEVATION_BANDS)
                .map(|band| {
                    let (rb, qb) = (&r[band], &q[band]);
                    (0..bins)
                        .map(|a| qb[a as usize] * rb[(a + k).rem_euclid(bins) as usize])
                        .sum::<f64>()
                })
                .sum()
        })
        .collect();
    let n = shifts.len();
    let full = n == HEADING_BINS;
    let mut peaks: Vec<(f64, f64)> = (0..n)
        .filter(|&i| {
            let (l, r) = if full {
                (scores[(i + n - 1) % n], scores[(i + 1) % n])
            } else {
                (
                    if i > 0 { scores[i - 1] } else { f64::MIN },
                    if i + 1 < n { scores[i + 1] } else { f64::MIN },
                )
            };
            scores[i] > 0.0 && scores[i] >= l && scores[i] > r
        })
        .map(|i| {
            // The peak's heading, refined by a parabola through it and its neighbours.
            let at = |j: i64| scores[j.rem_euclid(n as i64) as usize];
            let (l, c, r) = (at(i as i64 - 1), scores[i], at(i as i64 + 1));
            let denominator = l - 2.0 * c + r;
            let delta = if full || (i > 0 && i + 1 < n) {
                if denominator < 0.0 {
                    (0.5 * (l - r) / denominator).clamp(-0.5, 0.5)
                } else {
                    0.0
                }
            } else {
                0.0
            };
            let heading = (shifts[i] as f64 + delta) * 2.0 * PI / bins as f64;
            (crate::geometry::wrap_pi(heading), c)
        })
        .collect();
    peaks.sort_by(|a, b| b.1.total_cmp(&a.1));
    let best = peaks.first().map_or(0.0, |p| p.1);
    peaks.retain(|p| p.1 >= MIN_HEADING_SHARE * best);
    peaks.truncate(count);
    peaks
}

/// Hypotheses scoring below this share of the best are dropped.
pub const MIN_HEADING_SHARE: f64 = 0.3;
/// Heading bins of the correlation (1°).
const HEADING_BINS: usize = 360;
/// Elevation bands of the levelled images: normals from the horizon to 80° above or below
/// it, in bands of 10°, folded (a surface and its opposite side count alike).
const ELEVATION_BANDS: usize = 8;

/// A levelled scan's oriented cells binned by the azimuth of their normal (1°) in bands of
/// elevation, area-weighted and smoothed along azimuth by a Gaussian of 2°. Normals within 10°
/// of the vertical carry no heading and are left out.
fn heading_image(cells: &[OrientedCell]) -> Vec<Vec<f64>> {
    let bins = HEADING_BINS;
    let band_width = 10f64.to_radians();
    let mut image = vec![vec![0.0; bins]; ELEVATION_BANDS];
    for c in cells {
        let n = c.normal;
        let elevation = n.z.clamp(-1.0, 1.0).asin().abs();
        let band = (elevation / band_width) as usize;
        if band >= ELEVATION_BANDS {
            continue;
        }
        let azimuth = n.y.atan2(n.x);
        let position = (azimuth + PI) / (2.0 * PI) * bins as f64;
        let bin = (position as usize).min(bins - 1);
        image[band][bin] += c.area;
    }
    let sigma_bins = 2.0;
    let reach = 6i64;
    let kernel: Vec<f64> = (-reach..=reach)
        .map(|d| (-(d * d) as f64 / (2.0 * sigma_bins * sigma_bins)).exp())
        .collect();
    image
        .into_iter()
        .map(|band| {
            (0..bins as i64)
                .map(|a| {
                    (-reach..=reach)
                        .map(|d| {
                            kernel[(d + reach) as usize]
                                * band[(a + d).rem_euclid(bins as i64) as usize]
                        })
                        .sum()
                })
                .collect()
        })
        .collect()
}

/// `cells` as seen in the frame `rotation` takes them to.
pub fn rotated(cells: &[OrientedCell], rotation: &Rotation3<f64>) -> Vec<OrientedCell> {
    cells
        .iter()
        .map(|c| OrientedCell {
            normal: rotation * c.normal,
            area: c.area,
        })
        .collect()
}

#[cfg(test)]
mod tests {
    use super::*;
    use crate::sdem::SdemConfig;

    /// A 6 × 5 × 2.5 m room seen from (0.4, −0.3, 0.6) by a sensor rotated by
    /// `sensor_from_world`.
    fn room(sensor_from_world: &Rotation3<f64>) -> Vec<Vec3> {
        let origin = Vec3::new(0.4, -0.3, 0.6);
        let (lo, hi) = (Vec3::new(-3.0, -2.0, 0.0), Vec3::new(3.0, 3.0, 2.5));
        let mut points = Vec::new();
        for i in 0..720 {
            for j in 1..360 {
                let d = crate::geometry::direction(
                    -PI + i as f64 * PI / 360.0,
                    -PI / 2.0 + j as f64 * PI / 360.0,
                );
                let t = (0..3)
                    .filter(|&k| d[k].abs() > 1e-9)
                    .map(|k| ((if d[k] > 0.0 { hi[k] } else { lo[k] }) - origin[k]) / d[k])
                    .fold(f64::INFINITY, f64::min);
                points.push(sensor_from_world * (d * t));
            }
        }
        points
    }

    #[test]
    fn finds_the_vertical_of_a_tilted_room() {
        for (roll, pitch) in [(0.0, 0.0), (25.0, -20.0), (-28.0, 28.0)] {
            let world_from_sensor = Attitude::from_degrees(roll, pitch, 40.0).rotation();
            let sdem = Sdem::from_points(
                &room(&world_from_sensor.inverse()),
                &Attitude::default(),
                &SdemConfig::default(),
            )
            .unwrap();
            let found = level_from_surfaces(&sdem, &Vec3::z(), 45f64.to_radians()).unwrap();
            let true_up = world_from_sensor.inverse() * Vec3::z();
            let error = found.up.angle(&true_up).to_degrees();
            assert!(error < 0.1, "roll {roll}, pitch {pitch}: {error:.3}° off");
            let levelled = found.attitude.rotation() * true_up;
            assert!(levelled.angle(&Vec3::z()).to_degrees() < 0.1);
            assert!(found.horizontal_share > 0.2 && found.vertical_share > 0.3);
        }
    }

    #[test]
    fn the_heading_between_two_levelled_rooms_is_among_the_hypotheses() {
        let config = SdemConfig::default();
        // The scan of a sensor at `world_from_sensor`: its cells in its levelled frame, and the
        // attitude that levels it.
        let levelled = |world_from_sensor: &Rotation3<f64>| {
            let sdem = Sdem::from_points(
                &room(&world_from_sensor.inverse()),
                &Attitude::default(),
                &config,
            )
            .unwrap();
            let level = level_from_surfaces(&sdem, &Vec3::z(), 45f64.to_radians()).unwrap();
            let cells = rotated(&oriented_cells(&sdem), &level.attitude.rotation());
            (cells, level.attitude.rotation())
        };
        let world_from_reference = Attitude::from_degrees(2.0, -3.0, 0.0).rotation();
        let (reference, reference_level) = levelled(&world_from_reference);
        for (roll, pitch, yaw) in [(10.0, -15.0, 25.0), (-25.0, 5.0, -140.0), (0.0, 0.0, 91.0)] {
            let world_from_query = Attitude::from_degrees(roll, pitch, yaw).rotation();
            let (query, query_level) = levelled(&world_from_query);
            // The rotation from the query's levelled frame to the reference's: a heading.
            let turn = reference_level
                * world_from_reference.inverse()
                * world_from_query
                * query_level.inverse();
            let heading = turn.euler_angles().2;
            let hypotheses = heading_hypotheses(&reference, &query, PI, 6);
            let nearest = (hypotheses.iter())
                .map(|(h, _)| crate::geometry::wrap_pi(h - heading).abs())
                .fold(f64::INFINITY, f64::min)
                .to_degrees();
            assert!(
                nearest < 0.5,
                "{yaw}°: nearest hypothesis {nearest:.2}° off, {hypotheses:?}"
            );
            assert!(!hypotheses.is_empty() && hypotheses.len() <= 6);
        }
    }

    #[test]
    fn walls_alone_give_no_levelling() {
        // Inside a vertical shaft of radius 2 m, seen within ±40° of elevation: walls all round,
        // no floor or ceiling in view. Nothing says which way is up within 30° of the sensor's
        // z axis, and the levelling must not make it up.
        let points: Vec<Vec3> = (0..360)
            .flat_map(|i| {
                (0..80).map(move |j| {
                    let (az, el) = ((i as f64).to_radians(), (j as f64 - 39.5).to_radians());
                    let wobble = 0.05 * (3.0 * az).sin();
                    crate::geometry::direction(az, el) * ((2.0 + wobble) / el.cos())
                })
            })
            .collect();
        let sdem =
            Sdem::from_points(&points, &Attitude::default(), &SdemConfig::default()).unwrap();
        assert!(oriented_cells(&sdem).len() > 10_000);
        assert_eq!(
            level_from_surfaces(&sdem, &Vec3::z(), 30f64.to_radians()),
            None
        );
    }
}
