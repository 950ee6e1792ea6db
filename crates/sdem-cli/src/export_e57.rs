//! `sdem export MAP --e57 OUT.e57`: a saved map as an E57 survey, one scan per node with sdem's
//! pose, for surveying and point-cloud tools (CloudCompare, Cyclone, FARO SCENE, PDAL).

use anyhow::{bail, Context, Result};
use sdem::geometry::Pose;
use sdem_io::{Dataset, E57ScanOut, SavedMap};
use serde::Serialize;
use std::path::{Path, PathBuf};

/// The least share of a node's points a dataset's scan must hold returns near
/// ([`sdem::map::Node::share_found_in_scan`]) to be written as that node's scan. The scans a map
/// was made from hold 100 % (a simulated run, the shared 3DTK scans and KITTI frames, a 40-stop
/// run whose loop closures moved its nodes); the next stop's scan 37–44 %, the first stop of
/// another simulated building 63 %.
const SAME_SCAN_MIN_SHARE: f64 = 0.9;

/// What an export wrote.
#[derive(Serialize)]
pub struct Summary {
    /// The saved map read.
    map: PathBuf,
    /// The E57 file written.
    out: PathBuf,
    /// The scans written (one per map node).
    scans: usize,
    /// The points written, over all scans.
    points: usize,
    /// Where the points come from: `dataset` (the scans the map was made from) or `nodes` (the
    /// nodes' S-DEM points).
    points_from: &'static str,
    /// Why the points come from the nodes, when they do without `--node-points`.
    #[serde(skip_serializing_if = "Option::is_none")]
    note: Option<String>,
}

impl Summary {
    /// Prints the summary as text.
    pub fn print_text(&self) {
        println!(
            "wrote {} scans ({} points, from the {}) of the map {} to {}",
            self.scans,
            self.points,
            match self.points_from {
                "dataset" => "dataset's scans",
                _ => "nodes' S-DEM points",
            },
            self.map.display(),
            self.out.display()
        );
        if let Some(note) = &self.note {
            println!("  note: {note}");
        }
    }
}

/// Writes the map at `map` (a `sdem slam` output folder or its `map/`) to `out` as E57.
pub fn export(map: &Path, out: &Path, node_points: bool) -> Result<Summary> {
    let folder = map_folder(map)?;
    let saved = crate::output::load_saved_map(&folder)?;
    if saved.map.nodes.is_empty() {
        bail!(
            "the map {} has no nodes; there is nothing to export",
            folder.display()
        );
    }
    let (clouds, points_from, note) = if node_points {
        (node_clouds(&saved), "nodes", None)
    } else {
        match dataset_clouds(&saved) {
            Ok(clouds) => (clouds, "dataset", None),
            Err(why) => (node_clouds(&saved), "nodes", Some(format!("{why:#}"))),
        }
    };
    let names: Vec<String> = saved
        .map
        .nodes
        .iter()
        .map(|n| format!("scan {:06}", n.scan_index))
        .collect();
    let poses: Vec<Pose> = saved
        .map
        .nodes
        .iter()
        .map(|n| n.world_from_sensor)
        .collect();
    let scans: Vec<E57ScanOut> = clouds
        .iter()
        .zip(&names)
        .zip(&poses)
        .map(|((points, name), pose)| E57ScanOut {
            name,
            points_in_sensor: points,
            world_from_sensor: pose,
        })
        .collect();
    sdem_io::write_e57(out, &scans)?;
    Ok(Summary {
        map: folder,
        out: out.to_path_buf(),
        scans: scans.len(),
        points: clouds.iter().map(Vec::len).sum(),
        points_from,
        note,
    })
}

/// The saved map's folder: `map` itself when it holds the manifest, else `map/map`.
fn map_folder(map: &Path) -> Result<PathBuf> {
    for folder in [map.to_path_buf(), map.join("map")] {
        if folder.join(sdem_io::MAP_MANIFEST).is_file() {
            return Ok(folder);
        }
    }
    bail!(
        "{} is neither a folder that sdem slam wrote (OUT, with map/{}) nor a saved map (OUT/map)",
        map.display(),
        sdem_io::MAP_MANIFEST
    )
}

/// Each node's S-DEM points.
fn node_clouds(saved: &SavedMap) -> Vec<Vec<[f32; 3]>> {
    saved
        .map
        .nodes
        .iter()
        .map(|n| n.points_in_sensor.clone())
        .collect()
}

/// Each node's full scan, from the dataset its run was made from (a map extended by a second
/// run holds nodes of two datasets, whose scans are numbered alike).
fn dataset_clouds(saved: &SavedMap) -> Result<Vec<Vec<[f32; 3]>>> {
    let by_run = saved.datasets_by_run();
    let datasets = (by_run.iter().enumerate())
        .map(|(run, root)| {
            let root = root.as_ref().with_context(|| match by_run.len() {
                1 => "the map does not name its dataset, so the nodes' S-DEM points were written"
                    .to_string(),
                _ => format!(
                    "the map does not name the dataset of its run {run}, so the nodes' S-DEM \
                     points were written"
                ),
            })?;
            let dataset = Dataset::open(root).with_context(|| {
                format!(
                    "the map's dataset {} cannot be opened, so the nodes' S-DEM points were \
                     written (run from the folder sdem slam ran in, or pass --node-points)",
                    root.display()
                )
            })?;
            Ok((root, dataset))
        })
        .collect::<Result<Vec<_>>>()?;
    (saved.map.nodes.iter())
        .map(|node| {
            let (root, dataset) = &datasets[node.run];
            let points = dataset.load_scan(node.scan_index).with_context(|| {
                format!(
                    "scan {} of the map's dataset {} cannot be read, so the nodes' S-DEM points \
                     were written",
                    node.scan_index,
                    root.display()
                )
            })?;
            // A scan replaced since the map was made would be written at another scan's pose.
            let share = node.share_found_in_scan(&points, &saved.config.sdem)?;
            if share < SAME_SCAN_MIN_SHARE {
                bail!(
                    "scan {} of the map's dataset {} is not the scan the map was made from (it \
                     has returns near {:.0} % of its node's points, under {:.0} %): the dataset \
                     changed after mapping, so the nodes' S-DEM points were written",
                    node.scan_index,
                    root.display(),
                    share * 100.0,
                    SAME_SCAN_MIN_SHARE * 100.0
                );
            }
            Ok(points
                .iter()
                .map(|p| [p.x as f32, p.y as f32, p.z as f32])
                .collect())
        })
        .collect()
}
