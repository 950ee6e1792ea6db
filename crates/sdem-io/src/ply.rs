//! PLY point clouds: ASCII and binary reading through `ply-rs-bw`, binary little-endian writing.
//!
//! `ply-rs-bw` parses the header and the binary payload. Before it sees a file, the header is
//! pre-checked here for what the crate does not guard against (a count too large for 64 bits
//! panics inside its grammar; repeated property names silently shift the binary layout), and the
//! declared element counts are checked against the bytes that follow, so a lying header is an
//! error before anything is allocated; data left after the declared elements is an error too
//! (as in PCD and `.sweep`), since reading only the declared count would drop points silently.
//! The ASCII payload is read here, to report line numbers and to accept the `nan` that scanners
//! write for "no return".

use super::{check_points_writable, fmt_point, read_bytes, write_atomic};
use crate::error::{one_line, Error, Result};
use ply_rs_bw::parser::Parser;
use ply_rs_bw::ply::{
    ElementDef, Encoding, Header, Property, PropertyAccess, PropertyType, ScalarType,
};
use sdem::geometry::Vec3;
use std::collections::{HashMap, HashSet};
use std::path::Path;

/// Headers longer than this are rejected (real ones are a few hundred bytes).
const MAX_HEADER_BYTES: usize = 1 << 20;

/// The vertex element as sdem reads it: x, y, z, everything else dropped.
#[derive(Debug, Default, Clone, Copy)]
struct XyzVertex {
    xyz: [f64; 3],
}

impl PropertyAccess for XyzVertex {
    fn new() -> Self {
        Self::default()
    }

    fn set_property(&mut self, property_name: String, property: Property) {
        let (Some(axis), value) = (axis_of(&property_name), property) else {
            return;
        };
        let value = match value {
            Property::Float(v) => f64::from(v),
            Property::Double(v) => v,
            _ => return, // types are checked against the header before reading
        };
        if let Some(slot) = self.xyz.get_mut(axis) {
            *slot = value;
        }
    }
}

/// An element sdem skips: every property is dropped.
struct Skip;

impl PropertyAccess for Skip {
    fn new() -> Self {
        Skip
    }
}

fn axis_of(name: &str) -> Option<usize> {
    match name {
        "x" => Some(0),
        "y" => Some(1),
        "z" => Some(2),
        _ => None,
    }
}

fn scalar_size(t: &ScalarType) -> usize {
    match t {
        ScalarType::Char | ScalarType::UChar => 1,
        ScalarType::Short | ScalarType::UShort => 2,
        ScalarType::Int | ScalarType::UInt | ScalarType::Float => 4,
        ScalarType::Double => 8,
    }
}

/// The fewest bytes one element can take in a binary payload.
fn min_element_bytes(def: &ElementDef) -> usize {
    def.properties
        .values()
        .map(|p| match &p.data_type {
            PropertyType::Scalar(t) => scalar_size(t),
            // The list's length; the list itself may be empty.
            PropertyType::List(index, _) => scalar_size(index),
        })
        .sum()
}

/// What [`precheck_header`] learns: the byte length of the header (through the `end_header`
/// line), its line count, and the 1-based line that declares each element.
struct HeaderLayout {
    len: usize,
    lines: usize,
    element_lines: HashMap<String, usize>,
}

impl HeaderLayout {
    /// The line that declares element `name`.
    fn element_line(&self, name: &str) -> Option<usize> {
        self.element_lines.get(name).copied()
    }
}

