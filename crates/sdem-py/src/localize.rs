//! `sdem.Scan`, `sdem.localize` and its result, `sdem.Localization`, with its `sdem.Doubt`s.

use crate::arrays::{matrix4, matrix6, numbers, points_array, points_from};
use crate::errors::{invalid_input, sdem_error};
use crate::options::{dict_json, to_json, to_python, with_overrides};
use nalgebra::{Matrix6, Point3};
use pyo3::prelude::*;
use pyo3::types::{PyDict, PyList};
use sdem::cost::OffsetPrior;
use sdem::localize::RefinementSummary;
use sdem::{Attitude, AttitudeSigma, Doubt as RustDoubt, LocalizeOptions, Pose, SdemConfig};
use serde_json::{json, Value};

/// A scan as the sensor gave it: points in the sensor frame, metres, and the gyro/compass
/// attitude read when it was taken, if the robot has one.
///
/// The attitude belongs to the scan: the S-DEM (a grid of nearest ranges over azimuth and
/// elevation) is levelled by it, and a localization reads it from here. With no attitude
/// (``None``) the scan's tilt (up to 30°) and heading are unknown, and a localization searches
/// them.
///
/// Args:
///     points: ``(N, 3)`` array of float32 or float64, x, y, z in metres in the sensor frame
///         (x forward, y left, z up), C- or Fortran-ordered. Rows with a NaN are "no return"
///         and are skipped; an infinite coordinate is an error.
///     attitude_deg: ``(roll, pitch, yaw)`` in degrees, ``R = Rz(yaw) Ry(pitch) Rx(roll)``,
///         or ``None`` when the attitude is unknown.
///     roll_pitch_sigma_deg: how far the roll and pitch readings can be off, one standard
///         deviation in degrees (default 0.5: a gyro levelled by gravity). Only with
///         ``attitude_deg``.
///     yaw_sigma_deg: the same for the heading (default 3.5: a compass near steel; 180 says
///         the compass tells nothing). A localization searches the heading over three
///         standard deviations of the two readings' difference.
///     grid: the S-DEM grid, a dict of ``SdemConfig`` fields laid over the default 1° x 1°
///         grid, e.g. ``{"resolution_deg": 0.5}``, or ``sdem.grid_for_scan(points)`` for a
///         spinning LiDAR. Both scans of a localization must share one grid.
///
/// Raises:
///     sdem.InvalidInputError: points that are not an ``(N, 3)`` float array, an infinite
///         coordinate, a non-finite attitude or a standard deviation that is not positive.
///     sdem.TooFewPointsError: fewer than 100 S-DEM cells hold a return;
///         sdem.NoUsablePointsError (a TooFewPointsError) when none does, with the reason.
///     sdem.InvalidError: an invalid grid.
#[pyclass(module = "sdem", frozen)]
pub struct Scan {
    pub inner: sdem::Scan,
}

#[pymethods]
impl Scan {
    #[new]
    #[pyo3(signature = (points, attitude_deg=None, *, roll_pitch_sigma_deg=None, yaw_sigma_deg=None, grid=None))]
    fn new(
        py: Python<'_>,
        points: &Bound<'_, PyAny>,
        attitude_deg: Option<&Bound<'_, PyAny>>,
        roll_pitch_sigma_deg: Option<f64>,
        yaw_sigma_deg: Option<f64>,
        grid: Option<&Bound<'_, PyDict>>,
    ) -> PyResult<Self> {
        let points = points_from(points, "points")?;
        let attitude = attitude_from(attitude_deg, roll_pitch_sigma_deg, yaw_sigma_deg)?;
        let grid = with_overrides(&SdemConfig::default(), grid, "grid")?;
        let inner = py
            .detach(|| sdem::Scan::with_grid(&points, attitude, &grid))
            .map_err(sdem_error)?;
        Ok(Self { inner })
    }

