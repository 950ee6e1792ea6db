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

/// The keywords as JSON.
pub fn dict_json(dict: &Bound<'_, PyDict>, what: &str) -> PyResult<Value> {
    pythonize::depythonize::<Value>(dict.as_any()).map_err(|e| {
        invalid(format!(
            "{what}: a value is not a number, string, bool, list or dict: {e}"
        ))
    })
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
