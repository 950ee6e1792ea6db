use super::stops::lift_settings;
use super::*;
use approx::assert_relative_eq;
use nalgebra::{Rotation3, Vector3};
use rand::SeedableRng;
use rand_chacha::ChaCha8Rng;
use sdem::geometry::{attitude_of, Attitude, Pose};
use sdem::sensor::{LiftConfig, SensorConfig};

fn room_with(free: &[OrientedBox], solids: &[Solid]) -> Scene {
    let mut scene = Scene::new();
    free.iter().cloned().for_each(|b| scene.add_free(b));
    solids.iter().cloned().for_each(|s| scene.add_solid(s));
    scene
}

fn unit(x: f64, y: f64, z: f64) -> Vec3 {
    Vec3::new(x, y, z).normalize()
}

#[test]
fn raycast_inside_one_box_is_exact() {
    let scene = room_with(&[aabb([-1.0, -0.5, -0.3], [2.0, 1.5, 0.7])], &[]);
    let o = Vec3::zeros();
    let cases = [
        (Vec3::x(), 2.0),
        (-Vec3::x(), 1.0),
        (Vec3::y(), 1.5),
        (-Vec3::y(), 0.5),
        (Vec3::z(), 0.7),
        (-Vec3::z(), 0.3),
        (unit(1.0, 1.0, 0.0), 1.5 * 2f64.sqrt()),
        (unit(-1.0, 0.0, -1.0), 0.3 * 2f64.sqrt()),
    ];
    for (d, expected) in cases {
        assert_relative_eq!(
            scene.raycast(&o, &d, 10.0).unwrap(),
            expected,
            epsilon = 1e-12
        );
    }
    assert!(scene.raycast(&o, &Vec3::x(), 1.9).is_none());
    // A box turned 30° about z: along its own axes the distances are its half extents.
    let yaw = 30f64.to_radians();
    let turned =
        OrientedBox::new(Vec3::zeros(), Vec3::new(2.0, 1.0, 0.5), yaw_rotation(yaw)).unwrap();
    let scene = room_with(&[turned], &[]);
    let along = Vec3::new(yaw.cos(), yaw.sin(), 0.0);
    let across = Vec3::new(-yaw.sin(), yaw.cos(), 0.0);
    assert_relative_eq!(
        scene.raycast(&o, &along, 10.0).unwrap(),
        2.0,
        epsilon = 1e-12
    );
    assert_relative_eq!(
        scene.raycast(&o, &-across, 10.0).unwrap(),
        1.0,
        epsilon = 1e-12
    );
    // From outside the air the ray hits at once.
    assert_eq!(
        scene.raycast(&Vec3::new(0.0, 0.0, 3.0), &-Vec3::z(), 10.0),
        Some(0.0)
    );
}

#[test]
fn ray_crosses_shared_faces_of_free_boxes() {
    let a = aabb([-1.0, -1.0, -1.0], [1.0, 1.0, 1.0]);
    let b = aabb([1.0, -0.5, -0.5], [4.0, 0.5, 0.5]); // shares the face x = 1
    let c = aabb([3.0, -0.2, -0.2], [6.0, 0.2, 0.2]); // overlaps b
    let scene = room_with(&[a, b, c], &[]);
    let o = Vec3::zeros();
    assert_relative_eq!(
        scene.raycast(&o, &Vec3::x(), 10.0).unwrap(),
        6.0,
        epsilon = 1e-12
    );
    // Back from the far end through both junctions to a's far wall.
    let far = Vec3::new(5.5, 0.0, 0.0);
    assert_relative_eq!(
        scene.raycast(&far, &-Vec3::x(), 10.0).unwrap(),
        6.5,
        epsilon = 1e-12
    );
    // Through the shared face but outside b's cross-section: a's wall.
    let d = unit(1.0, 0.7, 0.0);
    assert_relative_eq!(
        scene.raycast(&o, &d, 10.0).unwrap(),
        (1.0f64 + 0.49).sqrt(),
        epsilon = 1e-12
    );
    // Into b, then out through b's side wall at y = 0.5.
    let d = unit(3.0, 0.5, 0.0);
    assert_relative_eq!(
        scene.raycast(&o, &d, 10.0).unwrap(),
        (9.0f64 + 0.25).sqrt(),
        epsilon = 1e-12
    );
    // A turned leg sharing an edge region with a: continues through.
    let yaw = 20f64.to_radians();
    let leg = OrientedBox::new(
        Vec3::new(2.0 * yaw.cos(), 2.0 * yaw.sin(), 0.0),
        Vec3::new(1.5, 0.3, 0.3),
        yaw_rotation(yaw),
    )
    .unwrap();
    let scene = room_with(&[aabb([-1.0, -1.0, -1.0], [1.0, 1.0, 1.0]), leg], &[]);
    let d = Vec3::new(yaw.cos(), yaw.sin(), 0.0);
    assert_relative_eq!(scene.raycast(&o, &d, 10.0).unwrap(), 3.5, epsilon = 1e-12);
    assert!(scene.is_free(&(d * 3.4)) && !scene.is_free(&(d * 3.6)));
}

