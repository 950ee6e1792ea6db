//! Saved maps: a folder that `sdem slam` writes after every scan and that `sdem slam --resume` and
//! `sdem localize --map` read back.
//!
//! ```text
//! MAP/
//!   map.json            the manifest: format, version, the configuration, every node's pose,
//!                       attitude reading and points file with its CRC-32, the pose-graph
//!                       edges, the accepted loop closures, and a CRC-32 of all that
//!   nodes/000000.pts    one node's points (one per S-DEM cell), sensor frame (immutable)
//! ```
//! `NNNNNN.pts`: the 8 bytes `SDEMPTS1`, a little-endian `u32` format version (1), a `u64` point
//! count, that many `f32` triples `x y z` (metres, sensor frame), and a `u32` CRC-32 of every
//! byte before it.
//!
//! Saving writes the new node files first and the manifest last, each through
//! [`super::write_atomic`] (temporary file, sync, rename), so a process killed at any moment
//! leaves the previous manifest — and every node file it names — intact; a node file written
//! before the kill but not yet named is simply written again, and the next save removes the
//! temporary files the killed process left. Loading checks the format name, the
//! version (a newer one says so), the manifest's checksum, each node file's size, magic, version
//! and checksum against the manifest, and every number for finiteness.

mod node_files;

use super::poses::to_rotation;
use super::voxels::crc32;
use super::{remove_stale_temporaries, write_atomic};
use crate::error::{one_line, Error, Result};
use nalgebra::{Isometry3, Matrix3, Translation3, UnitQuaternion, Vector3};
pub use node_files::NodeFiles;
use node_files::{decode_points, points_file_name, NodeFile};
pub(crate) use node_files::{read_node_file, write_node_file};
use sdem::geometry::{Attitude, Pose};
use sdem::map::{LoopClosure, Map, Node};
use sdem::posegraph::{Edge, EdgeKind};
use sdem::slam::SlamOptions;
use serde::{Deserialize, Serialize};
use std::path::{Path, PathBuf};

/// The manifest's file name.
pub const MAP_MANIFEST: &str = "map.json";
/// The folder of a saved map's node files (`NNNNNN.pts`), beside the manifest.
const NODES_DIR: &str = "nodes";
/// The manifest's `format` value.
pub const MAP_FORMAT: &str = "sdem-map";
/// The newest map version this build reads and the one it writes.
pub const MAP_VERSION: u32 = 1;
/// A saved map, as loaded.
#[derive(Debug, Clone)]
pub struct SavedMap {
    /// The configuration the map was made with.
    pub config: SlamOptions,
    /// The nodes.
    pub map: Map,
    /// The pose-graph edges.
    pub edges: Vec<Edge>,
    /// The accepted loop closures.
    pub loop_closures: Vec<LoopClosure>,
    /// The dataset the map's last run was made from, as given to `sdem slam`.
    pub dataset: Option<PathBuf>,
    /// The datasets of the runs before the last, by run (`None` where not known: maps saved
    /// before runs named their datasets say only the last run's).
    pub earlier_datasets: Vec<Option<PathBuf>>,
    /// The node files checked on loading; pass them to [`save_map`] to go on with this map.
    pub node_files: NodeFiles,
}

/// The entries of the saved map folder `folder` that sdem does not write there (anything but
/// the manifest, `nodes/NNNNNN.pts` and the temporaries a crash left), as paths relative
/// to it, sorted: what removing the folder would take of a user's.
pub fn foreign_in_map(folder: &Path) -> Vec<String> {
    let mut foreign = Vec::new();
    let Ok(entries) = std::fs::read_dir(folder) else {
        return foreign;
    };
    for entry in entries.flatten() {
        let name = entry.file_name().to_string_lossy().into_owned();
        let temporary = crate::unwrapped_temporary(&name) != name;
        if name == MAP_MANIFEST || temporary {
            continue;
        }
        if name == NODES_DIR && entry.path().is_dir() {
            let Ok(nodes) = std::fs::read_dir(entry.path()) else {
                continue;
            };
            for node in nodes.flatten() {
                let file = node.file_name().to_string_lossy().into_owned();
                if !crate::numbered_file(&file, Some("pts")) {
                    foreign.push(format!("{NODES_DIR}/{file}"));
                }
            }
            continue;
        }
        foreign.push(name);
    }
    foreign.sort();
    foreign
}

