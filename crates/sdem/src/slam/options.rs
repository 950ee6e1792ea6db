//! The loop's options, with their defaults: written beside every result as `config.toml`.

use crate::error::{Error, Result};
use crate::localize::LocalizeOptions;
use crate::map::LoopClosureConfig;
use crate::posegraph::OptimizeConfig;
use crate::sdem::SdemConfig;
use crate::voxel::VoxelConfig;
use serde::{Deserialize, Serialize};

/// Everything the loop needs; written beside the results as `config.toml`.
#[derive(Debug, Clone, PartialEq, Serialize, Deserialize)]
#[serde(default, deny_unknown_fields)]
pub struct SlamOptions {
    /// The S-DEM grid.
    pub sdem: SdemConfig,
    /// The search and refinement (the window and heading are set per scan from the fields below).
    pub localize: LocalizeOptions,
    /// Half-size of the window around an odometry prediction, metres.
    pub window_half_m: [f64; 3],
    /// Half-size of the window when there is no odometry (the robot may have moved anywhere
    /// nearby), metres.
    pub window_half_no_odometry_m: [f64; 3],
    /// Standard deviation of an odometry prediction, metres, weighed into the match as
    /// [`crate::cost::OffsetPrior`] (it decides only what the scans leave open, such as the
    /// position along a featureless ditch).
    pub prior_sigma_m: f64,
    /// The odometry's error grows with the distance it measured: its window's half-sizes
    /// (the height's too: a step over rubble climbs more or less than the odometry says) are at
    /// least twice this share of the distance driven since the last stop,
    /// and the variance its position carries along a direction the scans leave free at least
    /// this share squared (a crawler's tracks slip by 10–15 % on rubble, and a step of 1.5 m
    /// is 20 cm off then). The cost's prior keeps `prior_sigma_m`.
    pub odometry_error_per_m: f64,
    /// Standard deviation of the prediction without odometry (the last motion repeated), metres.
    pub prior_sigma_no_odometry_m: f64,
    /// Heading searched around an odometry prediction, ± degrees.
    pub heading_half_deg: f64,
    /// Heading searched around a compass reading when there is no odometry, ± degrees.
    pub heading_half_compass_deg: f64,
    /// Heading searched around the last node's heading with neither, ± degrees.
    pub heading_half_no_prior_deg: f64,
    /// Reference nodes lie within this of the predicted position, metres.
    pub reference_radius_m: f64,
    /// At most this many reference nodes are merged.
    pub max_reference_nodes: usize,
    /// A node is a reference only when at least this many of the new scan's cells see it.
    pub min_reference_overlap_cells: usize,
    /// A match from a prediction against the recent nodes is taken at once only when at least
    /// this fraction of the scan's points match: that search looks for no runner-up, and a
    /// wrong optimum inside a small window (the robot drove beyond it) matched 34 % on a
    /// simulated 1 m step where right ones match 50–90 %. Below, the scan is searched again,
    /// wider and against more nodes, with the runner-up search.
    pub min_tracking_inlier_fraction: f64,
    /// A match from the no-motion prediction (a step without odometry and without a motion
    /// before it to repeat: the second scan of a run or segment) is taken only after the
    /// runner-up search finds no rival basin, never from the quick search. A LiDAR's rings draw
    /// the same circles on a flat road wherever the vehicle stands: a simulated 16-beam
    /// scanner's second frame, 0.8 m on, matched 56 % of its cells where the first stood and
    /// was taken there, with the next one after it. [`Self::for_scan`] sets it for LiDARs; a
    /// stop-and-go tilting laser takes such a match at once (`false`).
    pub check_no_motion: bool,
    /// Floor on the standard deviation of an edge's translation, metres: the matcher's
    /// covariance is the two scans' alone, and a match can still be off by more.
    pub edge_sigma_floor_m: f64,
    /// Floor on the standard deviation of an edge's rotation, degrees.
    pub edge_sigma_floor_deg: f64,
    /// What the loop does when its predictions fail: wider windows, every heading, the whole
    /// map.
    pub recovery: RecoveryOptions,
    /// Loop closure.
    pub loop_closure: LoopClosureConfig,
    /// The pose-graph optimizer.
    pub optimize: OptimizeConfig,
    /// The fused occupancy map.
    pub voxel: VoxelConfig,
    /// How the work per stop and the memory stay bounded as the map grows.
    pub growth: super::GrowthOptions,
}

