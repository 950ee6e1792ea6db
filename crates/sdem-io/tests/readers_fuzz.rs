//! Fuzzing every reader of `sdem_io` with proptest, on the stable toolchain.
//!
//! Each reader is a target, fed two streams of inputs, each its own test:
//! - `*_arbitrary`: arbitrary bytes, alone or after a prefix of a valid file (so that binary
//!   formats get past their magic);
//! - `*_mutated`: a valid file with 1 to 6 mutations: bit flips, byte sets, inserts, deletes,
//!   truncation, duplicated chunks, and tokens spliced over bytes or over a number (`nan`,
//!   `inf`, `1e308`, `-0`, huge integers for declared counts, NaN/∞ as raw `f32`/`f64`,
//!   `u64::MAX`, line breaks, a BOM, …). Where a checksum guards a file (voxel maps, saved maps'
//!   manifest and node files), half of the mutated files get their checksums recomputed, so that
//!   the checks behind the checksum are reached too.
//!
//! Each input is written to a temporary file and read. The reader must return within
//! [`HANG_LIMIT`] (a watchdog thread ends the run otherwise), without panicking; an error must be one line naming the file (or, for a
//! folder, the folder); a success must hold only finite values that make sense: points finite
//! and within `f32`, rotations proper (`RᵀR = I`, `det R = 1`), attitudes finite, a sensor model
//! or voxel map that validates.
//!
//! Budget: [`DEFAULT_CASES`] inputs per test, from a fixed seed, so CI runs the same inputs in a
//! fixed time (measured in the README, "Bad input and fuzzing"). For a longer run, raise the
//! number of inputs and pick other seeds:
//!
//! ```text
//! SDEM_FUZZ_CASES=100000 SDEM_FUZZ_SEED=7 cargo test --release -p sdem-io --test readers_fuzz
//! ```
//!
//! Failing inputs are shrunk and printed, not saved (`failure_persistence: None`), so nothing is
//! written into the repository.

mod common;

use common::formats::{e57_file, e57_resealed, las_seed};
use common::{crc32, resealed};

use proptest::prelude::*;
use proptest::sample::Index;
use proptest::test_runner::{Config, RngSeed, TestCaseError, TestError, TestRunner};
use sdem::geometry::{pose_from_parts, Attitude, Pose, Vec3};

use sdem::map::{Map, Node};
use sdem::posegraph::{diagonal_information, Edge, EdgeKind};
use sdem::slam::SlamOptions;
use sdem::voxel::{VoxelConfig, VoxelMap};
use std::path::{Path, PathBuf};
use std::sync::atomic::{AtomicBool, Ordering};
use std::sync::{Arc, Mutex};
use std::time::{Duration, Instant};

/// Inputs per test (there are two tests per target) unless `SDEM_FUZZ_CASES` says otherwise.
const DEFAULT_CASES: u32 = 8000;

/// A reader that takes longer than this on an input of a few kilobytes hangs.
const HANG_LIMIT: Duration = Duration::from_secs(20);

fn config() -> Config {
    let env = |name: &str| -> Option<u64> {
        std::env::var(name).ok().and_then(|v| v.trim().parse().ok())
    };
    let cases = env("SDEM_FUZZ_CASES").map_or(DEFAULT_CASES, |n| n.min(u64::from(u32::MAX)) as u32);
    Config {
        cases,
        rng_seed: RngSeed::Fixed(env("SDEM_FUZZ_SEED").unwrap_or(0x5D_E6)),
        failure_persistence: None,
        max_shrink_iters: 4096,
        ..Config::default()
    }
}

// ---------------------------------------------------------------------------------------------
// Checking one input
// ---------------------------------------------------------------------------------------------