    /// The attitude reading ``(roll, pitch, yaw)`` in degrees, or ``None`` when unknown.
    #[getter]
    fn attitude_deg(&self) -> Option<(f64, f64, f64)> {
        self.inner.attitude().map(|a| {
            let [r, p, y] = a.to_degrees();
            (r, p, y)
        })
    }

    /// The reading's standard deviations ``(roll_pitch, yaw)`` in degrees, or ``None`` when
    /// the attitude is unknown.
    #[getter]
    fn sigma_deg(&self) -> Option<(f64, f64)> {
        (self.inner.attitude()).map(|a| (a.sigma.roll_pitch.to_degrees(), a.sigma.yaw.to_degrees()))
    }

    /// The finite points, ``(N, 3)`` float64, sensor frame, metres (a copy).
    #[getter]
    fn points<'py>(&self, py: Python<'py>) -> Bound<'py, PyAny> {
        points_array(py, self.inner.points_in_sensor(), |p| [p.x, p.y, p.z]).into_any()
    }

    /// The S-DEM cells that hold a return (a localization needs at least 100).
    #[getter]
    fn known_cells(&self) -> usize {
        self.inner.sdem().known_cells()
    }

    /// The S-DEM grid, a dict of ``SdemConfig`` fields.
    #[getter]
    fn grid<'py>(&self, py: Python<'py>) -> PyResult<Bound<'py, PyAny>> {
        to_python(py, self.inner.sdem().config())
    }

    /// The number of finite points.
    fn __len__(&self) -> usize {
        self.inner.points_in_sensor().len()
    }

    fn __repr__(&self) -> String {
        let attitude = match self.attitude_deg() {
            Some((r, p, y)) => format!("({r:.2}, {p:.2}, {y:.2})"),
            None => "None".into(),
        };
        format!(
            "sdem.Scan({} points, {} cells, attitude_deg={attitude})",
            self.__len__(),
            self.known_cells()
        )
    }
}

/// The attitude reading from its degrees and optional standard deviations.
pub fn attitude_from(
    attitude_deg: Option<&Bound<'_, PyAny>>,
    roll_pitch_sigma_deg: Option<f64>,
    yaw_sigma_deg: Option<f64>,
) -> PyResult<Option<Attitude>> {
    let Some(attitude_deg) = attitude_deg.filter(|a| !a.is_none()) else {
        if roll_pitch_sigma_deg.is_some() || yaw_sigma_deg.is_some() {
            return Err(invalid_input(
                "attitude standard deviations",
                "they describe the attitude reading; give attitude_deg=(roll, pitch, yaw) too",
            ));
        }
        return Ok(None);
    };
    let [r, p, y] = numbers::<3>(attitude_deg, "attitude_deg")?;
    for (name, sigma) in [
        ("roll_pitch_sigma_deg", roll_pitch_sigma_deg),
        ("yaw_sigma_deg", yaw_sigma_deg),
    ] {
        if let Some(s) = sigma.filter(|s| !(s.is_finite() && *s > 0.0)) {
            return Err(invalid_input(
                name,
                format!("{s}° must be positive: the reading's standard deviation, in degrees"),
            ));
        }
    }
    let default = AttitudeSigma::default();
    Ok(Some(Attitude::from_degrees(r, p, y).with_sigma_deg(
        roll_pitch_sigma_deg.unwrap_or(default.roll_pitch.to_degrees()),
        yaw_sigma_deg.unwrap_or(default.yaw.to_degrees()),
    )))
}

