//! `sdem.Slam` (the incremental loop) with its `sdem.Step`s, and `sdem.Map` (a saved map to
//! relocalize in) with its `sdem.Relocalization`.

use crate::arrays::{matrices4, matrix4, matrix6, numbers, points_array, points_from, pose_from};
use crate::errors::{invalid, invalid_input, io_error, sdem_error};
use crate::localize::{attitude_from, doubt_list};
use crate::options::{to_json, to_python, with_overrides};
use nalgebra::Matrix6;
use numpy::PyArray2;
use pyo3::prelude::*;
use pyo3::types::{PyDict, PyList};
use sdem::geometry::Vec3;
use sdem::slam::Near;
use sdem::{Doubt as RustDoubt, Pose, SlamOptions};
use sdem_io::{NodeFiles, SavedMap, MAP_MANIFEST};
use serde_json::Value;
use std::path::PathBuf;

/// The incremental stop-and-go loop (Nagatani et al. 2003, Sec. III, with loop closure): add
/// one stop's scan at a time; each is localized against the map, becomes a node, closes loops
/// and updates the fused map.
///
/// Args:
///     progress: an optional callable, called with each ``sdem.Step`` as ``add`` finishes it
///         (for a progress display or a log; sdem itself prints nothing). An exception it raises
///         comes out of ``add``, after the scan was added.
///     **options: ``SlamOptions`` fields, name for name, each defaulting to the library's
///         value (``sdem.slam_options()`` lists them all; a dict for a nested struct changes
///         only the fields it names): ``sdem`` (the S-DEM grid), ``localize`` (the search; the
///         window and heading are set per scan from the fields below; 2 cm steps, no runner-up
///         search), ``window_half_m`` ([0.15, 0.15, 0.08]: around an odometry prediction),
///         ``window_half_no_odometry_m`` ([0.5, 0.5, 0.15]), ``prior_sigma_m`` (0.05),
///         ``odometry_error_per_m`` (0.15: the odometry's σ and window grow with the distance
///         it measured), ``prior_sigma_no_odometry_m`` (0.2), ``heading_half_deg`` (3.0),
///         ``heading_half_compass_deg`` (8.0), ``heading_half_no_prior_deg`` (15.0),
///         ``reference_radius_m`` (4.0), ``max_reference_nodes`` (3),
///         ``min_reference_overlap_cells`` (300), ``min_tracking_inlier_fraction`` (0.5: a
///         match from a prediction is taken at once only above it, else searched again wider),
///         ``check_no_motion`` (false: a match from the no-motion prediction taken at once;
///         a LiDAR's options search its runner-up first), ``edge_sigma_floor_m`` (0.005),
///         ``edge_sigma_floor_deg`` (0.1), ``recovery`` (what the loop does when its
///         predictions fail: the widest window, every heading, the whole map),
///         ``loop_closure``, ``optimize`` (the pose graph), ``voxel`` (the fused
///         occupancy map) and ``growth`` (what keeps the work per stop and the memory bounded
///         as the map grows). A step's ``status`` is ``first``, ``tracked``, ``recovered``,
///         ``relocalized``, ``new_segment`` (found nowhere with confidence: a new map segment,
///         its pose a guess) or ``doubtful``.
///
/// Raises:
///     sdem.InvalidError: an unknown option, a value of the wrong type or out of range.
#[pyclass(module = "sdem")]
pub struct Slam {
    inner: sdem::Slam,
    last_step: Option<Py<Step>>,
    progress: Option<Py<PyAny>>,
    /// The folder this map was saved to or loaded from, with the node files it holds.
    saved: Option<(PathBuf, NodeFiles)>,
}

/// `slf` borrowed to read, or a `RuntimeError` saying that another thread is inside it.
fn read<'py>(slf: &Bound<'py, Slam>) -> PyResult<PyRef<'py, Slam>> {
    slf.try_borrow().map_err(|_| busy())
}

/// `slf` borrowed to change, or a `RuntimeError` saying that another thread is inside it.
fn write<'py>(slf: &Bound<'py, Slam>) -> PyResult<PyRefMut<'py, Slam>> {
    slf.try_borrow_mut().map_err(|_| busy())
}

