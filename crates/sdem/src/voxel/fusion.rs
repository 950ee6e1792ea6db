//! The fused map of a map whose nodes move: each voxel counts the scans that hit it and the
//! scans that crossed it, so a node's scan can be taken out at the pose it was fused at and put
//! back at its new pose, exactly, when a loop closure moves it ("subtract and re-add"), instead
//! of fusing every scan again.
//!
//! A voxel's log-odds is `clamp(hits · l_hit + misses · l_miss)` (the updates of
//! [`VoxelConfig`], clamped to its bounds when read). [`VoxelMap`] clamps after every update
//! instead, as OctoMap does, which depends on the order of the scans and cannot be undone; the
//! counts do not depend on it, so the map is the same whatever order nodes were added or moved
//! in. Within one scan a voxel counts once, a hit over a miss, as in [`VoxelMap::insert_scan`];
//! the misses come from one ray to the centre of each voxel the scan's rays end in (OctoMap's
//! discretized insertion), a third fewer rays than the scan's points.

use super::keys::{split_key, Key, KeyMap};
use super::{for_each_voxel_ray, VoxelConfig, VoxelKey, VoxelMap};
use crate::error::{Error, Result};
use crate::geometry::{Pose, Vec3};

/// Voxels along a block's edge (as [`VoxelMap`]'s blocks).
const BLOCK_LEN: usize = 512;

/// One voxel's counts, and the pass that last counted it.
#[derive(Debug, Clone, Copy, Default)]
struct Counts {
    hits: u32,
    misses: u32,
    stamp: u32,
}

impl Counts {
    /// Whether some scan reached the voxel (a hit or a miss counted).
    fn known(&self) -> bool {
        self.hits > 0 || self.misses > 0
    }
}

#[derive(Debug, Clone)]
struct CountBlock {
    block_key: VoxelKey,
    cells: Box<[Counts; BLOCK_LEN]>,
}

/// The fused occupancy of a set of scans that can be taken out and put back (see the module
/// documentation).
///
/// # Example
/// ```
/// use sdem::geometry::{Pose, Vec3};
/// use sdem::voxel::{Occupancy, VoxelConfig, VoxelFusion};
/// let mut fusion = VoxelFusion::new(VoxelConfig::default())?;
/// let wall = [Vec3::new(2.01, 0.0, 0.0)];
/// fusion.add(0, &Pose::identity(), &wall)?;
/// assert_eq!(fusion.to_voxel_map().occupancy(&Vec3::new(2.01, 0.0, 0.0)), Occupancy::Occupied);
/// // A loop closure moves node 0 by 30 cm: its rays go out and come back from there.
/// fusion.moved(0, &Pose::translation(0.3, 0.0, 0.0), &wall)?;
/// let map = fusion.to_voxel_map();
/// assert_eq!(map.occupancy(&Vec3::new(2.31, 0.0, 0.0)), Occupancy::Occupied);
/// assert_eq!(map.occupancy(&Vec3::new(0.1, 0.0, 0.0)), Occupancy::Unknown);
/// # Ok::<(), sdem::Error>(())
/// ```
#[derive(Debug, Clone)]
pub struct VoxelFusion {
    config: VoxelConfig,
    blocks: Vec<CountBlock>,
    block_index: KeyMap<u32>,
    /// Voxels with a count.
    known: usize,
    /// Passes (scans added or taken out) so far: the stamp of the current one.
    passes: u32,
    /// The pose each node's scan is fused at (`None`: not fused).
    fused_at: Vec<Option<Pose>>,
}

impl VoxelFusion {
    /// An empty fusion.
    ///
    /// # Errors
    /// [`Error::Invalid`] when the configuration fails [`VoxelConfig::validate`].
    pub fn new(config: VoxelConfig) -> Result<Self> {
        config.validate()?;
        Ok(Self {
            config,
            blocks: Vec::new(),
            block_index: KeyMap::default(),
            known: 0,
            passes: 0,
            fused_at: Vec::new(),
        })
    }

    /// The configuration.
    pub fn config(&self) -> &VoxelConfig {
        &self.config
    }

    /// The number of known voxels (hit or crossed by some fused scan).
    pub fn len(&self) -> usize {
        self.known
    }

