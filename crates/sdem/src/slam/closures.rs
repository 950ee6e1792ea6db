//! Loop closure in any direction, checked against the other closures; then, in a map of several
//! segments, a join with another segment ([`super::joins`]).
//!
//! **Proposal.** Within a segment, where poses are known, the older nodes near the new one are
//! scored by how many of its scan's cells their points explain at the current estimates
//! ([`crate::map::Map::overlaps_among`]): that counts what both saw, whichever way each scan
//! faced, so a robot coming back the other way (its scanner seeing only its front half) is
//! matched with the nodes that looked where it looks now. Across segments, whose relative place
//! is unknown, nodes are proposed by their place descriptors over every heading
//! ([`super::joins`]).
//!
//! **Verification.** The exact search over every heading, with the runner-up search, against
//! the candidate and its neighbours merged ([`crate::map::verify_loop_closure`]).
//!
//! **Consistency** (after Mangelson et al.'s pairwise consistency maximization, ICRA 2018).
//! Two closures `a` (i→j) and `b` (k→l) of one segment form a loop with the graph's relative
//! poses j→l and k→i; if both are right, the loop returns to where it began, within the
//! closures' covariances and the drift the graph may hold between the nodes (1 cm and 0.5° per
//! metre apart, plus 1 cm). A verified closure that agrees with every accepted one is
//! accepted. One that disagrees with some is accepted only when more verified closures agree
//! with it than with any of those, which are then withdrawn from the graph; otherwise it is
//! rejected, saying with which closures it disagrees.

use super::step::{Attempt, SegmentJoin};
use super::Slam;
use crate::error::Result;
use crate::geometry::attitude_of;
use crate::map::{verify_loop_closure_against, LoopClosure};
use crate::posegraph::EdgeKind;
use crate::sdem::Sdem;
use nalgebra::Matrix6;

/// Drift the graph may hold between two nodes: translation, metres per metre apart.
const DRIFT_PER_M: f64 = 0.01;
/// … and at no distance, metres.
const DRIFT_FLOOR_M: f64 = 0.01;
/// … rotation, degrees per metre apart.
const DRIFT_DEG_PER_M: f64 = 0.5;
/// … and at no distance, degrees.
const DRIFT_FLOOR_DEG: f64 = 0.3;

/// What loop closure did at one node.
#[derive(Debug, Default)]
pub(super) struct Closing {
    /// The closures checked, accepted or not.
    pub checked: Vec<LoopClosure>,
    /// Accepted closures withdrawn, as (from, to).
    pub withdrawn: Vec<(usize, usize)>,
    /// Segments joined.
    pub joined: Vec<SegmentJoin>,
    /// The searches tried to join segments.
    pub attempts: Vec<Attempt>,
    /// The graph of this segment changed and needs optimizing.
    pub changed: Option<usize>,
    /// The newest node that accepted a loop closure before this step (the solve frees what
    /// drifted since).
    pub anchored: Option<usize>,
}

impl Slam {
    /// Step 4: the loop closures of node `to` within its segment, checked against the others,
    /// and, when the map has other segments, a join with one of them.
    pub(super) fn close_loops(&mut self, to: usize) -> Result<Closing> {
        let mut closing = Closing {
            anchored: self.upkeep.last_closure(),
            ..Closing::default()
        };
        if !self.config.loop_closure.enabled {
            return Ok(closing);
        }
        // Within a few stops of an accepted closure none is looked for (on a route that
        // retraces itself every stop could close one; one in a few keeps the map as well).
        let places = match self.upkeep.closure_paused(to) {
            true => Vec::new(),
            false => {
                let near = self.loop_candidate_nodes(to);
                self.upkeep.bring(&mut self.map, &near)?;
                self.loop_candidates(to, &near)?
            }
        };
        for place in places {
            let prior = self.map.nodes[to].world_from_sensor;
            let mut closure = verify_loop_closure_against(
                &self.map,
                &place,
                to,
                &prior,
                &self.config.sdem,
                &self.config.localize,
                &self.config.loop_closure,
            )?;
            if closure.accepted {
                self.admit(&mut closure, &mut closing);
                if closure.accepted {
                    self.upkeep.closure_accepted(to);
                }
            }
            closing.checked.push(closure);
        }
        if self.segments().len() > 1 {
            self.join_elsewhere(to, &mut closing)?;
        }
        Ok(closing)
    }

    /// The older nodes of node `to`'s segment near it (not among its recent nodes) that may
    /// close a loop with it: within `search_radius_m`, at most
    /// [`super::GrowthOptions::closure_candidate_nodes`], the nearest.
    fn loop_candidate_nodes(&self, to: usize) -> Vec<usize> {
        let node = &self.map.nodes[to];
        let recent = self.recent_nodes(node.segment, to);
        self.candidates_near(
            (node.segment, &node.position()),
            self.config.loop_closure.search_radius_m,
            self.config.growth.closure_candidate_nodes,
            |id| id < to && !recent.contains(&id),
        )
    }