/// The saved map folder `path` names: `path` itself when it holds the manifest, its `map`
/// folder when that does (the output folder of `sdem slam`), else `path` (whose loading then
/// says it is not a saved map).
pub fn saved_map_folder(path: &Path) -> PathBuf {
    if path.join(MAP_MANIFEST).exists() || !path.join("map").join(MAP_MANIFEST).exists() {
        path.to_path_buf()
    } else {
        path.join("map")
    }
}

impl SavedMap {
    /// The dataset of each run of the map's nodes, by run (index = [`sdem::map::Node::run`]),
    /// `None` where the map does not say: what [`save_map`] takes to save the map again.
    pub fn datasets_by_run(&self) -> Vec<Option<PathBuf>> {
        let runs = (self.map.nodes.iter())
            .map(|n| n.run + 1)
            .max()
            .unwrap_or(1);
        let mut datasets = self.earlier_datasets.clone();
        datasets.resize(runs - 1, None);
        datasets.push(self.dataset.clone());
        datasets
    }

    /// The loop restored to go on with this map ([`sdem::Slam::restore`]: its configuration,
    /// nodes, edges and loop closures), as `sdem slam --resume` does; call
    /// [`sdem::Slam::begin_run`] first for a second run into it (`sdem slam --map`).
    ///
    /// # Errors
    /// As [`sdem::Slam::restore`]: a configuration or graph that does not hold together.
    pub fn into_slam(self) -> sdem::Result<sdem::Slam> {
        sdem::Slam::restore(self.config, self.map, self.edges, self.loop_closures)
    }

    /// Relocalizes a scan in this map with the map's own settings, as `sdem localize --map`
    /// does ([`sdem::slam::relocalize`]), trying `max_nodes` nodes, by default: near a
    /// position, its 3 nearest; without one, the map's `recovery.relocalize_candidates` whose
    /// places look most like the scan.
    ///
    /// # Errors
    /// As [`sdem::slam::relocalize`]; [`sdem::Error::NotFound`], with the nodes tried, when no
    /// place matches with confidence.
    pub fn relocalize<P: sdem::geometry::AsPoint>(
        &self,
        points_in_sensor: &[P],
        attitude: Option<Attitude>,
        near: Option<sdem::slam::Near>,
        max_nodes: Option<usize>,
    ) -> sdem::Result<sdem::slam::Relocalization> {
        let nodes = max_nodes.unwrap_or(match near {
            Some(_) => 3,
            None => self.config.recovery.relocalize_candidates,
        });
        sdem::slam::relocalize(
            &self.map,
            &self.config,
            points_in_sensor,
            attitude,
            near,
            nodes,
        )
    }
}

#[derive(Serialize, Deserialize)]
#[serde(deny_unknown_fields)]
struct Manifest {
    format: String,
    version: u32,
    /// CRC-32 of the body's canonical JSON text.
    checksum: u32,
    body: serde_json::Value,
}

/// The manifest's body alone, read from the manifest's text (the other fields are checked
/// through [`Manifest`]).
#[derive(Deserialize)]
struct BodyOnly {
    body: Body,
}

#[derive(Serialize, Deserialize)]
#[serde(deny_unknown_fields)]
struct Body {
    /// The last run's dataset.
    dataset: Option<PathBuf>,
    /// The earlier runs' datasets, by run.
    #[serde(default, skip_serializing_if = "Vec::is_empty")]
    earlier_datasets: Vec<Option<PathBuf>>,
    config: SlamOptions,
    nodes: Vec<NodeRecord>,
    edges: Vec<EdgeRecord>,
    loop_closures: Vec<ClosureRecord>,
}