/// Localizes ``query`` against ``reference``: where the query's sensor stood, in the
/// reference sensor's frame (Nagatani et al. 2003, Sec. III-C, searched exactly and refined in
/// 6-DoF). The computation runs without the GIL.
///
/// The attitudes come from the scans, with their standard deviations. When both have one whose
/// roll and pitch agree within 3° at three sigma, the search covers the ``window`` of
/// translations and, around the compass readings, three standard deviations of the two headings'
/// difference (``heading`` gives only the step); a match that tilts one scan against the other
/// beyond what the readings allow carries the doubt ``attitude_corrected``. Otherwise (a scan
/// without a reading, or readings too uncertain) the rotation is searched too; a rotation that
/// compares almost as well as the one returned is the doubt ``another_rotation``, and one that
/// agrees as well where the scans overlap, but overlaps less, the doubt ``unrefuted_rotation``.
///
/// Args:
///     reference: the scan the pose is expressed in.
///     query: the scan to localize.
///     **options: ``LocalizeOptions`` fields, name for name, each defaulting to the library's
///         value (``sdem.localize_options()`` lists them all). A dict for a nested struct
///         changes only the fields it names. The main ones:
///
///         - ``window``: the candidate translations, ``{"min": [x, y, z], "max": [x, y, z]}``
///           in metres (query origin minus reference origin on the levelled reference's axes);
///           default the paper's ``min [-0.5, -0.3, -0.1]``, ``max [0.5, 0.6, 0.1]``.
///         - ``step_m``: the grid step, metres (0.01).
///         - ``heading``: ``{"half_range_deg": 10.0, "step_deg": None}``; the step is matched
///           to the scan's extent when ``None``.
///         - ``mode``: ``"branch_and_bound"`` (exact, the default), ``"exhaustive"`` (every
///           candidate: the oracle) or ``"coarse_to_fine"`` (a heuristic).
///         - ``max_exhaustive_candidates`` (4,000,000): a larger exhaustive grid raises
///           ``sdem.TooManyCandidatesError`` before it runs.
///         - ``cost``: eq. (1): ``model`` (``"projective"``, ``"virtual_sdem"``),
///           ``truncation_m`` (0.05), ``min_overlap_cells`` (100), ``min_overlap_fraction``
///           (0.2), ``min_inlier_fraction`` (0.1), ``search_voxel_m`` (0.08),
///           ``max_search_points`` (1500), and ``prior``: a prediction of the offset,
///           ``{"offset": [x, y, z], "sigma_m": s}``, weighed in as one more point (default
///           none).
///         - ``refine`` (True), ``refinement``: the 6-DoF refinement's settings.
///         - ``coarse_step_m`` (0.08), ``keep`` (8): coarse-to-fine only.
///         - ``runner_up`` (True): search again outside the peak for a runner-up (branch-and-bound
///           goes on from what its first search set aside; the other modes score the grid again,
///           once more for each slope of the optimum passed over); ``peak_radius_m`` (0.1).
///         - ``ambiguous_cost_ratio`` (1.1), ``ambiguous_sigma_ratio`` (10.0),
///           ``ambiguous_rise_ratio`` (0.05), ``min_trusted_inlier_fraction`` (0.25),
///           ``min_trusted_support`` (0.01): when the result is doubted.
///
/// Returns:
///     sdem.Localization: the pose ``reference_from_query`` with ``trusted``, ``doubts``,
///     ``covariance``, ``time_ms`` and ``diagnostics``. A result with doubts is the best
///     candidate found, not a pose to trust (``trusted`` is False); it is not an exception.
///
/// Raises:
///     sdem.InvalidError: invalid options (an unknown name, a value of the wrong type or out
///         of range) or scans on different grids.
///     sdem.TooManyCandidatesError: an exhaustive search over more candidates than
///         ``max_exhaustive_candidates``.
///     sdem.NoOverlapError, sdem.NoMatchError: nothing in the window matches.
///     sdem.NoSurfacesError: no attitude, and a scan shows no surface whose orientation can be
///         measured.
#[pyfunction]
#[pyo3(signature = (reference, query, **options))]
pub fn localize(
    py: Python<'_>,
    reference: &Bound<'_, Scan>,
    query: &Bound<'_, Scan>,
    options: Option<&Bound<'_, PyDict>>,
) -> PyResult<Localization> {
    let options = localize_options_over(&LocalizeOptions::default(), options)?;
    let (reference, query) = (&reference.get().inner, &query.get().inner);
    let found = py
        .detach(|| sdem::localize(reference, query, &options))
        .map_err(sdem_error)?;
    Localization::new(&found)
}