/// Checks the header's lines for what `ply-rs-bw` does not guard against and finds its end.
fn precheck_header(path: &Path, bytes: &[u8]) -> Result<HeaderLayout> {
    let mut start = 0usize;
    let mut line_no = 0usize;
    let mut element_lines = HashMap::new();
    let mut property_names: Option<HashSet<String>> = None;
    loop {
        if start >= bytes.len() || start > MAX_HEADER_BYTES {
            return Err(Error::parse(
                path,
                Some(line_no.max(1)),
                format!(
                    "the file ends here (byte offset {start}) inside the PLY header, which has no \
                     'end_header' line; the file is truncated or not a PLY file"
                ),
            ));
        }
        let (raw, end) = crate::line_from(bytes, start);
        line_no += 1;
        let line = std::str::from_utf8(raw).map_err(|_| {
            Error::parse(
                path,
                Some(line_no),
                "the PLY header is not text; the file is damaged or not a PLY file",
            )
        })?;
        let tokens: Vec<&str> = line.split_whitespace().collect();
        let bad = |message: String| Error::parse(path, Some(line_no), message);
        if line_no == 1 {
            if tokens != ["ply"] {
                return Err(bad(
                    "not a PLY file: the first line must be 'ply'".to_string()
                ));
            }
            start = end;
            continue;
        }
        match tokens.as_slice() {
            ["format", encoding, version] => {
                if !matches!(
                    *encoding,
                    "ascii" | "binary_little_endian" | "binary_big_endian"
                ) {
                    return Err(bad(format!(
                        "unknown PLY format '{encoding}'; expected ascii, binary_little_endian \
                         or binary_big_endian"
                    )));
                }
                let version_ok = version.split_once('.').is_some_and(|(major, minor)| {
                    [major, minor].iter().all(|part| {
                        (1..=4).contains(&part.len()) && part.bytes().all(|c| c.is_ascii_digit())
                    })
                });
                if !version_ok {
                    return Err(bad(format!(
                        "PLY version '{version}' is malformed; expected 1.0"
                    )));
                }
            }
            ["format", ..] => {
                return Err(bad(
                    "expected 'format ascii|binary_little_endian|binary_big_endian 1.0'".into(),
                ))
            }
            ["element", name, count] => {
                if count.parse::<u64>().is_err() {
                    return Err(bad(format!(
                        "element '{name}' count '{count}' is not a whole number below 2^64"
                    )));
                }
                if element_lines.insert(name.to_string(), line_no).is_some() {
                    return Err(bad(format!("element '{name}' is declared twice")));
                }
                property_names = Some(HashSet::new());
            }
            ["element", ..] => return Err(bad("expected 'element NAME COUNT'".into())),
            ["property", .., name] => match property_names.as_mut() {
                None => return Err(bad("a property comes before any element".into())),
                Some(names) => {
                    if !names.insert(name.to_string()) {
                        return Err(bad(format!(
                            "property '{name}' is declared twice in the same element"
                        )));
                    }
                }
            },
            ["end_header"] => {
                return Ok(HeaderLayout {
                    len: end,
                    lines: line_no,
                    element_lines,
                })
            }
            // comment, obj_info, and anything else: ply-rs-bw accepts or rejects it.
            _ => {}
        }
        start = end;
    }
}

/// Reads the x, y, z of every vertex of a PLY file (see the module documentation).
pub(super) fn read_ply(path: &Path) -> Result<Vec<Vec3>> {
    let bytes = read_bytes(path)?;
    if bytes.is_empty() {
        return Err(Error::parse(
            path,
            None,
            "the file is empty; expected a PLY file starting with 'ply'",
        ));
    }
    let layout = precheck_header(path, &bytes)?;
    let (header_len, header_lines) = (layout.len, layout.lines);
    let mut header_bytes = bytes.get(..header_len).unwrap_or_default();
    let header = Parser::<XyzVertex>::new()
        .read_header(&mut header_bytes)
        .map_err(|e| {
            Error::parse(
                path,
                None,
                format!("malformed PLY header: {}", one_line(&e)),
            )
        })?;
    let body = bytes.get(header_len..).unwrap_or_default();

    let vertex = header.elements.get("vertex").ok_or_else(|| {
        Error::parse(
            path,
            None,
            "the PLY header declares no 'vertex' element; sdem reads points from 'element vertex N' \
             with properties x, y, z",
        )
    })?;
    check_vertex_axes(path, vertex)?;
    check_elements_fit(path, &header, &layout, body, bytes.len())?;

    let vertices = match header.encoding {
        Encoding::Ascii => return read_ascii_body(path, body, header_lines, &header.elements),
        Encoding::BinaryLittleEndian | Encoding::BinaryBigEndian => {
            read_binary_vertices(path, &header, vertex, &layout, body, bytes.len())?
        }
    };
    let mut points = Vec::with_capacity(vertices.len());
    for (index, v) in vertices.iter().enumerate() {
        if let Some(p) = finite_point(path, None, index, v.xyz)? {
            points.push(p);
        }
    }
    Ok(points)
}

/// A PLY scalar type as a header names it (`int`, `uchar`, …).
fn type_name(t: &ScalarType) -> &'static str {
    match t {
        ScalarType::Char => "char",
        ScalarType::UChar => "uchar",
        ScalarType::Short => "short",
        ScalarType::UShort => "ushort",
        ScalarType::Int => "int",
        ScalarType::UInt => "uint",
        ScalarType::Float => "float",
        ScalarType::Double => "double",
    }
}

