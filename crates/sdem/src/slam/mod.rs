//! The stop-and-go loop (Nagatani et al. 2003, Sec. III, Fig. 2): move, sense, build the local
//! S-DEM, compare it with the global map, localize, add it to the map, repeat — with what the
//! paper left open: merging (the merged virtual S-DEM, [`crate::map`], and the occupancy voxel
//! map, [`crate::voxel`]), loop closure over a robust pose graph ([`crate::posegraph`]), and
//! what a robot needs when its prediction is wrong.
//!
//! [`Slam::add_scan`] takes one scan at a time as plain values (points, attitude reading,
//! odometry), so the same loop runs on a dataset folder, a saved map being resumed or extended
//! by a second run, or a robot.
//!
//! Per scan:
//! 1. **Predict** where the scan was taken, several ways (`predictions`): the odometry's
//!    motion when there is odometry, the last motion repeated (constant velocity), no motion,
//!    the nodes the last one is linked to; roll and pitch from the gyro reading when there is
//!    one, the heading from the odometry, else the compass, else the motion — and each search
//!    window as wide as its source is weak.
//! 2. **Localize** (`recovery`): each prediction in turn against the recent nodes of the
//!    current segment that see what the scan sees there (merged into one virtual S-DEM), with
//!    the exact search and the 6-DoF refinement; the first match without doubt is taken. When
//!    none is, the window grows around the best; then every heading (and the tilt, without a
//!    gyro) is searched near the last node; then the whole map, without a prior, by place
//!    descriptors over every heading ([`relocalize`] does the same for a saved map). The
//!    match's covariance weighs its pose-graph edges.
//! 3. **Or start a segment** (`segments`): a stop found nowhere with confidence is not put
//!    into the map as if it were: it starts a new map segment in a frame of its own, and a
//!    later confident match joins the segments.
//! 4. **Close loops** (`closures`): older nodes that see what the new one sees are verified
//!    with the exact search over every heading, checked for consistency with the other
//!    closures, and the pose graph is optimized (robust Cauchy kernel): over the part of it
//!    the closure touches when the map is one segment, else the closure's segment alone.
//!
//! The fused voxel map is only read by the loop's outputs: it is brought up to date when the
//! map is settled for a view or a save ([`Slam::settle_map`]), or at every stop with
//! [`GrowthOptions::fuse_each_stop`].
//!
//! As the map grows the work per stop stays bounded (`upkeep`): the fused map takes a moved
//! node's scan out and puts it back instead of fusing every scan again, the graph is solved
//! over the part a closure touches, and with a node store attached, the nodes far from the
//! robot keep their points there.
//!
//! Each step reports its status ([`StepStatus`]: tracked, recovered and how, relocalized, a
//! new segment, doubtful), every search it tried ([`Attempt`]) and its doubts.
//!
//! The module's files: this one holds the loop, `predictions`, `recovery`, `segments`,
//! `closures` and `joins` its stages, `options` the configuration, `step` what a step reports,
//! `relocalize` finding a scan in a saved map, `trajectory` the errors of an estimated
//! trajectory against a reference one, `upkeep` what keeps the work per stop and the memory
//! bounded as the map grows.

mod closures;
mod joins;
mod map_search;
mod options;
mod predictions;
mod recovery;
mod relocalize;
mod segments;
mod step;
mod trajectory;
mod upkeep;

pub use options::{
    is_lidar, is_solid_state_lidar, is_spinning_lidar, RecoveryOptions, SlamOptions,
};
pub use relocalize::{relocalize, Near, Relocalization};
pub use segments::Segment;
pub use step::{
    Attempt, HeadingPrior, OptimizationSummary, PredictionSource, Recovery, SegmentJoin, Step,
    StepReport, StepStatus,
};
pub use trajectory::{alignment, trajectory_errors, TrajectoryErrors};
pub use upkeep::GrowthOptions;

use crate::error::{Error, Result};
use crate::geometry::{pose_from_parts, Attitude, Pose, Vec3};
use crate::map::{LoopClosure, Map, Node};
use crate::posegraph::{Edge, EdgeKind};
use crate::store::NodeStore;
use crate::voxel::VoxelMap;
use map_search::{Located, Matched};
use nalgebra::{Matrix3, Matrix6};
use std::sync::Arc;
use std::time::Instant;
use upkeep::Upkeep;

