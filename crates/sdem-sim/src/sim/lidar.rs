//! A spinning multi-beam LiDAR (Velodyne-, Ouster-like): rings of beams at fixed elevations
//! turning a full circle, one scan per turn, the sensor standing still while it turns.
//!
//! The tilting laser range finder of the paper ([`super::scan`]) sees the front half of the
//! sphere at 1° steps to 8 m; this one sees all around, within a band of elevations, to 100 m,
//! with a finer azimuth step and a coarser elevation step, as street and hall scans of today's
//! sensors do.

use super::scene::Scene;
use rand::{Rng, SeedableRng};
use rand_chacha::ChaCha8Rng;
use rand_distr::StandardNormal;
use rayon::prelude::*;
use sdem::error::{Error, Result};
use sdem::geometry::{Pose, Vec3};

/// A spinning LiDAR: `rings` beams spread evenly from `elevation_min_deg` to
/// `elevation_max_deg`, each fired every `azimuth_step_deg` over a full turn.
#[derive(Debug, Clone, PartialEq, serde::Serialize, serde::Deserialize)]
pub struct LidarConfig {
    /// Number of rings (beams stacked in elevation).
    pub rings: usize,
    /// Elevation of the lowest ring, degrees (negative: below the horizon).
    pub elevation_min_deg: f64,
    /// Elevation of the highest ring, degrees.
    pub elevation_max_deg: f64,
    /// Azimuth step between firings, degrees.
    pub azimuth_step_deg: f64,
    /// The horizontal field of view, degrees, centred on the sensor's +x: 360 for a spinning
    /// LiDAR, 60–120 for a solid-state one (Livox, the forward units of an Ouster or Hesai).
    pub azimuth_fov_deg: f64,
    /// Largest range returned, metres; beyond it, no return.
    pub max_range_m: f64,
    /// Returns closer than this are dropped (the vehicle itself), metres.
    pub min_range_m: f64,
    /// Standard deviation of the Gaussian range noise, metres.
    pub range_noise_m: f64,
}

impl Default for LidarConfig {
    /// 32 rings from −25° to +15°, 0.2° azimuth step (57,600 beams a turn), 100 m range, 0.5 m
    /// minimum range, 2 cm range noise: a 32-beam Velodyne/Ouster class sensor.
    fn default() -> Self {
        Self {
            rings: 32,
            elevation_min_deg: -25.0,
            elevation_max_deg: 15.0,
            azimuth_step_deg: 0.2,
            azimuth_fov_deg: 360.0,
            max_range_m: 100.0,
            min_range_m: 0.5,
            range_noise_m: 0.02,
        }
    }
}

impl LidarConfig {
    /// Checks every field; the message names the field.
    ///
    /// # Errors
    /// [`Error::Invalid`] for fewer than 2 rings, elevations outside ±90° or not increasing, an
    /// azimuth step outside (0°, 90°], or a negative, non-finite or inverted range or noise.
    pub fn validate(&self) -> Result<()> {
        let bad = |what: String| Err(Error::Invalid(format!("lidar: {what}")));
        if self.rings < 2 {
            return bad(format!("{} rings; it needs at least 2", self.rings));
        }
        let (lo, hi) = (self.elevation_min_deg, self.elevation_max_deg);
        if !(lo.is_finite() && hi.is_finite() && -90.0 <= lo && lo < hi && hi <= 90.0) {
            return bad(format!(
                "elevations {lo}°..{hi}° must increase and lie within ±90°"
            ));
        }
        if !(self.azimuth_fov_deg > 0.0 && self.azimuth_fov_deg <= 360.0) {
            return bad(format!(
                "azimuth field of view {}° must lie in (0, 360]",
                self.azimuth_fov_deg
            ));
        }
        if !(self.azimuth_step_deg > 0.0 && self.azimuth_step_deg <= 90.0) {
            return bad(format!(
                "azimuth step {}° must lie in (0, 90]",
                self.azimuth_step_deg
            ));
        }
        let ranges_ok = self.min_range_m.is_finite()
            && self.min_range_m >= 0.0
            && self.max_range_m.is_finite()
            && self.max_range_m > self.min_range_m;
        if !ranges_ok {
            return bad(format!(
                "ranges {} m..{} m must be finite, >= 0 and increasing",
                self.min_range_m, self.max_range_m
            ));
        }
        if !(self.range_noise_m.is_finite() && self.range_noise_m >= 0.0) {
            return bad(format!(
                "range noise {} m must be a finite number >= 0",
                self.range_noise_m
            ));
        }
        Ok(())
    }

    /// The rings' elevations, degrees, lowest first.
    pub fn ring_elevations_deg(&self) -> Vec<f64> {
        let n = self.rings.max(2);
        let step = (self.elevation_max_deg - self.elevation_min_deg) / (n - 1) as f64;
        (0..n)
            .map(|i| self.elevation_min_deg + i as f64 * step)
            .collect()
    }

