//! `sdem export`: a map made by `sdem slam` written for other tools. Each output format is a flag
//! with its own module (`--e57`: `export_e57.rs`).

use crate::output::print_json;
use anyhow::{bail, Result};
use std::path::PathBuf;

/// Arguments of `sdem export`.
#[derive(clap::Args)]
pub struct Args {
    /// The map: the folder `sdem slam` wrote (OUT) or its saved map (OUT/map).
    map: PathBuf,
    /// Write the aligned scans as an E57 survey: one scan per map node, its points in its own
    /// frame, its pose sdem's estimate. The points are the dataset's scans when the dataset the
    /// map was made from is still there, else the nodes' S-DEM points.
    #[arg(long, value_name = "OUT.e57")]
    e57: Option<PathBuf>,
    /// With --e57: write each node's S-DEM points (one per cell, what sdem matched) instead of
    /// the dataset's full scans.
    #[arg(long)]
    node_points: bool,
    /// Print one JSON object instead of text.
    #[arg(long)]
    json: bool,
}

/// Runs `sdem export`.
pub fn run(args: Args) -> Result<()> {
    let Some(e57) = &args.e57 else {
        bail!("say what to write, e.g. --e57 OUT.e57");
    };
    let summary = crate::export_e57::export(&args.map, e57, args.node_points)?;
    if args.json {
        return print_json(&summary);
    }
    summary.print_text();
    Ok(())
}
