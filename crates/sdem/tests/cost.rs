use sdem::cost::*;
use sdem::geometry::Vec3;
use sdem::sdem::Sdem;

/// The cap grows the cubes until the points fit, keeps a scan that fits as it is, and 0
/// lifts it; every chosen point is one of the scan's.
#[test]
fn search_points_respect_the_cap() {
    let (_, query) = sdem_sim::benchmark::paper_pair().unwrap();
    let base = CostConfig {
        max_search_points: 0,
        ..CostConfig::default()
    };
    let all = search_points_of(&query, &base);
    assert_eq!(all, search_points(&query, base.search_voxel_m));
    assert!(all.len() > 2000, "{}", all.len());
    for cap in [1500, 1000, 300] {
        let capped = search_points_of(
            &query,
            &CostConfig {
                max_search_points: cap,
                ..base.clone()
            },
        );
        assert!(
            capped.len() <= cap && capped.len() > cap / 3,
            "{cap}: {}",
            capped.len()
        );
        assert!(capped.iter().all(|p| query.points().contains(p)));
    }
    let roomy = CostConfig {
        max_search_points: all.len(),
        ..base
    };
    assert_eq!(search_points_of(&query, &roomy), all);
}

/// Settling runs of points that share a cube keeps, per cube, the same point as one table
/// lookup per point: the first of those nearest to the cube's centre (ties included: the
/// grid of points below puts several at one distance from a centre).
#[test]
fn search_points_keep_the_first_nearest_point_of_each_cube() {
    use rand::{Rng, SeedableRng};
    let one_lookup_per_point = |query: &Sdem, v: f32| -> Vec<[f32; 3]> {
        let mut chosen: std::collections::HashMap<[i32; 3], (usize, f32)> = Default::default();
        for (i, p) in query.points().iter().enumerate() {
            let key = p.map(|c| (c / v).floor() as i32);
            let off = [0, 1, 2].map(|a| p[a] - (key[a] as f32 + 0.5) * v);
            let d = off[0] * off[0] + off[1] * off[1] + off[2] * off[2];
            let e = chosen.entry(key).or_insert((i, d));
            if d < e.1 {
                *e = (i, d);
            }
        }
        let mut kept: Vec<usize> = chosen.values().map(|e| e.0).collect();
        kept.sort_unstable();
        kept.iter().map(|&i| query.points()[i]).collect()
    };
    let (_, paper) = sdem_sim::benchmark::paper_pair().unwrap();
    let mut rng = rand_chacha::ChaCha8Rng::seed_from_u64(5);
    // Points on a lattice of 1/32 m: with cubes of 1/16, 1/8 and 1/4 m every distance is
    // exact in f32, so many points tie for their cube.
    let lattice: Vec<Vec3> = (0..4000)
        .map(|_| {
            let mut c = |n: i32| f64::from(rng.random_range(-n..n)) / 32.0;
            Vec3::new(c(48), c(48), c(12))
        })
        .collect();
    let lattice = Sdem::from_points(
        &lattice,
        &sdem::geometry::Attitude::default(),
        &sdem::sdem::SdemConfig::default(),
    )
    .unwrap();
    for query in [&paper, &lattice] {
        for v in [0.0625, 0.08, 0.125, 0.25, 0.3] {
            let chosen = search_points(query, v);
            assert!(!chosen.is_empty());
            assert_eq!(chosen, one_lookup_per_point(query, v as f32), "cube {v} m");
        }
    }
}
