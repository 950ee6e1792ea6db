//! Where a stop's scan may have been taken, before it is matched: one hypothesis per source
//! (the odometry, the last motion repeated, no motion, the nodes the last node is linked to),
//! each with the search window and heading window its source allows.
//!
//! A continuously moving LiDAR needs the constant-velocity guess; a stop-and-go robot whose
//! tracks slipped, or that was carried, is better served by "it did not move" or by the place
//! it came from. The loop tries them in order and takes the first trusted match
//! ([`super::Slam::add_scan`]); the window grows around the best one when none is trusted.
//! Where a match leaves a direction free, the prediction sets the position along it
//! ([`take_prediction_along`]).

use super::map_search::Matched;
use super::step::{HeadingPrior, PredictionSource};
use super::{ScanInput, Slam};
use crate::doubt::Doubt;
use crate::geometry::{attitude_of, pose_from_parts, wrap_pi, Attitude, Pose, Vec3};
use crate::localize::Diagnostics;

/// Where a scan is expected before it is matched, and the search's window and prior around it.
#[derive(Debug, Clone)]
pub(super) struct Prediction {
    /// Where the hypothesis comes from.
    pub source: PredictionSource,
    /// The predicted position, world frame.
    pub position: Vec3,
    /// The predicted attitude (roll and pitch from the reading, or the last node's).
    pub attitude: Attitude,
    /// Where the heading came from.
    pub heading_prior: HeadingPrior,
    /// The heading window's half-width, degrees.
    pub heading_half: f64,
    /// The translation window's half-size, metres.
    pub window_half: [f64; 3],
    /// The prediction's σ, metres, weighed into the cost.
    pub prior_sigma_m: f64,
    /// How far off the measured motion may be, metres (one σ): the variance its position
    /// carries along a direction the scans leave free.
    pub motion_sigma_m: f64,
    /// The prediction measures the motion (odometry): along a direction the scans leave free,
    /// its position is taken, with its uncertainty.
    pub measured: bool,
}

impl Prediction {
    /// The predicted pose.
    pub fn pose(&self) -> Pose {
        pose_from_parts(self.position, self.attitude)
    }

    /// This prediction with its window grown to `max_half` and its heading window to
    /// `max_heading_deg` (neither shrinks).
    pub fn grown(&self, max_half: &[f64; 3], max_heading_deg: f64) -> Self {
        let mut window_half = self.window_half;
        for (h, max) in window_half.iter_mut().zip(max_half) {
            *h = h.max(*max);
        }
        Self {
            source: PredictionSource::WiderWindow,
            window_half,
            heading_half: self.heading_half.max(max_heading_deg),
            measured: false,
            ..self.clone()
        }
    }

    /// This prediction from another source.
    pub fn with_source(&self, source: PredictionSource) -> Self {
        Self {
            source,
            ..self.clone()
        }
    }

    /// Whether `pose` lies where this prediction allows: within two of its motion's σ of its
    /// position along each axis (at least its window, which the widest recovery window caps)
    /// and its heading within the heading window.
    pub fn allows(&self, pose: &Pose) -> bool {
        let d = pose.translation.vector - self.position;
        let turn = wrap_pi(attitude_of(pose).yaw - self.attitude.yaw)
            .abs()
            .to_degrees();
        let within = |i: usize| d[i].abs() <= self.window_half[i].max(2.0 * self.motion_sigma_m);
        (0..3).all(within) && turn <= self.heading_half
    }

    /// Whether `other`'s search lies inside this one's: its position within a quarter of this
    /// window, the same heading, and no wider windows.
    fn covers(&self, other: &Prediction) -> bool {
        let d = other.position - self.position;
        let inside = (0..3).all(|i| d[i].abs() <= 0.25 * self.window_half[i]);
        let narrower = (0..3).all(|i| other.window_half[i] <= self.window_half[i]);
        let turn = wrap_pi(other.attitude.yaw - self.attitude.yaw)
            .abs()
            .to_degrees();
        inside && narrower && turn + other.heading_half <= self.heading_half + 0.5
    }
}

