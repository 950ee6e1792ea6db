use proptest::prelude::*;
use rand::SeedableRng;
use rand_chacha::ChaCha8Rng;
use sdem::cost::{Correlator, CostModel};
use sdem::doubt::Doubt;
use sdem::error::Error;
use sdem::geometry::pose_from_parts;
use sdem::geometry::{Attitude, Pose, Vec3};
use sdem::localize::*;
use sdem::sdem::Sdem;
use sdem::sdem::SdemConfig;
use sdem::sensor::SensorConfig;
use sdem_sim::sim;

/// A scan of `scene` from `world_from_sensor`, as an S-DEM with its attitude reading.
fn sdem_at(
    scene: &sim::Scene,
    world_from_sensor: &Pose,
    sensor: &SensorConfig,
    grid: &SdemConfig,
    seed: u64,
) -> Sdem {
    let mut rng = ChaCha8Rng::seed_from_u64(seed);
    let sweep = sim::scan(scene, sensor, world_from_sensor, 0.0, &mut rng);
    Sdem::from_points(&sweep.points_in_sensor(), &sweep.mean_attitude(), grid).unwrap()
}

/// The paper room scanned at the origin (seed `seeds.0`) and at `truth` (seed `seeds.1`), the
/// second scan's compass reading `compass_off_deg` off (steel nearby), each S-DEM levelled by
/// its reading: reference, query.
fn pair_with_compass_off(truth: &Pose, compass_off_deg: f64, seeds: (u64, u64)) -> (Sdem, Sdem) {
    let scene = sim::paper_room();
    let grid = SdemConfig::default();
    let sensor = SensorConfig::default();
    let reference = sdem_at(&scene, &Pose::identity(), &sensor, &grid, seeds.0);
    let mut rng = ChaCha8Rng::seed_from_u64(seeds.1);
    let sweep = sim::scan(&scene, &sensor, truth, 0.0, &mut rng);
    let mut qa = sweep.mean_attitude();
    qa.yaw += compass_off_deg.to_radians();
    let query = Sdem::from_points(&sweep.points_in_sensor(), &qa, &grid).unwrap();
    (reference, query)
}

/// The localization's pose lies within 5 mm and 0.1° of the truth.
fn assert_within_5mm_and_a_tenth_degree(truth: &Pose, found: &Localization) {
    let (dt, dr) = sdem::geometry::pose_error(truth, &found.reference_from_query);
    assert!(
        dt < 0.005 && dr.to_degrees() < 0.1,
        "error {dt} m, {} deg",
        dr.to_degrees()
    );
}

fn noise_free(step_deg: f64) -> SensorConfig {
    SensorConfig {
        range_noise_m: 0.0,
        tilt_sensor_noise_deg: 0.0,
        compass_noise_deg: 0.0,
        tilt_step_deg: step_deg,
        pan_step_deg: step_deg,
        ..Default::default()
    }
}

fn virtual_cost() -> CostConfig {
    CostConfig {
        model: CostModel::VirtualSdem,
        ..Default::default()
    }
}

/// The virtual S-DEM of `reference` at the candidate `(offset, yaw)`, built here from the
/// candidate's definition and nothing of the correlator's: each boundary point `x` of the
/// reference, in double precision, is seen by the query at `Rz(−yaw) (x − offset)`, and the
/// S-DEM of those points (nearest per cell) is the virtual one.
fn virtual_sdem_by_hand(reference: &Sdem, offset: &Vec3, yaw: f64) -> Sdem {
    let (sin, cos) = yaw.sin_cos();
    let seen: Vec<Vec3> = reference
        .points()
        .iter()
        .map(|p| {
            let d = Vec3::new(p[0] as f64, p[1] as f64, p[2] as f64) - offset;
            Vec3::new(cos * d.x + sin * d.y, -sin * d.x + cos * d.y, d.z)
        })
        .collect();
    Sdem::from_points(&seen, &Attitude::default(), reference.config()).unwrap()
}