    /// The places to close a loop with at node `to`: of the nodes `near` (see
    /// [`Self::loop_candidate_nodes`]), those that explain enough of its scan's cells at the
    /// current estimates, most first; each place is such a node with the others of them within
    /// `reference_radius_m` of it (at most `reference_nodes`), and no two places start within
    /// that radius of each other; at most `max_candidates` places.
    fn loop_candidates(&self, to: usize, near: &[usize]) -> Result<Vec<Vec<usize>>> {
        let config = &self.config.loop_closure;
        let node = &self.map.nodes[to];
        if near.is_empty() {
            return Ok(Vec::new());
        }
        let query = Sdem::from_points(
            &node.sensor_points(),
            &attitude_of(&node.world_from_sensor),
            &self.config.sdem,
        )?;
        let seeing: Vec<usize> = (self.map)
            .overlaps_among(
                near.iter().copied(),
                &query,
                &node.position(),
                f64::INFINITY,
                0.2,
            )
            .into_iter()
            .filter(|&(_, cells)| cells >= config.min_overlap_cells)
            .map(|(id, _)| id)
            .collect();
        let apart = |a: usize, b: usize| {
            (self.map.nodes[a].position() - self.map.nodes[b].position()).norm()
        };
        let mut places: Vec<Vec<usize>> = Vec::new();
        for &first in &seeing {
            if places.len() >= config.max_candidates {
                break;
            }
            if places
                .iter()
                .any(|p| apart(p[0], first) <= config.reference_radius_m)
            {
                continue;
            }
            let place: Vec<usize> = (seeing.iter().copied())
                .filter(|&n| n == first || apart(n, first) <= config.reference_radius_m)
                .take(config.reference_nodes.max(1))
                .collect();
            places.push(place);
        }
        Ok(places)
    }

    /// A closure the match verified, checked against the other closures of its segment:
    /// accepted (its edge added, the closures it outweighs withdrawn) or rejected.
    fn admit(&mut self, closure: &mut LoopClosure, closing: &mut Closing) {
        let segment = self.map.nodes[closure.to].segment;
        let pool: Vec<LoopClosure> = (self.closure_pool.iter())
            .filter(|c| self.map.nodes[c.to].segment == segment)
            .cloned()
            .collect();
        let conflicts: Vec<&LoopClosure> = (pool.iter())
            .filter(|c| c.accepted && self.loop_error_sigmas(closure, c) > self.max_loop_sigmas())
            .collect();
        let support = |c: &LoopClosure| {
            (pool.iter().chain(std::iter::once(&*closure)))
                .filter(|o| (o.from, o.to) != (c.from, c.to))
                .filter(|o| self.loop_error_sigmas(c, o) <= self.max_loop_sigmas())
                .count()
        };
        let own = support(closure);
        let strongest = conflicts.iter().map(|c| support(c)).max();
        if let Some(strongest) = strongest.filter(|&s| s >= own) {
            let names: Vec<String> = (conflicts.iter())
                .map(|c| format!("{}→{}", c.from, c.to))
                .collect();
            closure.accepted = false;
            closure.reason = format!(
                "inconsistent with the accepted loop closures {} ({} verified closures agree \
                 with them, {own} with this one)",
                names.join(", "),
                strongest
            );
            self.closure_pool.push(closure.clone());
            return;
        }
        for c in &conflicts {
            self.withdraw(c.from, c.to);
            closing.withdrawn.push((c.from, c.to));
        }
        self.add_loop_closure_edge(closure);
        self.closure_pool.push(closure.clone());
        closing.changed = Some(segment);
    }

    /// The allowed loop error of two closures, in standard deviations.
    fn max_loop_sigmas(&self) -> f64 {
        self.config.loop_closure.max_loop_sigmas
    }

    /// How far the loop of closures `a` and `b` (with the graph's relative poses between their
    /// ends) is from returning to where it began, in standard deviations (0 for the same
    /// closure).
    fn loop_error_sigmas(&self, a: &LoopClosure, b: &LoopClosure) -> f64 {
        let (Some(ta), Some(tb)) = (a.from_from_to, b.from_from_to) else {
            return f64::INFINITY;
        };
        if (a.from, a.to) == (b.from, b.to) {
            return 0.0;
        }
        let pose = |n: usize| self.map.nodes[n].world_from_sensor;
        let between = |x: usize, y: usize| pose(x).inverse() * pose(y);
        let error = ta * between(a.to, b.to) * tb.inverse() * between(b.from, a.from);
        let apart = (pose(a.to).translation.vector - pose(b.to).translation.vector).norm()
            + (pose(a.from).translation.vector - pose(b.from).translation.vector).norm();
        let floor = self.config.edge_sigma_floor_m;
        let sigma_t = (self.closure_variance_t(a)
            + self.closure_variance_t(b)
            + 2.0 * floor * floor
            + (DRIFT_FLOOR_M + DRIFT_PER_M * apart).powi(2))
        .sqrt();
        let sigma_r = (DRIFT_FLOOR_DEG + DRIFT_DEG_PER_M * apart).to_radians();
        let e_t = error.translation.vector.norm() / sigma_t;
        let e_r = error.rotation.angle() / sigma_r;
        (e_t * e_t + e_r * e_r).sqrt()
    }

