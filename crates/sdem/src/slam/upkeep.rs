//! What keeps the loop's work per stop and its memory bounded as the map grows: the index of
//! node positions and descriptors (the candidates of a step come from near its place, not from
//! every node), the fused map that follows moved nodes by taking their scans out and putting
//! them back ([`VoxelFusion`]), the pose graph solved over the part a loop closure touches
//! ([`optimize_local`]), and the nodes far from the robot parked in a [`NodeStore`].
//!
//! [`Slam`](super::Slam) calls these at named points of its step: when a node joins the map
//! ([`Upkeep::node_added`]; only the world's segment is fused, [`Upkeep::joined`] fuses a
//! segment joined to it), before it reads nodes' points ([`Upkeep::bring`]), for the solve
//! after an accepted closure ([`Upkeep::solve`]) and at the end of the step
//! ([`Upkeep::after_step`]).

use crate::error::Result;
use crate::geometry::{attitude_of, Pose, Vec3};
use crate::index::NodeIndex;
use crate::map::{Descriptor, Map};
use crate::posegraph::{optimize_local, Edge, LocalSolve, OptimizeConfig, PoseGraph};
use crate::store::{NodeStore, Residency};
use crate::voxel::{VoxelConfig, VoxelFusion, VoxelMap};
use rayon::prelude::*;
use serde::{Deserialize, Serialize};
use std::sync::Arc;

/// How the loop keeps its work per stop and its memory bounded as the map grows; written with
/// the rest of [`SlamOptions`](super::SlamOptions) as `[growth]`.
#[derive(Debug, Clone, PartialEq, Serialize, Deserialize)]
#[serde(default, deny_unknown_fields)]
pub struct GrowthOptions {
    /// With a node store attached ([`Slam::set_node_store`](super::Slam::set_node_store)): at
    /// most this many nodes hold their points in memory, the most recently used (the newest
    /// always among them); the others' points are in the store until a step needs them.
    pub resident_nodes: usize,
    /// A node is fused again (taken out of the voxel map at the pose it was fused at and put
    /// back at its current one) once a solve has moved it more than this, metres …
    pub refuse_tolerance_m: f64,
    /// … or turned it more than this, degrees.
    pub refuse_tolerance_deg: f64,
    /// At most this many moved nodes are fused again per stop, the largest moves first; the
    /// others wait for later stops ([`Slam::settle_map`](super::Slam::settle_map) does them all).
    pub refuse_per_stop: usize,
    /// After a stop that accepted a loop closure, this many stops look for none: on a route
    /// that retraces itself every stop could close a loop, and one in a few keeps the map as
    /// well at a fraction of the time.
    pub closure_interval: usize,
    /// The solve after a closure frees the nodes from this many before the closure's oldest
    /// node on; older ones that edges reach are held.
    pub solve_margin_nodes: usize,
    /// A solve that would free more than this share of the nodes solves the whole graph.
    pub whole_solve_fraction: f64,
    /// At most this many older nodes near a new one are weighed as its loop-closure
    /// candidates (their points brought back and scored), the nearest: on a route that passes
    /// a place lap after lap the nodes there grow with the laps, the work of a stop does not.
    pub closure_candidate_nodes: usize,
    /// At most this many nodes near a prediction are weighed as references when the recent
    /// nodes do not see the scan (recovery), the nearest.
    pub recovery_candidate_nodes: usize,
    /// Fuse each new node into the voxel map at its own stop, and the nodes a solve moved a
    /// few per stop ([`Self::refuse_per_stop`]), so that the fused map is current after every
    /// step. Off (the default), the loop spends no time on the fused map, which only its
    /// outputs read: nodes are fused when the map is settled ([`Slam::settle_map`], before
    /// it is saved or viewed), and [`Slam::voxels`] and [`Slam::merged_cloud`] fuse the
    /// waiting ones into a copy. The map is the same either way: its counts do not depend
    /// on the order nodes are fused in.
    ///
    /// [`Slam::settle_map`]: super::Slam::settle_map
    /// [`Slam::voxels`]: super::Slam::voxels
    /// [`Slam::merged_cloud`]: super::Slam::merged_cloud
    pub fuse_each_stop: bool,
}