/// What a `Slam` used from two threads at once says: `add`, `save` and `merged_cloud` release
/// the GIL, so another thread can call it meanwhile, and finds it borrowed.
fn busy() -> PyErr {
    pyo3::exceptions::PyRuntimeError::new_err(
        "this sdem.Slam is in use by another thread (add, save and merged_cloud run without \
         the GIL and keep it borrowed until they return): call one Slam from one thread at a \
         time (hold a threading.Lock around it), or give each thread its own",
    )
}

/// Refuses a `progress` that cannot be called, before any scan is added (called only after
/// `add` has added its scan, it would fail with the map already changed).
fn check_progress(py: Python<'_>, progress: Option<&Py<PyAny>>) -> PyResult<()> {
    match progress {
        Some(p) if !p.bind(py).is_callable() => Err(crate::errors::invalid(format!(
            "progress must be a callable taking each sdem.Step (a function), not a {}",
            p.bind(py).get_type().name()?
        ))),
        _ => Ok(()),
    }
}

#[pymethods]
impl Slam {
    #[new]
    #[pyo3(signature = (*, progress=None, **options))]
    fn new(
        py: Python<'_>,
        progress: Option<Py<PyAny>>,
        options: Option<&Bound<'_, PyDict>>,
    ) -> PyResult<Self> {
        check_progress(py, progress.as_ref())?;
        let options = with_overrides(&SlamOptions::default(), options, "slam options")?;
        Ok(Self {
            inner: sdem::Slam::new(options).map_err(sdem_error)?,
            last_step: None,
            progress,
            saved: None,
        })
    }

    /// Resumes the map saved in ``path`` (by ``Slam.save`` or ``sdem slam``; the folder
    /// holding ``map.json``, or its parent), with the configuration it was made with.
    /// Odometry given to the next ``add`` is taken as a first reading: its motion counts from
    /// there.
    ///
    /// Raises:
    ///     sdem.FileError, sdem.ParseError: a missing or damaged map.
    #[staticmethod]
    #[pyo3(signature = (path, *, progress=None))]
    fn load(py: Python<'_>, path: PathBuf, progress: Option<Py<PyAny>>) -> PyResult<Self> {
        check_progress(py, progress.as_ref())?;
        let folder = sdem_io::saved_map_folder(&path);
        let saved = py.detach(|| sdem_io::load_map(&folder)).map_err(io_error)?;
        let node_files = saved.node_files.clone();
        let inner = py
            .detach(|| {
                sdem::Slam::restore(saved.config, saved.map, saved.edges, saved.loop_closures)
            })
            .map_err(sdem_error)?;
        Ok(Self {
            inner,
            last_step: None,
            progress,
            saved: Some((folder, node_files)),
        })
    }