/// Refuses a vertex element without x, y and z stored as float or double.
fn check_vertex_axes(path: &Path, vertex: &ElementDef) -> Result<()> {
    for axis in ["x", "y", "z"] {
        match vertex.properties.get(axis).map(|p| &p.data_type) {
            Some(PropertyType::Scalar(ScalarType::Float | ScalarType::Double)) => {}
            Some(other) => {
                let stored = match other {
                    PropertyType::Scalar(t) => format!("stored as {}", type_name(t)),
                    PropertyType::List(..) => "a list".to_string(),
                };
                return Err(Error::parse(
                    path,
                    None,
                    format!(
                        "vertex property '{axis}' is {stored}; sdem reads x, y, z stored as float \
                         or double"
                    ),
                ));
            }
            None => {
                return Err(Error::parse(
                    path,
                    None,
                    format!("element 'vertex' has no property '{axis}'; sdem needs x, y and z"),
                ))
            }
        }
    }
    Ok(())
}

/// Checks that every element fits in the `body` that follows the header (the file holds
/// `file_len` bytes), so that a lying count is an error before anything is allocated.
fn check_elements_fit(
    path: &Path,
    header: &Header,
    layout: &HeaderLayout,
    body: &[u8],
    file_len: usize,
) -> Result<()> {
    let mut needed = 0usize;
    for (name, def) in &header.elements {
        // An ASCII element takes at least its line break; a malformed short line is reported
        // with its line number while reading.
        let ascii = matches!(header.encoding, Encoding::Ascii);
        let element_bytes = if ascii { 1 } else { min_element_bytes(def) };
        let fits = def
            .count
            .checked_mul(element_bytes)
            .and_then(|b| needed.checked_add(b))
            .filter(|&total| total <= body.len());
        match fits {
            Some(total) => needed = total,
            None => {
                let room = body.len() - needed;
                let message = if ascii {
                    format!(
                        "the header declares {} '{name}' elements, one per line, but only {} bytes \
                         follow 'end_header'; the file is truncated or the header is wrong",
                        def.count,
                        body.len()
                    )
                } else {
                    // The first element that does not fit, and where it starts.
                    let index = room / element_bytes.max(1);
                    let offset = layout.len + needed + index * element_bytes;
                    format!(
                        "the header declares {} '{name}' elements of at least {element_bytes} \
                         bytes each, but the file ends at byte offset {}: '{name}' element {index} \
                         (byte offset {offset}) is cut off; the file is truncated or the header is \
                         wrong",
                        def.count, file_len
                    )
                };
                return Err(Error::parse(path, layout.element_line(name), message));
            }
        }
    }
    Ok(())
}

/// The declared elements in words, for a message: `3 'vertex' elements`, or
/// `3 'vertex' and 1 'face' elements`.
fn declared_elements(elements: &ply_rs_bw::ply::KeyMap<ElementDef>) -> String {
    let counts: Vec<String> = elements
        .iter()
        .map(|(name, def)| format!("{} '{name}'", def.count))
        .collect();
    format!("{} elements", counts.join(" and "))
}

/// Reads the binary `body` (of a file of `file_len` bytes): reads the `vertex` element and skips
/// every other. Bytes left after the last declared element (but for trailing whitespace, which
/// some writers add) are an error: they are data the header does not count, and reading only
/// the declared count would silently drop points.
fn read_binary_vertices(
    path: &Path,
    header: &Header,
    vertex: &ElementDef,
    layout: &HeaderLayout,
    body: &[u8],
    file_len: usize,
) -> Result<Vec<XyzVertex>> {
    let mut reader = body;
    // Where the reader stopped, as a byte offset in the file.
    let at = |reader: &[u8]| file_len - reader.len();
    let mut vertices = Vec::new();
    for (name, def) in &header.elements {
        if name == "vertex" {
            vertices = Parser::<XyzVertex>::new()
                .read_payload_for_element(&mut reader, vertex, header)
                .map_err(|e| {
                    let line = layout.element_line("vertex");
                    truncated(path, line, "vertex", vertex.count, at(reader), &e)
                })?;
        } else if !def.properties.is_empty() {
            Parser::<Skip>::new()
                .read_payload_for_element(&mut reader, def, header)
                .map_err(|e| {
                    truncated(
                        path,
                        layout.element_line(name),
                        name,
                        def.count,
                        at(reader),
                        &e,
                    )
                })?;
        }
    }
    if !reader.iter().all(u8::is_ascii_whitespace) {
        return Err(Error::parse(
            path,
            None,
            format!(
                "more data than the {} the header declares: {} bytes are left from byte offset {}; \
                 the header's count is wrong or data was appended",
                declared_elements(&header.elements),
                reader.len(),
                at(reader)
            ),
        ));
    }
    Ok(vertices)
}

