//! The global map (Nagatani et al. 2003, Sec. III: "a set of S-DEMs with their relative
//! locations"): nodes, reference selection, the merged virtual S-DEM, place descriptors and the
//! verification of loop closures.
//!
//! A [`Node`] keeps one scan as its S-DEM's surface points (one per direction cell: the mean of
//! the cell's returns on its nearest surface, [`Sdem::surface_points`]), in the sensor frame, and
//! its current `world_from_sensor` estimate; the pose graph moves the estimate, the points never
//! change. To localize a new scan the map is **merged** (the paper's future work): the points of
//! the nodes that overlap the prediction are carried into the world, re-centred on one origin
//! (the node that overlaps most) and binned into one S-DEM with world axes, nearest point per
//! cell ([`Map::merged_reference`]) — a virtual S-DEM of several nodes, so surfaces one node saw
//! and another did not are all there, and occlusion is kept by the z-buffer.
//!
//! Why the means and not the nearest returns (the paper's boundary points): where a cell holds
//! several returns (the tilting SICK's lines crowd together towards its sides), the nearest of
//! them lies in front of the surface by a fraction of the range noise, towards the sensor that
//! saw it, while the scan being localized is compared through its cells' means. After a turn
//! the pattern of those biased cells is turned against the query's, and it pulls the match round:
//! on the `wings` route each of the 10 steps that turn 18° came out 0.028° too far and 1.1 mm to
//! the right, and the ATE at 100 nodes was 2.41 cm; with the means, 0.002° and 0.03 mm, and
//! 0.42 cm (`docs/scale.md`).

use crate::error::{Error, Result};
use crate::geometry::{attitude_of, Attitude, Pose, Vec3};
use crate::localize::{localize, Localization, LocalizeOptions, SearchWindow};
use crate::sdem::{Sdem, SdemConfig};
use crate::search::HeadingWindow;
use nalgebra::{Isometry3, Matrix6, Translation3, UnitQuaternion};
use serde::{Deserialize, Serialize};

/// How far beyond half its cell a node's point may lie from a return of its scan for
/// [`Node::share_found_in_scan`], metres: the cell's returns average within 4 σ of the nearest
/// surface (2 cm at the SICK's 5 mm), and a curved surface's mean lies off it.
pub const SAME_SCAN_RANGE_M: f32 = 0.05;

/// One scan in the map.
#[derive(Debug, Clone, PartialEq)]
pub struct Node {
    /// Position in the map's node list.
    pub node_id: usize,
    /// Index of the scan in its dataset.
    pub scan_index: usize,
    /// The current estimate of the sensor's pose.
    pub world_from_sensor: Pose,
    /// The gyro/compass reading when the scan was taken, when there was one.
    pub attitude_reading: Option<Attitude>,
    /// The S-DEM's surface points (per known cell, the mean of its returns on the nearest
    /// surface), sensor frame, metres.
    pub points_in_sensor: Vec<[f32; 3]>,
    /// The map segment the node belongs to: the id of the segment's first node. Nodes of one
    /// segment are placed in one frame by their matches; segment 0 holds node 0 and is the
    /// world. A segment with another id is a piece of map whose place in the world is not known
    /// yet (a robot lost, kidnapped, or started at an unknown place): its poses are a guess
    /// until a confident match joins it to another segment ([`crate::slam`]).
    pub segment: usize,
    /// The run the scan came from: 0 for the run that started the map, 1 for the next run into
    /// the same map, and so on. Scan indices count within a run.
    pub run: usize,
}

impl Node {
    /// Makes a node from a raw scan: the scan is binned into an S-DEM levelled by
    /// `world_from_sensor`'s rotation and only its surface points are kept (one per cell, the
    /// mean of the cell's returns on its nearest surface: unbiased, where the nearest return
    /// lies in front of the surface; see the module's documentation).
    ///
    /// # Errors
    /// An invalid `sdem` configuration, or ([`Error::NoUsablePoints`], saying why) a scan with
    /// no usable point.
    pub fn from_scan(
        node_id: usize,
        scan_index: usize,
        world_from_sensor: Pose,
        attitude_reading: Option<Attitude>,
        points_in_sensor: &[Vec3],
        sdem: &SdemConfig,
    ) -> Result<Self> {
        let rotation = world_from_sensor.rotation.to_rotation_matrix();
        let levelled =
            Sdem::from_usable_points(points_in_sensor, &attitude_of(&world_from_sensor), sdem)
                .map_err(|e| e.of_scan(scan_index))?;
        let sensor_from_level = rotation.inverse();
        let points_in_sensor = levelled
            .surface_points()
            .iter()
            .map(|p| {
                let q = sensor_from_level * Vec3::new(p[0] as f64, p[1] as f64, p[2] as f64);
                [q.x as f32, q.y as f32, q.z as f32]
            })
            .collect();
        Ok(Self {
            node_id,
            scan_index,
            world_from_sensor,
            attitude_reading,
            points_in_sensor,
            segment: 0,
            run: 0,
        })
    }