impl Default for GrowthOptions {
    fn default() -> Self {
        Self {
            resident_nodes: 300,
            refuse_tolerance_m: 0.02,
            refuse_tolerance_deg: 0.2,
            refuse_per_stop: 2,
            closure_interval: 4,
            solve_margin_nodes: 10,
            whole_solve_fraction: 0.5,
            closure_candidate_nodes: 24,
            recovery_candidate_nodes: 96,
            fuse_each_stop: false,
        }
    }
}

impl GrowthOptions {
    /// Checks the values.
    pub fn validate(&self) -> Result<()> {
        let bad = |why: String| Err(crate::error::Error::Invalid(format!("growth: {why}")));
        if self.resident_nodes == 0 {
            return bad("resident_nodes must be at least 1".into());
        }
        for (name, v) in [
            ("closure_candidate_nodes", self.closure_candidate_nodes),
            ("recovery_candidate_nodes", self.recovery_candidate_nodes),
        ] {
            if v == 0 {
                return bad(format!("{name} must be at least 1"));
            }
        }
        for (name, v) in [
            ("refuse_tolerance_m", self.refuse_tolerance_m),
            ("refuse_tolerance_deg", self.refuse_tolerance_deg),
        ] {
            if !(v.is_finite() && v >= 0.0) {
                return bad(format!("{name} = {v} must be a finite number >= 0"));
            }
        }
        if !(0.0..=1.0).contains(&self.whole_solve_fraction) {
            return bad(format!(
                "whole_solve_fraction = {} must lie in 0..=1",
                self.whole_solve_fraction
            ));
        }
        Ok(())
    }
}

/// The loop's indices, fused map and node residency (see the module documentation).
#[derive(Debug, Clone)]
pub(super) struct Upkeep {
    options: GrowthOptions,
    index: NodeIndex,
    pub(super) fusion: VoxelFusion,
    pub(super) residency: Residency,
    /// The newest node at which a loop closure was accepted.
    last_closure: Option<usize>,
}

impl Upkeep {
    pub(super) fn new(options: &GrowthOptions, voxel: VoxelConfig) -> Result<Self> {
        options.validate()?;
        Ok(Self {
            options: options.clone(),
            index: NodeIndex::new(),
            fusion: VoxelFusion::new(voxel)?,
            residency: Residency::in_memory(),
            last_closure: None,
        })
    }

    /// Attaches a store: nodes beyond [`GrowthOptions::resident_nodes`] are parked in it.
    pub(super) fn set_store(&mut self, store: Arc<dyn NodeStore>) {
        self.residency = Residency::with_store(store, self.options.resident_nodes);
    }

    /// Indexes node `node_id`, which has just joined `map` with its points, and fuses it when
    /// it is in the world's segment (another segment's frame is not the world's) and
    /// [`GrowthOptions::fuse_each_stop`] asks for it.
    pub(super) fn node_added(&mut self, map: &Map, node_id: usize) -> Result<()> {
        let node = &map.nodes[node_id];
        let fuse = self.options.fuse_each_stop && in_world(map, node_id);
        self.enter(
            node_id,
            &node.world_from_sensor,
            &node.points_in_sensor,
            fuse,
        )
    }

    /// Indexes every node of `map` afresh (a restored map) and starts the fused map again: the
    /// nodes of the world's segment are fused now with [`GrowthOptions::fuse_each_stop`], else
    /// when the map is settled.
    pub(super) fn rebuild(&mut self, map: &mut Map) -> Result<()> {
        self.index = NodeIndex::new();
        self.fusion = VoxelFusion::new(*self.fusion.config())?;
        for id in 0..map.nodes.len() {
            let points = self.residency.points_of(map, id)?.into_owned();
            let fuse = self.options.fuse_each_stop && in_world(map, id);
            self.enter(id, &map.nodes[id].world_from_sensor, &points, fuse)?;
        }
        Ok(())
    }

    /// The nodes `ids` were moved into the world's segment (a segment joined to it): they
    /// move in the index and, with [`GrowthOptions::fuse_each_stop`], are fused at their new
    /// poses.
    pub(super) fn joined(&mut self, map: &mut Map, ids: &[usize]) -> Result<()> {
        for &id in ids {
            self.index.moved(id, map.nodes[id].position());
            if self.options.fuse_each_stop
                && in_world(map, id)
                && self.fusion.fused_pose(id).is_none()
            {
                fuse_first(&mut self.fusion, &self.residency, map, &[id])?;
            }
        }
        Ok(())
    }