impl Slam {
    /// The hypotheses for `scan` after node `last` (the robot's last stop), in the order they
    /// are tried: the odometry's motion; the last motion repeated; no motion; the nodes linked
    /// to `last`. A hypothesis whose search lies inside an earlier one's is left out.
    pub(super) fn predictions(&self, scan: &ScanInput, last: usize) -> Vec<Prediction> {
        let last_node = &self.map.nodes[last];
        let last_pose = last_node.world_from_sensor;
        let last_attitude = attitude_of(&last_pose);
        // The reading's tilt with its σ (what `attitude_corrected` judges a match by), else the
        // last node's with the default σ.
        let (roll, pitch, sigma) = scan.attitude.map_or(
            (last_attitude.roll, last_attitude.pitch, Default::default()),
            |a| (a.roll, a.pitch, a.sigma),
        );
        let level = |yaw| Attitude {
            sigma,
            ..Attitude::new(roll, pitch, yaw)
        };
        let compass = self.compass(scan);
        let config = &self.config;
        // Without odometry: the compass's heading, else the motion's.
        let unmeasured = |source, pose: &Pose, prior: HeadingPrior| {
            let (yaw, heading_prior, heading_half) = match compass {
                Some((yaw, half)) => (yaw, HeadingPrior::Compass, half),
                None => (
                    attitude_of(pose).yaw,
                    prior,
                    config.heading_half_no_prior_deg,
                ),
            };
            Prediction {
                source,
                position: pose.translation.vector,
                attitude: level(yaw),
                heading_prior,
                heading_half,
                window_half: config.window_half_no_odometry_m,
                // With odometry these are the alternatives to a measured motion: no prior pins
                // them, so that a direction the scans leave free shows as a doubt.
                prior_sigma_m: match scan.odometry {
                    Some(_) => f64::INFINITY,
                    None => config.prior_sigma_no_odometry_m,
                },
                motion_sigma_m: f64::INFINITY,
                measured: false,
            }
        };
        let mut all = Vec::new();
        if let Some(odometry) = &scan.odometry {
            let motion = odometry.previous_sensor_from_sensor();
            let pose = last_pose * motion;
            // The odometry's error grows with the distance it measured, on every axis (a 1.5 m
            // step on the route bench climbed 12 cm more than the odometry said).
            let sigma = config
                .prior_sigma_m
                .max(config.odometry_error_per_m * motion.translation.vector.norm());
            // No wider than the widest window a recovery searches: an odometry that claims a
            // step of a kilometre (a glitch, a wrong unit) made a window of 2.9 billion
            // candidates, and the run stopped with an error about the window. Capped, the
            // prediction simply finds nothing there, and the other hypotheses and the recovery
            // take over, as after a step the window does not hold.
            let mut window_half = config.window_half_m;
            for (h, widest) in window_half
                .iter_mut()
                .zip(config.recovery.max_window_half_m)
            {
                *h = h.max(2.0 * sigma).min(widest.max(*h));
            }
            all.push(Prediction {
                source: PredictionSource::Odometry,
                position: pose.translation.vector,
                attitude: level(attitude_of(&pose).yaw),
                heading_prior: HeadingPrior::Odometry,
                heading_half: config.heading_half_deg,
                window_half,
                prior_sigma_m: config.prior_sigma_m,
                motion_sigma_m: sigma,
                measured: true,
            });
        }
        if let Some(before) = self.stop_before(last) {
            let motion = self.map.nodes[before].world_from_sensor.inverse() * last_pose;
            let pose = last_pose * motion;
            all.push(unmeasured(
                PredictionSource::ConstantVelocity,
                &pose,
                HeadingPrior::ConstantVelocity,
            ));
        }
        all.push(unmeasured(
            PredictionSource::NoMotion,
            &last_pose,
            HeadingPrior::LastNode,
        ));
        for neighbour in self.linked_nodes(last).into_iter().take(2) {
            let pose = self.map.nodes[neighbour].world_from_sensor;
            all.push(unmeasured(
                PredictionSource::Neighbour,
                &pose,
                HeadingPrior::LastNode,
            ));
        }
        let mut kept: Vec<Prediction> = Vec::new();
        for p in all {
            if !kept.iter().any(|k| k.covers(&p)) {
                kept.push(p);
            }
        }
        kept
    }

    /// The compass reading of `scan` and the heading window it allows, degrees: the configured
    /// half-width, or three σ of the reading when that is wider; `None` without a reading or
    /// with one too uncertain to say anything (3σ of a quarter turn or more).
    pub(super) fn compass(&self, scan: &ScanInput) -> Option<(f64, f64)> {
        let a = scan.attitude?;
        let three_sigma: f64 = 3.0 * a.sigma.yaw.to_degrees();
        (three_sigma < 90.0).then(|| (a.yaw, three_sigma.max(self.config.heading_half_compass_deg)))
    }