    /// The share of this node's points that lie near a return of the scan `points_in_sensor`
    /// (sensor frame): 1 or nearly for the scan the node was made from, low for any other. It
    /// tells a dataset whose scan was replaced after mapping.
    ///
    /// A node's point is the mean of its S-DEM cell's returns on the nearest surface, so it lies
    /// among them: within half the cell's diagonal at its range (the grid `sdem`'s resolution)
    /// of one, plus [`SAME_SCAN_RANGE_M`] for the surface's curvature. Read against the raw
    /// returns, not against an S-DEM of the scan, the test does not depend on where the cells
    /// lie: a node whose pose a loop closure turned by half a cell (its points were binned on
    /// the grid levelled by its first pose) matches its scan all the same.
    ///
    /// # Errors
    /// An invalid `sdem` configuration.
    pub fn share_found_in_scan(&self, points_in_sensor: &[Vec3], sdem: &SdemConfig) -> Result<f64> {
        let half_diagonal =
            crate::sdem::GridSpec::new(sdem)?.resolution() * std::f64::consts::SQRT_2 / 2.0;
        let returns: Vec<[f64; 3]> = points_in_sensor
            .iter()
            .filter(|p| p.iter().all(|v| v.is_finite()))
            .map(|p| [p.x, p.y, p.z])
            .collect();
        if self.points_in_sensor.is_empty() || returns.is_empty() {
            return Ok(0.0);
        }
        let tree: kiddo::ImmutableKdTree<f64, 3> = kiddo::ImmutableKdTree::new_from_slice(&returns);
        let matching = (self.points_in_sensor.iter())
            .filter(|p| {
                let x = [p[0] as f64, p[1] as f64, p[2] as f64];
                let range = (x[0] * x[0] + x[1] * x[1] + x[2] * x[2]).sqrt();
                let reach = range * half_diagonal + SAME_SCAN_RANGE_M as f64;
                let found = tree.nearest_one::<kiddo::SquaredEuclidean>(&x);
                found.distance <= reach * reach
            })
            .count();
        Ok(matching as f64 / self.points_in_sensor.len() as f64)
    }

    /// The node's points in the sensor frame, as `f64` vectors.
    pub fn sensor_points(&self) -> Vec<Vec3> {
        self.points_in_sensor
            .iter()
            .map(|p| Vec3::new(p[0] as f64, p[1] as f64, p[2] as f64))
            .collect()
    }

    /// The node's points in the world frame.
    pub fn points_in_world(&self) -> Vec<Vec3> {
        self.points_in_sensor
            .iter()
            .map(|p| {
                self.world_from_sensor
                    * nalgebra::Point3::new(p[0] as f64, p[1] as f64, p[2] as f64)
            })
            .map(|p| p.coords)
            .collect()
    }

    /// The node's points rotated into world axes, relative to its sensor origin (its S-DEM
    /// levelled by the current estimate), f32.
    pub fn points_levelled(&self) -> Vec<[f32; 3]> {
        let r = self.world_from_sensor.rotation;
        self.points_in_sensor
            .iter()
            .map(|p| {
                let q = r * Vec3::new(p[0] as f64, p[1] as f64, p[2] as f64);
                [q.x as f32, q.y as f32, q.z as f32]
            })
            .collect()
    }

    /// The sensor origin in the world.
    pub fn position(&self) -> Vec3 {
        self.world_from_sensor.translation.vector
    }
}

/// A place descriptor: the mean range in each of [`SECTORS`] azimuth sectors × [`BANDS`]
/// elevation bands of the levelled sphere around a sensor (a coarse "what the place looks like
/// from here", in the spirit of Scan Context, on the S-DEM's own spherical grid and keeping the
/// elevation, which a rubble void is all about). Unknown cells are NaN.
///
/// Two descriptors are compared over the cells both saw and over every azimuth shift
/// ([`Descriptor::distance_any_heading`]), so a place is recognised whichever way the robot
/// faces; and since unknown cells do not count, a scanner that sees only its front half is
/// compared on that half. A map node's descriptor is best made from the node and its
/// neighbours together ([`Map::place_descriptor`]): they cover more of the sphere than one
/// scan, so a robot coming back facing the other way finds there what it sees.
#[derive(Debug, Clone, PartialEq, Serialize)]
pub struct Descriptor {
    /// Mean range per (band, sector), band-major, metres; NaN where nothing was seen.
    pub mean_range: Vec<f32>,
}

/// Azimuth sectors of a [`Descriptor`] (10° each).
pub const SECTORS: usize = 36;
/// Elevation bands of a [`Descriptor`] (20° each).
pub const BANDS: usize = 9;
/// Two descriptors are compared only over at least this many cells both saw.
pub const MIN_COMMON_CELLS: usize = 24;
/// A cell of a [`Descriptor`] is known when at least this many points fall in it.
const MIN_POINTS_PER_CELL: u32 = 3;