    /// Indexes node `node_id` at `world_from_sensor` with the descriptor of its points, and
    /// fuses them there when `fuse`.
    fn enter(
        &mut self,
        node_id: usize,
        world_from_sensor: &Pose,
        points_in_sensor: &[[f32; 3]],
        fuse: bool,
    ) -> Result<()> {
        let sensor = as_vectors(points_in_sensor);
        let levelled: Vec<[f32; 3]> = sensor
            .iter()
            .map(|p| {
                let q = world_from_sensor.rotation * p;
                [q.x as f32, q.y as f32, q.z as f32]
            })
            .collect();
        self.index.insert(
            node_id,
            world_from_sensor.translation.vector,
            Descriptor::from_levelled(&levelled),
            attitude_of(world_from_sensor).yaw,
        );
        if !fuse {
            return Ok(());
        }
        self.fusion.add(node_id, world_from_sensor, &sensor)
    }

    /// Brings the points of `ids` back into memory (from the store, where they were parked).
    pub(super) fn bring(&mut self, map: &mut Map, ids: &[usize]) -> Result<()> {
        self.residency.bring(map, ids)
    }

    /// Whether node `to` comes within [`GrowthOptions::closure_interval`] stops after the
    /// last node that accepted a loop closure: it looks for none.
    pub(super) fn closure_paused(&self, to: usize) -> bool {
        (self.last_closure).is_some_and(|last| to <= last + self.options.closure_interval)
    }

    /// The newest node at which a loop closure was accepted, if any.
    pub(super) fn last_closure(&self) -> Option<usize> {
        self.last_closure
    }

    /// Records that node `to` accepted a loop closure.
    pub(super) fn closure_accepted(&mut self, to: usize) {
        self.last_closure = Some(self.last_closure.map_or(to, |last| last.max(to)));
    }

    /// Solves the pose graph after loop closures whose oldest node is `oldest_from`, the last
    /// accepted before them at node `anchored`: what drifted since that closure, or since
    /// `oldest_from` when it is newer (a loop of its own), is freed with a margin, and the
    /// part grows as far as it must (see [`optimize_local`]). Moves the nodes and their index
    /// entries.
    pub(super) fn solve(
        &mut self,
        map: &mut Map,
        edges: &[Edge],
        oldest_from: usize,
        anchored: Option<usize>,
        config: &OptimizeConfig,
    ) -> Result<(LocalSolve, f64)> {
        let graph = PoseGraph {
            world_from_node: map.nodes.iter().map(|n| n.world_from_sensor).collect(),
            edges: edges.to_vec(),
        };
        let drifted_from = anchored.map_or(oldest_from, |a| a.max(oldest_from));
        let first = drifted_from.saturating_sub(self.options.solve_margin_nodes);
        let (poses, solve) =
            optimize_local(&graph, first, 0, config, self.options.whole_solve_fraction)?;
        let mut max_shift: f64 = 0.0;
        for (id, pose) in poses.into_iter().enumerate().skip(solve.first_free) {
            let node = &mut map.nodes[id];
            max_shift = max_shift.max((node.position() - pose.translation.vector).norm());
            node.world_from_sensor = pose;
            self.index.moved(id, pose.translation.vector);
        }
        Ok((solve, max_shift))
    }

    /// The nodes whose positions lie within `radius_m` of `position` (any segment), by id:
    /// from the index, the work of the nodes near the place.
    pub(super) fn nodes_within(&self, position: &Vec3, radius_m: f64) -> Vec<usize> {
        self.index.within(position, radius_m)
    }

    /// Moves every node's position in the index (after a solve of the whole graph elsewhere).
    pub(super) fn all_moved(&mut self, map: &Map) {
        for node in &map.nodes {
            self.index.moved(node.node_id, node.position());
        }
    }