    /// Adds the next stop's scan: predicts its pose, localizes it against the map, adds it as
    /// a node, closes loops and updates the fused map. Runs without the GIL.
    ///
    /// Args:
    ///     points: ``(N, 3)`` float32 or float64, sensor frame, metres (NaN rows skipped).
    ///     attitude_deg: the gyro/compass reading ``(roll, pitch, yaw)`` in degrees, or
    ///         ``None`` without one.
    ///     odometry: ``odom_from_sensor``, the odometry frame's pose of the sensor at this
    ///         stop as a 4x4 homogeneous matrix (as ROS's ``/odom`` gives it), or ``None``
    ///         without odometry. Only its motion since the last ``add`` that gave one is used.
    ///     roll_pitch_sigma_deg, yaw_sigma_deg: the reading's standard deviations, degrees
    ///         (defaults 0.5 and 3.5), as for ``sdem.Scan``.
    ///
    /// Returns:
    ///     numpy.ndarray: ``world_from_sensor``, the sensor's pose in the world as the step
    ///     left it, ``(4, 4)`` float64 (later loop closures can move it: see ``poses()``).
    ///     ``last_step`` holds the step's status, doubts and report.
    ///
    /// A scan found nowhere in the map with confidence is no error: it starts a new map
    ///     segment (``last_step.status == "new_segment"``, its pose a guess).
    ///
    /// Raises:
    ///     sdem.InvalidInputError, sdem.TooFewPointsError: bad input.
    #[pyo3(signature = (points, attitude_deg=None, odometry=None, *, roll_pitch_sigma_deg=None, yaw_sigma_deg=None))]
    fn add<'py>(
        slf: &Bound<'py, Self>,
        py: Python<'py>,
        points: &Bound<'py, PyAny>,
        attitude_deg: Option<&Bound<'py, PyAny>>,
        odometry: Option<&Bound<'py, PyAny>>,
        roll_pitch_sigma_deg: Option<f64>,
        yaw_sigma_deg: Option<f64>,
    ) -> PyResult<Bound<'py, PyArray2<f64>>> {
        let points = points_from(points, "points")?;
        let attitude = attitude_from(attitude_deg, roll_pitch_sigma_deg, yaw_sigma_deg)?;
        let odom_from_sensor = match odometry.filter(|o| !o.is_none()) {
            Some(o) => Some(pose_from(o, "odometry")?),
            None => None,
        };
        let mut this = write(slf)?;
        let inner = &mut this.inner;
        let step = py
            .detach(|| inner.add(&points, attitude, odom_from_sensor))
            .map_err(sdem_error)?;
        let world_from_sensor = matrix4(py, &step.world_from_sensor);
        let step = Py::new(py, Step::new(&step)?)?;
        this.last_step = Some(step.clone_ref(py));
        let progress = this.progress.as_ref().map(|p| p.clone_ref(py));
        drop(this); // the callback may read this Slam
        if let Some(progress) = progress {
            progress.call1(py, (step,))?;
        }
        Ok(world_from_sensor)
    }

    /// The last step ``add`` made (``None`` before the first).
    #[getter]
    fn last_step(slf: &Bound<'_, Self>, py: Python<'_>) -> PyResult<Option<Py<Step>>> {
        Ok(read(slf)?.last_step.as_ref().map(|s| s.clone_ref(py)))
    }

    /// ``world_from_sensor`` of every node, in the order the scans were added, as the last
    /// loop closure left them: ``(n, 4, 4)`` float64.
    fn poses<'py>(slf: &Bound<'py, Self>, py: Python<'py>) -> PyResult<Bound<'py, PyAny>> {
        Ok(matrices4(py, &read(slf)?.inner.poses()))
    }

    /// The merged point cloud: every node's points in the world, kept where the fused map is
    /// occupied now (moved rubble, seen through later, drops out), one per voxel; ``(M, 3)``
    /// float64. The map is settled first: the scans not fused into the voxel map yet, and
    /// those a loop closure moved, are fused now (the loop's steps leave that to a view), so
    /// a later call pays only for what is new.
    fn merged_cloud<'py>(
        slf: &Bound<'py, Self>,
        py: Python<'py>,
    ) -> PyResult<Bound<'py, PyArray2<f64>>> {
        let mut this = write(slf)?;
        let slam = &mut this.inner;
        let cloud = py
            .detach(|| {
                slam.settle_map()?;
                slam.merged_cloud()
            })
            .map_err(sdem_error)?;
        Ok(points_array(py, &cloud, |p| [p.x, p.y, p.z]))
    }

    /// Accepted loop closures as ``(from_node, to_node)`` pairs.
    #[getter]
    fn loop_closures(slf: &Bound<'_, Self>) -> PyResult<Vec<(usize, usize)>> {
        Ok((read(slf)?.inner.loop_closures.iter())
            .map(|c| (c.from, c.to))
            .collect())
    }

    /// The effective options, a dict of ``SlamOptions`` fields.
    #[getter]
    fn options<'py>(slf: &Bound<'py, Self>, py: Python<'py>) -> PyResult<Bound<'py, PyAny>> {
        to_python(py, read(slf)?.inner.config())
    }

    /// Saves the map into the folder ``path`` (created when missing) through sdem-io: node
    /// files, then the manifest ``map.json``, each written atomically, so a crash leaves the
    /// previous save whole. Saving again into the same folder writes only the new nodes.
    /// ``sdem.Map.load``, ``Slam.load`` and ``sdem localize --map`` read it.
    ///
    /// Args:
    ///     path: the folder.
    ///     overwrite: replace a map this ``Slam`` did not save there or load from there
    ///         (default False: that is an error).
    ///
    /// Raises:
    ///     sdem.InvalidError: ``path`` holds another map and ``overwrite`` is False.
    ///     sdem.FileError: the file system's errors.
    #[pyo3(signature = (path, *, overwrite=false))]
    fn save(slf: &Bound<'_, Self>, py: Python<'_>, path: PathBuf, overwrite: bool) -> PyResult<()> {
        let mut this = write(slf)?;
        let same_folder = this
            .saved
            .as_ref()
            .is_some_and(|(folder, _)| *folder == path);
        if !same_folder && path.join(MAP_MANIFEST).exists() && !overwrite {
            // Refused before anything is taken: the record of the folder saved to stays.
            return Err(invalid(format!(
                "{} already holds a map; pass overwrite=True to replace it",
                path.display()
            )));
        }
        let mut node_files = match this.saved.take() {
            Some((_, files)) if same_folder => files,
            _ => NodeFiles::default(),
        };
        let slam = &this.inner;
        let result = py.detach(|| {
            sdem_io::save_map(
                &path,
                &mut node_files,
                slam.config(),
                &slam.map,
                &slam.edges,
                &slam.loop_closures,
                &[],
            )
        });
        // After a failed save the folder's node files are unknown: the next save writes all.
        if result.is_ok() {
            this.saved = Some((path, node_files));
        }
        result.map_err(io_error)
    }

    /// The number of nodes (scans added).
    fn __len__(slf: &Bound<'_, Self>) -> PyResult<usize> {
        Ok(read(slf)?.inner.map.nodes.len())
    }

    fn __repr__(slf: &Bound<'_, Self>) -> PyResult<String> {
        let this = read(slf)?;
        Ok(format!(
            "sdem.Slam({} nodes, {} loop closures)",
            this.inner.map.nodes.len(),
            this.inner.loop_closures.len()
        ))
    }
}