#[test]
fn correlator_equals_the_virtual_sdem_correlation() {
    // The query stands turned 25° and its compass reads 12° too much: the candidate that
    // matches is the true offset with a heading correction of −12°.
    let t = Vec3::new(0.1, 0.05, 0.02);
    let truth = pose_from_parts(t, Attitude::from_degrees(0.0, 0.0, 25.0));
    let (reference, local) = pair_with_compass_off(&truth, 12.0, (1, 2));
    let correction = (-12f64).to_radians();
    // Any overlap scores, so that candidates turned far from the truth compare too.
    let cost = CostConfig {
        min_overlap_cells: 1,
        min_overlap_fraction: 0.0,
        ..virtual_cost()
    };
    let mut correlator = Correlator::new(&reference, &local, &cost).unwrap();
    // At heading 0 the correlator moves the points without rotating them, as `virtual_at`
    // does: the same numbers to the last bit.
    for o in [Vec3::zeros(), t, Vec3::new(-0.3, 0.2, -0.05)] {
        let fast = correlator.evaluate(&o, 0.0);
        let slow = correlate(&reference.virtual_at(&o), &local, &cost);
        assert_eq!(fast, slow, "at {o:?}");
    }
    // At other headings it rotates them in single precision, the hand-built virtual S-DEM in
    // double: a point within rounding of a cell's edge may fall in the neighbouring cell, and
    // each such cell changes the mean by at most τ² over the query's cells. A few cells may.
    let allowed_cells = 5;
    let per_cell = cost.truncation_m.powi(2) / local.known_cells() as f64;
    for (o, yaw_deg) in [
        (t, -12.0),
        (t, -10.0),
        (t + Vec3::new(0.05, 0.0, 0.0), -12.0),
        (Vec3::new(-0.3, 0.2, -0.05), 7.0),
        (t, 90.0),
        (Vec3::zeros(), -170.0),
    ] {
        let yaw = f64::to_radians(yaw_deg);
        let fast = correlator.evaluate(&o, yaw);
        let slow = correlate(&virtual_sdem_by_hand(&reference, &o, yaw), &local, &cost);
        let at = format!("at {o:?}, {yaw_deg}°: correlator {fast:?}, by hand {slow:?}");
        let (Some(fast), Some(slow)) = (fast, slow) else {
            panic!("not scored {at}");
        };
        assert!(fast.overlap.abs_diff(slow.overlap) <= allowed_cells, "{at}");
        assert!(fast.inliers.abs_diff(slow.inliers) <= allowed_cells, "{at}");
        assert!(
            (fast.cost - slow.cost).abs() <= allowed_cells as f64 * per_cell,
            "{at}"
        );
    }
    // For both costs the true candidate scores better than one 5 cm or 2° away.
    for cost in [virtual_cost(), CostConfig::default()] {
        let mut c = Correlator::new(&reference, &local, &cost).unwrap();
        let truth = c.evaluate(&t, correction).unwrap();
        let shifted = c
            .evaluate(&(t + Vec3::new(0.05, 0.0, 0.0)), correction)
            .unwrap();
        let turned = c.evaluate(&t, correction + 2f64.to_radians()).unwrap();
        assert!(
            truth.cost < shifted.cost && truth.cost < turned.cost,
            "{cost:?}: truth {truth:?}, 5 cm off {shifted:?}, 2° off {turned:?}"
        );
    }
}

#[test]
fn exhaustive_finds_on_grid_truth_without_noise() {
    let scene = sim::paper_room();
    let grid = SdemConfig::default();
    let sensor = noise_free(1.0);
    let truth = Vec3::new(0.06, -0.04, 0.02);
    let reference = sdem_at(&scene, &Pose::identity(), &sensor, &grid, 3);
    let query = sdem_at(
        &scene,
        &pose_from_parts(truth, Attitude::default()),
        &sensor,
        &grid,
        4,
    );
    for cost in [virtual_cost(), CostConfig::default()] {
        let config = LocalizeOptions {
            window: SearchWindow {
                min: [-0.1, -0.1, -0.1],
                max: [0.1, 0.1, 0.1],
            },
            step_m: 0.02,
            heading: HeadingWindow::none(),
            mode: SearchMode::Exhaustive,
            cost,
            refine: false,
            ..Default::default()
        };
        let found = localize(&reference, &query, &config).unwrap();
        assert_eq!(found.candidates_evaluated, 11 * 11 * 11);
        assert!(
            (found.grid_offset - truth).norm() < 1e-9,
            "{:?}: found {:?}, truth {truth:?}",
            config.cost.model,
            found.grid_offset
        );
        assert!(!found.on_window_edge);
    }
}

