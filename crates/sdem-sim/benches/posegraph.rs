//! Speed of the robust pose-graph optimizer on the 1,000-node synthetic loop: dead reckoning with
//! a drifting gyro, closed by three loop-closure edges. Fixed seed ([`BENCH_SEED`]), so every run
//! measures the same problem; `sdem bench` prints the same figure through
//! [`sdem_sim::pose_graphs::bench_1000_nodes`].

use criterion::{criterion_group, criterion_main, Criterion};
use sdem::posegraph::{optimize, position_rmse, OptimizeConfig};
use sdem_sim::pose_graphs::{synthetic_loop, SyntheticLoopConfig, BENCH_NODES, BENCH_SEED};
use std::hint::black_box;

fn benches(c: &mut Criterion) {
    let (graph, truth) = synthetic_loop(BENCH_NODES, BENCH_SEED, &SyntheticLoopConfig::default());
    let config = OptimizeConfig::default();
    let (world_from_node, report) = optimize(&graph, 0, &config).expect("the loop optimizes");
    eprintln!(
        "posegraph {} nodes, {} edges: ATE {:.3} m -> {:.3} m, {} iterations over {} kernel \
         stages, converged {}",
        graph.world_from_node.len(),
        graph.edges.len(),
        position_rmse(&truth, &graph.world_from_node).unwrap(),
        position_rmse(&truth, &world_from_node).unwrap(),
        report.iterations,
        report.kernel_stages,
        report.converged
    );
    let mut group = c.benchmark_group("posegraph");
    group.sample_size(10);
    group.bench_function("optimize_1000_node_loop", |b| {
        b.iter(|| black_box(optimize(black_box(&graph), 0, &config).expect("the loop optimizes")))
    });
    group.finish();
}

criterion_group!(posegraph_benches, benches);
criterion_main!(posegraph_benches);
