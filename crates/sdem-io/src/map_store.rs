//! A saved map's folder as the loop's node store: the points of nodes far from the robot live
//! in the map's own `nodes/NNNNNN.pts` files (immutable, written once), and come back from
//! them. One [`MapFolder`] both saves the map and keeps the parked nodes, so the manifest
//! always names the files the store holds.

use crate::error::{Error, Result};
use crate::mapfile::{read_node_file, save_map, write_node_file, NodeFiles};
use sdem::map::{LoopClosure, Map, Node};
use sdem::posegraph::Edge;
use sdem::slam::SlamOptions;
use std::path::{Path, PathBuf};
use std::sync::Mutex;

/// A map folder that saves the map and keeps the points of parked nodes: attach it to the loop
/// with `sdem::Slam::set_node_store`, save with [`MapFolder::save_slam`] (as often as wanted:
/// each save writes only the nodes it has not written yet, then the manifest).
///
/// # Example
/// ```
/// use std::sync::Arc;
/// use sdem_io::MapFolder;
/// let dir = tempfile::tempdir().unwrap();
/// let folder = Arc::new(MapFolder::create(&dir.path().join("map"))?);
/// let mut slam = sdem::Slam::new(sdem::SlamOptions::default())?;
/// slam.set_node_store(folder.clone());
/// // … slam.add(…) at every stop, then:
/// folder.save_slam(&slam)?;
/// assert!(dir.path().join("map/map.json").exists());
/// // `sdem localize --map`, `sdem view map` and `sdem_io::load_map` read it.
/// let saved = sdem_io::load_map(&dir.path().join("map"))?;
/// assert_eq!(saved.map.nodes.len(), slam.map.nodes.len());
/// # Ok::<(), Box<dyn std::error::Error>>(())
/// ```
#[derive(Debug)]
pub struct MapFolder {
    folder: PathBuf,
    files: Mutex<NodeFiles>,
}

impl MapFolder {
    /// A new map folder (created when missing; an old map in it is written over as nodes
    /// come).
    ///
    /// # Errors
    /// The folder cannot be created.
    pub fn create(folder: &Path) -> Result<Self> {
        Self::open(folder, NodeFiles::default())
    }

    /// A map folder that holds the node files `files` already (from [`crate::load_map`]'s
    /// [`crate::SavedMap::node_files`], to go on with a saved map).
    ///
    /// # Errors
    /// The folder cannot be created.
    pub fn open(folder: &Path, files: NodeFiles) -> Result<Self> {
        let nodes = folder.join("nodes");
        std::fs::create_dir_all(&nodes).map_err(|e| Error::io(&nodes, e))?;
        Ok(Self {
            folder: folder.to_path_buf(),
            files: Mutex::new(files),
        })
    }

    /// The folder.
    pub fn path(&self) -> &Path {
        &self.folder
    }

    /// Saves the map: the node files not written yet, then the manifest (see
    /// [`crate::save_map`]). Parked nodes were written when they were parked.
    ///
    /// # Errors
    /// The file system's errors, naming the file.
    pub fn save(
        &self,
        config: &SlamOptions,
        map: &Map,
        edges: &[Edge],
        loop_closures: &[LoopClosure],
        datasets: &[Option<PathBuf>],
    ) -> Result<()> {
        let mut files = self.lock();
        save_map(
            &self.folder,
            &mut files,
            config,
            map,
            edges,
            loop_closures,
            datasets,
        )
    }

    /// Saves the loop's map as it stands: its options, nodes, pose-graph edges and loop
    /// closures ([`Self::save`] with the loop's own parts). It names no dataset: a map loaded
    /// from `sdem slam`'s folder and saved so loses the names of its runs' datasets (`sdem export
    /// --e57` then writes the nodes' points, `sdem slam --resume` asks for the dataset); to keep
    /// them, give [`crate::SavedMap::datasets_by_run`] to [`Self::save`]. Keep this `MapFolder`
    /// between saves: a new one writes every node file again.
    ///
    /// # Errors
    /// The file system's errors, naming the file; a node parked in another store.
    pub fn save_slam(&self, slam: &sdem::Slam) -> Result<()> {
        self.save(
            slam.config(),
            &slam.map,
            &slam.edges,
            &slam.loop_closures,
            &[],
        )
    }