#[test]
fn solids_inside_the_air_are_hit_at_the_right_distance() {
    let air = aabb([-5.0, -5.0, -1.0], [5.0, 5.0, 2.0]);
    let diamond = OrientedBox::new(
        Vec3::new(2.0, 0.0, 0.0),
        Vec3::new(0.5, 0.5, 0.5),
        yaw_rotation(45f64.to_radians()),
    )
    .unwrap();
    let rock = Ellipsoid::new(
        Vec3::new(0.0, 2.0, 0.0),
        Vec3::new(0.3, 0.5, 0.4),
        Rotation3::identity(),
    )
    .unwrap();
    let tilted = OrientedBox::new(
        Vec3::new(0.0, -2.0, 0.0),
        Vec3::new(0.5, 0.5, 0.5),
        Rotation3::from_euler_angles(0.4, 0.0, 0.0),
    )
    .unwrap();
    let scene = room_with(
        &[air],
        &[
            Solid::Box(diamond),
            Solid::Ellipsoid(rock),
            Solid::Box(tilted),
        ],
    );
    let o = Vec3::zeros();
    // The diamond's near corner.
    assert_relative_eq!(
        scene.raycast(&o, &Vec3::x(), 10.0).unwrap(),
        2.0 - 0.5 * 2f64.sqrt(),
        epsilon = 1e-12
    );
    assert_relative_eq!(
        scene.raycast(&o, &Vec3::y(), 10.0).unwrap(),
        1.5,
        epsilon = 1e-12
    );
    // A box rolled by 0.4 rad about x: its face toward the origin is 0.5 from its centre
    // along the face normal (0, -cos 0.4, -sin 0.4).
    let along_y = 0.5 / 0.4f64.cos();
    assert_relative_eq!(
        scene.raycast(&o, &-Vec3::y(), 10.0).unwrap(),
        2.0 - along_y,
        epsilon = 1e-12
    );
    // Missed solids leave the wall; inside a solid nothing is free.
    assert_relative_eq!(
        scene.raycast(&o, &-Vec3::x(), 10.0).unwrap(),
        5.0,
        epsilon = 1e-12
    );
    assert!(!scene.is_free(&Vec3::new(2.0, 0.0, 0.0)));
    assert!(!scene.is_free(&Vec3::new(0.0, 2.0, 0.35)));
    assert!(scene.is_free(&Vec3::new(0.0, 2.0, 0.45)));
    assert_eq!(
        scene.raycast(&Vec3::new(2.0, 0.0, 0.0), &Vec3::x(), 10.0),
        Some(0.0)
    );
}

#[test]
fn floor_height_is_the_lowest_place_to_stand() {
    let room = paper_room();
    let f = -PAPER_ROOM_SENSOR_HEIGHT_M;
    assert_relative_eq!(room.floor_height(0.0, 0.0).unwrap(), f, epsilon = 1e-12);
    // On top of the box at (1.3, 0.7) (there is no gap under it).
    assert_relative_eq!(
        room.floor_height(1.3, 0.7).unwrap(),
        f + 0.4,
        epsilon = 1e-12
    );
    // Under the beam the floor is still the floor.
    assert_relative_eq!(room.floor_height(1.6, 0.0).unwrap(), f, epsilon = 1e-12);
    assert!(room.floor_height(9.0, 0.0).is_none());
    assert!(room.is_free(&Vec3::zeros()) && room.is_free(&Vec3::new(0.0, 0.0, 0.3)));
}

