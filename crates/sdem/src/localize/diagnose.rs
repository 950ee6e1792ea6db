//! What a match's figures say about it ([`super::Diagnostics`]): its overlap, runner-up,
//! covariance and the shape of its cost, and the doubts they raise, a prediction that
//! overrules the scans among them.

use super::{localize_below, CostConfig, Diagnostics, LocalizeOptions, SearchMode};
use crate::cost::{Correlator, CostModel};
use crate::doubt::Doubt;
use crate::error::Result;
use crate::geometry::{Attitude, Pose, Vec3};
use crate::refine::Refinement;
use crate::sdem::Sdem;
use nalgebra::{Matrix6, SymmetricEigen, UnitQuaternion, Vector3, U3};

/// The diagnostics of a match (overlap, runner-up, covariance) and its doubts. `refinement` is
/// the 6-DoF refinement's result when it converged, `refined_at` eq. (1) at its pose (`None`
/// where the scans share too few cells there); `refine_error` says why it failed, when it was
/// asked for and did. `cost_at(offset, refined)` is eq. (1) at `offset` with the query turned
/// by the refined rotation (`true`) or by the grid optimum's heading (`false`).
#[allow(clippy::too_many_arguments)]
pub(super) fn diagnose(
    config: &LocalizeOptions,
    query_known: usize,
    best: &crate::cost::Correlation,
    best_offset: Vec3,
    runner_up: Option<(f64, Vec3, f64)>,
    (refinement, refined_at): (Option<&Refinement>, Option<&crate::cost::Correlation>),
    refine_error: Option<&str>,
    cost_at: &mut dyn FnMut(Vec3, bool) -> f64,
) -> (Diagnostics, Vec<Doubt>) {
    let known = query_known.max(1) as f64;
    let inlier_fraction = best.inliers as f64 / known;
    let refined_inlier_fraction = refinement
        .is_some()
        .then(|| refined_at.map(|c| c.inliers as f64 / known))
        .flatten();
    let mut doubts = Vec::new();
    if let Some((c, at, _)) = runner_up {
        if c < config.ambiguous_cost_ratio * best.cost {
            doubts.push(Doubt::RunnerUp {
                distance_m: (at - best_offset).norm(),
                cost: c,
                best_cost: best.cost,
            });
        }
    }
    let covariance = refinement.and_then(|r| r.information.try_inverse());
    // Principal directions of the translational covariance (the axes without one).
    let eigen = covariance.as_ref().map(|cov| {
        let translation: nalgebra::Matrix3<f64> = cov.fixed_view::<3, 3>(0, 0).into_owned();
        translation.symmetric_eigen()
    });
    let (mut weakest, mut flat) = match &eigen {
        Some(eigen) => covariance_shape(eigen, config, &mut doubts),
        None => (None, None),
    };
    let weakest_support = refinement
        .zip(weakest)
        .map(|(r, (w, _, _))| r.support(&Vec3::from(w)));
    if let (Some(support), Some((w, _, _))) = (weakest_support, weakest) {
        if support < config.min_trusted_support {
            doubts.push(Doubt::Unconstrained {
                direction: w,
                facing_fraction: support,
                needed_fraction: config.min_trusted_support,
            });
            flat.get_or_insert(w);
        }
    }
    // The cost's shape is probed about the refined pose (with its tilt and heading), where there
    // is one, and about the grid optimum the search found; flat about either is a doubt. About
    // the refined pose: on the 2 cm grid a refined pose 8.6 cm from a wrong grid optimum (moved
    // rubble) lay on a slope of eq. (1) that the grid optimum hid. About the grid optimum: in a
    // corridor the refinement slides along the axis to where the two scans' samplings coincide,
    // a minimum of their pattern, not of the scene, while the grid optimum shows the valley flat.
    // On a grid as coarse as half the probe's distance (a LiDAR's) only the refined pose is
    // probed: the grid optimum may lie half a step from the cost's minimum, so that one probe
    // lies nearer the minimum than it does (on a 25 cm grid a street pair came out flat across
    // the street).
    let before = doubts.len();
    if let Some(r) = refinement {
        let centre = r.reference_level_from_query_level.translation.vector;
        let centre_cost = refined_at.map_or(f64::INFINITY, |c| c.cost);
        let mut about_refined = |o: Vec3| cost_at(o, true);
        cost_shape(
            config,
            centre_cost,
            centre,
            eigen.as_ref(),
            &mut about_refined,
            &mut weakest,
            &mut flat,
            &mut doubts,
            false,
            Some(r),
        );
    }
    let flat_found = doubts[before..]
        .iter()
        .any(|d| matches!(d, Doubt::FlatCost { .. }));
    let coarse = config.step_m >= 0.25 * config.peak_radius_m;
    let probe_grid = refinement.is_none() || !coarse;
    if probe_grid && !flat_found {
        let mut about_grid = |o: Vec3| cost_at(o, false);
        cost_shape(
            config,
            best.cost,
            best_offset,
            eigen.as_ref(),
            &mut about_grid,
            &mut weakest,
            &mut flat,
            &mut doubts,
            refinement.is_some(),
            refinement,
        );
    }
    // Too little in common, or the points did not confirm the grid's answer: on the fault
    // bench's failures (a query 0.45 m away seeing little of what the reference saw) 14–21 % of
    // the points matched, or the grid optimum was 10 cm off and the refinement refused to follow
    // it. Say so rather than return such a pose as if it were as good as the others.
    if refinement.is_some() && inlier_fraction < config.min_trusted_inlier_fraction {
        doubts.push(Doubt::FewInliers {
            fraction: inlier_fraction,
            trusted_from: config.min_trusted_inlier_fraction,
        });
    }
    if let Some(e) = refine_error {
        doubts.push(Doubt::RefinementFailed {
            reason: e.to_string(),
        });
    }
    let diagnostics = Diagnostics {
        overlap_fraction: best.overlap as f64 / known,
        inlier_fraction,
        refined_inlier_fraction,
        runner_up_cost: runner_up.map(|r| r.0),
        runner_up_cost_at_least: config
            .runner_up
            .then(|| runner_up.map_or(config.ambiguous_cost_ratio * best.cost, |r| r.0)),
        runner_up_offset: runner_up.map(|r| [r.1.x, r.1.y, r.1.z]),
        runner_up_heading_deg: runner_up.map(|r| r.2.to_degrees()),
        covariance: covariance.map(|c| std::array::from_fn(|i| std::array::from_fn(|j| c[(i, j)]))),
        weakest_direction: weakest.map(|w| w.0),
        weakest_sigma_m: weakest.map(|w| w.1),
        weakest_support,
        strongest_sigma_m: weakest.map(|w| w.2),
        flat_direction: flat,
        seen_through_fraction: 0.0,
        runner_up_slopes_passed: 0,
        ambiguous: doubts.iter().any(Doubt::is_ambiguity),
    };
    (diagnostics, doubts)
}

