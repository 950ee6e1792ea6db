//! numpy arrays in and out: points, poses, covariances and short vectors, each checked with a
//! message that says what was expected.

use crate::errors::invalid_input;
use nalgebra::{Isometry3, Matrix3, Matrix6, Point3, Translation3, UnitQuaternion};
use numpy::ndarray::{Array2, Array3};
use numpy::{
    dtype, IntoPyArray, PyArray1, PyArray2, PyArrayDescrMethods, PyArrayMethods, PyUntypedArray,
    PyUntypedArrayMethods,
};
use pyo3::prelude::*;

/// How far a given rotation may be from orthonormal (`RᵀR − I`, largest entry) and a
/// homogeneous matrix's last row from `[0, 0, 0, 1]`: sdem-io's pose files accept the same.
const ROTATION_TOLERANCE: f64 = 1e-3;

/// `obj` as a numpy array: an array as it is, anything else through `numpy.asarray(obj,
/// dtype=float64)` (lists and tuples of numbers).
fn as_array<'py>(obj: &Bound<'py, PyAny>, what: &str) -> PyResult<Bound<'py, PyUntypedArray>> {
    if let Ok(array) = obj.cast::<PyUntypedArray>() {
        return Ok(array.clone());
    }
    let py = obj.py();
    let converted = py
        .import("numpy")?
        .call_method1("asarray", (obj, "float64"))
        .map_err(|e| {
            invalid_input(
                what,
                format!(
                    "expected a numpy array or a sequence of numbers, got {} ({e})",
                    type_name(obj)
                ),
            )
        })?;
    Ok(converted.cast_into::<PyUntypedArray>()?)
}

/// The Python type name of `obj`, for messages.
fn type_name(obj: &Bound<'_, PyAny>) -> String {
    obj.get_type()
        .name()
        .map(|n| n.to_string())
        .unwrap_or_else(|_| "an object".into())
}

/// Points from an `(N, 3)` array of `float32` or `float64` (metres, sensor frame), in any
/// memory order. The one copy the library needs: it takes `Point3<f64>` values, `float32` must
/// be widened anyway, and a copy made with the GIL held cannot be changed by another Python
/// thread while the computation runs without it.
pub fn points_from(obj: &Bound<'_, PyAny>, what: &str) -> PyResult<Vec<Point3<f64>>> {
    let array = as_array(obj, what)?;
    let shape = array.shape().to_vec();
    if shape.len() != 2 || shape[1] != 3 {
        return Err(invalid_input(
            what,
            format!(
                "expected an (N, 3) array of points (x, y, z in metres, sensor frame), got shape \
                 {}",
                shape_text(&shape)
            ),
        ));
    }
    let py = obj.py();
    let kind = array.dtype();
    if kind.is_equiv_to(&dtype::<f64>(py)) {
        let typed = array.cast::<PyArray2<f64>>()?.readonly();
        Ok(typed
            .as_array()
            .rows()
            .into_iter()
            .map(|r| Point3::new(r[0], r[1], r[2]))
            .collect())
    } else if kind.is_equiv_to(&dtype::<f32>(py)) {
        let typed = array.cast::<PyArray2<f32>>()?.readonly();
        Ok(typed
            .as_array()
            .rows()
            .into_iter()
            .map(|r| Point3::new(r[0] as f64, r[1] as f64, r[2] as f64))
            .collect())
    } else {
        Err(invalid_input(
            what,
            format!(
                "expected float32 or float64 coordinates in metres, got dtype {}; convert with \
                 points.astype(numpy.float64) if the values are metres",
                kind.str().map(|s| s.to_string()).unwrap_or_default()
            ),
        ))
    }
}

/// A shape as Python prints it: `(5,)`, `(5, 2)`.
fn shape_text(shape: &[usize]) -> String {
    match shape {
        [n] => format!("({n},)"),
        _ => format!(
            "({})",
            shape
                .iter()
                .map(|n| n.to_string())
                .collect::<Vec<_>>()
                .join(", ")
        ),
    }
}

/// `N` finite numbers from a sequence or a 1-D array of `N`.
pub fn numbers<const N: usize>(obj: &Bound<'_, PyAny>, what: &str) -> PyResult<[f64; N]> {
    let array = obj
        .py()
        .import("numpy")?
        .call_method1("asarray", (obj, "float64"))
        .map_err(|_| {
            invalid_input(
                what,
                format!("expected {N} numbers, got {}", type_name(obj)),
            )
        })?
        .cast_into::<PyUntypedArray>()?;
    if array.shape() != [N] {
        return Err(invalid_input(
            what,
            format!(
                "expected {N} numbers, got shape {}",
                shape_text(array.shape())
            ),
        ));
    }
    let values = array
        .cast::<PyArray1<f64>>()?
        .readonly()
        .as_array()
        .to_vec();
    let values: [f64; N] = values.try_into().expect("the shape was checked");
    if let Some(bad) = values.iter().find(|v| !v.is_finite()) {
        return Err(invalid_input(
            what,
            format!("{values:?} holds {bad}; every value must be a finite number"),
        ));
    }
    Ok(values)
}

