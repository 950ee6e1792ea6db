//! Spinning LiDAR scans (a Velodyne on a street, simulated): the S-DEM grid and the search's
//! settings derived from the scan, a pair localized without a guess, and the exact search still
//! the exhaustive search's answer at the derived settings.

use nalgebra::{Isometry3, Vector3};
use rand::SeedableRng;
use sdem::geometry::{pose_error, Attitude, Pose, Vec3};
use sdem::localize::{localize, HeadingWindow, LocalizeOptions, SearchMode, SearchWindow};
use sdem::sdem::{Sdem, SdemConfig};
use sdem::sensor::SensorConfig;
use sdem_sim::sim::lidar_street::street;
use sdem_sim::sim::{self, spinning_scan, SpinningLidar};

/// Where the query stands in the reference's frame for street pair `seed`: 0.6–0.9 m along
/// the street (a car's step at 10 Hz), a little across it, turned up to ±2.5°.
fn street_truth(seed: u64) -> Pose {
    let s = seed as f64;
    Isometry3::new(
        Vector3::new(0.6 + 0.1 * s, 0.12 - 0.09 * s, 0.02),
        Vector3::z() * (2.5 - 1.6 * s).to_radians(),
    )
}

/// The two scans of street pair `seed` (reference at the origin, query at
/// [`street_truth`]), levelled S-DEMs on the grid derived from the reference scan.
fn street_pair(seed: u64, lidar: &SpinningLidar) -> (Sdem, Sdem, SdemConfig) {
    let scene = street(seed);
    let reference = spinning_scan(&scene, lidar, &Pose::identity(), 2 * seed);
    let query = spinning_scan(&scene, lidar, &street_truth(seed), 2 * seed + 1);
    let grid = SdemConfig::for_scan(&reference);
    let level = Attitude::default();
    let (r, q) = Sdem::pair_from_points((&reference, &level), (&query, &level), &grid).unwrap();
    (r, q, grid)
}

/// The options for a street pair: derived from the reference, a ±1 m window (±0.3 m in height)
/// and ±5° of heading around level, no guess.
fn street_options(reference: &Sdem) -> LocalizeOptions {
    LocalizeOptions {
        window: SearchWindow {
            min: [-1.0, -1.0, -0.3],
            max: [1.0, 1.0, 0.3],
        },
        heading: HeadingWindow {
            half_range_deg: 5.0,
            step_deg: None,
        },
        ..LocalizeOptions::for_scan(reference)
    }
}

#[test]
fn the_grid_is_derived_from_the_scanner() {
    let directions_as_points = |lidar: &SpinningLidar| -> Vec<Vec3> {
        lidar.directions().iter().map(|d| d * 10.0).collect()
    };
    // 64 lasers 0.43° apart: cells of about one laser, the band −24.9..+2° widened by 5°.
    let hdl64 = SdemConfig::for_scan(&directions_as_points(&SpinningLidar::hdl64()));
    assert!(
        (0.4..=0.5).contains(&hdl64.resolution_deg),
        "{}",
        hdl64.resolution_deg
    );
    assert_eq!(
        (hdl64.elevation_min_deg, hdl64.elevation_max_deg),
        (-30.0, 7.0)
    );
    assert_eq!(
        (hdl64.azimuth_min_deg, hdl64.azimuth_max_deg),
        (-180.0, 180.0)
    );
    // 32 lasers 1.33° apart.
    let hdl32 = SdemConfig::for_scan(&directions_as_points(&SpinningLidar::hdl32()));
    assert!(
        (1.2..=1.5).contains(&hdl32.resolution_deg),
        "{}",
        hdl32.resolution_deg
    );
    assert_eq!(
        (hdl32.elevation_min_deg, hdl32.elevation_max_deg),
        (-36.0, 16.0)
    );
    // A scanner looking forward only (±35°): still a full turn, since the S-DEM turns with
    // the compass reading.
    let forward: Vec<Vec3> = directions_as_points(&SpinningLidar::hdl32())
        .into_iter()
        .filter(|p| p.y.atan2(p.x).to_degrees().abs() <= 35.0)
        .collect();
    let narrow = SdemConfig::for_scan(&forward);
    assert_eq!(
        (narrow.azimuth_min_deg, narrow.azimuth_max_deg),
        (-180.0, 180.0)
    );
    assert_eq!(narrow.resolution_deg, hdl32.resolution_deg);
    // 16 lasers 2° apart (a VLP-16), fired every 0.2°: finer cells would leave rows of holes
    // between the lasers, and no cell a neighbour above and below to measure its surface by.
    let vlp16: Vec<Vec3> = (0..16)
        .flat_map(|laser| (0..1800).map(move |k| (laser, k)))
        .map(|(laser, k)| {
            let (el, az) = (
                (-15.0 + 2.0 * laser as f64).to_radians(),
                (0.2 * k as f64).to_radians(),
            );
            10.0 * Vec3::new(el.cos() * az.cos(), el.cos() * az.sin(), el.sin())
        })
        .collect();
    let vlp16 = SdemConfig::for_scan(&vlp16);
    assert!(vlp16.resolution_deg >= 1.9, "{}", vlp16.resolution_deg);
    // The paper's tilting SICK, 1° pan and tilt steps: 1° cells, as the sensor model says.
    let sensor = SensorConfig::default();
    let mut rng = rand_chacha::ChaCha8Rng::seed_from_u64(1);
    let sweep = sim::scan(
        &sim::paper_room(),
        &sensor,
        &Pose::identity(),
        0.0,
        &mut rng,
    );
    let sick = SdemConfig::for_scan(&sweep.points_in_sensor());
    assert_eq!(sick.resolution_deg, sensor.matched_sdem_resolution_deg());
    // Too few points to tell: the default grid.
    assert_eq!(
        SdemConfig::for_scan(&directions_as_points(&SpinningLidar::hdl64())[..50]),
        SdemConfig::default()
    );
    // Every derived grid is a valid one.
    for g in [hdl64, hdl32, vlp16, narrow, sick] {
        g.validate().unwrap();
    }
}