/// The weakest translational direction with its σ and the strongest σ.
type Weakest = Option<([f64; 3], f64, f64)>;

/// The shape of the refinement's translational covariance, from its principal directions
/// `eigen`: the weakest direction with its σ and the strongest σ, and that direction again
/// (the pose is free along it) when its σ exceeds the sigma ratio × the strongest, which is a
/// doubt.
fn covariance_shape(
    eigen: &SymmetricEigen<f64, U3>,
    config: &LocalizeOptions,
    doubts: &mut Vec<Doubt>,
) -> (Weakest, Option<[f64; 3]>) {
    let (mut i_max, mut i_min) = (0, 0);
    for i in 0..3 {
        if eigen.eigenvalues[i] > eigen.eigenvalues[i_max] {
            i_max = i;
        }
        if eigen.eigenvalues[i] < eigen.eigenvalues[i_min] {
            i_min = i;
        }
    }
    let v = eigen.eigenvectors.column(i_max).into_owned();
    let sigma_max = eigen.eigenvalues[i_max].max(0.0).sqrt();
    let sigma_min = eigen.eigenvalues[i_min].max(0.0).sqrt();
    let mut flat = None;
    if sigma_max > config.ambiguous_sigma_ratio * sigma_min {
        flat = Some([v.x, v.y, v.z]);
        doubts.push(Doubt::FlatCovariance {
            direction: [v.x, v.y, v.z],
            sigma_m: sigma_max,
            across_sigma_m: sigma_min,
        });
    }
    (Some(([v.x, v.y, v.z], sigma_max, sigma_min)), flat)
}

