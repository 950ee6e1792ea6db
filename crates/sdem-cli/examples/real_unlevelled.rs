//! Real scans seen again tilted and turned, localized with no attitude reading: how sdem levels
//! and turns scans it knows nothing about, on real surfaces with exact truth.
//!
//! Each scan becomes a surface model and is re-viewed (`sdem_sim::reviews`, as `sdem bench
//! --suite real-geometry` does), both views rolled and pitched each up to ±30° at any heading,
//! the reference from the scan's origin, the query from a seeded origin within ±0.7 m (±0.1 m
//! in height), about half its returns or more beside the reference's
//! (`ReviewConfig::unlevelled`). Neither view's attitude is given to sdem; it levels both by
//! their surfaces and finds the heading ([`sdem::localize()`] through its global search). A pose
//! is right within 2 cm and 0.5°, as in `sdem bench --suite unlevelled`.
//!
//! ```sh
//! cargo run --release -p sdem-cli --example real_unlevelled -- ../shared/data/3dtk-dat/scan000.3d
//! cargo run --release -p sdem-cli --example real_unlevelled -- --views 20 \
//!     ../shared/data/kitti-00-first16/velodyne/000000.bin
//! ```
//!
//! Options: `--views N` re-views per scan (30), `--seed S` (1), `--level-reference` (the
//! reference as the scan was taken, its own axes: only the query turned). One line per view (truth, error,
//! trusted or the doubts, time), then per scan: right, wrong and trusted, wrong and flagged,
//! errors (no pose), median time.

use anyhow::{bail, Context, Result};
use sdem::geometry::{pose_error, Vec3};
use sdem::SearchWindow;
use sdem_sim::reviews::{
    localize_review, review_pairs, ModelConfig, ReviewConfig, ReviewScanner, SurfaceModel,
};
use std::path::Path;
use std::time::Instant;

/// Right: within this, metres and degrees.
const RIGHT: (f64, f64) = (0.02, 0.5);

fn main() -> Result<()> {
    let mut args = std::env::args().skip(1);
    let (mut views, mut seed, mut files) = (30usize, 1u64, Vec::new());
    let mut level_reference = false;
    while let Some(a) = args.next() {
        match a.as_str() {
            "--views" => views = args.next().context("--views N")?.parse()?,
            "--seed" => seed = args.next().context("--seed S")?.parse()?,
            "--level-reference" => level_reference = true,
            _ => files.push(a),
        }
    }
    if files.is_empty() {
        bail!("usage: real_unlevelled [--views N] [--seed S] [--level-reference] SCAN...");
    }
    for file in &files {
        run_scan(Path::new(file), views, seed, level_reference)?;
    }
    Ok(())
}

fn run_scan(path: &Path, views: usize, seed: u64, level_reference: bool) -> Result<()> {
    let points = sdem_io::read_points(path)?;
    let extension = (path.extension())
        .map(|e| e.to_string_lossy().to_lowercase())
        .unwrap_or_default();
    let mut model_config = ModelConfig::default();
    if extension == "3d" {
        model_config.min_range_m = sdem_io::UOS_MIN_RANGE_M;
        model_config.max_range_m = sdem_io::UOS_MAX_RANGE_M;
    }
    let ranges = model_config.min_range_m..=model_config.max_range_m;
    let kept: Vec<Vec3> = (points.iter())
        .filter(|p| ranges.contains(&p.norm()))
        .copied()
        .collect();
    // A KITTI frame is re-viewed by its HDL-64E and matched on the grid derived from the scan,
    // as a LiDAR's; any other scan by a scanner like its own on the default grid.
    let spinning = extension == "bin";
    let scanner = if spinning {
        ReviewScanner::hdl64e()
    } else {
        ReviewScanner::like(&kept)
    };
    let model = SurfaceModel::new(&kept, &model_config)?;
    let mut config = ReviewConfig::unlevelled(scanner);
    if level_reference {
        config.reference_tilt_max_deg = 0.0;
        config.reference_yaw_spread_deg = 0.0;
    }
    let across = config.displacement_half_m[0] * 2f64.sqrt() + 0.05;
    let window = SearchWindow::around(&Vec3::zeros(), [across, across, 0.15]);
    let step_m = if spinning { 0.05 } else { 0.02 };
    let name = path.file_name().unwrap_or_default().to_string_lossy();
    let (mut right, mut wrong_trusted, mut wrong_flagged, mut errors) = (0, 0, 0, 0);
    let mut times = Vec::new();
    for review in review_pairs(&model, &config, seed, 0..views)? {
        let start = Instant::now();
        let found = localize_review(&review, &config.scanner, false, window, step_m);
        let ms = start.elapsed().as_secs_f64() * 1e3;
        times.push(ms);
        let truth = format!(
            "{name} #{:<3} truth {:.2} m {:5.1}°",
            review.index,
            review.truth.translation.vector.norm(),
            review.truth.rotation.angle().to_degrees()
        );
        match found {
            Ok(f) => {
                let (t, r) = pose_error(&review.truth, &f.reference_from_query);
                let ok = t <= RIGHT.0 && r.to_degrees() <= RIGHT.1;
                right += ok as usize;
                wrong_trusted += (!ok && f.trusted) as usize;
                wrong_flagged += (!ok && !f.trusted) as usize;
                let doubts: Vec<&str> = f.doubts.iter().map(|d| d.kind()).collect();
                println!(
                    "{truth} | error {:8.1} mm {:6.2}° {} {ms:.0} ms",
                    t * 1e3,
                    r.to_degrees(),
                    if f.trusted {
                        "trusted".to_string()
                    } else {
                        format!("doubts {doubts:?}")
                    }
                );
            }
            Err(e) => {
                errors += 1;
                println!("{truth} | no pose: {e}");
            }
        }
    }
    times.sort_by(f64::total_cmp);
    println!(
        "{name}: {right} / {views} right, {wrong_trusted} wrong and trusted, {wrong_flagged} wrong \
         and flagged, {errors} without a pose; median {:.0} ms",
        times.get(times.len() / 2).copied().unwrap_or(f64::NAN)
    );
    Ok(())
}