#[test]
fn a_street_pair_is_localized_without_a_guess() {
    let lidar = SpinningLidar::hdl32();
    for seed in 0..3 {
        let (reference, query, _) = street_pair(seed, &lidar);
        let options = street_options(&reference);
        let found = localize(&reference, &query, &options).unwrap();
        let (e_m, e_rad) = pose_error(&street_truth(seed), &found.reference_from_query);
        assert!(
            e_m < 0.03 && e_rad.to_degrees() < 0.3,
            "pair {seed}: {:.2} cm, {:.3}° (step {} m, τ {} m)",
            e_m * 100.0,
            e_rad.to_degrees(),
            options.step_m,
            options.cost.truncation_m
        );
        assert!(found.trusted, "pair {seed}: {:?}", found.doubts);
    }
}

#[test]
fn the_exact_search_finds_the_oracles_minimum_at_the_derived_settings() {
    let (reference, query, _) = street_pair(1, &SpinningLidar::hdl32());
    let derived = street_options(&reference);
    let options = LocalizeOptions {
        window: SearchWindow {
            min: [0.2, -0.4, -0.2],
            max: [1.2, 0.4, 0.2],
        },
        heading: HeadingWindow {
            half_range_deg: 3.0,
            step_deg: None,
        },
        refine: false,
        runner_up: false,
        ..derived
    };
    let exact = localize(&reference, &query, &options).unwrap();
    let oracle = localize(
        &reference,
        &query,
        &LocalizeOptions {
            mode: SearchMode::Exhaustive,
            ..options.clone()
        },
    )
    .unwrap();
    assert_eq!(exact.grid_index, oracle.grid_index);
    assert_eq!(exact.cost.to_bits(), oracle.cost.to_bits());
    assert!(exact.candidates_evaluated < oracle.candidates_evaluated / 4);
}

#[test]
fn a_second_query_against_one_reference_gives_the_same_answer() {
    // The reference keeps its normals and tables after the first localization; the second
    // reads them and must find exactly what a fresh reference finds.
    let (reference, query, grid) = street_pair(2, &SpinningLidar::hdl32());
    let options = street_options(&reference);
    let first = localize(&reference, &query, &options).unwrap();
    let again = localize(&reference, &query, &options).unwrap();
    let fresh = Sdem::from_points(
        &spinning_scan(&street(2), &SpinningLidar::hdl32(), &Pose::identity(), 4),
        &Attitude::default(),
        &grid,
    )
    .unwrap();
    let from_fresh = localize(&fresh, &query, &options).unwrap();
    for other in [&again, &from_fresh] {
        assert_eq!(first.reference_from_query, other.reference_from_query);
        assert_eq!(first.cost.to_bits(), other.cost.to_bits());
        assert_eq!(first.doubts, other.doubts);
    }
}