/// The share of the refined points' surface that must face a direction within 25° of the
/// vertical (each normal within 60° of it) for a flat eq. (1) along it to be no doubt ([`Refinement::support`]): a tenth, where a free
/// direction's is a few per cent (a corridor's axis seen from a small window: 3.5 %; the
/// `unconstrained` doubt fires below 1 %) and a floor and ceiling seen by a scanner that tilts
/// through them hold a fifth (3DTK's example scans: 19 %, where eq. (1) rose less than
/// 2·10⁻⁶ m² 5 cm up or down against 2.6·10⁻⁴ m² across the corridor).
pub const FLAT_COST_HELD_BY_SUPPORT: f64 = 0.1;

/// A direction within 25° of the vertical is "in height" for [`FLAT_COST_HELD_BY_SUPPORT`].
const VERTICAL_COS: f64 = 0.9;

/// The cost's own shape: how much it rises half the peak radius away from the optimum, along
/// the principal directions `eigen` (the axes without them). Flat along one direction and steep
/// along another is a corridor: a doubt, and the free direction when the covariance named none
/// and `weakest` agrees with it. With `only_where_weakest_agrees` (the grid optimum probed where
/// a refinement converged), a flatness across `weakest` is no doubt: the grid is searched at the
/// readings' tilt, and a tilt the refinement took out (1.5° on 3DTK's third scan, 1–3° from a
/// drifting gyro) can leave no floor point within `τ` at any height, a flatness in height the
/// refined pose does not share; a corridor's free axis is the refinement's weakest direction too.
#[allow(clippy::too_many_arguments)]
fn cost_shape(
    config: &LocalizeOptions,
    best_cost: f64,
    best_offset: Vec3,
    eigen: Option<&SymmetricEigen<f64, U3>>,
    cost_at: &mut dyn FnMut(Vec3) -> f64,
    weakest: &mut Weakest,
    flat: &mut Option<[f64; 3]>,
    doubts: &mut Vec<Doubt>,
    only_where_weakest_agrees: bool,
    refinement: Option<&Refinement>,
) {
    let directions: Vec<Vec3> = match eigen {
        Some(eigen) => (0..3)
            .map(|i| eigen.eigenvectors.column(i).into_owned())
            .collect(),
        None => vec![Vec3::x(), Vec3::y(), Vec3::z()],
    };
    let d = 0.5 * config.peak_radius_m;
    let rises: Vec<(f64, Vec3)> = directions
        .iter()
        .map(|v| {
            let rise = cost_at(best_offset + v * d).min(cost_at(best_offset - v * d)) - best_cost;
            (rise, *v)
        })
        .collect();
    // Flat in height where floors or ceilings the refinement matched face that way: eq. (1)
    // compares ranges, and a floor seen at a grazing angle (ahead of a scanner half a metre up)
    // changes its range along the ray by more than the truncation within one cell, so that a
    // shift in height moves few points in or out of `τ`; the points' planes hold the height.
    // Not across: walls face a scanner beside them, and a flat cost across them is a doubt (the
    // fault bench's moved rubble: a pose 10 cm off along x, flat there, with walls facing x).
    // A direction so held is left out, and the flattest of the others judged: a corridor flat
    // in height and along its axis still shows its axis.
    let held_by_floors = |v: &Vec3| {
        v.z.abs() >= VERTICAL_COS
            && refinement.is_some_and(|r| r.support(v) >= FLAT_COST_HELD_BY_SUPPORT)
    };
    let flattest = (rises.iter().cloned())
        .filter(|(_, v)| !held_by_floors(v))
        .fold((f64::INFINITY, Vec3::zeros()), |a, b| {
            if b.0 < a.0 {
                b
            } else {
                a
            }
        });
    let steepest = rises.iter().map(|r| r.0).fold(0.0, f64::max);
    let v = flattest.1;
    let agrees = weakest.is_none_or(|(w, _, _)| Vec3::from(w).dot(&v).abs() > 0.9);
    let flat_here = flattest.0 < config.ambiguous_rise_ratio * steepest;
    if flat_here && (agrees || !only_where_weakest_agrees) {
        doubts.push(Doubt::FlatCost {
            direction: [v.x, v.y, v.z],
            distance_m: d,
            rise: flattest.0.max(0.0),
            across_rise: steepest,
        });
        if weakest.is_none() {
            *weakest = Some(([v.x, v.y, v.z], f64::NAN, f64::NAN));
        }
        // The free direction only where the refinement's weakest direction agrees with it (or
        // there is none): the grid's cost alone can be flat where the refined pose is not.
        if flat.is_none() && agrees {
            *flat = Some([v.x, v.y, v.z]);
        }
    }
}