    /// The end of a step: fuses again up to [`GrowthOptions::refuse_per_stop`] of the nodes a
    /// solve moved, when [`GrowthOptions::fuse_each_stop`]; with `all` (the map settled), first
    /// fuses every node of the world's segment not fused yet, then again every node moved.
    /// Then parks the least recently used nodes beyond the resident limit (never the
    /// `keep_newest` newest). Returns the nodes fused, first or again.
    pub(super) fn after_step(
        &mut self,
        map: &mut Map,
        keep_newest: usize,
        all: bool,
    ) -> Result<usize> {
        if !all && !self.options.fuse_each_stop {
            self.residency.trim(map, keep_newest)?;
            return Ok(0);
        }
        let waiting = self.waiting(map);
        fuse_first(&mut self.fusion, &self.residency, map, &waiting)?;
        let poses: Vec<Pose> = map.nodes.iter().map(|n| n.world_from_sensor).collect();
        let mut stale = self.fusion.stale(
            &poses,
            self.options.refuse_tolerance_m,
            self.options.refuse_tolerance_deg.to_radians(),
        );
        if !all {
            stale.truncate(self.options.refuse_per_stop);
        }
        for &id in &stale {
            let sensor = as_vectors(&self.residency.points_of(map, id)?);
            self.fusion.moved(id, &poses[id], &sensor)?;
        }
        self.residency.trim(map, keep_newest)?;
        Ok(waiting.len() + stale.len())
    }

    /// The nodes of the world's segment not fused yet, by id.
    fn waiting(&self, map: &Map) -> Vec<usize> {
        (0..map.nodes.len())
            .filter(|&id| in_world(map, id) && self.fusion.fused_pose(id).is_none())
            .collect()
    }

    /// The fused map with the nodes of the world's segment not fused yet fused into a copy
    /// (at their current poses), as a [`VoxelMap`].
    ///
    /// # Errors
    /// [`crate::Error::NodeStore`] when a parked node's points cannot be read back.
    pub(super) fn voxels(&self, map: &Map) -> Result<VoxelMap> {
        let waiting = self.waiting(map);
        if waiting.is_empty() {
            return Ok(self.fusion.to_voxel_map());
        }
        let mut fusion = self.fusion.clone();
        fuse_first(&mut fusion, &self.residency, map, &waiting)?;
        Ok(fusion.to_voxel_map())
    }
}

/// Fuses the nodes `ids` of `map`, none fused yet, into `fusion` at their current poses (their
/// points from memory or read back from the store). Many nodes at once (a map settled for the
/// first time, or loaded) are fused in one contiguous share per thread, each into a fusion of
/// its own, and the shares' counts summed in order ([`VoxelFusion::absorb`]): the same map as
/// one by one, in about half the time on 2 cores.
fn fuse_first(
    fusion: &mut VoxelFusion,
    residency: &Residency,
    map: &Map,
    ids: &[usize],
) -> Result<()> {
    let fuse = |fusion: &mut VoxelFusion, ids: &[usize]| -> Result<()> {
        for &id in ids {
            let sensor = as_vectors(&residency.points_of(map, id)?);
            fusion.add(id, &map.nodes[id].world_from_sensor, &sensor)?;
        }
        Ok(())
    };
    let threads = rayon::current_num_threads();
    if threads < 2 || ids.len() < PARALLEL_FUSION_NODES {
        return fuse(fusion, ids);
    }
    let shares: Vec<Result<VoxelFusion>> = ids
        .par_chunks(ids.len().div_ceil(threads))
        .map(|share| {
            let mut part = VoxelFusion::new(*fusion.config())?;
            fuse(&mut part, share)?;
            Ok(part)
        })
        .collect();
    for part in shares {
        fusion.absorb(part?)?;
    }
    Ok(())
}

/// The least nodes [`fuse_first`] shares among threads: fewer are fused one by one, on one.
const PARALLEL_FUSION_NODES: usize = 8;

/// Whether node `id` is in the world's segment (node 0's).
fn in_world(map: &Map, id: usize) -> bool {
    map.nodes[id].segment == map.nodes.first().map_or(0, |n| n.segment)
}

/// Points as `f64` vectors.
fn as_vectors(points: &[[f32; 3]]) -> Vec<Vec3> {
    points
        .iter()
        .map(|p| Vec3::new(p[0] as f64, p[1] as f64, p[2] as f64))
        .collect()
}
