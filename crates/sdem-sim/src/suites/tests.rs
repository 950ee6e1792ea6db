use super::*;
use nalgebra::Point3;

/// [`SuiteConfig::unlevelled`] with a coarse sweep (3° steps): the same geometry, quicker.
fn quick_unlevelled() -> SuiteConfig {
    let mut config = SuiteConfig::unlevelled();
    if let SuiteSensor::Tilting(sensor) = &mut config.sensor {
        sensor.tilt_step_deg = 3.0;
        sensor.pan_step_deg = 3.0;
    }
    config
}

/// [`SuiteConfig::spinning_lidar`] with 8 rings every 2°: the same geometry, quicker.
fn quick_lidar() -> SuiteConfig {
    let mut config = SuiteConfig::spinning_lidar();
    if let SuiteSensor::Spinning(lidar) = &mut config.sensor {
        lidar.rings = 8;
        lidar.azimuth_step_deg = 2.0;
    }
    config
}

/// The scene a pair of `seed` was drawn in, built again.
fn scene_of(kind: SuiteScene, seed: u64) -> Scene {
    match kind {
        SuiteScene::RubbleVoid | SuiteScene::Ditch => sim::collapsed_building(seed),
        SuiteScene::Corridor => sim::corridor(CORRIDOR_LENGTH_M).unwrap(),
        SuiteScene::Hall => sim::open_hall(seed),
        SuiteScene::Street => sim::street(seed),
    }
}

/// Of the query's points mapped into the world by `world_from_query`, the share that the
/// reference sensor sees at the same range (within 3 cm) along its ray through them.
fn agreement(pair: &SuitePair, scene: &Scene, reference_from_query: &Pose) -> f64 {
    let world_from_query = pair.world_from_reference * reference_from_query;
    let origin = pair.world_from_reference.translation.vector;
    let (mut seen, mut total) = (0, 0);
    for p in pair.query_points.iter().step_by(11) {
        let in_world = (world_from_query * Point3::from(*p)).coords;
        let range = (in_world - origin).norm();
        let hit = scene.raycast(&origin, &((in_world - origin) / range), 200.0);
        total += 1;
        if hit.is_some_and(|h| (h - range).abs() < 0.03) {
            seen += 1;
        }
    }
    seen as f64 / total as f64
}

#[test]
fn pairs_are_deterministic_for_a_seed_and_any_thread_count() {
    let config = quick_unlevelled();
    let a = suite_pairs(5, 4, &config).unwrap();
    let b = rayon::ThreadPoolBuilder::new()
        .num_threads(1)
        .build()
        .unwrap()
        .install(|| suite_pairs(5, 4, &config))
        .unwrap();
    assert_eq!(a, b);
    // A prefix of a longer run is the same pairs.
    let c = suite_pairs(5, 2, &config).unwrap();
    assert_eq!(&a[..2], &c[..]);
    // Another seed gives other pairs.
    let d = suite_pairs(6, 4, &config).unwrap();
    assert_ne!(a[0].truth, d[0].truth);
    assert!(suite_pairs(5, 0, &config).unwrap().is_empty());
    // Pairs drawn by index from a generator are the same pairs.
    let generator = SuiteGenerator::new(5, config).unwrap();
    assert_eq!(generator.pairs(2..4).unwrap(), &a[2..4]);
}