#[derive(Serialize, Deserialize)]
#[serde(deny_unknown_fields)]
struct NodeRecord {
    node_id: usize,
    scan_index: usize,
    /// Row-major 3×4 `world_from_sensor`.
    world_from_sensor: [f64; 12],
    /// Roll, pitch, yaw in degrees.
    attitude_reading_deg: Option<[f64; 3]>,
    points_file: String,
    points: usize,
    points_crc32: u32,
    /// The map segment (the id of its first node; 0 is the world's). Absent in maps saved
    /// before segments: 0.
    #[serde(default)]
    segment: usize,
    /// The run the scan came from (0: the first). Absent in maps saved before runs: 0.
    #[serde(default)]
    run: usize,
}

#[derive(Serialize, Deserialize)]
#[serde(deny_unknown_fields)]
struct EdgeRecord {
    from: usize,
    to: usize,
    from_from_to: [f64; 12],
    information: [[f64; 6]; 6],
    kind: EdgeKind,
}

#[derive(Serialize, Deserialize)]
#[serde(deny_unknown_fields)]
struct ClosureRecord {
    from: usize,
    to: usize,
    descriptor_distance: Option<f64>,
    cost: Option<f64>,
    inlier_fraction: Option<f64>,
    correction_m: Option<f64>,
    from_from_to: [f64; 12],
}

fn pose_to_row_major(pose: &Pose) -> [f64; 12] {
    let m = pose.to_homogeneous();
    std::array::from_fn(|k| m[(k / 4, k % 4)])
}

fn pose_from_row_major(v: &[f64; 12]) -> Option<Pose> {
    if !v.iter().all(|x| x.is_finite()) {
        return None;
    }
    let r = Matrix3::from_fn(|i, j| v[i * 4 + j]);
    if ((r.transpose() * r) - Matrix3::identity()).abs().max() > 1e-6 || r.determinant() < 0.0 {
        return None;
    }
    // The nearest rotation: a quaternion taken from a matrix that is a rotation only to within
    // 1e-6 is not of unit length, and would scale every point it turns.
    let rotation = UnitQuaternion::from_rotation_matrix(&to_rotation(&r).ok()?);
    Some(Isometry3::from_parts(
        Translation3::from(Vector3::new(v[3], v[7], v[11])),
        rotation,
    ))
}

/// Saves the map into `folder` (created when missing): node files that `node_files` does not
/// list yet, then the manifest, each atomically (see the module documentation). `node_files`
/// is updated; start with [`NodeFiles::default`] for a new folder, or take
/// [`SavedMap::node_files`] from [`load_map`] to go on with a saved one. `datasets`: the
/// dataset each run's scans came from, by run, the last being the run mapped now
/// ([`SavedMap::datasets_by_run`] of a loaded map); empty when none is known.
///
/// # Errors
/// The file system's errors, naming the file.
pub fn save_map(
    folder: &Path,
    node_files: &mut NodeFiles,
    config: &SlamOptions,
    map: &Map,
    edges: &[Edge],
    loop_closures: &[LoopClosure],
    datasets: &[Option<PathBuf>],
) -> Result<()> {
    let nodes_dir = folder.join(NODES_DIR);
    std::fs::create_dir_all(&nodes_dir).map_err(|e| Error::io(&nodes_dir, e))?;
    remove_stale_temporaries(folder);
    remove_stale_temporaries(&nodes_dir);
    let mut records = Vec::with_capacity(map.nodes.len());
    for node in &map.nodes {
        let name = points_file_name(node.node_id);
        // A node's points never change: only the nodes this folder does not hold yet are
        // encoded and written (a save used to re-read every node file to compare).
        let file = match node_files.get(node.node_id) {
            Some(file) => file,
            None => write_node_file(folder, node)?,
        };
        node_files.set(node.node_id, file);
        records.push(NodeRecord {
            node_id: node.node_id,
            scan_index: node.scan_index,
            world_from_sensor: pose_to_row_major(&node.world_from_sensor),
            attitude_reading_deg: node.attitude_reading.map(|a| a.to_degrees()),
            points_file: name,
            points: file.points,
            points_crc32: file.crc32,
            segment: node.segment,
            run: node.run,
        });
    }
    let (dataset, earlier_datasets) = match datasets.split_last() {
        Some((last, earlier)) => (last.clone(), earlier.to_vec()),
        None => (None, Vec::new()),
    };
    let body = Body {
        dataset,
        earlier_datasets,
        config: config.clone(),
        nodes: records,
        edges: edges
            .iter()
            .map(|e| EdgeRecord {
                from: e.from,
                to: e.to,
                from_from_to: pose_to_row_major(&e.from_from_to),
                information: e.information,
                kind: e.kind,
            })
            .collect(),
        loop_closures: loop_closures
            .iter()
            .filter_map(|c| {
                Some(ClosureRecord {
                    from: c.from,
                    to: c.to,
                    descriptor_distance: c.descriptor_distance,
                    cost: c.cost,
                    inlier_fraction: c.inlier_fraction,
                    correction_m: c.correction_m,
                    from_from_to: pose_to_row_major(c.from_from_to.as_ref()?),
                })
            })
            .collect(),
    };
    let body = serde_json::to_value(&body)
        .map_err(|e| Error::Invalid(format!("cannot encode the map: {e}")))?;
    let canonical = serde_json::to_vec(&body)
        .map_err(|e| Error::Invalid(format!("cannot encode the map: {e}")))?;
    let manifest = Manifest {
        format: MAP_FORMAT.into(),
        version: MAP_VERSION,
        checksum: crc32(&canonical),
        body,
    };
    let text = serde_json::to_vec_pretty(&manifest)
        .map_err(|e| Error::Invalid(format!("cannot encode the map: {e}")))?;
    write_atomic(&folder.join(MAP_MANIFEST), |w| w.write_all(&text))
}

