//! Nodes far from the robot keep their points elsewhere: a [`NodeStore`] (the saved map's node
//! files, in `sdem_io`; the library itself never opens a file) keeps a node's points, the map
//! drops them from memory ("parks" the node), and they come back when a step needs them: a
//! loop closure to an old place, or a node whose fused scan a closure moved.
//!
//! [`Residency`] decides which nodes keep their points in memory: at most a set number, the ones
//! used most recently (the newest, which the next stops match against, always among them).

use crate::error::{Error, Result};
use crate::map::{Map, Node};
use std::sync::Arc;

/// Where the points of parked nodes are kept. Implemented outside the library (by `sdem_io` over
/// a saved map's `nodes/` folder), so the library stays free of file I/O.
pub trait NodeStore: Send + Sync + std::fmt::Debug {
    /// Keeps `node`'s points, so that [`NodeStore::fetch`] can give them back. Called before a
    /// node is parked; a node already kept (its points never change) needs nothing done.
    ///
    /// # Errors
    /// [`Error::NodeStore`] when they cannot be kept: the node then stays in memory.
    fn keep(&self, node: &Node) -> Result<()>;

    /// The points of node `node_id`, as [`NodeStore::keep`] got them.
    ///
    /// # Errors
    /// [`Error::NodeStore`] when they cannot be read back.
    fn fetch(&self, node_id: usize) -> Result<Vec<[f32; 3]>>;
}

/// Which nodes hold their points in memory, and the store that keeps the others'.
#[derive(Debug, Clone, Default)]
pub struct Residency {
    store: Option<Arc<dyn NodeStore>>,
    /// Most nodes holding their points at once (with a store).
    limit: usize,
    /// Per node: parked (points in the store only).
    parked: Vec<bool>,
    /// Per node: its points' count (checked when they come back).
    points: Vec<usize>,
    /// Per node: the use counter when it was last used.
    last_used: Vec<u64>,
    uses: u64,
}

impl Residency {
    /// Keeps every node's points in memory (no store).
    pub fn in_memory() -> Self {
        Self::default()
    }

    /// Parks nodes beyond `limit` (the least recently used) in `store`.
    pub fn with_store(store: Arc<dyn NodeStore>, limit: usize) -> Self {
        Self {
            store: Some(store),
            limit: limit.max(1),
            ..Self::default()
        }
    }

    /// Whether a store is attached.
    pub fn has_store(&self) -> bool {
        self.store.is_some()
    }

    /// Whether node `node_id`'s points are in the store only.
    pub fn is_parked(&self, node_id: usize) -> bool {
        self.parked.get(node_id).copied().unwrap_or(false)
    }

    /// The number of node `node_id`'s points, parked or not (0 for a node not in `map`).
    pub fn point_count(&self, map: &Map, node_id: usize) -> usize {
        match map.nodes.get(node_id) {
            Some(_) if self.is_parked(node_id) => self.points[node_id],
            Some(node) => node.points_in_sensor.len(),
            None => 0,
        }
    }

    /// Nodes holding their points in memory.
    pub fn resident(&self, map: &Map) -> usize {
        map.nodes.len() - self.parked.iter().filter(|&&p| p).count()
    }

    /// Records that the nodes of `map` up to its last exist (new ones are resident, in use).
    fn follow(&mut self, map: &Map) {
        let n = map.nodes.len();
        while self.parked.len() < n {
            let id = self.parked.len();
            self.parked.push(false);
            self.points.push(map.nodes[id].points_in_sensor.len());
            self.last_used.push(self.uses);
        }
    }

    /// Brings the points of `ids` back into memory where they were parked, and counts them as
    /// used now.
    ///
    /// # Errors
    /// [`Error::NodeStore`] when the store cannot give a node back, or gives back another
    /// number of points than the node had.
    pub fn bring(&mut self, map: &mut Map, ids: &[usize]) -> Result<()> {
        self.follow(map);
        self.uses += 1;
        for &id in ids {
            if id >= map.nodes.len() {
                continue;
            }
            self.last_used[id] = self.uses;
            if self.parked[id] {
                map.nodes[id].points_in_sensor = self.fetch_checked(id)?;
                self.parked[id] = false;
            }
        }
        Ok(())
    }

