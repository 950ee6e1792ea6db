//! How far an estimated trajectory lies from a reference one (absolute and relative pose errors).

use crate::error::{Error, Result};
use crate::geometry::{Pose, Vec3};
use nalgebra::Matrix3;
use serde::Serialize;

/// Errors of an estimated trajectory against a reference one (the same scans, in order).
#[derive(Debug, Clone, PartialEq, Serialize)]
pub struct TrajectoryErrors {
    /// Poses compared.
    pub poses: usize,
    /// Absolute trajectory error, RMSE of the positions after the best rigid alignment
    /// (Umeyama, no scale, as `evo_ape -a`), metres.
    pub ate_rmse_m: f64,
    /// Largest aligned position error, metres.
    pub ate_max_m: f64,
    /// Absolute error of the positions with no alignment (both start at the world origin),
    /// RMSE, metres.
    pub unaligned_rmse_m: f64,
    /// Relative pose error between consecutive scans: RMSE of the translation error, metres.
    pub rpe_translation_rmse_m: f64,
    /// … and of the rotation error, degrees.
    pub rpe_rotation_rmse_deg: f64,
    /// Per pose: aligned position error, metres.
    pub position_errors_m: Vec<f64>,
    /// Per pose, with no alignment (both in the same world frame): position error, metres.
    pub unaligned_position_errors_m: Vec<f64>,
    /// Per pose, with no alignment: rotation error, degrees.
    pub rotation_errors_deg: Vec<f64>,
}

/// Compares `estimate` with `reference` (ground truth, or another method's poses), pose by
/// pose. The arguments come in the order of [`crate::geometry::pose_error`]'s: the reference
/// first.
///
/// # Errors
/// Different lengths or no pose.
pub fn trajectory_errors(reference: &[Pose], estimate: &[Pose]) -> Result<TrajectoryErrors> {
    let Aligned {
        estimate: p,
        reference: q,
        rotation,
        translation,
    } = Aligned::new(reference, estimate, "compare")?;
    let n = estimate.len();
    let position_errors_m: Vec<f64> = p
        .iter()
        .zip(&q)
        .map(|(a, b)| (rotation * a + translation - b).norm())
        .collect();
    let rmse = |v: &mut dyn Iterator<Item = f64>| {
        let (s, c) = v.fold((0.0, 0usize), |(s, c), e| (s + e * e, c + 1));
        if c == 0 {
            0.0
        } else {
            (s / c as f64).sqrt()
        }
    };
    let ate_rmse_m = rmse(&mut position_errors_m.iter().copied());
    let ate_max_m = position_errors_m.iter().copied().fold(0.0, f64::max);
    let unaligned_rmse_m = rmse(&mut p.iter().zip(&q).map(|(a, b)| (a - b).norm()));
    let relative: Vec<(f64, f64)> = (1..n)
        .map(|i| {
            let de = estimate[i - 1].inverse() * estimate[i];
            let dr = reference[i - 1].inverse() * reference[i];
            let e = dr.inverse() * de;
            (e.translation.vector.norm(), e.rotation.angle().to_degrees())
        })
        .collect();
    Ok(TrajectoryErrors {
        poses: n,
        ate_rmse_m,
        ate_max_m,
        unaligned_rmse_m,
        rpe_translation_rmse_m: rmse(&mut relative.iter().map(|r| r.0)),
        rpe_rotation_rmse_deg: rmse(&mut relative.iter().map(|r| r.1)),
        position_errors_m,
        unaligned_position_errors_m: p.iter().zip(&q).map(|(a, b)| (a - b).norm()).collect(),
        rotation_errors_deg: estimate
            .iter()
            .zip(reference)
            .map(|(e, r)| e.rotation.angle_to(&r.rotation).to_degrees())
            .collect(),
    })
}

