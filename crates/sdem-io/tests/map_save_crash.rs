//! A process killed while it saves a map leaves the previous map intact.
//!
//! The test runs itself again as a child process (`child_saves_a_growing_map`, ignored unless
//! the parent sets `SDEM_KILL_SAVE_CHILD`) that grows a map node by node and saves it after each
//! node, the way `sdem slam` does, reporting each finished save on stdout. The parent kills the
//! child with SIGKILL at times spread over the run — while it writes a node file, syncs it,
//! renames it or writes the manifest — and then loads the folder: it must load without error and
//! hold every node of the last save the child finished (and at most the one it was writing),
//! each with its exact points and pose. A save started over the leftovers completes the map.

use sdem::geometry::{pose_from_parts, Attitude, Vec3};
use sdem::map::{Map, Node};
use sdem::posegraph::{diagonal_information, Edge, EdgeKind};
use sdem::slam::SlamOptions;
use sdem_io::{load_map, save_map, NodeFiles};
use std::io::{BufRead, BufReader, Write};
use std::path::Path;
use std::process::{Child, Command, Stdio};
use std::time::{Duration, Instant};

const CHILD_ENV: &str = "SDEM_KILL_SAVE_CHILD";
/// Nodes the child adds, one save each.
const NODES: usize = 40;
/// Points per node: 1.2 MB node files, so a save takes long enough to be caught mid-write.
const POINTS_PER_NODE: usize = 100_000;

/// Node `i`'s points and pose, the same in child and parent.
fn node(i: usize) -> Node {
    Node {
        node_id: i,
        scan_index: 3 * i,
        world_from_sensor: pose_from_parts(
            Vec3::new(0.4 * i as f64, 0.1 * (i % 3) as f64, -0.01 * i as f64),
            Attitude::from_degrees(0.5, -0.3, 7.0 * i as f64),
        ),
        attitude_reading: Some(Attitude::from_degrees(0.5, -0.3, 7.0 * i as f64)),
        points_in_sensor: (0..POINTS_PER_NODE)
            .map(|k| {
                let a = k as f32 * 0.001 + i as f32;
                [a.cos() * 2.0, a.sin() * 2.0, (k % 97) as f32 * 0.01 - 0.5]
            })
            .collect(),
        segment: 0,
        run: 0,
    }
}

fn edges(nodes: &[Node]) -> Vec<Edge> {
    nodes
        .windows(2)
        .map(|w| Edge {
            from: w[0].node_id,
            to: w[1].node_id,
            from_from_to: w[0].world_from_sensor.inverse() * w[1].world_from_sensor,
            information: diagonal_information(0.005, 0.002),
            kind: EdgeKind::Odometry,
        })
        .collect()
}

/// Saves `map` (node files already there are not rewritten).
fn save(folder: &Path, files: &mut NodeFiles, map: &Map) {
    let edges = edges(&map.nodes);
    save_map(
        folder,
        files,
        &SlamOptions::default(),
        map,
        &edges,
        &[],
        &[],
    )
    .expect("a save");
}

/// The map with nodes `0..count`.
fn map_of(count: usize) -> Map {
    Map {
        nodes: (0..count).map(node).collect(),
    }
}

#[test]
#[ignore = "run by `a_save_killed_at_any_moment_leaves_the_previous_map_intact` as its child"]
fn child_saves_a_growing_map() {
    let Ok(folder) = std::env::var(CHILD_ENV) else {
        return;
    };
    let folder = Path::new(&folder);
    let mut files = NodeFiles::default();
    let stdout = std::io::stdout();
    // Built up front, so the run's time goes to saving, as in `sdem slam`'s saves.
    let all = map_of(NODES);
    let mut map = Map { nodes: Vec::new() };
    for (count, node) in (1..).zip(all.nodes) {
        map.nodes.push(node);
        save(folder, &mut files, &map);
        let mut out = stdout.lock();
        writeln!(out, "saved {count}").unwrap();
        out.flush().unwrap();
    }
}

/// Checks that the map in `folder` loads and holds exactly nodes `0..n` as written; returns `n`.
fn check_intact(folder: &Path) -> usize {
    let saved = load_map(folder).unwrap_or_else(|e| panic!("the map does not load: {e}"));
    let n = saved.map.nodes.len();
    for (i, loaded) in saved.map.nodes.iter().enumerate() {
        let expected = node(i);
        assert_eq!(loaded.node_id, i);
        assert_eq!(loaded.scan_index, expected.scan_index);
        assert_eq!(
            loaded.points_in_sensor, expected.points_in_sensor,
            "node {i}"
        );
        let moved = (loaded.world_from_sensor.translation.vector
            - expected.world_from_sensor.translation.vector)
            .norm();
        assert!(moved < 1e-12, "node {i} pose moved by {moved} m");
    }
    assert_eq!(saved.edges.len(), n.saturating_sub(1));
    n
}

/// Spawns the child saving into `dir`.
fn spawn(dir: &Path) -> Child {
    Command::new(std::env::current_exe().unwrap())
        .args([
            "--ignored",
            "--exact",
            "child_saves_a_growing_map",
            "--nocapture",
            "--test-threads=1",
        ])
        .env(CHILD_ENV, dir)
        .stdout(Stdio::piped())
        .stderr(Stdio::null())
        .spawn()
        .unwrap()
}

