//! Finding the nodes near a place without looking at every node: a hash of node positions on a
//! grid of cubes, and each node's place descriptor computed once, when it joins the map. A
//! question about a place costs the nodes near it, not the map: what keeps the loop's time per
//! stop flat as the map grows to thousands of nodes.

use crate::geometry::Vec3;
use crate::map::{Descriptor, LoopClosureConfig};
use std::collections::HashMap;

/// Edge of the cubes nodes are hashed into, metres.
const CELL_M: f64 = 2.0;

/// A node as the index knows it.
#[derive(Debug, Clone)]
struct Entry {
    position: Vec3,
    cell: [i32; 3],
    descriptor: Descriptor,
    /// The node's heading when its descriptor was computed, radians.
    descriptor_yaw: f64,
}

/// Node positions hashed on a grid of `CELL_M` cubes, with each node's descriptor.
#[derive(Debug, Clone, Default)]
pub struct NodeIndex {
    cells: HashMap<[i32; 3], Vec<usize>>,
    entries: Vec<Option<Entry>>,
}

fn cell_of(p: &Vec3) -> [i32; 3] {
    let c = |v: f64| (v / CELL_M).floor().clamp(i32::MIN as f64, i32::MAX as f64) as i32;
    [c(p.x), c(p.y), c(p.z)]
}

impl NodeIndex {
    /// An empty index.
    pub fn new() -> Self {
        Self::default()
    }

    /// Nodes in the index.
    pub fn len(&self) -> usize {
        self.entries.iter().filter(|e| e.is_some()).count()
    }

    /// True when no node is in the index.
    pub fn is_empty(&self) -> bool {
        self.len() == 0
    }

    /// Adds node `node_id` at `position` with its descriptor, computed with the node at heading
    /// `yaw` (radians); a node already there is replaced.
    pub fn insert(&mut self, node_id: usize, position: Vec3, descriptor: Descriptor, yaw: f64) {
        self.remove_from_cell(node_id);
        let cell = cell_of(&position);
        self.cells.entry(cell).or_default().push(node_id);
        if self.entries.len() <= node_id {
            self.entries.resize(node_id + 1, None);
        }
        self.entries[node_id] = Some(Entry {
            position,
            cell,
            descriptor,
            descriptor_yaw: yaw,
        });
    }

    /// Moves node `node_id` to `position` (after a pose-graph solve); its descriptor stays.
    pub fn moved(&mut self, node_id: usize, position: Vec3) {
        let Some(Some(entry)) = self.entries.get(node_id) else {
            return;
        };
        let cell = cell_of(&position);
        if cell != entry.cell {
            self.remove_from_cell(node_id);
            self.cells.entry(cell).or_default().push(node_id);
        }
        if let Some(entry) = self.entries[node_id].as_mut() {
            entry.position = position;
            entry.cell = cell;
        }
    }

    fn remove_from_cell(&mut self, node_id: usize) {
        let Some(Some(entry)) = self.entries.get(node_id) else {
            return;
        };
        if let Some(ids) = self.cells.get_mut(&entry.cell) {
            ids.retain(|&id| id != node_id);
            if ids.is_empty() {
                self.cells.remove(&entry.cell);
            }
        }
    }

    /// The node's descriptor and the heading it was computed at.
    pub fn descriptor(&self, node_id: usize) -> Option<(&Descriptor, f64)> {
        let entry = self.entries.get(node_id)?.as_ref()?;
        Some((&entry.descriptor, entry.descriptor_yaw))
    }

    /// The nodes within `radius_m` of `position`, by id.
    pub fn within(&self, position: &Vec3, radius_m: f64) -> Vec<usize> {
        let lo = cell_of(&(position - Vec3::repeat(radius_m)));
        let hi = cell_of(&(position + Vec3::repeat(radius_m)));
        let mut found = Vec::new();
        let mut take = |ids: &[usize]| {
            for &id in ids {
                let entry = self.entries[id]
                    .as_ref()
                    .expect("indexed nodes have entries");
                if (entry.position - position).norm() <= radius_m {
                    found.push(id);
                }
            }
        };
        // The cube's cells, or the occupied cells when they are fewer: a radius of a kilometre
        // spans 1e9 cells of 2 m, and a loop-closure search over it never ended.
        let span: u128 = (0..3)
            .map(|a| (hi[a] as i128 - lo[a] as i128 + 1) as u128)
            .product();
        if span > self.cells.len() as u128 {
            for (cell, ids) in &self.cells {
                if (0..3).all(|a| (lo[a]..=hi[a]).contains(&cell[a])) {
                    take(ids);
                }
            }
        } else {
            for x in lo[0]..=hi[0] {
                for y in lo[1]..=hi[1] {
                    for z in lo[2]..=hi[2] {
                        take(self.cells.get(&[x, y, z]).map_or(&[], Vec::as_slice));
                    }
                }
            }
        }
        found.sort_unstable();
        found
    }

