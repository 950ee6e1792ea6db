use super::*;
use proptest::prelude::*;

fn map() -> VoxelMap {
    VoxelMap::new(VoxelConfig::default()).unwrap()
}

/// Keys visited by `traverse`, with the end key appended.
fn chain(origin: &Vec3, end: &Vec3, s: f64) -> Vec<VoxelKey> {
    let inv_s = 1.0 / s;
    let mut keys = Vec::new();
    traverse(origin, key_of(origin, inv_s).unwrap(), end, inv_s, |k| {
        keys.push(k)
    });
    keys.push(key_of(end, inv_s).unwrap());
    keys
}

#[test]
fn voxel_config_defaults_are_octomaps() {
    let c = VoxelConfig::default();
    c.validate().unwrap();
    assert!((c.hit_log_odds - 0.847_297_860_387_203_4).abs() < 1e-12);
    assert!((c.miss_log_odds + 0.405_465_108_108_164_3).abs() < 1e-12);
    assert!((c.min_log_odds + 1.992_430_164_690_206_3).abs() < 1e-12);
    assert!((c.max_log_odds - 3.476_098_689_835_272).abs() < 1e-12);
    for bad in [
        VoxelConfig { voxel_m: 0.0, ..c },
        VoxelConfig {
            voxel_m: f64::NAN,
            ..c
        },
        VoxelConfig {
            hit_log_odds: -0.1,
            ..c
        },
        VoxelConfig {
            miss_log_odds: 0.1,
            ..c
        },
        VoxelConfig {
            min_log_odds: 0.5,
            ..c
        },
        VoxelConfig {
            max_log_odds: f64::INFINITY,
            ..c
        },
        VoxelConfig {
            max_range_m: 0.0,
            ..c
        },
    ] {
        assert!(VoxelMap::new(bad).is_err(), "{bad:?}");
    }
    // Unknown keys are refused, missing keys take the defaults.
    assert!(toml::from_str::<VoxelConfig>("voxel_size = 0.1").is_err());
    let partial: VoxelConfig = toml::from_str("voxel_m = 0.1").unwrap();
    assert_eq!(partial.max_range_m, 8.0);
}

#[test]
fn voxel_single_ray_marks_free_then_occupied() {
    let mut m = map();
    let origin = Vec3::new(0.01, 0.02, 0.03);
    let pose = Pose::translation(origin.x, origin.y, origin.z);
    // A ray along +x, 1 m long: voxels i = 0..=20 at j = k = 0.
    m.insert_scan(&pose, &[Vec3::new(1.0, 0.0, 0.0)]);
    let hit = VoxelConfig::default().hit_log_odds as f32;
    let miss = VoxelConfig::default().miss_log_odds as f32;
    for i in 0..20 {
        assert_eq!(m.log_odds(&[i, 0, 0]), Some(miss), "voxel {i}");
    }
    assert_eq!(m.log_odds(&[20, 0, 0]), Some(hit));
    assert_eq!(m.counts(), (1, 20));
    assert_eq!(m.len(), 21);
    assert_eq!(
        m.occupancy(&(origin + Vec3::new(1.0, 0.0, 0.0))),
        Occupancy::Occupied
    );
    assert_eq!(m.occupancy(&Vec3::new(0.5, 0.02, 0.03)), Occupancy::Free);
    // Beyond the end, beside the ray, behind the origin: unknown.
    for p in [
        Vec3::new(1.2, 0.02, 0.03),
        Vec3::new(0.5, 0.1, 0.03),
        Vec3::new(0.5, 0.02, -0.03),
        Vec3::new(-0.1, 0.02, 0.03),
    ] {
        assert_eq!(m.occupancy(&p), Occupancy::Unknown, "{p:?}");
    }
    let centres = m.occupied_centres();
    assert_eq!(centres.len(), 1);
    assert!((centres[0] - Vec3::new(1.025, 0.025, 0.025)).norm() < 1e-12);
    let (lo, hi) = m.bounds().unwrap();
    assert!((lo - Vec3::zeros()).norm() < 1e-12);
    assert!((hi - Vec3::new(1.05, 0.05, 0.05)).norm() < 1e-12);
    assert!(map().bounds().is_none());
}

#[test]
fn voxel_rays_are_cut_at_max_range_and_bad_points_skipped() {
    let mut m = VoxelMap::new(VoxelConfig {
        max_range_m: 1.0,
        ..Default::default()
    })
    .unwrap();
    let pose = Pose::translation(0.01, 0.01, 0.01);
    m.insert_scan(
        &pose,
        &[
            Vec3::new(3.0, 0.0, 0.0),
            Vec3::new(f64::NAN, 1.0, 0.0),
            Vec3::new(0.0, f64::INFINITY, 0.0),
        ],
    );
    // Free up to the cut at 1 m, no hit, unknown beyond.
    assert_eq!(m.counts(), (0, 20));
    assert_eq!(m.occupancy(&Vec3::new(0.9, 0.01, 0.01)), Occupancy::Free);
    assert_eq!(
        m.occupancy(&Vec3::new(2.99, 0.01, 0.01)),
        Occupancy::Unknown
    );
    assert_eq!(m.occupancy(&Vec3::new(0.01, 0.5, 0.01)), Occupancy::Unknown);
}

