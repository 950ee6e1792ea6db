use super::inject::PERSON_RADII_M;
use super::*;
use crate::sim::{self, wrap_angle, OrientedBox, Scene};
use rand::SeedableRng;
use rand_chacha::ChaCha8Rng;
use sdem::geometry::{attitude_of, Pose, Vec3};
use sdem::sdem::SdemConfig;
use sdem::sensor::SensorConfig;

/// A coarse sweep (2° steps) keeps the tests quick; the geometry is the same.
fn quick_config() -> FaultConfig {
    let mut config = FaultConfig::default();
    config.pairs.sensor.tilt_step_deg = 2.0;
    config.pairs.sensor.pan_step_deg = 2.0;
    config
}

/// The two pairs the fault bench got wrong before the refinement paired only what the
/// reference saw and a candidate needed 100 compared cells instead of 200: pair 45 (the
/// robot at the ditch's mouth sees mostly what the reference did not; 12.7 cm off, flagged)
/// and pair 79 (5.9 cm off and *not* flagged), both with 30 % of the returns lost.
#[test]
fn the_ditch_mouth_pairs_with_lost_returns_are_localized() {
    let config = FaultConfig::default();
    for index in [45, 79] {
        let pair = fault_pair(1, index, &[Fault::Missing], &config).unwrap();
        let result = localize_fault_pair(&pair, &SdemConfig::default(), &config).unwrap();
        assert!(
            result.translation_error_m < 0.01 && result.rotation_error_deg < 0.5,
            "pair {index}: {:.1} mm, {:.2}°",
            result.translation_error_m * 1e3,
            result.rotation_error_deg
        );
        assert!(result.localization.refinement.is_some(), "pair {index}");
    }
}

/// Pair 79 under moved rubble: the exact search's optimum is 10 cm off (3,871 returns on the
/// moved pieces make the cost prefer it), and the refinement stops 8.6 cm from it where eq. (1)
/// does not rise along one direction. Probed about the refined pose, the match says so instead
/// of passing as certain, as the loop's tracking (no runner-up search) would take it. Under gyro
/// drift the refinement tilts the query by 1–2.7° against its reading; probed with the query
/// turned by the refined rotation, tilt included, right poses are not ambiguous (probed at the
/// reading's tilt, about half of them came out flat).
#[test]
fn a_wrong_pose_under_moved_rubble_is_flagged_and_tilt_corrected_ones_are_not() {
    let config = FaultConfig::default();
    let pair = fault_pair(1, 79, &[Fault::Rubble], &config).unwrap();
    let result = localize_fault_pair(&pair, &SdemConfig::default(), &config).unwrap();
    assert!(
        result.translation_error_m < 0.02 || !result.localization.trusted,
        "{:.1} mm off and trusted",
        result.translation_error_m * 1e3
    );
    let drifted = fault_pairs(1, 10, &[Fault::GyroDrift], &config).unwrap();
    for (index, pair) in drifted.iter().enumerate() {
        let result = localize_fault_pair(pair, &SdemConfig::default(), &config).unwrap();
        assert!(result.translation_error_m < 0.005, "pair {index}");
        // The reading's tilt may be off by more than its σ says (`attitude_corrected`), but the
        // match is not ambiguous.
        assert!(
            !result.localization.diagnostics.ambiguous,
            "pair {index}: {:?}",
            result.localization.doubts
        );
    }
}

/// [`fault_pair`] draws the same pair as [`fault_pairs`] at its index.
#[test]
fn one_pair_alone_equals_its_place_in_the_set() {
    let config = quick_config();
    let all = fault_pairs(5, 3, &[Fault::Dust], &config).unwrap();
    assert_eq!(fault_pair(5, 2, &[Fault::Dust], &config).unwrap(), all[2]);
}

