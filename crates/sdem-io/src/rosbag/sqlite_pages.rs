//! The rows of a rosbag2 SQLite database read straight from its pages, for a file that SQLite
//! itself cannot read to the end (cut short: the pages of the table's index are written last
//! and are the first lost, so SQLite stops at the first row). Every table-leaf page of the file
//! is scanned for rows shaped like `messages` (`id` as the rowid, two integers, a blob), whose
//! overflow chains lie whole in the file; see "Database File Format" on sqlite.org.

use std::fs::File;
use std::io::{Read, Seek, SeekFrom};
use std::path::Path;

/// One `messages` row found in the pages.
#[derive(Debug, Clone, PartialEq)]
pub struct PageRow {
    /// The row's id.
    pub id: i64,
    /// Its `topic_id`.
    pub topic_id: i64,
    /// Its `timestamp`.
    pub timestamp: i64,
    /// Its `data`.
    pub data: Vec<u8>,
}

struct Pages {
    file: File,
    page_size: usize,
    usable: usize,
    count: u64,
}

impl Pages {
    fn open(path: &Path) -> Option<Self> {
        let mut file = File::open(path).ok()?;
        let mut header = [0u8; 100];
        file.read_exact(&mut header).ok()?;
        if &header[..16] != b"SQLite format 3\0" {
            return None;
        }
        let page_size = match u16::from_be_bytes([header[16], header[17]]) {
            1 => 65_536,
            n if n >= 512 && n.is_power_of_two() => usize::from(n),
            _ => return None,
        };
        let usable = page_size - usize::from(header[20]);
        let count = file.metadata().ok()?.len() / page_size as u64;
        Some(Self {
            file,
            page_size,
            usable,
            count,
        })
    }

    /// Page `number` (1-based), `None` beyond the file's end.
    fn page(&mut self, number: u64) -> Option<Vec<u8>> {
        if number == 0 || number > self.count {
            return None;
        }
        let mut page = vec![0u8; self.page_size];
        self.file
            .seek(SeekFrom::Start((number - 1) * self.page_size as u64))
            .ok()?;
        self.file.read_exact(&mut page).ok()?;
        Some(page)
    }
}

/// A varint at `at`: the value and its length.
fn varint(bytes: &[u8], at: usize) -> Option<(i64, usize)> {
    let mut value: u64 = 0;
    for i in 0..9 {
        let b = *bytes.get(at + i)?;
        if i == 8 {
            return Some((((value << 8) | u64::from(b)) as i64, 9));
        }
        value = (value << 7) | u64::from(b & 0x7f);
        if b & 0x80 == 0 {
            return Some((value as i64, i + 1));
        }
    }
    None
}

fn integer(bytes: &[u8], serial: i64) -> Option<i64> {
    let len = match serial {
        1..=4 => serial as usize,
        5 => 6,
        6 => 8,
        8 => return Some(0),
        9 => return Some(1),
        _ => return None,
    };
    let raw = bytes.get(..len)?;
    let mut v: i64 = if raw[0] & 0x80 != 0 { -1 } else { 0 };
    for &b in raw {
        v = (v << 8) | i64::from(b);
    }
    Some(v)
}

fn integer_len(serial: i64) -> usize {
    match serial {
        1..=4 => serial as usize,
        5 => 6,
        6 => 8,
        _ => 0,
    }
}

/// The row of a `messages` record `[NULL, int, int, blob]`, `None` for any other record.
fn message_row(id: i64, payload: &[u8]) -> Option<PageRow> {
    let (header_len, n) = varint(payload, 0)?;
    let header_len = usize::try_from(header_len).ok()?;
    let mut serials = Vec::new();
    let mut at = n;
    while at < header_len {
        let (s, n) = varint(payload, at)?;
        serials.push(s);
        at += n;
    }
    let [0, t, s, b] = serials[..] else {
        return None;
    };
    let is_integer = |x: i64| (1..=6).contains(&x) || x == 8 || x == 9;
    if !is_integer(t) || !is_integer(s) || b < 12 || b % 2 != 0 {
        return None;
    }
    let body = payload.get(header_len..)?;
    let topic_id = integer(body, t)?;
    let body = &body[integer_len(t)..];
    let timestamp = integer(body, s)?;
    let body = &body[integer_len(s)..];
    let data = body.get(..usize::try_from((b - 12) / 2).ok()?)?.to_vec();
    Some(PageRow {
        id,
        topic_id,
        timestamp,
        data,
    })
}