impl Default for SlamOptions {
    fn default() -> Self {
        Self {
            sdem: SdemConfig::default(),
            // A 2 cm grid finds the basin and the 6-DoF refinement the bottom (sub-millimetre on
            // the seeded pairs of `sdem bench`), at an eighth of the 1 cm grid's candidates.
            localize: LocalizeOptions {
                step_m: 0.02,
                runner_up: false,
                ..Default::default()
            },
            window_half_m: [0.15, 0.15, 0.08],
            window_half_no_odometry_m: [0.5, 0.5, 0.15],
            prior_sigma_m: 0.05,
            odometry_error_per_m: 0.15,
            prior_sigma_no_odometry_m: 0.2,
            heading_half_deg: 3.0,
            heading_half_compass_deg: 8.0,
            heading_half_no_prior_deg: 15.0,
            reference_radius_m: 4.0,
            max_reference_nodes: 3,
            min_reference_overlap_cells: 300,
            min_tracking_inlier_fraction: 0.5,
            check_no_motion: false,
            edge_sigma_floor_m: 0.005,
            edge_sigma_floor_deg: 0.1,
            recovery: RecoveryOptions::default(),
            loop_closure: LoopClosureConfig::default(),
            optimize: OptimizeConfig::default(),
            voxel: VoxelConfig::default(),
            growth: super::GrowthOptions::default(),
        }
    }
}

/// What the loop does when no prediction leads to a trusted match ([`crate::slam`]'s
/// recovery): the window grows, then every heading is searched near the last node, then the
/// whole map; a scan found nowhere starts a new map segment.
#[derive(Debug, Clone, PartialEq, Serialize, Deserialize)]
#[serde(default, deny_unknown_fields)]
pub struct RecoveryOptions {
    /// When no prediction leads to a trusted match, the best one is searched again in a window
    /// this large, metres (a robot that drove 2 m between stops, or 30 cm up or down)…
    pub max_window_half_m: [f64; 3],
    /// When set (no wider than `max_window_half_m` on any axis), the wider window around the
    /// best prediction is searched in this window first, metres (the search over every heading,
    /// the new segment's guess and the joins keep the widest): [`SlamOptions::for_scan`] widens
    /// a LiDAR's widest window by its step's ratio to the default's (7.85 on the KITTI frames:
    /// ±17.3 m, 0.6–2 s a search), where the tilting laser's ±2.2 m finds frames two or three
    /// apart in 0.1–0.3 s.
    pub first_window_half_m: Option<[f64; 3]>,
    /// … and this many degrees of heading either way without a compass, every heading being
    /// searched next. Around a compass the window is searched at the compass's own heading
    /// window first, then at what a compass near steel may be off by (±25°, at most this).
    pub max_heading_half_deg: f64,
    /// The search over every heading (and over tilt when the scan has no attitude reading)
    /// merges up to this many nodes of the current segment, nearest the last one, and searches
    /// `max_window_half_m` around the prediction.
    pub every_heading_nodes: usize,
    /// Without a prior (a robot lost, kidnapped or starting a run in a saved map), at most
    /// this many nodes are tried, those whose place descriptors look most like the scan's
    /// first, each searched over every heading.
    pub relocalize_candidates: usize,
    /// … within this half-size around each node, metres: as wide as the tilting laser's widest
    /// recovery window (a LiDAR's keeps it), since a robot facing the other way from the nodes
    /// that saw what it sees stands up to a few metres from them (a second run facing back
    /// along the first).
    pub relocalize_window_half_m: [f64; 3],
    /// … and a node's place is the node and up to this many nodes of its segment within
    /// `relocalize_radius_m`, merged.
    pub relocalize_place_nodes: usize,
    /// See `relocalize_place_nodes`, metres.
    pub relocalize_radius_m: f64,
    /// When no place of that size is taken (and none was ambiguous), the places are searched
    /// again with up to this many nodes within `relocalize_wide_radius_m`. A scan facing back
    /// along a run sees a little of what many of its stops saw: on the route bench's second
    /// runs over seeds 1–12 (no odometry), places of 3 nodes within 1.5 m placed 4 runs,
    /// places of 20 within 4 m 6, and 7 with three weak matches that agree (`joins`). Searched
    /// first, the small places keep relocalization in the `revisit` map at 0.4 s a scan
    /// (median) where places of 20 take 1.2 s.
    pub relocalize_wide_place_nodes: usize,
    /// See `relocalize_wide_place_nodes`, metres.
    pub relocalize_wide_radius_m: f64,
    /// The nodes of the segment whose origins lie within this of a prediction are candidates
    /// when the recent ones do not see what the scan sees, metres (the scanner's reach).
    pub other_nodes_radius_m: f64,
    /// A match that shares little with the map (a robot turned round sees new ground) is
    /// taken when the part it shares is confident: at least this share of the cells both
    /// scans saw match within the truncation…
    pub min_shared_inlier_fraction: f64,
    /// … and at least this many cells match (twice as many without a prior), with no other
    /// doubt (the runner-up searched).
    pub min_shared_inliers: usize,
}

