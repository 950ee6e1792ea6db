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
//! **Three weak matches that agree.** A match by place with no doubt and no rival that
//! matches fewer cells than a match without a prior needs (a scan facing back along a run sees
//! a little of what many stops saw) is kept as a weak match of its node. When a later node of
//! the same segment finds a weak match into the same segment, and [`WEAK_AGREEING`] earlier
//! ones each place the segment within [`WEAK_AGREE_M`] and [`WEAK_AGREE_DEG`] of where it does
//! at both nodes, the segments are joined by all of them. Three scans taken apart (the retry
//! rule below) that each find the same wrong place, all off the same way, is what this takes
//! to be unlikely.
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
use crate::geometry::Pose;
use crate::geometry::{attitude_of, Attitude};
use crate::map::LoopClosure;
use crate::map::Map;
use crate::posegraph::{Edge, EdgeKind};
use crate::sdem::Sdem;
use nalgebra::Matrix6;

/// Nodes of other segments tried per join by place.
const JOIN_CANDIDATES: usize = 3;
/// Two weak matches agree when each places the other's node within this of where it places
/// it, metres… (on the route bench's second runs, relocalizations with places of 20 nodes
/// that matched 44–63 % of the cells were 0.1–1.3 cm and 0.05–0.14° from the truth)
pub(super) const WEAK_AGREE_M: f64 = 0.03;
/// … and turned by at most this, degrees.
pub(super) const WEAK_AGREE_DEG: f64 = 0.5;
/// A weak match joins its segment when this many earlier ones of the segment agree with it.
/// Alone, a weak match is often wrong: of eight on the route bench (`second-run` seeds 8, 11
/// and 12, `half-blocked` seed 4), four lay 1.2–3.6 m and 32–180° from the truth, with no doubt
/// and no rival (a corridor's half turn, a repeated stretch), and four within 0.3 cm and 0.05°.
/// No wrong one agreed with another; but two that agree could be one symmetry of the scene
/// seen twice, so three in all are asked for.
pub(super) const WEAK_AGREEING: usize = 2;
/// Weak matches kept per segment, the latest.
const WEAK_KEPT: usize = 16;

/// A weak match of a node ([`super::map_search::MapSearch::find_in_map_or_weak`]), kept until
/// another node of its segment finds one that agrees.
#[derive(Debug, Clone)]
pub(super) struct WeakJoin {
    /// The node whose scan matched.
    node: usize,
    /// The node of the other segment it was matched against, and the match relative to it (a
    /// later solve may move both).
    link: usize,
    link_from_node: Pose,
    matched: Matched,
}

impl WeakJoin {
    /// Node `node`'s weak match `matched`.
    pub(super) fn new(map: &Map, node: usize, matched: Matched) -> Self {
        let link = matched.references[0].0;
        let link_from_node =
            map.nodes[link].world_from_sensor.inverse() * matched.world_from_sensor;
        Self {
            node,
            link,
            link_from_node,
            matched,
        }
    }

    /// The node's pose in the frame of the link's segment, as this match has it, from where the
    /// link stands now.
    fn world_from_node(&self, map: &Map) -> Pose {
        map.nodes[self.link].world_from_sensor * self.link_from_node
    }

