//! Speed of the occupancy voxel map: one scan like the simulator's (15,480 rays of
//! 2–3 m, as the tilting LRF sweeps ±90° × −45°..40°) inserted into the default 5 cm map, once
//! into an empty map (its blocks are allocated) and again into the same map (the steady state
//! of a long run, where the blocks exist).

use criterion::{criterion_group, criterion_main, BatchSize, Criterion};
use sdem::geometry::{direction, Pose, Vec3};
use sdem::voxel::{VoxelConfig, VoxelMap};
use std::hint::black_box;

fn scan() -> Vec<Vec3> {
    let mut points = Vec::new();
    for ia in 0..180 {
        for ie in 0..86 {
            let az = (f64::from(ia) - 90.0).to_radians() * 2.0;
            let el = (f64::from(ie) - 45.0).to_radians();
            let range = 2.5 + 0.5 * (f64::from(ia * 7 + ie * 3) * 0.1).sin();
            points.push(direction(az, el) * range);
        }
    }
    points
}

fn benches(c: &mut Criterion) {
    let points = scan();
    let pose = Pose::translation(0.3, -0.2, 0.5);
    let empty = VoxelMap::new(VoxelConfig::default()).expect("the default configuration is valid");
    let mut seen = empty.clone();
    seen.insert_scan(&pose, &points);
    let mut group = c.benchmark_group("voxel");
    group.sample_size(20);
    group.bench_function("insert_15k_rays_into_empty_map", |b| {
        b.iter_batched(
            || empty.clone(),
            |mut map| {
                map.insert_scan(black_box(&pose), black_box(&points));
                map
            },
            BatchSize::LargeInput,
        )
    });
    group.bench_function("insert_15k_rays_into_same_place", |b| {
        b.iter(|| seen.insert_scan(black_box(&pose), black_box(&points)))
    });
    group.finish();
}

criterion_group!(voxel, benches);
criterion_main!(voxel);