/// The rigid motion that carries `estimate`'s positions onto `reference`'s best in the
/// least-squares sense (Umeyama, no scale; the alignment of [`TrajectoryErrors::ate_rmse_m`]):
/// the truth's view of the frame an estimate is in. A second run's stops are scored in the
/// first run's frame by the alignment of the first run's stops alone.
///
/// # Errors
/// Different lengths or no pose.
pub fn alignment(reference: &[Pose], estimate: &[Pose]) -> Result<Pose> {
    let aligned = Aligned::new(reference, estimate, "align")?;
    let rotation = nalgebra::UnitQuaternion::from_matrix(&aligned.rotation);
    Ok(Pose::from_parts(aligned.translation.into(), rotation))
}

/// The positions of an estimated and a reference trajectory, and the rotation and
/// translation that carry the first onto the second best ([`umeyama`]).
struct Aligned {
    estimate: Vec<Vec3>,
    reference: Vec<Vec3>,
    rotation: Matrix3<f64>,
    translation: Vec3,
}

impl Aligned {
    /// Refuses (to `verb` them) trajectories of different lengths, or with no pose.
    fn new(reference: &[Pose], estimate: &[Pose], verb: &str) -> Result<Self> {
        if estimate.len() != reference.len() || estimate.is_empty() {
            return Err(Error::Invalid(format!(
                "cannot {verb} {} estimated poses with {} reference poses",
                estimate.len(),
                reference.len()
            )));
        }
        let p: Vec<Vec3> = estimate.iter().map(|t| t.translation.vector).collect();
        let q: Vec<Vec3> = reference.iter().map(|t| t.translation.vector).collect();
        let (rotation, translation) = umeyama(&p, &q);
        Ok(Self {
            estimate: p,
            reference: q,
            rotation,
            translation,
        })
    }
}

/// The rotation and translation that carry `from` onto `to` best in the least-squares sense
/// (Umeyama 1991, without scale).
fn umeyama(from: &[Vec3], to: &[Vec3]) -> (Matrix3<f64>, Vec3) {
    let n = from.len() as f64;
    let mean_from = from.iter().sum::<Vec3>() / n;
    let mean_to = to.iter().sum::<Vec3>() / n;
    if from.len() < 3 {
        return (Matrix3::identity(), mean_to - mean_from);
    }
    let mut h = Matrix3::zeros();
    for (a, b) in from.iter().zip(to) {
        h += (b - mean_to) * (a - mean_from).transpose();
    }
    let svd = h.svd(true, true);
    let (Some(u), Some(v_t)) = (svd.u, svd.v_t) else {
        return (Matrix3::identity(), mean_to - mean_from);
    };
    let mut d = Matrix3::identity();
    if (u * v_t).determinant() < 0.0 {
        d[(2, 2)] = -1.0;
    }
    let rotation = u * d * v_t;
    (rotation, mean_to - rotation * mean_from)
}

#[cfg(test)]
mod tests {
    use super::*;
    use nalgebra::{Translation3, UnitQuaternion};

    #[test]
    fn the_alignment_is_the_motion_between_the_frames() {
        // A winding trajectory, and the same one seen from a frame turned by 7° and shifted.
        let truth: Vec<Pose> = (0..12)
            .map(|i| {
                let t = i as f64 * 0.4;
                Pose::from_parts(
                    Translation3::new(t, (t * 0.9).sin(), 0.1 * t),
                    UnitQuaternion::from_euler_angles(0.0, 0.0, 0.3 * t),
                )
            })
            .collect();
        let frame = Pose::from_parts(
            Translation3::new(0.5, -1.2, 0.3),
            UnitQuaternion::from_euler_angles(0.01, -0.02, 7f64.to_radians()),
        );
        let estimate: Vec<Pose> = truth.iter().map(|p| frame.inverse() * p).collect();
        let found = alignment(&truth, &estimate).unwrap();
        let (dt, dr) = crate::geometry::pose_error(&frame, &found);
        assert!(dt < 1e-9 && dr < 1e-9, "{dt} m, {dr} rad off");
        assert!(alignment(&truth, &estimate[..3]).is_err());
    }
}
