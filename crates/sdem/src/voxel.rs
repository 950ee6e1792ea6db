//! An occupancy voxel map fused from all scans: free, occupied and unknown space.
//!
//! Every scan is ray-cast into a sparse grid of cubic voxels, as OctoMap does (Hornung et al.,
//! "OctoMap: an efficient probabilistic 3D mapping framework based on octrees", Autonomous
//! Robots 2013, Sec. III): each voxel holds the log-odds of being occupied, a ray's end voxel gets
//! a *hit* update and every voxel the ray crosses on its way a *miss* update, and the log-odds are
//! clamped so the map stays able to change its mind. Rubble that was seen in one scan and moved
//! away before a later one is crossed by the later scans' rays and turns free, so it drops out of
//! the merged cloud ([`VoxelMap::filter_occupied`]).
//!
//! The voxels a ray crosses are enumerated exactly by the 3D DDA of Amanatides and Woo ("A fast
//! voxel traversal algorithm for ray tracing", Eurographics 1987).
//!
//! Voxel `[i, j, k]` is the cube `[i·s, (i+1)·s) × [j·s, (j+1)·s) × [k·s, (k+1)·s)` in the world
//! frame, `s` = [`VoxelConfig::voxel_m`]. Only voxels that some ray reached are stored; all others
//! are [`Occupancy::Unknown`].

use crate::error::{Error, Result};
use crate::geometry::{Pose, Vec3};
use serde::{Deserialize, Serialize};
use std::collections::HashMap;
use std::hash::{BuildHasherDefault, Hash, Hasher};

/// The integer key `[i, j, k]` of a voxel (see the module documentation).
pub type VoxelKey = [i32; 3];

/// Keys beyond this magnitude are not used, so that key arithmetic never overflows (at 5 cm this
/// is ±50,000 km).
pub const MAX_KEY: f64 = 1e9;

/// The log-odds `ln(p / (1 − p))` of a probability.
fn logit(p: f64) -> f64 {
    (p / (1.0 - p)).ln()
}

/// How scans become voxels: the voxel size, the log-odds updates (OctoMap's defaults) and the
/// longest ray that is trusted.
#[derive(Debug, Clone, Copy, PartialEq, Serialize, Deserialize)]
#[serde(default, deny_unknown_fields)]
pub struct VoxelConfig {
    /// Edge of a voxel, metres (default 0.05).
    pub voxel_m: f64,
    /// Added to a voxel's log-odds when a ray ends in it (default `logit(0.7)` ≈ 0.847, OctoMap's
    /// `prob_hit`); > 0.
    pub hit_log_odds: f64,
    /// Added to a voxel's log-odds when a ray crosses it (default `logit(0.4)` ≈ −0.405,
    /// OctoMap's `prob_miss`); < 0.
    pub miss_log_odds: f64,
    /// The log-odds never go below this (default `logit(0.12)` ≈ −1.992, OctoMap's
    /// `clamping_thres_min`); < 0.
    pub min_log_odds: f64,
    /// The log-odds never go above this (default `logit(0.97)` ≈ 3.476, OctoMap's
    /// `clamping_thres_max`); > 0.
    pub max_log_odds: f64,
    /// Rays longer than this, metres, are cut to it: they clear free space up to this distance but
    /// mark no hit, since far returns are the least trustworthy (default 8, the sensor's range).
    pub max_range_m: f64,
}

impl Default for VoxelConfig {
    fn default() -> Self {
        Self {
            voxel_m: 0.05,
            hit_log_odds: logit(0.7),
            miss_log_odds: logit(0.4),
            min_log_odds: logit(0.12),
            max_log_odds: logit(0.97),
            max_range_m: 8.0,
        }
    }
}

impl VoxelConfig {
    /// Checks every field for a usable value; the message names the field and the fix.
    pub fn validate(&self) -> Result<()> {
        let fields = [
            ("voxel_m", self.voxel_m),
            ("hit_log_odds", self.hit_log_odds),
            ("miss_log_odds", self.miss_log_odds),
            ("min_log_odds", self.min_log_odds),
            ("max_log_odds", self.max_log_odds),
            ("max_range_m", self.max_range_m),
        ];
        for (name, value) in fields {
            if !value.is_finite() || !(value as f32).is_finite() {
                return Err(Error::Invalid(format!(
                    "voxel map: {name} is {value}; it must be a finite number"
                )));
            }
        }
        if !(self.voxel_m >= 1e-4 && self.voxel_m <= 1e3) {
            return Err(Error::Invalid(format!(
                "voxel map: voxel_m is {} m; it must be between 0.0001 and 1000 m",
                self.voxel_m
            )));
        }
        if self.hit_log_odds <= 0.0 || self.miss_log_odds >= 0.0 {
            return Err(Error::Invalid(format!(
                "voxel map: need hit_log_odds > 0 and miss_log_odds < 0 (got {} and {})",
                self.hit_log_odds, self.miss_log_odds
            )));
        }
        if self.min_log_odds >= 0.0 || self.max_log_odds <= 0.0 {
            return Err(Error::Invalid(format!(
                "voxel map: need min_log_odds < 0 < max_log_odds (got {} and {})",
                self.min_log_odds, self.max_log_odds
            )));
        }
        if self.max_range_m <= 0.0 || self.max_range_m > 1e5 * self.voxel_m {
            return Err(Error::Invalid(format!(
                "voxel map: max_range_m is {} m; it must be > 0 and at most 100,000 voxels ({} m)",
                self.max_range_m,
                1e5 * self.voxel_m
            )));
        }
        Ok(())
    }
}

