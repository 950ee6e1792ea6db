//! `sdem view`: pictures of S-DEMs, maps and localizations for people (PNG), and the 3D viewer
//! page. The pictures are drawn by `sdem_viz`; this module reads the inputs and writes files.

use crate::cmd_localize::parse_window;
use crate::output::{check_output_file, create_folder, print_json};
use crate::parse::{
    fmt_number, heading_window_degrees, number_in, positive_metres, resolution_degrees,
    usage_error, POSITIVE,
};
use anyhow::{bail, Context, Result};
use sdem::geometry::{Pose, Vec3};
use sdem::localize::{localize, LocalizeOptions, SearchWindow};
use sdem::map::{LoopClosure, Map};
use sdem::sdem::{Sdem, SdemConfig};
use sdem::slam::SlamOptions;
use sdem_io::{read_points, write_atomic, Dataset};
use sdem_viz::{
    cost_surface, encode_png, map_plan, map_section, sample_cost_slice, sdem_panorama,
    sdem_polar_slice, viewer_html_with_status, MapView, RgbImage, Section,
};
use std::path::{Path, PathBuf};

/// Arguments of `sdem view`.
#[derive(clap::Args)]
pub struct Args {
    #[command(subcommand)]
    what: What,
    /// Print one JSON object (the files written) instead of text.
    #[arg(long, global = true)]
    json: bool,
}

#[derive(clap::Subcommand)]
enum What {
    /// One scan's S-DEM as a panorama: azimuth × elevation, range colour-mapped, unknown hatched.
    Panorama(ScanArgs),
    /// One elevation band of a scan's S-DEM from above (free space, boundary, unknown), like the
    /// paper's Fig. 10-11.
    Slice(SliceArgs),
    /// The pictures of a `sdem slam` output folder: plan.png, section.png, viewer.html (the 3D
    /// page), and the last node's panorama.png, slice.png and cost.png.
    Map(MapArgs),
    /// The cost surface of one localization: eq. (1) over x-y through the optimum.
    Cost(CostArgs),
}

/// Which scan, and where the picture goes.
#[derive(clap::Args)]
struct ScanArgs {
    /// A dataset folder (scans/, optional attitude.csv) or one point-cloud file (sensor frame,
    /// taken as level).
    input: PathBuf,
    /// The scan's index in the dataset.
    #[arg(long, default_value_t = 0)]
    index: usize,
    /// The PNG to write (refused when it exists, unless --force).
    #[arg(long)]
    out: PathBuf,
    /// Write over an existing --out file.
    #[arg(long)]
    force: bool,
    /// S-DEM cell size, degrees.
    #[arg(long, default_value_t = 1.0, allow_hyphen_values = true, value_parser = resolution_degrees)]
    resolution: f64,
}

#[derive(clap::Args)]
struct SliceArgs {
    #[command(flatten)]
    scan: ScanArgs,
    /// The elevation whose band is drawn, degrees (the paper's figures: -30).
    #[arg(long, default_value_t = -30.0, allow_hyphen_values = true, value_parser = elevation_degrees)]
    elevation: f64,
}

#[derive(clap::Args)]
struct MapArgs {
    /// The output folder of `sdem slam` (holding map/ and map.ply).
    slam_out: PathBuf,
    /// Where the pictures go [default: SLAM_OUT, whose pictures are redrawn]. Elsewhere, a
    /// file of a picture's name is refused unless --force.
    #[arg(long)]
    out_dir: Option<PathBuf>,
    /// Write over pictures of the same names in --out-dir.
    #[arg(long)]
    force: bool,
}

