//! Where a run of `sdem slam` starts: a fresh map, a killed run's saved map (`--resume`), or
//! a saved map extended by a second run (`--map`), each with its node store and step log.

use super::{run_nodes, Args, ExtendedMap, Run, MAP_DIR, STEPS_FILE};
use anyhow::{bail, Context, Result};
use sdem::slam::{Slam, SlamOptions};
use sdem_io::{load_map, Dataset, MapFolder};
use serde_json::Value;
use std::path::Path;
use std::sync::Arc;

/// Whether `saved` (as the map recorded it) and `given` name one dataset folder.
fn same_dataset(saved: &Path, given: &Path) -> bool {
    match (std::fs::canonicalize(saved), std::fs::canonicalize(given)) {
        (Ok(a), Ok(b)) => a == b,
        _ => saved == given,
    }
}

/// `--resume`: the saved map and step log, with the saved configuration.
pub(super) fn resume(args: &Args, map_dir: &Path) -> Result<Run> {
    let mut saved = crate::output::load_saved_map(map_dir).context("--resume")?;
    if let Some(made_from) = &saved.dataset {
        if !same_dataset(made_from, &args.dataset) {
            bail!(
                "--resume: the map in {} was made from {}, not {}; resume it with that \
                 dataset, or map {} into another folder",
                args.out.display(),
                made_from.display(),
                args.dataset.display(),
                args.dataset.display()
            );
        }
    }
    let next = saved.map.nodes.len();
    let mut earlier_datasets = saved.datasets_by_run();
    earlier_datasets.pop();
    let node_files = std::mem::take(&mut saved.node_files);
    let mut slam = saved.into_slam()?;
    let steps = read_steps(&args.out.join(STEPS_FILE), run_nodes(&slam))?;
    let folder = Arc::new(MapFolder::open(map_dir, node_files)?);
    slam.set_node_store(folder.clone());
    Ok(Run {
        slam,
        steps,
        resumed_at: Some(next),
        extends: None,
        folder,
        earlier_datasets,
    })
}

/// `--map EXISTING`: the saved map, with its configuration, ready for a new run; OUT/map must
/// be another folder.
pub(super) fn extend(existing: &Path, map_dir: &Path) -> Result<Run> {
    let folder = sdem_io::saved_map_folder(existing);
    let saved = load_map(&folder).with_context(|| format!("--map {}", existing.display()))?;
    let nodes = saved.map.nodes.len();
    let earlier_datasets = saved.datasets_by_run();
    let mut slam = saved.into_slam()?;
    slam.begin_run();
    let store = Arc::new(MapFolder::create(map_dir)?);
    slam.set_node_store(store.clone());
    Ok(Run {
        slam,
        steps: Vec::new(),
        resumed_at: None,
        extends: Some(ExtendedMap { map: folder, nodes }),
        folder: store,
        earlier_datasets,
    })
}

/// Refuses, before anything in `--out` is touched, a `--map existing` that is the map the run
/// writes in `out`: it would write over the map it extends (with `--force`, remove it first).
pub(super) fn check_extended_map(existing: &Path, out: &Path) -> Result<()> {
    let (Ok(folder), Ok(out_folder)) = (
        sdem_io::saved_map_folder(existing).canonicalize(),
        out.canonicalize(),
    ) else {
        return Ok(());
    };
    if folder == out_folder || folder.starts_with(out_folder.join(MAP_DIR)) {
        bail!(
            "--map {}: that is the map this run writes in --out {}; choose another --out \
             (the saved map is left as it was)",
            existing.display(),
            out.display()
        );
    }
    Ok(())
}

/// A new run with the configuration of `--config` (or the defaults, matched to the dataset's
/// sensor), `--step` and `--no-loop-closure`.
pub(super) fn start_fresh(args: &Args, dataset: &Dataset) -> Result<Run> {
    let mut config = match &args.config {
        Some(path) => sdem_io::read_slam_config(path)?,
        None => match &dataset.sensor {
            Some(sensor) => {
                let mut config = SlamOptions::default();
                config.sdem.resolution_deg = sensor.matched_sdem_resolution_deg();
                config
            }
            // No sensor model: the options follow the first scan's own sampling (a spinning or
            // solid-state LiDAR's grid, search and recovery; the tilting laser's defaults
            // otherwise).
            None if !dataset.is_empty() => {
                let first = dataset
                    .load_scan(0)
                    .context("scan 0 cannot be read to choose the loop's options")?;
                SlamOptions::for_scan(&first)
            }
            None => SlamOptions::default(),
        },
    };
    if let Some(step) = args.step {
        config.localize.step_m = step;
    }
    if args.no_loop_closure {
        config.loop_closure.enabled = false;
    }
    let mut slam = Slam::new(config)?;
    let folder = Arc::new(MapFolder::create(&args.out.join(MAP_DIR))?);
    slam.set_node_store(folder.clone());
    Ok(Run {
        slam,
        steps: Vec::new(),
        resumed_at: None,
        extends: None,
        folder,
        earlier_datasets: Vec::new(),
    })
}

/// Reads the step log of a resumed run, whose map has `nodes` nodes in this run. A log one
/// step ahead (a kill between the two writes of [`save_progress`]) loses that step, whose scan
/// is mapped again; one further ahead is another run's. (A map saved before its log, as
/// earlier versions did, may be a step ahead of the log: that step's line is missing.)
fn read_steps(path: &Path, nodes: usize) -> Result<Vec<Value>> {
    // The map is what a resume goes on from; a step log that is missing, damaged or short
    // only costs the report those steps, so the run goes on, saying so (it did without a word).
    let lost = |why: &str, kept: usize| {
        if nodes > kept {
            eprintln!(
                "sdem: warning: {} {why}: the map's {nodes} nodes are whole, but this run's \
                 report will list only {kept} of their steps",
                path.display()
            );
        }
    };
    if !path.exists() {
        lost("is missing", 0);
        return Ok(Vec::new());
    }
    let text = std::fs::read(path).with_context(|| format!("cannot read {}", path.display()))?;
    let Ok(mut values) = serde_json::from_slice::<Vec<Value>>(&text) else {
        lost("is damaged (not a step log)", 0);
        return Ok(Vec::new());
    };
    if values.len() == nodes + 1 {
        values.pop();
    }
    if values.len() > nodes {
        bail!(
            "{} logs {} steps but the map has {nodes} nodes; the folder mixes two runs",
            path.display(),
            values.len()
        );
    }
    // One step behind is a map saved before its log (sdem before the log was written first).
    if values.len() + 1 < nodes {
        lost(&format!("logs {} steps", values.len()), values.len());
    }
    Ok(values)
}