/// What the map knows about a place.
#[derive(Debug, Clone, Copy, PartialEq, Eq, Hash)]
pub enum Occupancy {
    /// No ray has reached the voxel.
    Unknown,
    /// Observed, and more likely free than occupied (log-odds ≤ 0).
    Free,
    /// Observed, and more likely occupied than free (log-odds > 0).
    Occupied,
}

/// Voxels are stored in dense cubic blocks of `BLOCK_EDGE³` (as in OpenVDB's leaves and
/// voxblox's blocks): a ray walks through several voxels of one block before it needs another
/// hash lookup, and the voxels of a block share cache lines.
const BLOCK_BITS: u32 = 3;
/// Voxels along a block's edge.
const BLOCK_EDGE: i32 = 1 << BLOCK_BITS;
/// Voxels in a block.
const BLOCK_LEN: usize = 1 << (3 * BLOCK_BITS);

/// A voxel: its log-odds (NaN while unknown) and the scan counter when it was last updated (0 =
/// never since the map was made). Side by side, so an update touches one cache line.
#[derive(Debug, Clone, Copy)]
struct Cell {
    log_odds: f32,
    stamp: u32,
}

/// A dense block of voxels.
#[derive(Debug, Clone)]
struct Block {
    /// The block's key: the voxel key divided by `BLOCK_EDGE`, rounded down.
    block_key: VoxelKey,
    cells: [Cell; BLOCK_LEN],
}

impl Block {
    fn new(block_key: VoxelKey) -> Self {
        Self {
            block_key,
            cells: [Cell {
                log_odds: f32::NAN,
                stamp: 0,
            }; BLOCK_LEN],
        }
    }

    /// The key of the voxel at `index` in this block.
    fn voxel_key(&self, index: usize) -> VoxelKey {
        let mask = BLOCK_EDGE as usize - 1;
        let b = BLOCK_BITS as usize;
        let local = [index & mask, (index >> b) & mask, index >> (2 * b)];
        std::array::from_fn(|axis| (self.block_key[axis] << BLOCK_BITS) + local[axis] as i32)
    }
}

/// The block holding a voxel and the voxel's index in it.
#[inline]
fn split_key(key: VoxelKey) -> (VoxelKey, usize) {
    let mask = BLOCK_EDGE - 1;
    let block_key = key.map(|v| v >> BLOCK_BITS);
    let [x, y, z] = key.map(|v| (v & mask) as usize);
    let b = BLOCK_BITS as usize;
    (block_key, x | (y << b) | (z << (2 * b)))
}

/// A key wrapped so that it hashes as one `u64` write (the std array hash writes a length and a
/// byte slice).
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
#[doc(hidden)]
pub struct Key(pub(crate) VoxelKey);

impl Hash for Key {
    #[inline]
    fn hash<H: Hasher>(&self, state: &mut H) {
        let [x, y, z] = self.0;
        let xy = (x as u32 as u64) | ((y as u32 as u64) << 32);
        state.write_u64(folded_multiply(
            xy ^ 0x243F_6A88_85A3_08D3,
            (z as u32 as u64) ^ 0x1319_8A2E_0370_7344,
        ));
    }
}

/// The high and low halves of a 128-bit product, xor-ed: every input bit reaches every output
/// bit (the mixing step of foldhash and wyhash).
#[inline]
fn folded_multiply(a: u64, b: u64) -> u64 {
    let product = (a as u128) * (b as u128);
    (product as u64) ^ ((product >> 64) as u64)
}

/// The hasher of the voxel table: the key's hash already mixes all bits, so this only passes it
/// on.
#[derive(Default)]
#[doc(hidden)]
pub struct KeyHasher(u64);

impl Hasher for KeyHasher {
    #[inline]
    fn finish(&self) -> u64 {
        self.0
    }

    #[inline]
    fn write_u64(&mut self, value: u64) {
        self.0 = folded_multiply(self.0 ^ value, 0x9E37_79B9_7F4A_7C15);
    }

    fn write(&mut self, bytes: &[u8]) {
        // Not used by `Key`; any input still hashes correctly.
        for chunk in bytes.chunks(8) {
            let mut word = [0u8; 8];
            word[..chunk.len()].copy_from_slice(chunk);
            self.write_u64(u64::from_le_bytes(word));
        }
    }
}

/// A hash map keyed by integer voxel coordinates (also used by the refinement's neighbour grid).
#[doc(hidden)]
pub type KeyMap<V> = HashMap<Key, V, BuildHasherDefault<KeyHasher>>;

/// A sparse occupancy voxel map (see the module documentation).
#[derive(Debug, Clone)]
pub struct VoxelMap {
    config: VoxelConfig,
    /// Every block with at least one voxel ever updated.
    blocks: Vec<Block>,
    /// Block key → position in `blocks`.
    block_index: KeyMap<u32>,
    /// The number of known voxels.
    known: usize,
    /// Scans inserted since the map was made (the stamp of the current scan).
    scan_counter: u32,
}