/// The binary body ended (at byte offset `at`) inside the elements declared at `line`.
fn truncated(
    path: &Path,
    line: Option<usize>,
    name: &str,
    count: usize,
    at: usize,
    e: &std::io::Error,
) -> Error {
    Error::parse(
        path,
        line,
        format!(
            "the binary body ends at byte offset {at}, before the {count} '{name}' elements the \
             header declares ({e}); the file is truncated",
            e = one_line(e)
        ),
    )
}

/// `Some(point)` for a finite vertex, `None` for one with a NaN coordinate (no return), an error
/// for an infinite coordinate.
fn finite_point(
    path: &Path,
    line: Option<usize>,
    index: usize,
    xyz: [f64; 3],
) -> Result<Option<Vec3>> {
    if xyz.iter().any(|v| v.is_nan()) {
        return Ok(None);
    }
    if xyz.iter().any(|v| v.is_infinite()) {
        return Err(Error::parse(
            path,
            line,
            format!(
                "vertex {index} is {}; coordinates must be finite (or nan for no return)",
                fmt_point(xyz)
            ),
        ));
    }
    Ok(Some(Vec3::new(xyz[0], xyz[1], xyz[2])))
}

/// Reads the ASCII payload: one element per line. Non-blank lines after the last declared
/// element are an error, as in PCD and `.sweep`: reading only the declared count would silently
/// drop the points a wrong header does not count.
fn read_ascii_body(
    path: &Path,
    body: &[u8],
    header_lines: usize,
    elements: &ply_rs_bw::ply::KeyMap<ElementDef>,
) -> Result<Vec<Vec3>> {
    // Each line with its line break, so that the break after the last line opens no empty one.
    let mut lines = body
        .split_inclusive(|&b| b == b'\n')
        .enumerate()
        .map(|(i, raw)| (header_lines + 1 + i, raw));
    let mut last_line = header_lines;
    let mut points = Vec::new();
    for (name, def) in elements {
        let is_vertex = name == "vertex";
        if is_vertex {
            // At most one point per 6 bytes ("0 0 0\n"): the declared count is not trusted.
            points.reserve(def.count.min(body.len() / 6));
        }
        for index in 0..def.count {
            let Some((line_no, raw)) = lines.next() else {
                return Err(Error::parse(
                    path,
                    Some(last_line),
                    format!(
                        "the file ends here, after {index} of the {} '{name}' elements the header \
                         declares; it is truncated or the header is wrong",
                        def.count
                    ),
                ));
            };
            last_line = line_no;
            if !is_vertex {
                // An element with properties has at least one value (a list, its length), so a
                // blank line is not one: it would shift every later line.
                if raw.trim_ascii().is_empty() && !def.properties.is_empty() {
                    return Err(Error::parse(
                        path,
                        Some(line_no),
                        format!(
                            "empty line where a '{name}' element should be; the header declares \
                             {} '{name}' elements, one per line",
                            def.count
                        ),
                    ));
                }
                continue;
            }
            let line = std::str::from_utf8(raw)
                .map_err(|_| Error::parse(path, Some(line_no), "this vertex line is not text"))?;
            let xyz = ascii_vertex(path, line_no, line, def)?;
            if let Some(p) = finite_point(path, Some(line_no), index, xyz)? {
                points.push(p);
            }
        }
    }
    if let Some((line_no, _)) = lines.find(|(_, raw)| !raw.trim_ascii().is_empty()) {
        return Err(Error::parse(
            path,
            Some(line_no),
            format!(
                "more data lines than the {} the header declares; the header's count is wrong or \
                 data was appended",
                declared_elements(elements)
            ),
        ));
    }
    Ok(points)
}