impl Default for RecoveryOptions {
    fn default() -> Self {
        Self {
            max_window_half_m: [2.2, 2.2, 0.3],
            first_window_half_m: None,
            max_heading_half_deg: 60.0,
            every_heading_nodes: 3,
            relocalize_candidates: 6,
            relocalize_window_half_m: [2.2, 2.2, 0.3],
            relocalize_place_nodes: 3,
            relocalize_radius_m: 1.5,
            relocalize_wide_place_nodes: 20,
            relocalize_wide_radius_m: 4.0,
            other_nodes_radius_m: 6.0,
            min_shared_inlier_fraction: 0.75,
            min_shared_inliers: 150,
        }
    }
}

impl RecoveryOptions {
    /// The windows a wide search grows through, narrowest first: `first_window_half_m` when
    /// it is set and differs from `max_window_half_m` (validation refuses one wider on an
    /// axis), then `max_window_half_m`.
    pub fn window_stages(&self) -> Vec<[f64; 3]> {
        let widest = self.max_window_half_m;
        match self.first_window_half_m {
            Some(first) if first != widest => vec![first, widest],
            _ => vec![widest],
        }
    }

    /// Checks every value.
    pub fn validate(&self) -> Result<()> {
        if let Some(first) = self.first_window_half_m {
            if first
                .iter()
                .zip(&self.max_window_half_m)
                .any(|(f, w)| f > w)
            {
                return Err(Error::Invalid(format!(
                    "recovery.first_window_half_m {first:?} m is wider than max_window_half_m \
                     {:?} m on an axis; give a first window inside the widest",
                    self.max_window_half_m
                )));
            }
        }
        let halves = self
            .max_window_half_m
            .iter()
            .chain(self.first_window_half_m.iter().flatten())
            .chain(&self.relocalize_window_half_m);
        if let Some(h) = halves.copied().find(|h| !(h.is_finite() && *h >= 0.0)) {
            return Err(Error::Invalid(format!(
                "recovery: window half-size {h} m must be a finite number >= 0"
            )));
        }
        if !(self.max_heading_half_deg.is_finite()
            && (0.0..=180.0).contains(&self.max_heading_half_deg))
        {
            return Err(Error::Invalid(format!(
                "recovery.max_heading_half_deg = {} must lie in 0..=180 degrees",
                self.max_heading_half_deg
            )));
        }
        if self.every_heading_nodes == 0
            || self.relocalize_place_nodes == 0
            || self.relocalize_wide_place_nodes == 0
        {
            return Err(Error::Invalid(
                "recovery.every_heading_nodes, relocalize_place_nodes and \
                 relocalize_wide_place_nodes must be at least 1"
                    .into(),
            ));
        }
        for (name, v) in [
            ("relocalize_radius_m", self.relocalize_radius_m),
            ("relocalize_wide_radius_m", self.relocalize_wide_radius_m),
            ("other_nodes_radius_m", self.other_nodes_radius_m),
        ] {
            if !(v.is_finite() && v >= 0.0) {
                return Err(Error::Invalid(format!(
                    "recovery.{name} = {v} must be a distance >= 0"
                )));
            }
        }
        if !(0.0..=1.0).contains(&self.min_shared_inlier_fraction) {
            return Err(Error::Invalid(format!(
                "recovery.min_shared_inlier_fraction = {} must lie in 0..=1",
                self.min_shared_inlier_fraction
            )));
        }
        Ok(())
    }
}