/// The exhaustive search counts its candidates before scoring one: beyond
/// `max_exhaustive_candidates` it is refused with the count, the grid and the limit (the
/// oracle over ±2 m at 1 cm with ±10° of heading would run for most of an hour).
#[test]
fn exhaustive_search_beyond_its_candidate_limit_is_refused_up_front() {
    let (reference, query) = pair_with_compass_off(
        &pose_from_parts(Vec3::new(0.2, 0.1, 0.0), Attitude::default()),
        0.0,
        (1, 2),
    );
    let config = LocalizeOptions {
        window: SearchWindow::around(&Vec3::zeros(), [2.0, 2.0, 0.1]),
        heading: HeadingWindow {
            half_range_deg: 10.0,
            step_deg: Some(1.0),
        },
        mode: SearchMode::Exhaustive,
        ..Default::default()
    };
    let start = std::time::Instant::now();
    let err = localize(&reference, &query, &config).unwrap_err();
    assert!(start.elapsed().as_secs_f64() < 5.0, "{:?}", start.elapsed());
    let (x, y, z, headings) = (401, 401, 21, 21);
    let total = x * y * z * headings;
    match &err {
        Error::TooManyCandidates {
            candidates,
            grid,
            limit,
        } => {
            assert_eq!(*candidates, total);
            assert_eq!(*grid, [x, y, z, headings]);
            assert_eq!(*limit, MAX_EXHAUSTIVE_CANDIDATES);
        }
        other => panic!("{other}"),
    }
    let message = err.to_string();
    for wanted in [
        &total.to_string(),
        &MAX_EXHAUSTIVE_CANDIDATES.to_string(),
        "window",
        "step",
    ] {
        assert!(message.contains(wanted), "{message} lacks {wanted}");
    }
    assert!(!err.is_no_match());
    // The same grid under a raised limit, and the exact search, pass the check (a small window
    // here, to keep the test quick).
    let small = LocalizeOptions {
        window: SearchWindow::around(&Vec3::new(0.2, 0.1, 0.0), [0.02, 0.02, 0.0]),
        max_exhaustive_candidates: 5 * 5 * 21,
        refine: false,
        runner_up: false,
        ..config.clone()
    };
    assert!(localize(&reference, &query, &small).is_ok());
    let tight = LocalizeOptions {
        max_exhaustive_candidates: 5 * 5 * 21 - 1,
        ..small.clone()
    };
    assert!(matches!(
        localize(&reference, &query, &tight),
        Err(Error::TooManyCandidates { .. })
    ));
    let exact = LocalizeOptions {
        mode: SearchMode::BranchAndBound,
        ..tight
    };
    assert!(localize(&reference, &query, &exact).is_ok());
}

#[test]
fn tilted_query_is_localized() {
    // The paper's second case: the body stands on a rock, tilted 8°; default search (exact
    // branch-and-bound with ±10° heading, then the 6-DoF refinement).
    let scene = sim::paper_room();
    let grid = SdemConfig::default();
    let sensor = SensorConfig::default();
    let truth = pose_from_parts(
        Vec3::new(0.22, 0.36, 0.05),
        Attitude::from_degrees(3.0, 8.0, 0.0),
    );
    let reference = sdem_at(&scene, &Pose::identity(), &sensor, &grid, 5);
    let query = sdem_at(&scene, &truth, &sensor, &grid, 6);
    // A window of ±8 cm around the truth keeps the test quick; the benchmarks run the paper's.
    let config = LocalizeOptions {
        window: SearchWindow::around(&truth.translation.vector, [0.08, 0.08, 0.05]),
        heading: HeadingWindow {
            half_range_deg: 3.0,
            step_deg: None,
        },
        ..Default::default()
    };
    let found = localize(&reference, &query, &config).unwrap();
    assert_within_5mm_and_a_tenth_degree(&truth, &found);
    assert_eq!(found.refined, RefineOutcome::SixDof);
}

#[test]
fn compass_error_is_found_by_the_heading_search() {
    let truth = pose_from_parts(
        Vec3::new(0.3, -0.1, 0.0),
        Attitude::from_degrees(0.0, 0.0, 25.0),
    );
    // The compass reads 8° off (steel nearby).
    let (reference, query) = pair_with_compass_off(&truth, 8.0, (9, 10));
    // The default ±10° heading window; a translation window of ±5 cm around the truth keeps
    // the test quick (the benchmarks run the paper's window).
    let config = LocalizeOptions {
        window: SearchWindow::around(&truth.translation.vector, [0.05, 0.05, 0.03]),
        ..Default::default()
    };
    let found = localize(&reference, &query, &config).unwrap();
    assert_within_5mm_and_a_tenth_degree(&truth, &found);
    assert!((found.heading_correction.to_degrees() + 8.0).abs() < 0.2);
    // Trusting the compass, the same pair localizes badly or not at all.
    let trusting = LocalizeOptions {
        heading: HeadingWindow::none(),
        refine: false,
        ..config
    };
    if let Ok(f) = localize(&reference, &query, &trusting) {
        let (dt, _) = sdem::geometry::pose_error(&truth, &f.reference_from_query);
        assert!(dt > 0.01, "a wrong compass should hurt: {dt}");
    }
}