/// Loads a map saved by [`save_map`], checking everything (see the module documentation).
///
/// # Errors
/// A missing or damaged manifest or node file, a newer version, a checksum mismatch, a
/// non-finite or non-rotation pose, edges naming missing nodes — each naming the file.
pub fn load_map(folder: &Path) -> Result<SavedMap> {
    let manifest_path = folder.join(MAP_MANIFEST);
    let body = read_manifest(folder, &manifest_path)?;
    let bad = |why: String| Error::parse(&manifest_path, None, why);
    let mut nodes = Vec::with_capacity(body.nodes.len());
    for (i, record) in body.nodes.iter().enumerate() {
        nodes.push(load_node(folder, &manifest_path, i, record)?);
    }
    let edges = edges_from_records(&manifest_path, &body.edges, nodes.len())?;
    let loop_closures = closures_from_records(&manifest_path, &body.loop_closures, nodes.len())?;
    body.config
        .validate()
        .map_err(|e| bad(format!("invalid configuration: {}", one_line(&e))))?;
    let node_files = NodeFiles {
        files: (body.nodes.iter())
            .map(|r| {
                Some(NodeFile {
                    crc32: r.points_crc32,
                    points: r.points,
                })
            })
            .collect(),
    };
    Ok(SavedMap {
        node_files,
        config: body.config,
        map: Map { nodes },
        edges,
        loop_closures,
        dataset: body.dataset,
        earlier_datasets: body.earlier_datasets,
    })
}