/// The fused map of a spinning LiDAR takes rays up to this far, metres.
const LIDAR_VOXEL_RANGE_M: f64 = 20.0;

/// Whether `points_in_sensor` look like one turn of a spinning multi-beam LiDAR: their
/// directions cover at least `LIDAR_MIN_AZIMUTH_DEG` of azimuth (in 1° bins) within at most
/// `LIDAR_MAX_ELEVATION_DEG` of elevation (the 1st to 99th percentile). A tilting laser
/// sweeps half the azimuth; a rotating 3D laser scanner nearly the whole sphere, an Ouster
/// OS0 90° of elevation, a Velodyne 27–40°.
pub fn is_spinning_lidar(points_in_sensor: &[crate::geometry::Vec3]) -> bool {
    field_of_view(points_in_sensor).is_some_and(|(azimuth, elevation)| spinning(azimuth, elevation))
}

/// Whether `points_in_sensor` look like one frame of a forward-looking solid-state LiDAR (a
/// Livox, a MEMS or flash unit): their directions cover at most
/// `SOLID_STATE_MAX_AZIMUTH_DEG` of azimuth (in 1° bins). A tilting laser pans over 180°.
pub fn is_solid_state_lidar(points_in_sensor: &[crate::geometry::Vec3]) -> bool {
    field_of_view(points_in_sensor)
        .is_some_and(|(azimuth, _)| azimuth <= SOLID_STATE_MAX_AZIMUTH_DEG)
}

/// Whether `points_in_sensor` look like a spinning ([`is_spinning_lidar`]) or a solid-state
/// ([`is_solid_state_lidar`]) LiDAR's, their field of view measured once.
pub fn is_lidar(points_in_sensor: &[crate::geometry::Vec3]) -> bool {
    field_of_view(points_in_sensor).is_some_and(|(azimuth, elevation)| {
        spinning(azimuth, elevation) || azimuth <= SOLID_STATE_MAX_AZIMUTH_DEG
    })
}

/// [`is_spinning_lidar`] of a field of view, degrees.
fn spinning(azimuth: f64, elevation: f64) -> bool {
    azimuth >= LIDAR_MIN_AZIMUTH_DEG && elevation <= LIDAR_MAX_ELEVATION_DEG
}