/// With the compass no use at all (150° off), a full turn of heading finds the pose, which the
/// default ±10° cannot.
#[test]
fn a_full_turn_of_heading_finds_a_compass_half_a_turn_off() {
    let truth = pose_from_parts(
        Vec3::new(0.2, 0.1, 0.0),
        Attitude::from_degrees(0.0, 0.0, -40.0),
    );
    let (reference, query) = pair_with_compass_off(&truth, 150.0, (11, 12));
    let config = LocalizeOptions {
        window: SearchWindow::around(&truth.translation.vector, [0.05, 0.05, 0.03]),
        heading: HeadingWindow {
            half_range_deg: 180.0,
            step_deg: None,
        },
        ..Default::default()
    };
    let found = localize(&reference, &query, &config).unwrap();
    assert_within_5mm_and_a_tenth_degree(&truth, &found);
    assert!(
        (found.heading_correction.to_degrees() + 150.0).abs() < 0.2,
        "heading correction {}°",
        found.heading_correction.to_degrees()
    );
    assert!(!found.diagnostics.ambiguous, "{:?}", found.diagnostics);
    // The ±10° default cannot reach it: the best it finds is far off, or nothing matches.
    let narrow = LocalizeOptions {
        heading: HeadingWindow::default(),
        refine: false,
        ..config
    };
    if let Ok(f) = localize(&reference, &query, &narrow) {
        let (dt, dr) = sdem::geometry::pose_error(&truth, &f.reference_from_query);
        assert!(
            dt > 0.02 || dr.to_degrees() > 10.0,
            "±10° should not reach a compass 150° off: {dt} m, {}°",
            dr.to_degrees()
        );
    }
}

#[test]
fn a_corridor_is_ambiguous_along_its_axis_and_a_room_is_not() {
    let grid = SdemConfig::default();
    let sensor = SensorConfig::default();
    let truth = Vec3::new(0.2, 0.05, 0.0);
    let config = LocalizeOptions {
        window: SearchWindow::around(&truth, [0.15, 0.06, 0.03]),
        heading: HeadingWindow::none(),
        ..Default::default()
    };
    let localize_in = |scene: &sim::Scene, seed: u64| {
        let r = sdem_at(scene, &Pose::identity(), &sensor, &grid, seed);
        let moved = pose_from_parts(truth, Attitude::default());
        let q = sdem_at(scene, &moved, &sensor, &grid, seed + 1);
        localize(&r, &q, &config).unwrap()
    };
    let found = localize_in(&sim::corridor(30.0).unwrap(), 21);
    let d = &found.diagnostics;
    println!("corridor: cost {:.3e}, {d:?}", found.cost);
    assert!(d.ambiguous, "{d:?}");
    let axis = d.weakest_direction.unwrap();
    assert!(
        axis[0].abs() > 0.95,
        "weakest direction {axis:?} is not the corridor's axis"
    );
    // Across the corridor the pose is still well fixed.
    assert!(d.strongest_sigma_m.unwrap() < 0.001, "{d:?}");
    // The grid's flat cost and the refinement's weakest direction agree: the pose is free
    // along the axis.
    let flat = d
        .flat_direction
        .expect("a corridor's pose is free along its axis");
    assert!(flat[0].abs() > 0.95, "flat direction {flat:?}");

    let found = localize_in(&sim::paper_room(), 23);
    let d = &found.diagnostics;
    println!("room: cost {:.3e}, {d:?}", found.cost);
    assert!(!d.ambiguous, "{d:?}");
    assert_eq!(d.flat_direction, None);
    assert!(d.runner_up_cost_at_least.unwrap() > found.cost, "{d:?}");
    assert!(d.overlap_fraction > 0.5 && d.inlier_fraction > 0.5, "{d:?}");
    let cov = d.covariance.unwrap();
    for (i, row) in cov.iter().enumerate() {
        assert!(row[i] > 0.0, "covariance diagonal {i}: {}", row[i]);
    }
}