/// One scan as the loop receives it.
#[derive(Debug, Clone)]
pub struct ScanInput<'a> {
    /// Index of the scan in its dataset.
    pub scan_index: usize,
    /// The scan, sensor frame, metres.
    pub points_in_sensor: &'a [Vec3],
    /// The gyro/compass reading, when there is one.
    pub attitude: Option<Attitude>,
    /// The odometry's readings at this scan and at the previous one, when there is odometry
    /// (only their relative motion is used).
    pub odometry: Option<Odometry>,
}

/// Two readings of the robot's odometry frame (as ROS's `/odom` gives it): at this scan and at
/// the previous one. Only the motion between them, `previous_sensor_from_sensor`, is used: the
/// odometry frame itself drifts without bound.
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct Odometry {
    /// The odometry's pose of the sensor at this scan.
    pub odom_from_sensor: Pose,
    /// The odometry's pose of the sensor at the previous scan.
    pub odom_from_previous_sensor: Pose,
}

impl Odometry {
    /// The motion since the previous scan, in the previous sensor's frame.
    pub fn previous_sensor_from_sensor(&self) -> Pose {
        self.odom_from_previous_sensor.inverse() * self.odom_from_sensor
    }
}

/// The loop's state: the map, the pose graph's edges and the fused voxel map.
#[derive(Debug, Clone)]
pub struct Slam {
    config: SlamOptions,
    /// The nodes. With a node store attached ([`Slam::set_node_store`]), the points of nodes
    /// far from the robot are in the store and their `points_in_sensor` is empty: read them
    /// through [`Slam::node_points`].
    pub map: Map,
    /// The pose graph's edges (matches to reference nodes and loop closures).
    pub edges: Vec<Edge>,
    /// Accepted loop closures.
    pub loop_closures: Vec<LoopClosure>,
    /// The node index, the fused occupancy map (of the world's segment) and the nodes'
    /// residency.
    upkeep: Upkeep,
    /// Every loop closure the match verified, accepted or not, for the consistency check.
    closure_pool: Vec<LoopClosure>,
    /// Segments started with no prior at all (a run begun in a saved map and found nowhere):
    /// their frames are not even roughly the world's.
    unplaced_segments: Vec<usize>,
    /// Segments whose first node was placed by the odometry's motion from the last one: their
    /// frames are the world's to within the odometry's error.
    measured_segments: Vec<usize>,
    /// The nodes a join of their segment with another was tried from (the tries are bounded:
    /// `joins`).
    join_tries: Vec<usize>,
    /// Weak matches of nodes of segments not yet joined, each waiting for another that agrees
    /// (`joins`).
    weak_joins: Vec<joins::WeakJoin>,
    /// The run the next scans belong to.
    run: usize,
    /// The robot's last stop, when its place in the map is known to the loop (`None` at the
    /// start of a run into a saved map).
    last_node: Option<usize>,
    /// The scan index of the last scan of this run.
    last_scan_index: Option<usize>,
    /// The odometry's reading at the last scan given to [`Slam::add`].
    last_odom_from_sensor: Option<Pose>,
    /// The index [`Slam::add`] gives the next scan.
    next_scan_index: usize,
}

impl Slam {
    /// An empty map.
    ///
    /// # Errors
    /// An invalid configuration.
    pub fn new(config: SlamOptions) -> Result<Self> {
        config.validate()?;
        let upkeep = Upkeep::new(&config.growth, config.voxel)?;
        Ok(Self {
            config,
            map: Map::default(),
            edges: Vec::new(),
            loop_closures: Vec::new(),
            upkeep,
            closure_pool: Vec::new(),
            unplaced_segments: Vec::new(),
            measured_segments: Vec::new(),
            join_tries: Vec::new(),
            weak_joins: Vec::new(),
            run: 0,
            last_node: None,
            last_scan_index: None,
            last_odom_from_sensor: None,
            next_scan_index: 0,
        })
    }

