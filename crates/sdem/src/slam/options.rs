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
    /// Floor on the standard deviation of an edge's translation, metres: the matcher's
    /// covariance assumes independent residuals and is optimistic.
    pub edge_sigma_floor_m: f64,
    /// Floor on the standard deviation of an edge's rotation, degrees.
    pub edge_sigma_floor_deg: f64,
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
            prior_sigma_no_odometry_m: 0.2,
            heading_half_deg: 3.0,
            heading_half_compass_deg: 8.0,
            heading_half_no_prior_deg: 15.0,
            reference_radius_m: 4.0,
            max_reference_nodes: 3,
            min_reference_overlap_cells: 300,
            edge_sigma_floor_m: 0.005,
            edge_sigma_floor_deg: 0.1,
            loop_closure: LoopClosureConfig::default(),
            optimize: OptimizeConfig::default(),
            voxel: VoxelConfig::default(),
            growth: super::GrowthOptions::default(),
        }
    }
}

impl SlamOptions {
    /// Checks the values the loop itself uses (the search, S-DEM and voxel settings check
    /// themselves when used).
    pub fn validate(&self) -> Result<()> {
        self.sdem.validate()?;
        self.voxel.validate()?;
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
        if !(self.reference_radius_m.is_finite() && self.reference_radius_m > 0.0) {
            return Err(Error::Invalid(format!(
                "reference_radius_m = {} must be a positive distance",
                self.reference_radius_m
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
        Ok(())
    }
}