/// What a target reads: a file, or a folder (saved maps, datasets) built from one mutated file.
#[derive(Clone, Copy)]
enum Target {
    Points(&'static str),
    Sweep,
    Attitude,
    KittiPoses,
    TumPoses,
    UosPose,
    UosFrames,
    KittiCalib,
    SensorToml,
    SlamOptions,
    VoxelMap,
    /// A saved map whose `map.json` is the input.
    MapManifest,
    /// A saved map whose `nodes/000001.pts` is the input (the manifest updated to match).
    MapNode,
    /// A dataset whose `attitude.csv`, `odometry.txt`, `sensor.toml` or first scan is the input.
    Dataset(&'static str),
    /// An E57 survey (`sdem_io::read_e57`).
    E57,
}

impl Target {
    /// The name of the file the input is written to.
    fn file_name(self) -> &'static str {
        match self {
            Target::Points(name) => name,
            Target::Sweep => "000000.sweep",
            Target::Attitude => "attitude.csv",
            Target::KittiPoses => "poses.txt",
            Target::TumPoses => "poses.tum",
            Target::UosPose => "scan000.pose",
            Target::UosFrames => "scan000.frames",
            Target::KittiCalib => "calib.txt",
            Target::SensorToml => "sensor.toml",
            Target::SlamOptions => "config.toml",
            Target::VoxelMap => "map.sdemvox",
            Target::MapManifest => "map.json",
            Target::MapNode => "000001.pts",
            Target::Dataset(name) => name,
            Target::E57 => "survey.e57",
        }
    }
}

fn finite_point(p: &Vec3) -> bool {
    p.iter()
        .all(|v| v.is_finite() && v.abs() <= f64::from(f32::MAX))
}

/// A pose whose rotation is proper and whose numbers are finite.
fn proper(pose: &Pose) -> Result<(), String> {
    let r = pose.rotation.to_rotation_matrix().into_inner();
    let t = pose.translation.vector;
    let orthonormal = (r.transpose() * r - nalgebra::Matrix3::identity())
        .abs()
        .max();
    let det = r.determinant();
    if t.iter().all(|v| v.is_finite()) && orthonormal < 1e-9 && (det - 1.0).abs() < 1e-9 {
        Ok(())
    } else {
        Err(format!("not a proper rigid transform: {pose:?}"))
    }
}

fn all<T>(items: &[T], check: impl Fn(&T) -> Result<(), String>) -> Result<(), String> {
    items.iter().try_for_each(check)
}

fn check_points(points: &[Vec3]) -> Result<(), String> {
    if points.is_empty() {
        return Err("Ok with no points".into());
    }
    match points.iter().position(|p| !finite_point(p)) {
        Some(i) => Err(format!("point {i} is {:?}", points[i])),
        None => Ok(()),
    }
}

fn check_attitude(a: &Attitude) -> Result<(), String> {
    if !a.is_finite() {
        Err(format!("non-finite attitude {a:?}"))
    } else if !a.sigma_is_valid() {
        Err(format!("invalid standard deviations {:?}", a.sigma))
    } else {
        Ok(())
    }
}

/// Reads `path` as `target` and checks what came back; `Ok(Err(message))` is a reader's error.
fn read_and_check(target: Target, path: &Path) -> Result<Result<(), String>, String> {
    let e = |e: sdem_io::Error| Ok(Err(e.to_string()));
    let checked = match target {
        Target::Points(_) => match sdem_io::read_points(path) {
            Ok(points) => check_points(&points),
            Err(err) => return e(err),
        },
        Target::Sweep => match sdem_io::read_sweep(path) {
            Ok(sweep) => sweep
                .validate()
                .map_err(|e| format!("Ok but invalid: {e}"))
                .and_then(|()| {
                    let ranges_ok = sweep.lines.iter().all(|l| {
                        l.ranges
                            .iter()
                            .all(|r| r.is_nan() || (r.is_finite() && *r >= 0.0))
                    });
                    if ranges_ok {
                        Ok(())
                    } else {
                        Err("a negative or infinite range".into())
                    }
                })
                .and_then(|()| match sdem_io::read_points(path) {
                    Ok(points) => check_points(&points),
                    Err(_) => Ok(()), // a sweep without returns has no points
                }),
            Err(err) => return e(err),
        },
        Target::Attitude => match sdem_io::read_attitude_csv(path) {
            Ok(a) if a.is_empty() => Err("Ok with no rows".into()),
            Ok(a) => all(&a, check_attitude),
            Err(err) => return e(err),
        },
        Target::KittiPoses => match sdem_io::read_kitti_poses(path) {
            Ok(poses) => all(&poses, proper),
            Err(err) => return e(err),
        },
        Target::TumPoses => match sdem_io::read_tum_poses(path) {
            Ok(poses) => all(&poses, |(t, pose)| {
                if t.is_finite() {
                    proper(pose)
                } else {
                    Err(format!("timestamp {t}"))
                }
            }),
            Err(err) => return e(err),
        },
        Target::UosPose => match sdem_io::read_uos_pose(path) {
            Ok(pose) => proper(&pose),
            Err(err) => return e(err),
        },
        Target::UosFrames => match sdem_io::read_uos_frames_last(path) {
            Ok(pose) => proper(&pose),
            Err(err) => return e(err),
        },
        Target::KittiCalib => match sdem_io::read_kitti_calib_tr(path) {
            Ok(pose) => proper(&pose),
            Err(err) => return e(err),
        },
        Target::SensorToml => match sdem_io::read_sensor_file(path) {
            Ok(file) => file
                .sensor
                .validate()
                .map_err(|e| format!("Ok but invalid: {e}"))
                .and_then(|()| match file.attitude_sigma {
                    Some(sigma) => check_attitude(&Attitude {
                        sigma,
                        ..Attitude::default()
                    }),
                    None => Ok(()),
                }),
            Err(err) => return e(err),
        },
        Target::SlamOptions => match sdem_io::read_slam_config(path) {
            Ok(config) => config
                .validate()
                .map_err(|e| format!("Ok but invalid: {e}")),
            Err(err) => return e(err),
        },
        Target::E57 => match sdem_io::read_e57(path) {
            Ok(scans) if scans.is_empty() => Err("Ok with no scans".into()),
            Ok(scans) => all(&scans, |scan| {
                if let Some(pose) = &scan.world_from_sensor {
                    proper(pose)?;
                }
                // A scan may be empty (every point invalid): the import skips it.
                match scan.points_in_sensor.is_empty() {
                    true => Ok(()),
                    false => check_points(&scan.points_in_sensor),
                }
            }),
            Err(err) => return e(err),
        },
        Target::VoxelMap => match sdem_io::read_voxel_map(path) {
            Ok(map) => map
                .config()
                .validate()
                .map_err(|e| format!("Ok but invalid: {e}"))
                .and_then(|()| match map.iter().find(|(_, l)| !l.is_finite()) {
                    Some((key, l)) => Err(format!("voxel {key:?} has log-odds {l}")),
                    None => Ok(()),
                }),
            Err(err) => return e(err),
        },
        Target::MapManifest | Target::MapNode => match sdem_io::load_map(path) {
            Ok(saved) => all(&saved.map.nodes, |n| {
                proper(&n.world_from_sensor)?;
                if let Some(a) = &n.attitude_reading {
                    check_attitude(a)?;
                }
                match n.points_in_sensor.iter().flatten().all(|v| v.is_finite()) {
                    true => Ok(()),
                    false => Err(format!("node {} has a non-finite point", n.node_id)),
                }
            })
            .and_then(|()| all(&saved.edges, |edge| proper(&edge.from_from_to)))
            .and_then(|()| {
                all(&saved.loop_closures, |c| match &c.from_from_to {
                    Some(pose) => proper(pose),
                    None => Err("an accepted loop closure without its pose".into()),
                })
            }),
            Err(err) => return e(err),
        },
        Target::Dataset(_) => {
            let dataset = match sdem_io::Dataset::open(path) {
                Ok(dataset) => dataset,
                Err(err) => return e(err),
            };
            let mut checked = Ok(());
            for i in 0..dataset.len() {
                match dataset.load_scan(i) {
                    Ok(points) => checked = checked.and_then(|()| check_points(&points)),
                    Err(err) => return e(err),
                }
            }
            checked
                .and_then(|()| all(dataset.attitudes.as_deref().unwrap_or(&[]), check_attitude))
                .and_then(|()| all(dataset.odometry.as_deref().unwrap_or(&[]), proper))
                .and_then(|()| match &dataset.sensor {
                    Some(s) => s.validate().map_err(|e| format!("Ok but invalid: {e}")),
                    None => Ok(()),
                })
        }
    };
    checked.map(Ok)
}

/// Where a target's inputs go: a temporary folder and, for folder targets, a valid folder in it
/// (built once, since saving a map syncs every file) in which each input replaces one file.
struct Fixture {
    dir: tempfile::TempDir,
    /// The valid folder of a folder target.
    root: PathBuf,
    /// The valid manifest of a saved map.
    manifest: Vec<u8>,
}

impl Fixture {
    fn new(target: Target) -> Fixture {
        let dir = tempfile::tempdir().unwrap();
        let root = dir.path().join("folder");
        let mut manifest = Vec::new();
        match target {
            Target::MapManifest | Target::MapNode => {
                save_small_map(&root);
                manifest = std::fs::read(root.join(sdem_io::MAP_MANIFEST)).unwrap();
            }
            Target::Dataset(_) => write_dataset(&root),
            _ => {}
        }
        Fixture {
            dir,
            root,
            manifest,
        }
    }

