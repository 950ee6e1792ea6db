//! Joining segments: a node of a segment other than the world's, matched against the nodes of
//! the other segments.
//!
//! **Near.** A segment started where a match failed is placed where the loop last believed the
//! robot was (by the odometry, or by the best match tried), so its frame is nearly the world's:
//! its node is searched for near that place, in the widest window, with the runner-up search.
//!
//! **By place.** Without a prior, the nodes whose place descriptors look alike are searched
//! over every heading ([`super::map_search::MapSearch::find_in_map`]): a match is taken as a
//! relocalization is, with as many inliers as a loop closure needs and no other place
//! comparing almost as well.
//!
//! A confident match moves the younger segment's nodes rigidly into the older one's frame and
//! becomes an edge of the joined graph.
//!
//! **Bounded work.** Both searches together took up to 6 s a stop on a loaded 2-core machine.
//! A join is tried from a node only when its segment has moved on since the last try: at
//! least [`RETRY_STOPS`] stops of the segment later, and from a node at least [`RETRY_M`] from
//! every node of its segment tried before, or turned [`RETRY_DEG`] from it (a scan taken where
//! a join failed shows the map nothing new).

use super::closures::Closing;
use super::map_search::{Located, Matched};
use super::predictions::Prediction;
use super::step::{Attempt, HeadingPrior, PredictionSource};
use super::{ScanInput, Slam};
use crate::error::Result;
use crate::geometry::{attitude_of, Attitude};
use crate::map::LoopClosure;
use crate::posegraph::{Edge, EdgeKind};
use crate::sdem::Sdem;
use nalgebra::Matrix6;

/// Nodes of other segments tried per join by place.
const JOIN_CANDIDATES: usize = 3;
/// A join is tried again from a node of a segment only this many stops of the segment after
/// the last try…
pub(super) const RETRY_STOPS: usize = 2;
/// … and only from a node at least this far from every node of its segment tried before,
/// metres…
pub(super) const RETRY_M: f64 = 0.75;
/// … or turned at least this much from each, degrees.
pub(super) const RETRY_DEG: f64 = 30.0;

impl Slam {
    /// Node `to` against the nodes of the other segments, when its segment has moved on since
    /// the last try ([`RETRY_STOPS`], [`RETRY_M`]): first near where its segment believes it
    /// is, then by place. A confident match joins the two segments.
    pub(super) fn join_elsewhere(&mut self, to: usize, closing: &mut Closing) -> Result<()> {
        if !self.join_due(to) {
            return Ok(());
        }
        self.join_tries.push(to);
        let found = match self.join_near(to, &mut closing.attempts)? {
            Some(matched) => Some(matched),
            None => self.join_by_place(to, &mut closing.attempts)?,
        };
        let Some(matched) = found else {
            return Ok(());
        };
        let (edge, mut closure) = self.join_link(to, &matched);
        let joined = self.join_segments(edge, &matched.world_from_sensor)?;
        closure.correction_m = Some(joined.moved_m);
        self.unplaced_segments.retain(|&s| s != joined.absorbed);
        self.measured_segments.retain(|&s| s != joined.absorbed);
        self.loop_closures.push(closure.clone());
        self.closure_pool.push(closure.clone());
        closing.checked.push(closure);
        closing.changed = Some(joined.into);
        closing.joined.push(joined);
        Ok(())
    }

    /// Whether a join is tried from node `to`: its segment was never tried, or it is at least
    /// [`RETRY_STOPS`] stops past the last try and stands at least [`RETRY_M`] or [`RETRY_DEG`]
    /// from every node of its segment tried before.
    fn join_due(&self, to: usize) -> bool {
        let node = &self.map.nodes[to];
        let tried: Vec<usize> = (self.join_tries.iter().copied())
            .filter(|&n| self.map.nodes[n].segment == node.segment)
            .collect();
        let Some(&latest) = tried.iter().max() else {
            return true;
        };
        let since = (latest + 1..=to)
            .filter(|&id| self.map.nodes[id].segment == node.segment)
            .count();
        let new_view = tried.iter().all(|&n| {
            let m = &self.map.nodes[n];
            (m.position() - node.position()).norm() >= RETRY_M
                || m.world_from_sensor
                    .rotation
                    .angle_to(&node.world_from_sensor.rotation)
                    >= RETRY_DEG.to_radians()
        });
        since >= RETRY_STOPS && new_view
    }

    /// The edge from the node that `matched` was matched against to `node`, and its record as
    /// an accepted closure.
    fn join_link(&self, node: usize, matched: &Matched) -> (Edge, LoopClosure) {
        let link = matched.references[0].0;
        let world_from_node = matched.world_from_sensor;
        let covariance = matched
            .diagnostics
            .covariance
            .map(|c| Matrix6::from_fn(|i, j| c[i][j]));
        let edge = Edge {
            from: link,
            to: node,
            from_from_to: self.map.nodes[link].world_from_sensor.inverse() * world_from_node,
            information: self.edge_information(covariance.as_ref(), &world_from_node, 1.0),
            kind: EdgeKind::LoopClosure,
        };
        let mut closure = LoopClosure::unchecked(link, node);
        closure.accepted = true;
        closure.cost = Some(matched.cost);
        closure.inlier_fraction = Some(matched.diagnostics.inlier_fraction);
        closure.from_from_to = Some(edge.from_from_to);
        closure.covariance = covariance;
        (edge, closure)
    }