#[test]
fn voxel_hit_wins_over_miss_and_one_update_per_scan() {
    let mut m = map();
    let pose = Pose::translation(0.01, 0.01, 0.01);
    // The first ray ends in voxel [20, 0, 0]; the second passes through it to [40, 0, 0];
    // the third repeats the first. [20, 0, 0] gets one hit, [10, 0, 0] one miss.
    m.insert_scan(
        &pose,
        &[
            Vec3::new(1.02, 0.0, 0.0),
            Vec3::new(2.02, 0.0, 0.0),
            Vec3::new(1.03, 0.0, 0.0),
        ],
    );
    let c = VoxelConfig::default();
    assert_eq!(m.log_odds(&[20, 0, 0]), Some(c.hit_log_odds as f32));
    assert_eq!(m.log_odds(&[40, 0, 0]), Some(c.hit_log_odds as f32));
    assert_eq!(m.log_odds(&[10, 0, 0]), Some(c.miss_log_odds as f32));
    assert_eq!(m.log_odds(&[30, 0, 0]), Some(c.miss_log_odds as f32));
}

#[test]
fn voxel_log_odds_are_clamped() {
    let mut m = map();
    let pose = Pose::translation(0.01, 0.01, 0.01);
    for _ in 0..20 {
        m.insert_scan(&pose, &[Vec3::new(0.5, 0.0, 0.0)]);
    }
    let c = VoxelConfig::default();
    assert_eq!(m.log_odds(&[10, 0, 0]), Some(c.max_log_odds as f32));
    assert_eq!(m.log_odds(&[5, 0, 0]), Some(c.min_log_odds as f32));
    // A clamped occupied voxel is cleared by a bounded number of misses (the map can change
    // its mind): ceil((3.476 + 0) / 0.405) = 9 scans.
    for n in 1..=9 {
        m.insert_scan(&pose, &[Vec3::new(1.0, 0.0, 0.0)]);
        let expect = if n < 9 {
            Occupancy::Occupied
        } else {
            Occupancy::Free
        };
        assert_eq!(
            m.occupancy(&Vec3::new(0.52, 0.01, 0.01)),
            expect,
            "scan {n}"
        );
    }
}

/// A fan of rays from `origin` ending on the plane x = `x`, over the patch
/// |y|, |z − 0.5| ≤ 0.03 · `half`.
fn fan(origin: &Vec3, x: f64, half: i32) -> Vec<Vec3> {
    let mut points = Vec::new();
    for iy in -half..=half {
        for iz in -half..=half {
            let target = Vec3::new(x, 0.03 * f64::from(iy), 0.5 + 0.03 * f64::from(iz));
            points.push(target - origin);
        }
    }
    points
}

#[test]
fn voxel_moved_rubble_is_cleared() {
    let mut m = map();
    let origin = Vec3::new(0.0, 0.0, 0.5);
    let pose = Pose::translation(origin.x, origin.y, origin.z);
    // Scan 1: rubble at x = 2.01 in front of a wall at x = 4.01.
    let rubble = fan(&origin, 2.01, 10);
    m.insert_scan(&pose, &rubble);
    let rubble_in_world: Vec<Vec3> = rubble.iter().map(|p| p + origin).collect();
    assert!(rubble_in_world
        .iter()
        .all(|p| m.occupancy(p) == Occupancy::Occupied));
    assert_eq!(
        m.filter_occupied(&rubble_in_world).len(),
        m.counts().0,
        "one point per occupied voxel"
    );
    // The rubble is moved away; later scans, from slightly different places, see the wall
    // through where it was (the wall's patch is wide enough that its rays cross all of the
    // rubble's place). One hit (+0.85) needs three misses (−0.41 each) to turn free.
    let mut all_points = rubble_in_world.clone();
    for n in 0..3 {
        let origin_n = origin + Vec3::new(0.0, 0.01 * f64::from(n), 0.0);
        let wall = fan(&origin_n, 4.01, 25);
        m.insert_scan(
            &Pose::translation(origin_n.x, origin_n.y, origin_n.z),
            &wall,
        );
        all_points.extend(wall.iter().map(|p| p + origin_n));
    }
    let merged = m.filter_occupied(&all_points);
    assert!(!merged.is_empty());
    assert!(
        merged.iter().all(|p| (p.x - 4.01).abs() < 1e-9),
        "rubble survived: {:?}",
        merged.iter().find(|p| p.x < 3.0)
    );
    let cleared = rubble_in_world
        .iter()
        .filter(|p| m.occupancy(p) == Occupancy::Free)
        .count();
    assert_eq!(cleared, rubble_in_world.len());
    // The merged cloud keeps one centroid per occupied wall voxel.
    let mut keys: Vec<VoxelKey> = merged.iter().map(|p| m.key_of(p).unwrap()).collect();
    keys.sort_unstable();
    keys.dedup();
    assert_eq!(keys.len(), merged.len());
}