/// `SlamOptions::for_scan` tells the scanners apart by the field of view their returns cover:
/// a spinning LiDAR's full turn in a narrow band and a solid-state unit's forward cone get the
/// options derived from the scan; the paper's tilting laser (half the azimuth, 85° of
/// elevation) and a scanner that sees the whole sphere (or all of it but the sky) keep the
/// tilting laser's defaults.
#[test]
fn the_loop_tells_lidars_from_the_tilting_laser_by_their_field_of_view() {
    use sdem::slam::{is_solid_state_lidar, is_spinning_lidar, SlamOptions};
    use sdem_sim::sim::{spin_scan, LidarConfig};
    let scene = street(1);
    let mut rng = rand_chacha::ChaCha8Rng::seed_from_u64(3);
    let spin = spin_scan(&scene, &LidarConfig::default(), &Pose::identity(), &mut rng).unwrap();
    // An Ouster OS0: 128 rows over ±45°.
    let os0 = LidarConfig {
        rings: 128,
        elevation_min_deg: -45.0,
        elevation_max_deg: 45.0,
        azimuth_step_deg: 0.35,
        ..LidarConfig::default()
    };
    let os0 = spin_scan(&scene, &os0, &Pose::identity(), &mut rng).unwrap();
    let solid = spin_scan(
        &scene,
        &LidarConfig::solid_state(),
        &Pose::identity(),
        &mut rng,
    )
    .unwrap();
    let sweep = sim::scan(
        &sim::paper_room(),
        &SensorConfig::default(),
        &Pose::identity(),
        0.0,
        &mut rng,
    )
    .points_in_sensor();
    // Every direction of the sphere at 2°, 5 m away.
    let sphere: Vec<Vec3> = (0..180)
        .flat_map(|i| (0..90).map(move |j| (i, j)))
        .map(|(i, j)| {
            let (az, el) = (
                (2.0 * i as f64).to_radians(),
                (-89.0 + 2.0 * j as f64).to_radians(),
            );
            5.0 * Vec3::new(el.cos() * az.cos(), el.cos() * az.sin(), el.sin())
        })
        .collect();
    assert!(is_spinning_lidar(&spin) && !is_solid_state_lidar(&spin));
    assert!(is_spinning_lidar(&os0) && !is_solid_state_lidar(&os0));
    assert!(is_solid_state_lidar(&solid) && !is_spinning_lidar(&solid));
    let default = SlamOptions::default();
    for (name, scan) in [("spinning", &spin), ("OS0", &os0), ("solid-state", &solid)] {
        let derived = SlamOptions::for_scan(scan);
        assert!(derived.localize.step_m > default.localize.step_m, "{name}");
    }
    // Outdoors a rotating scanner gets no returns from the sky: up to 25° of elevation.
    let no_sky: Vec<Vec3> = sphere
        .iter()
        .filter(|p| p.z < 5.0 * 0.42)
        .copied()
        .collect();
    for (name, scan) in [
        ("tilting laser", &sweep),
        ("whole sphere", &sphere),
        ("sphere without the sky", &no_sky),
    ] {
        assert!(
            !is_spinning_lidar(scan) && !is_solid_state_lidar(scan),
            "{name}"
        );
        // The defaults, on cells matched to the scan's sampling: the paper's sweep's 1° (the
        // default), the spheres' 2°.
        let options = SlamOptions::for_scan(scan);
        let resolution = if name == "tilting laser" { 1.0 } else { 2.0 };
        assert_eq!(options.sdem.resolution_deg, resolution, "{name}");
        let on_default_cells = SlamOptions {
            sdem: default.sdem.clone(),
            ..options
        };
        assert_eq!(on_default_cells, default, "{name}");
    }
    // A scanner sampling its front half at 0.3° gets cells of 0.5°, the finest matched.
    let fine: Vec<Vec3> = (0..600)
        .flat_map(|i| (0..200).map(move |j| (i, j)))
        .map(|(i, j)| {
            let (az, el) = (
                (-90.0 + 0.3 * i as f64).to_radians(),
                (-30.0 + 0.3 * j as f64).to_radians(),
            );
            5.0 * Vec3::new(el.cos() * az.cos(), el.cos() * az.sin(), el.sin())
        })
        .collect();
    assert!(!is_spinning_lidar(&fine) && !is_solid_state_lidar(&fine));
    assert_eq!(SlamOptions::for_scan(&fine).sdem.resolution_deg, 0.5);
}