/// The paper's room scanned at the origin and at `truth` (seeds 31 and 32), levelled by their
/// readings: reference, query.
fn paper_room_pair(truth: &Vec3) -> (Sdem, Sdem) {
    let (grid, sensor, scene) = (
        SdemConfig::default(),
        SensorConfig::default(),
        sim::paper_room(),
    );
    let reference = sdem_at(&scene, &Pose::identity(), &sensor, &grid, 31);
    let at_truth = pose_from_parts(*truth, Attitude::default());
    (reference, sdem_at(&scene, &at_truth, &sensor, &grid, 32))
}

#[test]
fn a_thin_match_and_an_unconfirmed_grid_pose_are_flagged() {
    let truth = Vec3::new(0.2, 0.05, 0.0);
    let (r, q) = paper_room_pair(&truth);
    let base = LocalizeOptions {
        window: SearchWindow::around(&truth, [0.05, 0.05, 0.03]),
        heading: HeadingWindow::none(),
        runner_up: false,
        ..Default::default()
    };
    let reasons = |config: &LocalizeOptions| {
        let found = localize(&r, &q, config).unwrap();
        let shape: Vec<Doubt> = (found.doubts.iter())
            .filter(|d| d.is_ambiguity())
            .cloned()
            .collect();
        assert_eq!(found.diagnostics.ambiguous, !shape.is_empty());
        assert_eq!(found.trusted, found.doubts.is_empty());
        shape
    };
    let has = |reasons: &[Doubt], kind: &str| reasons.iter().any(|d| d.kind() == kind);
    let clean = reasons(&base);
    assert!(
        !has(&clean, "few_inliers") && !has(&clean, "refinement_failed"),
        "{clean:?}"
    );
    // The same match is thin when almost every point must match.
    let strict = LocalizeOptions {
        min_trusted_inlier_fraction: 0.99,
        ..base.clone()
    };
    assert!(has(&reasons(&strict), "few_inliers"));
    // A refinement allowed to move 10 µm fails on 5 mm noise: the grid pose is flagged. (Only
    // the translation refined: a turn would allow what it moves the points by as well.)
    let mut stuck = base.clone();
    stuck.refinement.max_translation_m = 1e-5;
    stuck.refinement.estimate_rotation = false;
    let stuck = reasons(&stuck);
    assert!(has(&stuck, "refinement_failed"), "{stuck:?}");
}

/// A prediction that claims a millimetre and lies 20 cm from the truth holds the pose where it
/// says, and the result says that the scans alone fit a place elsewhere far better; a right
/// prediction, or a wrong one too loose to hold the pose, leaves the scans' pose trusted.
#[test]
fn a_prediction_that_overrules_the_scans_is_a_doubt() {
    let truth = Vec3::new(0.2, 0.05, 0.0);
    let (r, q) = paper_room_pair(&truth);
    let with_prior = |offset: Vec3, sigma_m: f64| {
        let config = LocalizeOptions {
            window: SearchWindow::around(&Vec3::zeros(), [0.4, 0.4, 0.05]),
            heading: HeadingWindow::none(),
            cost: CostConfig {
                prior: Some(OffsetPrior {
                    offset: offset.into(),
                    sigma_m,
                }),
                ..Default::default()
            },
            ..Default::default()
        };
        localize(&r, &q, &config).unwrap()
    };
    let conflict = |found: &Localization| found.doubts.iter().any(|d| d.kind() == "prior_conflict");
    let pinned = with_prior(Vec3::new(0.0, 0.05, 0.0), 0.001);
    let (error, _) = sdem::geometry::pose_error(
        &pose_from_parts(truth, Attitude::default()),
        &pinned.reference_from_query,
    );
    assert!(
        error > 0.1,
        "the prediction did not hold the pose: {error} m"
    );
    assert!(!pinned.trusted);
    let Some(&Doubt::PriorConflict {
        distance_m,
        cost,
        best_cost,
    }) = (pinned.doubts.iter()).find(|d| matches!(d, Doubt::PriorConflict { .. }))
    else {
        panic!("no prior_conflict: {:?}", pinned.doubts);
    };
    assert!(
        (0.1..0.3).contains(&distance_m) && cost * 2.0 <= best_cost,
        "{distance_m} {cost} {best_cost}"
    );
    for (offset, sigma_m) in [(truth, 0.001), (Vec3::new(0.0, 0.05, 0.0), 0.3)] {
        let found = with_prior(offset, sigma_m);
        assert!(
            !conflict(&found),
            "{offset:?} ± {sigma_m}: {:?}",
            found.doubts
        );
        assert_within_5mm_and_a_tenth_degree(&pose_from_parts(truth, Attitude::default()), &found);
    }
}

