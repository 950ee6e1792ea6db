//! Solving only the part of the graph a loop closure touches: the newest nodes, from a given one
//! on, with the older nodes their edges reach held where they are, so that a closure on a map of
//! thousands of nodes costs the nodes of its loop, not the map (in the spirit of iSAM's
//! incremental updates, Kaess et al., T-RO 2008: only what the new measurement changes is
//! solved again). The part grows, up to the whole graph, while the edges that tie it to the held
//! nodes disagree with the solution: then the correction reaches further back than the part.

use super::{optimize, optimize_holding, OptimizeConfig, OptimizeReport, PoseGraph};
use crate::error::{Error, Result};
use crate::geometry::Pose;
use serde::Serialize;

/// What [`optimize_local`] did.
#[derive(Debug, Clone, PartialEq, Serialize)]
pub struct LocalSolve {
    /// The oldest node the last solve moved: nodes from it on were free.
    pub first_free: usize,
    /// Nodes the last solve moved.
    pub free_nodes: usize,
    /// Nodes held at their poses at the boundary of the last solve (none when whole).
    pub held_nodes: usize,
    /// The last solve took the whole graph (holding only the gauge).
    pub whole: bool,
    /// Solves run: each after the first took a part twice as long.
    pub attempts: usize,
    /// The last solve's report (its edges are the part's, in the graph's order).
    pub report: OptimizeReport,
}

/// Optimizes nodes `first..` of `graph` (a trajectory in the order it was driven: where a loop
/// closure to an older node lands), holding every older node an edge ties them to; nodes before
/// `first` that no edge reaches do not take part. When an edge between the free part and a held
/// node ends with a Mahalanobis norm above the robust kernel's width (it disagrees with the
/// solution: the correction reaches further back), the part doubles and is solved again; a part
/// of more than `whole_fraction` of the nodes, or one that reaches the gauge, is solved whole
/// with [`optimize`] (holding `gauge`).
///
/// # Arguments
/// * `graph` — poses (the current estimates: a warm start) and edges.
/// * `first` — the oldest node to free.
/// * `gauge` — the node held when the whole graph is solved (usually 0).
/// * `config` — the optimizer's settings.
/// * `whole_fraction` — parts larger than this share of the nodes are solved whole (in 0..=1).
///
/// # Returns
/// Every node's pose (those outside the part unchanged, bit for bit) and what was solved.
///
/// # Errors
/// As [`optimize`]; an invalid `gauge` or `whole_fraction`.
///
/// # Example
/// ```
/// use nalgebra::{Isometry3, Vector3};
/// use sdem::posegraph::{diagonal_information, optimize_local, Edge, EdgeKind, OptimizeConfig, PoseGraph};
/// // Forty 1 m steps along x whose odometry says 1.01 m, and a closure that measures the last
/// // step from node 30 as it is.
/// let step = |m: f64| Isometry3::translation(m, 0.0, 0.0);
/// let mut graph = PoseGraph::default();
/// for k in 0..40 {
///     graph.world_from_node.push(step(1.01 * k as f64));
///     if k > 0 {
///         graph.edges.push(Edge { from: k - 1, to: k, from_from_to: step(1.01),
///             information: diagonal_information(0.05, 0.01), kind: EdgeKind::Odometry });
///     }
/// }
/// graph.edges.push(Edge { from: 30, to: 39, from_from_to: step(9.0),
///     information: diagonal_information(0.005, 0.001), kind: EdgeKind::LoopClosure });
/// let (poses, solve) = optimize_local(&graph, 25, 0, &OptimizeConfig::default(), 0.5)?;
/// assert!(!solve.whole && solve.first_free <= 25);
/// assert_eq!(poses[10], graph.world_from_node[10]);
/// let last = poses[39].translation.x - poses[30].translation.x;
/// assert!((last - 9.0).abs() < 0.01, "{last}");
/// # Ok::<(), sdem::Error>(())
/// ```
pub fn optimize_local(
    graph: &PoseGraph,
    first: usize,
    gauge: usize,
    config: &OptimizeConfig,
    whole_fraction: f64,
) -> Result<(Vec<Pose>, LocalSolve)> {
    let n = graph.world_from_node.len();
    if gauge >= n {
        return Err(Error::Invalid(format!(
            "pose graph: the gauge node {gauge} does not exist, the graph has {n} nodes"
        )));
    }
    if !(0.0..=1.0).contains(&whole_fraction) {
        return Err(Error::Invalid(format!(
            "pose graph: whole_fraction {whole_fraction} must lie in 0..=1"
        )));
    }
    let mut first = first.min(n - 1);
    let mut attempts = 0;
    loop {
        attempts += 1;
        let free = n - first;
        if first <= gauge || free as f64 > whole_fraction * n as f64 {
            let (poses, report) = optimize(graph, gauge, config)?;
            return Ok((
                poses,
                LocalSolve {
                    first_free: 0,
                    free_nodes: n - 1,
                    held_nodes: 0,
                    whole: true,
                    attempts,
                    report,
                },
            ));
        }
        match solve_part(graph, first, config)? {
            Some((poses, solve)) => return Ok((poses, LocalSolve { attempts, ..solve })),
            None => first = first.saturating_sub(free),
        }
    }
}