impl VoxelMap {
    /// An empty map (everything unknown).
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
            scan_counter: 0,
        })
    }

    /// A map from stored voxels, as a map file holds them.
    ///
    /// # Errors
    /// [`Error::Invalid`] when the configuration is invalid, a key appears twice, or a log-odds
    /// is not finite or lies outside `[min_log_odds, max_log_odds]`.
    pub fn from_voxels(
        config: VoxelConfig,
        voxels: impl IntoIterator<Item = (VoxelKey, f32)>,
    ) -> Result<Self> {
        let mut map = Self::new(config)?;
        let (lo, hi) = map.clamp_bounds();
        for (key, log_odds) in voxels {
            if !(log_odds.is_finite() && lo <= log_odds && log_odds <= hi) {
                return Err(Error::Invalid(format!(
                    "voxel {key:?} has log-odds {log_odds}; it must be finite and within \
                     [min_log_odds, max_log_odds] = [{lo}, {hi}]"
                )));
            }
            if key.iter().any(|v| f64::from(v.unsigned_abs()) > MAX_KEY) {
                return Err(Error::Invalid(format!(
                    "voxel {key:?} is out of range; keys are at most {MAX_KEY} in magnitude"
                )));
            }
            let (block_key, index) = split_key(key);
            let block = map.block_mut(block_key);
            if !block.cells[index].log_odds.is_nan() {
                return Err(Error::Invalid(format!("voxel {key:?} appears twice")));
            }
            block.cells[index].log_odds = log_odds;
            map.known += 1;
        }
        Ok(map)
    }

    /// The configuration the map was made with.
    pub fn config(&self) -> &VoxelConfig {
        &self.config
    }

    /// Edge of a voxel, metres.
    pub fn voxel_m(&self) -> f64 {
        self.config.voxel_m
    }

    /// The number of known (free or occupied) voxels.
    pub fn len(&self) -> usize {
        self.known
    }

    /// True when no voxel is known.
    pub fn is_empty(&self) -> bool {
        self.known == 0
    }

    /// Every known voxel as `(key, log_odds)`, in no particular order.
    pub fn iter(&self) -> impl Iterator<Item = (VoxelKey, f32)> + '_ {
        self.blocks.iter().flat_map(|block| {
            block
                .cells
                .iter()
                .enumerate()
                .filter(|(_, c)| !c.log_odds.is_nan())
                .map(|(index, c)| (block.voxel_key(index), c.log_odds))
        })
    }

    /// The log-odds of a voxel, `None` when it is unknown.
    pub fn log_odds(&self, key: &VoxelKey) -> Option<f32> {
        let (block_key, index) = split_key(*key);
        let position = *self.block_index.get(&Key(block_key))?;
        let log_odds = self.blocks[position as usize].cells[index].log_odds;
        (!log_odds.is_nan()).then_some(log_odds)
    }

    /// The block with this key, made (all unknown) if there is none yet.
    fn block_mut(&mut self, block_key: VoxelKey) -> &mut Block {
        let position = block_position(&mut self.blocks, &mut self.block_index, block_key);
        &mut self.blocks[position]
    }

    /// The key of the voxel holding a world point; `None` for a non-finite point or one too far
    /// from the origin for a key.
    pub fn key_of(&self, point_in_world: &Vec3) -> Option<VoxelKey> {
        key_of(point_in_world, 1.0 / self.config.voxel_m)
    }

    /// The centre of a voxel in the world frame, metres.
    pub fn centre_of(&self, key: &VoxelKey) -> Vec3 {
        let s = self.config.voxel_m;
        Vec3::new(
            (f64::from(key[0]) + 0.5) * s,
            (f64::from(key[1]) + 0.5) * s,
            (f64::from(key[2]) + 0.5) * s,
        )
    }

    /// The clamping bounds in the precision they are stored in.
    fn clamp_bounds(&self) -> (f32, f32) {
        (
            self.config.min_log_odds as f32,
            self.config.max_log_odds as f32,
        )
    }

    /// Fuses one scan into the map.
    ///
    /// Each point is the end of a ray from the sensor origin (`world_from_sensor`'s translation).
    /// Every voxel the ray crosses before its end voxel gets a miss update, the end voxel a hit
    /// update (Hornung et al. 2013, Eq. (2)–(3), with clamping, Eq. (4)). A ray longer than
    /// [`VoxelConfig::max_range_m`] is cut there: its voxels up to the cut get misses, none a hit.
    /// Within one scan a voxel is updated at most once and a hit wins over a miss, as OctoMap's
    /// `insertPointCloud` does, so a dense scan does not count one surface many times and rays
    /// grazing a surface do not erase it. Non-finite points are skipped.
    ///
    /// # Arguments
    /// * `world_from_sensor` — the pose of the sensor when the scan was taken.
    /// * `points_in_sensor` — the returns, sensor frame, metres.
    ///
    /// # Example
    /// ```
    /// use sdem::geometry::{Pose, Vec3};
    /// use sdem::voxel::{Occupancy, VoxelConfig, VoxelMap};
    ///
    /// let mut map = VoxelMap::new(VoxelConfig::default()).unwrap();
    /// // The sensor 0.5 m up, one return from a wall 2 m ahead.
    /// let world_from_sensor = Pose::translation(0.0, 0.0, 0.5);
    /// map.insert_scan(&world_from_sensor, &[Vec3::new(2.01, 0.0, 0.0)]);
    /// assert_eq!(map.occupancy(&Vec3::new(2.01, 0.0, 0.5)), Occupancy::Occupied);
    /// assert_eq!(map.occupancy(&Vec3::new(1.0, 0.0, 0.5)), Occupancy::Free);
    /// assert_eq!(map.occupancy(&Vec3::new(3.0, 0.0, 0.5)), Occupancy::Unknown);
    /// assert_eq!(map.counts(), (1, 40)); // 40 voxels crossed, one hit
    /// ```
    pub fn insert_scan(&mut self, world_from_sensor: &Pose, points_in_sensor: &[Vec3]) {
        self.next_stamp();
        let stamp = self.scan_counter;
        let inv_s = 1.0 / self.config.voxel_m;
        let (lo, hi) = self.clamp_bounds();
        let hit = self.config.hit_log_odds as f32;
        let miss = self.config.miss_log_odds as f32;
        let max_range = self.config.max_range_m;

        let origin = world_from_sensor.translation.vector;
        let Some(origin_key) = key_of(&origin, inv_s) else {
            return;
        };
        // Rays as (end point, whether it is a hit); hits are applied first, so that a voxel hit
        // anywhere in this scan is stamped before any ray could mark it free.
        let mut rays: Vec<(Vec3, bool)> = Vec::with_capacity(points_in_sensor.len());
        for point_in_sensor in points_in_sensor {
            let range = point_in_sensor.norm();
            if !range.is_finite() {
                continue;
            }
            let ray = if range > max_range {
                let cut = world_from_sensor.rotation * (point_in_sensor * (max_range / range));
                (origin + cut, false)
            } else {
                (
                    world_from_sensor
                        .transform_point(&(*point_in_sensor).into())
                        .coords,
                    true,
                )
            };
            if key_of(&ray.0, inv_s).is_some() {
                rays.push(ray);
            }
        }

        // Hornung et al. 2013, Eq. (2)–(4): L(n) ← clamp(L(n) + l, l_min, l_max). Consecutive
        // voxels of a ray mostly share a block, so the last block found is kept.
        let (blocks, block_index, known) =
            (&mut self.blocks, &mut self.block_index, &mut self.known);
        let mut last_block: Option<(VoxelKey, usize)> = None;
        let mut update = |key: VoxelKey, delta: f32| {
            let (block_key, index) = split_key(key);
            let position = match last_block {
                Some((k, position)) if k == block_key => position,
                _ => {
                    let position = block_position(blocks, block_index, block_key);
                    last_block = Some((block_key, position));
                    position
                }
            };
            let cell = &mut blocks[position].cells[index];
            if cell.stamp == stamp {
                return;
            }
            cell.stamp = stamp;
            let old = cell.log_odds;
            cell.log_odds = if old.is_nan() {
                *known += 1;
                delta.clamp(lo, hi)
            } else {
                (old + delta).clamp(lo, hi)
            };
        };
        for (end, is_hit) in &rays {
            if *is_hit {
                if let Some(key) = key_of(end, inv_s) {
                    update(key, hit);
                }
            }
        }
        for (end, _) in &rays {
            traverse(&origin, origin_key, end, inv_s, |key| update(key, miss));
        }
    }

    /// Advances the scan counter; on the (theoretical) wrap-around every stamp is cleared.
    fn next_stamp(&mut self) {
        if self.scan_counter == u32::MAX {
            for cell in self.blocks.iter_mut().flat_map(|b| b.cells.iter_mut()) {
                cell.stamp = 0;
            }
            self.scan_counter = 0;
        }
        self.scan_counter += 1;
    }

    /// What the map knows about the voxel holding a world point.
    pub fn occupancy(&self, point_in_world: &Vec3) -> Occupancy {
        match self.key_of(point_in_world).and_then(|k| self.log_odds(&k)) {
            None => Occupancy::Unknown,
            Some(l) => occupancy_of(l),
        }
    }

    /// The centres of all occupied voxels, sorted by key, world frame.
    pub fn occupied_centres(&self) -> Vec<Vec3> {
        let mut keys: Vec<VoxelKey> = self
            .iter()
            .filter(|(_, l)| occupancy_of(*l) == Occupancy::Occupied)
            .map(|(k, _)| k)
            .collect();
        keys.sort_unstable();
        keys.iter().map(|k| self.centre_of(k)).collect()
    }

    /// The numbers of occupied and of free voxels, `(occupied, free)`.
    pub fn counts(&self) -> (usize, usize) {
        let occupied = self
            .blocks
            .iter()
            .flat_map(|block| block.cells.iter())
            .filter(|c| c.log_odds > 0.0)
            .count();
        (occupied, self.known - occupied)
    }

    /// The merged point cloud: of `points_in_world` (typically every scan's points moved to the
    /// world frame), those whose voxel is occupied now, thinned to one point per voxel, the
    /// centroid of that voxel's points. Points on rubble that later scans saw through have turned
    /// free and drop out. The output is ordered by each voxel's first point in the input.
    pub fn filter_occupied(&self, points_in_world: &[Vec3]) -> Vec<Vec3> {
        let inv_s = 1.0 / self.config.voxel_m;
        // Per occupied voxel: its position in the output, the sum of its points and their count.
        let mut sums: KeyMap<usize> = KeyMap::default();
        let mut acc: Vec<(Vec3, u32)> = Vec::new();
        for p in points_in_world {
            let Some(key) = key_of(p, inv_s) else {
                continue;
            };
            let occupied = self
                .log_odds(&key)
                .is_some_and(|l| occupancy_of(l) == Occupancy::Occupied);
            if !occupied {
                continue;
            }
            let slot = *sums.entry(Key(key)).or_insert_with(|| {
                acc.push((Vec3::zeros(), 0));
                acc.len() - 1
            });
            acc[slot].0 += p;
            acc[slot].1 += 1;
        }
        acc.into_iter().map(|(sum, n)| sum / f64::from(n)).collect()
    }

    /// The axis-aligned box around all known (free or occupied) voxels, `(min corner, max
    /// corner)` in the world frame; `None` for an empty map.
    pub fn bounds(&self) -> Option<(Vec3, Vec3)> {
        let mut keys = self.iter().map(|(k, _)| k);
        let first = keys.next()?;
        let (mut min, mut max) = (first, first);
        for k in keys {
            for axis in 0..3 {
                min[axis] = min[axis].min(k[axis]);
                max[axis] = max[axis].max(k[axis]);
            }
        }
        let s = self.config.voxel_m;
        let corner = |k: VoxelKey, add: i32| {
            Vec3::new(
                f64::from(k[0] + add) * s,
                f64::from(k[1] + add) * s,
                f64::from(k[2] + add) * s,
            )
        };
        Some((corner(min, 0), corner(max, 1)))
    }
}