/// The azimuth the points' directions cover (1° bins with a return) and the band of elevation
/// they span (the 1st to 99th percentile), degrees; `None` for fewer than 1,000 usable points.
fn field_of_view(points_in_sensor: &[crate::geometry::Vec3]) -> Option<(f64, f64)> {
    let mut azimuth_bins = vec![false; 360];
    let mut elevations: Vec<f64> = Vec::with_capacity(points_in_sensor.len());
    for p in points_in_sensor {
        let r = p.norm();
        if !(r.is_finite() && r > 0.1) {
            continue;
        }
        let azimuth = p.y.atan2(p.x).to_degrees().rem_euclid(360.0);
        azimuth_bins[(azimuth as usize).min(359)] = true;
        elevations.push((p.z / r).asin().to_degrees());
    }
    if elevations.len() < 1000 {
        return None;
    }
    elevations.sort_by(f64::total_cmp);
    let at = |q: f64| elevations[((elevations.len() - 1) as f64 * q) as usize];
    let covered = azimuth_bins.iter().filter(|&&b| b).count() as f64;
    Some((covered, at(0.99) - at(0.01)))
}

/// A scanner is a spinning multi-beam LiDAR ([`SlamOptions::for_scan`]) when its scan covers at
/// least this much of the azimuth, degrees…
pub const LIDAR_MIN_AZIMUTH_DEG: f64 = 300.0;
/// … within at most this band of elevation (the 1st to 99th percentile of the returns),
/// degrees: the widest spinning LiDARs (an Ouster OS0, 90°), and not a rotating scanner's
/// sphere (about 180°; outdoors, without returns from the sky, 110° or more). At 60° a
/// simulated OS0 (128 rows over ±45°) got the tilting laser's defaults and 11 of 12 frames down
/// a street were doubtful (`examples/lidar_runs`); with the derived options 0.05–0.06 cm ATE.
pub const LIDAR_MAX_ELEVATION_DEG: f64 = 100.0;
/// A scanner is a forward-looking solid-state LiDAR ([`SlamOptions::for_scan`]) when its scan
/// covers at most this much of the azimuth, degrees (Livox units 38–82°, the widest MEMS units
/// 120°; the tilting laser pans over 180°).
pub const SOLID_STATE_MAX_AZIMUTH_DEG: f64 = 120.0;

