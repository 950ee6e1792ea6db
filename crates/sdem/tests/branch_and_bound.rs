use rand::SeedableRng;
use sdem::bnb::*;
use sdem::cost::Correlator;
use sdem::cost::CostConfig;
use sdem::geometry::{pose_from_parts, Attitude, Pose, Vec3};
use sdem::localize::SearchWindow;
use sdem::sdem::Sdem;
use sdem::sdem::SdemConfig;
use sdem::search::{better, CandidateGrid, Exclusion, Scored};
use sdem::sensor::SensorConfig;
use sdem_sim::sim;

/// A scan at the origin of the paper's room and one at `truth` turned by `yaw_deg`, both
/// coarse (2° sweeps and cells, to keep the brute-force checks quick).
fn coarse_pair(seed: u64, truth: Vec3, yaw_deg: f64) -> (Sdem, Sdem) {
    let scene = sim::paper_room();
    let sensor = SensorConfig {
        tilt_step_deg: 2.0,
        pan_step_deg: 2.0,
        ..Default::default()
    };
    let grid_cfg = SdemConfig {
        resolution_deg: 2.0,
        ..Default::default()
    };
    let mut rng = rand_chacha::ChaCha8Rng::seed_from_u64(seed);
    let mut at = |p: &Pose| {
        let s = sim::scan(&scene, &sensor, p, 0.0, &mut rng);
        let a = s.mean_attitude();
        Sdem::from_points(&s.points_in_sensor(), &a, &grid_cfg).unwrap()
    };
    let r = at(&Pose::identity());
    let q = at(&pose_from_parts(
        truth,
        Attitude::from_degrees(0.0, 0.0, yaw_deg),
    ));
    (r, q)
}

/// The bound of every box is at most the smallest cost of its candidates (the property the
/// exactness rests on), at every box size, with and without a heading interval; and it is
/// tight enough near the optimum to prune most small boxes.
#[test]
fn bound_never_exceeds_the_boxes_minimum() {
    let truth = Vec3::new(0.22, 0.36, 0.05);
    let (r, q) = coarse_pair(1, truth, 1.0);
    let cost = CostConfig::default();
    let window = SearchWindow::around(&truth, [0.08, 0.08, 0.04]);
    let yaws: Vec<f64> = (-2..=2).map(|k| (k as f64).to_radians()).collect();
    let grid = CandidateGrid::new(&window, 0.02, yaws).unwrap();
    let mut c = Correlator::new(&r, &q, &cost).unwrap();
    let prepared = Prepared::new(&c);
    let bnb = BranchAndBound::new(&prepared, &grid, f64::INFINITY);
    let n = grid.counts;
    let costs: Vec<f64> = (0..grid.len())
        .map(|f| {
            let i = grid.index(f);
            c.evaluate(&grid.offset(i), grid.yaw(i))
                .map_or(f64::INFINITY, |x| x.cost)
        })
        .collect();
    let best = costs.iter().cloned().fold(f64::INFINITY, f64::min);
    assert!(best.is_finite());
    for (size, yaw_size) in [
        (1, 1),
        (2, 1),
        (4, 1),
        (8, 1),
        (2, 2),
        (4, 5),
        (9, 5),
        (16, 5),
    ] {
        let (mut pruned, mut boxes) = (0, 0);
        for l in (0..n[3]).step_by(yaw_size) {
            for z in (0..n[2]).step_by(size) {
                for y in (0..n[1]).step_by(size) {
                    for x in (0..n[0]).step_by(size) {
                        let lo = [x, y, z, l];
                        let hi = [
                            (x + size).min(n[0]) - 1,
                            (y + size).min(n[1]) - 1,
                            (z + size).min(n[2]) - 1,
                            (l + yaw_size).min(n[3]) - 1,
                        ];
                        let node = Node { lo, hi };
                        let (bound, _) = bnb.bound(&node);
                        let mut min = f64::INFINITY;
                        for ll in lo[3]..=hi[3] {
                            for zz in lo[2]..=hi[2] {
                                for yy in lo[1]..=hi[1] {
                                    for xx in lo[0]..=hi[0] {
                                        min = min.min(costs[grid.flat([xx, yy, zz, ll])]);
                                    }
                                }
                            }
                        }
                        assert!(
                            bound <= min,
                            "box {lo:?}..{hi:?}: bound {bound:e} above its minimum {min:e}"
                        );
                        boxes += 1;
                        pruned += (bound > best) as usize;
                    }
                }
            }
        }
        println!("boxes of {size}^3 x {yaw_size} headings: {pruned} of {boxes} pruned");
        if (size, yaw_size) == (2, 1) {
            assert!(
                pruned * 2 > boxes,
                "only {pruned} of {boxes} small boxes pruned"
            );
        }
    }
}