/// The position in `blocks` of the block with this key, appending a new (all unknown) block if
/// there is none yet.
fn block_position(
    blocks: &mut Vec<Block>,
    block_index: &mut KeyMap<u32>,
    block_key: VoxelKey,
) -> usize {
    *block_index.entry(Key(block_key)).or_insert_with(|| {
        blocks.push(Block::new(block_key));
        (blocks.len() - 1) as u32
    }) as usize
}

/// Occupied when more likely occupied than free.
fn occupancy_of(log_odds: f32) -> Occupancy {
    if log_odds > 0.0 {
        Occupancy::Occupied
    } else {
        Occupancy::Free
    }
}

/// The key of the voxel holding `p`, with `inv_s` = 1 / voxel edge; `None` when non-finite or out
/// of the key range.
#[inline]
fn key_of(p: &Vec3, inv_s: f64) -> Option<VoxelKey> {
    let mut key = [0i32; 3];
    for axis in 0..3 {
        let v = (p[axis] * inv_s).floor();
        if v.is_nan() || v.abs() > MAX_KEY {
            return None;
        }
        key[axis] = v as i32;
    }
    Some(key)
}

/// Calls `visit` for every voxel the segment from `origin` (in voxel `origin_key`) to `end`
/// crosses, in order, from the origin's voxel up to but **not** including `end`'s voxel (so
/// nothing when both are in one voxel) — the
/// 3D DDA of Amanatides & Woo (1987). Consecutive voxels share a face. Exactly
/// `|Δi| + |Δj| + |Δk|` voxels are visited, so the walk always ends in `end`'s voxel, whatever
/// the rounding; where the segment passes exactly through an edge or corner, one of the voxels
/// sharing it is taken.
#[inline]
fn traverse(
    origin: &Vec3,
    origin_key: VoxelKey,
    end: &Vec3,
    inv_s: f64,
    mut visit: impl FnMut(VoxelKey),
) {
    let Some(end_key) = key_of(end, inv_s) else {
        return;
    };
    // In voxel units, relative to the origin.
    let dir = (end - origin) * inv_s;
    let o = origin * inv_s;
    let mut key = origin_key;
    let mut remaining = [0u64; 3];
    let mut step = [0i32; 3];
    // Ray parameter t ∈ [0, 1] at the next boundary along each axis, and between boundaries.
    let mut t_max = [f64::INFINITY; 3];
    let mut t_delta = [f64::INFINITY; 3];
    for axis in 0..3 {
        let diff = i64::from(end_key[axis]) - i64::from(origin_key[axis]);
        remaining[axis] = diff.unsigned_abs();
        if diff == 0 {
            continue;
        }
        step[axis] = diff.signum() as i32;
        let d = dir[axis];
        // Rounding can give a crossing with d = 0 (or of the wrong sign) only for degenerate
        // segments; such an axis is then stepped last, which keeps the walk connected.
        if d * f64::from(step[axis]) > 0.0 {
            let boundary = f64::from(origin_key[axis]) + if step[axis] > 0 { 1.0 } else { 0.0 };
            t_max[axis] = ((boundary - o[axis]) / d).clamp(0.0, f64::MAX);
            t_delta[axis] = (1.0 / d.abs()).min(f64::MAX);
        } else {
            t_max[axis] = f64::MAX;
        }
    }
    let total = remaining[0] + remaining[1] + remaining[2];
    if total == 0 {
        return;
    }
    visit(key);
    for _ in 1..total {
        // The axis whose boundary comes first. An axis with no steps left has t_max = ∞, above
        // the finite (at most f64::MAX) t_max of every axis with steps left.
        let axis = if t_max[0] <= t_max[1] {
            if t_max[0] <= t_max[2] {
                0
            } else {
                2
            }
        } else if t_max[1] <= t_max[2] {
            1
        } else {
            2
        };
        key[axis] += step[axis];
        remaining[axis] -= 1;
        t_max[axis] = if remaining[axis] == 0 {
            f64::INFINITY
        } else {
            (t_max[axis] + t_delta[axis]).min(f64::MAX)
        };
        visit(key);
    }
}