impl SlamOptions {
    /// The loop's options for the scanner that took `points_in_sensor`, as `sdem slam` chooses
    /// them for a dataset without a `sensor.toml`:
    ///
    /// * **a spinning multi-beam LiDAR** ([`is_spinning_lidar`]: every azimuth seen, within a
    ///   band of elevation), on a vehicle that moves continuously: the S-DEM grid derived from
    ///   the scan's own angular sampling ([`SdemConfig::for_scan`]), the search's step,
    ///   truncation and refinement from its ranges ([`LocalizeOptions::for_scan`]), loop
    ///   closure and the fused map on that step (voxels as large as the step, rays up to
    ///   20 m); a match without a prior (a loop closure, a relocalization, a second run's
    ///   first scan) needs the share of cells matching that tracking takes at once by default
    ///   ([`Self::min_tracking_inlier_fraction`], 50 %), not the tilting laser's 60 %: a
    ///   LiDAR on a moving vehicle always sees new ground ahead and sparse far returns (KITTI's
    ///   tracked frames match 56–58 % of their cells at the grid's best candidate against the
    ///   frame before), and a second run into their map was never placed; the tracking windows
    ///   stay the defaults (a vehicle's motion is predicted by its last one), but the recovery's
    ///   widest window and the σ of a prediction without odometry grow by the step's ratio to
    ///   the default's (the scene is that many times larger: 7.85 on the KITTI frames, ±17.3 m):
    ///   with the tilting laser's ±2.2 m and 20 cm, frames five apart (3.6–4.2 m) each opened
    ///   a segment, the true place outside the window and then, in a wider one, 3.6 m from the
    ///   no-motion prediction, which cost (3.6 / 0.2)² points' worth of τ² and put it over the
    ///   search's cost cap; the tilting laser's widest window is searched first (frames two
    ///   or three apart are found there in a sixth of the time);
    /// * **a forward-looking solid-state LiDAR** ([`is_solid_state_lidar`]: at most 120° of
    ///   azimuth): the same. On a simulated street (a 70° × 70° unit of 64 rows, 0.2° in
    ///   azimuth, 12 frames 0.8 m apart, no odometry, no attitude; `examples/lidar_runs`) the
    ///   tilting laser's defaults leave 10–11 of 12 frames doubtful, these options map them in
    ///   one segment (0.31–0.37 cm ATE, 14–15 ms a frame);
    /// * **any other scanner** (a tilting laser's half sphere, a rotating scanner's whole one):
    ///   [`SlamOptions::default`], the tilting laser's, on cells matched to the scan's sampling
    ///   ([`SdemConfig::default_for_scan`]: 0.6° for 3DTK's nodding laser at 0.5°, where the
    ///   default 1° left both later scans opening segments; 1° for the paper's sweep).
    ///
    /// # Example
    /// ```
    /// use sdem::geometry::Vec3;
    /// use sdem::slam::SlamOptions;
    /// // Walls 10 m around, seen by 32 lasers 1° apart over every azimuth.
    /// let points: Vec<Vec3> = (0..32)
    ///     .flat_map(|laser| (0..1800).map(move |k| (laser, k)))
    ///     .map(|(laser, k)| {
    ///         let (el, az) = (((laser as f64) - 20.0).to_radians(), (k as f64 * 0.2).to_radians());
    ///         let r = 10.0 / el.cos();
    ///         Vec3::new(r * el.cos() * az.cos(), r * el.cos() * az.sin(), r * el.sin())
    ///     })
    ///     .collect();
    /// let lidar = SlamOptions::for_scan(&points);
    /// let default = SlamOptions::default();
    /// assert!(lidar.localize.step_m > default.localize.step_m);
    /// // Its recovery searches the tilting laser's widest window first, then one as many times
    /// // wider as its step is coarser.
    /// let scale = lidar.localize.step_m / default.localize.step_m;
    /// let widest = lidar.recovery.window_stages();
    /// assert_eq!(widest[0], default.recovery.max_window_half_m);
    /// assert!((widest[1][0] - scale * default.recovery.max_window_half_m[0]).abs() < 1e-9);
    /// // The tilting laser's front half: the defaults.
    /// let front: Vec<Vec3> = points.iter().filter(|p| p.x > 0.0).copied().collect();
    /// assert_eq!(SlamOptions::for_scan(&front), SlamOptions::default());
    /// ```
    pub fn for_scan<P: crate::geometry::AsPoint>(points_in_sensor: &[P]) -> Self {
        let points_in_sensor = &*P::as_vec3s(points_in_sensor);
        let default = Self::default();
        if !is_lidar(points_in_sensor) {
            return Self {
                sdem: SdemConfig::default_for_scan(points_in_sensor),
                ..default
            };
        }
        let sdem = SdemConfig::for_scan(points_in_sensor);
        let Ok(scan) = crate::sdem::Sdem::from_points(
            points_in_sensor,
            &crate::geometry::Attitude::default(),
            &sdem,
        ) else {
            return default;
        };
        let localize = LocalizeOptions {
            runner_up: false,
            ..LocalizeOptions::for_scan(&scan)
        };
        let step = localize.step_m;
        let scale = step / default.localize.step_m;
        let widest = default.recovery.max_window_half_m;
        Self {
            sdem,
            check_no_motion: true,
            prior_sigma_no_odometry_m: default.prior_sigma_no_odometry_m * scale,
            recovery: RecoveryOptions {
                max_window_half_m: [
                    widest[0] * scale,
                    widest[1] * scale,
                    widest[2].max(2.0 * step),
                ],
                first_window_half_m: Some(widest),
                ..default.recovery.clone()
            },
            loop_closure: LoopClosureConfig {
                step_m: step,
                window_half_m: [
                    default.loop_closure.window_half_m[0].max(3.0 * step),
                    default.loop_closure.window_half_m[1].max(3.0 * step),
                    default.loop_closure.window_half_m[2].max(step),
                ],
                // See above: what tracking takes at once.
                min_inlier_fraction: default.min_tracking_inlier_fraction,
                ..default.loop_closure.clone()
            },
            voxel: VoxelConfig {
                voxel_m: default.voxel.voxel_m.max(step),
                max_range_m: LIDAR_VOXEL_RANGE_M,
                ..default.voxel
            },
            localize,
            ..default
        }
    }