/// The AVX2 build of the bound and the baseline one give the same bounds, estimates and
/// hints, bit for bit, on boxes of every size, with and without a heading interval and a
/// parent's hint (the search's exactness is proved against the oracle with whichever build
/// the machine runs; this ties the other one to it).
#[cfg(target_arch = "x86_64")]
#[test]
fn both_builds_of_the_bound_agree_bit_for_bit() {
    if !std::is_x86_feature_detected!("avx2") {
        println!("no AVX2 here: only the baseline build runs");
        return;
    }
    let truth = Vec3::new(0.22, 0.36, 0.05);
    let (r, q) = coarse_pair(3, truth, 4.0);
    let window = SearchWindow::around(&truth, [0.3, 0.3, 0.08]);
    let yaws: Vec<f64> = (-8..=8).map(|k| (k as f64).to_radians()).collect();
    let grid = CandidateGrid::new(&window, 0.02, yaws).unwrap();
    let c = Correlator::new(&r, &q, &CostConfig::default()).unwrap();
    let prepared = Prepared::new(&c);
    let bnb = BranchAndBound::new(&prepared, &grid, f64::INFINITY);
    let n = grid.counts;
    let mut compared = 0;
    for size in [1usize, 2, 3, 5, 8, 13, 31] {
        for yaw_size in [1usize, 2, 5, 17] {
            for x in (0..n[0]).step_by(size.max(7)) {
                for l in (0..n[3]).step_by(yaw_size.max(4)) {
                    let lo = [x, x % n[1], 0, l];
                    let hi = [
                        (lo[0] + size).min(n[0]) - 1,
                        (lo[1] + size).min(n[1]) - 1,
                        (lo[2] + size).min(n[2]) - 1,
                        (lo[3] + yaw_size).min(n[3]) - 1,
                    ];
                    let node = Node { lo, hi };
                    let (b0, e0, h0) = bnb.bound_below_any(&node, f64::INFINITY, None);
                    // SAFETY: AVX2 was found above.
                    let (b1, e1, h1) = unsafe { bnb.bound_below_avx2(&node, f64::INFINITY, None) };
                    assert_eq!((b0.to_bits(), e0.to_bits()), (b1.to_bits(), e1.to_bits()));
                    assert_eq!(h0.is_some(), h1.is_some());
                    if let (Some(h0), Some(h1)) = (h0, h1) {
                        assert_eq!((h0.saturated, &h0.order), (h1.saturated, &h1.order));
                        // The children's bounds with the parent's hint, cut short or not.
                        for child in node.children(&bnb.axis_step) {
                            for limit in [f64::INFINITY, b0 * 1.5] {
                                let a = bnb.bound_below_any(&child, limit, Some(&h0));
                                // SAFETY: as above.
                                let b = unsafe { bnb.bound_below_avx2(&child, limit, Some(&h1)) };
                                assert_eq!(
                                    (a.0.to_bits(), a.1.to_bits()),
                                    (b.0.to_bits(), b.1.to_bits())
                                );
                            }
                        }
                    }
                    compared += 1;
                }
            }
        }
    }
    assert!(compared > 100, "{compared} boxes compared");
}

/// Every candidate's cost on `grid`, by flat index (`None`: too little overlap).
fn costs_of(correlator: &mut Correlator, grid: &CandidateGrid) -> Vec<Option<f64>> {
    (0..grid.len())
        .map(|f| {
            let i = grid.index(f);
            correlator
                .evaluate(&grid.offset(i), grid.yaw(i))
                .map(|c| c.cost)
        })
        .collect()
}

/// The exhaustive answer: the best candidate of `grid` (which may leave some out) costing at
/// most `cap`, from every candidate's cost.
fn oracle_below(costs: &[Option<f64>], grid: &CandidateGrid, cap: f64) -> Option<Scored> {
    (0..grid.len())
        .filter(|&f| !grid.excluded(grid.index(f)))
        .filter_map(|f| costs[f].filter(|&c| c <= cap).map(|c| (c, f)))
        .fold(None, |b: Option<Scored>, s| match b {
            Some(b) if !better(&s, &b) => Some(b),
            _ => Some(s),
        })
}

/// The pair and grid the runner-up tests search: 7 headings, 2 cm steps.
fn runner_up_case() -> (Sdem, Sdem, CandidateGrid) {
    let truth = Vec3::new(0.12, -0.08, 0.03);
    let (r, q) = coarse_pair(4, truth, 2.0);
    let window = SearchWindow::around(&truth, [0.12, 0.12, 0.04]);
    let yaws: Vec<f64> = (-3..=3).map(|k| (k as f64).to_radians()).collect();
    (r, q, CandidateGrid::new(&window, 0.02, yaws).unwrap())
}

