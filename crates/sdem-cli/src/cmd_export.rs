//! `sdem export MAP --mcap OUT.mcap`: a saved map written for other tools.

use crate::output::print_json;
use anyhow::{bail, Context, Result};
use sdem::Slam;
use sdem_io::load_map;
use std::path::PathBuf;

/// Arguments of `sdem export`.
#[derive(clap::Args)]
pub struct Args {
    /// The map: the output folder of `sdem slam` (it holds map/) or the saved map folder itself.
    map: PathBuf,
    /// Write an MCAP file for Foxglove and RViz: the fused map and each stop's points as
    /// PointCloud2 in the map frame, the trajectory as nav_msgs/Path, the poses on /tf
    /// (map → base_link), the loop closures as markers; ROS 2 schemas embedded.
    #[arg(long, value_name = "OUT.mcap")]
    mcap: Option<PathBuf>,
    /// Replace an existing output file.
    #[arg(long)]
    force: bool,
    /// Print one JSON object instead of text.
    #[arg(long)]
    json: bool,
}

/// Runs `sdem export`.
pub fn run(args: Args) -> Result<()> {
    let Some(mcap) = &args.mcap else {
        bail!("name what to write: --mcap OUT.mcap");
    };
    crate::export_mcap::check_target(mcap, args.force)?;
    let folder = if args.map.join(sdem_io::MAP_MANIFEST).is_file() {
        args.map.clone()
    } else {
        args.map.join("map")
    };
    if !folder.join(sdem_io::MAP_MANIFEST).is_file() {
        bail!(
            "{} holds no saved map ({} nor {}); give the output folder of `sdem slam` or its map/",
            args.map.display(),
            args.map.join(sdem_io::MAP_MANIFEST).display(),
            folder.join(sdem_io::MAP_MANIFEST).display()
        );
    }
    let saved = load_map(&folder)?;
    let slam = Slam::restore(saved.config, saved.map, saved.edges, saved.loop_closures)
        .with_context(|| format!("the map in {} cannot be restored", folder.display()))?;
    let summary = crate::export_mcap::write(mcap, &slam)?;
    if args.json {
        return print_json(&serde_json::json!({
            "map": folder,
            "mcap": mcap,
            "nodes": slam.map.nodes.len(),
            "bytes": summary.bytes,
            "messages": summary.messages,
            "topics": summary.topics,
        }));
    }
    println!(
        "wrote {} ({:.1} MiB, {} messages) from the {}-node map in {}",
        mcap.display(),
        summary.bytes as f64 / (1024.0 * 1024.0),
        summary.messages,
        slam.map.nodes.len(),
        folder.display()
    );
    for (topic, type_name, count) in &summary.topics {
        println!("  {topic:22} {type_name:40} {count}");
    }
    Ok(())
}