#[test]
fn corridor_is_long_and_plain() {
    let c = corridor(20.0).unwrap();
    let o = Vec3::zeros();
    assert_relative_eq!(
        c.raycast(&o, &Vec3::x(), 20.0).unwrap(),
        10.0,
        epsilon = 1e-12
    );
    assert_relative_eq!(
        c.raycast(&o, &Vec3::y(), 20.0).unwrap(),
        0.6,
        epsilon = 1e-12
    );
    assert_relative_eq!(
        c.raycast(&o, &-Vec3::z(), 20.0).unwrap(),
        0.4,
        epsilon = 1e-12
    );
    assert!(corridor(f64::NAN).is_err() && corridor(-3.0).is_err());
}

fn bits(run: &[SimStop]) -> Vec<u32> {
    run.iter()
        .flat_map(|s| s.sweep.lines.iter())
        .flat_map(|l| l.ranges.iter().map(|r| r.to_bits()))
        .collect()
}

#[test]
fn same_seed_same_scene_and_sweep() {
    let sensor = SensorConfig::default();
    let a = collapsed_building(3);
    assert_eq!(a, collapsed_building(3));
    assert_ne!(a, collapsed_building(4));
    let stops = collapsed_building_stops(&a, 3, 2, &sensor.lift).unwrap();
    assert_eq!(
        stops,
        collapsed_building_stops(&a, 3, 2, &sensor.lift).unwrap()
    );
    let run1 = simulate_run(&a, &stops, &sensor, 3).unwrap();
    let run2 = simulate_run(&a, &stops, &sensor, 3).unwrap();
    assert_eq!(bits(&run1), bits(&run2));
    assert_eq!(
        run1[1].sweep.lines[0].attitude,
        run2[1].sweep.lines[0].attitude
    );
    let run3 = simulate_run(&a, &stops, &sensor, 4).unwrap();
    assert_ne!(bits(&run1), bits(&run3));
    // A stop's sweep does not depend on the other stops.
    let alone = simulate_run(&a, &stops[..1], &sensor, 3).unwrap();
    assert_eq!(bits(&alone), bits(&run1[..1]));
}

/// Checks every constraint of the collapsed-building path.
fn check_path(seed: u64) {
    let lift = LiftConfig::default();
    let scene = collapsed_building(seed);
    let stops = collapsed_building_stops(&scene, seed, MAX_STOPS, &lift).unwrap();
    let poses: Vec<Pose> = stops
        .iter()
        .map(|s| s.world_from_sensor(&lift).unwrap())
        .collect();
    assert_eq!(poses[0], Pose::identity(), "seed {seed}");
    let mut lift_changes = 0;
    for k in 0..stops.len() {
        let a = attitude_of(&stops[k].world_from_body);
        assert!(
            a.roll.abs() <= 4f64.to_radians() + 1e-12,
            "seed {seed} stop {k}"
        );
        assert!(
            a.pitch.abs() <= 4f64.to_radians() + 1e-12,
            "seed {seed} stop {k}"
        );
        let body = stops[k].world_from_body.translation.vector;
        let floor = scene.floor_height(body.x, body.y).unwrap();
        assert!(
            (body.z - floor).abs() < 0.04,
            "seed {seed} stop {k}: body off the floor"
        );
        let p = poses[k].translation.vector;
        let clearance = scene.clearance(&p, 600);
        assert!(
            clearance >= MIN_SENSOR_CLEARANCE_M,
            "seed {seed} stop {k}: {clearance}"
        );
        if k == 0 {
            continue;
        }
        let q = poses[k - 1].translation.vector;
        let step = (p - q).xy();
        assert!(
            (0.25..=0.45).contains(&step.norm()),
            "seed {seed} stop {k}: {}",
            step.norm()
        );
        let yaw0 = attitude_of(&stops[k - 1].world_from_body).yaw;
        let heading = Vector3::new(yaw0.cos(), yaw0.sin(), 0.0).xy();
        assert!(
            step.dot(&heading) > 0.8 * step.norm(),
            "seed {seed} stop {k}: not forward"
        );
        let turn = wrap_angle(a.yaw - yaw0).abs();
        assert!(
            turn <= 20f64.to_radians(),
            "seed {seed} stop {k}: turn {}",
            turn.to_degrees()
        );
        if stops[k].lift_slide_m != stops[k - 1].lift_slide_m {
            lift_changes += 1;
        } else {
            assert!(
                (p.z - q.z).abs() <= 0.06,
                "seed {seed} stop {k}: dz {}",
                p.z - q.z
            );
        }
    }
    assert_eq!(lift_changes, 2, "seed {seed}");
    // Low in the ditch, high in the void.
    assert!(stops[6].lift_slide_m > 0.5 && stops[MAX_STOPS - 1].lift_slide_m < 0.25);
    // The loop comes back to the place and heading where it began.
    let (i, j) = scene.loop_closure_stops().unwrap();
    assert!(j < MAX_STOPS, "seed {seed}: loop closes at stop {j}");
    let (pi, pj) = (poses[i].translation.vector, poses[j].translation.vector);
    assert!(
        (pi - pj).xy().norm() < 1e-9 && (pi.z - pj.z).abs() < 0.06,
        "seed {seed}"
    );
}