#[test]
fn bad_windows_and_steps_are_errors() {
    let scene = sim::paper_room();
    let grid = SdemConfig::default();
    let s = sdem_at(
        &scene,
        &Pose::identity(),
        &SensorConfig::default(),
        &grid,
        7,
    );
    let inverted = LocalizeOptions {
        window: SearchWindow {
            min: [0.1, 0.0, 0.0],
            max: [-0.1, 0.0, 0.0],
        },
        ..Default::default()
    };
    let message = localize(&s, &s, &inverted).unwrap_err().to_string();
    assert!(message.contains("inverted"), "{message}");
    for step in [0.0, -0.01, f64::NAN] {
        let config = LocalizeOptions {
            step_m: step,
            ..Default::default()
        };
        assert!(localize(&s, &s, &config).is_err());
    }
    let nan = LocalizeOptions {
        window: SearchWindow {
            min: [f64::NAN, 0.0, 0.0],
            max: [0.1, 0.0, 0.0],
        },
        ..Default::default()
    };
    assert!(localize(&s, &s, &nan).is_err());
    let bad_heading = LocalizeOptions {
        heading: HeadingWindow {
            half_range_deg: 200.0,
            step_deg: None,
        },
        ..Default::default()
    };
    assert!(localize(&s, &s, &bad_heading).is_err());
    let bnb_on_virtual = LocalizeOptions {
        cost: virtual_cost(),
        ..Default::default()
    };
    assert!(localize(&s, &s, &bnb_on_virtual).is_err());
    // A prediction 5 m outside the paper's window, σ 10 cm: the two contradict each other.
    let prior_outside = |x: f64| LocalizeOptions {
        cost: CostConfig {
            prior: Some(OffsetPrior {
                offset: [x, 0.0, 0.0],
                sigma_m: 0.1,
            }),
            ..Default::default()
        },
        ..Default::default()
    };
    match localize(&s, &s, &prior_outside(5.0)) {
        Err(Error::Invalid(why)) => assert!(why.contains("outside the search window"), "{why}"),
        other => panic!("a prediction outside the window came out as {other:?}"),
    }
    // Inside the window, or within five σ of it, it is a prediction like any other.
    assert!(localize(&s, &s, &prior_outside(0.9)).is_ok());
}

#[test]
fn no_overlap_is_an_error_not_a_pose() {
    let scene = sim::paper_room();
    let grid = SdemConfig::default();
    let s = sdem_at(
        &scene,
        &Pose::identity(),
        &SensorConfig::default(),
        &grid,
        8,
    );
    // Candidates 50 m away see nothing of the reference.
    for mode in [SearchMode::BranchAndBound, SearchMode::Exhaustive] {
        let far = LocalizeOptions {
            window: SearchWindow {
                min: [50.0, 50.0, 0.0],
                max: [50.1, 50.1, 0.0],
            },
            mode,
            ..Default::default()
        };
        let error = localize(&s, &s, &far).unwrap_err();
        assert!(
            matches!(error, Error::NoOverlap { .. } | Error::NoMatch { .. }),
            "{error}"
        );
    }
}

/// A small seeded problem: coarse 2° scans, a query displaced and turned.
/// A coarse (2°) pair in the paper's room: the reference at the origin, the query at
/// `(x, y, z)` turned by `yaw` degrees, its compass reading `compass_error_deg` off.
fn small_problem(
    seed: u64,
    x: f64,
    y: f64,
    z: f64,
    yaw: f64,
    compass_error_deg: f64,
) -> (Sdem, Sdem) {
    let scene = sim::paper_room();
    let grid = SdemConfig {
        resolution_deg: 2.0,
        ..Default::default()
    };
    let sensor = SensorConfig {
        tilt_step_deg: 2.0,
        pan_step_deg: 2.0,
        ..Default::default()
    };
    let truth = pose_from_parts(Vec3::new(x, y, z), Attitude::from_degrees(0.0, 0.0, yaw));
    let reference = sdem_at(&scene, &Pose::identity(), &sensor, &grid, seed);
    let mut rng = ChaCha8Rng::seed_from_u64(seed + 1);
    let sweep = sim::scan(&scene, &sensor, &truth, 0.0, &mut rng);
    let mut reading = sweep.mean_attitude();
    reading.yaw += compass_error_deg.to_radians();
    let query = Sdem::from_points(&sweep.points_in_sensor(), &reading, &grid).unwrap();
    (reference, query)
}