#[test]
fn voxel_from_voxels_checks_values() {
    let c = VoxelConfig::default();
    let m = VoxelMap::from_voxels(c, [([1, 2, 3], 0.5), ([-1, 0, 0], -0.2)]).unwrap();
    assert_eq!(m.counts(), (1, 1));
    assert!(VoxelMap::from_voxels(c, [([1, 2, 3], f32::NAN)]).is_err());
    assert!(VoxelMap::from_voxels(c, [([1, 2, 3], 10.0)]).is_err());
    assert!(VoxelMap::from_voxels(c, [([1, 2, 3], 0.5), ([1, 2, 3], 0.4)]).is_err());
    assert!(VoxelMap::from_voxels(c, [([i32::MAX, 2, 3], 0.5)]).is_err());
}

#[test]
fn voxel_dda_diagonal_and_degenerate() {
    // Same voxel: just that voxel.
    let a = Vec3::new(0.01, 0.01, 0.01);
    assert_eq!(chain(&a, &Vec3::new(0.02, 0.03, 0.04), 0.05).len(), 1);
    // Negative direction crossing zero.
    let c = chain(
        &Vec3::new(0.12, 0.01, 0.01),
        &Vec3::new(-0.12, 0.01, 0.01),
        0.05,
    );
    let xs: Vec<i32> = c.iter().map(|k| k[0]).collect();
    assert_eq!(xs, vec![2, 1, 0, -1, -2, -3]);
    // Through an exact corner: still a face-connected chain.
    let c = chain(
        &Vec3::new(0.025, 0.025, 0.025),
        &Vec3::new(0.125, 0.125, 0.125),
        0.05,
    );
    assert_eq!(c.first(), Some(&[0, 0, 0]));
    assert_eq!(c.last(), Some(&[2, 2, 2]));
    assert_eq!(c.len(), 7);
}

/// Distance from the segment to the closed box of a voxel is ~0 (the slab test).
fn segment_touches_voxel(o: &Vec3, e: &Vec3, key: &VoxelKey, s: f64) -> bool {
    let (mut t0, mut t1) = (0.0f64, 1.0f64);
    let eps = 1e-9;
    for axis in 0..3 {
        let lo = f64::from(key[axis]) * s - eps;
        let hi = f64::from(key[axis] + 1) * s + eps;
        let d = e[axis] - o[axis];
        if d.abs() < 1e-15 {
            if o[axis] < lo || o[axis] > hi {
                return false;
            }
        } else {
            let (a, b) = ((lo - o[axis]) / d, (hi - o[axis]) / d);
            t0 = t0.max(a.min(b));
            t1 = t1.min(a.max(b));
        }
    }
    t0 <= t1 + 1e-12
}

proptest! {
    #[test]
    fn voxel_dda_matches_dense_sampling(
        o in prop::array::uniform3(-2.0f64..2.0),
        e in prop::array::uniform3(-2.0f64..2.0),
        s in prop::sample::select(vec![0.05, 0.1, 0.37]),
    ) {
        let (o, e) = (Vec3::from(o), Vec3::from(e));
        let keys = chain(&o, &e, s);
        let inv_s = 1.0 / s;
        // Starts at the origin's voxel, ends at the end's, face-connected, no repeats.
        prop_assert_eq!(keys[0], key_of(&o, inv_s).unwrap());
        for w in keys.windows(2) {
            let d: i32 = (0..3).map(|a| (w[1][a] - w[0][a]).abs()).sum();
            prop_assert_eq!(d, 1, "{:?} -> {:?}", w[0], w[1]);
        }
        let mut sorted = keys.clone();
        sorted.sort_unstable();
        sorted.dedup();
        prop_assert_eq!(sorted.len(), keys.len());
        // Every voxel visited touches the segment.
        for k in &keys {
            prop_assert!(segment_touches_voxel(&o, &e, k, s), "{:?} off the ray", k);
        }
        // Every voxel a dense sampling of the segment lands in (away from boundaries, where
        // rounding may pick the neighbour) is visited.
        let n = ((e - o).norm() * inv_s * 50.0).ceil() as usize + 1;
        for i in 0..=n {
            let p = o + (e - o) * (i as f64 / n as f64);
            let near_boundary = (0..3).any(|a| {
                let f = p[a] * inv_s;
                (f - f.round()).abs() < 1e-7
            });
            if near_boundary {
                continue;
            }
            let k = key_of(&p, inv_s).unwrap();
            prop_assert!(sorted.binary_search(&k).is_ok(), "sample {:?} in {:?} missed", p, k);
        }
    }
}
