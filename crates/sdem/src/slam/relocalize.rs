//! Relocalization: finding where a scan was taken in a saved map, and the fusion of a match with
//! a prediction along the direction the scans leave free.

use super::{ms, SlamOptions};
use crate::doubt::Doubt;
use crate::error::{Error, Result};
use crate::geometry::{Attitude, Pose, Vec3};
use crate::localize::{
    localize, CostConfig, Diagnostics, LocalizeOptions, OffsetPrior, SearchWindow,
};
use crate::map::{world_from_query, Descriptor, Map};
use crate::sdem::Sdem;
use crate::search::HeadingWindow;
use serde::Serialize;
use std::time::Instant;

/// A scan relocalized in a saved map ([`relocalize`]).
#[derive(Debug, Clone, Serialize)]
pub struct Relocalization {
    /// The scan's estimated pose in the map's world frame.
    pub world_from_sensor: crate::geometry::PoseRecord,
    /// The node it was matched against.
    pub node_id: usize,
    /// The nodes tried, in order, with the reason each one failed (empty when it matched).
    pub tried: Vec<(usize, String)>,
    /// Eq. (1) at the best grid candidate, m².
    pub cost: f64,
    /// The match's diagnostics.
    pub diagnostics: crate::localize::Diagnostics,
    /// Every reason not to trust the pose (see [`crate::localize::Localization::doubts`]).
    pub doubts: Vec<Doubt>,
    /// No doubt: the pose can be used as it is.
    pub trusted: bool,
    /// Wall time, ms.
    pub time_ms: f64,
}

/// Where a scan to relocalize was taken, roughly (see [`relocalize`]).
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct Near {
    /// The sensor's position in the map's world frame, metres.
    pub position: Vec3,
    /// How well it is known, metres (one σ), when it is a prediction (odometry since the last
    /// known pose): then it also weighs in the cost ([`OffsetPrior`]), and along a direction the
    /// scan leaves free (a corridor's axis) the position is the prediction's, as in
    /// [`Slam::add_scan`]. Without it only the window is centred there.
    ///
    /// [`Slam::add_scan`]: super::Slam::add_scan
    pub sigma_m: Option<f64>,
}

/// Finds where a scan was taken in a saved map: near `near` when given, else at the nodes whose
/// place descriptors look most like the scan's, trying up to `max_nodes` nodes with the exact
/// search (a window of [`SlamOptions::window_half_no_odometry_m`] around the node, or around
/// `near`), nearest or most alike first, until one clears the inlier threshold of loop closure.
///
/// # Errors
/// An empty map or scan, a `near` that is not finite or whose σ is not a positive length, or no
/// node that matches.
pub fn relocalize(
    map: &Map,
    config: &SlamOptions,
    points_in_sensor: &[Vec3],
    attitude: Option<Attitude>,
    near: Option<Near>,
    max_nodes: usize,
) -> Result<Relocalization> {
    let start = Instant::now();
    if map.nodes.is_empty() {
        return Err(Error::Invalid(
            "the map has no node to relocalize in".into(),
        ));
    }
    if let Some(n) = &near {
        n.validate()?;
    }
    let near_position = near.map(|n| n.position);
    let level = attitude.unwrap_or_default();
    let query = Sdem::from_points(points_in_sensor, &level, &config.sdem)?;
    if query.known_cells() == 0 {
        return Err(Error::Invalid("the scan has no usable point".into()));
    }
    let candidates = candidate_nodes(map, &query, near_position, max_nodes);
    let heading = if attitude.is_some() {
        config.heading_half_compass_deg
    } else {
        config.heading_half_no_prior_deg
    };
    let mut tried = Vec::new();
    let mut best = None;
    for &(node_id, _) in &candidates {
        let origin = map.nodes[node_id].position();
        let reference = map.merged_reference(&[node_id], &origin, &config.sdem)?;
        let centre = near_position.map_or(Vec3::zeros(), |p| p - origin);
        let localize_config = search_options(config, centre, near, heading);
        match localize(&reference, &query, &localize_config) {
            Ok(found)
                if found.diagnostics.inlier_fraction >= config.loop_closure.min_inlier_fraction =>
            {
                // The nearest (or most alike) node that matches well is the answer; the others
                // are tried only when it does not.
                best = Some((node_id, found, origin));
                break;
            }
            Ok(found) => tried.push((
                node_id,
                format!(
                    "only {:.0} % of the cells match",
                    found.diagnostics.inlier_fraction * 100.0
                ),
            )),
            Err(e) if e.is_no_match() => tried.push((node_id, e.to_string())),
            Err(e) => return Err(e),
        }
    }
    let Some((node_id, found, origin)) = best else {
        return Err(Error::NotFound { tried });
    };
    let mut pose = world_from_query(&origin, &found);
    let mut diagnostics = found.diagnostics;
    let mut doubts = found.doubts;
    if let Some(Near {
        position,
        sigma_m: Some(sigma_m),
    }) = near
    {
        take_prediction_along(&mut pose, &mut diagnostics, &mut doubts, &position, sigma_m);
    }
    Ok(Relocalization {
        world_from_sensor: (&pose).into(),
        node_id,
        tried,
        cost: found.cost,
        diagnostics,
        trusted: doubts.is_empty(),
        doubts,
        time_ms: ms(start),
    })
}