    /// The solid-state sensor of [`crate::suites::SuiteConfig::solid_state_lidar`]: 64 rows
    /// from −35° to +35°, 0.2° apart in azimuth over a 70° field of view (~22,000 beams), 100 m,
    /// 2 cm of noise; a forward-looking unit of the Livox class, on a regular pattern.
    pub fn solid_state() -> Self {
        Self {
            rings: 64,
            elevation_min_deg: -35.0,
            elevation_max_deg: 35.0,
            azimuth_fov_deg: 70.0,
            ..Self::default()
        }
    }

    /// The firing azimuths of one frame, degrees: a full turn from −180° on, or the field of
    /// view, centred on 0°.
    pub fn azimuths_deg(&self) -> Vec<f64> {
        if self.azimuth_fov_deg >= 360.0 {
            let n = (360.0 / self.azimuth_step_deg).round().max(1.0) as usize;
            return (0..n)
                .map(|i| -180.0 + i as f64 * 360.0 / n as f64)
                .collect();
        }
        let n = (self.azimuth_fov_deg / self.azimuth_step_deg)
            .round()
            .max(1.0) as usize;
        let step = self.azimuth_fov_deg / n as f64;
        (0..=n)
            .map(|i| -0.5 * self.azimuth_fov_deg + i as f64 * step)
            .collect()
    }

    /// True when a beam along `direction_in_sensor` (a unit vector) lies within the rings'
    /// band of elevations (half a ring spacing beyond the outer rings) and the field of view
    /// (half an azimuth step beyond its edges).
    pub fn sees(&self, direction_in_sensor: &Vec3) -> bool {
        let elevation = direction_in_sensor.z.clamp(-1.0, 1.0).asin().to_degrees();
        let half = 0.5 * (self.elevation_max_deg - self.elevation_min_deg)
            / (self.rings.max(2) - 1) as f64;
        let azimuth = direction_in_sensor
            .y
            .atan2(direction_in_sensor.x)
            .to_degrees();
        (self.elevation_min_deg - half..=self.elevation_max_deg + half).contains(&elevation)
            && (self.azimuth_fov_deg >= 360.0
                || azimuth.abs() <= 0.5 * (self.azimuth_fov_deg + self.azimuth_step_deg))
    }
}

/// The unit beam of a spinning LiDAR at `elevation` and `azimuth` (radians), sensor frame:
/// x forward, y left, z up.
pub fn lidar_beam(elevation: f64, azimuth: f64) -> Vec3 {
    let (se, ce) = elevation.sin_cos();
    let (sa, ca) = azimuth.sin_cos();
    Vec3::new(ce * ca, ce * sa, se)
}

/// Simulates one turn of a spinning LiDAR at `world_from_sensor`: the returns as points in the
/// sensor frame, metres, ring by ring, lowest ring first.
///
/// Each beam `world_from_sensor.rotation · lidar_beam(elevation, azimuth)` is cast from the
/// sensor's origin; its range gets N(0, `range_noise_m`) noise and the beam is dropped when it
/// hits nothing within `max_range_m` or the noisy range lies outside
/// `[min_range_m, max_range_m]`.
///
/// Draws one seed per ring from `rng`; each ring's noise comes from its own `ChaCha8Rng`, so
/// the rings run in parallel and the result does not depend on the number of threads.
///
/// # Errors
/// [`Error::Invalid`] for an invalid `config` ([`LidarConfig::validate`]).
pub fn spin_scan(
    scene: &Scene,
    config: &LidarConfig,
    world_from_sensor: &Pose,
    rng: &mut impl Rng,
) -> Result<Vec<Vec3>> {
    config.validate()?;
    let elevations = config.ring_elevations_deg();
    let seeds: Vec<u64> = elevations.iter().map(|_| rng.random()).collect();
    let azimuths: Vec<f64> = config
        .azimuths_deg()
        .iter()
        .map(|a| a.to_radians())
        .collect();
    let origin = world_from_sensor.translation.vector;
    let rings: Vec<Vec<Vec3>> = elevations
        .par_iter()
        .zip(seeds.par_iter())
        .map(|(&elevation_deg, &seed)| {
            let mut ring_rng = ChaCha8Rng::seed_from_u64(seed);
            let elevation = elevation_deg.to_radians();
            azimuths
                .iter()
                .filter_map(|&azimuth| {
                    let beam = lidar_beam(elevation, azimuth);
                    let noise: f64 = ring_rng.sample(StandardNormal);
                    let hit = scene.raycast(
                        &origin,
                        &(world_from_sensor.rotation * beam),
                        config.max_range_m,
                    )?;
                    let range = hit + noise * config.range_noise_m;
                    (config.min_range_m..=config.max_range_m)
                        .contains(&range)
                        .then_some(beam * range)
                })
                .collect()
        })
        .collect();
    Ok(rings.concat())
}