    /// Writes `bytes` where `target` reads them and returns the path to read (a folder target's
    /// other files are left valid).
    fn place(&self, target: Target, bytes: &[u8], reseal: bool) -> PathBuf {
        let root = &self.root;
        match target {
            Target::MapManifest => {
                let bytes = if reseal {
                    resealed_manifest(bytes)
                } else {
                    bytes.to_vec()
                };
                rewrite(root.join(sdem_io::MAP_MANIFEST), bytes);
                root.clone()
            }
            Target::MapNode => {
                let (bytes, manifest) = if reseal && bytes.len() >= 4 {
                    let bytes = resealed(bytes.to_vec());
                    let crc = u32::from_le_bytes(bytes[bytes.len() - 4..].try_into().unwrap());
                    let mut json: serde_json::Value =
                        serde_json::from_slice(&self.manifest).unwrap();
                    json["body"]["nodes"][1]["points_crc32"] = crc.into();
                    let text = serde_json::to_vec_pretty(&json).unwrap();
                    (bytes, resealed_manifest(&text))
                } else {
                    (bytes.to_vec(), self.manifest.clone())
                };
                rewrite(root.join(sdem_io::MAP_MANIFEST), manifest);
                rewrite(root.join("nodes/000001.pts"), bytes);
                root.clone()
            }
            Target::Dataset(name) => {
                rewrite(dataset_file(root, name), bytes);
                root.clone()
            }
            _ => {
                let path = self.dir.path().join(target.file_name());
                let bytes = match target {
                    Target::VoxelMap if reseal && bytes.len() >= 4 => resealed(bytes.to_vec()),
                    Target::E57 if reseal => e57_resealed(bytes.to_vec()),
                    _ => bytes.to_vec(),
                };
                rewrite(&path, bytes);
                path
            }
        }
    }
}

/// Replaces the file at `path` by `bytes`. The old file is removed first: overwriting it in
/// place makes ext4 (`auto_da_alloc`) write the new content to disk on close, which made each
/// input cost milliseconds of waiting.
fn rewrite(path: impl AsRef<Path>, bytes: impl AsRef<[u8]>) {
    let path = path.as_ref();
    let _ = std::fs::remove_file(path);
    std::fs::write(path, bytes).unwrap();
}

/// Where a dataset target's file lies in the dataset folder.
fn dataset_file(root: &Path, name: &str) -> PathBuf {
    if name.ends_with(".xyz") {
        root.join("scans").join(name)
    } else {
        root.join(name)
    }
}

/// One input: placed, read, checked. A panic is caught by proptest, which reports it as a
/// failure and shrinks the input; a hang is caught by [`Watchdog`].
fn check_input(
    target: Target,
    fixture: &Fixture,
    bytes: &[u8],
    reseal: bool,
) -> Result<(), String> {
    let path = fixture.place(target, bytes, reseal);
    match read_and_check(target, &path) {
        Err(wrong) => Err(format!("the reader returned Ok, but {wrong}")),
        Ok(Ok(())) => Ok(()),
        Ok(Err(message)) => {
            // A folder's errors name the damaged file inside it, or the folder.
            let name = path.file_name().unwrap().to_string_lossy().into_owned();
            if !message.contains(&name) {
                Err(format!("the error does not name {name}: {message}"))
            } else if message.contains('\n') {
                Err(format!("the error is not one line: {message}"))
            } else {
                Ok(())
            }
        }
    }
}

/// The input being read and since when.
type Busy = (Instant, Vec<u8>);

/// Watches one test's inputs from another thread: when a reader has been busy with one input
/// for longer than [`HANG_LIMIT`], prints the input and ends the test process with a failure (a
/// hung thread cannot be stopped otherwise). Reading in the test's own thread, rather than
/// handing each input to a worker, keeps a case to microseconds on a loaded machine.
struct Watchdog {
    current: Arc<Mutex<Option<Busy>>>,
    done: Arc<AtomicBool>,
}

impl Watchdog {
    fn new(name: &'static str) -> Watchdog {
        let watchdog = Watchdog {
            current: Default::default(),
            done: Default::default(),
        };
        let (current, done) = (watchdog.current.clone(), watchdog.done.clone());
        std::thread::spawn(move || {
            while !done.load(Ordering::Relaxed) {
                std::thread::sleep(Duration::from_millis(200));
                let guard = current.lock().unwrap_or_else(|e| e.into_inner());
                if let Some((since, bytes)) = guard.as_ref() {
                    if since.elapsed() > HANG_LIMIT {
                        eprintln!(
                            "{name}: the reader did not return within {HANG_LIMIT:?} on {:?}",
                            String::from_utf8_lossy(bytes)
                        );
                        std::process::exit(101);
                    }
                }
            }
        });
        watchdog
    }