impl Descriptor {
    /// The descriptor of points in a levelled frame (world axes, origin at the sensor).
    pub fn from_levelled(points: &[[f32; 3]]) -> Self {
        let mut sum = vec![0.0f64; SECTORS * BANDS];
        let mut count = vec![0u32; SECTORS * BANDS];
        for p in points {
            let (x, y, z) = (p[0] as f64, p[1] as f64, p[2] as f64);
            let r = (x * x + y * y + z * z).sqrt();
            if !(r.is_finite() && r > 0.0) {
                continue;
            }
            let azimuth = y.atan2(x); // [-π, π]
            let elevation = (z / r).clamp(-1.0, 1.0).asin(); // [-π/2, π/2]
            let s = (((azimuth + std::f64::consts::PI) / std::f64::consts::TAU * SECTORS as f64)
                as usize)
                .min(SECTORS - 1);
            let b = (((elevation + std::f64::consts::FRAC_PI_2) / std::f64::consts::PI
                * BANDS as f64) as usize)
                .min(BANDS - 1);
            sum[b * SECTORS + s] += r;
            count[b * SECTORS + s] += 1;
        }
        let mean_range = sum
            .iter()
            .zip(&count)
            .map(|(&s, &c)| {
                if c >= MIN_POINTS_PER_CELL {
                    (s / c as f64) as f32
                } else {
                    f32::NAN
                }
            })
            .collect();
        Self { mean_range }
    }

    /// The cells this descriptor knows.
    pub fn known_cells(&self) -> usize {
        self.mean_range.iter().filter(|r| r.is_finite()).count()
    }

    /// Dissimilarity of two places: the mean absolute log-ratio of ranges over the cells both
    /// saw, minimized over azimuth shifts of up to `max_shift` sectors (a compass error); `None`
    /// when they share fewer than [`MIN_COMMON_CELLS`] cells at every shift.
    pub fn distance(&self, other: &Descriptor, max_shift: usize) -> Option<f64> {
        let shift_range = max_shift.min(SECTORS / 2) as isize;
        (-shift_range..=shift_range)
            .filter_map(|shift| self.distance_at(other, shift))
            .min_by(f64::total_cmp)
    }

    /// [`Self::distance`] over every azimuth shift: how unlike the two places are whichever way
    /// each sensor faced, and the heading to add to the yaw that levelled `self` for it to
    /// look like `other` (radians, a multiple of the sector's 10°). `None` when no shift
    /// leaves [`MIN_COMMON_CELLS`] cells in common.
    pub fn distance_any_heading(&self, other: &Descriptor) -> Option<(f64, f64)> {
        (0..SECTORS as isize)
            .filter_map(|shift| Some((self.distance_at(other, shift)?, shift)))
            .min_by(|a, b| a.0.total_cmp(&b.0))
            .map(|(d, shift)| {
                let heading = shift as f64 * std::f64::consts::TAU / SECTORS as f64;
                (d, crate::geometry::wrap_pi(heading))
            })
    }

    /// The dissimilarity with `other`'s sectors shifted by `shift`; `None` below
    /// [`MIN_COMMON_CELLS`] common cells.
    fn distance_at(&self, other: &Descriptor, shift: isize) -> Option<f64> {
        let (mut sum, mut n) = (0.0, 0usize);
        for b in 0..BANDS {
            for s in 0..SECTORS {
                let t = (s as isize + shift).rem_euclid(SECTORS as isize) as usize;
                let (ra, rb) = (
                    self.mean_range[b * SECTORS + s],
                    other.mean_range[b * SECTORS + t],
                );
                if ra.is_finite() && rb.is_finite() && ra > 0.0 && rb > 0.0 {
                    sum += (ra as f64 / rb as f64).ln().abs();
                    n += 1;
                }
            }
        }
        (n >= MIN_COMMON_CELLS).then(|| sum / n as f64)
    }
}

/// The nodes of the map, in the order they were added.
#[derive(Debug, Clone, Default, PartialEq)]
pub struct Map {
    /// The nodes; `nodes[i].node_id == i`.
    pub nodes: Vec<Node>,
}

impl Map {
    /// How many cells of the query S-DEM (levelled, origin at `origin`) each node's points land
    /// in within `tolerance_m` of the query's range: the nodes that see what the query sees.
    ///
    /// # Returns
    /// `(node_id, matching cells)` for the nodes whose origin lies within `radius_m` of
    /// `origin`, most overlapping first.
    pub fn overlaps(
        &self,
        query_levelled: &Sdem,
        origin: &Vec3,
        radius_m: f64,
        tolerance_m: f64,
    ) -> Vec<(usize, usize)> {
        self.overlaps_among(
            0..self.nodes.len(),
            query_levelled,
            origin,
            radius_m,
            tolerance_m,
        )
    }

