//! A spinning multi-beam LiDAR (a Velodyne, an Ouster) and a street to scan with it: real
//! scanners' scans, simulated, for the tests and benchmarks of `sdem` on them.

use super::scene::Scene;
use super::solids::{Ellipsoid, OrientedBox, Solid};
use super::{aabb, yaw_rotation, yawed_box};
use nalgebra::Rotation3;
use rand::{Rng, SeedableRng};
use rand_chacha::ChaCha8Rng;
use rand_distr::StandardNormal;
use rayon::prelude::*;
use sdem::geometry::{direction, Pose, Vec3};

/// A spinning multi-beam LiDAR: lasers fanned evenly in elevation, all firing at each azimuth
/// step of a full turn, from a sensor that stands still while it turns (or scans de-skewed).
#[derive(Debug, Clone, PartialEq)]
pub struct SpinningLidar {
    /// Number of lasers.
    pub lasers: usize,
    /// Elevation of the lowest laser, degrees.
    pub elevation_min_deg: f64,
    /// Elevation of the highest laser, degrees.
    pub elevation_max_deg: f64,
    /// Azimuth between two firings, degrees.
    pub azimuth_step_deg: f64,
    /// Returns beyond this are lost, metres.
    pub max_range_m: f64,
    /// Standard deviation of the Gaussian range noise, metres.
    pub range_noise_m: f64,
}

impl SpinningLidar {
    /// About a Velodyne HDL-64E (KITTI's): 64 lasers from −24.9° to +2°, a firing every 0.17°,
    /// 120 m, 2 cm of noise: some 135,000 rays a turn.
    pub fn hdl64() -> Self {
        Self {
            lasers: 64,
            elevation_min_deg: -24.9,
            elevation_max_deg: 2.0,
            azimuth_step_deg: 0.17,
            max_range_m: 120.0,
            range_noise_m: 0.02,
        }
    }

    /// About a 32-beam scanner (Velodyne HDL-32E: −30.7° to +10.7°, 1.33° apart), a firing every
    /// 0.4°: some 29,000 rays a turn.
    pub fn hdl32() -> Self {
        Self {
            lasers: 32,
            elevation_min_deg: -30.67,
            elevation_max_deg: 10.67,
            azimuth_step_deg: 0.4,
            max_range_m: 100.0,
            range_noise_m: 0.02,
        }
    }

    /// The unit direction of every ray of a turn, sensor frame: laser by laser, each a full turn
    /// from azimuth −180°.
    pub fn directions(&self) -> Vec<Vec3> {
        let firings = (360.0 / self.azimuth_step_deg).round().max(1.0) as usize;
        let spread = self.elevation_max_deg - self.elevation_min_deg;
        (0..self.lasers)
            .flat_map(|l| {
                let el =
                    self.elevation_min_deg + spread * l as f64 / (self.lasers.max(2) - 1) as f64;
                (0..firings).map(move |k| {
                    let az = -180.0 + k as f64 * 360.0 / firings as f64;
                    direction(az.to_radians(), el.to_radians())
                })
            })
            .collect()
    }
}

/// One turn of `lidar` at `world_from_sensor` in `scene`: the returns, sensor frame, metres,
/// with N(0, `range_noise_m`) noise on each range; rays that hit nothing within `max_range_m`
/// give no point. Seeded: the same `seed` gives the same points on any number of threads.
pub fn spinning_scan(
    scene: &Scene,
    lidar: &SpinningLidar,
    world_from_sensor: &Pose,
    seed: u64,
) -> Vec<Vec3> {
    let origin = world_from_sensor.translation.vector;
    let directions = lidar.directions();
    directions
        .par_chunks(4096)
        .enumerate()
        .flat_map_iter(|(chunk, rays)| {
            let mut rng = ChaCha8Rng::seed_from_u64(seed);
            rng.set_stream(chunk as u64);
            rays.iter()
                .filter_map(|d| {
                    let noise: f64 = rng.sample(StandardNormal);
                    let world = world_from_sensor.rotation * d;
                    let hit = scene.raycast(&origin, &world, lidar.max_range_m)?;
                    let range = hit + noise * lidar.range_noise_m;
                    (range > 0.0).then(|| d * range)
                })
                .collect::<Vec<_>>()
        })
        .collect()
}

/// Height of the sensor above the road of [`street`], metres (KITTI's Velodyne: 1.73 m).
pub const STREET_SENSOR_HEIGHT_M: f64 = 1.73;