#[test]
fn unlevelled_poses_are_free_tilted_within_bounds_and_overlap() {
    let config = quick_unlevelled();
    let seed = 3;
    let pairs = suite_pairs(seed, 8, &config).unwrap();
    let kinds: Vec<SuiteScene> = pairs.iter().map(|p| p.scene).collect();
    assert_eq!(&kinds[..4], &config.scenes[..], "the scenes in turn");
    let window = config.search_window();
    for pair in &pairs {
        let scene = scene_of(pair.scene, seed);
        for pose in [&pair.world_from_reference, &pair.world_from_query] {
            let origin = pose.translation.vector;
            assert!(scene.is_free(&origin), "{:?}", pair.scene);
            assert!(
                scene.clearance(&origin, 1000) >= config.min_clearance_m - 0.01,
                "{:?}",
                pair.scene
            );
        }
        let step =
            pair.world_from_query.translation.vector - pair.world_from_reference.translation.vector;
        assert!(step.norm() <= config.step_max_m + 1e-12);
        assert!((pair.step_m() - step.norm()).abs() < 1e-9);
        assert!(step.z.abs() <= config.step_z_max_m + 1e-12);
        let query = attitude_of(&pair.world_from_query).to_degrees();
        let reference = attitude_of(&pair.world_from_reference).to_degrees();
        for k in 0..2 {
            assert!(
                query[k].abs() <= config.query_tilt_max_deg + 1e-9,
                "{query:?}"
            );
            assert!(
                reference[k].abs() <= config.reference_tilt_max_deg + 1e-9,
                "{reference:?}"
            );
        }
        assert!(pair.query_tilt_deg() <= 45.0);
        assert!((-180.0..180.0).contains(&pair.relative_heading_deg()));
        assert!(pair.overlap >= config.min_overlap && pair.overlap <= 1.0);
        assert!(pair.reference_attitude.is_none() && pair.query_attitude.is_none());
        assert!(pair.reference_points.len() > 1000 && pair.query_points.len() > 1000);
        // The window holds the offset on the reference's levelled axes (world axes turned by
        // its heading).
        let heading = attitude_of(&pair.world_from_reference).yaw;
        let offset = nalgebra::Rotation3::from_axis_angle(&Vec3::z_axis(), -heading) * step;
        for axis in 0..3 {
            assert!(offset[axis] >= window.min[axis] && offset[axis] <= window.max[axis]);
        }
    }
    // Over the pairs, the query's tilt and the turn between the scans are large somewhere.
    assert!(pairs.iter().any(|p| p.query_tilt_deg() > 15.0));
    assert!(pairs.iter().any(|p| p.relative_heading_deg().abs() > 30.0));
}

#[test]
fn the_truth_maps_the_query_onto_the_reference_scene() {
    let seed = 2;
    let pairs = suite_pairs(seed, 4, &quick_unlevelled()).unwrap();
    for pair in &pairs {
        let scene = scene_of(pair.scene, seed);
        let origin = pair.world_from_reference.inverse()
            * Point3::from(pair.world_from_query.translation.vector);
        assert!((origin.coords - pair.truth.translation.vector).norm() < 1e-12);
        let right = agreement(pair, &scene, &pair.truth);
        let shifted = agreement(
            pair,
            &scene,
            &(Pose::translation(0.15, 0.1, 0.0) * pair.truth),
        );
        assert!(
            right > 0.25,
            "{:?}: truth agrees on only {right}",
            pair.scene
        );
        assert!(
            shifted < right - 0.1,
            "{:?}: shifted {shifted} vs truth {right}",
            pair.scene
        );
    }
}

#[test]
fn compass_noise_pairs_are_the_unlevelled_scans_with_readings() {
    let mut noisy = SuiteConfig::compass_noise();
    noisy.sensor = quick_unlevelled().sensor;
    let plain = suite_pairs(4, 4, &quick_unlevelled()).unwrap();
    let read = suite_pairs(4, 4, &noisy).unwrap();
    for (p, r) in plain.iter().zip(&read) {
        assert_eq!(p.query_points, r.query_points);
        assert_eq!(p.reference_points, r.reference_points);
        assert_eq!(p.truth, r.truth);
        for (reading, pose) in [
            (r.reference_attitude, &r.world_from_reference),
            (r.query_attitude, &r.world_from_query),
        ] {
            let reading = reading.expect("a reading on every scan");
            assert!((reading.sigma.roll_pitch.to_degrees() - 2.0).abs() < 1e-12);
            assert!((reading.sigma.yaw.to_degrees() - 20.0).abs() < 1e-12);
            let truth = attitude_of(pose);
            assert!((reading.roll - truth.roll).to_degrees().abs() < 6.0 * 2.0);
            assert!((reading.pitch - truth.pitch).to_degrees().abs() < 6.0 * 2.0);
            assert!(wrap_angle(reading.yaw - truth.yaw).to_degrees().abs() < 6.0 * 20.0);
        }
    }
    // The errors are not all zero.
    let r = read[0].query_attitude.unwrap();
    assert!(r.roll != attitude_of(&read[0].world_from_query).roll);
}