    /// Loop-closure candidates for a node at `position` with `descriptor`: the nodes with ids up
    /// to `newest_id` within `config.search_radius_m` whose descriptors lie within
    /// `config.max_descriptor_distance` (compared over azimuth shifts of up to `max_shift`
    /// sectors), most similar first, at most `config.max_candidates`.
    pub fn similar_near(
        &self,
        position: &Vec3,
        descriptor: &Descriptor,
        newest_id: usize,
        config: &LoopClosureConfig,
        max_shift: usize,
    ) -> Vec<(usize, f64)> {
        let (radius_m, max_distance) = (config.search_radius_m, config.max_descriptor_distance);
        let mut candidates: Vec<(usize, f64)> = self
            .within(position, radius_m)
            .into_iter()
            .filter(|&id| id <= newest_id)
            .filter_map(|id| {
                let (other, _) = self.descriptor(id)?;
                let d = other.distance(descriptor, max_shift)?;
                (d <= max_distance).then_some((id, d))
            })
            .collect();
        candidates.sort_by(|a, b| a.1.total_cmp(&b.1).then(a.0.cmp(&b.0)));
        candidates.truncate(config.max_candidates);
        candidates
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    fn descriptor(scale: f32) -> Descriptor {
        Descriptor {
            mean_range: (0..crate::map::SECTORS * crate::map::BANDS)
                .map(|k| scale * (1.0 + (k % 5) as f32))
                .collect(),
        }
    }

    #[test]
    fn nodes_near_a_place_are_those_a_scan_of_every_node_finds() {
        let mut index = NodeIndex::new();
        let positions: Vec<Vec3> = (0..300)
            .map(|i| {
                let a = i as f64 * 0.37;
                Vec3::new(
                    6.0 * a.cos() + 0.01 * i as f64,
                    4.0 * a.sin(),
                    0.1 * (i % 3) as f64,
                )
            })
            .collect();
        for (id, p) in positions.iter().enumerate() {
            index.insert(id, *p, descriptor(1.0), 0.0);
        }
        // Some nodes move, as after a solve.
        for id in (0..300).step_by(7) {
            let p = positions[id] + Vec3::new(2.5, -1.0, 0.0);
            index.moved(id, p);
        }
        let now = |id: usize| {
            if id.is_multiple_of(7) {
                positions[id] + Vec3::new(2.5, -1.0, 0.0)
            } else {
                positions[id]
            }
        };
        // A radius whose cube spans more cells than the index holds is answered from the
        // occupied cells (a kilometre's cube of 2 m cells never finished).
        for (centre, radius) in [
            (Vec3::zeros(), 1.5),
            (Vec3::new(6.0, 0.0, 0.0), 3.0),
            (Vec3::new(-2.0, 3.9, 0.1), 0.7),
            (Vec3::new(1.0, 1.0, 0.0), 20.0),
            (Vec3::zeros(), 1e6),
        ] {
            let brute: Vec<usize> = (0..300)
                .filter(|&id| (now(id) - centre).norm() <= radius)
                .collect();
            assert!(!brute.is_empty());
            assert_eq!(index.within(&centre, radius), brute);
        }
        assert_eq!(index.len(), 300);
    }

    #[test]
    fn candidates_are_the_most_similar_older_nodes_near_the_place() {
        let mut index = NodeIndex::new();
        for (id, (x, scale)) in [(0.0, 1.0), (0.2, 1.3), (0.4, 1.02), (5.0, 1.0), (0.3, 1.01)]
            .into_iter()
            .enumerate()
        {
            index.insert(id, Vec3::new(x, 0.0, 0.0), descriptor(scale), 0.0);
        }
        let found = index.similar_near(
            &Vec3::zeros(),
            &descriptor(1.0),
            3,
            &LoopClosureConfig {
                search_radius_m: 1.5,
                max_descriptor_distance: 0.2,
                max_candidates: 2,
                ..Default::default()
            },
            1,
        );
        // Node 3 is far, node 4 is too new, node 1 too different: 0 then 2.
        assert_eq!(found.iter().map(|c| c.0).collect::<Vec<_>>(), vec![0, 2]);
        assert!(found[0].1 < found[1].1);
    }
}