/// The runner-up with the optimum's slopes passed over is the same from branch-and-bound's
/// reserve as from the exhaustive oracle searching the grid again: on coarse pairs with a peak
/// radius of 4 cm (so that runner-ups and slopes lie inside a ±10 cm window), its cost, what
/// the search says every other candidate costs at least, the slopes passed over and the
/// doubts.
#[test]
fn the_runner_up_past_the_slopes_is_the_oracles() {
    let (mut flagged, mut clear, mut slopes) = (0, 0, 0);
    for seed in 0..10u64 {
        let k = seed as f64;
        let (x, y, yaw) = (
            0.1 * (k * 0.7).sin(),
            0.1 * (k * 1.3).cos(),
            8.0 * (k * 0.9).sin(),
        );
        let (reference, query) = small_problem(seed, x, y, 0.0, yaw, 0.5);
        let base = LocalizeOptions {
            window: SearchWindow::around(&Vec3::new(x, y, 0.0), [0.1, 0.1, 0.04]),
            step_m: 0.02,
            heading: HeadingWindow {
                half_range_deg: 3.0,
                step_deg: Some(1.0),
            },
            refine: false,
            peak_radius_m: 0.04,
            ambiguous_cost_ratio: 1.5,
            ..Default::default()
        };
        let oracle = localize(
            &reference,
            &query,
            &LocalizeOptions {
                mode: SearchMode::Exhaustive,
                ..base.clone()
            },
        )
        .unwrap();
        let fast = localize(&reference, &query, &base).unwrap();
        assert_eq!(fast.grid_index, oracle.grid_index, "seed {seed}");
        assert_eq!(fast.runner_up, oracle.runner_up, "seed {seed}");
        assert_eq!(
            fast.diagnostics.runner_up_cost_at_least, oracle.diagnostics.runner_up_cost_at_least,
            "seed {seed}"
        );
        assert_eq!(fast.doubts, oracle.doubts, "seed {seed}");
        let passed = fast.diagnostics.runner_up_slopes_passed;
        assert_eq!(
            passed, oracle.diagnostics.runner_up_slopes_passed,
            "seed {seed}"
        );
        slopes += passed;
        match fast.runner_up {
            Some(_) => flagged += 1,
            None => clear += 1,
        }
    }
    // Not vacuous: slopes are passed over, some pairs keep a runner-up, and some have none.
    assert!(slopes > 0, "no slope passed over");
    assert!(flagged > 0 && clear > 0, "{flagged} flagged, {clear} clear");
}

/// With a peak radius under a grid step the runner-up can be the optimum's neighbour: no line
/// lies between them to show a slope, so none is passed over and the neighbour, when it costs
/// within the ratio, is the runner-up.
#[test]
fn a_runner_up_next_to_the_optimum_shows_no_slope() {
    let mut flagged = 0;
    for seed in 0..4u64 {
        let (reference, query) = small_problem(seed, 0.05, -0.03, 0.0, 2.0, 0.5);
        let options = LocalizeOptions {
            window: SearchWindow::around(&Vec3::new(0.05, -0.03, 0.0), [0.06, 0.06, 0.02]),
            step_m: 0.02,
            heading: HeadingWindow {
                half_range_deg: 2.0,
                step_deg: Some(1.0),
            },
            refine: false,
            peak_radius_m: 0.015,
            ambiguous_cost_ratio: 2.0,
            ..Default::default()
        };
        let found = localize(&reference, &query, &options).unwrap();
        assert_eq!(found.diagnostics.runner_up_slopes_passed, 0, "seed {seed}");
        flagged += found.runner_up.is_some() as usize;
    }
    assert!(
        flagged > 0,
        "no runner-up next to the optimum: the test would be vacuous"
    );
}