/// Parses one ASCII vertex line against the element's properties.
fn ascii_vertex(path: &Path, line_no: usize, line: &str, def: &ElementDef) -> Result<[f64; 3]> {
    let mut tokens = line.split_whitespace();
    let declared = def.properties.len();
    if line.trim().is_empty() {
        return Err(Error::parse(
            path,
            Some(line_no),
            format!(
                "empty line where a vertex should be; the header declares {} vertices, one per line",
                def.count
            ),
        ));
    }
    let too_few = || {
        Error::parse(
            path,
            Some(line_no),
            format!(
                "this vertex has fewer values than the {declared} properties the header declares"
            ),
        )
    };
    let mut xyz = [f64::NAN; 3];
    for (name, property) in &def.properties {
        match &property.data_type {
            PropertyType::Scalar(t) => {
                let token = tokens.next().ok_or_else(too_few)?;
                if let Some(axis) = axis_of(name) {
                    let value = match t {
                        ScalarType::Float => token.parse::<f32>().map(f64::from).ok(),
                        _ => token.parse::<f64>().ok(),
                    };
                    let value = value.ok_or_else(|| {
                        Error::parse(
                            path,
                            Some(line_no),
                            format!("vertex {name} '{token}' is not a number"),
                        )
                    })?;
                    if let Some(slot) = xyz.get_mut(axis) {
                        *slot = value;
                    }
                }
            }
            PropertyType::List(_, _) => {
                let token = tokens.next().ok_or_else(too_few)?;
                let n: u64 = token.parse().map_err(|_| {
                    Error::parse(
                        path,
                        Some(line_no),
                        format!("list length '{token}' of property '{name}' is not a whole number"),
                    )
                })?;
                for _ in 0..n {
                    tokens.next().ok_or_else(too_few)?;
                }
            }
        }
    }
    if tokens.next().is_some() {
        return Err(Error::parse(
            path,
            Some(line_no),
            format!(
                "this vertex has more values than the {declared} properties the header declares"
            ),
        ));
    }
    Ok(xyz)
}

/// Writes points as a binary little-endian PLY with `float` x, y, z, atomically.
///
/// Coordinates are stored as 32-bit floats (sub-micrometre resolution within ±100 m). An empty
/// cloud or a non-finite coordinate is an [`Error::Invalid`]: sdem never writes a scan it would
/// refuse to read.
///
/// # Example
/// ```
/// # let dir = std::env::temp_dir().join(format!("sdem-doc-ply-{}", std::process::id()));
/// # std::fs::create_dir_all(&dir).unwrap();
/// use sdem::geometry::Vec3;
/// let path = dir.join("cloud.ply");
/// let points = vec![Vec3::new(1.0, 2.0, 3.0), Vec3::new(-0.5, 0.25, 8.0)];
/// sdem_io::write_points_ply(&path, &points).unwrap();
/// assert_eq!(sdem_io::read_points(&path).unwrap(), points);
/// # std::fs::remove_dir_all(&dir).unwrap();
/// ```
pub fn write_points_ply(path: &Path, points: &[Vec3]) -> Result<()> {
    check_points_writable(path, points)?;
    write_atomic(path, |w| {
        write!(
            w,
            "ply\nformat binary_little_endian 1.0\ncomment written by sdem, metres\n\
             element vertex {}\nproperty float x\nproperty float y\nproperty float z\nend_header\n",
            points.len()
        )?;
        let mut buffer = Vec::with_capacity(12 * 4096);
        for chunk in points.chunks(4096) {
            buffer.clear();
            for p in chunk {
                for v in p.iter() {
                    buffer.extend_from_slice(&(*v as f32).to_le_bytes());
                }
            }
            w.write_all(&buffer)?;
        }
        Ok(())
    })
}

#[cfg(test)]
mod tests {
    use super::*;
    use crate::read_points;
    use std::path::PathBuf;

    fn write(dir: &Path, name: &str, content: &[u8]) -> PathBuf {
        let path = dir.join(name);
        std::fs::write(&path, content).unwrap();
        path
    }

    /// Reading `content` fails with a parse error naming the file (and the line, when given).
    fn expect_err(content: &[u8], line: Option<usize>) -> String {
        let dir = tempfile::tempdir().unwrap();
        let path = write(dir.path(), "bad.ply", content);
        let err = read_points(&path).expect_err("malformed PLY must be an error");
        let msg = err.to_string();
        assert!(matches!(err, Error::Parse { .. }), "{msg}");
        assert!(msg.contains("bad.ply"), "{msg}");
        if let Some(line) = line {
            assert!(msg.contains(&format!("bad.ply:{line}:")), "{msg}");
        }
        msg
    }

