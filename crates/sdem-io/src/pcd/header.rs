//! The PCD header: its `KEY values` lines up to `DATA`, checked, and where `x`, `y`, `z` sit in
//! a point.

use crate::error::{Error, Result};
use crate::parse_count;
use std::path::Path;

/// One field of a PCD point.
#[derive(Debug, Clone)]
pub(super) struct Field {
    name: String,
    size: usize,
    kind: char,
    pub(super) count: usize,
}

/// Where x, y, z sit inside a point: `(byte offset in a binary point, token index in an ASCII
/// line, size in bytes)`.
pub(super) type AxisLayout = [(usize, usize, usize); 3];

#[derive(Debug, Default)]
pub(super) struct PcdHeader {
    fields: Option<Vec<String>>,
    sizes: Option<Vec<usize>>,
    types: Option<Vec<char>>,
    counts: Option<Vec<usize>>,
    width: Option<usize>,
    height: Option<usize>,
    points: Option<usize>,
    data: Option<String>,
    /// `VIEWPOINT tx ty tz qw qx qy qz`: where the sensor stood in the points' frame.
    pub(super) viewpoint: Option<nalgebra::Isometry3<f64>>,
    /// The 1-based lines of `WIDTH`, `POINTS` and `DATA`, to name in errors.
    width_line: Option<usize>,
    points_line: Option<usize>,
    data_line: Option<usize>,
}

/// What [`check_header`] returns: the fields, the point count with the line that declares it
/// (`POINTS`, else `WIDTH`), and the data mode with its line.
pub(super) struct Layout {
    pub(super) fields: Vec<Field>,
    pub(super) point_count: usize,
    pub(super) count_line: Option<usize>,
    pub(super) data: String,
    pub(super) data_line: Option<usize>,
}

impl Layout {
    /// The bytes of one point: every field's `SIZE × COUNT`. Sizes are at most 8 and counts at
    /// most 2^20, so the sum cannot overflow in practice; checked anyway.
    pub(super) fn point_bytes(&self) -> usize {
        self.fields
            .iter()
            .try_fold(0usize, |acc, f| {
                acc.checked_add(f.size.checked_mul(f.count)?)
            })
            .unwrap_or(usize::MAX)
    }
}

/// Reads header lines up to and including `DATA`. Returns the header, the byte offset where the
/// data starts and the number of header lines.
pub(super) fn parse_header(path: &Path, bytes: &[u8]) -> Result<(PcdHeader, usize, usize)> {
    let mut header = PcdHeader::default();
    let mut start = 0usize;
    let mut line_no = 0usize;
    while start < bytes.len() {
        let (raw, end) = crate::line_from(bytes, start);
        line_no += 1;
        start = end;
        let line = std::str::from_utf8(raw).map_err(|_| {
            Error::parse(
                path,
                Some(line_no),
                "the PCD header is not text; the file is damaged or not a PCD file",
            )
        })?;
        let line = line.trim();
        if line.is_empty() || line.starts_with('#') {
            continue;
        }
        let mut tokens = line.split_whitespace();
        let key = tokens.next().unwrap_or_default();
        let values: Vec<&str> = tokens.collect();
        if header.take(path, line_no, key, &values)? {
            return Ok((header, start, line_no));
        }
    }
    Err(Error::parse(
        path,
        Some(line_no.max(1)),
        "the file ends here, inside the PCD header, which has no DATA line; the file is truncated \
         or not a PCD file",
    ))
}