/// `base` with the keyword options laid over it, `cost.prior` included (serde skips it).
pub fn localize_options_over(
    base: &LocalizeOptions,
    options: Option<&Bound<'_, PyDict>>,
) -> PyResult<LocalizeOptions> {
    let Some(options) = options else {
        return with_overrides(base, None, "localize options");
    };
    let options = options.copy()?;
    let prior = take_prior(&options)?;
    let mut merged = with_overrides(base, Some(&options), "localize options")?;
    if prior.is_some() {
        merged.cost.prior = prior;
    }
    // Checked here, not only where a search uses them: `localize_options(step_m=-1)` returned
    // the value, and a heading window is not read when the rotation is searched.
    merged.validate().map_err(sdem_error)?;
    Ok(merged)
}

/// Removes `cost["prior"]` from the keywords (copying the `cost` dict) and returns it checked.
fn take_prior(options: &Bound<'_, PyDict>) -> PyResult<Option<OffsetPrior>> {
    let Some(cost) = options.get_item("cost")? else {
        return Ok(None);
    };
    let Ok(cost) = cost.cast::<PyDict>() else {
        return Ok(None);
    };
    let cost = cost.copy()?;
    let prior = cost.get_item("prior")?;
    if prior.is_some() {
        cost.del_item("prior")?;
    }
    options.set_item("cost", &cost)?;
    let Some(prior) = prior.filter(|p| !p.is_none()) else {
        return Ok(None);
    };
    let as_dict = PyDict::new(options.py());
    as_dict.set_item("prior", prior)?;
    let value = dict_json(&as_dict, "localize options: cost.prior")?;
    let prior: OffsetPrior = serde_json::from_value(value["prior"].clone()).map_err(|e| {
        crate::errors::invalid(format!(
            "localize options: cost.prior must be {{\"offset\": [x, y, z], \"sigma_m\": s}}: {e}"
        ))
    })?;
    prior.validate().map_err(sdem_error)?;
    Ok(Some(prior))
}

/// The result of ``sdem.localize``: where the query sensor stood in the reference sensor's
/// frame, and how far to trust it.
///
/// A result with doubts is still the best candidate the search found, to be used only as a
/// guess: check ``trusted`` (no doubt) before using ``reference_from_query`` as it is.
#[pyclass(module = "sdem", frozen)]
pub struct Localization {
    reference_from_query: Pose,
    covariance: Option<Matrix6<f64>>,
    doubts: Vec<RustDoubt>,
    trusted: bool,
    time_ms: f64,
    cost: f64,
    overlap: usize,
    runner_up: Option<f64>,
    diagnostics: Value,
}

impl Localization {
    /// The result's values, the diagnostics as the command line's JSON holds them.
    pub fn new(found: &sdem::Localization) -> PyResult<Self> {
        Ok(Self {
            reference_from_query: found.reference_from_query,
            covariance: found.covariance,
            doubts: found.doubts.clone(),
            trusted: found.trusted,
            time_ms: found.time.as_secs_f64() * 1e3,
            cost: found.cost,
            overlap: found.overlap,
            runner_up: found.runner_up,
            diagnostics: diagnostics_json(found)?,
        })
    }
}

/// The diagnostics with the search's figures, as `sdem localize --json` reports them.
fn diagnostics_json(found: &sdem::Localization) -> PyResult<Value> {
    let mut value = to_json(&found.diagnostics, "diagnostics")?;
    let extra = json!({
        "cost": found.cost,
        "rms_m": found.cost.sqrt(),
        "overlap": found.overlap,
        "runner_up": found.runner_up,
        "candidates_total": found.candidates_total,
        "candidates_evaluated": found.candidates_evaluated,
        "nodes_bounded": found.nodes_bounded,
        "on_window_edge": found.on_window_edge,
        "heading_correction_deg": found.heading_correction.to_degrees(),
        "refinement": RefinementSummary::new(found.refined, found.refinement.as_ref()),
    });
    if let (Some(object), Value::Object(extra)) = (value.as_object_mut(), extra) {
        object.extend(extra);
    }
    Ok(value)
}

