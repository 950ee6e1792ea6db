//! Bad input. Every reader of `sdem_io`, given malformed input of each kind
//! that applies to it, returns an error — never a panic, never a silently wrong value — whose
//! message names the file and the place: a line (`FILE:N:`), or an element, record, byte offset
//! or field named in words. The table below holds one row per reader × kind (often several: a
//! file is cut at several points); [`every_malformed_input_is_a_clear_error`] runs them all and
//! reports every row that fails, not only the first.
//!
//! Kinds: an empty file; a truncated one (cut inside the header, mid-record, mid-number, before
//! the declared count is reached); NaN; ±infinity; a wrong or missing header or magic; an absurd
//! declared count (checked against the file's size before anything is allocated); wrong units;
//! a matrix or quaternion that is not a rotation; a wrong number of columns (or an unknown key or
//! a wrong type); a value out of its range.
//!
//! What is detectable per reader, and what is not (so has no row):
//! - **NaN** is "no return" where the format says so: a PLY / PCD / KITTI `.bin` point with a NaN
//!   coordinate is skipped, and a `.sweep` range may be `nan`
//!   ([`nan_means_no_return_where_the_format_says_so`]); a file with nothing else is an error.
//!   Everywhere else NaN is an error naming the line.
//! - **Units.** Point clouds (every format) and `.sweep` ranges must be metres in the sensor
//!   frame: when half of a scan's points (ranges) lie beyond `MAX_MEDIAN_RANGE_M` = 1 km, the
//!   file is in millimetres or in world coordinates, and the error says so. Centimetres, and
//!   millimetres of a scan taken within a metre, look like metres and cannot be told apart.
//!   `attitude.csv` and `.sweep` readings are degrees: a roll or pitch beyond ±360° is not an
//!   angle in degrees (hundredths of a degree, raw counts); radians look like small angles in
//!   degrees and cannot be told apart, and yaw is not bounded (a gyro heading may be
//!   unwrapped). Pose translations (KITTI, TUM, 3DTK), `sensor.toml` lengths and angles, voxel
//!   sizes: any value is a possible one, so no unit check (3DTK `.pose` and `.frames` refuse
//!   only the absurd: a translation beyond ±1e6 m, an angle beyond a thousand turns).
//! - **Truncated mid-number** is detected where the cut leaves a non-number (`5e`, `1,1,`), where
//!   the declared count is not reached (PLY, PCD, `.sweep`, binary formats) and, in `.sweep`,
//!   where the last line lacks its line break. A text file without a declared count cut inside
//!   its last number so that the rest is still a number (`6.25` → `6.2`) cannot be told from a
//!   shorter valid file (`.xyz`, `.3d`, `attitude.csv`, pose files, `sensor.toml`).
//! - A KITTI `.bin` has no header (any 16 bytes are a point), so no header row.

mod common;

use common::formats::{e57_file, e57_without_scans, las_count, las_file, pcd_lzf_block};
use common::{crc32, resealed};

use sdem::geometry::{pose_from_parts, Attitude, Pose, Vec3};

use sdem::map::{LoopClosure, Map, Node};
use sdem::posegraph::{diagonal_information, Edge, EdgeKind};
use sdem::slam::SlamOptions;
use sdem::voxel::{VoxelConfig, VoxelMap};
use std::collections::BTreeMap;
use std::panic::{catch_unwind, AssertUnwindSafe};
use std::path::{Path, PathBuf};

// ---------------------------------------------------------------------------------------------
// The table's vocabulary
// ---------------------------------------------------------------------------------------------

/// The kinds of malformed input of the issue.
#[derive(Debug, Clone, Copy, PartialEq, Eq, PartialOrd, Ord)]
enum Kind {
    Empty,
    Truncated,
    Nan,
    Inf,
    Header,
    Count,
    Units,
    Rotation,
    /// A wrong number of columns or fields, an unknown key, a wrong type.
    Columns,
    /// A value outside its valid range.
    Range,
}

/// A reader under test; each reads one file, except `Map` and `Dataset`, which read a folder.
#[derive(Debug, Clone, Copy, PartialEq, Eq, PartialOrd, Ord)]
enum Reader {
    /// `sdem_io::read_points` (the format from the extension).
    Points,
    Sweep,
    Attitude,
    KittiPoses,
    TumPoses,
    UosPose,
    UosFrames,
    KittiCalib,
    SensorToml,
    /// `sdem_io::read_slam_config`, the file of `sdem slam --config`.
    SlamOptions,
    VoxelMap,
    /// `sdem_io::load_map` on a saved map folder.
    Map,
    /// `sdem_io::Dataset::open`, then every scan and sweep of it.
    Dataset,
    /// `sdem_io::read_e57`, an E57 survey.
    E57,
}