    /// Restores a loop from saved nodes and edges (a resumed run): the robot stands at the last
    /// node; the voxel map is rebuilt.
    ///
    /// # Errors
    /// An invalid configuration, or edges naming nodes that are not there.
    pub fn restore(
        config: SlamOptions,
        map: Map,
        edges: Vec<Edge>,
        loop_closures: Vec<LoopClosure>,
    ) -> Result<Self> {
        let n = map.nodes.len();
        if let Some(e) = edges.iter().find(|e| e.from >= n || e.to >= n) {
            return Err(Error::Invalid(format!(
                "a saved edge joins nodes {} and {} but the map has {n} nodes",
                e.from, e.to
            )));
        }
        if let Some(node) = (map.nodes.iter()).find(|node| node.segment > node.node_id) {
            return Err(Error::Invalid(format!(
                "node {} is saved in segment {}, which starts after it",
                node.node_id, node.segment
            )));
        }
        let mut slam = Self::new(config)?;
        slam.map = map;
        slam.edges = edges;
        slam.closure_pool = loop_closures.clone();
        // Whether a saved segment's frame is near the world's is not saved: none is taken to be.
        let world = slam.map.nodes.first().map_or(0, |n| n.segment);
        slam.unplaced_segments = (slam.map.nodes.iter())
            .map(|n| n.segment)
            .filter(|&s| s != world)
            .collect();
        slam.unplaced_segments.sort_unstable();
        slam.unplaced_segments.dedup();
        // The pause after the last accepted closure goes on where it stopped: a run resumed
        // within `closure_interval` stops of one looked for closures the uninterrupted run did
        // not (6 accepted instead of 4 on a 40-stop run resumed at 32).
        for c in loop_closures.iter().filter(|c| c.accepted) {
            slam.upkeep.closure_accepted(c.to);
        }
        slam.loop_closures = loop_closures;
        if let Some(last) = slam.map.nodes.last() {
            slam.run = last.run;
            slam.last_node = Some(last.node_id);
            slam.last_scan_index = Some(last.scan_index);
            slam.next_scan_index = last.scan_index + 1;
        }
        slam.rebuild_voxels()?;
        Ok(slam)
    }

    /// The configuration.
    pub fn config(&self) -> &SlamOptions {
        &self.config
    }

    /// Starts a new run into the map (a robot returning the next day, a second robot of the
    /// team): its first scan is taken with no known pose, relocalized in the whole map or, when
    /// it is found nowhere, the start of a new segment; its scan indices count from 0 again.
    pub fn begin_run(&mut self) {
        if !self.map.nodes.is_empty() {
            self.run = self.map.nodes.iter().map(|n| n.run).max().unwrap_or(0) + 1;
        }
        self.last_node = None;
        self.last_scan_index = None;
        self.last_odom_from_sensor = None;
        self.next_scan_index = 0;
    }

    /// The run the next scans belong to.
    pub fn run(&self) -> usize {
        self.run
    }

    /// Adds the next stop's scan: predicts its pose, localizes it against the map, adds it as
    /// a node and closes loops (and fuses it into the voxel map with
    /// [`GrowthOptions::fuse_each_stop`]): the loop `sdem slam` runs, one stop at a time.
    ///
    /// # Arguments
    /// * `points_in_sensor` — the scan, sensor frame, metres, as nalgebra points or vectors or
    ///   arrays ([`AsPoint`](crate::geometry::AsPoint)); NaN points are skipped.
    /// * `attitude` — the gyro/compass reading at the stop, or `None` without one.
    /// * `odom_from_sensor` — the odometry frame's pose of the sensor at the stop (as ROS's
    ///   `/odom` gives it), or `None` without odometry. Only its motion since the last call
    ///   that gave one is used.
    ///
    /// # Returns
    /// The [`Step`]: the sensor's pose in the world, the match's status and its report.
    ///
    /// # Errors
    /// Invalid input (see [`crate::Scan::from_points`]): the map is then unchanged.
    ///
    /// # Example
    /// ```
    /// use nalgebra::{Isometry3, Point3, Vector3};
    /// use sdem::{Attitude, Slam, SlamOptions};
    /// // A box-shaped room; the robot drives 10 cm along x between two stops.
    /// let room = |x: f64| -> Vec<Point3<f64>> {
    ///     let mut points = Vec::new();
    ///     for i in -40..=40 {
    ///         for j in -40..=40 {
    ///             let (u, v) = (i as f64 * 0.05, j as f64 * 0.05);
    ///             for p in [[2.0, u, v], [-1.5, u, v], [u, 1.7, v], [u, -1.3, v], [u, v, 1.1], [u, v, -0.4]] {
    ///                 points.push(Point3::new(p[0] - x, p[1], p[2]));
    ///             }
    ///         }
    ///     }
    ///     points
    /// };
    /// let mut slam = Slam::new(SlamOptions::default())?;
    /// let level = Some(Attitude::default());
    /// for x in [0.0, 0.1] {
    ///     let odom_from_sensor = Isometry3::translation(x * 1.05, 0.0, 0.0); // 5 % long
    ///     slam.add(&room(x), level, Some(odom_from_sensor))?;
    /// }
    /// let world_from_sensor = slam.poses()[1];
    /// assert!((world_from_sensor.translation.vector - Vector3::new(0.1, 0.0, 0.0)).norm() < 0.005);
    /// # Ok::<(), sdem::Error>(())
    /// ```
    pub fn add<P: crate::geometry::AsPoint>(
        &mut self,
        points_in_sensor: &[P],
        attitude: Option<crate::geometry::Attitude>,
        odom_from_sensor: Option<Pose>,
    ) -> Result<Step> {
        let points = crate::scan::checked_input(points_in_sensor, attitude.as_ref())?;
        let odometry = odom_from_sensor.zip(self.last_odom_from_sensor).map(
            |(odom_from_sensor, odom_from_previous_sensor)| Odometry {
                odom_from_sensor,
                odom_from_previous_sensor,
            },
        );
        let scan_index = self.next_scan_index;
        self.next_scan_index += 1;
        let report = self.add_scan(&ScanInput {
            scan_index,
            points_in_sensor: &points,
            attitude,
            odometry,
        })?;
        self.last_odom_from_sensor = odom_from_sensor;
        Ok(Step {
            world_from_sensor: self.map.nodes[report.node_id].world_from_sensor,
            status: report.status,
            report,
        })
    }