#[derive(clap::Args)]
struct CostArgs {
    /// The dataset folder.
    dataset: PathBuf,
    /// Index of the reference scan.
    #[arg(long)]
    reference: usize,
    /// Index of the scan localized against it.
    #[arg(long)]
    query: usize,
    /// The PNG to write (refused when it exists, unless --force).
    #[arg(long)]
    out: PathBuf,
    /// Write over an existing --out file.
    #[arg(long)]
    force: bool,
    /// The localization's candidate window, x0:x1,y0:y1,z0:z1 metres [default: the paper's].
    #[arg(long, allow_hyphen_values = true, value_parser = parse_window)]
    window: Option<SearchWindow>,
    /// Heading searched around the compass, ± degrees.
    #[arg(
        long,
        default_value_t = 10.0,
        allow_hyphen_values = true,
        value_parser = heading_window_degrees
    )]
    heading_window: f64,
    /// Grid step of the localization that finds the optimum, metres (it is refined below the
    /// grid afterwards).
    #[arg(long, default_value_t = 0.02, allow_hyphen_values = true, value_parser = positive_metres)]
    search_step: f64,
    /// Half the side of the square drawn around the optimum, metres.
    #[arg(long, default_value_t = 0.3, allow_hyphen_values = true, value_parser = parse_extent)]
    extent: f64,
    /// Sample spacing of the picture, metres: at least 3 samples across the extent, at most
    /// 401.
    #[arg(long, default_value_t = 0.01, allow_hyphen_values = true, value_parser = parse_step)]
    step: f64,
    /// S-DEM cell size, degrees.
    #[arg(long, default_value_t = 1.0, allow_hyphen_values = true, value_parser = resolution_degrees)]
    resolution: f64,
}

/// Parses `--elevation DEG` of `sdem view slice`.
fn elevation_degrees(text: &str) -> Result<f64, String> {
    number_in(text, -90.0..=90.0, "a number of degrees in [-90, 90]")
}

/// Parses `--extent M` of `sdem view cost`.
fn parse_extent(text: &str) -> Result<f64, String> {
    number_in(
        text,
        POSITIVE,
        "a positive number of metres (> 0), half the side of the picture (e.g. 0.3)",
    )
}

/// Parses `--step M` of `sdem view cost`.
fn parse_step(text: &str) -> Result<f64, String> {
    number_in(
        text,
        POSITIVE,
        "a positive number of metres (> 0), the picture's sample spacing (e.g. 0.01)",
    )
}

/// Runs `sdem view`.
pub fn run(args: Args) -> Result<()> {
    // Checked before the work: no file a user saved is written over without --force.
    match &args.what {
        What::Panorama(scan) | What::Slice(SliceArgs { scan, .. }) => {
            check_output_file(&scan.out, "--out", scan.force)?;
        }
        What::Cost(cost) => {
            check_cost_sampling(cost)?;
            check_output_file(&cost.out, "--out", cost.force)?;
        }
        What::Map(map) => {
            if let Some(dir) = map
                .out_dir
                .as_deref()
                .filter(|d| !same_folder(d, &map.slam_out))
            {
                crate::output::check_output_folder(dir, "--out-dir", MAP_PICTURE_FILES, map.force)?;
            }
        }
    }
    let written = match args.what {
        What::Panorama(scan) => {
            let (sdem, label) = scan_sdem(&scan)?;
            write_png(&scan.out, &sdem_panorama(&sdem, &label))?;
            vec![scan.out]
        }
        What::Slice(slice) => {
            write_slice(&slice)?;
            vec![slice.scan.out]
        }
        What::Map(map) => write_map_view(map, args.json)?,
        What::Cost(cost) => {
            write_cost_picture(&cost)?;
            vec![cost.out]
        }
    };
    if args.json {
        print_json(&serde_json::json!({ "written": written }))
    } else {
        for path in &written {
            println!("wrote {}", path.display());
        }
        Ok(())
    }
}

/// Whether `a` and `b` name one folder (as given, when either does not exist).
fn same_folder(a: &Path, b: &Path) -> bool {
    match (a.canonicalize(), b.canonicalize()) {
        (Ok(a), Ok(b)) => a == b,
        _ => a == b,
    }
}

/// `sdem view slice`: one elevation band of a scan's S-DEM.
fn write_slice(slice: &SliceArgs) -> Result<()> {
    let (sdem, label) = scan_sdem(&slice.scan)?;
    write_png(
        &slice.scan.out,
        &sdem_polar_slice(&sdem, slice.elevation, &label),
    )
}