/// The runner-up search, continued from what the first search set aside, finds the same
/// candidate as the exhaustive search of the grid without the peak's neighbourhood, with the
/// same cap: for several ratios (so the cap sits above a few, many or no candidates). The same
/// reserve then serves further searches, each leaving out a ball more around the last answer
/// (the candidates of other basins): each answer is the exhaustive one outside all the balls.
#[test]
fn runner_up_from_the_reserve_equals_the_exhaustive_runner_up() {
    let (r, q, grid) = runner_up_case();
    let mut correlator = Correlator::new(&r, &q, &CostConfig::default()).unwrap();
    let prepared = Prepared::new(&correlator);
    let costs = costs_of(&mut correlator, &grid);
    let (mut found, mut most_balls) = (0, 0);
    for ratio in [1.05, 1.3, 2.0, 5.0, 20.0] {
        let (best, _, reserve) = search(&prepared, &grid, f64::INFINITY, Some(ratio));
        let (best_cost, best_flat) = best.unwrap();
        let reserve = reserve.unwrap();
        let mut outside = grid.clone();
        outside.exclude = vec![Exclusion::ball(grid.offset(grid.index(best_flat)), 0.03)];
        let cap = ratio * best_cost;
        for round in 0..5 {
            let (next, _) = runner_up(&prepared, &outside, cap, &reserve);
            let oracle = oracle_below(&costs, &outside, cap);
            assert_eq!(next, oracle, "ratio {ratio}, round {round}");
            found += (round == 0 && oracle.is_some()) as usize;
            let Some((_, flat)) = next else { break };
            outside
                .exclude
                .push(Exclusion::ball(grid.offset(grid.index(flat)), 0.03));
            most_balls = most_balls.max(outside.exclude.len());
        }
    }
    // Not vacuous: the higher caps do hold candidates, and several balls were left out in turn.
    assert!(found >= 2, "only {found} of the caps held a runner-up");
    assert!(most_balls >= 4, "at most {most_balls} balls left out");
}

/// Balls left out at some headings only (the runner-up search's slopes of the optimum): each
/// answer from the reserve is the exhaustive one outside them (left out by a test of its own
/// here, not the grid's), and a candidate inside a ball's offsets at another heading is still
/// found.
#[test]
fn runner_up_leaving_balls_out_at_some_headings_equals_the_exhaustive_one() {
    let (r, q, grid) = runner_up_case();
    let last_heading = grid.counts[3] - 1;
    let mut correlator = Correlator::new(&r, &q, &CostConfig::default()).unwrap();
    let prepared = Prepared::new(&correlator);
    let costs = costs_of(&mut correlator, &grid);
    let mut at_another_heading = 0;
    for ratio in [1.3, 2.0, 5.0] {
        let (best, _, reserve) = search(&prepared, &grid, f64::INFINITY, Some(ratio));
        let (best_cost, best_flat) = best.unwrap();
        let reserve = reserve.unwrap();
        let peak = (grid.offset(grid.index(best_flat)), 0.03);
        let mut outside = grid.clone();
        outside.exclude = vec![Exclusion::ball(peak.0, peak.1)];
        let mut balls: Vec<(Vec3, f64, [usize; 2])> = Vec::new();
        let left_out = |f: usize, balls: &[(Vec3, f64, [usize; 2])]| {
            let idx = grid.index(f);
            let x = grid.offset(idx);
            (x - peak.0).norm() <= peak.1
                || balls
                    .iter()
                    .any(|(c, r, [h0, h1])| *h0 <= idx[3] && idx[3] <= *h1 && (x - c).norm() <= *r)
        };
        let cap = ratio * best_cost;
        for round in 0..8 {
            let (next, _) = runner_up(&prepared, &outside, cap, &reserve);
            let oracle = (0..grid.len())
                .filter(|&f| !left_out(f, &balls))
                .filter_map(|f| costs[f].filter(|&c| c <= cap).map(|c| (c, f)))
                .fold(None, |b: Option<Scored>, s| match b {
                    Some(b) if !better(&s, &b) => Some(b),
                    _ => Some(s),
                });
            assert_eq!(next, oracle, "ratio {ratio}, round {round}");
            let Some((_, flat)) = next else { break };
            let idx = grid.index(flat);
            let offset = grid.offset(idx);
            at_another_heading += balls.iter().any(|(c, r, _)| (offset - c).norm() <= *r) as usize;
            // Its own heading only, or with the next ones either side.
            let headings = if round % 2 == 0 {
                [idx[3], idx[3]]
            } else {
                [idx[3].saturating_sub(1), (idx[3] + 1).min(last_heading)]
            };
            balls.push((offset, 0.03, headings));
            outside
                .exclude
                .push(Exclusion::at_headings(offset, 0.03, headings));
        }
    }
    assert!(
        at_another_heading >= 1,
        "no answer lay in a left-out ball at another heading: the test would be vacuous"
    );
}