#[test]
fn spinning_lidar_scans_all_around_within_its_rings() {
    let lidar = LidarConfig {
        rings: 8,
        azimuth_step_deg: 2.0,
        ..LidarConfig::default()
    };
    let hall = sim::open_hall(1);
    let pose = Pose::translation(0.0, 0.0, 1.0);
    let mut rng = ChaCha8Rng::seed_from_u64(1);
    let points = sim::spin_scan(&hall, &lidar, &pose, &mut rng).unwrap();
    // A closed hall returns every beam.
    assert_eq!(points.len(), 8 * 180);
    let elevations = lidar.ring_elevations_deg();
    for p in &points {
        let range = p.norm();
        assert!(range >= lidar.min_range_m && range <= lidar.max_range_m);
        let elevation = (p.z / range).asin().to_degrees();
        let nearest = elevations
            .iter()
            .map(|e| (e - elevation).abs())
            .fold(f64::INFINITY, f64::min);
        assert!(nearest < 1.0, "elevation {elevation}");
    }
    // All around: returns in every quadrant of azimuth.
    for quadrant in 0..4 {
        let lo = -180.0 + 90.0 * quadrant as f64;
        assert!(points.iter().any(|p| {
            let a = p.y.atan2(p.x).to_degrees();
            a >= lo && a < lo + 90.0
        }));
    }
    // In the street the sky returns nothing; the same seed gives the same scan on one thread.
    let street = sim::street(1);
    let mut rng = ChaCha8Rng::seed_from_u64(2);
    let pose = Pose::translation(0.0, 0.0, 1.7);
    let open = sim::spin_scan(&street, &lidar, &pose, &mut rng).unwrap();
    assert!(
        open.len() < 8 * 180 && open.len() > 4 * 180,
        "{}",
        open.len()
    );
    let mut rng = ChaCha8Rng::seed_from_u64(2);
    let again = rayon::ThreadPoolBuilder::new()
        .num_threads(1)
        .build()
        .unwrap()
        .install(|| sim::spin_scan(&street, &lidar, &pose, &mut rng))
        .unwrap();
    assert_eq!(open, again);
    assert!(sim::spin_scan(&street, &LidarConfig { rings: 1, ..lidar }, &pose, &mut rng).is_err());
}

#[test]
fn a_solid_state_lidar_sees_only_its_field_of_view() {
    let lidar = LidarConfig {
        rings: 8,
        azimuth_step_deg: 2.0,
        ..LidarConfig::solid_state()
    };
    let hall = sim::open_hall(1);
    let pose = Pose::translation(0.0, 0.0, 1.0);
    let mut rng = ChaCha8Rng::seed_from_u64(1);
    let points = sim::spin_scan(&hall, &lidar, &pose, &mut rng).unwrap();
    // 70° at 2° steps: 36 azimuths a row, every beam returning in a closed hall.
    assert_eq!(points.len(), 8 * 36);
    for p in &points {
        let azimuth = p.y.atan2(p.x).to_degrees();
        assert!(azimuth.abs() <= 35.0 + 1e-9, "{azimuth}");
        assert!(lidar.sees(&(p / p.norm())));
    }
    assert!(!lidar.sees(&Vec3::new(-1.0, 0.0, 0.0)));
    assert!(!lidar.sees(&Vec3::new(0.5, 0.5, 0.0).normalize()));
    assert!(LidarConfig {
        azimuth_fov_deg: 0.0,
        ..lidar.clone()
    }
    .validate()
    .is_err());
}

#[test]
fn open_scenes_are_seeded_and_their_regions_are_free() {
    assert_eq!(sim::open_hall(1), sim::open_hall(1));
    assert_ne!(sim::open_hall(1), sim::open_hall(2));
    assert_eq!(sim::street(1), sim::street(1));
    assert_ne!(sim::street(1), sim::street(2));
    for (scene, [lo, hi]) in [
        (sim::open_hall(1), sim::open_hall_sensor_region()),
        (sim::street(1), sim::street_sensor_region()),
    ] {
        // Most of the region is free.
        let mut rng = ChaCha8Rng::seed_from_u64(9);
        let free = (0..100)
            .filter(|_| scene.is_free(&Vec3::from_fn(|i, _| rng.random_range(lo[i]..=hi[i]))))
            .count();
        assert!(free > 70, "{free} of 100 free");
    }
}