impl Near {
    /// Refuses a position that is not finite, or a σ that is not a positive length.
    fn validate(&self) -> Result<()> {
        if !self.position.iter().all(|v| v.is_finite()) {
            return Err(Error::Invalid(format!(
                "the position to relocalize near, {:?}, must be finite metres",
                self.position.as_slice()
            )));
        }
        if let Some(sigma_m) = self.sigma_m {
            OffsetPrior {
                offset: self.position.into(),
                sigma_m,
            }
            .validate()?;
        }
        Ok(())
    }
}

/// The nodes to try, with how near each lies to `near_position` or, without one, how unlike its
/// place descriptor is the scan's; nearest or most alike first, at most `max_nodes` (at least
/// one).
fn candidate_nodes(
    map: &Map,
    query: &Sdem,
    near_position: Option<Vec3>,
    max_nodes: usize,
) -> Vec<(usize, f64)> {
    let mut candidates: Vec<(usize, f64)> = match near_position {
        Some(p) => map
            .nodes
            .iter()
            .map(|n| (n.node_id, (n.position() - p).norm()))
            .collect(),
        None => {
            let descriptor = Descriptor::from_levelled(query.points());
            map.nodes
                .iter()
                .filter_map(|n| {
                    let d =
                        Descriptor::from_levelled(&n.points_levelled()).distance(&descriptor, 1)?;
                    Some((n.node_id, d))
                })
                .collect()
        }
    };
    candidates.sort_by(|a, b| a.1.total_cmp(&b.1));
    candidates.truncate(max_nodes.max(1));
    candidates
}

/// The search at one node: a window of [`SlamOptions::window_half_no_odometry_m`] around
/// `centre` (the offset from the node's origin), headings within `heading` degrees, and the
/// prior of `near` when it has a σ.
fn search_options(
    config: &SlamOptions,
    centre: Vec3,
    near: Option<Near>,
    heading: f64,
) -> LocalizeOptions {
    let prior = near.and_then(|n| n.sigma_m).map(|sigma_m| OffsetPrior {
        offset: centre.into(),
        sigma_m,
    });
    LocalizeOptions {
        window: SearchWindow::around(&centre, config.window_half_no_odometry_m),
        heading: HeadingWindow {
            half_range_deg: heading,
            step_deg: None,
        },
        cost: CostConfig {
            prior,
            ..config.localize.cost.clone()
        },
        ..config.localize.clone()
    }
}

/// Degeneracy-aware fusion (after Zhang, Kaess and Singh, ICRA 2016): where `diagnostics` name
/// a free direction (unit, world axes), moves `pose` along it to the `predicted` position's
/// place, widens the covariance (world axes) there by the prediction's variance `sigma_m²`, and
/// adds a doubt saying so.
pub(super) fn take_prediction_along(
    pose: &mut Pose,
    diagnostics: &mut Diagnostics,
    doubts: &mut Vec<Doubt>,
    predicted: &Vec3,
    sigma_m: f64,
) {
    let Some(flat) = diagnostics.flat_direction else {
        return;
    };
    let v = Vec3::from(flat);
    let t = pose.translation.vector;
    let along = v.dot(&(predicted - t));
    pose.translation.vector = t + v * along;
    if let Some(c) = diagnostics.covariance.as_mut() {
        for i in 0..3 {
            for j in 0..3 {
                c[i][j] += v[i] * v[j] * sigma_m.powi(2);
            }
        }
    }
    doubts.push(Doubt::TakenFromPrediction {
        direction: flat,
        shift_m: along,
    });
}