/// `sdem view map`: the pictures of a `sdem slam` output folder; returns the paths written.
fn write_map_view(map: MapArgs, json: bool) -> Result<Vec<PathBuf>> {
    let map_dir = map.slam_out.join("map");
    if !map_dir.join(sdem_io::MAP_MANIFEST).exists() {
        bail!(
            "{} is not a `sdem slam` output folder: {} is missing",
            map.slam_out.display(),
            map_dir.join(sdem_io::MAP_MANIFEST).display()
        );
    }
    let saved = crate::output::load_saved_map(&map_dir)?;
    let cloud_path = map.slam_out.join("map.ply");
    let cloud = if cloud_path.exists() {
        read_points(&cloud_path)?
    } else {
        // A run cut short writes map/ before map.ply: draw the nodes' own points.
        saved
            .map
            .nodes
            .iter()
            .flat_map(|n| n.points_in_world())
            .collect()
    };
    let out_dir = map.out_dir.unwrap_or(map.slam_out);
    // One step: the bar shows the elapsed time while the pictures are drawn.
    let bar = crate::progress::bar(1, json, "pictures");
    let written = write_map_pictures(
        &out_dir,
        &map_name(saved.dataset.as_deref(), &out_dir),
        &saved.map,
        &saved.loop_closures,
        &saved.config,
        &cloud,
        &[],
    )?;
    bar.inc(1);
    bar.finish_and_clear();
    Ok(written)
}

/// What the pictures' titles call a map: the dataset folder's name, else the output folder's.
pub fn map_name(dataset: Option<&Path>, out_dir: &Path) -> String {
    dataset
        .or(Some(out_dir))
        .and_then(|p| p.file_name())
        .map(|n| n.to_string_lossy().into_owned())
        .unwrap_or_else(|| "map".into())
}

/// The files [`write_map_pictures`] writes (`cost.png` only for a map of two nodes or more).
pub const MAP_PICTURE_FILES: &[&str] = &[
    "plan.png",
    "section.png",
    "panorama.png",
    "slice.png",
    "cost.png",
    "viewer.html",
];

/// Writes every picture of a map into `out_dir` (created if missing): `plan.png`,
/// `section.png` (a cut along the trajectory), `viewer.html` (the 3D page), and for the last
/// node `panorama.png` and `slice.png` (elevation −30°), and `cost.png` (the last node against
/// the one before, through the map's estimate). Returns the paths written.
///
/// # Arguments
/// * `out_dir` — the folder to write into (e.g. the `sdem slam` output folder).
/// * `name` — what the titles call the map ([`map_name`]).
/// * `map`, `loop_closures`, `config` — the map, its loop closures and the configuration it
///   was made with (a live `Slam`'s, or `sdem_io::load_map`'s).
/// * `cloud` — the fused map's points, world frame (`Slam::merged_cloud`, or `map.ply`).
pub fn write_map_pictures(
    out_dir: &Path,
    name: &str,
    map: &Map,
    loop_closures: &[LoopClosure],
    config: &SlamOptions,
    cloud: &[Vec3],
    status: &[String],
) -> Result<Vec<PathBuf>> {
    create_folder(out_dir)?;
    let nodes = &map.nodes;
    let world_from_node: Vec<Pose> = nodes.iter().map(|n| n.world_from_sensor).collect();
    let index_of = |node_id: usize| nodes.iter().position(|n| n.node_id == node_id);
    let loops: Vec<(usize, usize)> = loop_closures
        .iter()
        .filter(|c| c.accepted)
        .filter_map(|c| Some((index_of(c.from)?, index_of(c.to)?)))
        .collect();
    let view = MapView {
        points_in_world: cloud,
        world_from_node: &world_from_node,
        loop_closures: &loops,
    };
    let mut written = Vec::new();
    let mut png = |file: &str, image: RgbImage| -> Result<()> {
        let path = out_dir.join(file);
        write_png(&path, &image)?;
        written.push(path);
        Ok(())
    };
    png("plan.png", map_plan(&view, name))?;
    png(
        "section.png",
        map_section(&view, &Section::through_trajectory(&view, 0.1), name),
    )?;
    write_last_node_pictures(name, map, config, &mut png)?;
    let status: Vec<&str> = status.iter().map(String::as_str).collect();
    let page = viewer_html_with_status(&view, &format!("sdem map: {name}"), &status);
    let path = out_dir.join("viewer.html");
    write_atomic(&path, |w| w.write_all(page.as_bytes()))?;
    written.push(path);
    Ok(written)
}