#[test]
fn collapsed_building_path_is_drivable() {
    for seed in [0, 1, 2] {
        check_path(seed);
    }
}

#[test]
fn stops_reject_bad_arguments() {
    let lift = LiftConfig::default();
    let scene = collapsed_building(1);
    assert!(collapsed_building_stops(&scene, 1, 0, &lift).is_err());
    assert!(collapsed_building_stops(&scene, 1, MAX_STOPS + 1, &lift).is_err());
    assert!(collapsed_building_stops(&paper_room(), 1, 3, &lift).is_err());
    let short = LiftConfig {
        link_length_m: 0.2,
        slide_max_m: 0.39,
        ..LiftConfig::default()
    };
    assert!(collapsed_building_stops(&scene, 1, 3, &short).is_err());
}

#[test]
fn noise_free_scan_lies_on_the_surfaces() {
    let sensor = SensorConfig {
        range_noise_m: 0.0,
        tilt_sensor_noise_deg: 0.0,
        compass_noise_deg: 0.0,
        ..SensorConfig::default()
    };
    let room = paper_room();
    let mut rng = ChaCha8Rng::seed_from_u64(9);
    let sweep = scan(&room, &sensor, &Pose::identity(), 0.3, &mut rng);
    sweep.validate().unwrap();
    assert_eq!(sweep.lift_slide_m, 0.3);
    assert_eq!(sweep.mean_attitude(), Attitude::default());
    let points = sweep.points_in_sensor();
    // A closed room within range: every beam returns.
    assert_eq!(points.len(), 86 * 181);
    let mut on_solids = 0;
    for p in &points {
        let d = p.normalize();
        assert!(
            room.is_free(&(p - d * 1e-4)),
            "{p:?} is not reached through air"
        );
        assert!(!room.is_free(&(p + d * 1e-4)), "{p:?} is not on a surface");
        if room.free_volumes()[0].contains(&(p + d * 1e-4)) {
            on_solids += 1;
        }
    }
    assert!(on_solids > 500, "the obstacles are seen: {on_solids}");
}

#[test]
fn default_sensor_sees_most_of_the_ditch() {
    let sensor = SensorConfig::default();
    let scene = collapsed_building(5);
    let stops = collapsed_building_stops(&scene, 5, 6, &sensor.lift).unwrap();
    let (high, low) = lift_settings(&sensor.lift).unwrap();
    assert_eq!((stops[0].lift_slide_m, stops[5].lift_slide_m), (high, low));
    let run = simulate_run(&scene, &stops[5..], &sensor, 5).unwrap();
    let sweep = &run[0].sweep;
    assert_eq!(sweep.lines.len(), 86);
    assert!(sweep.lines.iter().all(|l| l.ranges.len() == 181));
    let total = 86 * 181;
    let returns = sweep.points_in_sensor().len();
    assert!(returns as f64 > 0.95 * total as f64, "{returns} of {total}");
    // The reading is near the truth and the same on every line.
    let truth = attitude_of(&run[0].world_from_sensor);
    let reading = sweep.lines[0].attitude;
    assert!(sweep.lines.iter().all(|l| l.attitude == reading));
    assert!((reading.roll - truth.roll).abs() < 1f64.to_radians());
    assert!((wrap_angle(reading.yaw - truth.yaw)).abs() < 1f64.to_radians());
}