#[pymethods]
impl Localization {
    /// The query sensor's pose in the reference sensor's frame, a ``(4, 4)`` float64
    /// homogeneous transform: ``reference_point = reference_from_query @ query_point``.
    #[getter]
    fn reference_from_query<'py>(&self, py: Python<'py>) -> Bound<'py, PyAny> {
        matrix4(py, &self.reference_from_query).into_any()
    }

    /// True when the result has no doubt: the pose can be used as it is.
    #[getter]
    fn trusted(&self) -> bool {
        self.trusted
    }

    /// Every reason not to trust the pose, a list of ``sdem.Doubt`` (empty when trusted).
    #[getter]
    fn doubts<'py>(&self, py: Python<'py>) -> PyResult<Bound<'py, PyList>> {
        doubt_list(py, &self.doubts)
    }

    /// Covariance of the pose over ``[x, y, z, rx, ry, rz]`` in the query sensor's frame
    /// (metres along its axes, then small rotations in radians about them), ``(6, 6)``
    /// float64; from the refinement's curvature, widened by the residuals' correlation and the
    /// bias of how the two scans sample their surfaces.
    /// ``None`` without a 6-DoF refinement.
    #[getter]
    fn covariance<'py>(&self, py: Python<'py>) -> Option<Bound<'py, PyAny>> {
        self.covariance.as_ref().map(|c| matrix6(py, c).into_any())
    }

    /// Wall time of the localization, milliseconds.
    #[getter]
    fn time_ms(&self) -> f64 {
        self.time_ms
    }

    /// Eq. (1) at the best grid candidate, m².
    #[getter]
    fn cost(&self) -> f64 {
        self.cost
    }

    /// Cells compared at the best grid candidate.
    #[getter]
    fn overlap(&self) -> usize {
        self.overlap
    }

    /// The lowest cost found far from the optimum, off its own slopes, when it comes close to
    /// the best (another place that looks almost the same), m²; ``None`` when nothing came that
    /// close.
    #[getter]
    fn runner_up(&self) -> Option<f64> {
        self.runner_up
    }

    /// The figures behind ``trusted``, as ``sdem localize --json`` reports them:
    /// ``overlap_fraction``, ``inlier_fraction``, ``refined_inlier_fraction``, ``runner_up_cost``,
    /// ``runner_up_cost_at_least``, ``runner_up_slopes_passed``, ``covariance`` (on the levelled reference's axes),
    /// ``weakest_direction``, ``weakest_sigma_m``, ``strongest_sigma_m``, ``flat_direction``,
    /// ``seen_through_fraction``, ``ambiguous``, and the search's ``cost``, ``rms_m``, ``overlap``, ``runner_up``,
    /// ``candidates_total``, ``candidates_evaluated``, ``nodes_bounded``, ``on_window_edge``,
    /// ``heading_correction_deg`` and ``refinement`` (``outcome``, ``iterations``,
    /// ``converged``, ``rms_m``). A new dict at each access.
    #[getter]
    fn diagnostics<'py>(&self, py: Python<'py>) -> PyResult<Bound<'py, PyAny>> {
        to_python(py, &self.diagnostics)
    }

    fn __repr__(&self) -> String {
        let record = sdem::geometry::PoseRecord::from(&self.reference_from_query);
        format!(
            "sdem.Localization(trusted={}, doubts={:?}, x={:.4}, y={:.4}, z={:.4}, \
             roll_deg={:.3}, pitch_deg={:.3}, yaw_deg={:.3}, time_ms={:.1})",
            if self.trusted { "True" } else { "False" },
            self.doubts.iter().map(|d| d.kind()).collect::<Vec<_>>(),
            record.x,
            record.y,
            record.z,
            record.roll_deg,
            record.pitch_deg,
            record.yaw_deg,
            self.time_ms
        )
    }
}

