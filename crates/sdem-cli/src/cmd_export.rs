//! `sdem export MAP --mcap OUT.mcap --e57 OUT.e57`: a map made by `sdem slam` written for
//! other tools. Each output format is a flag with its own module (`export_mcap.rs`,
//! `export_e57.rs`); one run may write several.

use crate::output::print_json;
use anyhow::{bail, Context, Result};
use sdem::Slam;
use std::path::{Path, PathBuf};

/// Arguments of `sdem export`.
#[derive(clap::Args)]
pub struct Args {
    /// The map: the folder `sdem slam` wrote (OUT, holding map/) or its saved map (OUT/map).
    map: PathBuf,
    /// Write an MCAP file for Foxglove and RViz: the fused map and each stop's points as
    /// PointCloud2 in the map frame, the trajectory as nav_msgs/Path, the poses on /tf
    /// (map → base_link), the loop closures as markers; ROS 2 schemas embedded.
    #[arg(long, value_name = "OUT.mcap")]
    mcap: Option<PathBuf>,
    /// Write the aligned scans as an E57 survey: one scan per map node, its points in its own
    /// frame, its pose sdem's estimate. The points are the dataset's scans when the dataset the
    /// map was made from is still there with the scans it mapped, else the nodes' S-DEM points.
    #[arg(long, value_name = "OUT.e57")]
    e57: Option<PathBuf>,
    /// With --e57: write each node's S-DEM points (one per cell, what sdem matched) instead of
    /// the dataset's full scans.
    #[arg(long)]
    node_points: bool,
    /// Replace an existing output file (MCAP or E57).
    #[arg(long)]
    force: bool,
    /// Print one JSON object instead of text.
    #[arg(long)]
    json: bool,
}

/// Runs `sdem export`.
pub fn run(args: Args) -> Result<()> {
    if args.mcap.is_none() && args.e57.is_none() {
        return Err(crate::parse::usage_error(
            "export",
            "say what to write: --mcap OUT.mcap, --e57 OUT.e57, or both",
        ));
    }
    // Both targets checked before either is written.
    if let Some(mcap) = &args.mcap {
        crate::export_mcap::check_target(mcap, args.force)?;
    }
    if let Some(e57) = &args.e57 {
        crate::output::check_output_file(e57, "--e57", args.force)?;
    }
    let mut json = serde_json::Map::new();
    if let Some(mcap) = &args.mcap {
        let value = export_mcap(&args.map, mcap, args.force, args.json)?;
        json.insert("mcap".into(), value);
    }
    if let Some(e57) = &args.e57 {
        let summary = crate::export_e57::export(&args.map, e57, args.node_points)?;
        if args.json {
            json.insert("e57".into(), serde_json::to_value(&summary)?);
        } else {
            summary.print_text();
        }
    }
    if args.json {
        return print_json(&serde_json::Value::Object(json));
    }
    Ok(())
}

/// Writes the MCAP file; prints what it wrote (as text unless `json`) and returns it as JSON.
fn export_mcap(map: &Path, mcap: &Path, force: bool, json: bool) -> Result<serde_json::Value> {
    crate::export_mcap::check_target(mcap, force)?;
    let folder = if map.join(sdem_io::MAP_MANIFEST).is_file() {
        map.to_path_buf()
    } else {
        map.join("map")
    };
    if !folder.join(sdem_io::MAP_MANIFEST).is_file() {
        bail!(
            "{} holds no saved map ({} nor {}); give the output folder of `sdem slam` or its map/",
            map.display(),
            map.join(sdem_io::MAP_MANIFEST).display(),
            folder.join(sdem_io::MAP_MANIFEST).display()
        );
    }
    let saved = crate::output::load_saved_map(&folder)?;
    let slam = Slam::restore(saved.config, saved.map, saved.edges, saved.loop_closures)
        .with_context(|| format!("the map in {} cannot be restored", folder.display()))?;
    let summary = crate::export_mcap::write(mcap, &slam)?;
    if !json {
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
    }
    Ok(serde_json::json!({
        "map": folder,
        "mcap": mcap,
        "nodes": slam.map.nodes.len(),
        "bytes": summary.bytes,
        "messages": summary.messages,
        "topics": summary.topics,
    }))
}
