//! # sdem-py — sdem from Python, numpy in and out
//!
//! The extension module `sdem._sdem` of the Python package `sdem` (built by maturin: `pip
//! install .` at the repository root). It converts and maps errors, nothing else: numpy arrays
//! `(N, 3)` of float32 or float64 become the library's points, keyword options become its
//! option structs field for field (through serde), results become 4×4 and 6×6 float64 arrays,
//! dicts and small classes, and every `sdem::Error` / `sdem_io::Error` becomes its
//! `sdem.*Error` (classes in `python/sdem/_errors.py`). Computations run without the GIL.
//!
//! The Python-facing documentation is in the docstrings here, the stubs
//! (`python/sdem/_sdem.pyi`) and `docs/python.md`; the tests are `tests/test_*.py` (pytest).

mod arrays;
mod errors;
mod localize;
mod options;
mod sim;
mod slam;

use pyo3::prelude::*;
use std::path::PathBuf;

/// Reads a point cloud file as the command line does: ``.ply``, ``.pcd`` (ascii, binary or
/// binary_compressed), ``.las`` / ``.laz`` (scale and offset applied), ``.xyz`` / ``.txt``
/// (x y z per line), KITTI ``.bin``, 3DTK ``.3d`` (centimetres, converted) or a raw ``.sweep``;
/// points with a NaN coordinate (no return) are skipped.
///
/// Args:
///     path: the file, a ``str`` or ``os.PathLike``.
///
/// Returns:
///     numpy.ndarray: ``(N, 3)`` float64, sensor frame, metres.
///
/// Raises:
///     sdem.FileError: the file cannot be read (an ``OSError``).
///     sdem.ParseError: malformed content, an unknown extension, no points, or coordinates
///         that are not metres (a ``ValueError``), naming the file and line.
#[pyfunction]
fn read_points<'py>(py: Python<'py>, path: PathBuf) -> PyResult<Bound<'py, PyAny>> {
    let points = py
        .detach(|| sdem_io::read_points(&path))
        .map_err(errors::io_error)?;
    Ok(arrays::points_array(py, &points, |p| [p.x, p.y, p.z]).into_any())
}

/// The default standard deviations of an attitude reading, degrees: ``(roll_pitch, yaw)``.
fn default_attitude_sigma_deg() -> (f64, f64) {
    let sigma = sdem::AttitudeSigma::default();
    (sigma.roll_pitch.to_degrees(), sigma.yaw.to_degrees())
}

#[pymodule]
fn _sdem(m: &Bound<'_, PyModule>) -> PyResult<()> {
    m.add_class::<localize::Scan>()?;
    m.add_class::<localize::Localization>()?;
    m.add_class::<localize::Doubt>()?;
    m.add_class::<slam::Slam>()?;
    m.add_class::<slam::Step>()?;
    m.add_class::<slam::Map>()?;
    m.add_class::<slam::Relocalization>()?;
    m.add_function(wrap_pyfunction!(localize::localize, m)?)?;
    m.add_function(wrap_pyfunction!(localize::localize_options, m)?)?;
    m.add_function(wrap_pyfunction!(localize::localize_options_for_scan, m)?)?;
    m.add_function(wrap_pyfunction!(localize::grid_for_scan, m)?)?;
    m.add_function(wrap_pyfunction!(slam::slam_options, m)?)?;
    m.add_function(wrap_pyfunction!(slam::slam_options_for_scan, m)?)?;
    m.add_function(wrap_pyfunction!(read_points, m)?)?;
    m.add("DEFAULT_ATTITUDE_SIGMA_DEG", default_attitude_sigma_deg())?;
    m.add("__version__", env!("CARGO_PKG_VERSION"))?;
    m.add_submodule(&sim::module(m.py())?)?;
    Ok(())
}