    /// [`Map::overlaps`] among the nodes `node_ids` only (the recent ones, say): the work is
    /// theirs, not the map's.
    pub fn overlaps_among(
        &self,
        node_ids: impl IntoIterator<Item = usize>,
        query_levelled: &Sdem,
        origin: &Vec3,
        radius_m: f64,
        tolerance_m: f64,
    ) -> Vec<(usize, usize)> {
        let spec = query_levelled.grid();
        let ranges = query_levelled.ranges();
        let mut scored: Vec<(usize, usize)> = node_ids
            .into_iter()
            .filter_map(|id| self.nodes.get(id))
            .filter(|n| (n.position() - origin).norm() <= radius_m)
            .map(|n| {
                let mut seen = vec![false; ranges.len()];
                let mut matching = 0usize;
                // Binned a chunk at a time (`GridSpec::cells_of`: vectorized, the same cells
                // and ranges as `cell_of`): a LiDAR node holds 30,000 points or more.
                const CHUNK: usize = 1024;
                let (mut xs, mut ys, mut zs) = ([0f32; CHUNK], [0f32; CHUNK], [0f32; CHUNK]);
                let (mut cells, mut rs) = ([0u32; CHUNK], [0f32; CHUNK]);
                for chunk in n.points_in_world().chunks(CHUNK) {
                    let k = chunk.len();
                    for (i, p) in chunk.iter().enumerate() {
                        let q = p - origin;
                        (xs[i], ys[i], zs[i]) = (q.x as f32, q.y as f32, q.z as f32);
                    }
                    spec.cells_of(&xs[..k], &ys[..k], &zs[..k], &mut cells[..k], &mut rs[..k]);
                    for (&cell, &r) in cells[..k].iter().zip(&rs[..k]) {
                        if cell == u32::MAX {
                            continue;
                        }
                        let c = cell as usize;
                        let rq = ranges[c];
                        if !seen[c] && rq.is_finite() && (rq - r).abs() <= tolerance_m as f32 {
                            seen[c] = true;
                            matching += 1;
                        }
                    }
                }
                (n.node_id, matching)
            })
            .collect();
        scored.sort_by(|a, b| b.1.cmp(&a.1).then(a.0.cmp(&b.0)));
        scored
    }

    /// The merged virtual S-DEM of `node_ids` seen from `origin` (world frame), with world axes:
    /// every node's points carried into the world and binned around `origin`, nearest per cell
    /// (paper Sec. III-C's virtual S-DEM, over several nodes). Its level is as uncertain as the
    /// least certain of the nodes' attitude readings, and at least the default σ: a match that
    /// tilts a query against it is judged by what the readings allow
    /// ([`crate::Doubt::AttitudeCorrected`]).
    ///
    /// # Errors
    /// An unknown node id, or an invalid S-DEM configuration.
    pub fn merged_reference(
        &self,
        node_ids: &[usize],
        origin: &Vec3,
        sdem: &SdemConfig,
    ) -> Result<Sdem> {
        let mut points = Vec::new();
        for &id in node_ids {
            let node = self.nodes.get(id).ok_or_else(|| {
                Error::Invalid(format!(
                    "node {id} is not in the map ({} nodes)",
                    self.nodes.len()
                ))
            })?;
            points.extend(node.points_in_world().into_iter().map(|p| p - origin));
        }
        // A node's level in the map is its match's, not its reading's: the default σ at least,
        // more where a reading says its level is that uncertain.
        let mut level = Attitude::default();
        let readings = (node_ids.iter()).filter_map(|&id| self.nodes[id].attitude_reading.as_ref());
        for reading in readings {
            level.sigma.roll_pitch = level.sigma.roll_pitch.max(reading.sigma.roll_pitch);
            level.sigma.yaw = level.sigma.yaw.max(reading.sigma.yaw);
        }
        Sdem::from_points(&points, &level, sdem)
    }

    /// The nodes of node `node_id`'s segment whose origins lie within `radius_m` of its own,
    /// nearest first (the node itself first), at most `max_nodes`.
    pub fn nearby_in_segment(&self, node_id: usize, radius_m: f64, max_nodes: usize) -> Vec<usize> {
        let Some(node) = self.nodes.get(node_id) else {
            return Vec::new();
        };
        let mut near: Vec<(usize, f64)> = (self.nodes.iter())
            .filter(|n| n.segment == node.segment)
            .map(|n| (n.node_id, (n.position() - node.position()).norm()))
            .filter(|&(_, d)| d <= radius_m)
            .collect();
        near.sort_by(|a, b| a.1.total_cmp(&b.1).then(a.0.cmp(&b.0)));
        near.into_iter().take(max_nodes).map(|(id, _)| id).collect()
    }