/// Reads the manifest of the map in `folder` (at `manifest_path`) and checks its format, version
/// and checksum; returns its body.
fn read_manifest(folder: &Path, manifest_path: &Path) -> Result<Body> {
    if !manifest_path.is_file() {
        return Err(Error::Invalid(format!(
            "{} is not a saved map: {} is missing (sdem slam writes it into DIR/map)",
            folder.display(),
            manifest_path.display()
        )));
    }
    let bytes = std::fs::read(manifest_path).map_err(|e| Error::io(manifest_path, e))?;
    let bad = |why: String| Error::parse(manifest_path, None, why);
    let manifest: Manifest = serde_json::from_slice(&bytes).map_err(|e| {
        Error::parse(
            manifest_path,
            Some(e.line()),
            format!("not a map manifest: {}", one_line(&e)),
        )
    })?;
    if manifest.format != MAP_FORMAT {
        return Err(bad(format!(
            "format is {:?}, not {MAP_FORMAT:?}",
            manifest.format
        )));
    }
    if manifest.version > MAP_VERSION {
        return Err(bad(format!(
            "map version {} is newer than this build reads ({MAP_VERSION}); update sdem",
            manifest.version
        )));
    }
    if manifest.version != MAP_VERSION {
        return Err(bad(format!(
            "map version {} does not exist; this build reads version {MAP_VERSION}",
            manifest.version
        )));
    }
    let canonical = serde_json::to_vec(&manifest.body)
        .map_err(|e| bad(format!("cannot re-encode the body: {e}")))?;
    let computed = crc32(&canonical);
    if computed != manifest.checksum {
        return Err(bad(format!(
            "checksum mismatch (manifest says {:08x}, content gives {computed:08x}): the file was \
             edited or damaged",
            manifest.checksum
        )));
    }
    // Parsed again from the text, so that a malformed body is reported with its line.
    let body: Body = serde_json::from_slice::<BodyOnly>(&bytes)
        .map_err(|e| {
            Error::parse(
                manifest_path,
                Some(e.line()),
                format!("malformed map body: {}", one_line(&e)),
            )
        })?
        .body;
    Ok(body)
}

/// Node `i` of the map in `folder` from its manifest record and its points file, checked.
fn load_node(folder: &Path, manifest_path: &Path, i: usize, record: &NodeRecord) -> Result<Node> {
    let bad = |why: String| Error::parse(manifest_path, None, why);
    if record.node_id != i {
        return Err(bad(format!(
            "node {i} is recorded with id {}",
            record.node_id
        )));
    }
    if record.points_file != points_file_name(i) {
        return Err(bad(format!(
            "node {i} names points file {:?}, expected {:?}",
            record.points_file,
            points_file_name(i)
        )));
    }
    let world_from_sensor = pose_from_row_major(&record.world_from_sensor).ok_or_else(|| {
        bad(format!(
            "node {i}: the pose is not a finite rigid transform"
        ))
    })?;
    let attitude_reading = match record.attitude_reading_deg {
        Some(a) if a.iter().all(|v| v.is_finite()) => {
            Some(Attitude::from_degrees(a[0], a[1], a[2]))
        }
        Some(_) => return Err(bad(format!("node {i}: non-finite attitude reading"))),
        None => None,
    };
    if record.segment > i {
        return Err(bad(format!(
            "node {i} is in segment {}, which would start after it (a segment is named for its \
             first node)",
            record.segment
        )));
    }
    let path = folder.join(&record.points_file);
    let bytes = std::fs::read(&path).map_err(|e| Error::io(&path, e))?;
    let points_in_sensor = decode_points(&path, &bytes, record.points_crc32)?;
    if points_in_sensor.len() != record.points {
        return Err(Error::parse(
            &path,
            None,
            format!(
                "holds {} points, the map says {}",
                points_in_sensor.len(),
                record.points
            ),
        ));
    }
    Ok(Node {
        node_id: i,
        scan_index: record.scan_index,
        world_from_sensor,
        attitude_reading,
        points_in_sensor,
        segment: record.segment,
        run: record.run,
    })
}

/// The pose graph's edges from their manifest records, checked against the `n` nodes.
fn edges_from_records(manifest_path: &Path, records: &[EdgeRecord], n: usize) -> Result<Vec<Edge>> {
    let bad = |why: String| Error::parse(manifest_path, None, why);
    let mut edges = Vec::with_capacity(records.len());
    for (k, e) in records.iter().enumerate() {
        if e.from >= n || e.to >= n {
            return Err(bad(format!(
                "edge {k} joins nodes {} and {}, but there are {n}",
                e.from, e.to
            )));
        }
        let from_from_to = pose_from_row_major(&e.from_from_to)
            .ok_or_else(|| bad(format!("edge {k}: not a finite rigid transform")))?;
        if !e.information.iter().flatten().all(|v| v.is_finite()) {
            return Err(bad(format!("edge {k}: non-finite information")));
        }
        edges.push(Edge {
            from: e.from,
            to: e.to,
            from_from_to,
            information: e.information,
            kind: e.kind,
        });
    }
    Ok(edges)
}