proptest! {
    #![proptest_config(ProptestConfig { cases: 32, ..ProptestConfig::default() })]

    /// The exact search lands on the exhaustive oracle's minimum, heading included, wherever
    /// the truth lies relative to the window (inside, near an edge, or outside it), with or
    /// without a prediction (weak or strong enough to decide, inside the window or out), and
    /// on its runner-up.
    #[test]
    fn branch_and_bound_finds_the_exhaustive_minimum(
        seed in 0u64..1_000_000,
        x in -0.3f64..0.3, y in -0.2f64..0.4, z in -0.05f64..0.05,
        yaw in -30.0f64..30.0,
        compass_error in -3.0f64..3.0,
        window_shift in -0.1f64..0.1,
        prior in proptest::option::of((-0.15f64..0.15, -0.15f64..0.15, -7.0f64..-1.6)),
    ) {
        let (reference, query) = small_problem(seed, x, y, z, yaw, compass_error);
        let centre = Vec3::new(x + window_shift, y - window_shift, z);
        let base = LocalizeOptions {
            window: SearchWindow::around(&centre, [0.08, 0.08, 0.04]),
            step_m: 0.02,
            heading: HeadingWindow { half_range_deg: 3.0, step_deg: Some(1.0) },
            refine: false,
            cost: CostConfig {
                // σ from 1 mm (the prediction decides) to 20 cm (the scans do).
                prior: prior.map(|(dx, dy, log_sigma)| OffsetPrior {
                    offset: [centre.x + dx, centre.y + dy, centre.z],
                    sigma_m: log_sigma.exp(),
                }),
                ..Default::default()
            },
            ..Default::default()
        };
        let oracle = localize(&reference, &query,
            &LocalizeOptions { mode: SearchMode::Exhaustive, ..base.clone() });
        let fast = localize(&reference, &query, &base);
        match (oracle, fast) {
            (Ok(oracle), Ok(fast)) => {
                prop_assert_eq!(fast.grid_index, oracle.grid_index);
                prop_assert_eq!(fast.cost, oracle.cost);
                prop_assert!(fast.candidates_evaluated < oracle.candidates_evaluated);
                // The runner-up, the optimum's slopes passed over, found from the reserve is
                // the one the oracle finds searching the grid again.
                prop_assert_eq!(fast.runner_up, oracle.runner_up);
                prop_assert_eq!(
                    fast.diagnostics.runner_up_cost_at_least,
                    oracle.diagnostics.runner_up_cost_at_least
                );
            }
            (Err(_), Err(_)) => {}
            (o, f) => prop_assert!(false, "oracle {:?} vs fast {:?}", o.map(|l| l.cost), f.map(|l| l.cost)),
        }
    }

    /// The coarse-to-fine heuristic lands on the oracle's minimum of the paper's cost on these
    /// small problems (it can miss in general: it is not exact).
    #[test]
    fn coarse_to_fine_finds_the_exhaustive_minimum(
        seed in 0u64..1_000_000,
        x in -0.3f64..0.3, y in -0.2f64..0.4, z in -0.05f64..0.05,
        yaw in -30.0f64..30.0,
    ) {
        let (reference, query) = small_problem(seed, x, y, z, yaw, 0.0);
        let window = SearchWindow::around(&Vec3::new(x, y, z), [0.12, 0.12, 0.06]);
        let base = LocalizeOptions {
            window,
            step_m: 0.02,
            heading: HeadingWindow::none(),
            mode: SearchMode::CoarseToFine,
            cost: virtual_cost(),
            refine: false,
            ..Default::default()
        };
        let oracle = localize(&reference, &query,
            &LocalizeOptions { mode: SearchMode::Exhaustive, ..base.clone() }).unwrap();
        let fast = localize(&reference, &query, &base).unwrap();
        prop_assert_eq!(fast.grid_index, oracle.grid_index);
        prop_assert_eq!(fast.cost, oracle.cost);
        prop_assert!(fast.candidates_evaluated < oracle.candidates_evaluated);
    }
}

/// A doubt's threshold that is not a number, or out of its range, is refused by name: a NaN
/// ambiguity ratio silenced the runner-up doubt.
#[test]
fn thresholds_of_the_doubts_are_checked() {
    use sdem::localize::{LocalizeOptions, SearchMode};
    type Spoil = fn(&mut LocalizeOptions);
    let bad: [(&str, Spoil); 6] = [
        ("ambiguous_cost_ratio", |o| {
            o.ambiguous_cost_ratio = f64::NAN
        }),
        ("ambiguous_sigma_ratio", |o| o.ambiguous_sigma_ratio = 0.5),
        ("ambiguous_rise_ratio", |o| o.ambiguous_rise_ratio = -0.1),
        ("min_trusted_inlier_fraction", |o| {
            o.min_trusted_inlier_fraction = 2.0
        }),
        ("min_trusted_support", |o| o.min_trusted_support = f64::NAN),
        ("keep", |o| {
            o.mode = SearchMode::CoarseToFine;
            o.cost.model = sdem::cost::CostModel::VirtualSdem;
            o.keep = 0;
        }),
    ];
    for (name, spoil) in bad {
        let mut options = LocalizeOptions::default();
        spoil(&mut options);
        let e = options.validate().unwrap_err().to_string();
        assert!(e.contains(name), "{name}: {e}");
    }
    LocalizeOptions::default().validate().unwrap();
}
