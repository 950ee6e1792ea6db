//! The library's errors as Python exceptions: one class per `sdem::Error` variant and per
//! `sdem_io::Error` kind, defined in `sdem/_errors.py` (so that a file error can be an
//! `OSError` and bad input a `ValueError` as well as an `sdem.Error`), each carrying the
//! variant's fields as attributes.

use pyo3::exceptions::PyRuntimeError;
use pyo3::prelude::*;
use pyo3::types::PyList;
use pyo3::BoundObject;

/// The Python module that defines the exception classes.
const ERRORS_MODULE: &str = "sdem._errors";

/// An attribute's value, converted to Python when the exception is made.
type Attribute<'py> = (&'static str, Bound<'py, PyAny>);

/// An instance of `sdem.<class>` made with `args`, with `attributes` set on it.
fn instance<'py>(
    py: Python<'py>,
    class: &str,
    args: impl pyo3::call::PyCallArgs<'py>,
    attributes: Vec<Attribute<'py>>,
) -> PyResult<Bound<'py, PyAny>> {
    let exception = py.import(ERRORS_MODULE)?.getattr(class)?.call1(args)?;
    for (name, value) in attributes {
        exception.setattr(name, value)?;
    }
    Ok(exception)
}

/// `sdem.<class>(message)` with `attributes`, as a `PyErr`; a `RuntimeError` with the message
/// should the classes be missing (a damaged installation).
fn raise(py: Python<'_>, class: &str, message: String, attributes: Vec<Attribute<'_>>) -> PyErr {
    match instance(py, class, (message.clone(),), attributes) {
        Ok(exception) => PyErr::from_value(exception),
        Err(e) => PyRuntimeError::new_err(format!("{message} (and sdem.{class}: {e})")),
    }
}

/// `value` as a Python object (for attributes).
fn py_value<'py, T: IntoPyObject<'py>>(py: Python<'py>, value: T) -> Bound<'py, PyAny> {
    match value.into_pyobject(py) {
        Ok(v) => v.into_any().into_bound(),
        Err(_) => py.None().into_bound(py),
    }
}

/// The exception class and attributes of an `sdem::Error`.
fn sdem_exception<'py>(py: Python<'py>, error: &sdem::Error) -> Bound<'py, PyAny> {
    use sdem::Error as E;
    let message = error.to_string();
    let made = match error {
        E::Invalid(_) => instance(py, "InvalidError", (message,), vec![]),
        E::InvalidInput { what, problem } => instance(
            py,
            "InvalidInputError",
            (message,),
            vec![
                ("what", py_value(py, what)),
                ("problem", py_value(py, problem)),
            ],
        ),
        E::NoUsablePoints { reason } => instance(
            py,
            "NoUsablePointsError",
            (message,),
            vec![
                ("reason", py_value(py, reason)),
                ("usable", py_value(py, 0)),
                ("needed", py_value(py, sdem::scan::MIN_KNOWN_CELLS)),
            ],
        ),
        E::TooFewPoints { usable, needed } => instance(
            py,
            "TooFewPointsError",
            (message,),
            vec![
                ("usable", py_value(py, usable)),
                ("needed", py_value(py, needed)),
            ],
        ),
        E::NoOverlap {
            needed,
            compared,
            max_cost_m2,
        } => instance(
            py,
            "NoOverlapError",
            (message,),
            vec![
                ("needed", py_value(py, needed)),
                ("compared", py_value(py, compared)),
                ("max_cost_m2", py_value(py, max_cost_m2)),
            ],
        ),
        E::TooManyCandidates {
            candidates,
            grid,
            limit,
        } => instance(
            py,
            "TooManyCandidatesError",
            (message,),
            vec![
                ("candidates", py_value(py, candidates)),
                ("grid", py_value(py, grid.to_vec())),
                ("limit", py_value(py, limit)),
            ],
        ),
        E::NoMatch {
            matched,
            compared,
            needed,
            truncation_m,
        } => instance(
            py,
            "NoMatchError",
            (message,),
            vec![
                ("matched", py_value(py, matched)),
                ("compared", py_value(py, compared)),
                ("needed", py_value(py, needed)),
                ("truncation_m", py_value(py, truncation_m)),
            ],
        ),
        E::NoSurfaces { which } => instance(
            py,
            "NoSurfacesError",
            (message,),
            vec![("which", py_value(py, *which))],
        ),
        E::RefinementFailed { reason } => instance(
            py,
            "RefinementFailedError",
            (message,),
            vec![("reason", py_value(py, reason))],
        ),
        E::NotFound { tried } => instance(
            py,
            "NotFoundError",
            (message,),
            vec![("tried", py_value(py, tried.clone()))],
        ),
        E::NodeStore { node_id, reason } => instance(
            py,
            "NodeStoreError",
            (message,),
            vec![
                ("node_id", py_value(py, *node_id)),
                ("reason", py_value(py, reason)),
            ],
        ),
        E::AtScan {
            scan_index,
            nodes,
            source,
        } => at_scan(py, message, *scan_index, nodes, source),
    };
    made.unwrap_or_else(|e| {
        PyRuntimeError::new_err(format!("{error} (and the exception class: {e})"))
            .into_value(py)
            .into_bound(py)
            .into_any()
    })
}

