//! CDR, the serialization of ROS 2 messages (OMG DDS-XTypes "XCDR1", plain CDR): a 4-byte
//! encapsulation header (`00 01` little-endian, `00 00` big-endian), then the fields in order,
//! each primitive aligned to its own size (counted from the end of the header), strings as a
//! `u32` length that counts the closing NUL, sequences as a `u32` count and their elements.
//!
//! Hand-written rather than taken from a serde-based crate: the few message types sdem reads
//! are fixed, a point cloud's `data` is borrowed without a copy, and every failure names the
//! field and the byte offset, which a generic deserializer cannot.

/// Why a message could not be decoded: the field and the byte offset (from the start of the
/// message, header included).
#[derive(Debug, Clone, PartialEq, Eq)]
pub struct CdrError {
    /// The field being read, e.g. `fields[2].name`.
    pub field: String,
    /// The byte offset in the message where it was read.
    pub offset: usize,
    /// What was wrong.
    pub what: String,
}

impl std::fmt::Display for CdrError {
    fn fmt(&self, f: &mut std::fmt::Formatter<'_>) -> std::fmt::Result {
        write!(f, "{} at byte {}: {}", self.field, self.offset, self.what)
    }
}

/// The result of decoding.
pub type CdrResult<T> = Result<T, CdrError>;

/// A bounds-checked reader over one serialized message.
pub struct CdrReader<'a> {
    bytes: &'a [u8],
    /// The position, counted from the start of `bytes` (the encapsulation header included).
    pos: usize,
    little_endian: bool,
}

/// The encapsulation header's length; alignment counts from its end.
const HEADER: usize = 4;

/// The most elements a sequence may claim before its bytes are checked: a count larger than
/// the bytes left is refused first anyway; this also bounds sequences of zero-sized elements.
const MAX_SEQUENCE: usize = 1 << 28;

impl<'a> CdrReader<'a> {
    /// A reader over `bytes`, after checking the encapsulation header.
    pub fn new(bytes: &'a [u8]) -> CdrResult<Self> {
        let mut reader = Self {
            bytes,
            pos: 0,
            little_endian: true,
        };
        if bytes.len() < HEADER {
            return Err(reader.error(
                "encapsulation header",
                format!(
                    "the message has {} bytes, fewer than the 4-byte header",
                    bytes.len()
                ),
            ));
        }
        reader.little_endian = match [bytes[0], bytes[1]] {
            [0, 0] => false,
            [0, 1] => true,
            [a, b] => {
                return Err(reader.error(
                    "encapsulation header",
                    format!(
                        "representation {a:02x} {b:02x} is not plain CDR (00 00 or 00 01); \
                         XCDR2 and parameter lists are not supported"
                    ),
                ))
            }
        };
        reader.pos = HEADER;
        Ok(reader)
    }

    /// Whether the message is little-endian.
    pub fn is_little_endian(&self) -> bool {
        self.little_endian
    }

    /// The position, bytes from the start of the message.
    pub fn position(&self) -> usize {
        self.pos
    }

    fn error(&self, field: &str, what: impl Into<String>) -> CdrError {
        CdrError {
            field: field.to_string(),
            offset: self.pos,
            what: what.into(),
        }
    }

    fn align(&mut self, size: usize, field: &str) -> CdrResult<()> {
        let misalign = (self.pos - HEADER) % size;
        if misalign != 0 {
            let pad = size - misalign;
            if self.pos + pad > self.bytes.len() {
                return Err(self.error(field, "the message ends here (truncated)"));
            }
            self.pos += pad;
        }
        Ok(())
    }

    fn take<const N: usize>(&mut self, field: &str) -> CdrResult<[u8; N]> {
        self.align(N, field)?;
        let end = self.pos + N;
        let Some(slice) = self.bytes.get(self.pos..end) else {
            return Err(self.error(field, "the message ends here (truncated)"));
        };
        let mut out = [0u8; N];
        out.copy_from_slice(slice);
        if !self.little_endian {
            out.reverse();
        }
        self.pos = end;
        Ok(out)
    }

    /// Reads a `uint8` (also `byte`, `char`).
    pub fn u8(&mut self, field: &str) -> CdrResult<u8> {
        self.take::<1>(field).map(|b| b[0])
    }

