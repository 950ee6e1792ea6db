//! The transform tree of a bag: the fixed mountings of `/tf_static` and the moving frames of
//! `/tf` (a tilting laser's frame), looked up between any two frames.

use super::messages::{pose_of, TransformStamped};
use super::series::{blend_pose, OutOfSpan, Series};
use sdem::geometry::Pose;
use std::collections::HashMap;

/// A frame name without the leading `/` that ROS 1 and some drivers write.
pub fn frame_name(name: &str) -> &str {
    name.trim_start_matches('/')
}

/// The names REP 105 gives frames fixed in the world.
const WORLD_FRAMES: [&str; 4] = ["map", "odom", "world", "earth"];

/// The transforms of a bag.
#[derive(Debug, Clone, Default)]
pub struct TfTree {
    /// `child → (parent, parent_from_child)` from `/tf_static`.
    fixed: HashMap<String, (String, Pose)>,
    /// `child → (parent, parent_from_child over time)` from `/tf`.
    moving: HashMap<String, (String, Series<Pose>)>,
}

/// The transforms of one frame over time, before they are made into a series.
#[derive(Debug, Default)]
pub struct MovingSamples {
    by_child: HashMap<String, (String, Vec<(i64, Pose)>)>,
}

impl MovingSamples {
    /// Adds the transforms of a `/tf` message; unusable rotations are skipped.
    pub fn add(&mut self, transforms: &[TransformStamped]) {
        for t in transforms {
            let Some(pose) = pose_of(t.translation, t.rotation) else {
                continue;
            };
            let child = frame_name(&t.child_frame_id).to_string();
            let parent = frame_name(&t.header.frame_id).to_string();
            let entry = self
                .by_child
                .entry(child)
                .or_insert_with(|| (parent, Vec::new()));
            entry.1.push((t.header.stamp_ns, pose));
        }
    }
}

impl TfTree {
    /// The tree of the fixed transforms (later ones replace earlier ones of the same child)
    /// and of the moving ones.
    pub fn new(fixed: &[TransformStamped], moving: MovingSamples) -> Self {
        let mut tree = TfTree::default();
        for t in fixed {
            if let Some(pose) = pose_of(t.translation, t.rotation) {
                tree.fixed.insert(
                    frame_name(&t.child_frame_id).to_string(),
                    (frame_name(&t.header.frame_id).to_string(), pose),
                );
            }
        }
        tree.moving = moving
            .by_child
            .into_iter()
            .map(|(child, (parent, samples))| (child, (parent, Series::new(samples))))
            .collect();
        tree
    }

    /// `root_from_frame` through fixed transforms, with the root's name.
    fn to_root(&self, frame: &str) -> (String, Pose) {
        let mut name = frame_name(frame).to_string();
        let mut root_from_frame = Pose::identity();
        for _ in 0..64 {
            let Some((parent, parent_from_child)) = self.fixed.get(&name) else {
                break;
            };
            root_from_frame = parent_from_child * root_from_frame;
            name.clone_from(parent);
        }
        (name, root_from_frame)
    }

    /// `target_from_source` through the fixed transforms, `None` when no chain joins them.
    pub fn fixed_transform(&self, target: &str, source: &str) -> Option<Pose> {
        if frame_name(target) == frame_name(source) {
            return Some(Pose::identity());
        }
        let (root_s, root_from_source) = self.to_root(source);
        let (root_t, root_from_target) = self.to_root(target);
        (root_s == root_t).then(|| root_from_target.inverse() * root_from_source)
    }

    /// The parent of a moving frame, when `/tf` moves it.
    pub fn moving_parent(&self, child: &str) -> Option<&str> {
        self.moving.get(frame_name(child)).map(|(p, _)| p.as_str())
    }

    /// When `frame` is a world frame: one of REP 105's names for it (`map`, `odom`, `world`,
    /// `earth`) in which `/tf` moves another frame (the first by name, returned). A robot's
    /// own frame can be a moving parent too (its joints), so the moving alone does not tell.
    pub fn world_frame_moving(&self, frame: &str) -> Option<&str> {
        let parent = frame_name(frame);
        if !WORLD_FRAMES.contains(&parent) {
            return None;
        }
        (self.moving.iter())
            .filter(|(_, (p, _))| p == parent)
            .map(|(child, _)| child.as_str())
            .min()
    }