    /// True when no scan is fused.
    pub fn is_empty(&self) -> bool {
        self.known == 0
    }

    /// Where node `node_id`'s scan is fused, if it is.
    pub fn fused_pose(&self, node_id: usize) -> Option<&Pose> {
        self.fused_at.get(node_id).and_then(Option::as_ref)
    }

    /// Fuses node `node_id`'s scan at `world_from_sensor`.
    ///
    /// # Errors
    /// [`Error::Invalid`] when the node's scan is fused already.
    pub fn add(
        &mut self,
        node_id: usize,
        world_from_sensor: &Pose,
        points_in_sensor: &[Vec3],
    ) -> Result<()> {
        if self.fused_pose(node_id).is_some() {
            return Err(Error::Invalid(format!(
                "voxel fusion: node {node_id}'s scan is fused already"
            )));
        }
        self.apply(world_from_sensor, points_in_sensor, true);
        if self.fused_at.len() <= node_id {
            self.fused_at.resize(node_id + 1, None);
        }
        self.fused_at[node_id] = Some(*world_from_sensor);
        Ok(())
    }

    /// Adds the counts of `other`, a fusion of other nodes' scans with the same settings: this
    /// then holds what adding those scans here would have made, voxel for voxel (a voxel's
    /// counts do not depend on the order of the scans). Fusions of disjoint sets of nodes made
    /// on several threads are summed so.
    ///
    /// # Errors
    /// [`Error::Invalid`] when the settings differ, or a node is fused in both.
    pub fn absorb(&mut self, other: VoxelFusion) -> Result<()> {
        if other.config != self.config {
            return Err(Error::Invalid(
                "voxel fusion: only a fusion with the same settings can be added".into(),
            ));
        }
        let both = (other.fused_at.iter().enumerate())
            .find(|&(id, pose)| pose.is_some() && self.fused_pose(id).is_some());
        if let Some((id, _)) = both {
            return Err(Error::Invalid(format!(
                "voxel fusion: node {id}'s scan is fused in both"
            )));
        }
        // Every stamp stays at most the passes so far, so the next scan's stamp is new.
        self.passes = self.passes.max(other.passes);
        for block in other.blocks {
            let Some(&position) = self.block_index.get(&Key(block.block_key)) else {
                let known = block.cells.iter().filter(|c| c.known());
                self.known += known.count();
                self.block_index
                    .insert(Key(block.block_key), self.blocks.len() as u32);
                self.blocks.push(block);
                continue;
            };
            let cells = self.blocks[position as usize].cells.iter_mut();
            for (mine, theirs) in cells.zip(block.cells.iter()) {
                if !theirs.known() {
                    continue;
                }
                if !mine.known() {
                    self.known += 1;
                }
                mine.hits += theirs.hits;
                mine.misses += theirs.misses;
            }
        }
        if self.fused_at.len() < other.fused_at.len() {
            self.fused_at.resize(other.fused_at.len(), None);
        }
        for (id, pose) in other.fused_at.into_iter().enumerate() {
            if pose.is_some() {
                self.fused_at[id] = pose;
            }
        }
        Ok(())
    }

    /// Takes node `node_id`'s scan out (it must be the points it was fused with).
    ///
    /// # Errors
    /// [`Error::Invalid`] when the node's scan is not fused.
    pub fn remove(&mut self, node_id: usize, points_in_sensor: &[Vec3]) -> Result<()> {
        let pose = *self.fused_pose(node_id).ok_or_else(|| {
            Error::Invalid(format!("voxel fusion: node {node_id}'s scan is not fused"))
        })?;
        self.apply(&pose, points_in_sensor, false);
        self.fused_at[node_id] = None;
        Ok(())
    }

    /// Moves node `node_id`'s scan to `world_from_sensor`: out at its old pose, in at the new.
    ///
    /// # Errors
    /// [`Error::Invalid`] when the node's scan is not fused.
    pub fn moved(
        &mut self,
        node_id: usize,
        world_from_sensor: &Pose,
        points_in_sensor: &[Vec3],
    ) -> Result<()> {
        self.remove(node_id, points_in_sensor)?;
        self.add(node_id, world_from_sensor, points_in_sensor)
    }