    /// The stop before node `last` on the robot's way, when it is in the same segment and run
    /// (the last motion is known).
    fn stop_before(&self, last: usize) -> Option<usize> {
        let before = last.checked_sub(1)?;
        let (a, b) = (&self.map.nodes[before], &self.map.nodes[last]);
        (a.segment == b.segment && a.run == b.run).then_some(before)
    }

    /// The nodes linked to `node` by an edge of the pose graph, other than the stop just
    /// before it, farthest from it first (the places the robot came from or closed a loop
    /// with, where it may have gone back to).
    fn linked_nodes(&self, node: usize) -> Vec<usize> {
        let before = self.stop_before(node);
        let here = self.map.nodes[node].position();
        let mut linked: Vec<usize> = (self.edges.iter())
            .filter_map(|e| match (e.from == node, e.to == node) {
                (true, false) => Some(e.to),
                (false, true) => Some(e.from),
                _ => None,
            })
            .filter(|&n| Some(n) != before)
            .collect();
        linked.sort_unstable();
        linked.dedup();
        linked.sort_by(|&a, &b| {
            let d = |n: usize| (self.map.nodes[n].position() - here).norm();
            d(b).total_cmp(&d(a))
        });
        linked
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
    let along = move_along(pose, &v, predicted);
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

/// Moves `pose` along the unit direction `v` to `predicted`'s place along it; returns the
/// shift, metres.
fn move_along(pose: &mut Pose, v: &Vec3, predicted: &Vec3) -> f64 {
    let t = pose.translation.vector;
    let along = v.dot(&(predicted - t));
    pose.translation.vector = t + v * along;
    along
}

/// The pose of the match `matched`, moved along the direction its scans leave free (the cost's
/// flat direction, else the refinement's weakest when too little faces along it) to the
/// measured `prediction`'s place there: along a ditch the scans' position is their sampling's,
/// the odometry's a measurement (a turned-round stop's match, 22 % of its cells, lay 4.7 cm
/// along the ditch from the truth, the odometry of its 19 cm step 0.9 cm). Only a guess: the
/// covariance and doubts stay as they are ([`take_prediction_along`] is for an edge).
pub(super) fn measured_along_free(matched: &Matched, prediction: &Prediction) -> Pose {
    let mut pose = matched.world_from_sensor;
    let unconstrained = (matched.doubts.iter()).find_map(|d| match d {
        Doubt::Unconstrained { direction, .. } => Some(*direction),
        _ => None,
    });
    if let Some(free) = matched.diagnostics.flat_direction.or(unconstrained) {
        move_along(&mut pose, &Vec3::from(free), &prediction.position);
    }
    pose
}

#[cfg(test)]
mod tests {
    use super::*;

    /// An odometry prediction after a 1.5 m step: ±15 cm horizontally (its window), σ 22.5 cm.
    fn after_long_step() -> Prediction {
        Prediction {
            source: PredictionSource::Odometry,
            position: Vec3::new(1.5, 0.0, 0.0),
            attitude: Attitude::new(0.0, 0.0, 0.2),
            heading_prior: HeadingPrior::Odometry,
            heading_half: 3.0,
            window_half: [0.15, 0.15, 0.08],
            prior_sigma_m: 0.05,
            motion_sigma_m: 0.225,
            measured: true,
        }
    }

    fn at(x: f64, y: f64, z: f64, yaw_deg: f64) -> Pose {
        pose_from_parts(
            Vec3::new(x, y, z),
            Attitude::new(0.0, 0.0, yaw_deg.to_radians()),
        )
    }

    /// A pose is allowed within two of the motion's σ on every axis, beyond a window that does
    /// not reach that far, and within the heading window.
    #[test]
    fn a_measured_prediction_allows_two_sigma_on_every_axis_and_its_heading_window() {
        let p = after_long_step();
        let yaw = 0.2f64.to_degrees();
        assert!(p.allows(&at(1.5, 0.0, 0.0, yaw)));
        assert!(p.allows(&at(1.9, -0.4, 0.12, yaw + 2.9)));
        assert!(!p.allows(&at(1.96, 0.0, 0.0, yaw)), "beyond 2σ along x");
        assert!(!p.allows(&at(1.5, 0.0, -0.46, yaw)), "beyond 2σ in height");
        assert!(
            !p.allows(&at(1.5, 0.0, 0.0, yaw - 3.1)),
            "outside the heading window"
        );
        // Across the half turn the heading wraps.
        let turned = Prediction {
            attitude: Attitude::new(0.0, 0.0, 179f64.to_radians()),
            ..after_long_step()
        };
        assert!(turned.allows(&at(1.5, 0.0, 0.0, -179.0)));
    }
}