#[test]
fn names_round_trip_and_unknown_names_are_listed() {
    for fault in Fault::ALL {
        assert_eq!(fault.name().parse::<Fault>().unwrap(), fault);
        assert!(!fault.describe(&FaultConfig::default()).is_empty());
    }
    let e = "smoke".parse::<Fault>().unwrap_err().to_string();
    assert!(e.contains("smoke") && e.contains("gyro-drift"), "{e}");
}

#[test]
fn clean_pairs_carry_nothing_and_are_deterministic() {
    let config = quick_config();
    let a = fault_pairs(3, 2, &[], &config).unwrap();
    let b = rayon::ThreadPoolBuilder::new()
        .num_threads(1)
        .build()
        .unwrap()
        .install(|| fault_pairs(3, 2, &[], &config))
        .unwrap();
    assert_eq!(a, b);
    for p in &a {
        assert_eq!(p.injected, Injected::default());
        // The prior is off by the odometry error: 5 % of the motion.
        let motion = p.pair.true_offset().norm();
        let error = (p.predicted_offset - p.pair.true_offset()).norm();
        assert!((error - 0.05 * motion).abs() < 1e-9, "{error} vs {motion}");
    }
}

#[test]
fn readings_carry_the_compass_and_gyro_errors() {
    let config = quick_config();
    let pairs = fault_pairs(4, 4, &[Fault::Compass, Fault::GyroDrift], &config).unwrap();
    let mut largest: f64 = 0.0;
    for p in &pairs {
        let truth = attitude_of(&p.pair.world_from_query);
        let read = p.pair.query_attitude;
        let yaw_off = wrap_angle(read.yaw - truth.yaw).to_degrees();
        assert!(
            (yaw_off - p.injected.compass_error_deg).abs() < 1.0,
            "{yaw_off}"
        );
        let roll_off = (read.roll - truth.roll).to_degrees();
        assert!(
            (roll_off - p.injected.gyro_error_deg[0]).abs() < 0.3,
            "{roll_off}"
        );
        assert!(p.injected.compass_error_deg.abs() <= 20.0);
        assert!(p.injected.gyro_error_deg.iter().all(|e| e.abs() <= 2.0));
        largest = largest.max(p.injected.compass_error_deg.abs());
    }
    assert!(
        largest > 5.0,
        "errors drawn over the whole range: {largest}"
    );
}

#[test]
fn dust_and_lost_returns_have_their_sizes() {
    let config = quick_config();
    let clean = fault_pairs(5, 1, &[], &config).unwrap().remove(0);
    let dusty = fault_pairs(5, 1, &[Fault::Dust], &config)
        .unwrap()
        .remove(0);
    let beams = 2 * config.pairs.sensor.tilt_angles_deg().len() * config.pairs.sensor.pan_count();
    let rate = dusty.injected.dust_returns as f64 / beams as f64;
    assert!(
        (0.035..0.065).contains(&rate),
        "dust on {rate} of the beams"
    );
    // Dust returns are nearer than the surface: the median range drops.
    let median = |points: &[Vec3]| {
        let mut r: Vec<f64> = points.iter().map(|p| p.norm()).collect();
        r.sort_by(f64::total_cmp);
        r[r.len() / 2]
    };
    assert!(median(&dusty.pair.query_points) < median(&clean.pair.query_points));

    let lossy = fault_pairs(5, 1, &[Fault::Missing], &config)
        .unwrap()
        .remove(0);
    let before = clean.pair.reference_points.len() + clean.pair.query_points.len();
    let after = lossy.pair.reference_points.len() + lossy.pair.query_points.len();
    assert_eq!(before - after, lossy.injected.lost_returns);
    let lost = lossy.injected.lost_returns as f64 / before as f64;
    assert!((0.29..0.32).contains(&lost), "lost {lost}");
}