    /// The pose `world_from_sensor` of every node's sensor, in the order the scans were added,
    /// as the last loop closure left them. The poses of a segment other than the world's are
    /// in that segment's own frame ([`Slam::segments`]).
    pub fn poses(&self) -> Vec<Pose> {
        self.map.nodes.iter().map(|n| n.world_from_sensor).collect()
    }

    /// Indexes every node afresh and starts the fused map again on the current poses: the
    /// nodes of the world's segment are fused now with [`GrowthOptions::fuse_each_stop`], else
    /// when the map is settled ([`Slam::settle_map`]) or read ([`Slam::voxels`]).
    ///
    /// # Errors
    /// [`Error::NodeStore`] when a parked node's points cannot be read back.
    pub fn rebuild_voxels(&mut self) -> Result<()> {
        self.upkeep.rebuild(&mut self.map)
    }

    /// The fused occupancy map of the world's segment: every node's scan, each at the pose it
    /// was fused at, which lies within [`GrowthOptions::refuse_tolerance_m`] and
    /// `refuse_tolerance_deg` of its current one once [`Slam::settle_map`] has run (after a
    /// loop closure, the moved nodes are fused again when the map is settled, or a few per
    /// stop with [`GrowthOptions::fuse_each_stop`]). Nodes not fused yet are fused into a copy
    /// at their current poses; [`Slam::settle_map`] fuses them for good.
    ///
    /// # Errors
    /// [`Error::NodeStore`] when a parked node's points cannot be read back.
    pub fn voxels(&self) -> Result<VoxelMap> {
        self.upkeep.voxels(&self.map)
    }

    /// Fuses every node of the world's segment not fused yet, and again every node a solve
    /// moved beyond the tolerances, so that [`Slam::voxels`] and [`Slam::merged_cloud`] show
    /// the map on the current poses without fusing into a copy.
    ///
    /// # Returns
    /// The nodes fused, for the first time or again.
    ///
    /// # Errors
    /// [`Error::NodeStore`] when a parked node's points cannot be read back.
    pub fn settle_map(&mut self) -> Result<usize> {
        let keep = self.config.loop_closure.min_node_separation + 1;
        self.upkeep.after_step(&mut self.map, keep, true)
    }

    /// Keeps the points of nodes far from the robot in `store`: from now on at most
    /// [`GrowthOptions::resident_nodes`] nodes hold their points in memory, the most recently
    /// used; the others' come back from the store when a step needs them (a loop closure to an
    /// old place, a moved node fused again). A parked node is no candidate of a search of the
    /// whole map without a prior (relocalization, a segment's join by place).
    pub fn set_node_store(&mut self, store: Arc<dyn NodeStore>) {
        self.upkeep.set_store(store);
    }