    fn lock(&self) -> std::sync::MutexGuard<'_, NodeFiles> {
        self.files
            .lock()
            .unwrap_or_else(std::sync::PoisonError::into_inner)
    }
}

fn store_error(node_id: usize, e: Error) -> sdem::Error {
    sdem::Error::NodeStore {
        node_id,
        reason: e.to_string(),
    }
}

impl sdem::store::NodeStore for MapFolder {
    fn keep(&self, node: &Node) -> sdem::Result<()> {
        let mut files = self.lock();
        if files.holds(node.node_id) {
            return Ok(());
        }
        let file = write_node_file(&self.folder, node).map_err(|e| store_error(node.node_id, e))?;
        files.set(node.node_id, file);
        Ok(())
    }

    fn fetch(&self, node_id: usize) -> sdem::Result<Vec<[f32; 3]>> {
        let file = self
            .lock()
            .get(node_id)
            .ok_or_else(|| sdem::Error::NodeStore {
                node_id,
                reason: format!("{} holds no file of it", self.folder.display()),
            })?;
        read_node_file(&self.folder, node_id, file).map_err(|e| store_error(node_id, e))
    }
}

#[cfg(test)]
mod tests {
    use super::*;
    use sdem::geometry::Pose;
    use sdem::store::NodeStore;

    fn node(id: usize) -> Node {
        Node {
            node_id: id,
            scan_index: id,
            world_from_sensor: Pose::translation(0.3 * id as f64, 0.0, 0.0),
            attitude_reading: None,
            points_in_sensor: (0..20 + id)
                .map(|k| [k as f32 * 0.1, 1.0, id as f32])
                .collect(),
            segment: 0,
            run: 0,
        }
    }

    #[test]
    fn parked_nodes_are_saved_and_come_back_as_they_were() {
        let dir = tempfile::tempdir().unwrap();
        let folder = MapFolder::create(&dir.path().join("map")).unwrap();
        let mut map = Map {
            nodes: (0..4).map(node).collect(),
        };
        // Node 1 is parked before the first save; its points leave memory.
        folder.keep(&map.nodes[1]).unwrap();
        let original = map.nodes[1].points_in_sensor.clone();
        map.nodes[1].points_in_sensor.clear();
        folder
            .save(&SlamOptions::default(), &map, &[], &[], &[])
            .unwrap();
        assert_eq!(folder.fetch(1).unwrap(), original);
        // The saved map is whole: node 1 with all its points.
        let saved = crate::load_map(folder.path()).unwrap();
        assert_eq!(saved.map.nodes[1].points_in_sensor, original);
        assert_eq!(
            saved.map.nodes[3].points_in_sensor,
            node(3).points_in_sensor
        );
        // A node the folder does not hold, and a damaged file, are errors naming the node.
        let e = folder.fetch(7).unwrap_err().to_string();
        assert!(e.contains("node 7"), "{e}");
        let path = folder.path().join("nodes/000002.pts");
        let mut bytes = std::fs::read(&path).unwrap();
        bytes[30] ^= 1;
        std::fs::write(&path, bytes).unwrap();
        let e = folder.fetch(2).unwrap_err().to_string();
        assert!(e.contains("node 2") && e.contains("checksum"), "{e}");
    }

    #[test]
    fn a_parked_node_saved_without_its_store_is_refused() {
        let dir = tempfile::tempdir().unwrap();
        let mut map = Map {
            nodes: (0..2).map(node).collect(),
        };
        map.nodes[0].points_in_sensor.clear();
        let e = save_map(
            dir.path(),
            &mut NodeFiles::default(),
            &SlamOptions::default(),
            &map,
            &[],
            &[],
            &[],
        )
        .unwrap_err()
        .to_string();
        assert!(e.contains("node 0") && e.contains("MapFolder"), "{e}");
    }
}