impl PcdHeader {
    /// Takes header line `line_no`, `key values…`; true at `DATA`, the header's last line.
    fn take(&mut self, path: &Path, line_no: usize, key: &str, values: &[&str]) -> Result<bool> {
        let bad = |message: String| Error::parse(path, Some(line_no), message);
        let duplicate = || bad(format!("{key} appears twice in the header"));
        let single = |what: &str| -> Result<usize> {
            match values {
                [v] => parse_count(path, line_no, v, what),
                _ => Err(bad(format!("{key} needs exactly one value"))),
            }
        };
        match key {
            "FIELDS" => {
                if self.fields.is_some() {
                    return Err(duplicate());
                }
                self.fields = Some(values.iter().map(|s| s.to_string()).collect());
            }
            "SIZE" => {
                if self.sizes.is_some() {
                    return Err(duplicate());
                }
                self.sizes = Some(parse_sizes(path, line_no, values)?);
            }
            "TYPE" => {
                if self.types.is_some() {
                    return Err(duplicate());
                }
                self.types = Some(parse_types(path, line_no, values)?);
            }
            "COUNT" => {
                if self.counts.is_some() {
                    return Err(duplicate());
                }
                self.counts = Some(parse_counts(path, line_no, values)?);
            }
            "WIDTH" => {
                if self.width.is_some() {
                    return Err(duplicate());
                }
                self.width = Some(single("WIDTH")?);
                self.width_line = Some(line_no);
            }
            "HEIGHT" => {
                if self.height.is_some() {
                    return Err(duplicate());
                }
                self.height = Some(single("HEIGHT")?);
            }
            "POINTS" => {
                if self.points.is_some() {
                    return Err(duplicate());
                }
                self.points = Some(single("POINTS")?);
                self.points_line = Some(line_no);
            }
            "DATA" => {
                let [mode] = values else {
                    return Err(bad(
                        "DATA needs exactly one value: ascii, binary or binary_compressed".into(),
                    ));
                };
                self.data = Some(mode.to_string());
                self.data_line = Some(line_no);
                return Ok(true);
            }
            "VIEWPOINT" => {
                if self.viewpoint.is_some() {
                    return Err(duplicate());
                }
                self.viewpoint = Some(parse_viewpoint(path, line_no, values)?);
            }
            // VERSION and keys of later PCD versions do not change x, y, z.
            _ => {}
        }
        Ok(false)
    }
}

/// The pose of a `VIEWPOINT` line: translation `tx ty tz`, then the quaternion `qw qx qy qz`
/// (PCL's order), which must be a unit quaternion.
fn parse_viewpoint(
    path: &Path,
    line_no: usize,
    values: &[&str],
) -> Result<nalgebra::Isometry3<f64>> {
    let bad = |message: String| Error::parse(path, Some(line_no), message);
    if values.len() != 7 {
        return Err(bad(format!(
            "VIEWPOINT needs 7 numbers (tx ty tz qw qx qy qz), found {}",
            values.len()
        )));
    }
    let mut v = [0f64; 7];
    for (value, token) in v.iter_mut().zip(values) {
        *value = token
            .parse::<f64>()
            .ok()
            .filter(|x| x.is_finite())
            .ok_or_else(|| bad(format!("VIEWPOINT value '{token}' is not a finite number")))?;
    }
    let q = nalgebra::Quaternion::new(v[3], v[4], v[5], v[6]);
    if (q.norm() - 1.0).abs() > 1e-3 {
        return Err(bad(format!(
            "VIEWPOINT's quaternion (qw qx qy qz) = ({}, {}, {}, {}) has length {:.4}, not 1",
            v[3],
            v[4],
            v[5],
            v[6],
            q.norm()
        )));
    }
    Ok(nalgebra::Isometry3::from_parts(
        nalgebra::Translation3::new(v[0], v[1], v[2]),
        nalgebra::UnitQuaternion::from_quaternion(q),
    ))
}

/// The values of a `SIZE` line: 1, 2, 4 or 8 bytes each.
fn parse_sizes(path: &Path, line_no: usize, values: &[&str]) -> Result<Vec<usize>> {
    let mut sizes = Vec::new();
    for v in values {
        match *v {
            "1" | "2" | "4" | "8" => sizes.push(parse_count(path, line_no, v, "SIZE")?),
            _ => {
                return Err(Error::parse(
                    path,
                    Some(line_no),
                    format!("SIZE '{v}' must be 1, 2, 4 or 8"),
                ))
            }
        }
    }
    Ok(sizes)
}

/// The values of a `TYPE` line: `F`, `I` or `U` each.
fn parse_types(path: &Path, line_no: usize, values: &[&str]) -> Result<Vec<char>> {
    let mut types = Vec::new();
    for v in values {
        match *v {
            "F" => types.push('F'),
            "I" => types.push('I'),
            "U" => types.push('U'),
            _ => {
                return Err(Error::parse(
                    path,
                    Some(line_no),
                    format!("TYPE '{v}' must be F, I or U"),
                ))
            }
        }
    }
    Ok(types)
}