/// One stop added by ``Slam.add``: where the sensor stood, how the match went, and the report
/// ``sdem slam`` writes for it in ``report.json``.
#[pyclass(module = "sdem", frozen)]
pub struct Step {
    world_from_sensor: Pose,
    status: String,
    doubts: Vec<RustDoubt>,
    trusted: bool,
    node_id: usize,
    time_ms: f64,
    covariance: Option<[[f64; 6]; 6]>,
    report: Value,
}

impl Step {
    fn new(step: &sdem::Step) -> PyResult<Self> {
        let status = to_json(&step.status, "step status")?;
        let mut report = to_json(&step.report, "step report")?;
        if let Some(object) = report.as_object_mut() {
            let doubts = step.report.doubts.iter().map(crate::localize::doubt_json);
            object.insert("doubts".into(), Value::Array(doubts.collect()));
        }
        Ok(Self {
            world_from_sensor: step.world_from_sensor,
            status: status.as_str().unwrap_or_default().to_string(),
            doubts: step.report.doubts.clone(),
            trusted: step.report.trusted,
            node_id: step.report.node_id,
            time_ms: step.report.time_ms,
            covariance: step.report.covariance,
            report,
        })
    }
}

#[pymethods]
impl Step {
    /// The sensor's pose in the world when the step ended, ``(4, 4)`` float64.
    #[getter]
    fn world_from_sensor<'py>(&self, py: Python<'py>) -> Bound<'py, PyAny> {
        matrix4(py, &self.world_from_sensor).into_any()
    }

    /// ``"first"`` (the scan defines the world frame), ``"tracked"`` (matched from the first
    /// prediction with no doubt), ``"recovered"`` (matched with no doubt after the first
    /// prediction failed), ``"relocalized"`` (found with no prior in the map),
    /// ``"new_segment"`` (found nowhere with confidence: it starts a new map segment, its pose a
    /// guess) or ``"doubtful"`` (matched, the position along a free direction the odometry's).
    #[getter]
    fn status(&self) -> &str {
        &self.status
    }

    /// No doubt about the match: the step's pose rests on the scans.
    #[getter]
    fn trusted(&self) -> bool {
        self.trusted
    }

    /// Every reason not to trust the match, a list of ``sdem.Doubt``.
    #[getter]
    fn doubts<'py>(&self, py: Python<'py>) -> PyResult<Bound<'py, PyList>> {
        doubt_list(py, &self.doubts)
    }

    /// The node the scan became.
    #[getter]
    fn node_id(&self) -> usize {
        self.node_id
    }

    /// Wall time of the whole step (localization, loop closure, optimization, map update), ms.
    #[getter]
    fn time_ms(&self) -> f64 {
        self.time_ms
    }

    /// The match's covariance of ``[x, y, z, roll, pitch, yaw]`` (metres, radians; world axes),
    /// ``(6, 6)`` float64, as the pose graph's edges carry it (``report["covariance"]``); None
    /// for the first scan or a match without a 6-DoF refinement.
    #[getter]
    fn covariance<'py>(&self, py: Python<'py>) -> Option<Bound<'py, PyAny>> {
        covariance_array(py, self.covariance.as_ref())
    }

    /// The step as ``report.json`` holds it: ``scan_index``, ``node_id``, ``time_ms``,
    /// ``localize_ms``, ``world_from_sensor`` and ``predicted_world_from_sensor`` (metres and
    /// degrees), ``heading_prior``, ``reference_nodes``, ``cost``, ``overlap_fraction``,
    /// ``inlier_fraction``, ``covariance``, ``doubts`` (with messages), ``trusted``,
    /// ``refinement``, ``loop_closures`` and ``optimization``. A new dict at each access.
    #[getter]
    fn report<'py>(&self, py: Python<'py>) -> PyResult<Bound<'py, PyAny>> {
        to_python(py, &self.report)
    }

    fn __repr__(&self) -> String {
        let t = self.world_from_sensor.translation.vector;
        format!(
            "sdem.Step(node_id={}, status='{}', x={:.4}, y={:.4}, z={:.4}, doubts={:?}, \
             time_ms={:.1})",
            self.node_id,
            self.status,
            t.x,
            t.y,
            t.z,
            self.doubts.iter().map(|d| d.kind()).collect::<Vec<_>>(),
            self.time_ms
        )
    }
}