/// A doubt when the match tilted the query's levelled frame against the reference's by more than
/// the two attitude readings' roll and pitch allow (3σ of their difference): one of the gyros, or
/// the match, is wrong.
pub(super) fn attitude_corrected(
    level_rotation: &UnitQuaternion<f64>,
    reference: &Attitude,
    query: &Attitude,
) -> Option<Doubt> {
    let tilt = (level_rotation * Vector3::z()).angle(&Vector3::z());
    let sigma = reference.sigma.roll_pitch.hypot(query.sigma.roll_pitch);
    (tilt > 3.0 * sigma).then(|| Doubt::AttitudeCorrected {
        tilt_deg: tilt.to_degrees(),
        three_sigma_deg: 3.0 * sigma.to_degrees(),
    })
}

/// A covariance over `[x, y, z, rx, ry, rz]` on the levelled reference's axes, expressed on the
/// query sensor's axes: both blocks turned by the rotation `level_from_query`.
pub(super) fn in_query_frame(
    covariance_in_level: &Matrix6<f64>,
    level_from_query: &Pose,
) -> Matrix6<f64> {
    let r = level_from_query.rotation.to_rotation_matrix().into_inner();
    let mut query_from_level = Matrix6::zeros();
    query_from_level
        .fixed_view_mut::<3, 3>(0, 0)
        .copy_from(&r.transpose());
    query_from_level
        .fixed_view_mut::<3, 3>(3, 3)
        .copy_from(&r.transpose());
    query_from_level * covariance_in_level * query_from_level.transpose()
}

/// With a prediction in the cost ([`CostConfig::prior`]), a candidate that the scans alone
/// fit [`PRIOR_CONFLICT_RATIO`] times better than the optimum found (`data_cost`, eq. 1 at
/// `grid_offset` without the prediction's term), more than three of the prediction's σ from
/// it: the prediction, not the scans, chose the pose ([`Doubt::PriorConflict`]). `cost`: the
/// optimum's cost with the prediction's term. Searched exactly below that cost, and only where
/// the prediction's term rises across the window by more than the scans could gain (else the
/// search would have found such a place itself).
pub(super) fn prior_conflict(
    reference: &Sdem,
    query: &Sdem,
    config: &LocalizeOptions,
    correlator: &Correlator,
    grid_offset: &Vec3,
    cost: f64,
) -> Result<Option<Doubt>> {
    let Some(prior) = config.cost.prior else {
        return Ok(None);
    };
    let at_optimum = correlator.prior_cost(grid_offset);
    let data_cost = cost - at_optimum;
    let farthest = Vec3::from_fn(|axis, _| {
        let (lo, hi) = (config.window.min[axis], config.window.max[axis]);
        let o = prior.offset[axis];
        if (lo - o).abs() > (hi - o).abs() {
            lo
        } else {
            hi
        }
    });
    if correlator.prior_cost(&farthest) - at_optimum
        < data_cost * (1.0 - 1.0 / PRIOR_CONFLICT_RATIO)
    {
        return Ok(None);
    }
    let scans_alone = LocalizeOptions {
        cost: CostConfig {
            prior: None,
            ..config.cost.clone()
        },
        refine: false,
        runner_up: false,
        // The exact search finds the oracle's minimum; the oracle itself is not run twice.
        mode: match config.cost.model {
            CostModel::Projective => SearchMode::BranchAndBound,
            _ => config.mode,
        },
        ..config.clone()
    };
    let Some(found) = localize_below(
        reference,
        query,
        &scans_alone,
        data_cost / PRIOR_CONFLICT_RATIO,
    )?
    else {
        return Ok(None);
    };
    let from_prediction = (found.grid_offset - Vec3::from(prior.offset)).norm();
    Ok(
        (from_prediction > 3.0 * prior.sigma_m).then(|| Doubt::PriorConflict {
            distance_m: (found.grid_offset - grid_offset).norm(),
            cost: found.cost,
            best_cost: data_cost,
        }),
    )
}