    /// The frame of the link's segment from the frame of the node's, as this match has it.
    fn other_from_segment(&self, map: &Map) -> Pose {
        self.world_from_node(map) * map.nodes[self.node].world_from_sensor.inverse()
    }
}
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
            Some(matched) => Some((matched, Vec::new())),
            None => self.join_by_place(to, &mut closing.attempts)?,
        };
        let Some((matched, earlier)) = found else {
            return Ok(());
        };
        let (edge, mut closure) = self.join_link(to, &matched);
        let joined = self.join_segments(edge, &matched.world_from_sensor)?;
        closure.correction_m = Some(joined.moved_m);
        for earlier in earlier {
            // The weak matches that this one agrees with are edges of the joined graph too, as
            // they placed their nodes from the nodes they were matched against.
            let matched = Matched {
                world_from_sensor: earlier.world_from_node(&self.map),
                ..earlier.matched
            };
            let (edge, mut other) = self.join_link(earlier.node, &matched);
            self.edges.push(edge);
            other.correction_m = Some(joined.moved_m);
            self.loop_closures.push(other.clone());
            self.closure_pool.push(other.clone());
            closing.checked.push(other);
        }
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

    /// [`Self::join_elsewhere`]'s search without a prior, by place descriptor: a match taken,
    /// or a weak match that agrees with [`WEAK_AGREEING`] earlier ones of the segment (returned
    /// too, for their edges). A weak match that does not is kept for the nodes to come.
    fn join_by_place(
        &mut self,
        to: usize,
        attempts: &mut Vec<Attempt>,
    ) -> Result<Option<(Matched, Vec<WeakJoin>)>> {
        let segment = self.map.nodes[to].segment;
        let points = self.map.nodes[to].sensor_points();
        let scan = self.scan_of(to, &points);
        let keep = |id: usize| self.map.nodes[id].segment != segment;
        let search =
            self.search()
                .find_in_map_or_weak(&scan, keep, Some(JOIN_CANDIDATES), attempts)?;
        if let Some(Located::Found { matched, .. }) = search.found {
            return Ok(Some((matched, Vec::new())));
        }
        let Some(weak) = search.weak else {
            return Ok(None);
        };
        let weak = WeakJoin::new(&self.map, to, weak);
        let agreeing: Vec<(usize, (f64, f64))> = (self.weak_joins.iter().enumerate())
            .filter_map(|(k, earlier)| self.agreement(earlier, &weak).map(|a| (k, a)))
            .collect();
        if agreeing.len() < WEAK_AGREEING {
            self.keep_weak(weak);
            return Ok(None);
        }
        let (apart_m, turned_deg) = (agreeing.iter())
            .fold((0.0f64, 0.0f64), |(m, d), (_, (a, t))| {
                (m.max(*a), d.max(*t))
            });
        let mut taken: Vec<usize> = agreeing.iter().map(|(k, _)| *k).collect();
        taken.sort_unstable();
        let earlier: Vec<WeakJoin> = (taken.iter().rev())
            .map(|&k| self.weak_joins.remove(k))
            .collect();
        let nodes: Vec<usize> = earlier.iter().map(|w| w.node).collect();
        let cost = Some(weak.matched.cost);
        if let Some(a) = attempts.iter_mut().rev().find(|a| a.cost == cost) {
            a.accepted = true;
            a.reason = format!(
                "taken with the weak matches of nodes {nodes:?}, which place this segment within \
                 {:.1} cm and {:.2}° of where this one does (each alone matches fewer cells than \
                 a match without a prior needs)",
                apart_m * 100.0,
                turned_deg
            );
        }
        Ok(Some((weak.matched, earlier)))
    }

    /// Whether weak matches `a` and `b` agree: nodes of one segment, matched into one other
    /// segment, each placing both nodes within [`WEAK_AGREE_M`] and [`WEAK_AGREE_DEG`] of
    /// where the other places them. `Some` with the largest distance (metres) and turn
    /// (degrees) between them, when they do.
    fn agreement(&self, a: &WeakJoin, b: &WeakJoin) -> Option<(f64, f64)> {
        let nodes = &self.map.nodes;
        let one_segment = nodes[a.node].segment == nodes[b.node].segment;
        let one_other = nodes[a.link].segment == nodes[b.link].segment;
        if a.node == b.node
            || !one_segment
            || !one_other
            || nodes[a.node].segment == nodes[a.link].segment
        {
            return None;
        }
        let at = [
            &nodes[a.node].world_from_sensor,
            &nodes[b.node].world_from_sensor,
        ];
        let (apart_m, turned_deg) = frames_apart(
            &a.other_from_segment(&self.map),
            &b.other_from_segment(&self.map),
            at,
        );
        (apart_m <= WEAK_AGREE_M && turned_deg <= WEAK_AGREE_DEG).then_some((apart_m, turned_deg))
    }

    /// Keeps a weak match, at most [`WEAK_KEPT`] of its segment (the latest), none of a node
    /// whose segment is joined to its link's since.
    fn keep_weak(&mut self, weak: WeakJoin) {
        let nodes = &self.map.nodes;
        let segment = nodes[weak.node].segment;
        self.weak_joins
            .retain(|w| nodes[w.node].segment != nodes[w.link].segment);
        let kept = (self.weak_joins.iter())
            .filter(|w| nodes[w.node].segment == segment)
            .count();
        if kept >= WEAK_KEPT {
            if let Some(k) = (self.weak_joins.iter()).position(|w| nodes[w.node].segment == segment)
            {
                self.weak_joins.remove(k);
            }
        }
        self.weak_joins.push(weak);
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

/// How far apart two estimates of one frame change (`from_a`, `from_b`) put the poses `at`: the
/// largest distance (metres) and turn (degrees) between where each puts them.
fn frames_apart(from_a: &Pose, from_b: &Pose, at: [&Pose; 2]) -> (f64, f64) {
    at.iter().fold((0.0f64, 0.0f64), |(apart, turned), pose| {
        let d = (from_a * *pose).inverse() * (from_b * *pose);
        (
            apart.max(d.translation.vector.norm()),
            turned.max(d.rotation.angle().to_degrees()),
        )
    })
}

#[cfg(test)]
mod tests {
    use super::*;
    use nalgebra::{Translation3, UnitQuaternion, Vector3};

    fn pose(x: f64, y: f64, yaw_deg: f64) -> Pose {
        Pose::from_parts(
            Translation3::new(x, y, 0.0),
            UnitQuaternion::from_axis_angle(&Vector3::z_axis(), yaw_deg.to_radians()),
        )
    }

    /// Two estimates of a segment's frame agree only where both put both nodes within the
    /// bounds: a turn a few tenths of a degree about one node moves the other, metres away.
    #[test]
    fn weak_matches_agree_only_where_they_place_both_nodes_alike() {
        let frame = pose(12.0, -3.0, 170.0);
        let nodes = [pose(0.0, 0.0, 0.0), pose(2.0, 0.5, 5.0)];
        let at = [&nodes[0], &nodes[1]];
        let (apart, turned) = frames_apart(&frame, &frame, at);
        assert!(apart < 1e-12 && turned < 1e-9, "{apart} {turned}");
        // 2 cm along x in the other segment's frame: agrees.
        let shifted = pose(0.02, 0.0, 0.0) * frame;
        let (apart, turned) = frames_apart(&frame, &shifted, at);
        assert!((apart - 0.02).abs() < 1e-9 && turned < 1e-9);
        assert!(apart <= WEAK_AGREE_M);
        // 0.4° about the first node: that node does not move, the second moves 1.4 cm.
        let about_first = frame * nodes[0] * pose(0.0, 0.0, 0.4) * nodes[0].inverse();
        let (apart, turned) = frames_apart(&frame, &about_first, at);
        let expected = 2.0 * (2.0f64.hypot(0.5)) * (0.2f64.to_radians()).sin();
        assert!((apart - expected).abs() < 1e-9, "{apart} {expected}");
        assert!((turned - 0.4).abs() < 1e-9 && turned <= WEAK_AGREE_DEG);
        // 1.5° about the first node moves the second 5.4 cm: beyond the bound.
        let turned_more = frame * nodes[0] * pose(0.0, 0.0, 1.5) * nodes[0].inverse();
        let (apart, _) = frames_apart(&frame, &turned_more, at);
        assert!(apart > WEAK_AGREE_M, "{apart}");
    }
}