#[cfg(test)]
mod tests {
    use super::*;
    use proptest::prelude::*;

    fn map() -> VoxelMap {
        VoxelMap::new(VoxelConfig::default()).unwrap()
    }

    /// Keys visited by `traverse`, with the end key appended.
    fn chain(origin: &Vec3, end: &Vec3, s: f64) -> Vec<VoxelKey> {
        let inv_s = 1.0 / s;
        let mut keys = Vec::new();
        traverse(origin, key_of(origin, inv_s).unwrap(), end, inv_s, |k| {
            keys.push(k)
        });
        keys.push(key_of(end, inv_s).unwrap());
        keys
    }

    #[test]
    fn voxel_config_defaults_are_octomaps() {
        let c = VoxelConfig::default();
        c.validate().unwrap();
        assert!((c.hit_log_odds - 0.847_297_860_387_203_4).abs() < 1e-12);
        assert!((c.miss_log_odds + 0.405_465_108_108_164_3).abs() < 1e-12);
        assert!((c.min_log_odds + 1.992_430_164_690_206_3).abs() < 1e-12);
        assert!((c.max_log_odds - 3.476_098_689_835_272).abs() < 1e-12);
        for bad in [
            VoxelConfig { voxel_m: 0.0, ..c },
            VoxelConfig {
                voxel_m: f64::NAN,
                ..c
            },
            VoxelConfig {
                hit_log_odds: -0.1,
                ..c
            },
            VoxelConfig {
                miss_log_odds: 0.1,
                ..c
            },
            VoxelConfig {
                min_log_odds: 0.5,
                ..c
            },
            VoxelConfig {
                max_log_odds: f64::INFINITY,
                ..c
            },
            VoxelConfig {
                max_range_m: 0.0,
                ..c
            },
        ] {
            assert!(VoxelMap::new(bad).is_err(), "{bad:?}");
        }
        // Unknown keys are refused, missing keys take the defaults.
        assert!(toml::from_str::<VoxelConfig>("voxel_size = 0.1").is_err());
        let partial: VoxelConfig = toml::from_str("voxel_m = 0.1").unwrap();
        assert_eq!(partial.max_range_m, 8.0);
    }