    /// Reads a `bool`: 0 or 1.
    pub fn bool(&mut self, field: &str) -> CdrResult<bool> {
        let at = self.pos;
        match self.u8(field)? {
            0 => Ok(false),
            1 => Ok(true),
            v => Err(CdrError {
                field: field.to_string(),
                offset: at,
                what: format!("a bool is 0 or 1, not {v}"),
            }),
        }
    }

    /// Reads an `int32`.
    pub fn i32(&mut self, field: &str) -> CdrResult<i32> {
        self.take::<4>(field).map(i32::from_le_bytes)
    }

    /// Reads a `uint32`.
    pub fn u32(&mut self, field: &str) -> CdrResult<u32> {
        self.take::<4>(field).map(u32::from_le_bytes)
    }

    /// Reads a `float32`.
    pub fn f32(&mut self, field: &str) -> CdrResult<f32> {
        self.take::<4>(field).map(f32::from_le_bytes)
    }

    /// Reads a `float64`.
    pub fn f64(&mut self, field: &str) -> CdrResult<f64> {
        self.take::<8>(field).map(f64::from_le_bytes)
    }

    /// Reads `N` `float64`s (a fixed-size array).
    pub fn f64_array<const N: usize>(&mut self, field: &str) -> CdrResult<[f64; N]> {
        let mut out = [0.0; N];
        for v in &mut out {
            *v = self.f64(field)?;
        }
        Ok(out)
    }

    /// Reads a sequence's element count, checked against the bytes left (each element takes
    /// at least `min_element_bytes`).
    pub fn sequence_len(&mut self, field: &str, min_element_bytes: usize) -> CdrResult<usize> {
        let at = self.pos;
        let count = self.u32(field)? as usize;
        let left = self.bytes.len() - self.pos;
        if count > MAX_SEQUENCE || count.saturating_mul(min_element_bytes.max(1)) > left + 7 {
            return Err(CdrError {
                field: field.to_string(),
                offset: at,
                what: format!(
                    "a sequence of {count} elements cannot fit in the {left} bytes left \
                     (truncated or not this message type)"
                ),
            });
        }
        Ok(count)
    }

    /// Reads a `uint8[]` without copying it.
    pub fn bytes(&mut self, field: &str) -> CdrResult<&'a [u8]> {
        let count = self.sequence_len(field, 1)?;
        let Some(slice) = self.bytes.get(self.pos..self.pos + count) else {
            return Err(self.error(field, "the message ends inside this byte array"));
        };
        self.pos += count;
        Ok(slice)
    }

    /// Reads a `string`: UTF-8, its length counting the closing NUL.
    pub fn string(&mut self, field: &str) -> CdrResult<String> {
        let at = self.pos;
        let count = self.sequence_len(field, 1)?;
        let Some(slice) = self.bytes.get(self.pos..self.pos + count) else {
            return Err(self.error(field, "the message ends inside this string"));
        };
        let text = match slice.split_last() {
            Some((0, text)) => text,
            Some(_) => {
                return Err(CdrError {
                    field: field.to_string(),
                    offset: at,
                    what: "the string does not end with a NUL byte".into(),
                })
            }
            // Some writers encode the empty string with length 0.
            None => &[],
        };
        let text = std::str::from_utf8(text).map_err(|_| CdrError {
            field: field.to_string(),
            offset: at,
            what: "the string is not UTF-8".into(),
        })?;
        self.pos += count;
        Ok(text.to_string())
    }

    /// Reads a `float32[]`.
    pub fn f32_sequence(&mut self, field: &str) -> CdrResult<Vec<f32>> {
        let count = self.sequence_len(field, 4)?;
        (0..count).map(|_| self.f32(field)).collect()
    }

    /// Reads a `float64[]`.
    pub fn f64_sequence(&mut self, field: &str) -> CdrResult<Vec<f64>> {
        let count = self.sequence_len(field, 8)?;
        (0..count).map(|_| self.f64(field)).collect()
    }
}

/// A writer of one message in little-endian plain CDR (the encapsulation ROS 2 writes).
#[derive(Debug, Default)]
pub struct CdrWriter {
    bytes: Vec<u8>,
}

impl CdrWriter {
    /// A writer holding the encapsulation header `00 01 00 00`.
    pub fn new() -> Self {
        Self {
            bytes: vec![0, 1, 0, 0],
        }
    }

    /// The serialized message.
    pub fn into_bytes(self) -> Vec<u8> {
        self.bytes
    }

    fn align(&mut self, size: usize) {
        while !(self.bytes.len() - HEADER).is_multiple_of(size) {
            self.bytes.push(0);
        }
    }