/// A street 100 m long along x (x ∈ [−50, 50]) between two rows of houses 22 m apart
/// (y ∈ [−11, 11]), the road at `z = −STREET_SENSOR_HEIGHT_M`, seeded: façades with doorways
/// and bays, parked cars along both kerbs, lamp posts, trees (a trunk and an ellipsoid crown)
/// and bins, so that, as in a real street, the scans fix the position along it only through
/// what stands beside it. The world origin is on the road's centre line, at the sensor's height.
pub fn street(seed: u64) -> Scene {
    let mut rng = ChaCha8Rng::seed_from_u64(seed);
    let g = -STREET_SENSOR_HEIGHT_M;
    let top = g + 14.0;
    let mut scene = Scene::new();
    scene.add_free(aabb([-50.0, -11.0, g], [50.0, 11.0, top]));
    // Façades: doorways and recesses as air beyond the wall line, bays as solids before it.
    for side in [-1.0f64, 1.0] {
        let mut x = -50.0;
        while x < 48.0 {
            let width = rng.random_range(1.0..4.0);
            let depth = rng.random_range(0.3..1.5);
            let height = rng.random_range(2.2..8.0);
            let (y0, y1) = (side * 11.0, side * (11.0 + depth));
            scene.add_free(aabb(
                [x, y0.min(y1), g],
                [x + width, y0.max(y1), g + height],
            ));
            let gap = rng.random_range(2.0..7.0);
            let bay = rng.random_range(0.3..0.9);
            let bay_x = x + width + 0.5 * gap;
            let bay_z = g + rng.random_range(2.5..5.0);
            scene.add_solid(Solid::Box(yawed_box(
                [bay_x, side * (11.0 - 0.5 * bay), bay_z],
                [0.5 * gap.min(3.0), 0.5 * bay, 0.6],
                0.0,
            )));
            x += width + gap;
        }
    }
    // Parked cars along both kerbs (y ≈ ±6.5), a few metres apart, slightly turned.
    for side in [-1.0f64, 1.0] {
        let mut x = -48.0 + rng.random_range(0.0..4.0);
        while x < 46.0 {
            let length = rng.random_range(3.8..4.8);
            let yaw = rng.random_range(-4.0..4.0);
            let y = side * rng.random_range(6.2..6.8);
            scene.add_solid(Solid::Box(yawed_box(
                [x + 0.5 * length, y, g + 0.75],
                [0.5 * length, 0.9, 0.75],
                yaw,
            )));
            x += length + rng.random_range(1.0..9.0);
        }
    }
    // Lamp posts, trees and bins on the pavements (y ≈ ±8.5).
    let mut x = -47.0;
    while x < 47.0 {
        let side = if rng.random_bool(0.5) { 1.0 } else { -1.0 };
        let y = side * rng.random_range(7.8..9.5);
        match rng.random_range(0..3) {
            0 => scene.add_solid(Solid::Box(yawed_box(
                [x, y, g + 3.0],
                [0.08, 0.08, 3.0],
                0.0,
            ))),
            1 => {
                scene.add_solid(Solid::Box(yawed_box(
                    [x, y, g + 1.5],
                    [0.15, 0.15, 1.5],
                    0.0,
                )));
                let crown = rng.random_range(1.2..2.2);
                scene.add_solid(Solid::Ellipsoid(Ellipsoid::build(
                    Vec3::new(x, y, g + 3.0 + crown),
                    Vec3::new(crown, crown, 1.3 * crown),
                    Rotation3::identity(),
                )));
            }
            _ => scene.add_solid(Solid::Box(OrientedBox::build(
                Vec3::new(x, y, g + 0.5),
                Vec3::new(0.3, 0.3, 0.5),
                yaw_rotation(rng.random_range(0.0..1.5)),
            ))),
        }
        x += rng.random_range(3.0..9.0);
    }
    scene
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn a_turn_has_a_ray_per_laser_and_firing() {
        let lidar = SpinningLidar::hdl32();
        let d = lidar.directions();
        assert_eq!(d.len(), 32 * 900);
        assert!(d.iter().all(|v| (v.norm() - 1.0).abs() < 1e-12));
        let lowest = d
            .iter()
            .map(|v| v.z.asin().to_degrees())
            .fold(90.0, f64::min);
        assert!((lowest + 30.67).abs() < 1e-9);
    }

    #[test]
    fn the_street_is_scanned_around_and_seeded() {
        let scene = street(3);
        let lidar = SpinningLidar {
            azimuth_step_deg: 2.0,
            ..SpinningLidar::hdl32()
        };
        let at = Pose::translation(1.0, 0.5, 0.0);
        let points = spinning_scan(&scene, &lidar, &at, 9);
        assert_eq!(points, spinning_scan(&scene, &lidar, &at, 9));
        assert_ne!(points, spinning_scan(&scene, &lidar, &at, 10));
        // Most rays below the horizon hit the road or what stands on it.
        assert!(points.len() > 32 * 180 * 3 / 4, "{} returns", points.len());
        // Straight down the lowest laser meets the road at its slant range.
        let down = points.iter().map(|p| p.z).fold(0.0, f64::min);
        assert!((down + STREET_SENSOR_HEIGHT_M).abs() < 0.1, "{down}");
    }
}