/// `AtScanError` with its cause: the step's own error, as `source` and `__cause__`.
fn at_scan<'py>(
    py: Python<'py>,
    message: String,
    scan_index: usize,
    nodes: &[usize],
    source: &sdem::Error,
) -> PyResult<Bound<'py, PyAny>> {
    let cause = sdem_exception(py, source);
    let exception = instance(
        py,
        "AtScanError",
        (message,),
        vec![
            ("scan_index", py_value(py, scan_index)),
            ("nodes", PyList::new(py, nodes)?.into_any()),
            ("is_no_match", py_value(py, source.is_no_match())),
            ("source", cause.clone()),
        ],
    )?;
    exception.setattr("__cause__", cause)?;
    Ok(exception)
}

/// An `sdem::Error` as its `sdem.*Error`.
pub fn sdem_error(error: sdem::Error) -> PyErr {
    Python::attach(|py| PyErr::from_value(sdem_exception(py, &error)))
}

/// An `sdem_io::Error` as `sdem.FileError` (an `OSError` with `errno`, `strerror` and
/// `filename`), `sdem.ParseError` (a `ValueError` with `path`, `line` and `message`),
/// `sdem.InvalidError`, or the algorithms' error it passes on.
pub fn io_error(error: sdem_io::Error) -> PyErr {
    Python::attach(|py| match error {
        sdem_io::Error::Io { path, source, hint } => file_error(py, &path, &source, &hint),
        sdem_io::Error::Parse {
            ref path,
            line,
            ref message,
        } => raise(
            py,
            "ParseError",
            error.to_string(),
            vec![
                ("path", py_value(py, path.display().to_string())),
                ("line", py_value(py, line)),
                ("message", py_value(py, message)),
            ],
        ),
        sdem_io::Error::Invalid(message) => raise(py, "InvalidError", message, vec![]),
        sdem_io::Error::Sdem(e) => PyErr::from_value(sdem_exception(py, &e)),
    })
}

/// `sdem.FileError(errno, strerror, filename)` as `OSError` makes it, so that `errno` and
/// `filename` read as for any `OSError`; without an operating-system code, the message alone
/// with `filename` set.
fn file_error(
    py: Python<'_>,
    path: &std::path::Path,
    source: &std::io::Error,
    hint: &str,
) -> PyErr {
    let filename = path.display().to_string();
    let made = match source.raw_os_error() {
        // The system's words, then what they leave out (a missing folder, a folder for a
        // file, a full disk), as the command line says it.
        Some(errno) => py
            .import("os")
            .and_then(|os| os.call_method1("strerror", (errno,)))
            .and_then(|text| text.extract::<String>())
            .and_then(|text| {
                let text = format!("{text}{hint}");
                instance(py, "FileError", (errno, text, filename.clone()), vec![])
            }),
        None => instance(
            py,
            "FileError",
            (format!("{filename}: {source}{hint}"),),
            vec![("filename", py_value(py, filename.clone()))],
        ),
    };
    match made {
        Ok(exception) => PyErr::from_value(exception),
        Err(e) => {
            PyRuntimeError::new_err(format!("{filename}: {source} (and sdem.FileError: {e})"))
        }
    }
}

/// `sdem.InvalidInputError` for an argument that cannot be used: `what` it is and the problem.
pub fn invalid_input(what: &str, problem: impl Into<String>) -> PyErr {
    sdem_error(sdem::Error::InvalidInput {
        what: what.into(),
        problem: problem.into(),
    })
}

/// `sdem.InvalidError` for options that cannot be used.
pub fn invalid(message: impl Into<String>) -> PyErr {
    sdem_error(sdem::Error::Invalid(message.into()))
}