    /// Writes a `uint8`.
    pub fn u8(&mut self, v: u8) {
        self.bytes.push(v);
    }

    /// Writes a `bool`.
    pub fn bool(&mut self, v: bool) {
        self.bytes.push(u8::from(v));
    }

    /// Writes an `int32`.
    pub fn i32(&mut self, v: i32) {
        self.align(4);
        self.bytes.extend_from_slice(&v.to_le_bytes());
    }

    /// Writes a `uint32`.
    pub fn u32(&mut self, v: u32) {
        self.align(4);
        self.bytes.extend_from_slice(&v.to_le_bytes());
    }

    /// Writes a `float32`.
    pub fn f32(&mut self, v: f32) {
        self.align(4);
        self.bytes.extend_from_slice(&v.to_le_bytes());
    }

    /// Writes a `float64`.
    pub fn f64(&mut self, v: f64) {
        self.align(8);
        self.bytes.extend_from_slice(&v.to_le_bytes());
    }

    /// Writes a sequence's element count.
    ///
    /// # Panics
    /// When `count` exceeds `u32::MAX`, which no message sdem writes comes near.
    pub fn sequence_len(&mut self, count: usize) {
        self.u32(u32::try_from(count).expect("a CDR sequence holds at most u32::MAX elements"));
    }

    /// Writes a `string`.
    pub fn string(&mut self, v: &str) {
        self.sequence_len(v.len() + 1);
        self.bytes.extend_from_slice(v.as_bytes());
        self.bytes.push(0);
    }

    /// Writes a `uint8[]`.
    pub fn bytes(&mut self, v: &[u8]) {
        self.sequence_len(v.len());
        self.bytes.extend_from_slice(v);
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn a_written_message_reads_back_with_its_alignment() {
        let mut w = CdrWriter::new();
        w.u8(7);
        w.f64(1.5);
        w.string("map");
        w.bool(true);
        w.u32(9);
        w.bytes(&[1, 2, 3]);
        w.f32(-2.25);
        let bytes = w.into_bytes();
        // u8 at 4, f64 padded to 12, string length at 20, "map\0" 24..28, bool 28, u32 at 32.
        assert_eq!(&bytes[..4], &[0, 1, 0, 0]);
        assert_eq!(bytes[20], 4);
        let mut r = CdrReader::new(&bytes).unwrap();
        assert_eq!(r.u8("a").unwrap(), 7);
        assert_eq!(r.f64("b").unwrap(), 1.5);
        assert_eq!(r.string("c").unwrap(), "map");
        assert!(r.bool("d").unwrap());
        assert_eq!(r.u32("e").unwrap(), 9);
        assert_eq!(r.bytes("f").unwrap(), &[1, 2, 3]);
        assert_eq!(r.f32("g").unwrap(), -2.25);
        assert_eq!(r.position(), bytes.len());
    }

    #[test]
    fn big_endian_messages_read_the_same_values() {
        // 00 00 header, then u32 5 big-endian, then f64 at offset 8 (aligned from the header).
        let mut bytes = vec![0, 0, 0, 0, 0, 0, 0, 5, 0, 0, 0, 0];
        bytes.extend_from_slice(&2.5f64.to_be_bytes());
        let mut r = CdrReader::new(&bytes).unwrap();
        assert!(!r.is_little_endian());
        assert_eq!(r.u32("n").unwrap(), 5);
        assert_eq!(r.f64("x").unwrap(), 2.5);
    }

    #[test]
    fn truncation_and_impossible_counts_name_the_field_and_offset() {
        let mut w = CdrWriter::new();
        w.u32(1_000_000);
        let bytes = w.into_bytes();
        let mut r = CdrReader::new(&bytes).unwrap();
        let e = r.bytes("data").unwrap_err();
        assert_eq!((e.field.as_str(), e.offset), ("data", 4));
        assert!(e.what.contains("cannot fit"), "{e}");
        let mut r = CdrReader::new(&[0, 1, 0, 0, 1]).unwrap();
        let e = r.f64("x").unwrap_err();
        assert!(e.to_string().contains("x at byte 4"), "{e}");
        assert!(CdrReader::new(&[0, 7, 0, 0]).is_err());
        assert!(CdrReader::new(&[0]).is_err());
        let mut r = CdrReader::new(&[0, 1, 0, 0, 2]).unwrap();
        assert!(r.bool("flag").unwrap_err().what.contains("0 or 1"));
    }
}
