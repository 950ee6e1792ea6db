//! The stop-and-go loop (Nagatani et al. 2003, Sec. III, Fig. 2): move, sense, build the local
//! S-DEM, compare it with the global map, localize, add it to the map, repeat — with what the
//! paper left open: merging (the merged virtual S-DEM, [`crate::map`], and the occupancy voxel
//! map, [`crate::voxel`]), and loop closure over a robust pose graph ([`crate::posegraph`]).
//!
//! [`Slam::add_scan`] takes one scan at a time as plain values (points, attitude reading,
//! odometry), so the same loop runs on a dataset folder, a saved map being resumed, or a robot.
//!
//! Per scan:
//! 1. **Predict** the pose: the last node's pose times the odometry's relative motion when there
//!    is odometry, else times the last motion (constant velocity); roll and pitch from the gyro
//!    reading when there is one; heading from the odometry, else the compass, else the last
//!    motion — and the search window widens with the weaker prior.
//! 2. **Pick reference nodes** among the recent ones (the local map) by position and overlap:
//!    how many of the new scan's cells each node's points land on.
//! 3. **Localize** with the exact search against their merged virtual S-DEM (seen from the
//!    origin of the node that overlaps most), then the 6-DoF refinement; the match's covariance
//!    weighs the new pose-graph edges.
//! 4. **Loop closure**: older nodes near the new one whose place descriptor is similar are
//!    verified with the exact search; an accepted closure becomes an edge and the pose graph is
//!    optimized (robust Cauchy kernel) over the part of it the closure touches; the nodes that
//!    moved are fused again into the voxel map, a few per stop.
//!
//! As the map grows the work per stop stays bounded (`upkeep`): candidates come from an index
//! of node positions and descriptors, not from every node; the fused map takes a moved node's
//! scan out and puts it back instead of fusing every scan again; and with a node store
//! attached, the nodes far from the robot keep their points there.

//!
//! The module's files: this one holds the configuration and the loop, `relocalize` finding a scan
//! in a saved map, `trajectory` the errors of an estimated trajectory against a reference one,
//! `upkeep` what keeps the work per stop and the memory bounded as the map grows.

mod options;
mod relocalize;
mod step;
mod trajectory;
mod upkeep;

pub use options::SlamOptions;
pub use relocalize::{relocalize, Near, Relocalization};
pub use step::{HeadingPrior, OptimizationSummary, Step, StepReport, StepStatus};
pub use trajectory::{trajectory_errors, TrajectoryErrors};
pub use upkeep::GrowthOptions;