    /// The fused nodes whose pose in `world_from_node` lies more than `tolerance_m` or
    /// `tolerance_rad` from the pose they are fused at, the largest move first (a rotation
    /// counts as far as it moves a point at the voxel map's longest ray).
    pub fn stale(
        &self,
        world_from_node: &[Pose],
        tolerance_m: f64,
        tolerance_rad: f64,
    ) -> Vec<usize> {
        let reach = self.config.max_range_m;
        let mut moved: Vec<(f64, usize)> = (self.fused_at.iter().enumerate())
            .filter_map(|(id, fused)| Some((id, fused.as_ref()?, world_from_node.get(id)?)))
            .filter_map(|(id, fused, now)| {
                let shift = (now.translation.vector - fused.translation.vector).norm();
                let turn = now.rotation.angle_to(&fused.rotation);
                (shift > tolerance_m || turn > tolerance_rad).then_some((shift + turn * reach, id))
            })
            .collect();
        moved.sort_by(|a, b| b.0.total_cmp(&a.0).then(a.1.cmp(&b.1)));
        moved.into_iter().map(|(_, id)| id).collect()
    }

    /// The log-odds of a voxel, `None` when it is unknown.
    pub fn log_odds(&self, key: &VoxelKey) -> Option<f32> {
        let (block_key, index) = split_key(*key);
        let position = *self.block_index.get(&Key(block_key))?;
        self.cell_log_odds(&self.blocks[position as usize].cells[index])
    }

    /// The fused map as a [`VoxelMap`] (every known voxel with its log-odds): to save, view or
    /// filter a cloud with.
    pub fn to_voxel_map(&self) -> VoxelMap {
        let voxels = self.blocks.iter().flat_map(|block| {
            block
                .cells
                .iter()
                .enumerate()
                .filter_map(move |(index, c)| {
                    Some((voxel_key(block, index), self.cell_log_odds(c)?))
                })
        });
        VoxelMap::from_voxels(self.config, voxels)
            .expect("clamped log-odds of distinct keys make a valid map")
    }

    /// `clamp(hits · l_hit + misses · l_miss)`, `None` for a voxel no scan reached.
    fn cell_log_odds(&self, c: &Counts) -> Option<f32> {
        if !c.known() {
            return None;
        }
        let l = f64::from(c.hits) * self.config.hit_log_odds
            + f64::from(c.misses) * self.config.miss_log_odds;
        let (lo, hi) = (
            self.config.min_log_odds as f32,
            self.config.max_log_odds as f32,
        );
        Some((l as f32).clamp(lo, hi))
    }

    /// Counts one scan's updates in (`add`) or out.
    fn apply(&mut self, world_from_sensor: &Pose, points_in_sensor: &[Vec3], add: bool) {
        self.passes = self.passes.wrapping_add(1);
        if self.passes == 0 {
            for cell in self.blocks.iter_mut().flat_map(|b| b.cells.iter_mut()) {
                cell.stamp = 0;
            }
            self.passes = 1;
        }
        let stamp = self.passes;
        let (blocks, block_index, known) =
            (&mut self.blocks, &mut self.block_index, &mut self.known);
        let mut last_block: Option<(VoxelKey, usize)> = None;
        for_each_voxel_ray(
            &self.config,
            world_from_sensor,
            points_in_sensor,
            |key, is_hit| {
                let (block_key, index) = split_key(key);
                let position = match last_block {
                    Some((k, position)) if k == block_key => position,
                    _ => {
                        let position = *block_index.entry(Key(block_key)).or_insert_with(|| {
                            blocks.push(CountBlock {
                                block_key,
                                cells: Box::new([Counts::default(); BLOCK_LEN]),
                            });
                            (blocks.len() - 1) as u32
                        }) as usize;
                        last_block = Some((block_key, position));
                        position
                    }
                };
                let cell = &mut blocks[position].cells[index];
                if cell.stamp == stamp {
                    return;
                }
                cell.stamp = stamp;
                let was_known = cell.known();
                let count = if is_hit {
                    &mut cell.hits
                } else {
                    &mut cell.misses
                };
                if add {
                    *count += 1;
                } else {
                    // The same updates as when the scan went in: the count is at least 1.
                    *count -= 1;
                }
                let is_known = cell.known();
                match (was_known, is_known) {
                    (false, true) => *known += 1,
                    (true, false) => *known -= 1,
                    _ => {}
                }
            },
        );
    }
}