/// One reason not to trust a pose: its ``kind``, its figures and a ``message`` in words, the
/// same as each entry of ``doubts`` in ``sdem localize --json``.
///
/// Kinds and figures (directions are unit vectors on the reference's levelled axes):
///
/// - ``runner_up``: another candidate far away, off the optimum's own slopes, scores almost as
///   well (``distance_m``, ``cost``, ``best_cost``).
/// - ``flat_covariance``: the pose is free along ``direction`` (``sigma_m``,
///   ``across_sigma_m``).
/// - ``unconstrained``: hardly any matched surface faces along ``direction``
///   (``facing_fraction``, ``needed_fraction``).
/// - ``flat_cost``: the cost barely rises along ``direction`` (``distance_m``, ``rise``,
///   ``across_rise``).
/// - ``few_inliers``: too few of the query's points matched (``fraction``,
///   ``trusted_from``).
/// - ``refinement_failed``: the pose is the grid's, unconfirmed (``reason``).
/// - ``on_window_edge``: the optimum lies on the window's edge.
/// - ``attitude_corrected``: the match tilts the scans beyond their readings (``tilt_deg``,
///   ``three_sigma_deg``).
/// - ``another_rotation``: another rotation compares almost as well (``angle_deg``, ``cost``,
///   ``best_cost``).
/// - ``unrefuted_rotation``: another rotation agrees as well where the scans overlap, but
///   overlaps less (``angle_deg``, ``overlap_fraction``, ``best_overlap_fraction``).
/// - ``seen_through``: a cheaper pose puts returns where the other scan saw through; the pose
///   is the best that does not (``distance_m``, ``cost``, ``seen_through_fraction``).
/// - ``free_space_conflict``: a quarter or more of the returns compared at the pose lie where
///   the other scan saw through (``seen_through_fraction``, ``trusted_below``).
/// - ``taken_from_prediction``: along a free direction the position is the prediction's
///   (``direction``, ``shift_m``).
/// - ``prior_conflict``: the scans alone fit a place far from the pose much better; the
///   prediction chose the pose (``distance_m``, ``cost``, ``best_cost``).
///
/// A figure reads as an attribute (``doubt.fraction``) or from ``doubt.figures``.
#[pyclass(module = "sdem", frozen)]
pub struct Doubt {
    kind: &'static str,
    message: String,
    /// The figures, without the kind.
    figures: Value,
}

impl Doubt {
    fn new(doubt: &RustDoubt) -> Self {
        let mut figures = doubt_json(doubt);
        if let Some(object) = figures.as_object_mut() {
            object.remove("kind");
            object.remove("message");
        }
        Self {
            kind: doubt.kind(),
            message: doubt.to_string(),
            figures,
        }
    }
}

/// One doubt as `sdem localize --json` writes it: its `kind` and figures (as the library
/// serializes it) and a `message` in words.
pub fn doubt_json(doubt: &RustDoubt) -> Value {
    let mut value = serde_json::to_value(doubt).unwrap_or_else(|_| json!({ "kind": doubt.kind() }));
    if let Some(object) = value.as_object_mut() {
        object.insert("message".into(), Value::String(doubt.to_string()));
    }
    value
}

/// The doubts as a list of `sdem.Doubt`.
pub fn doubt_list<'py>(py: Python<'py>, doubts: &[RustDoubt]) -> PyResult<Bound<'py, PyList>> {
    let items = doubts
        .iter()
        .map(|d| Py::new(py, Doubt::new(d)))
        .collect::<PyResult<Vec<_>>>()?;
    PyList::new(py, items)
}

