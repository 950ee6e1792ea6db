//! Simulated odometry: dead reckoning from the true poses with seeded noise.
//!
//! A robot's wheel/track odometry measures each step between stops with an error that grows with
//! the step, and its heading error accumulates: dead reckoning drifts without bound. The dataset
//! file `odometry.txt` holds the dead-reckoned `world_from_sensor` of each scan; only the relative
//! motion between consecutive scans is meant to be used (see the dataset folder in `sdem_io`).

use nalgebra::{Translation3, UnitQuaternion, Vector3};
use rand::{Rng, SeedableRng};
use rand_chacha::ChaCha8Rng;
use rand_distr::StandardNormal;
use sdem::error::{Error, Result};
use sdem::geometry::Pose;
use serde::{Deserialize, Serialize};

/// The random stream of the odometry noise, apart from the simulator's per-stop streams
/// (`0, 1, 2, …`), so that adding odometry changes no scan.
const ODOMETRY_STREAM: u64 = 0x6f64_6f6d_6574_7279; // "odometry"

/// How noisy the simulated odometry is.
#[derive(Debug, Clone, Copy, PartialEq, Serialize, Deserialize)]
pub struct OdometryNoise {
    /// Per step and per axis, the translation error's standard deviation as a fraction of the
    /// step's length: N(0, `translation_frac · |step|`). Default 0.05, so a 35 cm step is off by
    /// about 2 cm per axis.
    pub translation_frac: f64,
    /// Per step, the standard deviation of the heading (yaw) error, degrees; it accumulates over
    /// the steps. Default 0.5°.
    pub yaw_deg_per_step: f64,
}

impl Default for OdometryNoise {
    fn default() -> Self {
        Self {
            translation_frac: 0.05,
            yaw_deg_per_step: 0.5,
        }
    }
}

impl OdometryNoise {
    /// Checks that both values are finite and not negative.
    pub fn validate(&self) -> Result<()> {
        for (name, value) in [
            ("translation_frac", self.translation_frac),
            ("yaw_deg_per_step", self.yaw_deg_per_step),
        ] {
            if !(value.is_finite() && value >= 0.0) {
                return Err(Error::Invalid(format!(
                    "odometry noise {name} is {value}; it must be a finite number ≥ 0"
                )));
            }
        }
        Ok(())
    }
}

/// Dead-reckoned poses from true ones: the first pose is the truth, then each true step
/// `step_i = world_from_sensor[i-1]⁻¹ · world_from_sensor[i]` (in the previous sensor frame) is
/// measured with noise and chained onto the previous dead-reckoned pose:
///
/// - translation: `step_i.t + n`, `n ~ N(0, (translation_frac · |step_i.t|)²)` per axis;
/// - heading: the step's rotation is followed by a turn of `ε ~ N(0, yaw_deg_per_step²)` about
///   the sensor's z axis. Chained, heading errors add up and bend all later steps: the drift of
///   dead reckoning.
///
/// Pure and seeded: the noise comes from `ChaCha8Rng::seed_from_u64(seed)` on a stream of its
/// own, so the same seed gives the same poses on every machine.
///
/// # Arguments
/// * `world_from_sensor` — the true poses, in stop order.
/// * `noise` — the noise levels ([`OdometryNoise::default`]: 5 % of each step, 0.5° per step).
/// * `seed` — the random seed.
///
/// # Returns
/// One dead-reckoned `world_from_sensor` per input pose (empty for no poses).
///
/// # Errors
/// [`Error::Invalid`] for negative or non-finite noise levels.
///
/// # Example
/// ```
/// use sdem::geometry::Pose;
/// use sdem_sim::odometry::{simulate_odometry, OdometryNoise};
/// let truth: Vec<Pose> = (0..5).map(|i| Pose::translation(0.35 * i as f64, 0.0, 0.0)).collect();
/// let odometry = simulate_odometry(&truth, &OdometryNoise::default(), 7).unwrap();
/// assert_eq!(odometry[0], truth[0]);
/// let drift = (odometry[4].translation.vector - truth[4].translation.vector).norm();
/// assert!(drift > 0.0 && drift < 0.3);
/// assert_eq!(odometry, simulate_odometry(&truth, &OdometryNoise::default(), 7).unwrap());
/// ```
pub fn simulate_odometry(
    world_from_sensor: &[Pose],
    noise: &OdometryNoise,
    seed: u64,
) -> Result<Vec<Pose>> {
    noise.validate()?;
    let mut rng = ChaCha8Rng::seed_from_u64(seed);
    rng.set_stream(ODOMETRY_STREAM);
    let yaw_sigma = noise.yaw_deg_per_step.to_radians();
    let mut odometry = Vec::with_capacity(world_from_sensor.len());
    let Some(first) = world_from_sensor.first() else {
        return Ok(odometry);
    };
    odometry.push(*first);
    for pair in world_from_sensor.windows(2) {
        let step = pair[0].inverse() * pair[1];
        let t = step.translation.vector;
        let sigma = noise.translation_frac * t.norm();
        let n = Vector3::new(
            rng.sample::<f64, _>(StandardNormal),
            rng.sample::<f64, _>(StandardNormal),
            rng.sample::<f64, _>(StandardNormal),
        ) * sigma;
        let yaw_error: f64 = rng.sample::<f64, _>(StandardNormal) * yaw_sigma;
        let measured = Pose::from_parts(
            Translation3::from(t + n),
            step.rotation * UnitQuaternion::from_axis_angle(&Vector3::z_axis(), yaw_error),
        );
        let previous = *odometry.last().expect("the first pose was pushed");
        odometry.push(previous * measured);
    }
    Ok(odometry)
}