/// A saved map (``Slam.save`` or ``sdem slam`` wrote it), loaded to relocalize scans in, as
/// ``sdem localize --map`` does. Load it with ``sdem.Map.load(path)``.
#[pyclass(module = "sdem", frozen)]
pub struct Map {
    saved: SavedMap,
    folder: PathBuf,
}

#[pymethods]
impl Map {
    /// Loads the map saved in ``path`` (the folder holding ``map.json``, or its parent, as
    /// ``sdem slam`` writes ``OUT/map``), checking every file.
    ///
    /// Raises:
    ///     sdem.FileError, sdem.ParseError, sdem.InvalidError: a missing or damaged map, each
    ///         naming the file.
    #[staticmethod]
    fn load(py: Python<'_>, path: PathBuf) -> PyResult<Self> {
        let folder = sdem_io::saved_map_folder(&path);
        let saved = py.detach(|| sdem_io::load_map(&folder)).map_err(io_error)?;
        Ok(Self { saved, folder })
    }

    /// Finds where a scan was taken in the map, with the map's own search settings: near
    /// ``near`` when given, else at the nodes whose place descriptors look most like the
    /// scan's, trying up to ``max_nodes`` nodes with the exact search until one matches.
    /// Runs without the GIL.
    ///
    /// Args:
    ///     points: ``(N, 3)`` float32 or float64, sensor frame, metres.
    ///     attitude_deg: the gyro/compass reading ``(roll, pitch, yaw)`` in degrees, or
    ///         ``None`` (taken as level, heading searched ±15°).
    ///     near: where the scan was taken, roughly: ``(x, y, z)`` in the map's frame, metres.
    ///     near_sigma_m: how well ``near`` is known (one sigma, metres) when it is a
    ///         prediction (odometry since the last known pose): it then also weighs in the
    ///         cost, and along a direction the scan leaves free the position is the
    ///         prediction's.
    ///     max_nodes: at most this many nodes are tried (3 near ``near``; without it, the
    ///         map's ``recovery.relocalize_candidates``, 6, as ``sdem localize --map``).
    ///     roll_pitch_sigma_deg, yaw_sigma_deg: the reading's standard deviations, degrees.
    ///
    /// Returns:
    ///     sdem.Relocalization: ``world_from_sensor`` with ``trusted`` and ``doubts``.
    ///
    /// Raises:
    ///     sdem.NotFoundError: no node matches (``tried`` says why for each).
    ///     sdem.InvalidInputError, sdem.TooFewPointsError: bad input;
    ///         sdem.NoUsablePointsError (a TooFewPointsError) when no point is usable, saying why.
    #[pyo3(signature = (points, attitude_deg=None, *, near=None, near_sigma_m=None, max_nodes=None, roll_pitch_sigma_deg=None, yaw_sigma_deg=None))]
    #[allow(clippy::too_many_arguments)]
    fn localize(
        &self,
        py: Python<'_>,
        points: &Bound<'_, PyAny>,
        attitude_deg: Option<&Bound<'_, PyAny>>,
        near: Option<&Bound<'_, PyAny>>,
        near_sigma_m: Option<f64>,
        max_nodes: Option<i64>,
        roll_pitch_sigma_deg: Option<f64>,
        yaw_sigma_deg: Option<f64>,
    ) -> PyResult<Relocalization> {
        let max_nodes = (max_nodes.map(|n| crate::arrays::non_negative(n, "max_nodes")))
            .transpose()?
            .map(|n| n as usize);
        let points = points_from(points, "points")?;
        let attitude = attitude_from(attitude_deg, roll_pitch_sigma_deg, yaw_sigma_deg)?;
        let near = near_from(near, near_sigma_m)?;
        if max_nodes == Some(0) {
            return Err(invalid_input(
                "max_nodes",
                "at least one node must be tried",
            ));
        }
        let saved = &self.saved;
        let found = py.detach(|| {
            // The checks of a scan (finite, enough cells on the map's grid), then its points.
            let scan = sdem::Scan::with_grid(&points, attitude, &saved.config.sdem)?;
            saved.relocalize(scan.points_in_sensor(), attitude, near, max_nodes)
        });
        Relocalization::new(&found.map_err(sdem_error)?)
    }