/// Solves nodes `first..` holding the older nodes their edges reach; `None` when no edge reaches
/// an older node or a boundary edge disagrees with the solution (the part must grow).
fn solve_part(
    graph: &PoseGraph,
    first: usize,
    config: &OptimizeConfig,
) -> Result<Option<(Vec<Pose>, LocalSolve)>> {
    let n = graph.world_from_node.len();
    let touching: Vec<usize> = (0..graph.edges.len())
        .filter(|&k| graph.edges[k].from >= first || graph.edges[k].to >= first)
        .collect();
    let mut held: Vec<usize> = touching
        .iter()
        .flat_map(|&k| [graph.edges[k].from, graph.edges[k].to])
        .filter(|&node| node < first)
        .collect();
    held.sort_unstable();
    held.dedup();
    if held.is_empty() {
        return Ok(None);
    }
    // The part's graph: the held nodes first, then the free ones.
    let mut index = vec![usize::MAX; n];
    let order: Vec<usize> = held.iter().copied().chain(first..n).collect();
    for (i, &node) in order.iter().enumerate() {
        index[node] = i;
    }
    let part = PoseGraph {
        world_from_node: order
            .iter()
            .map(|&node| graph.world_from_node[node])
            .collect(),
        edges: touching
            .iter()
            .map(|&k| {
                let e = &graph.edges[k];
                super::Edge {
                    from: index[e.from],
                    to: index[e.to],
                    ..e.clone()
                }
            })
            .collect(),
    };
    let holding: Vec<usize> = (0..held.len()).collect();
    let (part_poses, report) = optimize_holding(&part, &holding, config)?;
    let boundary_disagrees = part.edges.iter().enumerate().any(|(k, e)| {
        (e.from < held.len() || e.to < held.len())
            && report.edge_mahalanobis[k] > config.robust_kernel_width
    });
    if boundary_disagrees {
        return Ok(None);
    }
    let mut poses = graph.world_from_node.clone();
    for (i, &node) in order.iter().enumerate().skip(held.len()) {
        poses[node] = part_poses[i];
    }
    Ok(Some((
        poses,
        LocalSolve {
            first_free: first,
            free_nodes: n - first,
            held_nodes: held.len(),
            whole: false,
            attempts: 1,
            report,
        },
    )))
}

#[cfg(test)]
mod tests {
    use super::*;
    use crate::posegraph::{diagonal_information, Edge, EdgeKind};
    use nalgebra::Isometry3;

    /// `n` nodes 1 m apart along x whose odometry says `odometry_m` a step, and a closure from
    /// node `from` to the last one measuring the truth.
    fn chain(n: usize, odometry_m: f64, from: usize) -> PoseGraph {
        let step = |m: f64| Isometry3::translation(m, 0.0, 0.0);
        let mut graph = PoseGraph::default();
        for k in 0..n {
            graph.world_from_node.push(step(odometry_m * k as f64));
            if k > 0 {
                graph.edges.push(Edge {
                    from: k - 1,
                    to: k,
                    from_from_to: step(odometry_m),
                    information: diagonal_information(0.05, 0.01),
                    kind: EdgeKind::Odometry,
                });
            }
        }
        graph.edges.push(Edge {
            from,
            to: n - 1,
            from_from_to: step((n - 1 - from) as f64),
            information: diagonal_information(0.005, 0.001),
            kind: EdgeKind::LoopClosure,
        });
        graph
    }

    #[test]
    fn a_correction_the_recent_part_cannot_absorb_grows_it_to_the_whole_graph() {
        // 39 steps 10 cm long each against a closure to the first node: 3.9 m that five free
        // nodes (or ten, or twenty) cannot take up without straining the edges to the held ones
        // beyond the robust kernel's width.
        let graph = chain(40, 1.1, 0);
        let config = OptimizeConfig::default();
        let (poses, solve) = optimize_local(&graph, 35, 0, &config, 0.5).unwrap();
        assert!(solve.whole && solve.attempts >= 2, "{solve:?}");
        let (whole, _) = optimize(&graph, 0, &config).unwrap();
        assert_eq!(poses, whole);
        let span = poses[39].translation.x - poses[0].translation.x;
        assert!((span - 39.0).abs() < 0.01, "{span}");
    }

    #[test]
    fn a_closure_within_the_recent_part_leaves_the_older_nodes_as_they_were() {
        let graph = chain(40, 1.01, 34);
        let (poses, solve) =
            optimize_local(&graph, 32, 0, &OptimizeConfig::default(), 0.5).unwrap();
        assert!(
            !solve.whole && solve.first_free == 32 && solve.attempts == 1,
            "{solve:?}"
        );
        assert_eq!(solve.free_nodes, 8);
        assert_eq!(&poses[..32], &graph.world_from_node[..32]);
        let span = poses[39].translation.x - poses[34].translation.x;
        assert!((span - 5.0).abs() < 0.01, "{span}");
    }

    #[test]
    fn a_gauge_outside_the_graph_or_a_share_outside_0_to_1_is_refused() {
        let graph = chain(5, 1.0, 0);
        let config = OptimizeConfig::default();
        assert!(optimize_local(&graph, 2, 5, &config, 0.5).is_err());
        assert!(optimize_local(&graph, 2, 0, &config, 1.5).is_err());
    }
}