    /// Node `node_id`'s points, sensor frame: from memory, or read back from the node store
    /// for this use when the node is parked.
    ///
    /// # Errors
    /// [`Error::NodeStore`] when a parked node's points cannot be read back; [`Error::Invalid`]
    /// for a node not in the map.
    pub fn node_points(&self, node_id: usize) -> Result<std::borrow::Cow<'_, [[f32; 3]]>> {
        if node_id >= self.map.nodes.len() {
            return Err(Error::Invalid(format!(
                "node {node_id} is not in the map ({} nodes)",
                self.map.nodes.len()
            )));
        }
        self.upkeep.residency.points_of(&self.map, node_id)
    }

    /// The number of node `node_id`'s points, parked or not (0 for a node not in the map).
    pub fn node_point_count(&self, node_id: usize) -> usize {
        self.upkeep.residency.point_count(&self.map, node_id)
    }

    /// Nodes whose points are in memory (all of them without a node store).
    pub fn resident_nodes(&self) -> usize {
        self.upkeep.residency.resident(&self.map)
    }

    /// The merged point cloud: every node's points of the world's segment in the world, kept
    /// where the fused map is occupied now (moved rubble, seen through later, drops out), one
    /// per voxel. Parked nodes are read back one at a time.
    ///
    /// # Errors
    /// [`Error::NodeStore`] when a parked node's points cannot be read back.
    pub fn merged_cloud(&self) -> Result<Vec<Vec3>> {
        let voxels = self.voxels()?;
        let mut merged = voxels.occupied_centroids();
        let world = self.world_segment();
        for node in self.map.nodes.iter().filter(|n| n.segment == world) {
            let points = self.node_points(node.node_id)?;
            merged.add(points.iter().map(|p| {
                (node.world_from_sensor
                    * nalgebra::Point3::new(p[0] as f64, p[1] as f64, p[2] as f64))
                .coords
            }));
        }
        Ok(merged.finish())
    }

    /// Runs one step of the loop on `scan`.
    ///
    /// # Errors
    /// An empty scan, or a scan index that does not follow the last one of the run — the map
    /// is unchanged by these. An invalid loop-closure or optimizer setting fails after the
    /// node was added (the node stays, localized). A scan that matches nothing is no error: it
    /// starts a new segment ([`StepStatus::NewSegment`]).
    pub fn add_scan(&mut self, scan: &ScanInput) -> Result<StepReport> {
        let start = Instant::now();
        if self.map.nodes.is_empty() {
            return self.add_first_scan(scan, start);
        }
        self.check_order(scan)?;
        let node_id = self.map.nodes.len();
        if let Some(last) = self.last_node {
            // The local map; the segment's other nodes come back only when a search needs
            // them (recovery, loop closure).
            let recent = self.recent_nodes(self.map.nodes[last].segment, last);
            self.upkeep.bring(&mut self.map, &recent)?;
        }
        let mut attempts = Vec::new();
        let located = self.locate(scan, self.last_node, &mut attempts)?;
        let mut lost_weak = None;
        let (status, matched, segment, world_from_sensor) = match located {
            Located::Found {
                matched,
                status,
                segment,
            } => {
                let status = if matched.doubts.is_empty() {
                    status
                } else {
                    StepStatus::Doubtful
                };
                let pose = matched.world_from_sensor;
                (status, Some(matched), segment, pose)
            }
            Located::Lost {
                guess,
                best,
                measured,
                weak,
            } => {
                lost_weak = weak;
                if self.last_node.is_none() {
                    self.unplaced_segments.push(node_id);
                } else if measured {
                    self.measured_segments.push(node_id);
                }
                // The whole map was searched for this scan: its join is tried from the next
                // nodes of its segment, once they have moved on (`joins`).
                self.join_tries.push(node_id);
                (StepStatus::NewSegment, best, node_id, guess)
            }
        };
        let links = match (&matched, status) {
            (Some(m), s) if s != StepStatus::NewSegment => m.references.clone(),
            _ => Vec::new(),
        };
        self.add_node(
            scan,
            node_id,
            world_from_sensor,
            segment,
            matched.as_ref(),
            &links,
        )?;
        if let Some(weak) = lost_weak {
            self.weak_joins
                .push(joins::WeakJoin::new(&self.map, node_id, *weak));
        }
        let closing_start = Instant::now();
        let mut closing = self.close_loops(node_id)?;
        attempts.append(&mut closing.attempts);
        let optimization = match closing.changed {
            Some(segment) => Some(self.solve_after_closure(segment, closing.anchored)?),
            None => None,
        };
        let loop_closure_ms = ms(closing_start);
        let map_start = Instant::now();
        let keep = self.config.loop_closure.min_node_separation + 1;
        self.upkeep.after_step(&mut self.map, keep, false)?;
        let map_update_ms = ms(map_start);
        let pose = self.map.nodes[node_id].world_from_sensor;
        let doubts = matched
            .as_ref()
            .map(|m| m.doubts.clone())
            .unwrap_or_default();
        Ok(StepReport {
            scan_index: scan.scan_index,
            run: self.run,
            node_id,
            status,
            recovery: (status == StepStatus::Recovered)
                .then(|| matched.as_ref().map(|m| m.source))
                .flatten(),
            segment: self.map.nodes[node_id].segment,
            attempts,
            joined: closing.joined,
            withdrawn_closures: closing.withdrawn,
            time_ms: ms(start),
            localize_ms: matched.as_ref().map_or(0.0, |m| m.localize_ms),
            loop_closure_ms,
            map_update_ms,
            world_from_sensor: (&pose).into(),
            predicted_world_from_sensor: (&matched.as_ref().map_or(pose, |m| m.predicted)).into(),
            heading_prior: matched
                .as_ref()
                .map_or(HeadingPrior::LastNode, |m| m.heading_prior),
            reference_nodes: links,
            cost: matched.as_ref().map(|m| m.cost),
            overlap_fraction: matched.as_ref().map(|m| m.diagnostics.overlap_fraction),
            inlier_fraction: matched.as_ref().map(|m| m.diagnostics.inlier_fraction),
            covariance: matched.as_ref().and_then(|m| m.diagnostics.covariance),
            trusted: matches!(
                status,
                StepStatus::Tracked | StepStatus::Recovered | StepStatus::Relocalized
            ),
            doubts,
            refinement: matched.as_ref().map(|m| m.refinement),
            loop_closures: closing.checked,
            optimization,
        })
    }

    /// Refuses a scan whose index does not follow the last one of the run.
    fn check_order(&self, scan: &ScanInput) -> Result<()> {
        match self.last_scan_index {
            Some(last) if scan.scan_index <= last => Err(Error::Invalid(format!(
                "scan {} comes after scan {last} of this run in the map; scans must be added in \
                 order",
                scan.scan_index
            ))),
            _ => Ok(()),
        }
    }

    /// The first scan defines the world: origin at its sensor, axes level, heading from its
    /// compass (DESIGN.md, "Units and frames"). It becomes node 0 as it is.
    fn add_first_scan(&mut self, scan: &ScanInput, start: Instant) -> Result<StepReport> {
        let attitude = scan.attitude.unwrap_or_default();
        let pose = pose_from_parts(Vec3::zeros(), attitude);
        self.add_node(scan, 0, pose, 0, None, &[])?;
        Ok(StepReport {
            scan_index: scan.scan_index,
            run: self.run,
            node_id: 0,
            status: StepStatus::First,
            recovery: None,
            segment: 0,
            attempts: Vec::new(),
            joined: Vec::new(),
            withdrawn_closures: Vec::new(),
            time_ms: ms(start),
            localize_ms: 0.0,
            loop_closure_ms: 0.0,
            map_update_ms: 0.0,
            world_from_sensor: (&pose).into(),
            predicted_world_from_sensor: (&pose).into(),
            heading_prior: HeadingPrior::First,
            reference_nodes: Vec::new(),
            cost: None,
            overlap_fraction: None,
            inlier_fraction: None,
            covariance: None,
            doubts: Vec::new(),
            trusted: true,
            refinement: None,
            loop_closures: Vec::new(),
            optimization: None,
        })
    }

    /// Adds the scan as node `node_id` of `segment` at `world_from_sensor`, with one edge from
    /// each of `links` (together they carry the match's information once), indexes it, fuses
    /// its points into the voxel map when it is in the world's segment, and makes it the
    /// robot's last stop.
    fn add_node(
        &mut self,
        scan: &ScanInput,
        node_id: usize,
        world_from_sensor: Pose,
        segment: usize,
        matched: Option<&Matched>,
        links: &[(usize, usize)],
    ) -> Result<()> {
        let mut node = Node::from_scan(
            node_id,
            scan.scan_index,
            world_from_sensor,
            scan.attitude,
            scan.points_in_sensor,
            &self.config.sdem,
        )?;
        node.segment = segment;
        node.run = self.run;
        let covariance = matched
            .and_then(|m| m.diagnostics.covariance)
            .map(|c| Matrix6::from_fn(|i, j| c[i][j]));
        let share = 1.0 / links.len().max(1) as f64;
        for &(r, _) in links {
            let world_from_r = self.map.nodes[r].world_from_sensor;
            self.edges.push(Edge {
                from: r,
                to: node_id,
                from_from_to: world_from_r.inverse() * world_from_sensor,
                information: self.edge_information(covariance.as_ref(), &world_from_sensor, share),
                kind: EdgeKind::Odometry,
            });
        }
        self.map.nodes.push(node);
        self.upkeep.node_added(&self.map, node_id)?;
        self.last_node = Some(node_id);
        self.last_scan_index = Some(scan.scan_index);
        Ok(())
    }

    /// Adds an accepted loop closure as a pose-graph edge.
    pub fn add_loop_closure_edge(&mut self, closure: &LoopClosure) {
        let (Some(from_from_to), true) = (closure.from_from_to, closure.accepted) else {
            return;
        };
        let world_from_to = self.map.nodes[closure.from].world_from_sensor * from_from_to;
        self.edges.push(Edge {
            from: closure.from,
            to: closure.to,
            from_from_to,
            information: self.edge_information(closure.covariance.as_ref(), &world_from_to, 1.0),
            kind: EdgeKind::LoopClosure,
        });
        self.loop_closures.push(closure.clone());
    }

    /// Optimizes the whole pose graph of every segment (each with its first node held) and
    /// moves the nodes; the fused map follows them in the steps to come, or at once with
    /// [`Slam::settle_map`]. Returns the summary of all: iterations, costs and free nodes added
    /// up, the largest move.
    ///
    /// # Errors
    /// The optimizer's errors (invalid edges).
    pub fn optimize_graph(&mut self) -> Result<OptimizationSummary> {
        let start = Instant::now();
        let mut total = OptimizationSummary {
            iterations: 0,
            initial_cost: 0.0,
            final_cost: 0.0,
            time_ms: 0.0,
            max_node_shift_m: 0.0,
            free_nodes: 0,
            whole_graph: true,
        };
        for segment in self.segments() {
            let s = self.optimize_segment(segment.id)?;
            total.iterations += s.iterations;
            total.initial_cost += s.initial_cost;
            total.final_cost += s.final_cost;
            total.max_node_shift_m = total.max_node_shift_m.max(s.max_node_shift_m);
            total.free_nodes += s.free_nodes;
        }
        total.time_ms = ms(start);
        Ok(total)
    }

    /// The information matrix of an edge ending at `world_from_to`, in the pose graph's residual
    /// convention (`[t, r]` in the `to` frame), from the match's covariance (world axes) plus the
    /// configured floor, times `share`.
    fn edge_information(
        &self,
        covariance_world: Option<&Matrix6<f64>>,
        world_from_to: &Pose,
        share: f64,
    ) -> [[f64; 6]; 6] {
        let floor_t = self.config.edge_sigma_floor_m.powi(2);
        let floor_r = self.config.edge_sigma_floor_deg.to_radians().powi(2);
        let to_from_world: Matrix3<f64> = world_from_to
            .rotation
            .inverse()
            .to_rotation_matrix()
            .into_inner();
        let mut rotate = Matrix6::zeros();
        rotate
            .fixed_view_mut::<3, 3>(0, 0)
            .copy_from(&to_from_world);
        rotate
            .fixed_view_mut::<3, 3>(3, 3)
            .copy_from(&to_from_world);
        let mut covariance = covariance_world
            .map(|c| rotate * c * rotate.transpose())
            .unwrap_or_else(Matrix6::zeros);
        for i in 0..3 {
            covariance[(i, i)] += floor_t;
            covariance[(i + 3, i + 3)] += floor_r;
        }
        let covariance = 0.5 * (covariance + covariance.transpose());
        let information = covariance.try_inverse().unwrap_or_else(|| {
            Matrix6::from_diagonal(&nalgebra::Vector6::new(
                1.0 / floor_t,
                1.0 / floor_t,
                1.0 / floor_t,
                1.0 / floor_r,
                1.0 / floor_r,
                1.0 / floor_r,
            ))
        }) * share;
        let information = 0.5 * (information + information.transpose());
        std::array::from_fn(|i| std::array::from_fn(|j| information[(i, j)]))
    }
}

fn ms(start: Instant) -> f64 {
    start.elapsed().as_secs_f64() * 1e3
}