    /// The place descriptor of node `node_id` ([`Descriptor`]): its points and those of the
    /// nearest nodes of its segment ([`Self::nearby_in_segment`] with `radius_m` and
    /// `max_nodes`), carried into the world and seen from its origin on world axes. `None` for
    /// an unknown node.
    pub fn place_descriptor(
        &self,
        node_id: usize,
        radius_m: f64,
        max_nodes: usize,
    ) -> Option<Descriptor> {
        let origin = self.nodes.get(node_id)?.position();
        let points: Vec<[f32; 3]> = (self.nearby_in_segment(node_id, radius_m, max_nodes))
            .into_iter()
            .flat_map(|id| self.nodes[id].points_in_world())
            .map(|p| {
                let q = p - origin;
                [q.x as f32, q.y as f32, q.z as f32]
            })
            .collect();
        Some(Descriptor::from_levelled(&points))
    }
}

/// Settings of loop-closure proposal and verification.
#[derive(Debug, Clone, PartialEq, Serialize, Deserialize)]
#[serde(default, deny_unknown_fields)]
pub struct LoopClosureConfig {
    /// Look for loop closures at all.
    pub enabled: bool,
    /// A revisit must be at least this many nodes back (nearer ones are the odometry chain).
    pub min_node_separation: usize,
    /// Candidates lie within this of the new node's estimated position, metres (a robot coming
    /// back the other way sees what nodes behind it saw).
    pub search_radius_m: f64,
    /// A candidate of the same segment must explain at least this many of the new scan's cells
    /// at its estimated pose ([`Map::overlaps_among`]), whichever way either scan faced.
    pub min_overlap_cells: usize,
    /// Candidates in another segment (placed nowhere yet) are proposed by their place
    /// descriptors ([`Map::place_descriptor`]), compared over every heading: within this
    /// dissimilarity (mean |ln r₁/r₂|).
    pub max_descriptor_distance: f64,
    /// At most this many candidates are verified per new node, most overlapping or most
    /// similar first.
    pub max_candidates: usize,
    /// The candidate's place is the candidate and up to this many nodes of its segment around
    /// it (within `reference_radius_m`), merged: a robot coming back the other way sees what
    /// the nodes behind the candidate saw.
    pub reference_nodes: usize,
    /// See `reference_nodes`, metres.
    pub reference_radius_m: f64,
    /// Half-size of the verification window around the predicted relative position, metres.
    pub window_half_m: [f64; 3],
    /// Heading searched around the predicted relative heading, ± degrees. Within a segment the
    /// pose graph knows which way the robot faced, however it turned, so the search covers the
    /// heading drift the map may hold (a match turned further is no closure:
    /// `max_heading_correction_deg`); across segments, where nothing is known, the loop
    /// searches every heading ([`crate::slam`]).
    pub heading_half_deg: f64,
    /// Grid step of the verification search, metres.
    pub step_m: f64,
    /// A closure is accepted only when at least this fraction of the query's cells match…
    pub min_inlier_fraction: f64,
    /// … or, for a scan that shares little with the place (a robot coming back the other way
    /// with a scanner that sees its front half), when at least this share of the cells both saw
    /// match…
    pub min_shared_inlier_fraction: f64,
    /// … and at least this many.
    pub min_shared_inliers: usize,
    /// … and it moves the node by no more than this from its current estimate, metres.
    pub max_correction_m: f64,
    /// … and turns it by no more than this, degrees.
    pub max_heading_correction_deg: f64,
    /// … and it agrees with the other closures it forms a loop with
    /// ([`crate::slam`]: pairwise consistency): a loop of transforms that does not return to
    /// where it began beyond this many standard deviations (χ with 6 degrees of freedom).
    pub max_loop_sigmas: f64,
}

impl LoopClosureConfig {
    /// Checks every distance, angle and share in its range (a negative `max_correction_m` or
    /// `search_radius_m` silently turned every closure off).
    ///
    /// # Errors
    /// [`Error::Invalid`] naming the first bad setting (`loop_closure.NAME`) and its range.
    pub fn validate(&self) -> Result<()> {
        let positive = [
            ("search_radius_m", self.search_radius_m),
            ("reference_radius_m", self.reference_radius_m),
            ("step_m", self.step_m),
            ("max_correction_m", self.max_correction_m),
            ("max_loop_sigmas", self.max_loop_sigmas),
        ];
        for (name, v) in positive {
            if !(v.is_finite() && v > 0.0) {
                return Err(Error::Invalid(format!(
                    "loop_closure.{name} = {v} must be a positive number"
                )));
            }
        }
        if !(self.max_descriptor_distance.is_finite() && self.max_descriptor_distance >= 0.0) {
            return Err(Error::Invalid(format!(
                "loop_closure.max_descriptor_distance = {} must be a number >= 0",
                self.max_descriptor_distance
            )));
        }
        for (name, v) in [
            ("heading_half_deg", self.heading_half_deg),
            (
                "max_heading_correction_deg",
                self.max_heading_correction_deg,
            ),
        ] {
            if !(v.is_finite() && (0.0..=180.0).contains(&v)) {
                return Err(Error::Invalid(format!(
                    "loop_closure.{name} = {v} must lie in 0..=180 degrees"
                )));
            }
        }
        for (name, v) in [
            ("min_inlier_fraction", self.min_inlier_fraction),
            (
                "min_shared_inlier_fraction",
                self.min_shared_inlier_fraction,
            ),
        ] {
            if !(0.0..=1.0).contains(&v) {
                return Err(Error::Invalid(format!(
                    "loop_closure.{name} = {v} must lie in 0..=1"
                )));
            }
        }
        if self
            .window_half_m
            .iter()
            .any(|h| !(h.is_finite() && *h >= 0.0))
        {
            return Err(Error::Invalid(format!(
                "loop_closure.window_half_m {:?} must hold finite numbers >= 0",
                self.window_half_m
            )));
        }
        Ok(())
    }
}