/// The values of a `COUNT` line: each in 1..=2^20.
fn parse_counts(path: &Path, line_no: usize, values: &[&str]) -> Result<Vec<usize>> {
    let mut counts = Vec::new();
    for v in values {
        let c = parse_count(path, line_no, v, "COUNT")?;
        if c == 0 || c > 1 << 20 {
            return Err(Error::parse(
                path,
                Some(line_no),
                format!("COUNT {c} must lie in 1..=1048576"),
            ));
        }
        counts.push(c);
    }
    Ok(counts)
}

/// Checks the header's consistency; returns the fields, the point count and the data mode.
pub(super) fn check_header(path: &Path, header: PcdHeader) -> Result<Layout> {
    let bad = |message: String| Error::parse(path, None, message);
    let names = header
        .fields
        .ok_or_else(|| bad("the PCD header has no FIELDS line".into()))?;
    if names.is_empty() {
        return Err(bad("FIELDS lists no fields".into()));
    }
    let sizes = header
        .sizes
        .ok_or_else(|| bad("the PCD header has no SIZE line".into()))?;
    let types = header
        .types
        .ok_or_else(|| bad("the PCD header has no TYPE line".into()))?;
    let counts = header.counts.unwrap_or_else(|| vec![1; names.len()]);
    if sizes.len() != names.len() || types.len() != names.len() || counts.len() != names.len() {
        return Err(bad(format!(
            "FIELDS has {} entries but SIZE has {}, TYPE {} and COUNT {}; they must match",
            names.len(),
            sizes.len(),
            types.len(),
            counts.len()
        )));
    }
    let mut fields = Vec::with_capacity(names.len());
    for (((name, size), kind), count) in names.into_iter().zip(sizes).zip(types).zip(counts) {
        if kind == 'F' && size != 4 && size != 8 {
            return Err(bad(format!(
                "field '{name}' is TYPE F with SIZE {size}; floating-point fields have SIZE 4 or 8"
            )));
        }
        fields.push(Field {
            name,
            size,
            kind,
            count,
        });
    }
    let from_size = match (header.width, header.height) {
        (Some(w), Some(h)) => Some(w.checked_mul(h).ok_or_else(|| {
            Error::parse(
                path,
                header.width_line,
                format!("WIDTH {w} × HEIGHT {h} overflows"),
            )
        })?),
        (Some(w), None) => Some(w),
        (None, _) => None,
    };
    let count_line = header.points_line.or(header.width_line);
    let points =
        match (header.points, from_size) {
            (Some(p), Some(s)) if p != s => {
                return Err(Error::parse(
                    path,
                    count_line,
                    format!("POINTS {p} disagrees with WIDTH × HEIGHT = {s}; fix the header"),
                ))
            }
            (Some(p), _) => p,
            (None, Some(s)) => s,
            (None, None) => return Err(bad(
                "the PCD header has neither POINTS nor WIDTH; sdem cannot tell how many points \
                 follow"
                    .into(),
            )),
        };
    Ok(Layout {
        fields,
        point_count: points,
        count_line,
        data: header.data.unwrap_or_default(),
        data_line: header.data_line,
    })
}

/// Finds x, y, z among the fields.
pub(super) fn axis_layout(path: &Path, fields: &[Field]) -> Result<AxisLayout> {
    let mut layout = [(0usize, 0usize, 0usize); 3];
    for (axis, slot) in ["x", "y", "z"].iter().zip(layout.iter_mut()) {
        let mut offset = 0usize;
        let mut token = 0usize;
        let mut found = false;
        for f in fields {
            if f.name == *axis {
                if f.kind != 'F' || f.count != 1 {
                    return Err(Error::parse(
                        path,
                        None,
                        format!(
                            "field '{axis}' is TYPE {} COUNT {}; sdem reads x, y, z as TYPE F \
                             (SIZE 4 or 8) with COUNT 1",
                            f.kind, f.count
                        ),
                    ));
                }
                *slot = (offset, token, f.size);
                found = true;
                break;
            }
            offset = offset.saturating_add(f.size.saturating_mul(f.count));
            token = token.saturating_add(f.count);
        }
        if !found {
            return Err(Error::parse(
                path,
                None,
                format!("the PCD file has no field '{axis}'; sdem needs x, y and z"),
            ));
        }
    }
    Ok(layout)
}