/// [`Doubt::PriorConflict`]: a place the scans fit this many times better than the pose found
/// (eq. 1 at a right pose is the scans' noise and sampling; at a place 2× as costly they
/// disagree plainly, while along a corridor's axis, where only the prediction can say, it
/// varies by tens of per cent).
pub const PRIOR_CONFLICT_RATIO: f64 = 2.0;

#[cfg(test)]
mod tests {
    use super::*;
    use nalgebra::{Isometry3, Matrix6};

    /// A refinement whose matched surfaces face up or down for `vertical` of their area, the
    /// rest across (y).
    fn refined_with_vertical_share(vertical: f64) -> Refinement {
        let up = (vertical * 100.0).round() as usize;
        Refinement {
            reference_level_from_query_level: Isometry3::identity(),
            iterations: 5,
            converged: true,
            inliers: 100,
            rms_m: 0.005,
            information: Matrix6::identity(),
            supporting_normals: (0..100)
                .map(|i| {
                    (
                        if i < up {
                            [0.0, 0.0, 1.0]
                        } else {
                            [0.0, 1.0, 0.0]
                        },
                        1.0,
                    )
                })
                .collect(),
        }
    }

    /// Eq. (1) flat in height and steep across: a doubt where few matched surfaces face up,
    /// none where a fifth of them do (a floor seen at a grazing angle, whose ranges eq. (1)
    /// compares within a cell's spread while the points' planes hold the height). Flat across,
    /// however many surfaces face that way: a doubt.
    #[test]
    fn a_flat_cost_along_a_direction_the_surfaces_face_is_no_doubt() {
        let config = LocalizeOptions::default();
        // The doubts of eq. (1) shaped as `cost_at` about the origin, with `refinement`.
        let shape = |cost_at: &mut dyn FnMut(Vec3) -> f64, refinement: Option<&Refinement>| {
            let (mut weakest, mut flat, mut doubts) = (None, None, Vec::new());
            cost_shape(
                &config,
                cost_at(Vec3::zeros()),
                Vec3::zeros(),
                None,
                cost_at,
                &mut weakest,
                &mut flat,
                &mut doubts,
                false,
                refinement,
            );
            doubts
        };
        let mut flat_in_height = |o: Vec3| 1e-3 + 0.1 * (o.x * o.x + o.y * o.y) + 1e-4 * o.z * o.z;
        let few = shape(
            &mut flat_in_height,
            Some(&refined_with_vertical_share(0.03)),
        );
        assert!(
            matches!(few.as_slice(), [Doubt::FlatCost { direction, .. }] if direction[2].abs() > 0.99),
            "{few:?}"
        );
        assert!(shape(&mut flat_in_height, Some(&refined_with_vertical_share(0.2))).is_empty());
        // No refinement: the cost alone decides.
        assert_eq!(shape(&mut flat_in_height, None).len(), 1);
        // Flat in height and, a little less, along x (a corridor's axis): the axis is the doubt.
        let mut flat_both = |o: Vec3| 1e-3 + 2e-4 * o.x * o.x + 0.1 * o.y * o.y + 1e-4 * o.z * o.z;
        let doubts = shape(&mut flat_both, Some(&refined_with_vertical_share(0.2)));
        assert!(
            matches!(doubts.as_slice(), [Doubt::FlatCost { direction, .. }] if direction[0].abs() > 0.99),
            "{doubts:?}"
        );
        // Flat across (x), with as many surfaces facing x: a doubt all the same.
        let mut across = refined_with_vertical_share(0.0);
        for n in across.supporting_normals.iter_mut().take(20) {
            n.0 = [1.0, 0.0, 0.0];
        }
        let mut flat_across = |o: Vec3| 1e-3 + 1e-4 * o.x * o.x + 0.1 * (o.y * o.y + o.z * o.z);
        let doubts = shape(&mut flat_across, Some(&across));
        assert!(
            matches!(doubts.as_slice(), [Doubt::FlatCost { direction, .. }] if direction[0].abs() > 0.99),
            "{doubts:?}"
        );
    }
}
