//! Map segments: pieces of the map each in a frame of its own, as trajectories are in
//! Cartographer.
//!
//! A stop found nowhere with confidence does not bend the map: it starts a new segment, whose
//! nodes are placed relative to one another by their matches while the segment's place in the
//! world is unknown (its poses are a guess, reported as such). When a later match links a node
//! of one segment to a node of another with confidence (a loop closure, a relocalization), the
//! younger segment's nodes are moved into the older one's frame by that match, the match
//! becomes a pose-graph edge, and the joined graph is optimized. Segment 0, which holds the
//! first node, is the world.
//!
//! A segment is identified by its first node's id; its pose graph is optimized alone, its
//! first node held.

use super::step::{OptimizationSummary, SegmentJoin};
use super::{ms, Slam};
use crate::error::Result;
use crate::geometry::Pose;
use crate::posegraph::{optimize, Edge, PoseGraph};
use serde::Serialize;
use std::time::Instant;

/// One segment of the map ([`Slam::segments`]).
#[derive(Debug, Clone, PartialEq, Serialize)]
pub struct Segment {
    /// Its id: the id of its first node.
    pub id: usize,
    /// How many nodes it holds.
    pub nodes: usize,
    /// It is the world's segment (it holds node 0): its poses are in the world frame. Another
    /// segment's place in the world is not known.
    pub in_world: bool,
    /// The runs its nodes come from.
    pub runs: Vec<usize>,
}

impl Slam {
    /// The map's segments, the world's first.
    pub fn segments(&self) -> Vec<Segment> {
        let mut segments: Vec<Segment> = Vec::new();
        for node in &self.map.nodes {
            match segments.iter_mut().find(|s| s.id == node.segment) {
                Some(s) => {
                    s.nodes += 1;
                    if !s.runs.contains(&node.run) {
                        s.runs.push(node.run);
                    }
                }
                None => segments.push(Segment {
                    id: node.segment,
                    nodes: 1,
                    in_world: node.segment == self.world_segment(),
                    runs: vec![node.run],
                }),
            }
        }
        segments.sort_by_key(|s| s.id);
        segments
    }

    /// The segment that holds node 0: the world.
    pub(super) fn world_segment(&self) -> usize {
        self.map.nodes.first().map_or(0, |n| n.segment)
    }

    /// The nodes of `segment` that `keep` keeps whose origins lie within `radius_m` of
    /// `position`: the `limit` nearest, nearest first (ties by id). Where a route passes a
    /// place lap after lap the nodes there grow with the laps; the ones a step weighs do not.
    pub(super) fn candidates_near(
        &self,
        (segment, position): (usize, &crate::geometry::Vec3),
        radius_m: f64,
        limit: usize,
        keep: impl Fn(usize) -> bool,
    ) -> Vec<usize> {
        let mut near: Vec<(usize, f64)> = (self.upkeep.nodes_within(position, radius_m))
            .into_iter()
            .filter(|&id| self.map.nodes[id].segment == segment && keep(id))
            .map(|id| (id, (self.map.nodes[id].position() - position).norm()))
            .filter(|&(_, d)| d <= radius_m)
            .collect();
        near.sort_by(|a, b| a.1.total_cmp(&b.1).then(a.0.cmp(&b.0)));
        near.truncate(limit);
        near.into_iter().map(|(id, _)| id).collect()
    }

    /// The nodes of `segment`, in order.
    pub(super) fn segment_nodes(&self, segment: usize) -> Vec<usize> {
        (self.map.nodes.iter())
            .filter(|n| n.segment == segment)
            .map(|n| n.node_id)
            .collect()
    }