/// The key of the voxel at `index` in `block`.
fn voxel_key(block: &CountBlock, index: usize) -> VoxelKey {
    let local = [index & 7, (index >> 3) & 7, index >> 6];
    std::array::from_fn(|axis| (block.block_key[axis] << 3) + local[axis] as i32)
}

#[cfg(test)]
mod tests {
    use super::*;
    use crate::geometry::{pose_from_parts, Attitude};

    /// A fan of rays to a wall 2 m ahead and rubble in front of part of it.
    fn scan() -> Vec<Vec3> {
        let mut points = Vec::new();
        for i in -20i32..=20 {
            for j in -5..=5 {
                let d = Vec3::new(1.0, i as f64 * 0.02, j as f64 * 0.02).normalize();
                let range = if i.abs() < 5 { 1.2 } else { 2.0 / d.x };
                points.push(d * range);
            }
        }
        points
    }

    /// Four poses a `step` and `turn_deg` of heading apart, 1 cm up and a little tilted.
    fn poses_along(step: Vec3, turn_deg: f64) -> Vec<Pose> {
        (0..4)
            .map(|k| {
                pose_from_parts(
                    step * k as f64 + Vec3::new(0.0, 0.0, 0.01),
                    Attitude::from_degrees(0.5, -0.3, turn_deg * k as f64),
                )
            })
            .collect()
    }

    fn as_sorted(map: &VoxelMap) -> Vec<(VoxelKey, u32)> {
        let mut v: Vec<(VoxelKey, u32)> = map.iter().map(|(k, l)| (k, l.to_bits())).collect();
        v.sort_unstable();
        v
    }

    #[test]
    fn a_node_moved_is_the_node_fused_at_its_new_pose_in_the_first_place() {
        let config = VoxelConfig::default();
        let poses = poses_along(Vec3::new(0.1, 0.03, 0.0), 7.0);
        let points = scan();
        let mut fusion = VoxelFusion::new(config).unwrap();
        for (id, pose) in poses.iter().enumerate() {
            fusion.add(id, pose, &points).unwrap();
        }
        // A loop closure moves nodes 1 and 3.
        let mut moved = poses.clone();
        moved[1] = pose_from_parts(
            Vec3::new(0.17, -0.04, 0.0),
            Attitude::from_degrees(0.2, 0.1, 11.0),
        );
        moved[3] = pose_from_parts(
            Vec3::new(0.25, 0.12, 0.02),
            Attitude::from_degrees(0.0, 0.0, 19.0),
        );
        // Node 1 turned 4° (as far as 56 cm at the longest ray), node 3 only 2°.
        assert_eq!(fusion.stale(&moved, 0.01, 0.002), vec![1, 3]);
        fusion.moved(1, &moved[1], &points).unwrap();
        fusion.moved(3, &moved[3], &points).unwrap();
        assert!(fusion.stale(&moved, 0.01, 0.002).is_empty());
        // Fused afresh in another order: the same voxels, the same log-odds, bit for bit.
        let mut fresh = VoxelFusion::new(config).unwrap();
        for id in [3, 0, 2, 1] {
            fresh.add(id, &moved[id], &points).unwrap();
        }
        assert_eq!(fusion.len(), fresh.len());
        assert_eq!(
            as_sorted(&fusion.to_voxel_map()),
            as_sorted(&fresh.to_voxel_map())
        );
        // All out: nothing is known.
        for id in 0..4 {
            fusion.remove(id, &points).unwrap();
        }
        assert!(fusion.is_empty());
        assert!(fusion.to_voxel_map().is_empty());
        assert!(fusion.remove(0, &points).is_err());
    }