    fn sample_points() -> Vec<Vec3> {
        (0..500)
            .map(|i| {
                let t = i as f64 * 0.37;
                Vec3::new(t.sin() * 3.1, t.cos() * -7.3, 0.001 * i as f64 - 0.2)
            })
            .collect()
    }

    #[test]
    fn binary_round_trip_is_bitwise_for_f32_values() {
        let dir = tempfile::tempdir().unwrap();
        let path = dir.path().join("cloud.ply");
        let points: Vec<Vec3> = sample_points()
            .iter()
            .map(|p| p.map(|v| f64::from(v as f32)))
            .collect();
        write_points_ply(&path, &points).unwrap();
        let back = read_points(&path).unwrap();
        assert_eq!(back.len(), points.len());
        for (a, b) in points.iter().zip(&back) {
            for (u, v) in a.iter().zip(b.iter()) {
                assert_eq!(u.to_bits(), v.to_bits());
            }
        }
        // Values that need f64 come back rounded to the nearest f32.
        let fine = sample_points();
        write_points_ply(&path, &fine).unwrap();
        let back = read_points(&path).unwrap();
        for (a, b) in fine.iter().zip(&back) {
            assert_eq!(a.map(|v| f64::from(v as f32)), *b);
        }
    }

    #[test]
    fn writer_rejects_empty_and_non_finite() {
        let dir = tempfile::tempdir().unwrap();
        let path = dir.path().join("cloud.ply");
        assert!(matches!(
            write_points_ply(&path, &[]),
            Err(Error::Invalid(_))
        ));
        let bad = [Vec3::new(1.0, f64::NAN, 0.0)];
        assert!(matches!(
            write_points_ply(&path, &bad),
            Err(Error::Invalid(_))
        ));
        let huge = [Vec3::new(1e300, 0.0, 0.0)];
        assert!(matches!(
            write_points_ply(&path, &huge),
            Err(Error::Invalid(_))
        ));
        assert!(!path.exists());
    }

    #[test]
    fn ascii_ply_with_extra_properties_and_faces() {
        let dir = tempfile::tempdir().unwrap();
        let text = "ply\r\nformat ascii 1.0\r\ncomment made by hand\r\nobj_info test\r\n\
                    element vertex 4\r\nproperty double x\r\nproperty float y\r\n\
                    property uchar red\r\nproperty list uchar int idx\r\nproperty float z\r\n\
                    element face 1\r\nproperty list uchar int vertex_indices\r\nend_header\r\n\
                    1 2 255 0 3\r\n-1.5e1 0.1 0 2 7 8 .5\r\nnan 0 0 0 0\r\n4 5 6 1 9 -0\r\n\
                    3 0 1 2\r\n";
        let path = write(dir.path(), "hand.ply", text.as_bytes());
        let points = read_points(&path).unwrap();
        assert_eq!(
            points,
            vec![
                Vec3::new(1.0, 2.0, 3.0),
                Vec3::new(-15.0, f64::from(0.1f32), 0.5),
                Vec3::new(4.0, 5.0, -0.0),
            ]
        );
    }

    fn binary_ply(big_endian: bool) -> Vec<u8> {
        // A face element (with a list) before the vertices, doubles for x y z and an extra field.
        let format = if big_endian {
            "binary_big_endian"
        } else {
            "binary_little_endian"
        };
        let mut bytes = format!(
            "ply\nformat {format} 1.0\nelement face 2\nproperty list uchar int vertex_indices\n\
             element vertex 3\nproperty double x\nproperty double y\nproperty double z\n\
             property float intensity\nend_header\n"
        )
        .into_bytes();
        let i32b = |v: i32| {
            if big_endian {
                v.to_be_bytes()
            } else {
                v.to_le_bytes()
            }
        };
        let f64b = |v: f64| {
            if big_endian {
                v.to_be_bytes()
            } else {
                v.to_le_bytes()
            }
        };
        let f32b = |v: f32| {
            if big_endian {
                v.to_be_bytes()
            } else {
                v.to_le_bytes()
            }
        };
        bytes.push(3);
        for i in [0, 1, 2] {
            bytes.extend(i32b(i));
        }
        bytes.push(0);
        for p in [[0.1, 0.2, 0.3], [f64::NAN, 1.0, 1.0], [-4.0, 5.5, 1e-3]] {
            for v in p {
                bytes.extend(f64b(v));
            }
            bytes.extend(f32b(0.5));
        }
        bytes
    }