    /// Checks every setting, the search's, the S-DEM's and the voxel map's included, so that a
    /// bad one is refused before the first scan rather than at the second.
    pub fn validate(&self) -> Result<()> {
        self.sdem.validate()?;
        self.localize.validate()?;
        self.voxel.validate()?;
        self.recovery.validate()?;
        self.growth.validate()?;
        let halves = self
            .window_half_m
            .iter()
            .chain(&self.window_half_no_odometry_m)
            .chain(&self.loop_closure.window_half_m);
        for &h in halves {
            if !(h.is_finite() && h >= 0.0) {
                return Err(Error::Invalid(format!(
                    "window half-size {h} m must be a finite number >= 0"
                )));
            }
        }
        for (name, v) in [
            ("prior_sigma_m", self.prior_sigma_m),
            ("prior_sigma_no_odometry_m", self.prior_sigma_no_odometry_m),
            ("odometry_error_per_m", self.odometry_error_per_m),
        ] {
            if !(v.is_finite() && v > 0.0) {
                return Err(Error::Invalid(format!(
                    "{name} = {v} m must be a positive number"
                )));
            }
        }
        for (name, v) in [
            ("heading_half_deg", self.heading_half_deg),
            ("heading_half_compass_deg", self.heading_half_compass_deg),
            ("heading_half_no_prior_deg", self.heading_half_no_prior_deg),
        ] {
            if !(v.is_finite() && (0.0..=180.0).contains(&v)) {
                return Err(Error::Invalid(format!(
                    "{name} = {v} must lie in 0..=180 degrees"
                )));
            }
        }
        // A grid step wider than the tracking window leaves it one candidate a side: every stop
        // would be searched again wider, or open a segment.
        let widest = 2.0 * self.window_half_m[0].max(self.window_half_m[1]);
        if self.localize.step_m > widest {
            return Err(Error::Invalid(format!(
                "the search's step {} m is wider than the tracking window ({} m across, \
                 window_half_m); give a step of at most {} m",
                self.localize.step_m, widest, widest
            )));
        }
        if !(self.reference_radius_m.is_finite() && self.reference_radius_m > 0.0) {
            return Err(Error::Invalid(format!(
                "reference_radius_m = {} must be a positive distance",
                self.reference_radius_m
            )));
        }
        if !(0.0..=1.0).contains(&self.min_tracking_inlier_fraction) {
            return Err(Error::Invalid(format!(
                "min_tracking_inlier_fraction = {} must lie in 0..=1",
                self.min_tracking_inlier_fraction
            )));
        }
        if self.max_reference_nodes == 0 {
            return Err(Error::Invalid(
                "max_reference_nodes must be at least 1".into(),
            ));
        }
        if !(self.edge_sigma_floor_m.is_finite()
            && self.edge_sigma_floor_m > 0.0
            && self.edge_sigma_floor_deg.is_finite()
            && self.edge_sigma_floor_deg > 0.0)
        {
            return Err(Error::Invalid(
                "edge_sigma_floor_m and edge_sigma_floor_deg must be positive".into(),
            ));
        }
        // Checked here, before the first scan: the pose graph's settings were checked at the
        // first solve and the loop closure's at the first closure, so a run stopped there
        // (scan 23 or 31 of 40) and `--resume`, reading the same settings, stopped again.
        self.optimize.validate()?;
        self.loop_closure.validate()?;
        // A grid too fine for its window was refused at the second scan.
        for (what, half, step) in [
            ("window_half_m", &self.window_half_m, self.localize.step_m),
            (
                "window_half_no_odometry_m",
                &self.window_half_no_odometry_m,
                self.localize.step_m,
            ),
            (
                "loop_closure.window_half_m",
                &self.loop_closure.window_half_m,
                self.loop_closure.step_m,
            ),
        ] {
            let window =
                crate::search::SearchWindow::around(&crate::geometry::Vec3::zeros(), *half);
            let counts = (window.positions(step))
                .map_err(|e| Error::Invalid(format!("{what} at steps of {step} m: {e}")))?;
            let positions: f64 = counts.iter().map(|&n| n as f64).product();
            if positions > crate::search::MAX_GRID_CANDIDATES as f64 {
                return Err(Error::Invalid(format!(
                    "{what} {half:?} m searched at steps of {step} m is {positions:.3e} \
                     positions, more than the {} a search may have; give a larger step or a \
                     smaller window",
                    crate::search::MAX_GRID_CANDIDATES
                )));
            }
        }
        Ok(())
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    /// A wide search grows through the first window to the widest; a first window equal to the
    /// widest, or none, is one stage; one wider on an axis is refused, naming the setting.
    #[test]
    fn the_recovery_windows_grow_from_the_first_to_the_widest() {
        let mut recovery = RecoveryOptions::default();
        let widest = recovery.max_window_half_m;
        assert_eq!(recovery.window_stages(), vec![widest]);
        recovery.first_window_half_m = Some(widest);
        assert_eq!(recovery.window_stages(), vec![widest]);
        let first = [1.0, 1.0, 0.3];
        recovery.first_window_half_m = Some(first);
        assert_eq!(recovery.window_stages(), vec![first, widest]);
        recovery.validate().unwrap();
        recovery.first_window_half_m = Some([1.0, 3.0, 0.3]);
        let e = recovery.validate().unwrap_err().to_string();
        assert!(e.contains("first_window_half_m"), "{e}");
    }

    /// A search step wider than the tracking window is refused, naming the widest it may be;
    /// the defaults, and a spinning LiDAR's derived options, pass.
    /// Settings that stopped a run at its first pose-graph solve or loop closure (then
    /// `--resume`, with the same settings, stopped again), that hung it, or that silently turned
    /// loop closure off, are refused before the first scan, naming the setting.
    #[test]
    fn settings_checked_late_or_never_are_refused_up_front() {
        type Change = fn(&mut SlamOptions);
        let cases: [(&str, Change); 8] = [
            ("robust_kernel_width", |o| {
                o.optimize.robust_kernel_width = 0.0
            }),
            ("initial_damping", |o| o.optimize.initial_damping = -1.0),
            ("loop_closure.max_correction_m", |o| {
                o.loop_closure.max_correction_m = -1.0
            }),
            ("loop_closure.search_radius_m", |o| {
                o.loop_closure.search_radius_m = -1.0
            }),
            ("loop_closure.heading_half_deg", |o| {
                o.loop_closure.heading_half_deg = 1e9
            }),
            ("loop_closure.window_half_m", |o| {
                o.loop_closure.step_m = 1e-9
            }),
            ("window_half_m", |o| o.localize.step_m = 1e-4),
            ("normal_radius_cells", |o| {
                o.localize.refinement.normal_radius_cells = 1_000_000_000
            }),
        ];
        for (name, change) in cases {
            let mut options = SlamOptions::default();
            change(&mut options);
            let e = options.validate().unwrap_err().to_string();
            assert!(e.contains(name), "{name}: {e}");
        }
    }

    #[test]
    fn a_step_wider_than_the_tracking_window_is_refused() {
        let mut options = SlamOptions::default();
        options.validate().unwrap();
        options.localize.step_m = 5.0;
        let e = options.validate().unwrap_err().to_string();
        assert!(e.contains("5 m") && e.contains("at most 0.3 m"), "{e}");
        options.localize.step_m = 0.3;
        options.validate().unwrap();
    }
}