    #[test]
    fn voxel_single_ray_marks_free_then_occupied() {
        let mut m = map();
        let origin = Vec3::new(0.01, 0.02, 0.03);
        let pose = Pose::translation(origin.x, origin.y, origin.z);
        // A ray along +x, 1 m long: voxels i = 0..=20 at j = k = 0.
        m.insert_scan(&pose, &[Vec3::new(1.0, 0.0, 0.0)]);
        let hit = VoxelConfig::default().hit_log_odds as f32;
        let miss = VoxelConfig::default().miss_log_odds as f32;
        for i in 0..20 {
            assert_eq!(m.log_odds(&[i, 0, 0]), Some(miss), "voxel {i}");
        }
        assert_eq!(m.log_odds(&[20, 0, 0]), Some(hit));
        assert_eq!(m.counts(), (1, 20));
        assert_eq!(m.len(), 21);
        assert_eq!(
            m.occupancy(&(origin + Vec3::new(1.0, 0.0, 0.0))),
            Occupancy::Occupied
        );
        assert_eq!(m.occupancy(&Vec3::new(0.5, 0.02, 0.03)), Occupancy::Free);
        // Beyond the end, beside the ray, behind the origin: unknown.
        for p in [
            Vec3::new(1.2, 0.02, 0.03),
            Vec3::new(0.5, 0.1, 0.03),
            Vec3::new(0.5, 0.02, -0.03),
            Vec3::new(-0.1, 0.02, 0.03),
        ] {
            assert_eq!(m.occupancy(&p), Occupancy::Unknown, "{p:?}");
        }
        let centres = m.occupied_centres();
        assert_eq!(centres.len(), 1);
        assert!((centres[0] - Vec3::new(1.025, 0.025, 0.025)).norm() < 1e-12);
        let (lo, hi) = m.bounds().unwrap();
        assert!((lo - Vec3::zeros()).norm() < 1e-12);
        assert!((hi - Vec3::new(1.05, 0.05, 0.05)).norm() < 1e-12);
        assert!(map().bounds().is_none());
    }

