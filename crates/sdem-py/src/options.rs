//! Keyword options, name for name with the library's option structs: the struct's value (its
//! defaults, or options derived from a scan) serialized, the keywords laid over it (a dict
//! given for a nested struct changes only the fields it names), and the result read back
//! through serde, which checks every type.

use crate::errors::invalid;
use pyo3::prelude::*;
use pyo3::types::PyDict;
use serde::de::DeserializeOwned;
use serde::Serialize;
use serde_json::{Map, Value};

/// `base` with `overrides` laid over it; `what` names the options in messages
/// (`"localize options"`).
///
/// # Errors
/// `sdem.InvalidError` for a name the struct does not have (listing those it has) or a value
/// of the wrong type.
pub fn with_overrides<T: Serialize + DeserializeOwned>(
    base: &T,
    overrides: Option<&Bound<'_, PyDict>>,
    what: &str,
) -> PyResult<T> {
    let Some(overrides) = overrides else {
        return clone_through_json(base, what);
    };
    let mut value = to_json(base, what)?;
    merge(&mut value, dict_json(overrides, what)?, what, "")?;
    serde_json::from_value(value).map_err(|e| invalid(format!("{what}: {e}")))
}

/// The keywords as JSON. numpy scalars and arrays count as the numbers and lists they hold
/// (robotics code builds windows and offsets with numpy); a number that is not finite, or a
/// value of another type, is an error naming the option.
pub fn dict_json(dict: &Bound<'_, PyDict>, what: &str) -> PyResult<Value> {
    let plain = plain(dict.as_any(), what, "")?;
    pythonize::depythonize::<Value>(&plain).map_err(|e| {
        invalid(format!(
            "{what}: a value is not a number, string, bool, list or dict: {e}"
        ))
    })
}

/// `value` (the option at `path`) with numpy's scalars and arrays turned into Python numbers
/// and lists, checked to be finite where it is a number.
fn plain<'py>(value: &Bound<'py, PyAny>, what: &str, path: &str) -> PyResult<Bound<'py, PyAny>> {
    use pyo3::types::{PyBool, PyFloat, PyInt, PyList, PyString, PyTuple};
    let py = value.py();
    let at = |key: &str| {
        if path.is_empty() {
            key.to_string()
        } else {
            format!("{path}.{key}")
        }
    };
    if value.is_none() || value.is_instance_of::<PyBool>() || value.is_instance_of::<PyString>() {
        return Ok(value.clone());
    }
    if value.is_instance_of::<PyInt>() {
        return Ok(value.clone());
    }
    if let Ok(f) = value.cast::<PyFloat>() {
        let v = f.value();
        if !v.is_finite() {
            return Err(invalid(format!(
                "{what}: {} is {v}; it must be a finite number",
                if path.is_empty() { "a value" } else { path }
            )));
        }
        return Ok(value.clone());
    }
    if let Ok(dict) = value.cast::<PyDict>() {
        let out = PyDict::new(py);
        for (k, v) in dict.iter() {
            let key = k.str().map(|s| s.to_string()).unwrap_or_default();
            out.set_item(&k, plain(&v, what, &at(&key))?)?;
        }
        return Ok(out.into_any());
    }
    if value.is_instance_of::<PyList>() || value.is_instance_of::<PyTuple>() {
        let items: Vec<Bound<'py, PyAny>> = (value.try_iter()?)
            .enumerate()
            .map(|(i, item)| plain(&item?, what, &format!("{path}[{i}]")))
            .collect::<PyResult<_>>()?;
        return Ok(PyList::new(py, items)?.into_any());
    }
    // numpy: an array's or a scalar's own Python form.
    if value.hasattr("tolist")? {
        let listed = value.call_method0("tolist")?;
        if !listed.is(value) {
            return plain(&listed, what, path);
        }
    }
    Err(invalid(format!(
        "{what}: {} is a {}; give a number, string, bool, list or dict",
        if path.is_empty() { "a value" } else { path },
        value.get_type().name()?
    )))
}

/// `base` read back from its own serialization (so that fields serde skips take their
/// defaults, as they do when keywords are given).
fn clone_through_json<T: Serialize + DeserializeOwned>(base: &T, what: &str) -> PyResult<T> {
    serde_json::from_value(to_json(base, what)?).map_err(|e| invalid(format!("{what}: {e}")))
}

/// `value` serialized.
pub fn to_json<T: Serialize>(value: &T, what: &str) -> PyResult<Value> {
    serde_json::to_value(value).map_err(|e| invalid(format!("{what}: cannot encode: {e}")))
}

/// `value` as a Python object, as its JSON reads (dicts, lists, numbers, strings, `None`:
/// fixed-size arrays become lists, as they are given).
pub fn to_python<'py, T: Serialize>(py: Python<'py>, value: &T) -> PyResult<Bound<'py, PyAny>> {
    let value = to_json(value, "a result")?;
    pythonize::pythonize(py, &value).map_err(|e| invalid(format!("cannot convert to Python: {e}")))
}

/// Lays `overrides` over `base`: a dict over a struct field merges field by field, any other
/// value replaces; a name `base` lacks is an error naming the names it has.
fn merge(base: &mut Value, overrides: Value, what: &str, path: &str) -> PyResult<()> {
    let (Value::Object(fields), Value::Object(given)) = (&mut *base, &overrides) else {
        *base = overrides;
        return Ok(());
    };
    for (name, value) in given {
        let full = if path.is_empty() {
            name.clone()
        } else {
            format!("{path}.{name}")
        };
        let Some(field) = fields.get_mut(name) else {
            return Err(unknown(what, &full, fields));
        };
        merge(field, value.clone(), what, &full)?;
    }
    Ok(())
}

/// The error for an unknown option name.
fn unknown(what: &str, name: &str, fields: &Map<String, Value>) -> PyErr {
    let known: Vec<&str> = fields.keys().map(String::as_str).collect();
    invalid(format!(
        "{what}: no option '{name}'; the options here are: {}",
        known.join(", ")
    ))
}
