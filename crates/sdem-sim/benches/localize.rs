//! Speed of one candidate's evaluation (projective and virtual-S-DEM cost) and of whole
//! searches, on the paper's experiment (Sec. V): a scan at the origin of the simulated room, a
//! second after moving (22, 36, 5) cm.
//! Fixed seeds, so every run measures the same problem.

use criterion::{criterion_group, criterion_main, Criterion};
use sdem::cost::{Correlator, CostModel};
use sdem::geometry::Vec3;
use sdem::localize::{
    localize, CostConfig, HeadingWindow, LocalizeOptions, SearchMode, SearchWindow,
};
use sdem_sim::benchmark::{paper_pair, PAPER_MOVE_M};
use std::hint::black_box;

fn benches(c: &mut Criterion) {
    let (reference, query) = paper_pair().expect("the paper's pair");
    let origin = Vec3::from(PAPER_MOVE_M);
    // One candidate scored in each form of eq. (1): the projective one every search uses by
    // default, and the paper's virtual S-DEM (what its brute force pays per candidate).
    for (name, model) in [
        ("projective_evaluation", CostModel::Projective),
        ("virtual_sdem_evaluation", CostModel::VirtualSdem),
    ] {
        let cost = CostConfig {
            model,
            ..Default::default()
        };
        let mut correlator = Correlator::new(&reference, &query, &cost).expect("same grid");
        c.bench_function(name, |b| {
            b.iter(|| black_box(correlator.evaluate(black_box(&origin), 0.0)))
        });
    }
    let mut group = c.benchmark_group("search");
    group.sample_size(10);
    group.bench_function("branch_and_bound_paper_window_1cm", |b| {
        let config = LocalizeOptions {
            heading: HeadingWindow::none(),
            refine: false,
            runner_up: false,
            ..Default::default()
        };
        b.iter(|| black_box(localize(&reference, &query, &config).expect("localizes")))
    });
    // ±10° of heading over the paper's whole window takes tens of seconds (see `sdem bench`);
    // here a ±10 cm window around the truth.
    group.bench_function("branch_and_bound_10cm_window_1cm_heading_10deg", |b| {
        let config = LocalizeOptions {
            window: SearchWindow::around(&origin, [0.1, 0.1, 0.05]),
            refine: false,
            runner_up: false,
            ..Default::default()
        };
        b.iter(|| black_box(localize(&reference, &query, &config).expect("localizes")))
    });
    group.bench_function("coarse_to_fine_paper_window_1cm", |b| {
        let config = LocalizeOptions {
            heading: HeadingWindow::none(),
            mode: SearchMode::CoarseToFine,
            refine: false,
            runner_up: false,
            ..Default::default()
        };
        b.iter(|| black_box(localize(&reference, &query, &config).expect("localizes")))
    });
    // The exhaustive search over the paper's whole window takes minutes; measure it on a
    // 21 x 21 x 21 cube (9,261 candidates) and scale by candidates in the README.
    group.bench_function("exhaustive_21cube_1cm", |b| {
        let config = LocalizeOptions {
            window: SearchWindow::around(&origin, [0.1, 0.1, 0.1]),
            heading: HeadingWindow::none(),
            mode: SearchMode::Exhaustive,
            refine: false,
            runner_up: false,
            ..Default::default()
        };
        b.iter(|| black_box(localize(&reference, &query, &config).expect("localizes")))
    });
    group.finish();
}

criterion_group!(localize_benches, benches);
criterion_main!(localize_benches);
