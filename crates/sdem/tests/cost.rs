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

/// The sum in a given order, which the exact search takes first for a candidate of a box it
/// has bounded: over every point, in any order, it is eq. (1) up to rounding; cut short at a
/// cap it passes the cap and stops well below the cost; points counted as saturated add `τ²`
/// each; and its indices name the points as `Correlator::search_points` lists them.
#[test]
fn an_ordered_sum_is_the_cost_in_another_order() {
    use rand::seq::SliceRandom;
    use rand::SeedableRng;
    let (reference, query) = sdem_sim::benchmark::paper_pair().unwrap();
    let config = CostConfig::default();
    let mut correlator = Correlator::new(&reference, &query, &config).unwrap();
    let points = correlator.search_points();
    let n = points.len() as u32;
    let tau_sq = correlator.truncation_sq() as f64;
    let mut rng = rand_chacha::ChaCha8Rng::seed_from_u64(3);
    let mut checked = 0;
    for (x, y, yaw) in [
        (0.0, 0.0, 0.0),
        (0.12, 0.05, 0.02),
        (-0.3, 0.2, -0.1),
        (0.4, -0.1, 0.15),
    ] {
        let offset = Vec3::new(x, y, 0.0);
        let Some(cost) = correlator.evaluate(&offset, yaw).map(|c| c.cost) else {
            continue;
        };
        let mut order: Vec<u32> = (0..n).collect();
        order.shuffle(&mut rng);
        let full = correlator.ordered_lower_bound(&offset, yaw, 0, &order, f64::INFINITY);
        assert!((full - cost).abs() <= 1e-9 * cost, "{full} against {cost}");
        let cap = 0.5 * cost;
        let cut = correlator.ordered_lower_bound(&offset, yaw, 0, &order, cap);
        // Cut short: past the cap, after about half the points (checked every 64 of them).
        assert!(
            cut > cap && cut < 0.9 * cost,
            "{cut}: cap {cap}, cost {cost}"
        );
        let (saturated, rest) = order.split_at(100);
        let with_saturated = correlator.ordered_lower_bound(&offset, yaw, 100, rest, f64::INFINITY);
        let of_rest = correlator.ordered_lower_bound(&offset, yaw, 0, rest, f64::INFINITY);
        assert!(
            (with_saturated - of_rest - 100.0 * tau_sq / n as f64).abs() <= 1e-9 * cost,
            "{with_saturated} against {of_rest} + 100 τ²"
        );
        let of_saturated =
            correlator.ordered_lower_bound(&offset, yaw, 0, saturated, f64::INFINITY);
        assert!((of_saturated + of_rest - cost).abs() <= 1e-9 * cost);
        // The indices name the points as `search_points` lists them: the first 100 summed
        // point by point, each moved and looked up in the reference's cells here.
        let m = yaw_matrix(yaw);
        let t = offset.cast::<f32>();
        let by_hand: f64 = saturated
            .iter()
            .map(|&i| {
                let [x, y, z] = points[i as usize];
                let moved = [
                    m[(0, 0)] * x + m[(0, 1)] * y + m[(0, 2)] * z + t.x,
                    m[(1, 0)] * x + m[(1, 1)] * y + m[(1, 2)] * z + t.y,
                    m[(2, 0)] * x + m[(2, 1)] * y + m[(2, 2)] * z + t.z,
                ];
                let term = reference.grid().cell_of(moved).and_then(|(cell, range)| {
                    reference
                        .surfaces()
                        .squared_distance(cell as usize, moved, range)
                });
                term.map_or(tau_sq, |e2| (e2 as f64).min(tau_sq))
            })
            .sum::<f64>()
            / n as f64;
        assert!(
            (of_saturated - by_hand).abs() <= 1e-6 * of_saturated,
            "{of_saturated} against {by_hand} point by point"
        );
        checked += 1;
    }
    assert!(checked >= 3, "{checked} candidates with overlap");
}