    #[test]
    fn binary_both_endians_with_double_and_skipped_elements() {
        let dir = tempfile::tempdir().unwrap();
        for big in [false, true] {
            let path = write(dir.path(), "b.ply", &binary_ply(big));
            let points = read_points(&path).unwrap();
            assert_eq!(
                points,
                vec![Vec3::new(0.1, 0.2, 0.3), Vec3::new(-4.0, 5.5, 1e-3)],
                "big endian: {big}"
            );
        }
    }

    #[test]
    fn malformed_headers() {
        expect_err(b"", None);
        expect_err(b"plx\nformat ascii 1.0\nend_header\n", Some(1));
        expect_err(
            b"ply\nformat ascii 1.0\nelement vertex 1\nproperty float x\n",
            None,
        );
        expect_err(b"ply\nformat ascii 1.0\nend_header\n", None); // no vertex element
        expect_err(b"ply\nformat utf8 1.0\nend_header\n", Some(2));
        expect_err(
            b"ply\nformat ascii 99999999999999999999999.0\nend_header\n",
            Some(2),
        );
        expect_err(b"ply\nelement vertex 1\nproperty float x\nproperty float y\nproperty float z\nend_header\n1 2 3\n", None);
        let msg = expect_err(
            b"ply\nformat ascii 1.0\nelement vertex 99999999999999999999999\nproperty float x\nend_header\n",
            Some(3),
        );
        assert!(msg.contains("count"), "{msg}");
        expect_err(b"ply\nformat ascii 1.0\nelement vertex 1\nproperty float x\nproperty float x\nproperty float z\nend_header\n1 2 3\n", Some(5));
        expect_err(b"ply\nformat ascii 1.0\nelement vertex 1\nproperty int x\nproperty float y\nproperty float z\nend_header\n1 2 3\n", None);
        expect_err(b"ply\nformat ascii 1.0\nelement vertex 1\nproperty float x\nproperty float z\nend_header\n1 2\n", None);
        expect_err(
            b"ply\nformat ascii 1.0\nproperty float x\nend_header\n",
            Some(3),
        );
        expect_err(b"ply\nformat ascii 1.0\nelement vertex 1\nproperty float x\nproperty float y\nproperty float z\nbogus line\nend_header\n1 2 3\n", None);
        expect_err(b"ply\n\xff\xfe\nend_header\n", Some(2));
    }

    #[test]
    fn absurd_counts_are_rejected_before_reading() {
        for format in ["ascii", "binary_little_endian"] {
            let text = format!(
                "ply\nformat {format} 1.0\nelement vertex 99999999999\nproperty float x\n\
                 property float y\nproperty float z\nend_header\n1 2 3\n"
            );
            let msg = expect_err(text.as_bytes(), None);
            assert!(msg.contains("99999999999"), "{msg}");
        }
        // usize::MAX elements of 12 bytes overflows the size computation.
        let text = format!(
            "ply\nformat binary_little_endian 1.0\nelement vertex {}\nproperty float x\n\
             property float y\nproperty float z\nend_header\n",
            u64::MAX
        );
        expect_err(text.as_bytes(), None);
    }

    #[test]
    fn truncated_binary_body() {
        let dir = tempfile::tempdir().unwrap();
        let path = dir.path().join("full.ply");
        write_points_ply(&path, &sample_points()).unwrap();
        let mut bytes = std::fs::read(&path).unwrap();
        bytes.truncate(bytes.len() - 5);
        let msg = expect_err(&bytes, None);
        assert!(msg.contains("truncated"), "{msg}");
        // A list element whose lengths run past the end.
        let mut bytes = binary_ply(false);
        bytes.truncate(bytes.len() - 30);
        expect_err(&bytes, None);
    }

    #[test]
    fn malformed_ascii_values_name_the_line() {
        let head = "ply\nformat ascii 1.0\nelement vertex 2\nproperty float x\nproperty float y\n\
                    property float z\nend_header\n";
        let with = |body: &str| format!("{head}{body}").into_bytes();
        expect_err(&with("1 2 3\n4 5\n"), Some(9));
        expect_err(&with("1 2 3\n4 5 6 7\n"), Some(9));
        expect_err(&with("1 2 3\n4 five 6\n"), Some(9));
        expect_err(&with("1 inf 3\n4 5 6\n"), Some(8));
        expect_err(&with("1 2 3\n"), None);
        expect_err(&with("1 2 3\n\n4 5 6\n"), Some(9));
        expect_err(&with("nan 2 3\nnan 5 6\n"), None); // no points at all
    }