    /// The largest translational variance of a closure's match, m².
    fn closure_variance_t(&self, c: &LoopClosure) -> f64 {
        c.covariance.as_ref().map_or(0.0, |m: &Matrix6<f64>| {
            m.fixed_view::<3, 3>(0, 0).symmetric_eigenvalues().max()
        })
    }

    /// Removes the accepted closure `from`→`to` from the graph (its edge and the list).
    fn withdraw(&mut self, from: usize, to: usize) {
        self.edges
            .retain(|e| !(e.kind == EdgeKind::LoopClosure && e.from == from && e.to == to));
        self.loop_closures
            .retain(|c| !(c.from == from && c.to == to));
        for c in self.closure_pool.iter_mut() {
            if c.from == from && c.to == to {
                c.accepted = false;
                c.reason = "withdrawn: later closures agree with one another, not with it".into();
            }
        }
    }
}

#[cfg(test)]
mod tests {
    use super::*;
    use crate::geometry::{pose_from_parts, Attitude, Pose, Vec3};
    use crate::map::Node;
    use crate::slam::SlamOptions;

    /// A map of six nodes 1 m apart along x, each with a box room's walls as its scan.
    fn straight_map() -> Slam {
        let mut slam = Slam::new(SlamOptions::default()).unwrap();
        let mut points = Vec::new();
        for i in -20..=20 {
            for j in -10..=10 {
                let (u, v) = (i as f64 * 0.1, j as f64 * 0.1);
                points.extend([
                    Vec3::new(2.0, u, v),
                    Vec3::new(u, 2.0, v),
                    Vec3::new(u, -2.0, v),
                ]);
            }
        }
        for id in 0..6 {
            let pose = pose_from_parts(Vec3::new(id as f64, 0.0, 0.0), Attitude::default());
            let sdem = &slam.config.sdem;
            let node = Node::from_scan(id, id, pose, None, &points, sdem).unwrap();
            slam.map.nodes.push(node);
        }
        slam
    }

    /// A verified closure `from`→`to` that measures `from_from_to`.
    fn closure(from: usize, to: usize, from_from_to: Pose) -> LoopClosure {
        LoopClosure {
            accepted: true,
            from_from_to: Some(from_from_to),
            ..LoopClosure::unchecked(from, to)
        }
    }

    /// What the graph says `from`→`to` is, moved by `off` metres along y.
    fn measured(slam: &Slam, from: usize, to: usize, off: f64) -> Pose {
        let pose = |n: usize| slam.map.nodes[n].world_from_sensor;
        nalgebra::Translation3::new(0.0, off, 0.0) * (pose(from).inverse() * pose(to))
    }

    #[test]
    fn a_closure_that_disagrees_with_the_accepted_ones_is_rejected_naming_them() {
        let mut slam = straight_map();
        let mut closing = Closing::default();
        for (from, to) in [(0, 4), (1, 5)] {
            let mut c = closure(from, to, measured(&slam, from, to, 0.0));
            slam.admit(&mut c, &mut closing);
            assert!(c.accepted, "{}", c.reason);
        }
        // 30 cm off what both agree on: a wrong closure (a place that looks alike).
        let mut wrong = closure(0, 5, measured(&slam, 0, 5, 0.3));
        slam.admit(&mut wrong, &mut closing);
        assert!(!wrong.accepted);
        assert!(
            wrong.reason.contains("0→4") && wrong.reason.contains("1→5"),
            "{}",
            wrong.reason
        );
        assert_eq!(slam.loop_closures.len(), 2);
        assert!(closing.withdrawn.is_empty());
        // 5 mm off is within the closures' and the graph's uncertainty: accepted.
        let mut right = closure(0, 5, measured(&slam, 0, 5, 0.005));
        slam.admit(&mut right, &mut closing);
        assert!(right.accepted, "{}", right.reason);
        assert_eq!(slam.loop_closures.len(), 3);
    }

    #[test]
    fn a_wrong_closure_accepted_first_is_withdrawn_when_more_closures_disagree_with_it() {
        let mut slam = straight_map();
        let mut closing = Closing::default();
        let mut wrong = closure(0, 4, measured(&slam, 0, 4, 0.4));
        slam.admit(&mut wrong, &mut closing);
        assert!(wrong.accepted, "alone, nothing contradicts it");
        for (from, to) in [(1, 5), (0, 5)] {
            let mut c = closure(from, to, measured(&slam, from, to, 0.0));
            slam.admit(&mut c, &mut closing);
            if (from, to) == (0, 5) {
                // Two right closures agree with each other, against the one wrong one.
                assert!(c.accepted, "{}", c.reason);
            }
        }
        assert_eq!(closing.withdrawn, vec![(0, 4)]);
        assert!(slam.loop_closures.iter().all(|c| (c.from, c.to) != (0, 4)));
        assert!(!(slam.edges.iter()).any(|e| e.kind == EdgeKind::LoopClosure && e.to == 4));
    }
}