    #[test]
    fn voxel_rays_are_cut_at_max_range_and_bad_points_skipped() {
        let mut m = VoxelMap::new(VoxelConfig {
            max_range_m: 1.0,
            ..Default::default()
        })
        .unwrap();
        let pose = Pose::translation(0.01, 0.01, 0.01);
        m.insert_scan(
            &pose,
            &[
                Vec3::new(3.0, 0.0, 0.0),
                Vec3::new(f64::NAN, 1.0, 0.0),
                Vec3::new(0.0, f64::INFINITY, 0.0),
            ],
        );
        // Free up to the cut at 1 m, no hit, unknown beyond.
        assert_eq!(m.counts(), (0, 20));
        assert_eq!(m.occupancy(&Vec3::new(0.9, 0.01, 0.01)), Occupancy::Free);
        assert_eq!(
            m.occupancy(&Vec3::new(2.99, 0.01, 0.01)),
            Occupancy::Unknown
        );
        assert_eq!(m.occupancy(&Vec3::new(0.01, 0.5, 0.01)), Occupancy::Unknown);
    }

    #[test]
    fn voxel_hit_wins_over_miss_and_one_update_per_scan() {
        let mut m = map();
        let pose = Pose::translation(0.01, 0.01, 0.01);
        // The first ray ends in voxel [20, 0, 0]; the second passes through it to [40, 0, 0];
        // the third repeats the first. [20, 0, 0] gets one hit, [10, 0, 0] one miss.
        m.insert_scan(
            &pose,
            &[
                Vec3::new(1.02, 0.0, 0.0),
                Vec3::new(2.02, 0.0, 0.0),
                Vec3::new(1.03, 0.0, 0.0),
            ],
        );
        let c = VoxelConfig::default();
        assert_eq!(m.log_odds(&[20, 0, 0]), Some(c.hit_log_odds as f32));
        assert_eq!(m.log_odds(&[40, 0, 0]), Some(c.hit_log_odds as f32));
        assert_eq!(m.log_odds(&[10, 0, 0]), Some(c.miss_log_odds as f32));
        assert_eq!(m.log_odds(&[30, 0, 0]), Some(c.miss_log_odds as f32));
    }

    #[test]
    fn voxel_log_odds_are_clamped() {
        let mut m = map();
        let pose = Pose::translation(0.01, 0.01, 0.01);
        for _ in 0..20 {
            m.insert_scan(&pose, &[Vec3::new(0.5, 0.0, 0.0)]);
        }
        let c = VoxelConfig::default();
        assert_eq!(m.log_odds(&[10, 0, 0]), Some(c.max_log_odds as f32));
        assert_eq!(m.log_odds(&[5, 0, 0]), Some(c.min_log_odds as f32));
        // A clamped occupied voxel is cleared by a bounded number of misses (the map can change
        // its mind): ceil((3.476 + 0) / 0.405) = 9 scans.
        for n in 1..=9 {
            m.insert_scan(&pose, &[Vec3::new(1.0, 0.0, 0.0)]);
            let expect = if n < 9 {
                Occupancy::Occupied
            } else {
                Occupancy::Free
            };
            assert_eq!(
                m.occupancy(&Vec3::new(0.52, 0.01, 0.01)),
                expect,
                "scan {n}"
            );
        }
    }

    /// A fan of rays from `origin` ending on the plane x = `x`, over the patch
    /// |y|, |z − 0.5| ≤ 0.03 · `half`.
    fn fan(origin: &Vec3, x: f64, half: i32) -> Vec<Vec3> {
        let mut points = Vec::new();
        for iy in -half..=half {
            for iz in -half..=half {
                let target = Vec3::new(x, 0.03 * f64::from(iy), 0.5 + 0.03 * f64::from(iz));
                points.push(target - origin);
            }
        }
        points
    }

    #[test]
    fn voxel_moved_rubble_is_cleared() {
        let mut m = map();
        let origin = Vec3::new(0.0, 0.0, 0.5);
        let pose = Pose::translation(origin.x, origin.y, origin.z);
        // Scan 1: rubble at x = 2.01 in front of a wall at x = 4.01.
        let rubble = fan(&origin, 2.01, 10);
        m.insert_scan(&pose, &rubble);
        let rubble_in_world: Vec<Vec3> = rubble.iter().map(|p| p + origin).collect();
        assert!(rubble_in_world
            .iter()
            .all(|p| m.occupancy(p) == Occupancy::Occupied));
        assert_eq!(
            m.filter_occupied(&rubble_in_world).len(),
            m.counts().0,
            "one point per occupied voxel"
        );
        // The rubble is moved away; later scans, from slightly different places, see the wall
        // through where it was (the wall's patch is wide enough that its rays cross all of the
        // rubble's place). One hit (+0.85) needs three misses (−0.41 each) to turn free.
        let mut all_points = rubble_in_world.clone();
        for n in 0..3 {
            let origin_n = origin + Vec3::new(0.0, 0.01 * f64::from(n), 0.0);
            let wall = fan(&origin_n, 4.01, 25);
            m.insert_scan(
                &Pose::translation(origin_n.x, origin_n.y, origin_n.z),
                &wall,
            );
            all_points.extend(wall.iter().map(|p| p + origin_n));
        }
        let merged = m.filter_occupied(&all_points);
        assert!(!merged.is_empty());
        assert!(
            merged.iter().all(|p| (p.x - 4.01).abs() < 1e-9),
            "rubble survived: {:?}",
            merged.iter().find(|p| p.x < 3.0)
        );
        let cleared = rubble_in_world
            .iter()
            .filter(|p| m.occupancy(p) == Occupancy::Free)
            .count();
        assert_eq!(cleared, rubble_in_world.len());
        // The merged cloud keeps one centroid per occupied wall voxel.
        let mut keys: Vec<VoxelKey> = merged.iter().map(|p| m.key_of(p).unwrap()).collect();
        keys.sort_unstable();
        keys.dedup();
        assert_eq!(keys.len(), merged.len());
    }