    /// Node `id`'s points: from memory, or fetched from the store for this use only.
    ///
    /// # Errors
    /// As [`Residency::bring`].
    pub fn points_of<'m>(
        &self,
        map: &'m Map,
        id: usize,
    ) -> Result<std::borrow::Cow<'m, [[f32; 3]]>> {
        if self.is_parked(id) {
            Ok(std::borrow::Cow::Owned(self.fetch_checked(id)?))
        } else {
            Ok(std::borrow::Cow::Borrowed(&map.nodes[id].points_in_sensor))
        }
    }

    fn fetch_checked(&self, id: usize) -> Result<Vec<[f32; 3]>> {
        let store = self.store.as_ref().ok_or_else(|| Error::NodeStore {
            node_id: id,
            reason: "the node is parked but no store is attached".into(),
        })?;
        let points = store.fetch(id)?;
        if points.len() != self.points[id] {
            return Err(Error::NodeStore {
                node_id: id,
                reason: format!(
                    "the store gave back {} points; the node had {}",
                    points.len(),
                    self.points[id]
                ),
            });
        }
        Ok(points)
    }

    /// Parks the least recently used nodes, none of the `keep_newest` newest, until at most the
    /// limit hold their points. Does nothing without a store.
    ///
    /// # Returns
    /// The nodes parked.
    ///
    /// # Errors
    /// [`Error::NodeStore`] when the store cannot keep a node (it stays in memory; the nodes
    /// parked before it stay parked).
    pub fn trim(&mut self, map: &mut Map, keep_newest: usize) -> Result<usize> {
        self.follow(map);
        let Some(store) = self.store.clone() else {
            return Ok(0);
        };
        let resident = self.resident(map);
        if resident <= self.limit {
            return Ok(0);
        }
        let newest_from = map.nodes.len().saturating_sub(keep_newest);
        let mut candidates: Vec<usize> = (0..newest_from).filter(|&id| !self.parked[id]).collect();
        candidates.sort_by_key(|&id| (self.last_used[id], id));
        let mut parked = 0;
        for id in candidates.into_iter().take(resident - self.limit) {
            store.keep(&map.nodes[id])?;
            map.nodes[id].points_in_sensor = Vec::new();
            self.parked[id] = true;
            parked += 1;
        }
        Ok(parked)
    }
}

#[cfg(test)]
mod tests {
    use super::*;
    use crate::geometry::Pose;
    use std::collections::HashMap;
    use std::sync::Mutex;

    /// A store in memory that counts what it is asked.
    #[derive(Debug, Default)]
    struct Memory {
        kept: Mutex<HashMap<usize, Vec<[f32; 3]>>>,
        fetches: Mutex<usize>,
    }

    impl NodeStore for Memory {
        fn keep(&self, node: &Node) -> Result<()> {
            let mut kept = self.kept.lock().unwrap();
            kept.entry(node.node_id)
                .or_insert_with(|| node.points_in_sensor.clone());
            Ok(())
        }

        fn fetch(&self, node_id: usize) -> Result<Vec<[f32; 3]>> {
            *self.fetches.lock().unwrap() += 1;
            self.kept
                .lock()
                .unwrap()
                .get(&node_id)
                .cloned()
                .ok_or(Error::NodeStore {
                    node_id,
                    reason: "never kept".into(),
                })
        }
    }

    fn map(n: usize) -> Map {
        Map {
            nodes: (0..n)
                .map(|i| Node {
                    node_id: i,
                    scan_index: i,
                    world_from_sensor: Pose::identity(),
                    attitude_reading: None,
                    points_in_sensor: vec![[i as f32, 1.0, 2.0]; 10 + i],
                })
                .collect(),
        }
    }

    #[test]
    fn the_least_recently_used_nodes_are_parked_and_come_back_as_they_were() {
        let original = map(12);
        let mut map = original.clone();
        let store = Arc::new(Memory::default());
        let mut residency = Residency::with_store(store.clone(), 5);
        residency.bring(&mut map, &[1, 2]).unwrap();
        // Nodes 1 and 2 were used last, 9..12 are the newest: 0, 3, 4, 5, 6, 7 go, in that order.
        assert_eq!(residency.trim(&mut map, 3).unwrap(), 7);
        let parked: Vec<usize> = (0..12).filter(|&i| residency.is_parked(i)).collect();
        assert_eq!(parked, vec![0, 3, 4, 5, 6, 7, 8]);
        assert_eq!(residency.resident(&map), 5);
        assert!(map.nodes[4].points_in_sensor.is_empty());
        // Read for one use, and brought back for good.
        assert_eq!(
            *residency.points_of(&map, 4).unwrap(),
            original.nodes[4].points_in_sensor[..]
        );
        assert!(residency.is_parked(4));
        residency.bring(&mut map, &[4, 6]).unwrap();
        assert_eq!(map, {
            let mut expected = original.clone();
            for i in [0, 3, 5, 7, 8] {
                expected.nodes[i].points_in_sensor.clear();
            }
            expected
        });
        assert_eq!(*store.fetches.lock().unwrap(), 3);
        // A store that gives back the wrong points is an error, not a wrong map.
        store.kept.lock().unwrap().get_mut(&0).unwrap().pop();
        let e = residency.bring(&mut map, &[0]).unwrap_err();
        assert!(
            e.to_string().contains("node 0") && e.to_string().contains("9 points"),
            "{e}"
        );
    }

    #[test]
    fn without_a_store_nothing_is_parked() {
        let mut map = map(50);
        let mut residency = Residency::in_memory();
        assert_eq!(residency.trim(&mut map, 1).unwrap(), 0);
        assert_eq!(residency.resident(&map), 50);
    }
}