    /// Runs `f` on `bytes` under watch.
    fn watch<R>(&self, bytes: &[u8], f: impl FnOnce() -> R) -> R {
        *self.current.lock().unwrap_or_else(|e| e.into_inner()) =
            Some((Instant::now(), bytes.to_vec()));
        let result = f();
        *self.current.lock().unwrap_or_else(|e| e.into_inner()) = None;
        result
    }
}

impl Drop for Watchdog {
    fn drop(&mut self) {
        self.done.store(true, Ordering::Relaxed);
    }
}

// ---------------------------------------------------------------------------------------------
// Inputs
// ---------------------------------------------------------------------------------------------

/// Tokens spliced into files: special numbers as text and as raw little-endian bytes, huge
/// counts, separators and encodings.
fn tokens() -> Vec<Vec<u8>> {
    let mut tokens: Vec<Vec<u8>> = [
        "nan",
        "NaN",
        "-nan",
        "inf",
        "-inf",
        "infinity",
        "1e308",
        "-1e308",
        "1e309",
        "3.5e38",
        "1e-320",
        "-0",
        "0",
        "-1",
        "4294967296",
        "18446744073709551615",
        "18446744073709551616",
        "99999999999999999999999",
        "0x10",
        "1.5.5",
        "\n",
        "\r\n",
        " ",
        "\t",
        ",",
        "#",
        "//",
        ":",
        "=",
        "\"",
        "[",
        "{",
        "\u{feff}",
        "é",
    ]
    .iter()
    .map(|t| t.as_bytes().to_vec())
    .collect();
    tokens.push(f32::NAN.to_le_bytes().to_vec());
    tokens.push(f32::INFINITY.to_le_bytes().to_vec());
    tokens.push(f32::NEG_INFINITY.to_be_bytes().to_vec());
    tokens.push(f64::NAN.to_le_bytes().to_vec());
    tokens.push(f64::INFINITY.to_le_bytes().to_vec());
    tokens.push(u64::MAX.to_le_bytes().to_vec());
    tokens.push((1u64 << 40).to_le_bytes().to_vec());
    tokens.push(u32::MAX.to_le_bytes().to_vec());
    tokens.push(vec![0xFF; 3]);
    tokens.push(vec![0]);
    tokens
}

#[derive(Debug, Clone)]
enum Mutation {
    Flip(Index, u8),
    Set(Index, u8),
    Insert(Index, Vec<u8>),
    Delete(Index, usize),
    Truncate(Index),
    Duplicate(Index, usize, Index),
    /// Replaces `n` bytes at a place by a token.
    Splice(Index, usize, Index),
    /// Replaces one of the file's numbers (a run of digits, signs, dots and exponents) by a token.
    Number(Index, Index),
}

fn mutation() -> impl Strategy<Value = Mutation> {
    prop_oneof![
        (any::<Index>(), 0u8..8).prop_map(|(at, bit)| Mutation::Flip(at, bit)),
        (any::<Index>(), any::<u8>()).prop_map(|(at, b)| Mutation::Set(at, b)),
        (any::<Index>(), prop::collection::vec(any::<u8>(), 1..8))
            .prop_map(|(at, bytes)| Mutation::Insert(at, bytes)),
        (any::<Index>(), 1usize..24).prop_map(|(at, n)| Mutation::Delete(at, n)),
        any::<Index>().prop_map(Mutation::Truncate),
        (any::<Index>(), 1usize..40, any::<Index>())
            .prop_map(|(from, n, to)| Mutation::Duplicate(from, n, to)),
        (any::<Index>(), 0usize..6, any::<Index>())
            .prop_map(|(at, n, token)| Mutation::Splice(at, n, token)),
        (any::<Index>(), any::<Index>()).prop_map(|(at, token)| Mutation::Number(at, token)),
        (any::<Index>(), any::<Index>()).prop_map(|(at, token)| Mutation::Number(at, token)),
    ]
}

fn apply(bytes: &mut Vec<u8>, m: &Mutation, tokens: &[Vec<u8>]) {
    // A position in 0..=len.
    let at = |i: &Index, len: usize| i.index(len + 1);
    match m {
        Mutation::Flip(i, bit) if !bytes.is_empty() => {
            let k = i.index(bytes.len());
            bytes[k] ^= 1 << bit;
        }
        Mutation::Set(i, b) if !bytes.is_empty() => {
            let k = i.index(bytes.len());
            bytes[k] = *b;
        }
        Mutation::Insert(i, new) => {
            let k = at(i, bytes.len());
            bytes.splice(k..k, new.iter().copied());
        }
        Mutation::Delete(i, n) => {
            let k = at(i, bytes.len());
            let end = (k + n).min(bytes.len());
            bytes.drain(k..end);
        }
        Mutation::Truncate(i) => {
            let k = at(i, bytes.len());
            bytes.truncate(k);
        }
        Mutation::Duplicate(from, n, to) if !bytes.is_empty() => {
            let k = from.index(bytes.len());
            let chunk = bytes[k..(k + n).min(bytes.len())].to_vec();
            let t = at(to, bytes.len());
            bytes.splice(t..t, chunk);
        }
        Mutation::Splice(i, n, token) => {
            let k = at(i, bytes.len());
            let end = (k + n).min(bytes.len());
            bytes.splice(k..end, token.get(tokens).iter().copied());
        }
        Mutation::Number(i, token) => {
            let numeric = |b: u8| b.is_ascii_digit() || matches!(b, b'.' | b'-' | b'+' | b'e');
            let mut numbers = Vec::new();
            let mut k = 0;
            while k < bytes.len() {
                if bytes[k].is_ascii_digit() {
                    let mut start = k;
                    while start > 0 && numeric(bytes[start - 1]) {
                        start -= 1;
                    }
                    let mut end = k;
                    while end < bytes.len() && numeric(bytes[end]) {
                        end += 1;
                    }
                    numbers.push(start..end);
                    k = end;
                } else {
                    k += 1;
                }
            }
            if !numbers.is_empty() {
                let range = i.get(&numbers).clone();
                bytes.splice(range, token.get(tokens).iter().copied());
            }
        }
        _ => {}
    }
}

/// A valid file, mutated; and whether to recompute its checksums.
fn mutated(seeds: Vec<Vec<u8>>) -> impl Strategy<Value = (Vec<u8>, bool)> {
    let tokens = tokens();
    (
        any::<Index>(),
        prop::collection::vec(mutation(), 1..7),
        any::<bool>(),
    )
        .prop_map(move |(seed, mutations, reseal)| {
            let mut bytes = seed.get(&seeds).clone();
            for m in &mutations {
                apply(&mut bytes, m, &tokens);
            }
            (bytes, reseal)
        })
}

/// Arbitrary bytes, alone or after a prefix of a valid file.
fn arbitrary(seeds: Vec<Vec<u8>>) -> impl Strategy<Value = (Vec<u8>, bool)> {
    (
        any::<Index>(),
        any::<Index>(),
        any::<bool>(),
        prop::collection::vec(any::<u8>(), 0..300),
        any::<bool>(),
    )
        .prop_map(move |(seed, cut, keep_prefix, tail, reseal)| {
            let mut bytes = Vec::new();
            if keep_prefix {
                let seed = seed.get(&seeds);
                bytes.extend_from_slice(&seed[..cut.index(seed.len() + 1)]);
            }
            bytes.extend(tail);
            (bytes, reseal)
        })
}

fn fuzz(target: Target, strategy: impl Strategy<Value = (Vec<u8>, bool)>) {
    let fixture = Fixture::new(target);
    let watchdog = Watchdog::new(target.file_name());
    let mut runner = TestRunner::new(config());
    let result = runner.run(&strategy, |(bytes, reseal)| {
        watchdog
            .watch(&bytes, || check_input(target, &fixture, &bytes, reseal))
            .map_err(TestCaseError::fail)
    });
    match result {
        Ok(()) => {}
        Err(TestError::Fail(why, (bytes, reseal))) => panic!(
            "{}: {why}\nminimal input (checksums recomputed: {reseal}), as text: {:?}\nas bytes: \
             {bytes:02x?}",
            target.file_name(),
            String::from_utf8_lossy(&bytes)
        ),
        Err(e) => panic!("{}: {e}", target.file_name()),
    }
}

// ---------------------------------------------------------------------------------------------
// Valid files
// ---------------------------------------------------------------------------------------------

const POINTS: [[f32; 3]; 4] = [
    [1.0, 2.0, 0.5],
    [-3.0, 0.25, 1.5],
    [2.0, -1.0, -0.5],
    [0.75, 4.0, 2.25],
];

fn seeds(target: Target) -> Vec<Vec<u8>> {
    let text = |s: &str| vec![s.as_bytes().to_vec()];
    match target {
        Target::Points("ascii.ply") => vec![
            b"ply\nformat ascii 1.0\ncomment seed\nelement vertex 4\nproperty float x\n\
              property float y\nproperty double z\nproperty uchar red\nelement face 1\n\
              property list uchar int vertex_indices\nend_header\n1 2 0.5 255\n-3 0.25 1.5 0\n\
              2 -1 -0.5 7\nnan 4 2.25 1\n3 0 1 2\n"
                .to_vec(),
        ],
        Target::Points(name @ ("le.ply" | "be.ply")) => {
            let big = name == "be.ply";
            let format = if big {
                "binary_big_endian"
            } else {
                "binary_little_endian"
            };
            let mut bytes = format!(
                "ply\nformat {format} 1.0\nelement face 2\nproperty list uchar int idx\n\
                 element vertex 4\nproperty float x\nproperty float y\nproperty double z\n\
                 property ushort intensity\nend_header\n"
            )
            .into_bytes();
            let int = |v: i32| if big { v.to_be_bytes() } else { v.to_le_bytes() };
            bytes.push(3);
            for i in [0, 1, 2] {
                bytes.extend(int(i));
            }
            bytes.push(1);
            bytes.extend(int(3));
            for p in POINTS {
                let (x, y) = if big {
                    (p[0].to_be_bytes(), p[1].to_be_bytes())
                } else {
                    (p[0].to_le_bytes(), p[1].to_le_bytes())
                };
                bytes.extend(x);
                bytes.extend(y);
                let z = f64::from(p[2]);
                bytes.extend(if big { z.to_be_bytes() } else { z.to_le_bytes() });
                bytes.extend([0, 9]);
            }
            vec![bytes]
        }
        Target::Points("ascii.pcd") => text(
            "# .PCD v0.7\nVERSION 0.7\nFIELDS x y z rgb\nSIZE 4 4 8 4\nTYPE F F F U\nCOUNT 1 1 1 1\n\
             WIDTH 4\nHEIGHT 1\nVIEWPOINT 0 0 0 1 0 0 0\nPOINTS 4\nDATA ascii\n1 2 0.5 0\n\
             -3 0.25 1.5 255\n2 -1 -0.5 7\nnan 4 2.25 1\n",
        ),
        Target::Points("binary.pcd") => {
            let mut bytes = b"VERSION 0.7\nFIELDS x y _ z\nSIZE 4 4 1 8\nTYPE F F U F\n\
                              COUNT 1 1 2 1\nWIDTH 2\nHEIGHT 2\nPOINTS 4\nDATA binary\n"
                .to_vec();
            for p in POINTS {
                bytes.extend(p[0].to_le_bytes());
                bytes.extend(p[1].to_le_bytes());
                bytes.extend([0xAB, 0xCD]);
                bytes.extend(f64::from(p[2]).to_le_bytes());
            }
            vec![bytes]
        }
        // Written by Open3D (tests/fixtures/open3d): real LZF blocks with back references.
        Target::Points("compressed.pcd") => vec![
            include_bytes!("fixtures/open3d/legacy_compressed.pcd").to_vec(),
            include_bytes!("fixtures/open3d/tensor_compressed.pcd").to_vec(),
        ],
        // Point formats 3 (LAZ: point-wise chunks) and 7 (LAS 1.4; LAZ: layered chunks).
        Target::Points(name @ ("scan.las" | "scan.laz")) => [3, 7]
            .into_iter()
            .map(|format| las_seed(&POINTS, format, name == "scan.laz"))
            .collect(),
        Target::Points("scan.xyz") => text("# x y z\n1 2 0.5\n-3,0.25,1.5,0.9\n\t2 -1 -0.5 # c\n"),
        Target::Points("scan.bin") => vec![POINTS
            .iter()
            .flat_map(|p| [p[0], p[1], p[2], 0.5])
            .flat_map(f32::to_le_bytes)
            .collect()],
        Target::Points("scan000.3d") => text("360 x 225\n100 50 200 0.3\n-10.5 0 300\n40 -20 150\n"),
        Target::Points(other) => panic!("no seed for {other}"),
        Target::Sweep => text(
            "sdem-sweep 1\npan_deg -90 45 5\nlift_slide_m 0.55\n# comment\nlines 3\n\
             -45 0.01 -0.02 0.1 1.2345 nan 1.25 2 3.5\n\
             0 0.01 -0.02 0.1 1.2411 1.2398 nan 0.5 0\n\
             40 0.01 -0.02 0.1 2 2 2 2 7.25\n",
        ),
        Target::Attitude => vec![
            b"index,roll_deg,pitch_deg,yaw_deg\n0,0.5,-1.25,90\n1,0.25,-1,92.5\n".to_vec(),
            b"index,roll_deg,pitch_deg,yaw_deg,roll_pitch_sigma_deg,yaw_sigma_deg\n\
              0,0.5,-1.25,90,0.5,3.5\n1,0.25,-1,92.5,0.25,20\n"
                .to_vec(),
        ],
        Target::KittiPoses => text(
            "1 0 0 0 0 1 0 0 0 0 1 0\n\
             9.999978e-01 5.272628e-04 -2.066935e-03 -4.690294e-02 -5.296506e-04 9.999992e-01 \
             -1.154865e-03 -2.839928e-02 2.066324e-03 1.155958e-03 9.999971e-01 8.586941e-01\n",
        ),
        Target::TumPoses => text("# t x y z qx qy qz qw\n0 1 2 3 0 0 0 1\n1 1.5 2 3 0 0 0.7071068 0.7071068\n"),
        Target::UosPose => text("-3.1 -7.5 156.9\n1.36 -30 -0.56\n"),
        Target::UosFrames => text(
            "1 0 0 0 0 1 0 0 0 0 1 0 0 0 0 1 2\n\
             0 0 -1 0 0 1 0 0 1 0 0 0 100 0 300 1 1\n",
        ),
        Target::KittiCalib => text(
            "P0: 7.18e+02 0 6.07e+02 0 0 7.18e+02 1.85e+02 0 0 0 1 0\n\
             Tr: 4.276802385584e-04 -9.999672484946e-01 -8.084491683471e-03 -1.198459927713e-02 \
             -7.210626507497e-03 8.081198471645e-03 -9.999413164504e-01 -5.403984729748e-02 \
             9.999738645903e-01 4.859485810390e-04 -7.206933692422e-03 -2.921968648686e-01\n",
        ),
        Target::SensorToml => vec![
            b"# sdem sensor model\ntilt_min_deg = -45.0\ntilt_max_deg = 40.0\npan_step_deg = 1.0\n\
              max_range_m = 8.0\ntrusted_range_m = 3.0\n\n[lift]\nlink_length_m = 0.4\n"
                .to_vec(),
            b"attitude_sigma_roll_pitch_deg = 0.5\nattitude_sigma_yaw_deg = 20\nmax_range_m = 8.0\n\
              \n[lift]\nlink_length_m = 0.4\n"
                .to_vec(),
        ],
        Target::SlamOptions => vec![toml::to_string_pretty(&SlamOptions::default())
            .unwrap()
            .into_bytes()],
        Target::VoxelMap => vec![voxel_bytes()],
        Target::E57 => vec![e57_file(&[&POINTS, &POINTS[..2]])],
        Target::MapManifest | Target::MapNode => {
            let dir = tempfile::tempdir().unwrap();
            save_small_map(dir.path());
            let file = match target {
                Target::MapManifest => sdem_io::MAP_MANIFEST,
                _ => "nodes/000001.pts",
            };
            vec![std::fs::read(dir.path().join(file)).unwrap()]
        }
        Target::Dataset(name) => {
            let dir = tempfile::tempdir().unwrap();
            write_dataset(dir.path());
            vec![std::fs::read(dataset_file(dir.path(), name)).unwrap()]
        }
    }
}

fn voxel_bytes() -> Vec<u8> {
    let mut map = VoxelMap::new(VoxelConfig {
        voxel_m: 0.25,
        max_range_m: 4.0,
        ..Default::default()
    })
    .unwrap();
    let points: Vec<Vec3> = (0..12)
        .map(|i| {
            let a = f64::from(i) * 0.5;
            Vec3::new(1.5 * a.cos(), 1.5 * a.sin(), 0.2)
        })
        .collect();
    map.insert_scan(&Pose::identity(), &points);
    let dir = tempfile::tempdir().unwrap();
    let path = dir.path().join("m.sdemvox");
    sdem_io::write_voxel_map(&path, &map).unwrap();
    std::fs::read(path).unwrap()
}

/// A manifest with its checksum recomputed, when it is a JSON object with a body (else as is).
fn resealed_manifest(bytes: &[u8]) -> Vec<u8> {
    let Ok(mut json) = serde_json::from_slice::<serde_json::Value>(bytes) else {
        return bytes.to_vec();
    };
    if !json.is_object() || json.get("body").is_none() {
        return bytes.to_vec();
    }
    let canonical = serde_json::to_vec(&json["body"]).unwrap();
    json["checksum"] = crc32(&canonical).into();
    serde_json::to_vec_pretty(&json).unwrap()
}

fn save_small_map(root: &Path) {
    let nodes: Vec<Node> = (0..3)
        .map(|i| Node {
            node_id: i,
            scan_index: i,
            world_from_sensor: pose_from_parts(
                Vec3::new(0.5 * i as f64, 0.1, 0.0),
                Attitude::from_degrees(0.5, -1.0, 10.0 * i as f64),
            ),
            attitude_reading: (i != 1).then(|| Attitude::from_degrees(0.5, -1.0, 9.0)),
            points_in_sensor: (0..4).map(|k| [k as f32 * 0.25, 1.0, 0.3]).collect(),
            segment: 0,
            run: 0,
        })
        .collect();
    let edges = vec![Edge {
        from: 0,
        to: 1,
        from_from_to: nodes[0].world_from_sensor.inverse() * nodes[1].world_from_sensor,
        information: diagonal_information(0.01, 0.002),
        kind: EdgeKind::Odometry,
    }];
    sdem_io::save_map(
        root,
        &mut sdem_io::NodeFiles::default(),
        &SlamOptions::default(),
        &Map { nodes },
        &edges,
        &[],
        &[],
    )
    .unwrap();
}

fn write_dataset(root: &Path) {
    std::fs::create_dir_all(root.join("scans")).unwrap();
    std::fs::write(root.join("scans/000000.xyz"), "1 2 0.5\n-3 0.25 1.5\n").unwrap();
    std::fs::write(root.join("scans/000001.xyz"), "2 -1 -0.5\n").unwrap();
    std::fs::write(
        root.join("attitude.csv"),
        "index,roll_deg,pitch_deg,yaw_deg\n0,0.5,-1,10\n1,0.25,-1,12\n",
    )
    .unwrap();
    std::fs::write(
        root.join("odometry.txt"),
        "1 0 0 0 0 1 0 0 0 0 1 0\n0 -1 0 0.5 1 0 0 0 0 0 1 0\n",
    )
    .unwrap();
    std::fs::write(root.join("sensor.toml"), "max_range_m = 8.0\n").unwrap();
}

// ---------------------------------------------------------------------------------------------
// The targets: two tests each
// ---------------------------------------------------------------------------------------------

macro_rules! fuzz_targets {
    ($($name:ident => $target:expr,)*) => {
        mod arbitrary {
            use super::*;
            $(#[test]
            fn $name() {
                let target = $target;
                fuzz(target, arbitrary(seeds(target)));
            })*
        }
        mod mutated {
            use super::*;
            $(#[test]
            fn $name() {
                let target = $target;
                fuzz(target, mutated(seeds(target)));
            })*
        }
        /// Every seed is valid: mutations start from files the reader accepts.
        #[test]
        fn seeds_are_valid() {
            $(let fixture = Fixture::new($target);
            for seed in seeds($target) {
                let path = fixture.place($target, &seed, false);
                match read_and_check($target, &path) {
                    Ok(Ok(())) => {}
                    other => panic!("{}: {other:?}", stringify!($name)),
                }
            })*
        }
    };
}

fuzz_targets! {
    ply_ascii => Target::Points("ascii.ply"),
    ply_binary_little_endian => Target::Points("le.ply"),
    ply_binary_big_endian => Target::Points("be.ply"),
    pcd_ascii => Target::Points("ascii.pcd"),
    pcd_binary => Target::Points("binary.pcd"),
    pcd_binary_compressed => Target::Points("compressed.pcd"),
    las => Target::Points("scan.las"),
    laz => Target::Points("scan.laz"),
    xyz => Target::Points("scan.xyz"),
    kitti_bin => Target::Points("scan.bin"),
    uos_3d => Target::Points("scan000.3d"),
    sweep => Target::Sweep,
    attitude_csv => Target::Attitude,
    kitti_poses => Target::KittiPoses,
    tum_poses => Target::TumPoses,
    uos_pose => Target::UosPose,
    uos_frames => Target::UosFrames,
    kitti_calib => Target::KittiCalib,
    sensor_toml => Target::SensorToml,
    slam_config => Target::SlamOptions,
    voxel_map => Target::VoxelMap,
    e57 => Target::E57,
    map_manifest => Target::MapManifest,
    map_node_file => Target::MapNode,
    dataset_attitude => Target::Dataset("attitude.csv"),
    dataset_odometry => Target::Dataset("odometry.txt"),
    dataset_sensor => Target::Dataset("sensor.toml"),
    dataset_scan => Target::Dataset("000000.xyz"),
}
