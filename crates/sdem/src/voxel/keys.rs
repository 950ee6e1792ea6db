//! How voxels are keyed and stored: the integer key of the voxel holding a point, the dense
//! blocks that hold the voxels, and the hash table from block keys to blocks.

use super::{VoxelKey, MAX_KEY};
use crate::geometry::Vec3;
use std::collections::HashMap;
use std::hash::{BuildHasherDefault, Hash, Hasher};

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
pub(super) struct Cell {
    pub(super) log_odds: f32,
    pub(super) stamp: u32,
}

/// A dense block of voxels.
#[derive(Debug, Clone)]
pub(super) struct Block {
    /// The block's key: the voxel key divided by `BLOCK_EDGE`, rounded down.
    block_key: VoxelKey,
    pub(super) cells: [Cell; BLOCK_LEN],
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
    pub(super) fn voxel_key(&self, index: usize) -> VoxelKey {
        let mask = BLOCK_EDGE as usize - 1;
        let b = BLOCK_BITS as usize;
        let local = [index & mask, (index >> b) & mask, index >> (2 * b)];
        std::array::from_fn(|axis| (self.block_key[axis] << BLOCK_BITS) + local[axis] as i32)
    }
}

/// The block holding a voxel and the voxel's index in it.
#[inline]
pub(super) fn split_key(key: VoxelKey) -> (VoxelKey, usize) {
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

/// The position in `blocks` of the block with this key, appending a new (all unknown) block if
/// there is none yet.
pub(super) fn block_position(
    blocks: &mut Vec<Block>,
    block_index: &mut KeyMap<u32>,
    block_key: VoxelKey,
) -> usize {
    *block_index.entry(Key(block_key)).or_insert_with(|| {
        blocks.push(Block::new(block_key));
        (blocks.len() - 1) as u32
    }) as usize
}

/// The key of the voxel holding `p`, with `inv_s` = 1 / voxel edge; `None` when non-finite or out
/// of the key range.
#[inline]
pub(super) fn key_of(p: &Vec3, inv_s: f64) -> Option<VoxelKey> {
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