    /// [`Self::join_elsewhere`]'s search near the node's believed place; `None` when its
    /// segment was started with no prior at all, or nothing there matches with confidence.
    fn join_near(&self, to: usize, attempts: &mut Vec<Attempt>) -> Result<Option<Matched>> {
        let node = &self.map.nodes[to];
        let segment = node.segment;
        let recovery = &self.config.recovery;
        let others = |id: usize| {
            let n = &self.map.nodes[id];
            n.segment != segment
                && !self.unplaced_segments.contains(&n.segment)
                && (n.position() - node.position()).norm() <= recovery.other_nodes_radius_m
        };
        if self.unplaced_segments.contains(&segment) {
            return Ok(None);
        }
        let near: Vec<usize> = (0..self.map.nodes.len()).filter(|&id| others(id)).collect();
        if near.is_empty() {
            return Ok(None);
        }
        let points = node.sensor_points();
        let scan = self.scan_of(to, &points);
        // A segment placed by the odometry is searched for in the window a prediction without
        // odometry gets, where a match may share little with the map; another, in the widest.
        let measured = self.measured_segments.contains(&segment);
        let (window_half, heading_half, gate) = if measured {
            let c = &self.config;
            (c.window_half_no_odometry_m, c.heading_half_compass_deg, 0.0)
        } else {
            (
                recovery.max_window_half_m,
                recovery.max_heading_half_deg,
                0.3,
            )
        };
        let prediction = Prediction {
            source: PredictionSource::WiderWindow,
            position: node.position(),
            attitude: attitude_of(&node.world_from_sensor),
            heading_prior: HeadingPrior::LastNode,
            heading_half,
            window_half,
            prior_sigma_m: f64::INFINITY,
            motion_sigma_m: f64::INFINITY,
            measured: false,
        };
        let query = Sdem::from_points(&points, &prediction.attitude, &self.config.sdem)?;
        let tolerance = 0.2 + prediction.window_half[0].max(prediction.window_half[1]);
        let scored = (self.map).overlaps_among(
            near.iter().copied(),
            &query,
            &prediction.position,
            f64::INFINITY,
            tolerance,
        );
        let Some(&(first, cells)) = scored.first() else {
            return Ok(None);
        };
        if cells < self.config.min_reference_overlap_cells {
            return Ok(None);
        }
        let other = self.map.nodes[first].segment;
        let references: Vec<(usize, usize)> = (scored.into_iter())
            .filter(|&(id, c)| {
                self.map.nodes[id].segment == other && c >= self.config.min_reference_overlap_cells
            })
            .take(2 * self.config.max_reference_nodes)
            .collect();
        let search = self.search();
        let start = std::time::Instant::now();
        let mut attempt = Attempt::new(&prediction, &references);
        let found = search.match_prediction(&scan, &query, &prediction, references, true, gate);
        let outcome = match found {
            Ok(mut matched) => {
                let reason = search.verdict(&mut matched, false, true, false);
                attempt.record(&matched, reason);
                attempt.accepted.then_some(matched)
            }
            Err(e) if e.is_no_match() => {
                attempt.reason = e.to_string();
                None
            }
            Err(e) => return Err(e),
        };
        attempt.time_ms = start.elapsed().as_secs_f64() * 1e3;
        attempts.push(attempt);
        Ok(outcome)
    }

    /// [`Self::join_elsewhere`]'s search without a prior, by place descriptor.
    fn join_by_place(&self, to: usize, attempts: &mut Vec<Attempt>) -> Result<Option<Matched>> {
        let segment = self.map.nodes[to].segment;
        let points = self.map.nodes[to].sensor_points();
        let scan = self.scan_of(to, &points);
        let keep = |id: usize| self.map.nodes[id].segment != segment;
        let found = self
            .search()
            .find_in_map(&scan, keep, Some(JOIN_CANDIDATES), attempts)?;
        Ok(match found {
            Some(Located::Found { matched, .. }) => Some(matched),
            _ => None,
        })
    }

    /// Node `node`'s scan (its points, one per S-DEM cell, `points`) as the loop takes a scan:
    /// its roll and pitch as its segment's estimate has them, with its reading's σ.
    fn scan_of<'p>(&self, node: usize, points: &'p [crate::geometry::Vec3]) -> ScanInput<'p> {
        let n = &self.map.nodes[node];
        let a = attitude_of(&n.world_from_sensor);
        ScanInput {
            scan_index: n.scan_index,
            points_in_sensor: points,
            attitude: Some(n.attitude_reading.map_or(a, |r| Attitude {
                sigma: r.sigma,
                ..a
            })),
            odometry: None,
        }
    }
}