    #[test]
    fn voxel_from_voxels_checks_values() {
        let c = VoxelConfig::default();
        let m = VoxelMap::from_voxels(c, [([1, 2, 3], 0.5), ([-1, 0, 0], -0.2)]).unwrap();
        assert_eq!(m.counts(), (1, 1));
        assert!(VoxelMap::from_voxels(c, [([1, 2, 3], f32::NAN)]).is_err());
        assert!(VoxelMap::from_voxels(c, [([1, 2, 3], 10.0)]).is_err());
        assert!(VoxelMap::from_voxels(c, [([1, 2, 3], 0.5), ([1, 2, 3], 0.4)]).is_err());
        assert!(VoxelMap::from_voxels(c, [([i32::MAX, 2, 3], 0.5)]).is_err());
    }

    #[test]
    fn voxel_dda_diagonal_and_degenerate() {
        // Same voxel: just that voxel.
        let a = Vec3::new(0.01, 0.01, 0.01);
        assert_eq!(chain(&a, &Vec3::new(0.02, 0.03, 0.04), 0.05).len(), 1);
        // Negative direction crossing zero.
        let c = chain(
            &Vec3::new(0.12, 0.01, 0.01),
            &Vec3::new(-0.12, 0.01, 0.01),
            0.05,
        );
        let xs: Vec<i32> = c.iter().map(|k| k[0]).collect();
        assert_eq!(xs, vec![2, 1, 0, -1, -2, -3]);
        // Through an exact corner: still a face-connected chain.
        let c = chain(
            &Vec3::new(0.025, 0.025, 0.025),
            &Vec3::new(0.125, 0.125, 0.125),
            0.05,
        );
        assert_eq!(c.first(), Some(&[0, 0, 0]));
        assert_eq!(c.last(), Some(&[2, 2, 2]));
        assert_eq!(c.len(), 7);
    }

    /// Distance from the segment to the closed box of a voxel is ~0 (the slab test).
    fn segment_touches_voxel(o: &Vec3, e: &Vec3, key: &VoxelKey, s: f64) -> bool {
        let (mut t0, mut t1) = (0.0f64, 1.0f64);
        let eps = 1e-9;
        for axis in 0..3 {
            let lo = f64::from(key[axis]) * s - eps;
            let hi = f64::from(key[axis] + 1) * s + eps;
            let d = e[axis] - o[axis];
            if d.abs() < 1e-15 {
                if o[axis] < lo || o[axis] > hi {
                    return false;
                }
            } else {
                let (a, b) = ((lo - o[axis]) / d, (hi - o[axis]) / d);
                t0 = t0.max(a.min(b));
                t1 = t1.min(a.max(b));
            }
        }
        t0 <= t1 + 1e-12
    }

    proptest! {
        #[test]
        fn voxel_dda_matches_dense_sampling(
            o in prop::array::uniform3(-2.0f64..2.0),
            e in prop::array::uniform3(-2.0f64..2.0),
            s in prop::sample::select(vec![0.05, 0.1, 0.37]),
        ) {
            let (o, e) = (Vec3::from(o), Vec3::from(e));
            let keys = chain(&o, &e, s);
            let inv_s = 1.0 / s;
            // Starts at the origin's voxel, ends at the end's, face-connected, no repeats.
            prop_assert_eq!(keys[0], key_of(&o, inv_s).unwrap());
            for w in keys.windows(2) {
                let d: i32 = (0..3).map(|a| (w[1][a] - w[0][a]).abs()).sum();
                prop_assert_eq!(d, 1, "{:?} -> {:?}", w[0], w[1]);
            }
            let mut sorted = keys.clone();
            sorted.sort_unstable();
            sorted.dedup();
            prop_assert_eq!(sorted.len(), keys.len());
            // Every voxel visited touches the segment.
            for k in &keys {
                prop_assert!(segment_touches_voxel(&o, &e, k, s), "{:?} off the ray", k);
            }
            // Every voxel a dense sampling of the segment lands in (away from boundaries, where
            // rounding may pick the neighbour) is visited.
            let n = ((e - o).norm() * inv_s * 50.0).ceil() as usize + 1;
            for i in 0..=n {
                let p = o + (e - o) * (i as f64 / n as f64);
                let near_boundary = (0..3).any(|a| {
                    let f = p[a] * inv_s;
                    (f - f.round()).abs() < 1e-7
                });
                if near_boundary {
                    continue;
                }
                let k = key_of(&p, inv_s).unwrap();
                prop_assert!(sorted.binary_search(&k).is_ok(), "sample {:?} in {:?} missed", p, k);
            }
        }
    }
}