/// With [`Fault::Tilt`] the query's roll and pitch are drawn uniformly within ±30° (the
/// bench's pairs otherwise stay within ±3°): over 12 pairs both angles go past 20° either way,
/// none past 30°, and their mean size is near 15° (24 draws: 15° ± 4.5°, 2.5 standard errors).
#[test]
fn tilt_reaches_thirty_degrees() {
    let config = quick_config();
    let pairs = fault_pairs(6, 12, &[Fault::Tilt], &config).unwrap();
    let angles: Vec<[f64; 2]> = pairs
        .iter()
        .map(|p| {
            let a = attitude_of(&p.pair.world_from_query);
            [a.roll.to_degrees(), a.pitch.to_degrees()]
        })
        .collect();
    assert!(
        angles.iter().flatten().all(|a| a.abs() <= 30.0 + 1e-9),
        "{angles:?}"
    );
    for axis in 0..2 {
        let most = angles.iter().map(|a| a[axis]).fold(f64::MIN, f64::max);
        let least = angles.iter().map(|a| a[axis]).fold(f64::MAX, f64::min);
        assert!(most > 20.0 && least < -20.0, "axis {axis}: {angles:?}");
    }
    let mean_size = angles.iter().flatten().map(|a| a.abs()).sum::<f64>() / 24.0;
    assert!((mean_size - 15.0).abs() < 4.5, "mean |tilt| {mean_size}°");
}

#[test]
fn the_person_and_the_rubble_are_seen() {
    let config = quick_config();
    let pairs = fault_pairs(7, 3, &[Fault::Person, Fault::Rubble], &config).unwrap();
    for p in &pairs {
        assert!(p.injected.person_returns > 20, "{:?}", p.injected);
        assert!(p.injected.rubble_returns > 20, "{:?}", p.injected);
    }
}

#[test]
fn a_person_moves_during_the_sweep_and_hides_what_is_behind() {
    let sensor = SensorConfig {
        tilt_step_deg: 2.0,
        pan_step_deg: 2.0,
        range_noise_m: 0.0,
        ..SensorConfig::default()
    };
    let mut scene = Scene::new();
    scene.add_free(
        OrientedBox::axis_aligned(Vec3::new(-1.0, -3.0, -0.5), Vec3::new(5.0, 3.0, 2.0)).unwrap(),
    );
    let pose = Pose::identity();
    let mut rng = ChaCha8Rng::seed_from_u64(1);
    let mut sweep = sim::scan(&scene, &sensor, &pose, 0.0, &mut rng);
    let clean = sweep.clone();
    // Walks across the view 2 m ahead, from left to right.
    let person = WalkingPerson {
        start: Vec3::new(2.0, 1.0, 0.35),
        end: Vec3::new(2.0, -1.0, 0.35),
        radii: Vec3::from(PERSON_RADII_M),
    };
    let hits = add_walking_person(&mut sweep, &pose, &person, &sensor, &mut rng);
    assert!(hits > 10);
    // Every changed range got nearer, never farther; note the pan angles hit per line.
    let mut hit_pans: Vec<(usize, f64)> = Vec::new();
    for (i, (a, b)) in sweep.lines.iter().zip(&clean.lines).enumerate() {
        let pans: Vec<f64> = a
            .ranges
            .iter()
            .zip(&b.ranges)
            .enumerate()
            .filter(|(_, (x, y))| x.to_bits() != y.to_bits())
            .map(|(k, (x, y))| {
                assert!(x < y, "line {i}: {x} vs {y}");
                sweep.pan_min_deg + k as f64 * sweep.pan_step_deg
            })
            .collect();
        if !pans.is_empty() {
            hit_pans.push((i, pans.iter().sum::<f64>() / pans.len() as f64));
        }
    }
    // The person walks from the left (positive pan) to the right while the lines go by.
    let (first, last) = (hit_pans[0], hit_pans[hit_pans.len() - 1]);
    assert!(
        last.0 > first.0 + 5,
        "seen over several lines: {hit_pans:?}"
    );
    assert!(
        first.1 > last.1 + 10.0,
        "seen further right in later lines: {hit_pans:?}"
    );
}