/// The count of a child's "saved N" line (the test harness may have printed the test's name in
/// front of the first one).
fn saved_count(line: &str) -> Option<usize> {
    let at = line.rfind("saved ")?;
    line[at + "saved ".len()..].trim().parse().ok()
}

/// Waits (up to a minute) for the child to create its node folder, i.e. to start saving.
fn wait_for_first_save(dir: &Path) {
    let start = Instant::now();
    while !dir.join("nodes").exists() && start.elapsed() < Duration::from_secs(60) {
        std::thread::sleep(Duration::from_micros(200));
    }
}

#[test]
fn a_save_killed_at_any_moment_leaves_the_previous_map_intact() {
    // How long one save takes on this machine, uninterrupted: the median time between the
    // child's reports.
    let save_time = {
        let dir = tempfile::tempdir().unwrap();
        let mut child = spawn(dir.path());
        let mut stamps = Vec::new();
        for line in BufReader::new(child.stdout.take().unwrap()).lines() {
            if saved_count(&line.unwrap()).is_some() {
                stamps.push(Instant::now());
            }
        }
        child.wait().unwrap();
        assert_eq!(stamps.len(), NODES);
        assert_eq!(check_intact(dir.path()), NODES);
        let mut gaps: Vec<Duration> = stamps.windows(2).map(|w| w[1] - w[0]).collect();
        gaps.sort();
        gaps[gaps.len() / 2]
    };
    // Each kill waits for the child to report a given save finished (none: for its first node
    // file to appear) and then for a fraction of a save's time, so the kills land in every part
    // of a save — writing a node file, syncing it, renaming it, writing the manifest — whatever
    // the machine's speed, and always while the map is still growing.
    let kills: Vec<(usize, Duration)> = (0..16)
        .map(|j| (2 * j, save_time.mul_f64((j % 8) as f64 / 8.0)))
        .collect();
    let mut outcomes = Vec::new();
    for &(after_save, delay) in &kills {
        let dir = tempfile::tempdir().unwrap();
        let mut child = spawn(dir.path());
        let mut lines = BufReader::new(child.stdout.take().unwrap()).lines();
        let mut finished = 0;
        if after_save == 0 {
            wait_for_first_save(dir.path());
        } else {
            for line in lines.by_ref() {
                if let Some(n) = saved_count(&line.unwrap()) {
                    finished = n;
                    if n >= after_save {
                        break;
                    }
                }
            }
        }
        std::thread::sleep(delay);
        child.kill().unwrap();
        child.wait().unwrap();
        // Saves the child finished while the parent slept.
        for line in lines {
            if let Some(n) = line.ok().as_deref().and_then(saved_count) {
                finished = n;
            }
        }

        let loaded = if dir.path().join("map.json").exists() {
            check_intact(dir.path())
        } else {
            // Killed before the first manifest: there is no map yet, and loading says so.
            let e = load_map(dir.path()).unwrap_err().to_string();
            assert!(e.contains("not a saved map"), "{e}");
            assert_eq!(finished, 0, "a finished save left no manifest");
            0
        };
        assert!(
            loaded >= finished && loaded <= finished + 1,
            "killed {delay:?} after save {after_save}: the child had finished {finished} saves, \
             the folder holds {loaded} nodes"
        );
        // What the kill left beyond the loaded map: temporary files, node files the manifest
        // does not name yet — the kill caught the child inside a save.
        let files_in = |folder: &Path| std::fs::read_dir(folder).map_or(0, |d| d.count());
        let leftovers = files_in(dir.path()) + files_in(&dir.path().join("nodes"))
            - usize::from(dir.path().join("map.json").exists()) // the manifest
            - usize::from(dir.path().join("nodes").exists()) // the node folder
            - loaded;
        // Going on from the leftovers (stray temporary files, a node file the manifest does not
        // name yet) completes the map.
        let mut files = if loaded > 0 {
            load_map(dir.path()).unwrap().node_files
        } else {
            NodeFiles::default()
        };
        save(dir.path(), &mut files, &map_of(NODES));
        assert_eq!(check_intact(dir.path()), NODES);
        // … and removes the temporary files the killed child left.
        for folder in [dir.path().to_path_buf(), dir.path().join("nodes")] {
            let stray: Vec<String> = std::fs::read_dir(&folder)
                .unwrap()
                .map(|e| e.unwrap().file_name().to_string_lossy().into_owned())
                .filter(|n| n.contains(".tmp-"))
                .collect();
            assert!(stray.is_empty(), "left in {}: {stray:?}", folder.display());
        }
        outcomes.push((after_save, delay, finished, loaded, leftovers));
    }
    // The kills landed while the map grew (not after the child was done), and some of them
    // during a save (the folder holding one node more than the last finished save).
    let mid_run = outcomes
        .iter()
        .filter(|&&(_, _, _, loaded, _)| loaded < NODES)
        .count();
    let mid_save = outcomes
        .iter()
        .filter(|&&(_, _, _, _, leftovers)| leftovers > 0)
        .count();
    eprintln!(
        "save time {save_time:?}; (after save, delay, finished, loaded, leftovers): {outcomes:?}"
    );
    assert!(
        mid_run == kills.len() && mid_save >= kills.len() / 4,
        "kills did not land during the saves: {outcomes:?}"
    );
}