use crate::doubt::Doubt;
use crate::error::{Error, Result};
use crate::geometry::{attitude_of, pose_from_parts, Attitude, Pose, Vec3};
use crate::localize::{
    localize, CostConfig, Diagnostics, LocalizeOptions, OffsetPrior, RefinementSummary,
    SearchWindow,
};
use crate::map::{verify_loop_closure, world_from_query, LoopClosure, Map, Node};
use crate::posegraph::{optimize, Edge, EdgeKind, PoseGraph};
use crate::sdem::Sdem;
use crate::search::HeadingWindow;
use crate::store::NodeStore;
use crate::voxel::VoxelMap;
use nalgebra::{Matrix3, Matrix6};
use relocalize::take_prediction_along;
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
    /// The node index, the fused occupancy map and the nodes' residency.
    upkeep: Upkeep,
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
            last_odom_from_sensor: None,
            next_scan_index: 0,
        })
    }

    /// Restores a loop from saved nodes and edges (a resumed run); the voxel map is rebuilt.
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
        let mut slam = Self::new(config)?;
        slam.map = map;
        slam.edges = edges;
        slam.loop_closures = loop_closures;
        slam.next_scan_index = slam.map.nodes.last().map_or(0, |node| node.scan_index + 1);
        slam.rebuild_voxels()?;
        Ok(slam)
    }

    /// The configuration.
    pub fn config(&self) -> &SlamOptions {
        &self.config
    }

    /// Adds the next stop's scan: predicts its pose, localizes it against the map, adds it as
    /// a node, closes loops and updates the fused map: the loop `sdem slam` runs, one stop at a
    /// time.
    ///
    /// # Arguments
    /// * `points_in_sensor` — the scan, sensor frame, metres (NaN points are skipped).
    /// * `attitude` — the gyro/compass reading at the stop, or `None` without one.
    /// * `odom_from_sensor` — the odometry frame's pose of the sensor at the stop (as ROS's
    ///   `/odom` gives it), or `None` without odometry. Only its motion since the last call
    ///   that gave one is used.
    ///
    /// # Returns
    /// The [`Step`]: the sensor's pose in the world, the match's status and its report.
    ///
    /// # Errors
    /// Invalid input (see [`crate::Scan::from_points`]), or a scan that matches nothing in the
    /// map ([`Error::is_no_match`]): the map is then unchanged.
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
    pub fn add(
        &mut self,
        points_in_sensor: &[nalgebra::Point3<f64>],
        attitude: Option<Attitude>,
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
        let status = if report.reference_nodes.is_empty() {
            StepStatus::First
        } else if report.trusted {
            StepStatus::Tracked
        } else {
            StepStatus::Doubtful
        };
        Ok(Step {
            world_from_sensor: self.map.nodes[report.node_id].world_from_sensor,
            status,
            report,
        })
    }

    /// The pose in the world, `world_from_sensor`, of every node's sensor, in the order the
    /// scans were added, as the last loop closure left them.
    pub fn poses(&self) -> Vec<Pose> {
        self.map.nodes.iter().map(|n| n.world_from_sensor).collect()
    }

    /// Indexes and fuses every node afresh, on the current poses.
    ///
    /// # Errors
    /// [`Error::NodeStore`] when a parked node's points cannot be read back.
    pub fn rebuild_voxels(&mut self) -> Result<()> {
        self.upkeep.rebuild(&mut self.map)
    }

    /// The fused occupancy map: every node's scan, each at the pose it was fused at, which
    /// lies within [`GrowthOptions::refuse_tolerance_m`] and `refuse_tolerance_deg` of its
    /// current one once [`Slam::settle_map`] has run (after a loop closure, the moved nodes
    /// are fused again a few per stop).
    pub fn voxels(&self) -> VoxelMap {
        self.upkeep.fusion.to_voxel_map()
    }

    /// Fuses again every node a solve moved beyond the tolerances, so that [`Slam::voxels`]
    /// and [`Slam::merged_cloud`] show the map on the current poses.
    ///
    /// # Returns
    /// The nodes fused again.
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
    /// old place, a moved node fused again).
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

    /// The merged point cloud: every node's points in the world, kept where the fused map is
    /// occupied now (moved rubble, seen through later, drops out), one per voxel. Parked nodes
    /// are read back one at a time.
    ///
    /// # Errors
    /// [`Error::NodeStore`] when a parked node's points cannot be read back.
    pub fn merged_cloud(&self) -> Result<Vec<Vec3>> {
        let voxels = self.voxels();
        let mut merged = voxels.occupied_centroids();
        for node in &self.map.nodes {
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
    /// An empty scan; a scan index that does not follow the last one; no reference node that
    /// sees the scan; a localization that fails (nothing matches within the window) — the map is
    /// unchanged by these. An invalid loop-closure or optimizer setting fails after the node was
    /// added (the node stays, localized).
    pub fn add_scan(&mut self, scan: &ScanInput) -> Result<StepReport> {
        let start = Instant::now();
        let node_id = self.map.nodes.len();
        let Some(last) = self.map.nodes.last() else {
            return self.add_first_scan(scan, start);
        };
        if scan.scan_index <= last.scan_index {
            return Err(Error::Invalid(format!(
                "scan {} comes after scan {} in the map; scans must be added in order",
                scan.scan_index, last.scan_index
            )));
        }

        // 1. Predict.
        let prediction = self.predict(scan, last.world_from_sensor, node_id);
        let recent = self.recent_nodes(node_id);
        self.upkeep.bring(&mut self.map, &recent)?;

        // 2. Reference nodes: recent nodes (the local map) that see what the scan sees.
        let query = Sdem::from_points(
            scan.points_in_sensor,
            &prediction.attitude,
            &self.config.sdem,
        )?;
        if query.known_cells() == 0 {
            return Err(Error::Invalid(format!(
                "scan {} has no usable point (all closer than {} m or not finite)",
                scan.scan_index, self.config.sdem.min_range_m
            )));
        }
        let references = self.reference_nodes(&query, &prediction.position, node_id);
        let reference_ids: Vec<usize> = references.iter().map(|r| r.0).collect();

        // 3. Localize, and add the node with one edge per reference node.
        let matched = self.match_scan(scan, &query, &prediction, &reference_ids)?;
        self.add_node(scan, node_id, &matched, &reference_ids)?;

        // 4. Loop closure.
        let closure_start = Instant::now();
        let (closures, optimization) = self.close_loops_and_optimize(node_id)?;
        let loop_closure_ms = ms(closure_start);
        let map_start = Instant::now();
        let keep = self.config.loop_closure.min_node_separation + 1;
        self.upkeep.after_step(&mut self.map, keep, false)?;
        let map_update_ms = ms(map_start);

        let pose = self.map.nodes[node_id].world_from_sensor;
        let Matched {
            cost,
            refinement,
            diagnostics,
            doubts,
            localize_ms,
            ..
        } = matched;
        Ok(StepReport {
            scan_index: scan.scan_index,
            node_id,
            time_ms: ms(start),
            localize_ms,
            loop_closure_ms,
            map_update_ms,
            world_from_sensor: (&pose).into(),
            predicted_world_from_sensor: (&prediction.predicted).into(),
            heading_prior: prediction.heading_prior,
            reference_nodes: references,
            cost: Some(cost),
            overlap_fraction: Some(diagnostics.overlap_fraction),
            inlier_fraction: Some(diagnostics.inlier_fraction),
            covariance: diagnostics.covariance,
            trusted: doubts.is_empty(),
            doubts,
            refinement: Some(refinement),
            loop_closures: closures,
            optimization,
        })
    }

    /// The first scan defines the world: origin at its sensor, axes level, heading from its
    /// compass (DESIGN.md, "Units and frames"). It becomes node 0 as it is.
    fn add_first_scan(&mut self, scan: &ScanInput, start: Instant) -> Result<StepReport> {
        let node_id = self.map.nodes.len();
        let attitude = scan.attitude.unwrap_or_default();
        let world_from_sensor = pose_from_parts(Vec3::zeros(), attitude);
        let node = Node::from_scan(
            node_id,
            scan.scan_index,
            world_from_sensor,
            scan.attitude,
            scan.points_in_sensor,
            &self.config.sdem,
        )?;
        self.map.nodes.push(node);
        self.upkeep.node_added(&self.map, node_id)?;
        let pose = world_from_sensor;
        Ok(StepReport {
            scan_index: scan.scan_index,
            node_id,
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

    /// Step 1: the scan's predicted pose from the last node's, `last_pose`, and the search's
    /// window and prior around it, wider with a weaker prior.
    fn predict(&self, scan: &ScanInput, last_pose: Pose, node_id: usize) -> Prediction {
        let last_attitude = attitude_of(&last_pose);
        // Without odometry the robot is assumed to repeat its last motion (a constant-velocity
        // model, as KISS-ICP does), or to stand still after the first scan.
        let before_last = node_id
            .checked_sub(2)
            .map(|i| self.map.nodes[i].world_from_sensor);
        let (motion, motion_prior) = match (&scan.odometry, before_last) {
            (Some(odometry), _) => (
                Some(odometry.previous_sensor_from_sensor()),
                HeadingPrior::Odometry,
            ),
            (None, Some(before)) => (
                Some(before.inverse() * last_pose),
                HeadingPrior::ConstantVelocity,
            ),
            (None, None) => (None, HeadingPrior::LastNode),
        };
        let predicted_motion = motion.map(|m| last_pose * m);
        let position =
            predicted_motion.map_or(last_pose.translation.vector, |p| p.translation.vector);
        let (yaw, heading_prior, heading_half) = match (scan.odometry.is_some(), scan.attitude) {
            (true, _) => (
                predicted_motion.map_or(last_attitude.yaw, |p| attitude_of(&p).yaw),
                HeadingPrior::Odometry,
                self.config.heading_half_deg,
            ),
            (false, Some(a)) => (
                a.yaw,
                HeadingPrior::Compass,
                self.config.heading_half_compass_deg,
            ),
            (false, None) => (
                predicted_motion.map_or(last_attitude.yaw, |p| attitude_of(&p).yaw),
                motion_prior,
                self.config.heading_half_no_prior_deg,
            ),
        };
        let (roll, pitch) = match scan.attitude {
            Some(a) => (a.roll, a.pitch),
            None => (last_attitude.roll, last_attitude.pitch),
        };
        let attitude = Attitude::new(roll, pitch, yaw);
        let predicted = pose_from_parts(position, attitude);
        let (window_half, prior_sigma_m) = if scan.odometry.is_some() {
            (self.config.window_half_m, self.config.prior_sigma_m)
        } else {
            (
                self.config.window_half_no_odometry_m,
                self.config.prior_sigma_no_odometry_m,
            )
        };
        Prediction {
            has_motion: motion.is_some(),
            position,
            attitude,
            predicted,
            heading_prior,
            heading_half,
            window_half,
            prior_sigma_m,
        }
    }

    /// The recent nodes, among which step 2 picks the references: the last
    /// `min_node_separation` (older ones are loop closures' to find).
    fn recent_nodes(&self, node_id: usize) -> Vec<usize> {
        let recent_from = node_id.saturating_sub(self.config.loop_closure.min_node_separation);
        (recent_from..node_id).collect()
    }

    /// Step 2: the recent nodes near `position` that overlap `query` enough, most overlap first,
    /// with the cells they overlap; the last node when none does (the search then says why).
    fn reference_nodes(
        &self,
        query: &Sdem,
        position: &Vec3,
        node_id: usize,
    ) -> Vec<(usize, usize)> {
        let mut references: Vec<(usize, usize)> = self
            .map
            .overlaps_among(
                self.recent_nodes(node_id),
                query,
                position,
                self.config.reference_radius_m,
                0.2,
            )
            .into_iter()
            .filter(|&(_, cells)| cells >= self.config.min_reference_overlap_cells)
            .take(self.config.max_reference_nodes)
            .collect();
        if references.is_empty() {
            // The last node always takes part: with no overlap the search says why.
            references.push((node_id - 1, 0));
        }
        references
    }

    /// Step 3: localizes `query` against the merged virtual S-DEM of `reference_ids`, seen from
    /// the origin of the node that overlaps most: its own points keep their full density there,
    /// and the other nodes fill in what it did not see. (Seen from the predicted origin instead,
    /// a node's points spread apart and leave holes: on the 3DTK scans, 1.6 m apart, a quarter
    /// of the query's cells found a reference cell instead of all of them.)
    fn match_scan(
        &self,
        scan: &ScanInput,
        query: &Sdem,
        prediction: &Prediction,
        reference_ids: &[usize],
    ) -> Result<Matched> {
        let position = prediction.position;
        let origin = self.map.nodes[reference_ids[0]].position();
        let reference = self
            .map
            .merged_reference(reference_ids, &origin, &self.config.sdem)?;
        let localize_config = LocalizeOptions {
            window: SearchWindow::around(&(position - origin), prediction.window_half),
            heading: HeadingWindow {
                half_range_deg: prediction.heading_half,
                step_deg: None,
            },
            cost: CostConfig {
                prior: Some(OffsetPrior {
                    offset: (position - origin).into(),
                    sigma_m: prediction.prior_sigma_m,
                }),
                ..self.config.localize.cost.clone()
            },
            ..self.config.localize.clone()
        };
        let localize_start = Instant::now();
        let found = localize(&reference, query, &localize_config).map_err(|e| {
            if e.is_no_match() {
                Error::AtScan {
                    scan_index: scan.scan_index,
                    nodes: reference_ids.to_vec(),
                    source: Box::new(e),
                }
            } else {
                e
            }
        })?;
        let localize_ms = ms(localize_start);
        let mut world_from_sensor = world_from_query(&origin, &found);
        let refinement = RefinementSummary::new(found.refined, found.refinement.as_ref());
        let mut diagnostics = found.diagnostics;
        let mut doubts = found.doubts;
        // Along a direction the scans leave free (a ditch's or a corridor's axis), the match's
        // position is the scans' sampling pattern, not the scene: it pulls towards the
        // reference's own origin (a forward-looking scan in a straight corridor came out 20 %
        // short at every step). There the prediction decides, and the edge carries the
        // prediction's uncertainty.
        if prediction.has_motion {
            take_prediction_along(
                &mut world_from_sensor,
                &mut diagnostics,
                &mut doubts,
                &position,
                prediction.prior_sigma_m,
            );
        }
        Ok(Matched {
            world_from_sensor,
            cost: found.cost,
            refinement,
            diagnostics,
            doubts,
            localize_ms,
        })
    }

    /// Adds the matched scan as node `node_id`, with one edge from each reference node (together
    /// they carry the match's information once), and fuses its points into the voxel map.
    fn add_node(
        &mut self,
        scan: &ScanInput,
        node_id: usize,
        matched: &Matched,
        reference_ids: &[usize],
    ) -> Result<()> {
        let world_from_sensor = matched.world_from_sensor;
        let covariance = matched
            .diagnostics
            .covariance
            .map(|c| Matrix6::from_fn(|i, j| c[i][j]));
        let node = Node::from_scan(
            node_id,
            scan.scan_index,
            world_from_sensor,
            scan.attitude,
            scan.points_in_sensor,
            &self.config.sdem,
        )?;
        // One edge per reference node; together they carry the match's information once.
        let share = 1.0 / reference_ids.len() as f64;
        for &r in reference_ids {
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
        self.upkeep.node_added(&self.map, node_id)
    }

    /// Step 4, when loop closure is enabled: closes loops to node `node_id` and, when one was
    /// accepted, optimizes the pose graph.
    fn close_loops_and_optimize(
        &mut self,
        node_id: usize,
    ) -> Result<(Vec<LoopClosure>, Option<OptimizationSummary>)> {
        let mut closures = Vec::new();
        let mut optimization = None;
        if self.config.loop_closure.enabled {
            let anchored = self.upkeep.last_closure();
            closures = self.close_loops(node_id)?;
            let oldest = (closures.iter())
                .filter(|c| c.accepted)
                .map(|c| c.from.min(c.to))
                .min();
            if let Some(oldest) = oldest {
                optimization = Some(self.solve_after_closure(oldest, anchored)?);
            }
        }
        Ok((closures, optimization))
    }

    /// Proposes revisits of older places for node `to` and verifies them; accepted ones become
    /// pose-graph edges.
    fn close_loops(&mut self, to: usize) -> Result<Vec<LoopClosure>> {
        let candidates = self
            .upkeep
            .closure_candidates(&self.map, to, &self.config.loop_closure);
        let mut checked = Vec::new();
        for (from, distance) in candidates {
            self.upkeep.bring(&mut self.map, &[from, to])?;
            let prior = self.map.nodes[to].world_from_sensor;
            let mut closure = verify_loop_closure(
                &self.map,
                from,
                to,
                &prior,
                &self.config.sdem,
                &self.config.localize,
                &self.config.loop_closure,
            )?;
            closure.descriptor_distance = Some(distance);
            if closure.accepted {
                self.add_loop_closure_edge(&closure);
                self.upkeep.closure_accepted(to);
            }
            checked.push(closure);
        }
        Ok(checked)
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

    /// Solves the pose graph after loop closures whose oldest node is `oldest` (the last
    /// closure before them accepted at node `anchored`): over the part of the graph that
    /// drifted since, grown as far as the edges ask, the whole graph when it reaches that far
    /// (see [`crate::posegraph::optimize_local`]); the moved nodes are fused again in the
    /// steps to come.
    fn solve_after_closure(
        &mut self,
        oldest: usize,
        anchored: Option<usize>,
    ) -> Result<OptimizationSummary> {
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

    /// Optimizes the whole pose graph (node 0 held) and moves the nodes; the fused map follows
    /// them in the steps to come, or at once with [`Slam::settle_map`].
    ///
    /// # Errors
    /// The optimizer's errors (invalid edges).
    pub fn optimize_graph(&mut self) -> Result<OptimizationSummary> {
        let start = Instant::now();
        let graph = PoseGraph {
            world_from_node: self.poses(),
            edges: self.edges.clone(),
        };
        let (poses, report) = optimize(&graph, 0, &self.config.optimize)?;
        let mut max_shift: f64 = 0.0;
        for (node, pose) in self.map.nodes.iter_mut().zip(poses) {
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
            free_nodes: self.map.nodes.len().saturating_sub(1),
            whole_graph: true,
        })
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

/// Where a scan is expected before it is matched (step 1 of [`Slam::add_scan`]), and the
/// search's window and prior around it.
struct Prediction {
    /// Whether the prediction moved the last pose (odometry or the last motion): then the
    /// prediction decides along a direction the match leaves free.
    has_motion: bool,
    /// The predicted position, world frame.
    position: Vec3,
    /// The predicted attitude, and the pose of both.
    attitude: Attitude,
    predicted: Pose,
    /// Where the heading came from, and the heading window's half-width, degrees.
    heading_prior: HeadingPrior,
    heading_half: f64,
    /// The translation window's half-size and the prior's σ, metres.
    window_half: [f64; 3],
    prior_sigma_m: f64,
}

/// A scan's match against its reference nodes (step 3 of [`Slam::add_scan`]).
struct Matched {
    /// The sensor's pose in the world (the prediction's position along a free direction).
    world_from_sensor: Pose,
    /// The match's cost, refinement, diagnostics and doubts, for the report.
    cost: f64,
    refinement: RefinementSummary,
    diagnostics: Diagnostics,
    doubts: Vec<Doubt>,
    /// Wall time of the localization, ms.
    localize_ms: f64,
}

fn ms(start: Instant) -> f64 {
    start.elapsed().as_secs_f64() * 1e3
}