/// The accepted loop closures from their manifest records, checked against the `n` nodes.
fn closures_from_records(
    manifest_path: &Path,
    records: &[ClosureRecord],
    n: usize,
) -> Result<Vec<LoopClosure>> {
    let bad = |why: String| Error::parse(manifest_path, None, why);
    let mut loop_closures = Vec::with_capacity(records.len());
    for (k, c) in records.iter().enumerate() {
        if c.from >= n || c.to >= n {
            return Err(bad(format!("loop closure {k} joins missing nodes")));
        }
        let from_from_to = pose_from_row_major(&c.from_from_to)
            .ok_or_else(|| bad(format!("loop closure {k}: not a finite rigid transform")))?;
        loop_closures.push(LoopClosure {
            descriptor_distance: c.descriptor_distance,
            accepted: true,
            cost: c.cost,
            inlier_fraction: c.inlier_fraction,
            correction_m: c.correction_m,
            from_from_to: Some(from_from_to),
            ..LoopClosure::unchecked(c.from, c.to)
        });
    }
    Ok(loop_closures)
}

#[cfg(test)]
mod tests {
    use super::node_files::encode_points;
    use super::*;
    use sdem::geometry::{pose_from_parts, Vec3};
    use sdem::posegraph::diagonal_information;

    fn small_map() -> (SlamOptions, Map, Vec<Edge>, Vec<LoopClosure>) {
        let nodes: Vec<Node> = (0..3)
            .map(|i| Node {
                node_id: i,
                scan_index: 10 + i,
                world_from_sensor: pose_from_parts(
                    Vec3::new(0.35 * i as f64, 0.01, -0.02),
                    Attitude::from_degrees(0.5, -1.0, 10.0 * i as f64),
                ),
                attitude_reading: (i != 1).then(|| Attitude::from_degrees(0.5, -1.0, 9.0)),
                points_in_sensor: (0..50 + i)
                    .map(|k| [k as f32 * 0.1, 1.0 - k as f32 * 0.01, 0.3])
                    .collect(),
                segment: 0,
                run: 0,
            })
            .collect();
        let edges = vec![Edge {
            from: 0,
            to: 2,
            from_from_to: nodes[0].world_from_sensor.inverse() * nodes[2].world_from_sensor,
            information: diagonal_information(0.01, 0.002),
            kind: EdgeKind::LoopClosure,
        }];
        let closures = vec![LoopClosure {
            descriptor_distance: Some(0.01),
            accepted: true,
            cost: Some(1e-3),
            inlier_fraction: Some(0.9),
            correction_m: Some(0.004),
            from_from_to: Some(edges[0].from_from_to),
            ..LoopClosure::unchecked(0, 2)
        }];
        (SlamOptions::default(), Map { nodes }, edges, closures)
    }

    /// Each run's dataset comes back by run; a map whose manifest names only its last run's
    /// dataset (as maps saved before the earlier runs were named) leaves the earlier ones unknown.
    #[test]
    fn the_datasets_of_a_maps_runs_come_back_by_run() {
        let dir = tempfile::tempdir().unwrap();
        let (config, mut map, edges, closures) = small_map();
        map.nodes[2].run = 1;
        let datasets = [Some(PathBuf::from("day1")), Some(PathBuf::from("day2"))];
        let mut files = NodeFiles::default();
        save_map(
            dir.path(),
            &mut files,
            &config,
            &map,
            &edges,
            &closures,
            &datasets,
        )
        .unwrap();
        let saved = load_map(dir.path()).unwrap();
        assert_eq!(saved.datasets_by_run(), datasets.to_vec());
        assert_eq!(saved.dataset.as_deref(), Some(Path::new("day2")));

        let manifest = dir.path().join(MAP_MANIFEST);
        let mut value: serde_json::Value =
            serde_json::from_slice(&std::fs::read(&manifest).unwrap()).unwrap();
        let body = value["body"].as_object_mut().unwrap();
        assert!(body.remove("earlier_datasets").is_some());
        let canonical = serde_json::to_vec(&value["body"]).unwrap();
        value["checksum"] = crc32(&canonical).into();
        std::fs::write(&manifest, serde_json::to_vec(&value).unwrap()).unwrap();
        let saved = load_map(dir.path()).unwrap();
        assert_eq!(
            saved.datasets_by_run(),
            vec![None, Some(PathBuf::from("day2"))]
        );
    }