impl Default for LoopClosureConfig {
    fn default() -> Self {
        Self {
            enabled: true,
            min_node_separation: 10,
            search_radius_m: 3.0,
            min_overlap_cells: 300,
            max_descriptor_distance: 0.25,
            max_candidates: 2,
            reference_nodes: 3,
            reference_radius_m: 1.5,
            window_half_m: [0.3, 0.3, 0.1],
            heading_half_deg: 20.0,
            step_m: 0.02,
            min_inlier_fraction: 0.6,
            min_shared_inlier_fraction: 0.75,
            min_shared_inliers: 150,
            max_correction_m: 0.5,
            max_heading_correction_deg: 20.0,
            max_loop_sigmas: 5.0,
        }
    }
}

/// A checked loop-closure hypothesis.
#[derive(Debug, Clone, PartialEq, Serialize)]
pub struct LoopClosure {
    /// The earlier node.
    pub from: usize,
    /// The new node.
    pub to: usize,
    /// Descriptor dissimilarity that proposed it (`None` when proposed by overlap or by hand).
    pub descriptor_distance: Option<f64>,
    /// Accepted as a pose-graph edge.
    pub accepted: bool,
    /// Why it was rejected, in words (empty when accepted).
    pub reason: String,
    /// Cost of the match, m² (`None` when the search failed).
    pub cost: Option<f64>,
    /// Inlier fraction of the match.
    pub inlier_fraction: Option<f64>,
    /// How far the match moves the new node from its estimate, metres.
    pub correction_m: Option<f64>,
    /// How far the match turns the new node from its estimate, degrees.
    pub heading_correction_deg: Option<f64>,
    /// The measured `from_from_to` (KITTI row-major 3×4) when accepted.
    #[serde(skip)]
    pub from_from_to: Option<Pose>,
    /// Covariance of the match (`[x, y, z, roll, pitch, yaw]`, world axes), when accepted.
    #[serde(skip)]
    pub covariance: Option<Matrix6<f64>>,
}

impl LoopClosure {
    /// A closure from `from` to `to` not checked yet: not accepted, no figures.
    pub fn unchecked(from: usize, to: usize) -> Self {
        Self {
            from,
            to,
            descriptor_distance: None,
            accepted: false,
            reason: String::new(),
            cost: None,
            inlier_fraction: None,
            correction_m: None,
            heading_correction_deg: None,
            from_from_to: None,
            covariance: None,
        }
    }
}

/// Verifies that the scan of node `to`, placed at `world_from_to_prior`, sees the place of node
/// `from` (the node and its neighbours, `config.reference_nodes`): the exact search over a
/// window around the prior and `config.heading_half_deg` of heading, with the runner-up
/// search, then the match's diagnostics decide.
///
/// The result's `descriptor_distance` is `None`; the caller that proposed the closure by
/// descriptor fills it in.
///
/// Rejected when the search fails (nothing matches), the match is ambiguous (another place in
/// the window compares almost as well), the optimum lies on the window's edge, too few cells
/// match, or the correction (position or heading) is implausibly large.
pub fn verify_loop_closure(
    map: &Map,
    from: usize,
    to: usize,
    world_from_to_prior: &Pose,
    sdem: &SdemConfig,
    localize_base: &LocalizeOptions,
    config: &LoopClosureConfig,
) -> Result<LoopClosure> {
    if map.nodes.get(from).is_none() || map.nodes.get(to).is_none() {
        return Err(Error::Invalid(format!(
            "loop closure {from}→{to}: node not in the map ({} nodes)",
            map.nodes.len()
        )));
    }
    let place = map.nearby_in_segment(
        from,
        config.reference_radius_m,
        config.reference_nodes.max(1),
    );
    verify_loop_closure_against(
        map,
        &place,
        to,
        world_from_to_prior,
        sdem,
        localize_base,
        config,
    )
}