#[test]
fn a_run_with_faults_keeps_the_clean_run_where_no_fault_touches_it() {
    let sensor = quick_config().pairs.sensor;
    let scene = sim::collapsed_building(2);
    let stops = sim::collapsed_building_stops(&scene, 2, 4, &sensor.lift).unwrap();
    let clean = sim::simulate_run(&scene, &stops, &sensor, 2).unwrap();
    let config = FaultConfig::default();
    let (none, injected) =
        simulate_run_with_faults(&scene, &stops, &sensor, 2, &[], &config).unwrap();
    assert_eq!(none, clean);
    assert!(injected.iter().all(|i| *i == Injected::default()));

    let faults = [
        Fault::Compass,
        Fault::GyroDrift,
        Fault::Rubble,
        Fault::Person,
    ];
    let (run, injected) =
        simulate_run_with_faults(&scene, &stops, &sensor, 2, &faults, &config).unwrap();
    for (k, (stop, i)) in run.iter().zip(&injected).enumerate() {
        assert_eq!(stop.world_from_sensor, clean[k].world_from_sensor);
        // The readings differ by the compass and gyro errors, and by nothing else.
        let (read, clean_read) = (stop.sweep.mean_attitude(), clean[k].sweep.mean_attitude());
        let yaw_off = wrap_angle(read.yaw - clean_read.yaw);
        assert!((yaw_off.to_degrees() - i.compass_error_deg).abs() < 1e-6);
        assert!(((read.roll - clean_read.roll).to_degrees() - i.gyro_error_deg[0]).abs() < 1e-6);
        assert!(((read.pitch - clean_read.pitch).to_degrees() - i.gyro_error_deg[1]).abs() < 1e-6);
        assert!(i.gyro_error_deg.iter().all(|e| e.abs() <= 2.0));
        assert!(i.person_returns > 0, "stop {k}: {i:?}");
        // The ranges are the clean run's, to the bit, but for the beams the person or the
        // moved rubble stopped: fewer than they count (the person may stand before rubble),
        // each nearer than the clean return or where it had none.
        assert_eq!(stop.sweep.lines.len(), clean[k].sweep.lines.len());
        let mut changed = 0;
        for (line, clean_line) in stop.sweep.lines.iter().zip(&clean[k].sweep.lines) {
            assert_eq!(line.tilt_deg, clean_line.tilt_deg);
            for (r, c) in line.ranges.iter().zip(&clean_line.ranges) {
                if r.to_bits() != c.to_bits() {
                    changed += 1;
                    assert!(
                        c.is_nan() || r < c,
                        "stop {k}: {r} m where the clean run saw {c} m"
                    );
                }
            }
        }
        assert!(
            changed >= i.person_returns,
            "stop {k}: {changed} changed, {i:?}"
        );
        assert!(
            changed <= i.person_returns + i.rubble_returns,
            "stop {k}: {changed} changed, {i:?}"
        );
    }
    // Rubble was moved in view of some stop after the first.
    assert!(
        injected.iter().any(|i| i.rubble_returns > 0),
        "{injected:?}"
    );
    let tilt = simulate_run_with_faults(&scene, &stops, &sensor, 2, &[Fault::Tilt], &config);
    assert!(tilt.unwrap_err().to_string().contains("bench --faults"));
}

#[test]
fn invalid_configs_name_the_field() {
    let bad = FaultConfig {
        dust_fraction: 1.5,
        ..FaultConfig::default()
    };
    assert!(bad
        .validate()
        .unwrap_err()
        .to_string()
        .contains("dust_fraction"));
    let bad = FaultConfig {
        rubble_move_min_m: 0.6,
        ..FaultConfig::default()
    };
    assert!(bad.validate().is_err());
    let bad = FaultConfig {
        step_m: 0.0,
        ..FaultConfig::default()
    };
    assert!(fault_pairs(1, 1, &[], &bad).is_err());
}