#[pymethods]
impl Doubt {
    /// The kind, as the JSON's ``kind`` spells it (``"runner_up"``, ``"few_inliers"``, ...).
    #[getter]
    fn kind(&self) -> &'static str {
        self.kind
    }

    /// The doubt in words.
    #[getter]
    fn message(&self) -> &str {
        &self.message
    }

    /// The figures, a dict (empty for ``on_window_edge``).
    #[getter]
    fn figures<'py>(&self, py: Python<'py>) -> PyResult<Bound<'py, PyAny>> {
        to_python(py, &self.figures)
    }

    /// The doubt as ``sdem localize --json`` writes it: ``kind``, the figures, ``message``.
    fn to_dict<'py>(&self, py: Python<'py>) -> PyResult<Bound<'py, PyAny>> {
        let mut value = json!({ "kind": self.kind });
        if let (Some(object), Some(figures)) = (value.as_object_mut(), self.figures.as_object()) {
            object.extend(figures.clone());
            object.insert("message".into(), Value::String(self.message.clone()));
        }
        to_python(py, &value)
    }

    fn __getattr__<'py>(&self, py: Python<'py>, name: &str) -> PyResult<Bound<'py, PyAny>> {
        match self.figures.get(name) {
            Some(value) => to_python(py, value),
            None => Err(pyo3::exceptions::PyAttributeError::new_err(format!(
                "a {} doubt has no figure '{name}'",
                self.kind
            ))),
        }
    }

    fn __str__(&self) -> &str {
        &self.message
    }

    fn __repr__(&self) -> String {
        let figures = (self.figures.as_object().into_iter().flatten())
            .map(|(k, v)| format!(", {k}={v}"))
            .collect::<String>();
        format!("sdem.Doubt(kind='{}'{figures})", self.kind)
    }
}

/// The library's localization options with ``overrides`` laid over them, as a dict: every
/// ``LocalizeOptions`` field with its default (``sdem.localize(ref, qry, **options)`` takes
/// the same names).
///
/// Raises:
///     sdem.InvalidError: an unknown name or a value of the wrong type.
#[pyfunction]
#[pyo3(signature = (**overrides))]
pub fn localize_options<'py>(
    py: Python<'py>,
    overrides: Option<&Bound<'py, PyDict>>,
) -> PyResult<Bound<'py, PyAny>> {
    to_python(
        py,
        &localize_options_over(&LocalizeOptions::default(), overrides)?,
    )
}

/// The localization options matched to a scan's scale (``LocalizeOptions::for_scan``): the
/// step, truncation, compared points and refinement derived from its S-DEM, for a spinning
/// LiDAR (build the scans on ``grid=sdem.grid_for_scan(points)``), with ``overrides`` laid
/// over them. Pass the result on: ``sdem.localize(ref, qry, **options)``.
#[pyfunction]
#[pyo3(signature = (scan, **overrides))]
pub fn localize_options_for_scan<'py>(
    py: Python<'py>,
    scan: &Bound<'py, Scan>,
    overrides: Option<&Bound<'py, PyDict>>,
) -> PyResult<Bound<'py, PyAny>> {
    let base = LocalizeOptions::for_scan(scan.get().inner.sdem());
    to_python(py, &localize_options_over(&base, overrides)?)
}

/// The S-DEM grid matched to a scan (``SdemConfig::for_scan``), as a dict for ``sdem.Scan(...,
/// grid=...)``: the resolution at which a cell holds about one return, the band of elevations
/// the scanner covers, planes reaching as far as their neighbours. For a spinning LiDAR; the
/// default grid (1° x 1°) is the tilting laser range finder's.
///
/// Args:
///     points: ``(N, 3)`` float32 or float64, sensor frame, metres.
#[pyfunction]
pub fn grid_for_scan<'py>(
    py: Python<'py>,
    points: &Bound<'py, PyAny>,
) -> PyResult<Bound<'py, PyAny>> {
    let points: Vec<Point3<f64>> = points_from(points, "points")?;
    let grid = py.detach(|| SdemConfig::for_scan(&points));
    to_python(py, &grid)
}