    /// Joins the segments of nodes `a` and `b`, linked by `edge` (from `a`'s node to `b`'s, the
    /// match measured in `a`'s segment's frame as `world_from_b`): the younger segment's nodes
    /// are moved rigidly so that `b` stands at `world_from_b` in the older one's frame (or `a`
    /// where `b` says), relabelled, and the edge added. Returns the join.
    ///
    /// # Errors
    /// [`crate::Error::NodeStore`] when a parked node's points cannot be read back to fuse it.
    pub(super) fn join_segments(&mut self, edge: Edge, world_from_b: &Pose) -> Result<SegmentJoin> {
        let (a, b) = (edge.from, edge.to);
        let (segment_a, segment_b) = (self.map.nodes[a].segment, self.map.nodes[b].segment);
        let b_now = self.map.nodes[b].world_from_sensor;
        // The transform that carries frame B into frame A, and the one back.
        let a_from_b = world_from_b * b_now.inverse();
        let (into, absorbed, into_from_absorbed) = if segment_a <= segment_b {
            (segment_a, segment_b, a_from_b)
        } else {
            (segment_b, segment_a, a_from_b.inverse())
        };
        let first = self.map.nodes[absorbed].position();
        for node in self.map.nodes.iter_mut().filter(|n| n.segment == absorbed) {
            node.world_from_sensor = into_from_absorbed * node.world_from_sensor;
            node.segment = into;
        }
        let moved_m = (self.map.nodes[absorbed].position() - first).norm();
        self.edges.push(edge);
        let ids = self.segment_nodes(into);
        self.upkeep.joined(&mut self.map, &ids)?;
        Ok(SegmentJoin {
            into,
            absorbed,
            link: (a, b),
            moved_m,
        })
    }

    /// Optimizes the whole pose graph of `segment` alone (its first node held) and moves its
    /// nodes (the fused map follows them in the steps to come).
    ///
    /// # Errors
    /// The optimizer's errors (invalid edges).
    pub(super) fn optimize_segment(&mut self, segment: usize) -> Result<OptimizationSummary> {
        let start = Instant::now();
        let ids = self.segment_nodes(segment);
        let mut index = vec![usize::MAX; self.map.nodes.len()];
        for (k, &id) in ids.iter().enumerate() {
            index[id] = k;
        }
        let edges: Vec<Edge> = (self.edges.iter())
            .filter(|e| index[e.from] != usize::MAX && index[e.to] != usize::MAX)
            .map(|e| Edge {
                from: index[e.from],
                to: index[e.to],
                ..e.clone()
            })
            .collect();
        let graph = PoseGraph {
            world_from_node: ids
                .iter()
                .map(|&id| self.map.nodes[id].world_from_sensor)
                .collect(),
            edges,
        };
        let (poses, report) = optimize(&graph, 0, &self.config.optimize)?;
        let mut max_shift: f64 = 0.0;
        for (&id, pose) in ids.iter().zip(poses) {
            let node = &mut self.map.nodes[id];
            max_shift = max_shift.max((node.position() - pose.translation.vector).norm());
            node.world_from_sensor = pose;
        }
        self.upkeep.all_moved(&self.map);
        Ok(OptimizationSummary {
            iterations: report.iterations,
            initial_cost: report.initial_cost,
            final_cost: report.final_cost,
            time_ms: ms(start),
            max_node_shift_m: max_shift,
            free_nodes: ids.len().saturating_sub(1),
            whole_graph: true,
        })
    }

    /// Solves the pose graph after the loop closures of this step in `segment` (the last
    /// closure before them accepted at node `anchored`). A map of one segment is solved over
    /// the part of it that drifted since, grown as far as the edges ask, the whole graph when
    /// it reaches that far ([`crate::posegraph::optimize_local`]); a map of several segments
    /// solves `segment` alone, whole. The moved nodes are fused again in the steps to come.
    ///
    /// # Errors
    /// The optimizer's errors (invalid edges).
    pub(super) fn solve_after_closure(
        &mut self,
        segment: usize,
        anchored: Option<usize>,
    ) -> Result<OptimizationSummary> {
        let last = self.map.nodes.len().saturating_sub(1);
        let oldest = (self.loop_closures.iter())
            .filter(|c| c.to == last)
            .map(|c| c.from.min(c.to))
            .min();
        let (Some(oldest), true) = (oldest, self.segments().len() == 1) else {
            return self.optimize_segment(segment);
        };
        let start = Instant::now();
        let (solve, max_shift) = self.upkeep.solve(
            &mut self.map,
            &self.edges,
            oldest,
            anchored,
            &self.config.optimize,
        )?;
        Ok(OptimizationSummary {
            iterations: solve.report.iterations,
            initial_cost: solve.report.initial_cost,
            final_cost: solve.report.final_cost,
            time_ms: ms(start),
            max_node_shift_m: max_shift,
            free_nodes: solve.free_nodes,
            whole_graph: solve.whole,
        })
    }
}