    /// ``world_from_sensor`` of every node, ``(n, 4, 4)`` float64.
    fn poses<'py>(&self, py: Python<'py>) -> Bound<'py, PyAny> {
        let poses: Vec<Pose> = self
            .saved
            .map
            .nodes
            .iter()
            .map(|n| n.world_from_sensor)
            .collect();
        matrices4(py, &poses)
    }

    /// The options the map was made with, a dict of ``SlamOptions`` fields.
    #[getter]
    fn options<'py>(&self, py: Python<'py>) -> PyResult<Bound<'py, PyAny>> {
        to_python(py, &self.saved.config)
    }

    /// The folder the map was loaded from.
    #[getter]
    fn path(&self) -> PathBuf {
        self.folder.clone()
    }

    /// The number of nodes.
    fn __len__(&self) -> usize {
        self.saved.map.nodes.len()
    }

    fn __repr__(&self) -> String {
        format!(
            "sdem.Map({} nodes, from {})",
            self.__len__(),
            self.folder.display()
        )
    }
}

/// `near` and its σ as the library's `Near`.
fn near_from(near: Option<&Bound<'_, PyAny>>, sigma_m: Option<f64>) -> PyResult<Option<Near>> {
    match (near.filter(|n| !n.is_none()), sigma_m) {
        (Some(near), sigma_m) => Ok(Some(Near {
            position: Vec3::from(numbers::<3>(near, "near")?),
            sigma_m,
        })),
        (None, Some(_)) => Err(invalid_input(
            "near_sigma_m",
            "it says how well `near` is known; give near=(x, y, z) too",
        )),
        (None, None) => Ok(None),
    }
}

/// A scan relocalized in a saved map (``Map.localize``).
#[pyclass(module = "sdem", frozen)]
pub struct Relocalization {
    world_from_sensor: Pose,
    node_id: usize,
    tried: Vec<(usize, String)>,
    cost: f64,
    diagnostics: Value,
    doubts: Vec<RustDoubt>,
    trusted: bool,
    time_ms: f64,
    covariance: Option<[[f64; 6]; 6]>,
}

impl Relocalization {
    fn new(found: &sdem::slam::Relocalization) -> PyResult<Self> {
        Ok(Self {
            world_from_sensor: found.world_from_sensor,
            node_id: found.node_id,
            tried: found.tried.clone(),
            cost: found.cost,
            diagnostics: to_json(&found.diagnostics, "diagnostics")?,
            doubts: found.doubts.clone(),
            trusted: found.trusted,
            time_ms: found.time.as_secs_f64() * 1e3,
            covariance: found.diagnostics.covariance,
        })
    }
}