    #[test]
    fn data_beyond_the_declared_count_is_an_error() {
        // Binary: four points under a header that declares three.
        let head = |count: usize| {
            format!(
                "ply\nformat binary_little_endian 1.0\nelement vertex {count}\nproperty float x\n\
                 property float y\nproperty float z\nend_header\n"
            )
            .into_bytes()
        };
        let mut bytes = head(3);
        for i in 0..4 {
            for v in [i as f32, 1.0, 2.0] {
                bytes.extend(v.to_le_bytes());
            }
        }
        let msg = expect_err(&bytes, None);
        assert!(
            msg.contains("more data than the 3 'vertex' elements the header declares")
                && msg.contains("12 bytes are left"),
            "{msg}"
        );
        // The same with the count right, and a trailing line break as some writers add: read.
        bytes.splice(..head(3).len(), head(4));
        bytes.extend(b"\r\n");
        let dir = tempfile::tempdir().unwrap();
        assert_eq!(
            read_points(&write(dir.path(), "ok.ply", &bytes))
                .unwrap()
                .len(),
            4
        );
        // Bytes after an element declared before the vertices.
        let mut bytes = binary_ply(true);
        bytes.extend([0u8; 28]);
        let msg = expect_err(&bytes, None);
        assert!(msg.contains("2 'face' and 3 'vertex' elements"), "{msg}");

        // ASCII: a line after the declared vertices, and after the declared faces.
        let ascii = |count: usize, faces: &str, body: &str| {
            format!(
                "ply\nformat ascii 1.0\nelement vertex {count}\nproperty float x\n\
                 property float y\nproperty float z\n{faces}end_header\n{body}"
            )
            .into_bytes()
        };
        let msg = expect_err(&ascii(2, "", "1 2 3\n4 5 6\n7 8 9\n"), Some(10));
        assert!(
            msg.contains("more data lines than the 2 'vertex' elements the header declares"),
            "{msg}"
        );
        let faces = "element face 1\nproperty list uchar int vertex_indices\n";
        let msg = expect_err(&ascii(2, faces, "1 2 3\n4 5 6\n2 0 1\n2 1 0\n"), Some(13));
        assert!(msg.contains("2 'vertex' and 1 'face' elements"), "{msg}");
        // Declared faces that are missing: the file is cut short.
        let msg = expect_err(&ascii(2, faces, "1 2 3\n4 5 6\n"), None);
        assert!(msg.contains("'face'"), "{msg}");
        // Faces after the vertices, and trailing blank lines: read.
        let ok = ascii(2, faces, "1 2 3\n4 5 6\n2 0 1\n\n  \n");
        assert_eq!(
            read_points(&write(dir.path(), "ok.ply", &ok))
                .unwrap()
                .len(),
            2
        );
    }

    #[test]
    fn binary_infinite_coordinate_is_an_error() {
        let mut bytes =
            b"ply\nformat binary_little_endian 1.0\nelement vertex 1\nproperty float x\n\
                          property float y\nproperty float z\nend_header\n"
                .to_vec();
        for v in [1.0f32, f32::INFINITY, 0.0] {
            bytes.extend(v.to_le_bytes());
        }
        let msg = expect_err(&bytes, None);
        assert!(msg.contains("vertex 0"), "{msg}");
    }

    #[test]
    fn no_input_prefix_panics() {
        // Every truncation and a few corruptions of valid files give a result, never a panic.
        let dir = tempfile::tempdir().unwrap();
        let path = dir.path().join("cloud.ply");
        write_points_ply(&path, &sample_points()[..4]).unwrap();
        let binary = std::fs::read(&path).unwrap();
        let ascii =
            b"ply\nformat ascii 1.0\nelement vertex 2\nproperty float x\nproperty float y\n\
                      property float z\nelement face 1\nproperty list uchar int v\nend_header\n\
                      1 2 3\n4 5 6\n3 0 1 1\n"
                .to_vec();
        for file in [binary, ascii, binary_ply(true)] {
            for len in 0..file.len() {
                let p = write(dir.path(), "cut.ply", &file[..len]);
                let _ = read_points(&p);
            }
            for i in 0..file.len() {
                let mut corrupt = file.clone();
                corrupt[i] = corrupt[i].wrapping_add(0x55);
                let p = write(dir.path(), "flip.ply", &corrupt);
                let _ = read_points(&p);
            }
        }
    }
}