/// For the last node of `map`: `panorama.png` and `slice.png`, and `cost.png` against the node
/// before it when there is one, each handed to `png` with its file name.
fn write_last_node_pictures(
    name: &str,
    map: &Map,
    config: &SlamOptions,
    png: &mut dyn FnMut(&str, RgbImage) -> Result<()>,
) -> Result<()> {
    let nodes = &map.nodes;
    let sdem_config = &config.sdem;
    let node_sdem = |i: usize| -> Result<Sdem> {
        let node = &nodes[i];
        // Levelled by the map's estimate: the S-DEM's axes are the world's.
        let attitude = sdem::geometry::attitude_of(&node.world_from_sensor);
        Ok(Sdem::from_points(
            &node.sensor_points(),
            &attitude,
            sdem_config,
        )?)
    };
    if let Some(last) = nodes.len().checked_sub(1) {
        let query = node_sdem(last)?;
        let label = format!("{name}, node {last}");
        png("panorama.png", sdem_panorama(&query, &label))?;
        png("slice.png", sdem_polar_slice(&query, -30.0, &label))?;
        if last >= 1 {
            let reference = node_sdem(last - 1)?;
            let offset = nodes[last].position() - nodes[last - 1].position();
            let slice = sample_cost_slice(
                &reference,
                &query,
                &config.localize.cost,
                &offset,
                0.0,
                0.3,
                0.01,
            )?;
            png(
                "cost.png",
                cost_surface(
                    &slice,
                    &format!("{name}, node {last} against node {}", last - 1),
                ),
            )?;
        }
    }
    Ok(())
}

/// Writes `image` as a PNG at `path`, creating its folder.
fn write_png(path: &Path, image: &RgbImage) -> Result<()> {
    if let Some(parent) = path.parent().filter(|p| !p.as_os_str().is_empty()) {
        create_folder(parent)?;
    }
    let bytes = encode_png(image)?;
    write_atomic(path, |w| w.write_all(&bytes))?;
    Ok(())
}

/// The S-DEM of the scan named by `args`, levelled by the dataset's attitude, and a label.
fn scan_sdem(args: &ScanArgs) -> Result<(Sdem, String)> {
    let config = SdemConfig {
        resolution_deg: args.resolution,
        ..Default::default()
    };
    let input = &args.input;
    let (points, attitude, label) = if input.is_dir() {
        let dataset = Dataset::open(input)?;
        if args.index >= dataset.len() {
            bail!(
                "--index {} is out of range: {} has {}",
                args.index,
                input.display(),
                sdem_io::scans_numbered(dataset.len())
            );
        }
        let points = dataset.load_scan(args.index)?;
        let attitude = dataset.attitude_or_level(args.index).unwrap_or_default();
        let name = input
            .canonicalize()
            .ok()
            .and_then(|p| p.file_name().map(|n| n.to_string_lossy().into_owned()))
            .unwrap_or_else(|| input.display().to_string());
        (points, attitude, format!("{name}, scan {}", args.index))
    } else if input.is_file() {
        if args.index != 0 {
            bail!(
                "--index {}: {} is a single scan; --index applies to dataset folders",
                args.index,
                input.display()
            );
        }
        let points = read_points(input)?;
        let name = input
            .file_name()
            .map(|n| n.to_string_lossy().into_owned())
            .unwrap_or_default();
        (
            points,
            Default::default(),
            format!("{name} (taken as level)"),
        )
    } else {
        bail!("{}: no such file or dataset folder", input.display());
    };
    // A scan that fills no cell is refused saying why, as `sdem localize` refuses it.
    let sdem = Sdem::from_usable_points(&points, &attitude, &config)
        .with_context(|| format!("cannot build the S-DEM of {}", input.display()))?;
    Ok((sdem, label))
}