/// What the error message must contain besides the file name.
#[derive(Debug, Clone, Copy)]
enum Check {
    /// `FILE:N:`, the file and line N.
    Line(usize),
    /// `FILE:N:` for some line N (where the exact line is up to a JSON or TOML parser).
    SomeLine,
    /// These words: an element, record, field or byte offset, or for a whole-file problem
    /// (empty, no points) what is wrong.
    Has(&'static str),
}

use Check::{Has, Line, SomeLine};

/// The input: one file's bytes, or a folder to build.
enum Input {
    File(Vec<u8>),
    Folder(Box<dyn Fn(&Path)>),
}

struct Case {
    reader: Reader,
    /// The format or file, as the summary lists it (`ply ascii`, `attitude.csv`, …).
    format: &'static str,
    kind: Kind,
    /// The file the message must name: the file read, or for a folder the damaged file in it.
    name: &'static str,
    input: Input,
    checks: Vec<Check>,
}

fn file(
    reader: Reader,
    format: &'static str,
    kind: Kind,
    name: &'static str,
    bytes: impl Into<Vec<u8>>,
    checks: &[Check],
) -> Case {
    Case {
        reader,
        format,
        kind,
        name,
        input: Input::File(bytes.into()),
        checks: checks.to_vec(),
    }
}

fn folder(
    reader: Reader,
    format: &'static str,
    kind: Kind,
    name: &'static str,
    build: impl Fn(&Path) + 'static,
    checks: &[Check],
) -> Case {
    Case {
        reader,
        format,
        kind,
        name,
        input: Input::Folder(Box::new(build)),
        checks: checks.to_vec(),
    }
}

/// Runs one reader on `path` (a file, or a folder for `Map` and `Dataset`).
fn read(reader: Reader, path: &Path) -> sdem_io::Result<()> {
    match reader {
        Reader::Points => sdem_io::read_points(path).map(drop),
        Reader::Sweep => sdem_io::read_sweep(path).map(drop),
        Reader::Attitude => sdem_io::read_attitude_csv(path).map(drop),
        Reader::KittiPoses => sdem_io::read_kitti_poses(path).map(drop),
        Reader::TumPoses => sdem_io::read_tum_poses(path).map(drop),
        Reader::UosPose => sdem_io::read_uos_pose(path).map(drop),
        Reader::UosFrames => sdem_io::read_uos_frames_last(path).map(drop),
        Reader::KittiCalib => sdem_io::read_kitti_calib_tr(path).map(drop),
        Reader::SensorToml => sdem_io::read_sensor_toml(path).map(drop),
        Reader::SlamOptions => sdem_io::read_slam_config(path).map(drop),
        Reader::VoxelMap => sdem_io::read_voxel_map(path).map(drop),
        Reader::Map => sdem_io::load_map(path).map(drop),
        Reader::E57 => sdem_io::read_e57(path).map(drop),
        Reader::Dataset => {
            let dataset = sdem_io::Dataset::open(path)?;
            for i in 0..dataset.len() {
                dataset.load_scan(i)?;
                dataset.load_sweep(i)?;
            }
            Ok(())
        }
    }
}

/// Builds the case's input in `dir`; returns the path to read.
fn materialize(case: &Case, dir: &Path) -> PathBuf {
    match &case.input {
        Input::File(bytes) => {
            let path = dir.join(case.name);
            std::fs::write(&path, bytes).unwrap();
            path
        }
        Input::Folder(build) => {
            let root = dir.join("folder");
            std::fs::create_dir_all(&root).unwrap();
            build(&root);
            root
        }
    }
}

/// Runs a case: `Ok(())` when the reader returned an error that passes every check, else why not.
fn run(case: &Case) -> Result<(), String> {
    let dir = tempfile::tempdir().unwrap();
    let path = materialize(case, dir.path());
    let result = catch_unwind(AssertUnwindSafe(|| read(case.reader, &path)));
    let message = match result {
        Err(_) => return Err("the reader panicked".into()),
        Ok(Ok(())) => return Err("the reader accepted it".into()),
        Ok(Err(e)) => e.to_string(),
    };
    let mut problems = Vec::new();
    if !message.contains(case.name) {
        problems.push(format!("does not name {}", case.name));
    }
    if message.contains('\n') {
        problems.push("is not one line".to_string());
    }
    for check in &case.checks {
        let ok = match check {
            Line(n) => message.contains(&format!("{}:{n}:", case.name)),
            SomeLine => message
                .split(&format!("{}:", case.name))
                .skip(1)
                .any(|rest| {
                    let digits: String = rest.chars().take_while(char::is_ascii_digit).collect();
                    !digits.is_empty() && rest[digits.len()..].starts_with(':')
                }),
            Has(words) => message.contains(words),
        };
        if !ok {
            problems.push(format!("lacks {check:?}"));
        }
    }
    if problems.is_empty() {
        Ok(())
    } else {
        Err(format!("{}: {message}", problems.join(", ")))
    }
}

// ---------------------------------------------------------------------------------------------
// Valid files to start from
// ---------------------------------------------------------------------------------------------

/// Three points in metres, and the same in millimetres (median range ~3.6 km as metres: the
/// median point is point 0).
const POINTS: [[f32; 3]; 3] = [[1.0, 2.0, 0.5], [-3.0, 0.25, 1.5], [2.0, -1.0, -0.5]];
const POINTS_MM: [[f32; 3]; 3] = [
    [1200.0, 3400.0, -500.0],
    [2500.0, 800.0, 900.0],
    [-4000.0, 150.0, 1000.0],
];
const TEXT_POINTS: &str = "1 2 0.5\n-3 0.25 1.5\n2 -1 -0.5\n";
const TEXT_POINTS_MM: &str = "1200 3400 -500\n2500 800 900\n-4000 150 1000\n";
const ALL_NAN: &str = "nan nan nan\nnan 1 2\n1 nan 2\n";

/// An ASCII PLY of x y z floats: the header is 7 lines, the first vertex is line 8.
fn ply_ascii(count: &str, body: &str) -> Vec<u8> {
    format!(
        "ply\nformat ascii 1.0\nelement vertex {count}\nproperty float x\nproperty float y\n\
         property float z\nend_header\n{body}"
    )
    .into_bytes()
}

/// A binary PLY of x y z floats; the vertex element is declared on line 3.
fn ply_binary(big_endian: bool, count: Option<&str>, points: &[[f32; 3]]) -> Vec<u8> {
    let format = if big_endian {
        "binary_big_endian"
    } else {
        "binary_little_endian"
    };
    let count = count.map_or(points.len().to_string(), str::to_string);
    let mut bytes = format!(
        "ply\nformat {format} 1.0\nelement vertex {count}\nproperty float x\nproperty float y\n\
         property float z\nend_header\n"
    )
    .into_bytes();
    for v in points.iter().flatten() {
        bytes.extend(if big_endian {
            v.to_be_bytes()
        } else {
            v.to_le_bytes()
        });
    }
    bytes
}

/// A PCD header (8 lines: WIDTH on line 5, POINTS on line 7, DATA on line 8) and its data.
fn pcd(count: &str, data: &str, body: &[u8]) -> Vec<u8> {
    let mut bytes = format!(
        "FIELDS x y z\nSIZE 4 4 4\nTYPE F F F\nCOUNT 1 1 1\nWIDTH {count}\nHEIGHT 1\n\
         POINTS {count}\nDATA {data}\n"
    )
    .into_bytes();
    bytes.extend_from_slice(body);
    bytes
}

fn f32_le(points: &[[f32; 3]]) -> Vec<u8> {
    points
        .iter()
        .flatten()
        .flat_map(|v| v.to_le_bytes())
        .collect()
}

/// KITTI records: x y z intensity.
fn kitti_bin(points: &[[f32; 3]]) -> Vec<u8> {
    points
        .iter()
        .flat_map(|p| [p[0], p[1], p[2], 0.5])
        .flat_map(|v| v.to_le_bytes())
        .collect()
}

/// A sweep: header lines 1–4, data lines 5 and 6.
fn sweep(data: &str) -> String {
    format!("sdem-sweep 1\npan_deg -90 90 3\nlift_slide_m 0.5\nlines 2\n{data}")
}
const SWEEP_DATA: &str = "0 0.1 -0.2 10 1.5 nan 2.25\n5 0.1 -0.2 10 1.25 3 0.75\n";

const ATTITUDE_HEADER: &str = "index,roll_deg,pitch_deg,yaw_deg\n";
const KITTI_IDENTITY: &str = "1 0 0 0 0 1 0 0 0 0 1 0\n";
const TUM_IDENTITY: &str = "0 1 2 3 0 0 0 1\n";
/// slam6D's frame line: the identity, column-major, and a flag.
const FRAMES_IDENTITY: &str = "1 0 0 0 0 1 0 0 0 0 1 0 0 0 0 1 2\n";
const CALIB: &str = "P0: 1 0 0 0 0 1 0 0 0 0 1 0\nTr: 0 -1 0 0.1 0 0 -1 -0.05 1 0 0 -0.3\n";

/// A voxel map file: header (68 bytes), records of 16 bytes, CRC-32.
fn voxel_bytes() -> Vec<u8> {
    let mut map = VoxelMap::new(VoxelConfig {
        voxel_m: 0.2,
        max_range_m: 5.0,
        ..Default::default()
    })
    .unwrap();
    let points: Vec<Vec3> = (0..40)
        .map(|i| {
            let a = f64::from(i) * 0.16;
            Vec3::new(2.0 * a.cos(), 2.0 * a.sin(), 0.3)
        })
        .collect();
    map.insert_scan(&Pose::identity(), &points);
    let dir = tempfile::tempdir().unwrap();
    let path = dir.path().join("m.sdemvox");
    sdem_io::write_voxel_map(&path, &map).unwrap();
    std::fs::read(path).unwrap()
}

/// A saved map of three nodes with one loop closure, written into `root`.
fn save_small_map(root: &Path) {
    let nodes: Vec<Node> = (0..3)
        .map(|i| Node {
            node_id: i,
            scan_index: i,
            world_from_sensor: pose_from_parts(
                Vec3::new(0.5 * i as f64, 0.1, 0.0),
                Attitude::from_degrees(0.5, -1.0, 10.0 * i as f64),
            ),
            attitude_reading: Some(Attitude::from_degrees(0.5, -1.0, 10.0 * i as f64)),
            points_in_sensor: (0..8)
                .map(|k| [k as f32 * 0.25, 1.0 - k as f32 * 0.1, 0.3])
                .collect(),
            segment: 0,
            run: 0,
        })
        .collect();
    let from_from_to = nodes[0].world_from_sensor.inverse() * nodes[2].world_from_sensor;
    let edges = vec![Edge {
        from: 0,
        to: 2,
        from_from_to,
        information: diagonal_information(0.01, 0.002),
        kind: EdgeKind::LoopClosure,
    }];
    let closures = vec![LoopClosure {
        descriptor_distance: Some(0.01),
        accepted: true,
        cost: Some(1e-3),
        inlier_fraction: Some(0.9),
        correction_m: Some(0.004),
        from_from_to: Some(from_from_to),
        ..LoopClosure::unchecked(0, 2)
    }];
    sdem_io::save_map(
        root,
        &mut sdem_io::NodeFiles::default(),
        &SlamOptions::default(),
        &Map { nodes },
        &edges,
        &closures,
        &[],
    )
    .unwrap();
}

/// Edits the manifest's JSON with `edit` and recomputes its checksum, as a careful forger would:
/// what is then wrong must be found by the checks after the checksum.
fn edit_manifest(root: &Path, edit: impl Fn(&mut serde_json::Value)) {
    let path = root.join(sdem_io::MAP_MANIFEST);
    let mut manifest: serde_json::Value =
        serde_json::from_slice(&std::fs::read(&path).unwrap()).unwrap();
    edit(&mut manifest);
    let canonical = serde_json::to_vec(&manifest["body"]).unwrap();
    manifest["checksum"] = crc32(&canonical).into();
    std::fs::write(&path, serde_json::to_vec_pretty(&manifest).unwrap()).unwrap();
}

/// Replaces node 1's file by `edit` of its bytes, resealed, and updates the manifest's record
/// of it (checksum, and the point count it declares), so that only the edit is wrong.
fn edit_node_file(root: &Path, edit: impl Fn(&mut Vec<u8>)) {
    let path = root.join("nodes/000001.pts");
    let mut bytes = std::fs::read(&path).unwrap();
    edit(&mut bytes);
    let bytes = resealed(bytes);
    let crc = u32::from_le_bytes(bytes[bytes.len() - 4..].try_into().unwrap());
    std::fs::write(&path, &bytes).unwrap();
    edit_manifest(root, |m| {
        m["body"]["nodes"][1]["points_crc32"] = crc.into();
    });
}

/// A minimal valid dataset: two `.xyz` scans, attitude, odometry, truth and a sensor model.
fn write_dataset(root: &Path) {
    std::fs::create_dir_all(root.join("scans")).unwrap();
    std::fs::write(root.join("scans/000000.xyz"), TEXT_POINTS).unwrap();
    std::fs::write(root.join("scans/000001.xyz"), TEXT_POINTS).unwrap();
    std::fs::write(
        root.join("attitude.csv"),
        format!("{ATTITUDE_HEADER}0,0.5,-1,10\n1,0.25,-1,12\n"),
    )
    .unwrap();
    std::fs::write(
        root.join("odometry.txt"),
        format!("{KITTI_IDENTITY}{KITTI_IDENTITY}"),
    )
    .unwrap();
    std::fs::write(
        root.join("poses_truth.txt"),
        format!("{KITTI_IDENTITY}{KITTI_IDENTITY}"),
    )
    .unwrap();
    std::fs::write(root.join("sensor.toml"), "max_range_m = 8.0\n").unwrap();
}

/// A dataset with `name` (relative to the root) replaced by `content`.
fn dataset_with(name: &'static str, content: &'static str) -> impl Fn(&Path) {
    move |root| {
        write_dataset(root);
        std::fs::write(root.join(name), content).unwrap();
    }
}

fn cut(bytes: &[u8], len: usize) -> Vec<u8> {
    bytes[..len].to_vec()
}

fn minus(bytes: &[u8], n: usize) -> Vec<u8> {
    bytes[..bytes.len() - n].to_vec()
}

// ---------------------------------------------------------------------------------------------
// The table
// ---------------------------------------------------------------------------------------------

#[allow(clippy::vec_init_then_push)]
#[rustfmt::skip]
fn cases() -> Vec<Case> {
    use Kind::*;
    use Reader::*;
    let mut c = Vec::new();

    // --- PLY, ascii ---------------------------------------------------------------------------
    let (r, f, n) = (Points, "ply ascii", "scan.ply");
    c.push(file(r, f, Empty, n, "", &[Has("empty")]));
    c.push(file(r, f, Truncated, n, "ply\nformat ascii 1.0\nelement vert", &[Line(3)]));
    c.push(file(r, f, Truncated, n, "ply\nformat ascii 1.0\nelement vertex 3\nproperty float x\n", &[Line(4), Has("end_header")]));
    c.push(file(r, f, Truncated, n, ply_ascii("3", "1 2 0.5\n-3 0.25 1.5\n2 -1"), &[Line(10)]));
    c.push(file(r, f, Truncated, n, ply_ascii("3", "1 2 0.5\n-3 0.25 1.5\n2 -1 -5e"), &[Line(10)]));
    c.push(file(r, f, Truncated, n, ply_ascii("3", "1 2 0.5\n-3 0.25 1.5"), &[Line(9), Has("2 of the 3")]));
    c.push(file(r, f, Nan, n, ply_ascii("3", ALL_NAN), &[Has("no points")]));
    c.push(file(r, f, Inf, n, ply_ascii("3", "1 2 0.5\ninf 0 0\n2 -1 -0.5\n"), &[Line(9)]));
    c.push(file(r, f, Inf, n, ply_ascii("3", "1 2 0.5\n0 0 0\n2 -inf -0.5\n"), &[Line(10)]));
    c.push(file(r, f, Header, n, [b"plx".as_slice(), &ply_ascii("3", TEXT_POINTS)[3..]].concat(), &[Line(1)]));
    c.push(file(r, f, Header, n, "ply\nformat ascii\nelement vertex 1\nproperty float x\nproperty float y\nproperty float z\nend_header\n1 2 3\n", &[Line(2)]));
    c.push(file(r, f, Header, n, "ply\nformat ascii 1.0\nelement vertex 1\nproperty float x\nproperty float y\nend_header\n1 2\n", &[Has("'z'")]));
    c.push(file(r, f, Header, n, "ply\nformat ascii 1.0\nelement point 1\nproperty float x\nproperty float y\nproperty float z\nend_header\n1 2 3\n", &[Has("'vertex'")]));
    c.push(file(r, f, Count, n, ply_ascii("4000000000", TEXT_POINTS), &[Line(3), Has("4000000000")]));
    c.push(file(r, f, Units, n, ply_ascii("3", TEXT_POINTS_MM), &[Has("point 0"), Has("millimetres")]));
    c.push(file(r, f, Columns, n, ply_ascii("3", "1 2\n-3 0.25 1.5\n2 -1 -0.5\n"), &[Line(8)]));
    c.push(file(r, f, Columns, n, ply_ascii("3", "1 2 0.5\n-3 0.25 1.5 7\n2 -1 -0.5\n"), &[Line(9)]));

    // --- PLY, binary little and big endian ----------------------------------------------------
    let (f, n) = ("ply binary_little_endian", "scan_le.ply");
    let good = ply_binary(false, None, &POINTS);
    let header_len = good.len() - 36;
    c.push(file(r, f, Truncated, n, minus(&good, 5), &[Line(3), Has("'vertex' element 2"), Has("byte offset")]));
    c.push(file(r, f, Truncated, n, cut(&good, header_len + 13), &[Line(3), Has("'vertex' element 1")]));
    c.push(file(r, f, Truncated, n, cut(&good, header_len), &[Line(3), Has("'vertex' element 0")]));
    c.push(file(r, f, Truncated, n, cut(&good, 40), &[SomeLine, Has("end_header")]));
    // A list element before the vertices whose list runs past the end of the file.
    let mut list = b"ply\nformat binary_little_endian 1.0\nelement face 2\nproperty list uchar int idx\nelement vertex 1\nproperty float x\nproperty float y\nproperty float z\nend_header\n".to_vec();
    list.extend([3, 0, 0, 0, 0, 1, 0, 0, 0, 2, 0, 0, 0, 200, 1, 0, 0, 0]);
    list.extend(f32_le(&POINTS[..1]));
    c.push(file(r, f, Truncated, n, list, &[Line(3), Has("byte offset")]));
    c.push(file(r, f, Nan, n, ply_binary(false, None, &[[f32::NAN; 3], [1.0, f32::NAN, 0.0]]), &[Has("no points")]));
    c.push(file(r, f, Inf, n, ply_binary(false, None, &[POINTS[0], [f32::INFINITY, 0.0, 0.0]]), &[Has("vertex 1")]));
    let mut magic = good.clone();
    magic[0] = 0;
    c.push(file(r, f, Header, n, magic, &[Line(1)]));
    c.push(file(r, f, Header, n, String::from_utf8_lossy(&good[..header_len]).replace("property float x", "property uchar x"), &[Has("'x'")]));
    c.push(file(r, f, Count, n, ply_binary(false, Some("4000000000"), &POINTS), &[Line(3), Has("4000000000")]));
    c.push(file(r, f, Count, n, ply_binary(false, Some("99999999999999999999999"), &POINTS), &[Line(3)]));
    c.push(file(r, f, Units, n, ply_binary(false, None, &POINTS_MM), &[Has("point 0"), Has("millimetres")]));

    let (f, n) = ("ply binary_big_endian", "scan_be.ply");
    let good = ply_binary(true, None, &POINTS);
    c.push(file(r, f, Truncated, n, minus(&good, 7), &[Line(3), Has("'vertex' element 2")]));
    c.push(file(r, f, Nan, n, ply_binary(true, None, &[[f32::NAN, 1.0, 1.0]]), &[Has("no points")]));
    c.push(file(r, f, Header, n, String::from_utf8_lossy(&good).replacen("binary_big_endian", "binary_middle_endian", 1).into_bytes(), &[Line(2)]));
    c.push(file(r, f, Inf, n, ply_binary(true, None, &[POINTS[0], POINTS[1], [0.0, f32::NEG_INFINITY, 0.0]],), &[Has("vertex 2")]));
    c.push(file(r, f, Count, n, ply_binary(true, Some("18446744073709551615"), &POINTS), &[Line(3)]));
    c.push(file(r, f, Units, n, ply_binary(true, None, &POINTS_MM), &[Has("millimetres")]));

    // --- PCD, ascii, binary and binary_compressed ------------------------------------------
    let (f, n) = ("pcd ascii", "scan.pcd");
    c.push(file(r, f, Empty, n, "", &[Has("empty")]));
    c.push(file(r, f, Truncated, n, "FIELDS x y z\nSIZE 4 4 4\nTYPE F F F\nCOU", &[Line(4), Has("DATA")]));
    c.push(file(r, f, Truncated, n, pcd("3", "ascii", b"1 2 0.5\n-3 0.25 1.5\n2 -1"), &[Line(11)]));
    c.push(file(r, f, Truncated, n, pcd("3", "ascii", b"1 2 0.5\n-3 0.25 1.5\n2 -1 -5e"), &[Line(11)]));
    c.push(file(r, f, Truncated, n, pcd("3", "ascii", b"1 2 0.5\n-3 0.25 1.5\n"), &[Line(10), Has("2 of the 3")]));
    c.push(file(r, f, Nan, n, pcd("3", "ascii", ALL_NAN.as_bytes()), &[Has("no points")]));
    c.push(file(r, f, Inf, n, pcd("3", "ascii", b"1 2 0.5\n-3 inf 1.5\n2 -1 -0.5\n"), &[Line(10)]));
    c.push(file(r, f, Inf, n, pcd("3", "ascii", b"-inf 2 0.5\n-3 0 1.5\n2 -1 -0.5\n"), &[Line(9)]));
    c.push(file(r, f, Header, n, "FIELDS x y\nSIZE 4 4\nTYPE F F\nWIDTH 1\nPOINTS 1\nDATA ascii\n1 2\n", &[Has("'z'")]));
    c.push(file(r, f, Header, n, "FIELDS x y z\nSIZE 4 4 3\nTYPE F F F\nWIDTH 1\nPOINTS 1\nDATA ascii\n1 2 3\n", &[Line(2)]));
    c.push(file(r, f, Header, n, pcd("3", "zip", TEXT_POINTS.as_bytes()), &[Line(8)]));
    c.push(file(r, f, Count, n, pcd("999999999999", "ascii", TEXT_POINTS.as_bytes()), &[Line(7), Has("999999999999")]));
    c.push(file(r, f, Units, n, pcd("3", "ascii", TEXT_POINTS_MM.as_bytes()), &[Has("point 0"), Has("millimetres")]));
    c.push(file(r, f, Columns, n, pcd("3", "ascii", b"1 2 0.5 9\n-3 0.25 1.5\n2 -1 -0.5\n"), &[Line(9)]));

    let (f, n) = ("pcd binary", "scan_bin.pcd");
    let good = pcd("3", "binary", &f32_le(&POINTS));
    c.push(file(r, f, Truncated, n, minus(&good, 5), &[Line(7), Has("point 2 (byte offset")]));
    c.push(file(r, f, Truncated, n, pcd("3", "binary", b""), &[Line(7), Has("point 0 (byte offset")]));
    c.push(file(r, f, Nan, n, pcd("2", "binary", &f32_le(&[[f32::NAN; 3], [0.0, 0.0, f32::NAN]]),), &[Has("no points")]));
    c.push(file(r, f, Inf, n, pcd("3", "binary", &f32_le(&[POINTS[0], [0.0, 0.0, f32::INFINITY], POINTS[2]]),), &[Has("point 1")]));
    c.push(file(r, f, Count, n, pcd("999999999999", "binary", &f32_le(&POINTS)), &[Line(7), Has("999999999999")]));
    c.push(file(r, f, Units, n, pcd("3", "binary", &f32_le(&POINTS_MM)), &[Has("millimetres")]));

    let (f, n) = ("pcd binary_compressed", "scan_lzf.pcd");
    let good = pcd("3", "binary_compressed", &pcd_lzf_block(&POINTS));
    let sizes_at = good.len() - pcd_lzf_block(&POINTS).len();
    c.push(file(r, f, Truncated, n, cut(&good, sizes_at + 5), &[Has("inside the 8 bytes"), Has("truncated")]));
    c.push(file(r, f, Truncated, n, minus(&good, 5), &[Has("byte offset"), Has("truncated")]));
    c.push(file(r, f, Nan, n, pcd("2", "binary_compressed", &pcd_lzf_block(&[[f32::NAN; 3], [0.0, f32::NAN, 0.0]])), &[Has("no points")]));
    c.push(file(r, f, Inf, n, pcd("3", "binary_compressed", &pcd_lzf_block(&[POINTS[0], [0.0, f32::INFINITY, 0.0], POINTS[2]])), &[Has("point 1")]));
    c.push(file(r, f, Count, n, pcd("999999999999", "binary_compressed", &pcd_lzf_block(&POINTS)), &[Line(7), Has("declares 999999999999 points")]));
    c.push(file(r, f, Count, n, pcd("4", "binary_compressed", &pcd_lzf_block(&POINTS)), &[Line(7), Has("unpacks to 36 bytes")]));
    let mut huge = pcd("100000", "binary_compressed", &pcd_lzf_block(&POINTS));
    let at = huge.len() - pcd_lzf_block(&POINTS).len() + 4;
    huge[at..at + 4].copy_from_slice(&1_200_000u32.to_le_bytes());
    c.push(file(r, f, Count, n, huge, &[Has("more than LZF")]));
    let mut damaged = good.clone();
    damaged[sizes_at + 8] = 0xE0; // a back reference before the first byte
    c.push(file(r, f, Header, n, damaged, &[Has("damaged"), Has("byte offset")]));
    c.push(file(r, f, Units, n, pcd("3", "binary_compressed", &pcd_lzf_block(&POINTS_MM)), &[Has("millimetres")]));

    // --- LAS and LAZ -------------------------------------------------------------------------
    let (f, n) = ("las", "scan.las");
    let good = las_file(&POINTS, false);
    let mut magic = good.clone();
    magic[..4].copy_from_slice(b"LAZF");
    let mut scale = good.clone();
    scale[131..139].copy_from_slice(&f64::NAN.to_le_bytes());
    c.push(file(r, f, Empty, n, "", &[Has("empty")]));
    c.push(file(r, f, Truncated, n, cut(&good, 200), &[Has("ends inside the LAS header")]));
    c.push(file(r, f, Truncated, n, minus(&good, 7), &[Has("declares 3 points"), Has("byte offset")]));
    c.push(file(r, f, Header, n, magic, &[Has("'LASF'")]));
    c.push(file(r, f, Count, n, las_count(good.clone(), 4_000_000_000), &[Has("declares 4000000000 points"), Has("holds 3")]));
    c.push(file(r, f, Units, n, las_file(&POINTS_MM, false), &[Has("millimetres")]));
    c.push(file(r, f, Range, n, scale, &[Has("scale factors")]));

    let (f, n) = ("laz", "scan.laz");
    let good = las_file(&POINTS, true);
    let data_start = u32::from_le_bytes(good[96..100].try_into().unwrap()) as usize;
    let table = u64::from_le_bytes(good[data_start..data_start + 8].try_into().unwrap()) as usize;
    let mut chunks = good.clone();
    chunks[table + 4..table + 8].copy_from_slice(&u32::MAX.to_le_bytes());
    c.push(file(r, f, Truncated, n, minus(&good, 9), &[Has("truncated")]));
    c.push(file(r, f, Truncated, n, cut(&good, table + 2), &[Has("past the end of the file")]));
    c.push(file(r, f, Count, n, las_count(good.clone(), 60_000), &[Has("declares 60000 points"), Has("chunk table")]));
    c.push(file(r, f, Count, n, chunks, &[Has("4294967295 chunks"), Has("byte offset")]));
    c.push(file(r, f, Units, n, las_file(&POINTS_MM, true), &[Has("millimetres")]));
    // The LASzip VLR's first item (its data start 54 bytes after the record's user id - 2)
    // declares a size its type does not have.
    let mut items = good.clone();
    let vlr = items.windows(14).position(|w| w == b"laszip encoded").unwrap() - 2 + 54;
    items[vlr + 36..vlr + 38].copy_from_slice(&21u16.to_le_bytes());
    c.push(file(r, f, Header, n, items, &[Has("LASzip VLR's item 0"), Has("21 bytes")]));

    // --- E57 surveys (sdem import) -----------------------------------------------------------
    let (r, f, n) = (Reader::E57, "e57", "survey.e57");
    let good = e57_file(&[&POINTS, &POINTS[..2]]);
    let mut magic = good.clone();
    magic[..8].copy_from_slice(b"ASTM-E58");
    let mut lying_xml = good.clone();
    lying_xml[32..40].copy_from_slice(&(u64::MAX / 2).to_le_bytes());
    let mut damaged = good.clone();
    damaged[700] ^= 0x10;
    c.push(file(r, f, Empty, n, "", &[Has("empty")]));
    c.push(file(r, f, Empty, n, e57_without_scans(), &[Has("no scans")]));
    c.push(file(r, f, Truncated, n, minus(&good, 1024), &[Has("truncated")]));
    c.push(file(r, f, Truncated, n, minus(&good, 100), &[Has("truncated")]));
    c.push(file(r, f, Header, n, magic, &[Has("'ASTM-E57'")]));
    c.push(file(r, f, Header, n, damaged, &[Has("checksum")]));
    c.push(file(r, f, Count, n, lying_xml, &[Has("XML")]));
    c.push(file(r, f, Units, n, e57_file(&[&POINTS, &POINTS_MM]), &[Has("scan 1"), Has("millimetres")]));
    let r = Reader::Points;

    // --- XYZ text -----------------------------------------------------------------------------
    let (f, n) = ("xyz", "scan.xyz");
    c.push(file(r, f, Empty, n, "", &[Has("empty")]));
    c.push(file(r, f, Empty, n, "# only a comment\n\n", &[Has("no points")]));
    c.push(file(r, f, Truncated, n, "1 2 0.5\n-3 0.2", &[Line(2)]));
    c.push(file(r, f, Truncated, n, "1 2 0.5\n-3 0.25 1.5e", &[Line(2)]));
    c.push(file(r, f, Nan, n, "nan 2 0.5\n-3 nan 1.5\n", &[Has("no points")]));
    c.push(file(r, f, Inf, n, "1 2 0.5\n-3 0.25 inf\n", &[Line(2)]));
    c.push(file(r, f, Inf, n, "-inf 2 0.5\n", &[Line(1)]));
    c.push(file(r, f, Header, n, "x y z\n1 2 0.5\n", &[Line(1)]));
    c.push(file(r, f, Units, n, TEXT_POINTS_MM, &[Has("point 0"), Has("millimetres")]));
    c.push(file(r, f, Columns, n, "1 2 0.5\n-3 0.25\n", &[Line(2)]));

    // --- KITTI .bin ---------------------------------------------------------------------------
    let (f, n) = ("kitti bin", "000000.bin");
    let good = kitti_bin(&POINTS);
    c.push(file(r, f, Empty, n, "", &[Has("empty")]));
    c.push(file(r, f, Truncated, n, minus(&good, 5), &[Has("point 2 (byte offset 32)")]));
    c.push(file(r, f, Truncated, n, cut(&good, 22), &[Has("point 1 (byte offset 16)")]));
    c.push(file(r, f, Nan, n, kitti_bin(&[[f32::NAN, 0.0, 0.0], [1.0, 1.0, f32::NAN]]), &[Has("no points")]));
    c.push(file(r, f, Inf, n, kitti_bin(&[POINTS[0], [f32::INFINITY, 0.0, 0.0]]), &[Has("point 1 (byte offset 16)")]));
    c.push(file(r, f, Inf, n, kitti_bin(&[[0.0, f32::NEG_INFINITY, 0.0]]), &[Has("point 0")]));
    c.push(file(r, f, Units, n, kitti_bin(&POINTS_MM), &[Has("point 0"), Has("millimetres")]));

    // --- 3DTK .3d (the scans `sdem import` reads) ---------------------------------------------
    let (f, n) = ("3dtk .3d", "scan000.3d");
    c.push(file(r, f, Empty, n, "", &[Has("empty")]));
    c.push(file(r, f, Empty, n, "360 x 225\n", &[Has("no points")]));
    c.push(file(r, f, Truncated, n, "100 50 200\n10 20", &[Line(2)]));
    c.push(file(r, f, Truncated, n, "100 50 200\n10 20 3e", &[Line(2)]));
    c.push(file(r, f, Nan, n, "NaN 50 200\n10 NaN 30\n", &[Has("no points")]));
    c.push(file(r, f, Inf, n, "100 50 200\n10 20 -inf\n", &[Line(2)]));
    c.push(file(r, f, Header, n, "360 x\n100 50 200\n", &[Line(1)]));
    c.push(file(r, f, Header, n, "100 50 200\n360 x 225\n", &[Line(2)]));
    c.push(file(r, f, Columns, n, "100 50 200\n10 20\n", &[Line(2)]));

    // --- .sweep -------------------------------------------------------------------------------
    let (r, f, n) = (Sweep, ".sweep", "000000.sweep");
    c.push(file(r, f, Empty, n, "", &[Has("empty")]));
    c.push(file(r, f, Truncated, n, "sdem-sweep 1\npan_deg -90 90 3\nlift_sl", &[Line(3)]));
    c.push(file(r, f, Truncated, n, sweep(""), &[Line(4), Has("0 of the 2")]));
    c.push(file(r, f, Truncated, n, sweep("0 0.1 -0.2 10 1.5 nan 2.25\n5 0.1 -0.2 10 1.25"), &[Line(6)]));
    c.push(file(r, f, Truncated, n, sweep("0 0.1 -0.2 10 1.5 nan 2.25\n5 0.1 -0.2 10 1.25 3 0.7"), &[Line(6), Has("line break")]));
    c.push(file(r, f, Nan, n, sweep("0 nan -0.2 10 1.5 nan 2.25\n5 0.1 -0.2 10 1.25 3 0.75\n"), &[Line(5)]));
    c.push(file(r, f, Nan, n, sweep("0 0.1 -0.2 10 1.5 nan 2.25\nnan 0.1 -0.2 10 1.25 3 0.75\n"), &[Line(6)]));
    c.push(file(r, f, Inf, n, sweep("0 0.1 -0.2 10 1.5 nan 2.25\n5 0.1 -0.2 10 1.25 inf 0.75\n"), &[Line(6)]));
    c.push(file(r, f, Inf, n, sweep("0 0.1 -0.2 -inf 1.5 nan 2.25\n5 0.1 -0.2 10 1.25 3 0.75\n"), &[Line(5)]));
    c.push(file(r, f, Header, n, sweep(SWEEP_DATA).replace("sdem-sweep", "sdem-swep"), &[Line(1)]));
    c.push(file(r, f, Header, n, sweep(SWEEP_DATA).replace("sdem-sweep 1", "sdem-sweep 2"), &[Line(1)]));
    c.push(file(r, f, Header, n, sweep(SWEEP_DATA).replace("lines 2\n", ""), &[Line(4)]));
    c.push(file(r, f, Count, n, sweep(SWEEP_DATA).replace("lines 2", "lines 4000000000"), &[Line(4), Has("4000000000")]));
    c.push(file(r, f, Count, n, sweep(SWEEP_DATA).replace("-90 90 3", "-90 90 4000000000"), &[Line(2)]));
    c.push(file(r, f, Range, n, sweep(SWEEP_DATA).replace("-90 90 3", "-90 1e308 3"), &[Line(2), Has("pan angles")]));
    c.push(file(r, f, Range, n, sweep("0 0.1 -0.2 10 1.5 -2 2.25\n5 0.1 -0.2 10 1.25 3 0.75\n"), &[Line(5)]));
    c.push(file(r, f, Units, n, sweep("0 0.1 -0.2 10 1500 nan 2250\n5 0.1 -0.2 10 1250 3000 750\n"), &[Line(5), Has("millimetres")]));
    c.push(file(r, f, Units, n, sweep("0 0.1 -2000 10 1.5 nan 2.25\n5 0.1 -0.2 10 1.25 3 0.75\n"), &[Line(5), Has("degrees")]));
    c.push(file(r, f, Columns, n, sweep("0 0.1 -0.2 10 1.5 nan\n5 0.1 -0.2 10 1.25 3 0.75\n"), &[Line(5)]));

    // --- attitude.csv -------------------------------------------------------------------------
    let (r, f, n) = (Attitude, "attitude.csv", "attitude.csv");
    let h = ATTITUDE_HEADER;
    c.push(file(r, f, Empty, n, "", &[Has("empty")]));
    c.push(file(r, f, Empty, n, h, &[Has("no rows")]));
    c.push(file(r, f, Truncated, n, format!("{h}0,1,2,3\n1,1,"), &[Line(3)]));
    c.push(file(r, f, Truncated, n, format!("{h}0,1,2,3\n1,0.5,-1,9e"), &[Line(3)]));
    c.push(file(r, f, Nan, n, format!("{h}0,1,2,3\n1,0.5,NaN,3\n"), &[Line(3)]));
    c.push(file(r, f, Inf, n, format!("{h}0,inf,2,3\n"), &[Line(2)]));
    c.push(file(r, f, Inf, n, format!("{h}0,1,2,-inf\n"), &[Line(2)]));
    c.push(file(r, f, Header, n, "index,roll,pitch,yaw\n0,1,2,3\n", &[Line(1)]));
    c.push(file(r, f, Header, n, "0,1,2,3\n1,1,2,3\n", &[Line(1)]));
    c.push(file(r, f, Count, n, format!("{h}4000000000,1,2,3\n"), &[Line(2)]));
    c.push(file(r, f, Units, n, format!("{h}0,1,2,3\n1,4500,-120,9000\n"), &[Line(3), Has("roll")]));
    c.push(file(r, f, Units, n, format!("{h}0,1,-720.5,3\n"), &[Line(2), Has("pitch")]));
    c.push(file(r, f, Columns, n, format!("{h}0,1,2,3\n1,1,2\n"), &[Line(3)]));
    c.push(file(r, f, Columns, n, format!("{h}0,1,2,3,4\n"), &[Line(2)]));

    // --- KITTI poses --------------------------------------------------------------------------
    let (r, f, n) = (KittiPoses, "kitti poses", "poses.txt");
    let id = KITTI_IDENTITY;
    c.push(file(r, f, Empty, n, "", &[Has("no poses")]));
    c.push(file(r, f, Truncated, n, format!("{id}1 0 0 0.5 0 1 0"), &[Line(2)]));
    c.push(file(r, f, Truncated, n, format!("{id}1 0 0 0.5 0 1 0 0 0 0 1 1e"), &[Line(2)]));
    c.push(file(r, f, Nan, n, format!("{id}1 0 0 nan 0 1 0 0 0 0 1 0\n"), &[Line(2)]));
    c.push(file(r, f, Inf, n, format!("{id}1 0 0 0 0 1 0 0 0 0 1 -inf\n"), &[Line(2)]));
    c.push(file(r, f, Header, n, format!("# x y z\n{id}"), &[Line(1)]));
    c.push(file(r, f, Rotation, n, format!("{id}2 0 0 0 0 1 0 0 0 0 1 0\n"), &[Line(2), Has("rotation")]));
    c.push(file(r, f, Rotation, n, format!("{id}-1 0 0 0 0 1 0 0 0 0 1 0\n"), &[Line(2)]));
    c.push(file(r, f, Rotation, n, format!("{id}1 0.2 0 0 0 1 0 0 0 0 1 0\n"), &[Line(2)]));
    c.push(file(r, f, Rotation, n, format!("{id}0 -90 0 0 90 0 0 0 0 0 1 0\n"), &[Line(2)]));
    c.push(file(r, f, Columns, n, format!("{id}1 0 0 0 0 1 0 0 0 0 1 0 0\n"), &[Line(2)]));

    // --- TUM poses ----------------------------------------------------------------------------
    let (r, f, n) = (TumPoses, "tum poses", "poses.tum");
    let ok = TUM_IDENTITY;
    c.push(file(r, f, Empty, n, "", &[Has("no poses")]));
    c.push(file(r, f, Truncated, n, format!("{ok}1 1 2 3 0 0"), &[Line(2)]));
    c.push(file(r, f, Nan, n, format!("{ok}1 nan 2 3 0 0 0 1\n"), &[Line(2)]));
    c.push(file(r, f, Inf, n, format!("{ok}1 1 2 3 0 0 inf 1\n"), &[Line(2)]));
    c.push(file(r, f, Header, n, format!("timestamp tx ty tz qx qy qz qw\n{ok}"), &[Line(1)]));
    c.push(file(r, f, Rotation, n, format!("{ok}1 1 2 3 0 0 0 0\n"), &[Line(2), Has("norm")]));
    c.push(file(r, f, Rotation, n, format!("{ok}1 1 2 3 0.5 0.5 0.5 0.6\n"), &[Line(2)]));
    c.push(file(r, f, Columns, n, format!("{ok}1 1 2 3 0 0 0 1 9\n"), &[Line(2)]));

    // --- 3DTK .pose, slam6D .frames, KITTI calib.txt (read by `sdem import`) -----------------
    let (r, f, n) = (UosPose, "3dtk .pose", "scan000.pose");
    c.push(file(r, f, Empty, n, "", &[Has("0 line")]));
    c.push(file(r, f, Truncated, n, "10 20 300\n", &[Has("1 line")]));
    c.push(file(r, f, Truncated, n, "10 20 300\n0 45", &[Line(2)]));
    c.push(file(r, f, Nan, n, "10 20 300\n0 nan 0\n", &[Line(2)]));
    c.push(file(r, f, Inf, n, "10 inf 300\n0 45 0\n", &[Line(1)]));
    c.push(file(r, f, Columns, n, "10 20 300 1\n0 45 0\n", &[Line(1)]));
    c.push(file(r, f, Columns, n, "10 20 300\n0 45 0\n1 1 1\n", &[Line(3)]));

    let (r, f, n) = (UosFrames, "slam6d .frames", "scan000.frames");
    let fr = FRAMES_IDENTITY;
    c.push(file(r, f, Empty, n, "", &[Has("no frames")]));
    c.push(file(r, f, Truncated, n, format!("{fr}1 0 0 0 0 1 0"), &[Line(2)]));
    c.push(file(r, f, Nan, n, format!("{fr}1 0 0 0 0 1 0 0 0 0 1 0 nan 0 0 1 2\n"), &[Line(2)]));
    c.push(file(r, f, Inf, n, format!("{fr}1 0 0 0 0 1 0 0 0 0 1 0 0 inf 0 1 2\n"), &[Line(2)]));
    c.push(file(r, f, Rotation, n, format!("{fr}2 0 0 0 0 1 0 0 0 0 1 0 0 0 0 1 2\n"), &[Line(2)]));
    c.push(file(r, f, Rotation, n, format!("{fr}1 0 0 5 0 1 0 0 0 0 1 0 0 0 0 1 2\n"), &[Line(2), Has("bottom row")]));
    c.push(file(r, f, Columns, n, format!("{fr}1 0 0 0 0 1 0 0 0 0 1 0 0 0 0 1 2 3\n"), &[Line(2)]));

    let (r, f, n) = (KittiCalib, "kitti calib.txt", "calib.txt");
    c.push(file(r, f, Empty, n, "", &[Has("no 'Tr:'")]));
    c.push(file(r, f, Truncated, n, minus(CALIB.as_bytes(), 6), &[Line(2)]));
    c.push(file(r, f, Nan, n, CALIB.replace("0.1", "nan"), &[Line(2)]));
    c.push(file(r, f, Inf, n, CALIB.replace("-0.3", "-inf"), &[Line(2)]));
    c.push(file(r, f, Header, n, CALIB.replace("Tr:", "Tr_cam:"), &[Has("no 'Tr:'")]));
    c.push(file(r, f, Rotation, n, CALIB.replace("Tr: 0 -1 0", "Tr: 0 -2 0"), &[Line(2)]));
    c.push(file(r, f, Columns, n, CALIB.replace("-0.3", "-0.3 1"), &[Line(2)]));

    // --- sensor.toml --------------------------------------------------------------------------
    let (r, f, n) = (SensorToml, "sensor.toml", "sensor.toml");
    c.push(file(r, f, Empty, n, "", &[Has("empty")]));
    c.push(file(r, f, Empty, n, "\n  \n", &[Has("empty")]));
    c.push(file(r, f, Truncated, n, "tilt_min_deg = -45.0\nmax_range_m = ", &[Line(2)]));
    c.push(file(r, f, Truncated, n, "tilt_min_deg = -45.0\nmax_ran", &[Line(2)]));
    c.push(file(r, f, Truncated, n, "[lift]\nlink_length_m = 0.4\nslide_max_m = 1e", &[Line(3)]));
    c.push(file(r, f, Nan, n, "tilt_min_deg = -45.0\nmin_range_m = nan\n", &[Line(2), Has("min_range_m")]));
    c.push(file(r, f, Inf, n, "max_range_m = inf\n", &[Line(1), Has("max_range_m")]));
    c.push(file(r, f, Inf, n, "pan_step_deg = 1.0\ntilt_min_deg = -inf\n", &[Line(2)]));
    c.push(file(r, f, Header, n, "[sensor]\nmax_range_m = 8.0\n", &[Line(1)]));
    c.push(file(r, f, Header, n, "max_range_m = 8.0\n[lift\n", &[Line(2)]));
    c.push(file(r, f, Columns, n, "max_range_m = \"far\"\n", &[Line(1)]));
    c.push(file(r, f, Columns, n, "max_range_m = 8.0\nmax_rnage_m = 9.0\n", &[Line(2)]));
    c.push(file(r, f, Range, n, "tilt_step_deg = 1.0\npan_max_deg = 200.0\n", &[Line(2), Has("pan_max_deg")]));
    c.push(file(r, f, Range, n, "[lift]\nlink_length_m = -0.4\n", &[Line(2)]));

    // --- the configuration of `sdem slam --config` (an empty file is all defaults) -------------
    let (r, f, n) = (SlamOptions, "slam config.toml", "config.toml");
    c.push(file(r, f, Truncated, n, "heading_half_deg = 3.0\n[localize]\nstep_m = ", &[Line(3)]));
    c.push(file(r, f, Truncated, n, "heading_half_deg = 3.0\n[locali", &[Line(2)]));
    c.push(file(r, f, Nan, n, "reference_radius_m = 4.0\nheading_half_deg = nan\n", &[Line(2), Has("heading_half_deg")]));
    c.push(file(r, f, Inf, n, "[voxel]\nvoxel_m = inf\n", &[Line(2), Has("voxel_m")]));
    c.push(file(r, f, Header, n, "[slam]\nheading_half_deg = 3.0\n", &[Line(1)]));
    c.push(file(r, f, Columns, n, "heading_half_deg = \"wide\"\n", &[Line(1)]));
    c.push(file(r, f, Columns, n, "heading_half_deg = 3.0\nheading_hlaf_deg = 4.0\n", &[Line(2)]));
    c.push(file(r, f, Range, n, "max_reference_nodes = 3\nheading_half_deg = 720.0\n", &[Line(2)]));

    // --- .sdemvox voxel maps ------------------------------------------------------------------
    let (r, f, n) = (VoxelMap, ".sdemvox", "map.sdemvox");
    let good = voxel_bytes();
    let set = |at: usize, value: &[u8]| {
        let mut bytes = good.clone();
        bytes[at..at + value.len()].copy_from_slice(value);
        bytes
    };
    c.push(file(r, f, Empty, n, "", &[Has("truncated: 0 bytes")]));
    c.push(file(r, f, Truncated, n, cut(&good, 5), &[Has("truncated: 5 bytes")]));
    c.push(file(r, f, Truncated, n, cut(&good, 30), &[Has("truncated: 30 bytes")]));
    c.push(file(r, f, Truncated, n, cut(&good, 68 + 20), &[Has("declares"), Has("88 bytes")]));
    c.push(file(r, f, Truncated, n, minus(&good, 1), &[Has("declares")]));
    c.push(file(r, f, Nan, n, resealed(set(68 + 12, &f32::NAN.to_le_bytes())), &[Has("record 0 (byte offset 68)")]));
    c.push(file(r, f, Nan, n, resealed(set(12, &f64::NAN.to_le_bytes())), &[Has("voxel_m")]));
    c.push(file(r, f, Inf, n, resealed(set(68 + 16 + 12, &f32::INFINITY.to_le_bytes())), &[Has("record 1 (byte offset 84)")]));
    c.push(file(r, f, Header, n, set(0, b"sdem-vax"), &[Has("does not start with")]));
    c.push(file(r, f, Header, n, set(8, &7u32.to_le_bytes()), &[Has("version 7")]));
    c.push(file(r, f, Count, n, set(60, &u64::MAX.to_le_bytes()), &[Has("declares 18446744073709551615")]));
    c.push(file(r, f, Count, n, set(60, &(1u64 << 40).to_le_bytes()), &[Has("declares 1099511627776")]));

    // --- saved map folders (map.json + nodes/NNNNNN.pts) --------------------------------------
    let (r, f) = (Map, "saved map");
    c.push(folder(
        r,
        f,
        Empty,
        "map.json",
        |root| {
            save_small_map(root);
            std::fs::write(root.join("map.json"), "").unwrap();
        },
        &[Line(1)],
    ));
    c.push(folder(
        r,
        f,
        Empty,
        "000002.pts",
        |root| {
            save_small_map(root);
            std::fs::write(root.join("nodes/000002.pts"), "").unwrap();
        },
        &[Has("truncated: 0 bytes")],
    ));
    c.push(folder(
        r,
        f,
        Truncated,
        "map.json",
        |root| {
            save_small_map(root);
            let text = std::fs::read(root.join("map.json")).unwrap();
            std::fs::write(root.join("map.json"), &text[..text.len() / 2]).unwrap();
        },
        &[SomeLine],
    ));
    c.push(folder(
        r,
        f,
        Truncated,
        "000001.pts",
        |root| {
            save_small_map(root);
            let bytes = std::fs::read(root.join("nodes/000001.pts")).unwrap();
            std::fs::write(root.join("nodes/000001.pts"), &bytes[..bytes.len() - 7]).unwrap();
        },
        &[Has("declares 8 points")],
    ));
    c.push(folder(
        r,
        f,
        Truncated,
        "000001.pts",
        |root| {
            save_small_map(root);
            let bytes = std::fs::read(root.join("nodes/000001.pts")).unwrap();
            std::fs::write(root.join("nodes/000001.pts"), &bytes[..10]).unwrap();
        },
        &[Has("truncated: 10 bytes")],
    ));
    c.push(folder(
        r,
        f,
        Nan,
        "000001.pts",
        |root| {
            save_small_map(root);
            edit_node_file(root, |b| {
                b[20 + 12 * 3 + 4..20 + 12 * 3 + 8].copy_from_slice(&f32::NAN.to_le_bytes())
            });
        },
        &[Has("point 3 (byte offset 56)")],
    ));
    c.push(folder(
        r,
        f,
        Nan,
        "map.json",
        |root| {
            save_small_map(root);
            let text = std::fs::read_to_string(root.join("map.json")).unwrap();
            std::fs::write(root.join("map.json"), text.replacen("0.5,", "NaN,", 1)).unwrap();
        },
        &[SomeLine],
    ));
    c.push(folder(
        r,
        f,
        Inf,
        "000001.pts",
        |root| {
            save_small_map(root);
            edit_node_file(root, |b| {
                b[20..24].copy_from_slice(&f32::NEG_INFINITY.to_le_bytes())
            });
        },
        &[Has("point 0 (byte offset 20)")],
    ));
    c.push(folder(
        r,
        f,
        Inf,
        "map.json",
        |root| {
            save_small_map(root);
            // JSON has no infinity: a number too large for f64 is the nearest thing.
            edit_manifest(root, |m| {
                m["body"]["edges"][0]["information"][2][2] = 123456.75.into()
            });
            let text = std::fs::read_to_string(root.join("map.json")).unwrap();
            assert!(text.contains("123456.75"));
            std::fs::write(
                root.join("map.json"),
                text.replacen("123456.75", "1e400", 1),
            )
            .unwrap();
        },
        &[SomeLine],
    ));
    c.push(folder(
        r,
        f,
        Header,
        "map.json",
        |root| {
            save_small_map(root);
            let text = std::fs::read_to_string(root.join("map.json")).unwrap();
            std::fs::write(
                root.join("map.json"),
                text.replacen("sdem-map", "sdem-mop", 1),
            )
            .unwrap();
        },
        &[Has("format")],
    ));
    c.push(folder(
        r,
        f,
        Header,
        "map.json",
        |root| {
            save_small_map(root);
            let text = std::fs::read_to_string(root.join("map.json")).unwrap();
            std::fs::write(
                root.join("map.json"),
                text.replacen("\"version\": 1", "\"version\": 0", 1),
            )
            .unwrap();
        },
        &[Has("version 0")],
    ));
    c.push(folder(
        r,
        f,
        Header,
        "000001.pts",
        |root| {
            save_small_map(root);
            edit_node_file(root, |b| b[..8].copy_from_slice(b"SDEMPTS9"));
        },
        &[Has("not an sdem node file")],
    ));
    c.push(folder(
        r,
        f,
        Header,
        "map.json",
        |root| {
            save_small_map(root);
            std::fs::remove_file(root.join("map.json")).unwrap();
        },
        &[Has("not a saved map")],
    ));
    c.push(folder(
        r,
        f,
        Count,
        "000001.pts",
        |root| {
            save_small_map(root);
            edit_node_file(root, |b| b[12..20].copy_from_slice(&u64::MAX.to_le_bytes()));
        },
        &[Has("declares 18446744073709551615 points")],
    ));
    c.push(folder(
        r,
        f,
        Count,
        "000001.pts",
        |root| {
            save_small_map(root);
            edit_manifest(root, |m| m["body"]["nodes"][1]["points"] = 999_999.into());
        },
        &[Has("the map says 999999")],
    ));
    c.push(folder(
        r,
        f,
        Rotation,
        "map.json",
        |root| {
            save_small_map(root);
            edit_manifest(root, |m| {
                m["body"]["nodes"][1]["world_from_sensor"][0] = 2.0.into()
            });
        },
        &[Has("node 1")],
    ));
    c.push(folder(
        r,
        f,
        Rotation,
        "map.json",
        |root| {
            save_small_map(root);
            edit_manifest(root, |m| {
                m["body"]["loop_closures"][0]["from_from_to"][5] = (-3.0).into()
            });
        },
        &[Has("loop closure 0")],
    ));
    c.push(folder(
        r,
        f,
        Columns,
        "map.json",
        |root| {
            save_small_map(root);
            edit_manifest(root, |m| {
                m["body"]["nodes"][0]["world_from_sensor"]
                    .as_array_mut()
                    .unwrap()
                    .pop();
            });
        },
        &[SomeLine, Has("malformed map body")],
    ));

    // --- dataset folders ----------------------------------------------------------------------
    let (r, f) = (Dataset, "dataset folder");
    let h = ATTITUDE_HEADER;
    c.push(folder(
        r,
        f,
        Empty,
        "attitude.csv",
        dataset_with("attitude.csv", ""),
        &[Has("empty")],
    ));
    c.push(folder(
        r,
        f,
        Empty,
        "sensor.toml",
        dataset_with("sensor.toml", ""),
        &[Has("empty")],
    ));
    c.push(folder(
        r,
        f,
        Empty,
        "000001.xyz",
        dataset_with("scans/000001.xyz", ""),
        &[Has("empty")],
    ));
    c.push(folder(
        r,
        f,
        Truncated,
        "odometry.txt",
        dataset_with("odometry.txt", KITTI_IDENTITY),
        &[Has("1 poses"), Has("2 scans")],
    ));
    c.push(folder(
        r,
        f,
        Truncated,
        "attitude.csv",
        move |root: &Path| {
            write_dataset(root);
            std::fs::write(
                root.join("attitude.csv"),
                format!("{h}0,0.5,-1,10\n1,0.25,"),
            )
            .unwrap();
        },
        &[Line(3)],
    ));
    c.push(folder(
        r,
        f,
        Nan,
        "attitude.csv",
        move |root: &Path| {
            write_dataset(root);
            std::fs::write(
                root.join("attitude.csv"),
                format!("{h}0,0.5,-1,10\n1,nan,-1,12\n"),
            )
            .unwrap();
        },
        &[Line(3)],
    ));
    c.push(folder(
        r,
        f,
        Nan,
        "000001.xyz",
        dataset_with("scans/000001.xyz", "nan 2 0.5\nnan 0 1\n"),
        &[Has("no points")],
    ));
    c.push(folder(
        r,
        f,
        Nan,
        "sensor.toml",
        dataset_with("sensor.toml", "max_range_m = nan\n"),
        &[Line(1)],
    ));
    c.push(folder(
        r,
        f,
        Inf,
        "poses_truth.txt",
        dataset_with(
            "poses_truth.txt",
            "1 0 0 0 0 1 0 0 0 0 1 0\n1 0 0 inf 0 1 0 0 0 0 1 0\n",
        ),
        &[Line(2)],
    ));
    c.push(folder(
        r,
        f,
        Header,
        "scans",
        |root: &Path| {
            write_dataset(root);
            std::fs::remove_dir_all(root.join("scans")).unwrap();
        },
        &[Has("has no scans/ folder")],
    ));
    c.push(folder(
        r,
        f,
        Header,
        "000000.sweep",
        |root: &Path| {
            write_dataset(root);
            std::fs::create_dir_all(root.join("sweeps")).unwrap();
            std::fs::write(root.join("sweeps/000000.sweep"), "sdem-sweep 3\n").unwrap();
        },
        &[Line(1)],
    ));
    c.push(folder(
        r,
        f,
        Count,
        "attitude.csv",
        move |root: &Path| {
            write_dataset(root);
            std::fs::write(
                root.join("attitude.csv"),
                format!("{h}0,0,0,0\n1,0,0,0\n2,0,0,0\n"),
            )
            .unwrap();
        },
        &[Has("3 rows"), Has("2 scans")],
    ));
    c.push(folder(
        r,
        f,
        Units,
        "000000.xyz",
        dataset_with("scans/000000.xyz", TEXT_POINTS_MM),
        &[Has("millimetres")],
    ));
    c.push(folder(
        r,
        f,
        Rotation,
        "odometry.txt",
        dataset_with(
            "odometry.txt",
            "1 0 0 0 0 1 0 0 0 0 1 0\n1 0 0 0 0 1 0 0 0 0 -1 0\n",
        ),
        &[Line(2)],
    ));
    c.push(folder(
        r,
        f,
        Columns,
        "poses_truth.txt",
        dataset_with(
            "poses_truth.txt",
            "1 0 0 0 0 1 0 0 0 0 1\n1 0 0 0 0 1 0 0 0 0 1 0\n",
        ),
        &[Line(1)],
    ));
    c
}

// ---------------------------------------------------------------------------------------------
// The tests
// ---------------------------------------------------------------------------------------------

/// Every row of the table: an error (no panic, no value), one line, naming the file and place.
#[test]
fn every_malformed_input_is_a_clear_error() {
    let cases = cases();
    let mut failures = Vec::new();
    let mut counts: BTreeMap<(Reader, &str), BTreeMap<Kind, usize>> = BTreeMap::new();
    for (i, case) in cases.iter().enumerate() {
        *counts
            .entry((case.reader, case.format))
            .or_default()
            .entry(case.kind)
            .or_default() += 1;
        if let Err(why) = run(case) {
            failures.push(format!(
                "#{i} {} / {:?} ({}): {why}",
                case.format, case.kind, case.name
            ));
        }
    }
    // The summary the README quotes (`cargo test -p sdem-io --test bad_input -- --nocapture`).
    let kinds: usize = counts.values().map(BTreeMap::len).sum();
    println!(
        "{} cases over {} reader × format pairs and {kinds} reader × kind pairs:",
        cases.len(),
        counts.len()
    );
    for ((_, format), by_kind) in &counts {
        let list: Vec<String> = by_kind.iter().map(|(k, n)| format!("{k:?} {n}")).collect();
        println!("  {format:<26} {}", list.join(", "));
    }
    assert!(
        failures.is_empty(),
        "{} of {} malformed inputs were not reported clearly:\n{}",
        failures.len(),
        cases.len(),
        failures.join("\n")
    );
}

/// The table starts from valid files: each reader reads its valid input, so that every row's
/// error comes from what the row changed.
#[test]
fn the_valid_inputs_the_table_starts_from_are_read() {
    let dir = tempfile::tempdir().unwrap();
    let files: Vec<(Reader, &str, Vec<u8>)> = vec![
        (Reader::Points, "a.ply", ply_ascii("3", TEXT_POINTS)),
        (Reader::Points, "b.ply", ply_binary(false, None, &POINTS)),
        (Reader::Points, "c.ply", ply_binary(true, None, &POINTS)),
        (
            Reader::Points,
            "a.pcd",
            pcd("3", "ascii", TEXT_POINTS.as_bytes()),
        ),
        (
            Reader::Points,
            "b.pcd",
            pcd("3", "binary", &f32_le(&POINTS)),
        ),
        (Reader::E57, "a.e57", e57_file(&[&POINTS, &POINTS[..1]])),
        (Reader::Points, "a.las", las_file(&POINTS, false)),
        (Reader::Points, "a.laz", las_file(&POINTS, true)),
        (
            Reader::Points,
            "c.pcd",
            pcd("3", "binary_compressed", &pcd_lzf_block(&POINTS)),
        ),
        (Reader::Points, "a.xyz", TEXT_POINTS.into()),
        (Reader::Points, "a.bin", kitti_bin(&POINTS)),
        (Reader::Points, "a.3d", b"360 x 225\n100 50 200\n".to_vec()),
        (Reader::Sweep, "a.sweep", sweep(SWEEP_DATA).into_bytes()),
        (
            Reader::Attitude,
            "attitude.csv",
            format!("{ATTITUDE_HEADER}0,1,2,3\n1,0.5,-1,359\n").into_bytes(),
        ),
        (
            Reader::KittiPoses,
            "p.txt",
            format!("{KITTI_IDENTITY}0 -1 0 0.5 1 0 0 0 0 0 1 0\n").into_bytes(),
        ),
        (Reader::TumPoses, "p.tum", TUM_IDENTITY.into()),
        (Reader::UosPose, "s.pose", b"10 20 300\n0 45 0\n".to_vec()),
        (Reader::UosFrames, "s.frames", FRAMES_IDENTITY.into()),
        (Reader::KittiCalib, "calib.txt", CALIB.into()),
        (
            Reader::SensorToml,
            "sensor.toml",
            b"tilt_min_deg = -45.0\nmax_range_m = 8.0\n[lift]\nlink_length_m = 0.4\n".to_vec(),
        ),
        (Reader::VoxelMap, "m.sdemvox", voxel_bytes()),
        (Reader::SlamOptions, "empty.toml", Vec::new()),
        (
            Reader::SlamOptions,
            "config.toml",
            toml::to_string_pretty(&SlamOptions::default())
                .unwrap()
                .into_bytes(),
        ),
    ];
    for (reader, name, bytes) in files {
        let path = dir.path().join(name);
        std::fs::write(&path, bytes).unwrap();
        read(reader, &path).unwrap_or_else(|e| panic!("{name}: {e}"));
    }
    let map = dir.path().join("map");
    save_small_map(&map);
    // The forger's edit with nothing changed keeps the map valid: the edits below test only
    // what they change.
    edit_manifest(&map, |_| {});
    edit_node_file(&map, |_| {});
    let saved = sdem_io::load_map(&map).unwrap();
    assert_eq!(saved.map.nodes.len(), 3);
    assert_eq!(saved.loop_closures.len(), 1);
    let data = dir.path().join("data");
    write_dataset(&data);
    read(Reader::Dataset, &data).unwrap();
}

/// NaN is "no return" in the formats that say so: such points (ranges) are skipped, the rest is
/// read, and nothing non-finite comes back.
#[test]
fn nan_means_no_return_where_the_format_says_so() {
    let dir = tempfile::tempdir().unwrap();
    let with_nan = [[f32::NAN, 0.0, 0.0], POINTS[0], [0.0, f32::NAN, 1.0]];
    for (name, bytes) in [
        ("a.ply", ply_ascii("3", "nan 0 0\n1 2 0.5\n0 nan 1\n")),
        ("b.ply", ply_binary(false, None, &with_nan)),
        ("c.ply", ply_binary(true, None, &with_nan)),
        ("a.pcd", pcd("3", "ascii", b"nan 0 0\n1 2 0.5\n0 nan 1\n")),
        ("b.pcd", pcd("3", "binary", &f32_le(&with_nan))),
        ("a.bin", kitti_bin(&with_nan)),
    ] {
        let path = dir.path().join(name);
        std::fs::write(&path, bytes).unwrap();
        let points = sdem_io::read_points(&path).unwrap_or_else(|e| panic!("{name}: {e}"));
        assert_eq!(points, vec![Vec3::new(1.0, 2.0, 0.5)], "{name}");
    }
    let path = dir.path().join("a.sweep");
    std::fs::write(&path, sweep(SWEEP_DATA)).unwrap();
    let read = sdem_io::read_sweep(&path).unwrap();
    assert!(read.lines[0].ranges[1].is_nan());
    let points = sdem_io::read_points(&path).unwrap();
    assert_eq!(points.len(), 5);
    assert!(points.iter().all(|p| p.iter().all(|v| v.is_finite())));
}

/// The unit checks reject only what cannot be metres: a scan of a large hall or a street (median
/// range tens of metres, a few points kilometres away) is read, as are attitudes up to a full
/// turn and an unwrapped yaw.
#[test]
fn unit_checks_accept_real_extremes() {
    let dir = tempfile::tempdir().unwrap();
    let mut text = String::new();
    for i in 0..100 {
        text.push_str(&format!("{} 0.5 -1\n", 5.0 + i as f64 * 0.8));
    }
    text.push_str("2500 10 3\n-4000 0 0\n9000 1 1\n");
    let path = dir.path().join("street.xyz");
    std::fs::write(&path, &text).unwrap();
    assert_eq!(sdem_io::read_points(&path).unwrap().len(), 103);

    let path = dir.path().join("attitude.csv");
    std::fs::write(
        &path,
        format!("{ATTITUDE_HEADER}0,-180,89.9,725\n1,360,-360,-3000\n"),
    )
    .unwrap();
    assert_eq!(sdem_io::read_attitude_csv(&path).unwrap().len(), 2);
    // Writers refuse what the readers refuse, so sdem never writes such a file.
    let err = sdem_io::write_attitude_csv(&path, &[Attitude::from_degrees(400.0, 0.0, 0.0)]);
    assert!(matches!(err, Err(sdem_io::Error::Invalid(_))), "{err:?}");
}
