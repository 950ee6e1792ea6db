//! The real LiDAR pairs of `sdem bench --suite lidar`: KITTI odometry frames
//! (`velodyne/NNNNNN.bin`, `poses.txt`, `calib.txt`), consecutive frames i → i+1 and, harder,
//! i → i+2, with the truth from KITTI's poses turned into Velodyne poses by `calib.txt`'s `Tr`.

use anyhow::{bail, Context, Result};
use sdem::geometry::{Pose, Vec3};
use std::path::{Path, PathBuf};

/// The default KITTI folder: `../shared/data/kitti-00-first16` beside the repository.
pub(crate) fn default_folder() -> PathBuf {
    Path::new(env!("CARGO_MANIFEST_DIR")).join("../../../shared/data/kitti-00-first16")
}

/// A KITTI sequence's frames with their Velodyne poses.
pub(crate) struct Kitti {
    /// The folder read.
    pub folder: PathBuf,
    /// The frames' numbers (`NNNNNN` of their file names), ascending and consecutive.
    pub numbers: Vec<usize>,
    /// Each frame's points, Velodyne frame, metres (no-return NaNs dropped).
    pub frames: Vec<Vec<Vec3>>,
    /// Each frame's `world_from_velodyne`, re-based on the first.
    pub world_from_velodyne: Vec<Pose>,
}

/// One pair: indices into [`Kitti::frames`] (reference, query).
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
pub(crate) struct KittiPair {
    pub reference: usize,
    pub query: usize,
}

impl Kitti {
    /// Reads `folder`: every `velodyne/NNNNNN.bin`, `poses.txt` and `calib.txt`.
    ///
    /// # Errors
    /// A missing file or folder (naming it), fewer than 2 frames, frames that are not
    /// consecutive, fewer poses than a frame needs, or a malformed file.
    pub(crate) fn read(folder: &Path) -> Result<Self> {
        let velodyne = folder.join("velodyne");
        let poses_path = folder.join("poses.txt");
        let calib_path = folder.join("calib.txt");
        for (path, what) in [
            (&velodyne, "the folder velodyne/ of NNNNNN.bin frames"),
            (&poses_path, "poses.txt, the truth (KITTI's camera poses)"),
            (
                &calib_path,
                "calib.txt, whose Tr turns camera poses into Velodyne poses",
            ),
        ] {
            if !path.exists() {
                bail!(
                    "--kitti {}: {} is missing; a KITTI odometry sequence holds {what}",
                    folder.display(),
                    path.display()
                );
            }
        }
        let mut numbered: Vec<(usize, PathBuf)> = std::fs::read_dir(&velodyne)
            .with_context(|| format!("cannot list {}", velodyne.display()))?
            .filter_map(|entry| entry.ok().map(|e| e.path()))
            .filter(|p| p.extension().is_some_and(|e| e == "bin"))
            .filter_map(|p| {
                let number = p.file_stem()?.to_str()?.parse().ok()?;
                Some((number, p))
            })
            .collect();
        numbered.sort();
        if numbered.len() < 2 {
            bail!(
                "--kitti {}: {} holds {} NNNNNN.bin frame(s); the pairs need at least 2",
                folder.display(),
                velodyne.display(),
                numbered.len()
            );
        }
        if numbered.windows(2).any(|w| w[1].0 != w[0].0 + 1) {
            bail!(
                "--kitti {}: the frames in {} are not consecutive",
                folder.display(),
                velodyne.display()
            );
        }
        let tr = sdem_io::read_kitti_calib_tr(&calib_path)?;
        let camera = sdem_io::read_kitti_poses(&poses_path)?;
        let mut selected = Vec::with_capacity(numbered.len());
        for (number, path) in &numbered {
            let pose = camera.get(*number).with_context(|| {
                format!(
                    "{} has {} poses; {} needs pose {number}",
                    poses_path.display(),
                    camera.len(),
                    path.display()
                )
            })?;
            selected.push(*pose);
        }
        let mut frames = Vec::with_capacity(numbered.len());
        for (_, path) in &numbered {
            let points = sdem_io::read_points(path)?;
            frames.push(
                points
                    .into_iter()
                    .filter(|p| p.iter().all(|v| v.is_finite()))
                    .collect(),
            );
        }
        Ok(Self {
            folder: folder.to_path_buf(),
            numbers: numbered.iter().map(|(n, _)| *n).collect(),
            frames,
            world_from_velodyne: sdem_io::kitti_velodyne_poses(&selected, &tr),
        })
    }

    /// The pairs i → i+1 and i → i+2, interleaved by `i` (so a prefix holds both kinds).
    pub(crate) fn pairs(&self) -> Vec<KittiPair> {
        let n = self.frames.len();
        let mut pairs = Vec::new();
        for i in 0..n {
            for gap in [1, 2] {
                if i + gap < n {
                    pairs.push(KittiPair {
                        reference: i,
                        query: i + gap,
                    });
                }
            }
        }
        pairs
    }

    /// True `reference_from_query` of `pair`.
    pub(crate) fn truth(&self, pair: KittiPair) -> Pose {
        self.world_from_velodyne[pair.reference].inverse() * self.world_from_velodyne[pair.query]
    }
}
