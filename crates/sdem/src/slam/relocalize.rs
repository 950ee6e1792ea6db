//! Relocalization: finding where a scan was taken in a saved map.

use super::map_search::{Located, MapSearch};
use super::predictions::take_prediction_along;
use super::step::Attempt;
use super::{ScanInput, SlamOptions};
use crate::doubt::Doubt;
use crate::error::{Error, Result};
use crate::geometry::{Attitude, Pose, PoseRecord, Vec3};
use crate::localize::{localize, CostConfig, LocalizeOptions, OffsetPrior, SearchWindow};
use crate::map::{world_from_query, Map};
use crate::sdem::Sdem;
use crate::search::HeadingWindow;
use serde::{Serialize, Serializer};
use std::time::{Duration, Instant};

/// A scan relocalized in a saved map ([`relocalize`]).
///
/// Serialized (as `sdem localize --map --json` prints it) with the pose as DESIGN.md's
/// [`PoseRecord`] and the time as `time_ms`.
#[derive(Debug, Clone, Serialize)]
pub struct Relocalization {
    /// The scan's estimated pose in the map's world frame (in its node's segment's frame when
    /// that is not the world's), as [`crate::Step::world_from_sensor`] gives a stop's.
    #[serde(serialize_with = "as_pose_record")]
    pub world_from_sensor: Pose,
    /// The node it was matched against.
    pub node_id: usize,
    /// The segment of that node (0: the world's).
    pub segment: usize,
    /// The nodes tried that did not match, in order, with the reason each one failed.
    pub tried: Vec<(usize, String)>,
    /// Without a position: every search tried, with its figures.
    pub candidates: Vec<Attempt>,
    /// Eq. (1) at the best grid candidate, m².
    pub cost: f64,
    /// The match's diagnostics.
    pub diagnostics: crate::localize::Diagnostics,
    /// Every reason not to trust the pose (see [`crate::localize::Localization::doubts`]).
    pub doubts: Vec<Doubt>,
    /// No doubt: the pose can be used as it is.
    pub trusted: bool,
    /// Wall time.
    #[serde(rename = "time_ms", serialize_with = "as_milliseconds")]
    pub time: Duration,
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

/// Finds where a scan was taken in a saved map.
///
/// * **Near a position** (`near`): the `max_nodes` nodes nearest it, in turn, with the exact
///   search over a window of [`SlamOptions::window_half_no_odometry_m`] around it and the
///   heading the reading allows, until one clears the inlier threshold of loop closure.
/// * **Without a prior**: the `max_nodes` nodes whose places (each node with its neighbours,
///   [`crate::map::Map::place_descriptor`]) look most like the scan, whichever way it faced,
///   each searched over every heading ([`crate::localize`](crate::scan::localize) with the
///   heading unknown; the tilt too without an attitude reading) within
///   [`super::RecoveryOptions::relocalize_window_half_m`] around it. The best match that has
///   no doubt and matches as many cells as a loop closure must is the answer — unless a match
///   at another place compares almost as well (the ambiguity ratio): then the scan is not
///   found, rather than found in the wrong place. Every heading comes first from the surfaces'
///   heading hypotheses; a scan with an attitude reading that is not found so has its places
///   searched again over a full turn of heading, exactly, before it is said not to be found.
///
/// # Errors
/// An empty map or `max_nodes` 0, a scan of which no point is usable ([`Error::NoUsablePoints`], saying why) or
/// that fills too few cells to compare ([`Error::TooFewPoints`]), a
/// `near` that is not finite or whose σ is not a positive length, or ([`Error::NotFound`]) no
/// node that matches with confidence, each tried node with its reason.
pub fn relocalize<P: crate::geometry::AsPoint>(
    map: &Map,
    config: &SlamOptions,
    points_in_sensor: &[P],
    attitude: Option<Attitude>,
    near: Option<Near>,
    max_nodes: usize,
) -> Result<Relocalization> {
    let start = Instant::now();
    let points_in_sensor = &*P::as_vec3s(points_in_sensor);
    if max_nodes == 0 {
        return Err(Error::Invalid(
            "max_nodes = 0: at least one node must be tried".into(),
        ));
    }
    if map.nodes.is_empty() {
        return Err(Error::Invalid(
            "the map has no node to relocalize in".into(),
        ));
    }
    // The scan on the map's grid, levelled by its reading: a scan that fills no cell (every
    // point at the sensor's origin or out of range) is said to be so, and why, not "not found".
    let query = Sdem::from_usable_points(
        points_in_sensor,
        &attitude.unwrap_or_default(),
        &config.sdem,
    )?;
    // Too few cells to compare anywhere: said so, not "tried no node".
    if query.known_cells() < crate::scan::MIN_KNOWN_CELLS {
        return Err(Error::TooFewPoints {
            usable: query.known_cells(),
            needed: crate::scan::MIN_KNOWN_CELLS,
        });
    }
    match near {
        Some(near) => relocalize_near(map, config, &query, attitude, near, max_nodes),
        None => relocalize_anywhere(map, config, points_in_sensor, attitude, max_nodes),
    }
    .map(|mut found| {
        found.time = start.elapsed();
        found
    })
}

/// [`relocalize`] without a prior.
fn relocalize_anywhere(
    map: &Map,
    config: &SlamOptions,
    points_in_sensor: &[Vec3],
    attitude: Option<Attitude>,
    max_nodes: usize,
) -> Result<Relocalization> {
    let config = SlamOptions {
        recovery: super::RecoveryOptions {
            relocalize_candidates: max_nodes,
            ..config.recovery.clone()
        },
        ..config.clone()
    };
    let mut search = MapSearch {
        map,
        config: &config,
        full_turn: false,
    };
    let scan = ScanInput {
        scan_index: 0,
        points_in_sensor,
        attitude,
        odometry: None,
    };
    let mut attempts = Vec::new();
    let mut found = search.find_in_map(&scan, |_| true, None, &mut attempts)?;
    if found.is_none() && attitude.is_some() {
        // The headings came from the surfaces' hypotheses, which can miss one; before a scan
        // with a reading is said not to be in the map, its places are searched again over a
        // full turn, exactly (on the `revisit` map's 53 stops the hypotheses find 52 in 0.38 s
        // median; the full turn finds all 53 in 3.1 s).
        search.full_turn = true;
        found = search.find_in_map(&scan, |_| true, None, &mut attempts)?;
    }
    let tried: Vec<(usize, String)> = (attempts.iter())
        .filter(|a| !a.accepted || !a.reason.is_empty())
        .map(|a| (a.nodes.first().copied().unwrap_or(0), a.reason.clone()))
        .collect();
    let Some(Located::Found {
        matched, segment, ..
    }) = found
    else {
        return Err(Error::NotFound { tried });
    };
    Ok(Relocalization {
        world_from_sensor: matched.world_from_sensor,
        node_id: matched.references[0].0,
        segment,
        tried,
        candidates: attempts,
        cost: matched.cost,
        trusted: matched.doubts.is_empty(),
        diagnostics: matched.diagnostics,
        doubts: matched.doubts,
        time: Duration::ZERO,
    })
}

/// [`relocalize`] near a position.
fn relocalize_near(
    map: &Map,
    config: &SlamOptions,
    query: &Sdem,
    attitude: Option<Attitude>,
    near: Near,
    max_nodes: usize,
) -> Result<Relocalization> {
    near.validate()?;
    let candidates = nearest_nodes(map, &near.position, max_nodes);
    let heading = if attitude.is_some() {
        config.heading_half_compass_deg
    } else {
        config.heading_half_no_prior_deg
    };
    let mut tried = Vec::new();
    let mut best = None;
    for node_id in candidates {
        let origin = map.nodes[node_id].position();
        let reference = map.merged_reference(&[node_id], &origin, &config.sdem)?;
        let centre = near.position - origin;
        let localize_config = search_options(config, centre, Some(near), heading);
        match localize(&reference, query, &localize_config) {
            // Counted at the refined pose too (a LiDAR's coarse grid, see
            // `Diagnostics::refined_inlier_fraction`).
            Ok(found)
                if found.diagnostics.matching_fraction()
                    >= config.loop_closure.min_inlier_fraction =>
            {
                // The nearest node that matches well is the answer; the others are tried only
                // when it does not.
                best = Some((node_id, found, origin));
                break;
            }
            Ok(found) => tried.push((
                node_id,
                format!(
                    "only {:.0} % of the cells match (a match near a position needs {:.0} %: \
                     the map's loop_closure.min_inlier_fraction)",
                    found.diagnostics.matching_fraction() * 100.0,
                    config.loop_closure.min_inlier_fraction * 100.0
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
    if let Some(sigma_m) = near.sigma_m {
        take_prediction_along(
            &mut pose,
            &mut diagnostics,
            &mut doubts,
            &near.position,
            sigma_m,
        );
    }
    Ok(Relocalization {
        world_from_sensor: pose,
        node_id,
        segment: map.nodes[node_id].segment,
        tried,
        candidates: Vec::new(),
        cost: found.cost,
        diagnostics,
        trusted: doubts.is_empty(),
        doubts,
        time: Duration::ZERO,
    })
}

fn as_pose_record<S: Serializer>(pose: &Pose, s: S) -> std::result::Result<S::Ok, S::Error> {
    PoseRecord::from(pose).serialize(s)
}

fn as_milliseconds<S: Serializer>(time: &Duration, s: S) -> std::result::Result<S::Ok, S::Error> {
    s.serialize_f64(time.as_secs_f64() * 1e3)
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

/// The `max_nodes` nodes nearest `position` (at least one), nearest first.
fn nearest_nodes(map: &Map, position: &Vec3, max_nodes: usize) -> Vec<usize> {
    let mut by_distance: Vec<(usize, f64)> = (map.nodes.iter())
        .map(|n| (n.node_id, (n.position() - position).norm()))
        .collect();
    by_distance.sort_by(|a, b| a.1.total_cmp(&b.1));
    by_distance.truncate(max_nodes.max(1));
    by_distance.into_iter().map(|(id, _)| id).collect()
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