    #[test]
    fn a_saved_map_loads_back_as_it_was() {
        let dir = tempfile::tempdir().unwrap();
        let (config, map, edges, closures) = small_map();
        let mut files = NodeFiles::default();
        save_map(
            dir.path(),
            &mut files,
            &config,
            &map,
            &edges,
            &closures,
            &[Some(PathBuf::from("data/x"))],
        )
        .unwrap();
        let saved = load_map(dir.path()).unwrap();
        assert_eq!(saved.config, config);
        assert_eq!(saved.dataset.as_deref(), Some(Path::new("data/x")));
        assert_eq!(saved.map.nodes.len(), 3);
        // Poses go through text and a rotation matrix: equal to rounding.
        let same_pose = |a: &Pose, b: &Pose| {
            (a.translation.vector - b.translation.vector).norm() < 1e-12
                && a.rotation.angle_to(&b.rotation) < 1e-9
        };
        for (a, b) in saved.map.nodes.iter().zip(&map.nodes) {
            assert_eq!(a.node_id, b.node_id);
            assert_eq!(a.points_in_sensor, b.points_in_sensor);
            assert_eq!(a.scan_index, b.scan_index);
            assert!(same_pose(&a.world_from_sensor, &b.world_from_sensor));
            // Node 1 has no reading; the others theirs, angle by angle.
            match (a.attitude_reading, b.attitude_reading) {
                (None, None) => {}
                (Some(x), Some(y)) => assert!(
                    [x.roll - y.roll, x.pitch - y.pitch, x.yaw - y.yaw]
                        .iter()
                        .all(|d| d.abs() < 1e-12),
                    "node {}: {x:?} vs {y:?}",
                    b.node_id
                ),
                other => panic!("node {}: reading {other:?}", b.node_id),
            }
        }
        assert_eq!(saved.edges.len(), 1);
        let (a, b) = (&saved.edges[0], &edges[0]);
        assert_eq!((a.from, a.to, a.kind), (b.from, b.to, b.kind));
        assert_eq!(a.information, b.information);
        assert!(
            same_pose(&a.from_from_to, &b.from_from_to),
            "{a:?} vs {b:?}"
        );
        assert_eq!(saved.loop_closures.len(), 1);
        let (a, b) = (&saved.loop_closures[0], &closures[0]);
        assert_eq!(
            (a.from, a.to, a.accepted, &a.reason),
            (b.from, b.to, b.accepted, &b.reason)
        );
        assert_eq!(
            (
                a.descriptor_distance,
                a.cost,
                a.inlier_fraction,
                a.correction_m
            ),
            (
                b.descriptor_distance,
                b.cost,
                b.inlier_fraction,
                b.correction_m
            )
        );
        assert!(same_pose(
            a.from_from_to.as_ref().unwrap(),
            b.from_from_to.as_ref().unwrap()
        ));
        assert_eq!(saved.node_files, files);
        // Saving again rewrites nothing but the manifest, and the result is the same.
        save_map(
            dir.path(),
            &mut files,
            &config,
            &map,
            &edges,
            &closures,
            &[Some(PathBuf::from("data/x"))],
        )
        .unwrap();
        assert_eq!(load_map(dir.path()).unwrap().map.nodes.len(), 3);
    }