#[cfg(test)]
mod tests {
    use super::*;
    use sdem::geometry::{attitude_of, pose_from_parts, Attitude, Vec3};

    fn straight_run(steps: usize, step_m: f64) -> Vec<Pose> {
        (0..=steps)
            .map(|i| {
                pose_from_parts(
                    Vec3::new(step_m * i as f64, 0.0, 0.3),
                    Attitude::from_degrees(1.0, -2.0, 15.0),
                )
            })
            .collect()
    }

    #[test]
    fn noise_free_odometry_is_the_truth() {
        let truth = straight_run(6, 0.35);
        let zero = OdometryNoise {
            translation_frac: 0.0,
            yaw_deg_per_step: 0.0,
        };
        let odometry = simulate_odometry(&truth, &zero, 3).unwrap();
        for (o, t) in odometry.iter().zip(&truth) {
            let (dt, dr) = sdem::geometry::pose_error(t, o);
            assert!(dt < 1e-12 && dr < 1e-12);
        }
        assert!(simulate_odometry(&[], &zero, 3).unwrap().is_empty());
    }

    #[test]
    fn step_errors_match_the_noise_model() {
        // Many independent single steps of 0.35 m: translation error ~ N(0, 0.0175) per axis,
        // heading error ~ N(0, 0.5°).
        let truth = straight_run(1, 0.35);
        let noise = OdometryNoise::default();
        let (mut sum_sq, mut yaw_sq) = (0.0, 0.0);
        let runs = 2000;
        for seed in 0..runs {
            let odometry = simulate_odometry(&truth, &noise, seed).unwrap();
            let step = odometry[0].inverse() * odometry[1];
            let true_step = truth[0].inverse() * truth[1];
            sum_sq += (step.translation.vector - true_step.translation.vector).norm_squared();
            let dyaw = attitude_of(&(true_step.inverse() * step)).yaw;
            yaw_sq += dyaw * dyaw;
        }
        let per_axis = (sum_sq / (3.0 * runs as f64)).sqrt();
        assert!((per_axis - 0.0175).abs() < 0.0015, "{per_axis}");
        let yaw_deg = (yaw_sq / runs as f64).sqrt().to_degrees();
        assert!((yaw_deg - 0.5).abs() < 0.05, "{yaw_deg}");
    }

    #[test]
    fn heading_drift_accumulates_and_is_seeded() {
        let truth = straight_run(30, 0.35);
        let noise = OdometryNoise {
            translation_frac: 0.0,
            yaw_deg_per_step: 0.5,
        };
        let a = simulate_odometry(&truth, &noise, 11).unwrap();
        assert_eq!(a, simulate_odometry(&truth, &noise, 11).unwrap());
        assert_ne!(a, simulate_odometry(&truth, &noise, 12).unwrap());
        // Step lengths are exact without translation noise.
        for w in a.windows(2) {
            let d = (w[1].translation.vector - w[0].translation.vector).norm();
            assert!((d - 0.35).abs() < 1e-9);
        }
        // The heading errors add up: after k steps of N(0, 0.5°) each the heading is off by
        // N(0, 0.5° √k), and the position drifts sideways as the errors bend the later steps:
        // by 0.35 m · Σ_{j<k} (k − j) ε_j, of σ 0.35 m · 0.5° · √((k−1)k(2k−1)/6) (none after
        // the first step, which the first pose's heading measures). Over 400 seeds the RMS
        // estimates each σ within 12 % (3.4 of its standard errors, 1/√800).
        let seeds = 400;
        let (mut heading_sq, mut drift_sq) = ([0.0f64; 31], [0.0f64; 31]);
        for seed in 0..seeds {
            let odometry = simulate_odometry(&truth, &noise, seed).unwrap();
            for k in 0..=30 {
                let error = truth[k].inverse() * odometry[k];
                heading_sq[k] += error.rotation.angle().powi(2);
                drift_sq[k] += error.translation.vector.norm_squared();
            }
        }
        let rms = |sum_sq: f64| (sum_sq / seeds as f64).sqrt();
        assert!(heading_sq[0] < 1e-20 && drift_sq[0] < 1e-20 && drift_sq[1] < 1e-20);
        for k in [1usize, 4, 10, 30] {
            let n = k as f64;
            let heading_deg = rms(heading_sq[k]).to_degrees();
            let expected_deg = 0.5 * n.sqrt();
            assert!(
                (heading_deg / expected_deg - 1.0).abs() < 0.12,
                "step {k}: heading off by {heading_deg}° RMS, expected {expected_deg}°"
            );
            let drift = rms(drift_sq[k]);
            if k == 1 {
                continue;
            }
            let expected =
                0.35 * 0.5f64.to_radians() * ((n - 1.0) * n * (2.0 * n - 1.0) / 6.0).sqrt();
            assert!(
                (drift / expected - 1.0).abs() < 0.12,
                "step {k}: {drift} m off RMS, expected {expected} m"
            );
        }
    }

    #[test]
    fn invalid_noise_is_refused() {
        for noise in [
            OdometryNoise {
                translation_frac: -0.1,
                ..Default::default()
            },
            OdometryNoise {
                yaw_deg_per_step: f64::NAN,
                ..Default::default()
            },
        ] {
            assert!(simulate_odometry(&straight_run(2, 0.3), &noise, 0).is_err());
        }
    }
}