/// A box is skipped as left out only when every candidate in it is: over every box of up to
/// three candidates a side of a small grid, with balls at a single heading (the first, the
/// last, one between) and over a range of headings.
#[test]
fn a_box_left_out_holds_only_left_out_candidates() {
    let window = SearchWindow::around(&Vec3::zeros(), [0.06, 0.06, 0.02]);
    let yaws: Vec<f64> = (-3..=3).map(|k| (k as f64).to_radians()).collect();
    let mut grid = CandidateGrid::new(&window, 0.02, yaws).unwrap();
    let last = grid.counts[3] - 1;
    grid.exclude = vec![Exclusion::ball(Vec3::new(0.04, 0.04, 0.0), 0.025)];
    let plain = grid.clone();
    grid.exclude.extend([
        Exclusion::at_headings(Vec3::new(-0.03, 0.0, 0.0), 0.035, [0, 0]),
        Exclusion::at_headings(Vec3::new(0.0, -0.02, 0.0), 0.045, [last, last]),
        Exclusion::at_headings(Vec3::new(0.01, 0.01, 0.01), 0.05, [2, 4]),
    ]);
    let [nx, ny, nz, nh] = grid.counts;
    let (mut boxes, mut left_out, mut by_turned) = (0, 0, 0);
    for lo in (0..nx * ny * nz * nh).map(|f| grid.index(f)) {
        for size in (0..27 * 3).map(|k| [k % 3, (k / 3) % 3, (k / 9) % 3, k / 27]) {
            let hi: [usize; 4] = std::array::from_fn(|a| lo[a] + size[a]);
            if (0..4).any(|a| hi[a] >= grid.counts[a]) {
                continue;
            }
            boxes += 1;
            if !grid.box_excluded(lo, hi) {
                continue;
            }
            left_out += 1;
            by_turned += !plain.box_excluded(lo, hi) as usize;
            for k in 0..(size.iter().map(|s| s + 1).product::<usize>()) {
                let (sx, sy, sz) = (size[0] + 1, size[1] + 1, size[2] + 1);
                let idx = [
                    lo[0] + k % sx,
                    lo[1] + (k / sx) % sy,
                    lo[2] + (k / (sx * sy)) % sz,
                    lo[3] + k / (sx * sy * sz),
                ];
                assert!(grid.excluded(idx), "box {lo:?}..={hi:?} holds {idx:?}");
            }
        }
    }
    assert!(left_out < boxes, "{left_out} of {boxes} boxes left out");
    assert!(by_turned > 0, "no box left out by a ball at some headings");
}

/// The workers share one queue and finish in any order: the minimum and the runner-up are
/// the exhaustive ones with one worker, with three, and with eight (more than the cores,
/// so that they interleave at every step).
#[test]
fn the_answers_do_not_depend_on_the_workers() {
    let truth = Vec3::new(-0.06, 0.1, 0.02);
    let (r, q) = coarse_pair(7, truth, -1.5);
    let cost = CostConfig::default();
    let window = SearchWindow::around(&truth, [0.16, 0.16, 0.04]);
    let yaws: Vec<f64> = (-4..=4).map(|k| (0.5 * k as f64).to_radians()).collect();
    let grid = CandidateGrid::new(&window, 0.02, yaws).unwrap();
    let mut correlator = Correlator::new(&r, &q, &cost).unwrap();
    let prepared = Prepared::new(&correlator);
    let costs = costs_of(&mut correlator, &grid);
    let best = oracle_below(&costs, &grid, f64::INFINITY).unwrap();
    let mut outside = grid.clone();
    outside.exclude = vec![Exclusion::ball(grid.offset(grid.index(best.1)), 0.03)];
    let cap = 1.5 * best.0;
    let second = oracle_below(&costs, &outside, cap);
    assert!(
        second.is_some(),
        "no runner-up below the cap: the test would be vacuous"
    );
    for threads in [1, 3, 8] {
        let pool = rayon::ThreadPoolBuilder::new()
            .num_threads(threads)
            .build()
            .unwrap();
        let (found, found_second) = pool.install(|| {
            let (found, _, reserve) = search(&prepared, &grid, f64::INFINITY, Some(1.5));
            let (found_second, _) = runner_up(&prepared, &outside, cap, &reserve.unwrap());
            (found, found_second)
        });
        assert_eq!(found, Some(best), "{threads} workers");
        assert_eq!(found_second, second, "{threads} workers");
    }
}