/// A rigid transform from a 4×4 homogeneous matrix: its rotation must be orthonormal within
/// [`ROTATION_TOLERANCE`] (and is re-orthonormalized), its last row `[0, 0, 0, 1]`.
pub fn pose_from(obj: &Bound<'_, PyAny>, what: &str) -> PyResult<Isometry3<f64>> {
    let array = as_array(obj, what)?;
    let shape = array.shape().to_vec();
    if shape != [4, 4] {
        return Err(invalid_input(
            what,
            format!(
                "expected a 4x4 homogeneous transform, got shape {}",
                shape_text(&shape)
            ),
        ));
    }
    let array = obj
        .py()
        .import("numpy")?
        .call_method1("asarray", (array, "float64"))?
        .cast_into::<PyArray2<f64>>()?;
    let m = array.readonly().as_array().to_owned();
    if m.iter().any(|v| !v.is_finite()) {
        return Err(invalid_input(what, "every entry must be a finite number"));
    }
    let last_row = [m[[3, 0]], m[[3, 1]], m[[3, 2]], m[[3, 3]] - 1.0];
    if last_row.iter().any(|v| v.abs() > ROTATION_TOLERANCE) {
        return Err(invalid_input(
            what,
            format!(
                "the last row is {:?}; a rigid transform's is [0, 0, 0, 1]",
                [m[[3, 0]], m[[3, 1]], m[[3, 2]], m[[3, 3]]]
            ),
        ));
    }
    let rotation = Matrix3::from_fn(|i, j| m[[i, j]]);
    let off = (rotation.transpose() * rotation - Matrix3::identity())
        .abs()
        .max();
    if off > ROTATION_TOLERANCE || rotation.determinant() <= 0.0 {
        return Err(invalid_input(
            what,
            format!(
                "the upper-left 3x3 block is not a rotation (RᵀR differs from the identity by \
                 {off:.1e}, determinant {:.3}); give a rigid transform",
                rotation.determinant()
            ),
        ));
    }
    let rotation = UnitQuaternion::from_matrix(&rotation);
    let translation = Translation3::new(m[[0, 3]], m[[1, 3]], m[[2, 3]]);
    Ok(Isometry3::from_parts(translation, rotation))
}

/// A pose as a 4×4 homogeneous `float64` array.
pub fn matrix4<'py>(py: Python<'py>, pose: &Isometry3<f64>) -> Bound<'py, PyArray2<f64>> {
    let m = pose.to_homogeneous();
    Array2::from_shape_fn((4, 4), |(i, j)| m[(i, j)]).into_pyarray(py)
}

/// Poses as an `(n, 4, 4)` `float64` array.
pub fn matrices4<'py>(py: Python<'py>, poses: &[Isometry3<f64>]) -> Bound<'py, PyAny> {
    let homogeneous: Vec<_> = poses.iter().map(|p| p.to_homogeneous()).collect();
    Array3::from_shape_fn((poses.len(), 4, 4), |(k, i, j)| homogeneous[k][(i, j)])
        .into_pyarray(py)
        .into_any()
}

/// A 6×6 matrix as a `float64` array.
pub fn matrix6<'py>(py: Python<'py>, m: &Matrix6<f64>) -> Bound<'py, PyArray2<f64>> {
    Array2::from_shape_fn((6, 6), |(i, j)| m[(i, j)]).into_pyarray(py)
}

/// Points (any float triple) as an `(N, 3)` `float64` array.
pub fn points_array<'py, P, F>(py: Python<'py>, points: &[P], xyz: F) -> Bound<'py, PyArray2<f64>>
where
    F: Fn(&P) -> [f64; 3],
{
    let mut flat = Vec::with_capacity(points.len() * 3);
    for p in points {
        flat.extend_from_slice(&xyz(p));
    }
    Array2::from_shape_vec((points.len(), 3), flat)
        .expect("three coordinates a point")
        .into_pyarray(py)
}

/// A count or seed given as a Python int: refused, naming `what`, when negative (pyo3's own
/// conversion raises a bare `OverflowError` that names nothing).
pub fn non_negative(value: i64, what: &str) -> PyResult<u64> {
    u64::try_from(value).map_err(|_| {
        crate::errors::invalid_input(what, format!("{value} is negative; give 0 or more"))
    })
}