    #[test]
    fn a_damaged_or_foreign_map_is_refused_with_the_file_named() {
        let (config, map, edges, closures) = small_map();
        let fresh = || {
            let dir = tempfile::tempdir().unwrap();
            save_map(
                dir.path(),
                &mut NodeFiles::default(),
                &config,
                &map,
                &edges,
                &closures,
                &[],
            )
            .unwrap();
            dir
        };
        let err = |dir: &Path| load_map(dir).unwrap_err().to_string();

        // A flipped byte in a node file.
        let dir = fresh();
        let node = dir.path().join("nodes/000001.pts");
        let mut bytes = std::fs::read(&node).unwrap();
        bytes[40] ^= 0x10;
        std::fs::write(&node, &bytes).unwrap();
        let e = err(dir.path());
        assert!(e.contains("000001.pts") && e.contains("checksum"), "{e}");

        // A truncated node file.
        let dir = fresh();
        let node = dir.path().join("nodes/000002.pts");
        let bytes = std::fs::read(&node).unwrap();
        std::fs::write(&node, &bytes[..bytes.len() - 7]).unwrap();
        let e = err(dir.path());
        assert!(e.contains("000002.pts") && e.contains("truncated"), "{e}");

        // A missing node file.
        let dir = fresh();
        std::fs::remove_file(dir.path().join("nodes/000000.pts")).unwrap();
        assert!(err(dir.path()).contains("000000.pts"));

        // An edited manifest (a pose moved by hand).
        let dir = fresh();
        let manifest = dir.path().join(MAP_MANIFEST);
        let text = std::fs::read_to_string(&manifest).unwrap();
        let edited = text.replacen("0.35", "0.36", 1);
        assert_ne!(edited, text);
        std::fs::write(&manifest, edited).unwrap();
        let e = err(dir.path());
        assert!(e.contains("map.json") && e.contains("checksum"), "{e}");

        // A newer version, a foreign JSON file, a truncated manifest, no manifest at all.
        let dir = fresh();
        let text = std::fs::read_to_string(manifest_of(dir.path())).unwrap();
        std::fs::write(
            manifest_of(dir.path()),
            text.replacen("\"version\": 1", "\"version\": 9", 1),
        )
        .unwrap();
        assert!(err(dir.path()).contains("newer"));
        std::fs::write(manifest_of(dir.path()), "{\"hello\": 1}").unwrap();
        assert!(err(dir.path()).contains("map.json"));
        std::fs::write(manifest_of(dir.path()), &text[..text.len() / 2]).unwrap();
        assert!(err(dir.path()).contains("map.json"));
        std::fs::remove_file(manifest_of(dir.path())).unwrap();
        assert!(err(dir.path()).contains("not a saved map"));
    }

    fn manifest_of(dir: &Path) -> PathBuf {
        dir.join(MAP_MANIFEST)
    }

    #[test]
    fn a_save_killed_before_the_manifest_leaves_the_previous_map() {
        // Saving writes node files, then the manifest: a process killed in between leaves new
        // node files that the old manifest does not name, and a stray temporary file.
        let dir = tempfile::tempdir().unwrap();
        let (config, mut map, edges, closures) = small_map();
        let two = Map {
            nodes: map.nodes[..2].to_vec(),
        };
        let mut files = NodeFiles::default();
        save_map(dir.path(), &mut files, &config, &two, &[], &[], &[]).unwrap();
        std::fs::write(
            dir.path().join("nodes/000002.pts"),
            encode_points(&map.nodes[2].points_in_sensor),
        )
        .unwrap();
        std::fs::write(
            dir.path().join(".map.json.tmp-1-0"),
            b"{\"format\": \"sdem-m",
        )
        .unwrap();
        let saved = load_map(dir.path()).unwrap();
        assert_eq!(saved.map.nodes.len(), 2);
        // And the next save completes the map.
        map.nodes[2].scan_index = 12;
        save_map(
            dir.path(),
            &mut files,
            &config,
            &map,
            &edges,
            &closures,
            &[],
        )
        .unwrap();
        assert_eq!(load_map(dir.path()).unwrap().map.nodes.len(), 3);
    }
}