    #[test]
    fn fusions_of_two_shares_of_the_nodes_summed_are_the_fusion_of_all() {
        let config = VoxelConfig::default();
        let poses = poses_along(Vec3::new(0.4, 0.05, 0.0), 9.0);
        let points = scan();
        let fused = |ids: &[usize]| {
            let mut fusion = VoxelFusion::new(config).unwrap();
            for &id in ids {
                fusion.add(id, &poses[id], &points).unwrap();
            }
            fusion
        };
        let mut whole = fused(&[0, 1, 2, 3]);
        // The shares overlap in space: their counts add up in the voxels both reach.
        let mut summed = fused(&[0, 1]);
        summed.absorb(fused(&[2, 3])).unwrap();
        assert_eq!(summed.len(), whole.len());
        // Contiguous shares summed in order: the voxels in the same order as one by one (so a
        // saved map is the same file).
        let listed = |f: &VoxelFusion| -> Vec<(VoxelKey, u32)> {
            (f.to_voxel_map().iter())
                .map(|(k, l)| (k, l.to_bits()))
                .collect()
        };
        assert_eq!(listed(&summed), listed(&whole));
        assert_eq!(summed.fused_pose(3), Some(&poses[3]));
        // Scans taken out and moved afterwards leave the same counts in both.
        let away = pose_from_parts(
            Vec3::new(0.2, -0.1, 0.0),
            Attitude::from_degrees(0.0, 0.0, 25.0),
        );
        for fusion in [&mut summed, &mut whole] {
            fusion.remove(2, &points).unwrap();
            fusion.moved(1, &away, &points).unwrap();
        }
        assert_eq!(summed.len(), whole.len());
        assert_eq!(
            as_sorted(&summed.to_voxel_map()),
            as_sorted(&whole.to_voxel_map())
        );
        // A node in both shares, or other settings, cannot be summed.
        let mut twice = fused(&[0, 1]);
        assert!(twice.absorb(fused(&[1])).is_err());
        let coarse = VoxelConfig {
            voxel_m: 2.0 * config.voxel_m,
            ..config
        };
        assert!(twice.absorb(VoxelFusion::new(coarse).unwrap()).is_err());
    }

    #[test]
    fn one_scan_hits_its_end_voxels_and_clears_what_its_rays_cross() {
        let config = VoxelConfig::default();
        let pose = pose_from_parts(
            Vec3::new(0.02, 0.01, 0.3),
            Attitude::from_degrees(1.0, 2.0, 30.0),
        );
        let mut fusion = VoxelFusion::new(config).unwrap();
        fusion.add(0, &pose, &scan()).unwrap();
        assert!(fusion.add(0, &pose, &scan()).is_err());
        let fused = fusion.to_voxel_map();
        // Occupied: exactly the voxels the rays end in, fewer than the rays.
        let mut ends: Vec<VoxelKey> = scan()
            .iter()
            .map(|p| {
                fused
                    .key_of(&(pose * nalgebra::Point3::from(*p)).coords)
                    .unwrap()
            })
            .collect();
        ends.sort_unstable();
        ends.dedup();
        assert!(ends.len() < scan().len(), "{} voxels", ends.len());
        let occupied = |map: &VoxelMap| -> Vec<VoxelKey> {
            let mut keys: Vec<VoxelKey> = map
                .iter()
                .filter(|(_, l)| *l > 0.0)
                .map(|(k, _)| k)
                .collect();
            keys.sort_unstable();
            keys
        };
        assert_eq!(occupied(&fused), ends);
        // Free: what the rays to every point cross, give or take a voxel sideways: a ray to a
        // voxel's centre and one to a point in it are less than a voxel apart.
        let mut exact = VoxelMap::new(config).unwrap();
        exact.insert_scan(&pose, &scan());
        assert_eq!(occupied(&exact), ends);
        let free = |map: &VoxelMap| -> std::collections::HashSet<VoxelKey> {
            map.iter()
                .filter(|(_, l)| *l <= 0.0)
                .map(|(k, _)| k)
                .collect()
        };
        let (a, b) = (free(&fused), free(&exact));
        let both: std::collections::HashSet<&VoxelKey> = a.intersection(&b).collect();
        let next_to_both = |k: &VoxelKey| {
            (-1..=1).any(|dx| {
                (-1..=1)
                    .any(|dy| (-1..=1).any(|dz| both.contains(&[k[0] + dx, k[1] + dy, k[2] + dz])))
            })
        };
        let differing: Vec<&VoxelKey> = a.symmetric_difference(&b).collect();
        assert!(
            differing.len() * 10 <= b.len(),
            "{} of {}",
            differing.len(),
            b.len()
        );
        assert!(differing.iter().all(|k| next_to_both(k)));
    }
}