/// The cells of a table-leaf page as `(rowid, payload)`, overflow chains followed; cells whose
/// chain leaves the file are skipped.
fn leaf_cells(pages: &mut Pages, number: u64, page: &[u8]) -> Vec<(i64, Vec<u8>)> {
    let start = if number == 1 { 100 } else { 0 };
    let cells = usize::from(u16::from_be_bytes([page[start + 3], page[start + 4]]));
    let u = pages.usable;
    let (max_local, min_local) = (u - 35, (u - 12) * 32 / 255 - 23);
    let mut out = Vec::new();
    for c in 0..cells {
        let p = start + 8 + 2 * c;
        let Some(ptr) = page.get(p..p + 2) else { break };
        let at = usize::from(u16::from_be_bytes([ptr[0], ptr[1]]));
        let Some((len, n1)) = varint(page, at) else {
            continue;
        };
        let Some((rowid, n2)) = varint(page, at + n1) else {
            continue;
        };
        let Ok(len) = usize::try_from(len) else {
            continue;
        };
        let body = at + n1 + n2;
        let local = if len <= max_local {
            len
        } else {
            let k = min_local + (len - min_local) % (u - 4);
            if k <= max_local {
                k
            } else {
                min_local
            }
        };
        let Some(head) = page.get(body..body + local) else {
            continue;
        };
        let mut payload = head.to_vec();
        let mut next = if local < len {
            page.get(body + local..body + local + 4)
                .map_or(0, |b| u32::from_be_bytes([b[0], b[1], b[2], b[3]]))
        } else {
            0
        };
        let mut hops = 0u64;
        while payload.len() < len && next != 0 && hops <= pages.count {
            let Some(overflow) = pages.page(u64::from(next)) else {
                break;
            };
            let take = (len - payload.len()).min(u - 4);
            payload.extend_from_slice(&overflow[4..4 + take]);
            next = u32::from_be_bytes([overflow[0], overflow[1], overflow[2], overflow[3]]);
            hops += 1;
        }
        if payload.len() == len {
            out.push((rowid, payload));
        }
    }
    out
}

/// Every whole `messages` row in the pages of `path` with an id above `after`, by id.
pub fn rows_after(path: &Path, after: i64) -> Vec<PageRow> {
    let Some(mut pages) = Pages::open(path) else {
        return Vec::new();
    };
    let mut rows = Vec::new();
    for number in 1..=pages.count {
        let Some(page) = pages.page(number) else {
            break;
        };
        let start = if number == 1 { 100 } else { 0 };
        if page[start] != 0x0D {
            continue;
        }
        for (rowid, payload) in leaf_cells(&mut pages, number, &page) {
            if rowid > after {
                rows.extend(message_row(rowid, &payload));
            }
        }
    }
    rows.sort_by_key(|r| r.id);
    rows.dedup_by_key(|r| r.id);
    rows
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn rows_are_read_from_the_pages_of_a_database_cut_short() {
        let dir = tempfile::tempdir().unwrap();
        let path = dir.path().join("bag.db3");
        let db = rusqlite::Connection::open(&path).unwrap();
        db.execute_batch(
            "CREATE TABLE topics(id INTEGER PRIMARY KEY, name TEXT NOT NULL, type TEXT NOT NULL, \
             serialization_format TEXT NOT NULL, offered_qos_profiles TEXT NOT NULL);
             CREATE TABLE messages(id INTEGER PRIMARY KEY, topic_id INTEGER NOT NULL, \
             timestamp INTEGER NOT NULL, data BLOB NOT NULL);
             INSERT INTO topics VALUES (1, '/points', 'sensor_msgs/msg/PointCloud2', 'cdr', '');",
        )
        .unwrap();
        // Rows of 3 bytes to 30 kB: small ones inline, large ones over overflow chains.
        for i in 1..=300i64 {
            let data: Vec<u8> = (0..(i * 97 % 30_000) + 3).map(|k| (k * i) as u8).collect();
            db.execute(
                "INSERT INTO messages VALUES (?1, 1, ?2, ?3)",
                rusqlite::params![i, 1_000_000_000 * i, data],
            )
            .unwrap();
        }
        drop(db);
        let whole = rows_after(&path, 0);
        assert_eq!(whole.len(), 300);
        assert_eq!(whole[41].timestamp, 42_000_000_000);
        assert_eq!(whole[41].data.len(), 42 * 97 + 3);
        assert_eq!(whole[41].data[5], (5 * 42) as u8);
        let bytes = std::fs::read(&path).unwrap();
        std::fs::write(&path, &bytes[..bytes.len() / 2]).unwrap();
        let cut = rows_after(&path, 10);
        assert!(cut.len() > 50 && cut.len() < 290, "{}", cut.len());
        assert_eq!(cut[0].id, 11);
        assert!(cut.iter().all(|r| whole[r.id as usize - 1] == *r));
    }
}