/// `sdem view cost`: localizes, then draws the cost around the optimum.
fn write_cost_picture(args: &CostArgs) -> Result<()> {
    let dataset = Dataset::open(&args.dataset)?;
    for (flag, index) in [("--reference", args.reference), ("--query", args.query)] {
        if index >= dataset.len() {
            bail!(
                "{flag} {index} is out of range: {} has {}",
                args.dataset.display(),
                sdem_io::scans_numbered(dataset.len())
            );
        }
    }
    let sdem_config = SdemConfig {
        resolution_deg: args.resolution,
        ..Default::default()
    };
    let config = cost_localize_config(args);
    let build = |index: usize| -> Result<Sdem> {
        let attitude = dataset.attitude_or_level(index).unwrap_or_default();
        let points = dataset.load_scan(index)?;
        Ok(Sdem::from_points(&points, &attitude, &sdem_config)?)
    };
    let (reference, query) = (build(args.reference)?, build(args.query)?);
    let found = localize(&reference, &query, &config)
        .with_context(|| format!("scan {} against scan {}", args.query, args.reference))?;
    let slice = sample_cost_slice(
        &reference,
        &query,
        &config.cost,
        &found.offset,
        found.heading_correction,
        args.extent,
        args.step,
    )?;
    let name = args
        .dataset
        .canonicalize()
        .ok()
        .and_then(|p| p.file_name().map(|n| n.to_string_lossy().into_owned()))
        .unwrap_or_else(|| args.dataset.display().to_string());
    write_png(
        &args.out,
        &cost_surface(
            &slice,
            &format!(
                "{name}, scan {} against scan {}",
                args.query, args.reference
            ),
        ),
    )
}

/// Samples a side of the cost picture: at least 3 (a picture, not one flat sample), at most
/// 401 (as `sdem_viz::sample_cost_slice` allows).
const COST_SAMPLES: std::ops::RangeInclusive<i64> = 3..=401;

/// Refuses (a usage error) an `--extent` and `--step` of `sdem view cost` (each positive, by
/// its parser) whose number of samples across the picture lies outside [`COST_SAMPLES`]
/// (counted as `sdem_viz::sample_cost_slice` counts them).
fn check_cost_sampling(args: &CostArgs) -> Result<()> {
    let half_count = (args.extent / args.step).round();
    let samples = if half_count < 1e9 {
        2 * half_count as i64 + 1
    } else {
        i64::MAX
    };
    if !COST_SAMPLES.contains(&samples) {
        let (low, high) = (COST_SAMPLES.start(), COST_SAMPLES.end());
        let count = match samples {
            i64::MAX => "too many samples".to_string(),
            1 => "1 sample".to_string(),
            n => format!("{n} samples"),
        };
        return Err(usage_error(
            "view cost",
            format!(
                "--step {} m over --extent ±{} m gives {count} a side; the picture needs \
                 {low} to {high}: choose a --step between {} and {} m, or another --extent",
                fmt_number(args.step),
                fmt_number(args.extent),
                short_metres(2.0 * args.extent / (*high as f64 - 1.0)),
                short_metres(2.0 * args.extent / (*low as f64 - 1.0)),
            ),
        ));
    }
    Ok(())
}

/// A positive length as short text, four significant digits: `0.0015`, `0.3`, `12.5`.
fn short_metres(value: f64) -> String {
    let decimals = (3.0 - value.log10().floor()).clamp(0.0, 20.0) as usize;
    let text = format!("{value:.decimals$}");
    if text.contains('.') {
        text.trim_end_matches('0').trim_end_matches('.').to_string()
    } else {
        text
    }
}

/// The localization `sdem view cost` runs to find the optimum, from the arguments.
fn cost_localize_config(args: &CostArgs) -> LocalizeOptions {
    let mut config = LocalizeOptions::default();
    if let Some(window) = args.window {
        config.window = window;
    }
    config.heading.half_range_deg = args.heading_window;
    config.step_m = args.search_step;
    // The picture needs the optimum only, not the runner-up search.
    config.runner_up = false;
    config
}