#[test]
fn spinning_lidar_pairs_stay_within_their_bounds() {
    let config = quick_lidar();
    let pairs = suite_pairs(1, 2, &config).unwrap();
    assert_eq!(pairs[0].scene, SuiteScene::Street);
    assert_eq!(pairs[1].scene, SuiteScene::Hall);
    for pair in &pairs {
        assert!(pair.step_m() <= 1.0 + 1e-12);
        for pose in [&pair.world_from_reference, &pair.world_from_query] {
            let a = attitude_of(pose).to_degrees();
            assert!(a[0].abs() <= 3.0 + 1e-9 && a[1].abs() <= 3.0 + 1e-9);
        }
        assert!(pair.overlap >= 0.5);
        assert!(pair.query_points.len() > 500);
    }
}

#[test]
fn invalid_configs_are_rejected() {
    let base = SuiteConfig::unlevelled();
    let bad = [
        SuiteConfig {
            scenes: Vec::new(),
            ..base.clone()
        },
        SuiteConfig {
            step_max_m: f64::NAN,
            ..base.clone()
        },
        SuiteConfig {
            query_tilt_max_deg: 95.0,
            ..base.clone()
        },
        SuiteConfig {
            min_overlap: 1.5,
            ..base.clone()
        },
        SuiteConfig {
            readings: Readings::Noisy {
                roll_pitch_sigma_deg: 0.0,
                yaw_sigma_deg: 20.0,
            },
            ..base.clone()
        },
    ];
    for config in &bad {
        assert!(config.validate().is_err(), "{config:?}");
        assert!(suite_pairs(1, 1, config).is_err());
    }
    assert!(base.validate().is_ok());
    assert!(SuiteConfig::compass_noise().validate().is_ok());
    assert!(SuiteConfig::spinning_lidar().validate().is_ok());
}

/// Localizes pair `index` of `compass-noise` (seed 1) as `sdem bench --suite compass-noise`
/// does: the pose's error against the truth, and the localization.
fn compass_noise_pair(index: usize) -> (f64, sdem::Localization) {
    let config = SuiteConfig::compass_noise();
    let generator = SuiteGenerator::new(1, config.clone()).unwrap();
    let pair = generator.pairs(index..index + 1).unwrap().remove(0);
    let reference = sdem::Scan::from_points(&pair.reference_points, pair.reference_attitude)
        .expect("the reference");
    let query =
        sdem::Scan::from_points(&pair.query_points, pair.query_attitude).expect("the query");
    let options = sdem::LocalizeOptions {
        window: config.search_window(),
        step_m: 0.02,
        ..Default::default()
    };
    let found = sdem::localize(&reference, &query, &options).expect("a pose");
    let error =
        (found.reference_from_query.translation.vector - pair.truth.translation.vector).norm();
    (error, found)
}

/// A runner-up on the optimum's own slope is no rival: on pair 51 of `compass-noise` (seed 1,
/// a hall) the best candidate beyond the peak radius within the ambiguity ratio lies where eq.
/// (1) falls along the line to the optimum. It is passed over, no other candidate within the
/// ratio is found, and the pose, within 2 mm of the truth, is trusted (it was flagged
/// `runner_up` while the slope counted as a rival).
#[test]
fn a_runner_up_on_the_optimums_own_slope_is_no_rival() {
    let (error, found) = compass_noise_pair(51);
    assert!(error < 0.002, "{:.2} mm from the truth", error * 1e3);
    assert!(found.trusted, "{:?}", found.doubts);
    assert!(
        found.diagnostics.runner_up_cost.is_none(),
        "{:?}",
        found.diagnostics
    );
}

/// A runner-up near the optimum whose line to it rises stays a rival: pairs 17 (a ditch, the
/// pose right) and 162 (a corridor, the pose 1.1 m off) of `compass-noise` keep their
/// `runner_up` 10–14 cm from the optimum, within the slopes' reach. Counting every candidate
/// found there as a slope, both lose it.
#[test]
fn a_runner_up_whose_line_to_the_optimum_rises_stays_a_rival() {
    for index in [17, 162] {
        let (_, found) = compass_noise_pair(index);
        let distance = found.doubts.iter().find_map(|d| match d {
            sdem::Doubt::RunnerUp { distance_m, .. } => Some(*distance_m),
            _ => None,
        });
        assert!(
            distance.is_some_and(|d| d < 0.2),
            "pair {index}: {:?}",
            found.doubts
        );
        assert!(!found.trusted);
    }
}
