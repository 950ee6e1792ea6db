//! A map as MCAP for Foxglove and RViz (`sdem slam --mcap`, `sdem export --mcap`): the
//! values `sdem_io::write_map_mcap` writes, taken from the mapper.

use anyhow::Result;
use sdem::Slam;
use sdem_io::{write_map_mcap, MapScene, McapSummary};
use std::path::Path;

/// Refuses to replace an existing file without `force`, before any work is done.
pub fn check_target(path: &Path, force: bool) -> Result<()> {
    crate::output::check_output_file(path, "--mcap", force)
}

/// Writes the map of `slam`: its fused cloud, every node's points in the world, the poses, the
/// accepted loop closures.
pub fn write(path: &Path, slam: &Slam) -> Result<McapSummary> {
    let poses = slam.poses();
    // Every node's points, parked ones read back from the map's node files.
    let scans = (slam.map.nodes.iter())
        .map(|n| {
            let points = slam.node_points(n.node_id)?;
            Ok(points
                .iter()
                .map(|p| {
                    (n.world_from_sensor
                        * nalgebra::Point3::new(p[0] as f64, p[1] as f64, p[2] as f64))
                    .coords
                })
                .collect::<Vec<_>>())
        })
        .collect::<Result<Vec<_>>>()?;
    let cloud = slam.merged_cloud()?;
    let closures: Vec<(usize, usize)> = slam
        .loop_closures
        .iter()
        .filter(|c| c.accepted)
        .map(|c| (c.from, c.to))
        .collect();
    let scene = MapScene {
        world_from_sensor: &poses,
        scans_in_world: &scans,
        map_cloud: &cloud,
        loop_closures: &closures,
    };
    Ok(write_map_mcap(path, &scene)?)
}