#[pymethods]
impl Relocalization {
    /// The scan's pose in the map's world frame, ``(4, 4)`` float64.
    #[getter]
    fn world_from_sensor<'py>(&self, py: Python<'py>) -> Bound<'py, PyAny> {
        matrix4(py, &self.world_from_sensor).into_any()
    }

    /// The node it was matched against.
    #[getter]
    fn node_id(&self) -> usize {
        self.node_id
    }

    /// The nodes tried before it, each ``(node_id, why it did not match)``.
    #[getter]
    fn tried(&self) -> Vec<(usize, String)> {
        self.tried.clone()
    }

    /// Eq. (1) at the best grid candidate, m².
    #[getter]
    fn cost(&self) -> f64 {
        self.cost
    }

    /// The match's figures (as ``sdem.Localization.diagnostics`` without the search's).
    #[getter]
    fn diagnostics<'py>(&self, py: Python<'py>) -> PyResult<Bound<'py, PyAny>> {
        to_python(py, &self.diagnostics)
    }

    /// Every reason not to trust the pose, a list of ``sdem.Doubt``.
    #[getter]
    fn doubts<'py>(&self, py: Python<'py>) -> PyResult<Bound<'py, PyList>> {
        doubt_list(py, &self.doubts)
    }

    /// No doubt: the pose can be used as it is.
    #[getter]
    fn trusted(&self) -> bool {
        self.trusted
    }

    /// Wall time, milliseconds.
    #[getter]
    fn time_ms(&self) -> f64 {
        self.time_ms
    }

    /// The match's covariance of ``[x, y, z, roll, pitch, yaw]`` (metres, radians), ``(6, 6)``
    /// float64 (``diagnostics["covariance"]``); None without a 6-DoF refinement.
    #[getter]
    fn covariance<'py>(&self, py: Python<'py>) -> Option<Bound<'py, PyAny>> {
        covariance_array(py, self.covariance.as_ref())
    }

    fn __repr__(&self) -> String {
        let t = self.world_from_sensor.translation.vector;
        format!(
            "sdem.Relocalization(trusted={}, node_id={}, x={:.4}, y={:.4}, z={:.4}, \
             doubts={:?}, time_ms={:.1})",
            if self.trusted { "True" } else { "False" },
            self.node_id,
            t.x,
            t.y,
            t.z,
            self.doubts.iter().map(|d| d.kind()).collect::<Vec<_>>(),
            self.time_ms
        )
    }
}

/// The library's loop options with ``overrides`` laid over them, as a dict: every
/// ``SlamOptions`` field with its default (``sdem.Slam(**options)`` takes the same names).
///
/// Raises:
///     sdem.InvalidError: an unknown name or a value of the wrong type.
#[pyfunction]
#[pyo3(signature = (**overrides))]
pub fn slam_options<'py>(
    py: Python<'py>,
    overrides: Option<&Bound<'py, PyDict>>,
) -> PyResult<Bound<'py, PyAny>> {
    to_python(
        py,
        &with_overrides(&SlamOptions::default(), overrides, "slam options")?,
    )
}

/// The loop's options matched to a scan (``SlamOptions::for_scan``), with ``overrides`` laid
/// over them, as a dict for ``sdem.Slam(**options)``. For a LiDAR (a spinning one: every
/// azimuth within a band of elevation; a solid-state one: at most 120° of azimuth): the S-DEM
/// grid at the scan's own angular step, the search's step, truncation and refinement from its
/// ranges, loop closure and the fused map on that step (rays up to 20 m), the recovery's
/// widest window and the no-odometry σ scaled with the step, the no-motion match checked for
/// a rival, as ``sdem slam`` chooses them for a dataset without ``sensor.toml``; for any
/// other scanner, ``sdem.slam_options()``'s defaults (the tilting laser's) on S-DEM cells
/// matched to the scan's sampling, 0.5° at the finest.
///
/// Args:
///     points: the first scan, ``(N, 3)`` float32 or float64, sensor frame, metres.
///
/// Raises:
///     sdem.InvalidInputError: points not ``(N, 3)``; sdem.InvalidError: an unknown name or a
///     value of the wrong type.
#[pyfunction]
#[pyo3(signature = (points, **overrides))]
pub fn slam_options_for_scan<'py>(
    py: Python<'py>,
    points: &Bound<'py, PyAny>,
    overrides: Option<&Bound<'py, PyDict>>,
) -> PyResult<Bound<'py, PyAny>> {
    let points: Vec<Vec3> = (points_from(points, "points")?.into_iter())
        .map(|p| p.coords)
        .collect();
    let base = py.detach(|| SlamOptions::for_scan(&points));
    to_python(py, &with_overrides(&base, overrides, "slam options")?)
}

/// A report's covariance (`[[f64; 6]; 6]`) as a `(6, 6)` array, or None.
fn covariance_array<'py>(
    py: Python<'py>,
    covariance: Option<&[[f64; 6]; 6]>,
) -> Option<Bound<'py, PyAny>> {
    covariance.map(|c| matrix6(py, &Matrix6::from_fn(|i, j| c[i][j])).into_any())
}