/// [`verify_loop_closure`] against the merged nodes `place` (the closure links the first one to
/// `to`, and the search's origin is its).
///
/// # Errors
/// A node not in the map, an empty `place`, or an invalid configuration.
pub fn verify_loop_closure_against(
    map: &Map,
    place: &[usize],
    to: usize,
    world_from_to_prior: &Pose,
    sdem: &SdemConfig,
    localize_base: &LocalizeOptions,
    config: &LoopClosureConfig,
) -> Result<LoopClosure> {
    let from = *place
        .first()
        .ok_or_else(|| Error::Invalid(format!("loop closure to {to}: no node to close it with")))?;
    let (Some(from_node), Some(to_node)) = (map.nodes.get(from), map.nodes.get(to)) else {
        return Err(Error::Invalid(format!(
            "loop closure {from}→{to}: node not in the map ({} nodes)",
            map.nodes.len()
        )));
    };
    let origin = from_node.position();
    let reference = map.merged_reference(place, &origin, sdem)?;
    let query = Sdem::from_points(
        &to_node.sensor_points(),
        &attitude_of(world_from_to_prior),
        sdem,
    )?;
    let prior_offset = world_from_to_prior.translation.vector - origin;
    let localize_config = LocalizeOptions {
        window: SearchWindow::around(&prior_offset, config.window_half_m),
        step_m: config.step_m,
        heading: HeadingWindow {
            half_range_deg: config.heading_half_deg,
            step_deg: None,
        },
        runner_up: true,
        ..localize_base.clone()
    };
    let mut closure = LoopClosure::unchecked(from, to);
    let found = match search_coarse_to_fine(
        &reference,
        &to_node.sensor_points(),
        &query,
        &localize_config,
        sdem,
    ) {
        Ok(found) => found,
        Err(e) if e.is_no_match() => {
            closure.reason = e.to_string();
            return Ok(closure);
        }
        Err(e) => return Err(e),
    };
    let world_from_to = world_from_query(&origin, &found);
    let correction =
        (world_from_to.translation.vector - world_from_to_prior.translation.vector).norm();
    let turn = crate::geometry::wrap_pi(
        attitude_of(&world_from_to).yaw - attitude_of(world_from_to_prior).yaw,
    )
    .abs()
    .to_degrees();
    closure.cost = Some(found.cost);
    closure.inlier_fraction = Some(found.diagnostics.inlier_fraction);
    closure.correction_m = Some(correction);
    closure.heading_correction_deg = Some(turn);
    closure.reason = rejection(&found, config, correction, turn).unwrap_or_default();
    if closure.reason.is_empty() {
        closure.accepted = true;
        closure.from_from_to = Some(from_node.world_from_sensor.inverse() * world_from_to);
        closure.covariance =
            (found.diagnostics.covariance).map(|c| Matrix6::from_fn(|i, j| c[i][j]));
    }
    Ok(closure)
}

/// A search whose grid step is finer than this, metres, runs on this grid first
/// (`search_coarse_to_fine`).
pub const COARSE_STEP_M: f64 = 0.05;
/// The fine search around a coarse optimum covers ± this, metres…
const FINE_HALF_M: f64 = 0.08;
/// … and ± this, degrees.
const FINE_HEADING_DEG: f64 = 3.0;

/// The exact search of `options` (window and heading around `query`'s levelling, runner-up
/// search as asked) in two passes: on a [`COARSE_STEP_M`] grid without refinement, then on
/// `options.step_m` within ±8 cm and ±3° of the coarse optimum (the query, `points_in_sensor`,
/// levelled again at its heading) with the refinement. A coarse runner-up is searched the same
/// way around it and stays a doubt only when it still compares almost as well (on a coarse
/// grid each cost lies above its basin's bottom by as much as the grid misses it). With a step
/// of [`COARSE_STEP_M`] or more, one pass.
///
/// # Errors
/// As [`localize`].
pub(crate) fn search_coarse_to_fine(
    reference: &Sdem,
    points_in_sensor: &[Vec3],
    query: &Sdem,
    options: &LocalizeOptions,
    sdem: &SdemConfig,
) -> Result<Localization> {
    if options.step_m >= COARSE_STEP_M {
        return localize(reference, query, options);
    }
    let coarse = localize(
        reference,
        query,
        &LocalizeOptions {
            step_m: COARSE_STEP_M,
            refine: false,
            ..options.clone()
        },
    )?;
    let level = query.attitude();
    let fine_at = |offset: Vec3, heading: f64| -> Result<Localization> {
        let turned = Attitude::new(level.roll, level.pitch, level.yaw + heading);
        let query = Sdem::from_points(points_in_sensor, &turned, sdem)?;
        let mut found = localize(
            reference,
            &query,
            &LocalizeOptions {
                window: SearchWindow::around(&offset, [FINE_HALF_M; 3]),
                heading: HeadingWindow {
                    half_range_deg: FINE_HEADING_DEG,
                    step_deg: None,
                },
                runner_up: false,
                ..options.clone()
            },
        )?;
        // The pose is the query's as levelled here: its heading correction is from the
        // coarse levelling.
        found.heading_correction += heading;
        Ok(found)
    };
    let mut found = fine_at(coarse.grid_offset, coarse.grid_heading)?;
    let d = &coarse.diagnostics;
    if let (Some(offset), Some(heading)) = (d.runner_up_offset, d.runner_up_heading_deg) {
        if d.runner_up_cost.is_some() {
            match fine_at(Vec3::from(offset), heading.to_radians()) {
                Ok(rival) => {
                    let apart = (rival.offset - found.offset).norm();
                    if apart > options.peak_radius_m
                        && rival.cost < options.ambiguous_cost_ratio * found.cost
                    {
                        found.doubts.push(crate::doubt::Doubt::RunnerUp {
                            distance_m: apart,
                            cost: rival.cost,
                            best_cost: found.cost,
                        });
                        found.diagnostics.ambiguous = true;
                        found.trusted = false;
                    }
                }
                Err(e) if e.is_no_match() => {}
                Err(e) => return Err(e),
            }
        }
    }
    found
        .doubts
        .extend((coarse.doubts.into_iter()).filter(|d| d.is_other_rotation()));
    Ok(found)
}

