//! What several integration tests of the loop share.

use sdem::map::Node;
use sdem::store::NodeStore;
use std::collections::HashMap;
use std::sync::Mutex;

/// A node store in memory that counts the nodes it gave back.
#[derive(Debug, Default)]
pub struct Memory {
    /// The points of every node kept, by node id.
    pub kept: Mutex<HashMap<usize, Vec<[f32; 3]>>>,
    /// How many nodes [`NodeStore::fetch`] gave back.
    pub fetches: Mutex<usize>,
}

impl NodeStore for Memory {
    fn keep(&self, node: &Node) -> sdem::Result<()> {
        let mut kept = self.kept.lock().unwrap();
        kept.entry(node.node_id)
            .or_insert_with(|| node.points_in_sensor.clone());
        Ok(())
    }

    fn fetch(&self, node_id: usize) -> sdem::Result<Vec<[f32; 3]>> {
        *self.fetches.lock().unwrap() += 1;
        Ok(self.kept.lock().unwrap()[&node_id].clone())
    }
}