    /// `parent_from_child` of a moving frame at `stamp`.
    ///
    /// # Errors
    /// [`OutOfSpan`] when `/tf` does not move `child` or has no transform near `stamp`.
    pub fn moving_at(&self, child: &str, stamp: i64) -> Result<Pose, OutOfSpan> {
        match self.moving.get(frame_name(child)) {
            Some((_, series)) => series.at(stamp, blend_pose),
            None => Err(OutOfSpan::Empty),
        }
    }
}

#[cfg(test)]
mod tests {
    use super::*;
    use crate::rosbag::messages::Header;

    fn transform(parent: &str, child: &str, t: [f64; 3], q: [f64; 4]) -> TransformStamped {
        TransformStamped {
            header: Header {
                stamp_ns: 0,
                frame_id: parent.into(),
            },
            child_frame_id: child.into(),
            translation: t,
            rotation: q,
        }
    }

    #[test]
    fn fixed_chains_join_through_their_common_root() {
        let s = std::f64::consts::FRAC_1_SQRT_2;
        let fixed = vec![
            transform("base_link", "lidar", [0.2, 0.0, 0.5], [0.0, 0.0, s, s]),
            transform(
                "/base_link",
                "imu_link",
                [0.0, 0.1, 0.1],
                [0.0, 0.0, 0.0, 1.0],
            ),
        ];
        let tree = TfTree::new(&fixed, MovingSamples::default());
        let imu_from_lidar = tree.fixed_transform("imu_link", "lidar").unwrap();
        // A point 1 m ahead of the lidar (turned 90° left) lies 1 m to the left of the base.
        let p = imu_from_lidar * nalgebra::Point3::new(1.0, 0.0, 0.0);
        assert!(
            (p - nalgebra::Point3::new(0.2, 0.9, 0.4)).norm() < 1e-12,
            "{p}"
        );
        assert!(tree.fixed_transform("map", "lidar").is_none());
        assert_eq!(tree.fixed_transform("x", "/x"), Some(Pose::identity()));
    }

    #[test]
    fn moving_frames_interpolate_over_time() {
        let mut moving = MovingSamples::default();
        let mut a = transform("tilt_base", "laser", [0.0; 3], [0.0, 0.0, 0.0, 1.0]);
        let mut b = transform("tilt_base", "laser", [0.0, 0.0, 0.2], [0.0, 0.0, 0.0, 1.0]);
        a.header.stamp_ns = 0;
        b.header.stamp_ns = 100_000_000;
        moving.add(&[a, b]);
        let tree = TfTree::new(&[], moving);
        assert_eq!(tree.moving_parent("laser"), Some("tilt_base"));
        let mid = tree.moving_at("laser", 50_000_000).unwrap();
        assert!((mid.translation.vector.z - 0.1).abs() < 1e-12);
    }

    /// A world frame is a REP 105 name that `/tf` moves a frame in: `map` with the robot in it
    /// is one, `map` alone is not known to be, and a robot's frame that moves its joints is not.
    #[test]
    fn a_world_frame_is_a_rep_105_name_that_tf_moves_a_frame_in() {
        let mut moving = MovingSamples::default();
        let q = [0.0, 0.0, 0.0, 1.0];
        moving.add(&[
            transform("/map", "base_link", [1.0, 0.0, 0.0], q),
            transform("base_link", "tilt_link", [0.0; 3], q),
        ]);
        let tree = TfTree::new(&[], moving);
        assert_eq!(tree.world_frame_moving("map"), Some("base_link"));
        assert_eq!(tree.world_frame_moving("/map"), Some("base_link"));
        assert_eq!(tree.world_frame_moving("base_link"), None);
        assert_eq!(tree.world_frame_moving("odom"), None);
        assert_eq!(TfTree::default().world_frame_moving("map"), None);
    }
}