/// Why a loop closure's match is rejected, in words; `None` when it is accepted.
fn rejection(
    found: &Localization,
    config: &LoopClosureConfig,
    correction: f64,
    turn_deg: f64,
) -> Option<String> {
    let d = &found.diagnostics;
    // A scan that shares little with the place, but that little with confidence.
    let shared = d.shared_inlier_fraction();
    let partial = shared >= config.min_shared_inlier_fraction
        && (shared * found.overlap as f64).round() as usize >= config.min_shared_inliers;
    let why: Vec<String> = (found.doubts.iter())
        .filter(|d| d.is_ambiguity())
        .filter(|d| !(partial && matches!(d, crate::doubt::Doubt::FewInliers { .. })))
        .map(ToString::to_string)
        .collect();
    Some(if !why.is_empty() {
        format!("ambiguous: {}", why.join("; "))
    } else if found.on_window_edge {
        "the best match lies on the search window's edge".into()
    } else if d.inlier_fraction < config.min_inlier_fraction && !partial {
        format!(
            "only {:.0} % of the cells match (need {:.0} %, or {:.0} % of {} cells both saw)",
            d.inlier_fraction * 100.0,
            config.min_inlier_fraction * 100.0,
            config.min_shared_inlier_fraction * 100.0,
            config.min_shared_inliers
        )
    } else if correction > config.max_correction_m {
        format!(
            "it would move the node {:.2} m (at most {:.2} m)",
            correction, config.max_correction_m
        )
    } else if turn_deg > config.max_heading_correction_deg {
        format!(
            "it would turn the node {turn_deg:.1}° (at most {:.1}°)",
            config.max_heading_correction_deg
        )
    } else if d.covariance.is_none() {
        "the 6-DoF refinement failed, no covariance".into()
    } else {
        return None;
    })
}

/// The query's `world_from_sensor` from a localization against a reference S-DEM with world axes
/// centred on `origin`.
pub fn world_from_query(origin: &Vec3, found: &Localization) -> Pose {
    Isometry3::from_parts(Translation3::from(*origin), UnitQuaternion::identity())
        * found.reference_from_query
}

#[cfg(test)]
mod tests {
    use super::*;
    use crate::geometry::{Attitude, AttitudeSigma};

    /// The merged reference is as uncertain in level as the least certain of its nodes'
    /// readings, so that a match that tilts a query against it is judged by the σ a user gave
    /// (`attitude.csv`'s columns, `--attitude-sigma-deg`), never below the default.
    #[test]
    fn the_merged_reference_carries_its_readings_sigma() {
        let points: Vec<Vec3> = (0..2000)
            .map(|i| {
                let (a, e) = ((i % 100) as f64 * 0.06, (i / 100) as f64 * 0.05 - 0.5);
                Vec3::new(a.cos() * e.cos(), a.sin() * e.cos(), e.sin()) * 3.0
            })
            .collect();
        let grid = SdemConfig::default();
        let reading = |deg: Option<f64>| {
            deg.map(|d| Attitude {
                sigma: AttitudeSigma {
                    roll_pitch: d.to_radians(),
                    yaw: 20f64.to_radians(),
                },
                ..Attitude::default()
            })
        };
        let node = |id, deg| {
            Node::from_scan(id, id, Pose::identity(), reading(deg), &points, &grid).unwrap()
        };
        let map = Map {
            nodes: vec![node(0, Some(1.0)), node(1, Some(0.2)), node(2, None)],
        };
        let sigma = |ids: &[usize]| {
            let merged = map.merged_reference(ids, &Vec3::zeros(), &grid).unwrap();
            (merged.attitude().sigma.roll_pitch.to_degrees() * 1e6).round() / 1e6
        };
        assert_eq!(sigma(&[0, 1]), 1.0);
        // Never below the default: a node's level in the map is its match's.
        assert_eq!(sigma(&[1, 2]), 0.5);
        assert_eq!(sigma(&[2]), 0.5);
    }
}
