//! Opening a bag (a rosbag2 folder, or one `.mcap` or `.db3` file) and reading its messages in
//! file order from either storage, noting where a damaged file stops being readable.

use super::metadata::{read_metadata, Metadata};
use crate::error::{Error, Result};
use std::cell::Cell;
use std::collections::HashMap;
use std::io::Read;
use std::path::{Path, PathBuf};
use std::rc::Rc;

/// How a bag stores its messages.
#[derive(Debug, Clone, Copy, PartialEq, Eq, serde::Serialize)]
#[serde(rename_all = "lowercase")]
pub enum Storage {
    /// MCAP files (the default since ROS 2 Iron).
    Mcap,
    /// SQLite3 databases (`.db3`, the default before).
    Sqlite3,
}

impl Storage {
    /// The name rosbag2 gives it in `metadata.yaml` (`mcap`, `sqlite3`).
    pub fn name(self) -> &'static str {
        match self {
            Storage::Mcap => "mcap",
            Storage::Sqlite3 => "sqlite3",
        }
    }

    /// The kind of file, in words.
    fn kind(self) -> &'static str {
        match self {
            Storage::Mcap => "an MCAP file",
            Storage::Sqlite3 => "an SQLite database",
        }
    }

    /// The bytes its files begin with: MCAP's magic, SQLite's header string.
    fn magic(self) -> &'static [u8] {
        match self {
            Storage::Mcap => b"\x89MCAP0\r\n",
            Storage::Sqlite3 => b"SQLite format 3\0",
        }
    }

    /// The extension of its files.
    fn extension(self) -> &'static str {
        match self {
            Storage::Mcap => "mcap",
            Storage::Sqlite3 => "db3",
        }
    }
}

/// An opened bag: its storage and files, not yet read.
#[derive(Debug, Clone)]
pub struct Bag {
    /// What was opened: the rosbag2 folder or the single file.
    pub path: PathBuf,
    /// How the messages are stored.
    pub storage: Storage,
    /// The storage files, in order.
    pub files: Vec<PathBuf>,
    /// The folder's `metadata.yaml`, when there is one.
    pub metadata: Option<Metadata>,
    /// Each file is zstd-compressed whole (rosbag2 compression mode `FILE`).
    pub file_compressed: bool,
    /// Each message is zstd-compressed (rosbag2 compression mode `MESSAGE`).
    pub message_compressed: bool,
}

/// One message as read from a bag.
#[derive(Debug)]
pub struct BagMessage<'a> {
    /// The topic.
    pub topic: &'a str,
    /// Its message type (`sensor_msgs/msg/Imu`); empty when the bag does not say.
    pub type_name: &'a str,
    /// Its serialization format (`cdr`).
    pub serialization_format: &'a str,
    /// The message's index within its topic, counting from 0 in file order.
    pub index: u64,
    /// When it was recorded, nanoseconds since the epoch.
    pub log_time_ns: i64,
    /// The serialized message.
    pub data: &'a [u8],
    /// The file it is in.
    pub file: &'a Path,
}

/// Where a bag stopped being readable.
#[derive(Debug, Clone, PartialEq, serde::Serialize)]
pub struct Damage {
    /// The damaged file.
    pub file: PathBuf,
    /// How far into the file reading got, bytes, where known.
    pub byte_offset: Option<u64>,
    /// The file's size, bytes.
    pub file_size: u64,
    /// What the storage library said.
    pub cause: String,
    /// How many messages were read before the damage (all files).
    pub messages_read: u64,
    /// The topic and index of the last message read whole.
    pub last_message: Option<(String, u64)>,
    /// Messages recovered past the damage from the pages of an SQLite file that SQLite could
    /// not read on (they are among `messages_read`).
    pub recovered_from_pages: u64,
}

impl Damage {
    /// The damage in words: the file, where, the last whole message and the cause.
    pub fn describe(&self) -> String {
        let at = match self.byte_offset {
            Some(offset) if offset >= self.file_size => {
                format!("where it ends, at byte {}", self.file_size)
            }
            Some(offset) => format!("at byte {offset} of {}", self.file_size),
            None => format!("({} bytes)", self.file_size),
        };
        let last = match &self.last_message {
            Some((topic, index)) => format!("the last whole message is {topic} #{index}"),
            None => "no message before it could be read".to_string(),
        };
        let recovered = match self.recovered_from_pages {
            0 => String::new(),
            n => format!(" ({n} of them recovered from the file's pages past the damage)"),
        };
        format!(
            "{} is damaged {at}: {}; {} messages read{recovered}, {last}",
            self.file.display(),
            self.cause,
            self.messages_read
        )
    }
}

/// Refuses a storage file of 0 bytes by name: read, it was called damaged at byte 0 (MCAP)
/// or said to have no table of topics (SQLite), and offered `--salvage`, where nothing was
/// ever recorded into it.
/// Checks each of a bag's files before its storage reads it: an empty file, one that cannot be
/// opened (said with the system's reason, not as damage), and one whose first bytes are not its
/// storage's (a text file named `.mcap`, an MCAP named `.db3`) are refused by name. A file that
/// holds only the start of its storage's header (cut short), or is zstd-compressed, is left to
/// the storage's reader.
fn check_files(storage: Storage, files: &[std::path::PathBuf]) -> Result<()> {
    for file in files {
        if std::fs::metadata(file).is_ok_and(|m| m.len() == 0) {
            return Err(Error::Invalid(format!(
                "{} is empty (0 bytes): nothing was recorded into it",
                file.display()
            )));
        }
        if has_zstd_extension(file) {
            std::fs::File::open(file).map_err(|e| Error::io(file, e))?;
            continue;
        }
        let head = first_bytes(file).map_err(|e| Error::io(file, e))?;
        match magic_storage(&head) {
            Some(found) if found == storage => {}
            // The start of its storage's own header: a file cut short, for the reader to say.
            None if storage.magic().starts_with(&head) => {}
            Some(found) => {
                return Err(Error::Invalid(format!(
                    "{} is {} data, but the bag's files are {}: rename it .{} or give it alone",
                    file.display(),
                    found.kind(),
                    storage.kind(),
                    found.extension()
                )))
            }
            None => {
                return Err(Error::Invalid(format!(
                    "{} is not {}: its first bytes are not {}'s (a file of another kind under a \
                     bag's name?)",
                    file.display(),
                    storage.kind(),
                    storage.kind()
                )))
            }
        }
    }
    Ok(())
}

/// The storage a file's first bytes say (up to 16): MCAP's magic or SQLite's header.
fn magic_storage(head: &[u8]) -> Option<Storage> {
    [Storage::Mcap, Storage::Sqlite3]
        .into_iter()
        .find(|s| head.starts_with(s.magic()))
}

impl Bag {
    /// Opens a bag: a rosbag2 folder (its `metadata.yaml` names the storage and the files; a
    /// folder without one is read from its `.mcap` or `.db3` files in name order), or a single
    /// `.mcap` or `.db3` file.
    ///
    /// # Errors
    /// [`Error::Invalid`] for a path that is neither, a folder whose files are missing or of
    /// two storages, an unknown storage or compression; [`Error::Parse`] for a malformed
    /// `metadata.yaml`.
    pub fn open(path: &Path) -> Result<Bag> {
        if path.is_file() {
            return Self::open_file(path);
        }
        if !path.is_dir() {
            return Err(Error::Invalid(format!(
                "{} does not exist; give a rosbag2 folder (metadata.yaml with .mcap or .db3 \
                 files) or one .mcap file",
                path.display()
            )));
        }
        let metadata_path = path.join("metadata.yaml");
        let metadata = if metadata_path.is_file() {
            Some(read_metadata(&metadata_path)?)
        } else {
            None
        };
        let (storage, files) = match &metadata {
            Some(m) => files_of_metadata(path, &metadata_path, m)?,
            None => files_in_folder(path)?,
        };
        let (file_compressed, message_compressed) = compression(&metadata_path, metadata.as_ref())?;
        check_files(storage, &files)?;
        Ok(Bag {
            path: path.to_path_buf(),
            storage,
            files,
            metadata,
            file_compressed,
            message_compressed,
        })
    }

    fn open_file(path: &Path) -> Result<Bag> {
        let storage = storage_of_file(path).ok_or_else(|| {
            Error::Invalid(format!(
                "{} is neither an MCAP nor an SQLite (.db3) file, by its name or its first bytes; \
                 give a rosbag2 folder or one .mcap file",
                path.display()
            ))
        })?;
        check_files(storage, &[path.to_path_buf()])?;
        Ok(Bag {
            path: path.to_path_buf(),
            storage,
            files: vec![path.to_path_buf()],
            metadata: None,
            file_compressed: has_zstd_extension(path),
            message_compressed: false,
        })
    }

    /// The size of all files, bytes.
    pub fn size_bytes(&self) -> u64 {
        self.files
            .iter()
            .map(|f| std::fs::metadata(f).map_or(0, |m| m.len()))
            .sum()
    }

    /// Reads every message in file order and gives it to `visit`; `progress` gets the bytes
    /// read so far (of [`Bag::size_bytes`]) now and then.
    ///
    /// # Returns
    /// `None` when every file was read to its end, or where a file stopped being readable
    /// ([`Damage`]): the messages before it were all given to `visit`, and later files are not
    /// read.
    ///
    /// # Errors
    /// An error of `visit`, a file that cannot be opened, or a message of a compressed bag
    /// that does not decompress.
    pub fn read(
        &self,
        visit: &mut dyn FnMut(&BagMessage) -> Result<()>,
        progress: &mut dyn FnMut(u64),
    ) -> Result<Option<Damage>> {
        let mut state = ReadState::default();
        for file in &self.files {
            let damage = match self.storage {
                Storage::Mcap => self.read_mcap(file, &mut state, visit, progress)?,
                Storage::Sqlite3 => self.read_sqlite(file, &mut state, visit, progress)?,
            };
            if let Some(damage) = damage {
                return Ok(Some(damage));
            }
            state.bytes_before += std::fs::metadata(file).map_or(0, |m| m.len());
        }
        Ok(None)
    }

    /// Hands one message to `visit`, decompressing it first in a `MESSAGE`-compressed bag.
    #[allow(clippy::too_many_arguments)]
    fn deliver(
        &self,
        state: &mut ReadState,
        file: &Path,
        topic: &str,
        type_name: &str,
        format: &str,
        log_time_ns: i64,
        data: &[u8],
        visit: &mut dyn FnMut(&BagMessage) -> Result<()>,
    ) -> Result<()> {
        let index = state.next_index(topic);
        let decompressed;
        let data = if self.message_compressed {
            decompressed = zstd::decode_all(data).map_err(|e| {
                Error::parse(
                    file,
                    None,
                    format!("{topic} message #{index} does not decompress (zstd): {e}"),
                )
            })?;
            &decompressed[..]
        } else {
            data
        };
        visit(&BagMessage {
            topic,
            type_name,
            serialization_format: format,
            index,
            log_time_ns,
            data,
            file,
        })?;
        state.messages_read += 1;
        state.last = Some((topic.to_string(), index));
        Ok(())
    }

    fn read_mcap(
        &self,
        file: &Path,
        state: &mut ReadState,
        visit: &mut dyn FnMut(&BagMessage) -> Result<()>,
        progress: &mut dyn FnMut(u64),
    ) -> Result<Option<Damage>> {
        let handle = std::fs::File::open(file).map_err(|e| Error::io(file, e))?;
        let size = handle.metadata().map_or(0, |m| m.len());
        let counter = Rc::new(Cell::new(0u64));
        let counting = Counting {
            inner: handle,
            count: Rc::clone(&counter),
        };
        let source: Box<dyn Read> = if self.file_compressed {
            Box::new(zstd::Decoder::new(counting).map_err(|e| Error::io(file, e))?)
        } else {
            Box::new(std::io::BufReader::with_capacity(1 << 20, counting))
        };
        let options = mcap::sans_io::LinearReaderOptions::default()
            // A chunk's CRC checked before any of its messages is used: a changed byte must
            // not reach the import as a message.
            .with_prevalidate_chunk_crcs(true)
            .with_record_length_limit(usize::try_from(MCAP_RECORD_LIMIT).unwrap_or(usize::MAX));
        let reader = mcap::io::MessageReader::new_with_options(source, options);
        for (n, message) in reader.enumerate() {
            let message = match message {
                Ok(m) => m,
                Err(e) => {
                    return Ok(Some(state.damage(
                        file,
                        Some(counter.get()),
                        size,
                        mcap_cause(&e),
                    )))
                }
            };
            let channel = &message.channel;
            let type_name = channel.schema.as_ref().map_or("", |s| s.name.as_str());
            self.deliver(
                state,
                file,
                &channel.topic,
                type_name,
                &channel.message_encoding,
                i64::try_from(message.log_time).unwrap_or(i64::MAX),
                &message.data,
                visit,
            )?;
            if n % 256 == 0 {
                progress(state.bytes_before + counter.get());
            }
        }
        progress(state.bytes_before + size);
        Ok(None)
    }

    fn read_sqlite(
        &self,
        file: &Path,
        state: &mut ReadState,
        visit: &mut dyn FnMut(&BagMessage) -> Result<()>,
        progress: &mut dyn FnMut(u64),
    ) -> Result<Option<Damage>> {
        let size = std::fs::metadata(file).map_or(0, |m| m.len());
        let unpacked = if self.file_compressed {
            Some(TemporaryCopy::unpack(file)?)
        } else {
            None
        };
        let db_path = unpacked.as_ref().map_or(file, |t| t.path.as_path());
        let flags =
            rusqlite::OpenFlags::SQLITE_OPEN_READ_ONLY | rusqlite::OpenFlags::SQLITE_OPEN_NO_MUTEX;
        let db = match rusqlite::Connection::open_with_flags(db_path, flags) {
            Ok(db) => db,
            Err(e) => return Ok(Some(state.damage(file, None, size, format!("SQLite: {e}")))),
        };
        // A file cut short holds fewer pages than its header says, which SQLite calls corrupt
        // unless the schema is writable; read-only, that only makes it read what is there.
        let _ = db.execute_batch("PRAGMA writable_schema = ON");
        let topics = match sqlite_topics(&db) {
            Ok(t) => t,
            Err(e) => return Ok(Some(state.damage(file, None, size, format!("SQLite: {e}")))),
        };
        let mut last_id = 0i64;
        let stopped = self.sqlite_rows(
            &db,
            file,
            size,
            &topics,
            &mut last_id,
            state,
            visit,
            progress,
        )?;
        let Some(e) = stopped else {
            progress(state.bytes_before + size);
            return Ok(None);
        };
        // SQLite stops where the file's index is lost; the rows may still lie in its pages.
        let mut damage = state.damage(file, None, size, format!("SQLite: {e}"));
        for row in super::sqlite_pages::rows_after(db_path, last_id) {
            let Some(topic) = topics.get(&row.topic_id) else {
                continue;
            };
            self.deliver(
                state,
                file,
                &topic.0,
                &topic.1,
                &topic.2,
                row.timestamp,
                &row.data,
                visit,
            )?;
            damage.recovered_from_pages += 1;
        }
        damage.messages_read = state.messages_read;
        damage.last_message.clone_from(&state.last);
        Ok(Some(damage))
    }

    /// Reads the `messages` table in id order until its end (`None`) or an error of SQLite's
    /// (returned); `last_id` is the id of the last row delivered.
    #[allow(clippy::too_many_arguments)]
    fn sqlite_rows(
        &self,
        db: &rusqlite::Connection,
        file: &Path,
        size: u64,
        topics: &HashMap<i64, (String, String, String)>,
        last_id: &mut i64,
        state: &mut ReadState,
        visit: &mut dyn FnMut(&BagMessage) -> Result<()>,
        progress: &mut dyn FnMut(u64),
    ) -> Result<Option<rusqlite::Error>> {
        let rows_total: u64 = db
            .query_row("SELECT MAX(id) FROM messages", [], |r| {
                r.get::<_, Option<i64>>(0)
            })
            .ok()
            .flatten()
            .map_or(0, |v| v.max(0) as u64);
        let mut statement =
            match db.prepare("SELECT id, topic_id, timestamp, data FROM messages ORDER BY id") {
                Ok(s) => s,
                Err(e) => return Ok(Some(e)),
            };
        let mut rows = match statement.query([]) {
            Ok(r) => r,
            Err(e) => return Ok(Some(e)),
        };
        let mut n = 0u64;
        loop {
            let row = match rows.next() {
                Ok(Some(row)) => row,
                Ok(None) => return Ok(None),
                Err(e) => return Ok(Some(e)),
            };
            let fields = (|| -> rusqlite::Result<_> {
                Ok((
                    row.get::<_, i64>(0)?,
                    row.get::<_, i64>(1)?,
                    row.get::<_, i64>(2)?,
                    row.get_ref(3)?.as_blob()?,
                ))
            })();
            let (id, topic_id, timestamp, data) = match fields {
                Ok(f) => f,
                Err(e) => return Ok(Some(e)),
            };
            let Some(topic) = topics.get(&topic_id) else {
                return Err(Error::parse(
                    file,
                    None,
                    format!(
                        "message {n} names topic id {topic_id}, which the topics table does not \
                         hold; the database is not a rosbag2 bag or is damaged"
                    ),
                ));
            };
            self.deliver(
                state, file, &topic.0, &topic.1, &topic.2, timestamp, data, visit,
            )?;
            *last_id = id;
            n += 1;
            if n.is_multiple_of(256) && rows_total > 0 {
                progress(state.bytes_before + size * n.min(rows_total) / rows_total);
            }
        }
    }
}

/// The largest record or chunk the MCAP reader accepts, bytes: a length beyond it is damage.
/// Not the file's size: a chunk of zeros may unpack to a thousand times its stored size.
const MCAP_RECORD_LIMIT: u64 = 4 << 30;

/// An MCAP reading error in words, naming the likely cause of the usual ones.
fn mcap_cause(e: &mcap::McapError) -> String {
    match e {
        mcap::McapError::UnexpectedEof => "the file ends in the middle of a record (cut short: \
             a copy that did not finish, or a recording that was killed)"
            .to_string(),
        mcap::McapError::BadMagic | mcap::McapError::BadFooter => format!(
            "{e} (the file does not end as an MCAP file does: cut short, or a recording that \
             was not closed)"
        ),
        other => format!("MCAP: {other}"),
    }
}

/// `id → (name, type, serialization format)` of a rosbag2 SQLite database's `topics` table.
fn sqlite_topics(
    db: &rusqlite::Connection,
) -> rusqlite::Result<HashMap<i64, (String, String, String)>> {
    let mut statement = db.prepare("SELECT id, name, type, serialization_format FROM topics")?;
    let rows = statement.query_map([], |r| {
        Ok((r.get::<_, i64>(0)?, (r.get(1)?, r.get(2)?, r.get(3)?)))
    })?;
    rows.collect()
}

/// What a read has seen so far, across files.
#[derive(Default)]
struct ReadState {
    per_topic: HashMap<String, u64>,
    messages_read: u64,
    last: Option<(String, u64)>,
    bytes_before: u64,
}

impl ReadState {
    fn next_index(&mut self, topic: &str) -> u64 {
        let slot = self.per_topic.entry(topic.to_string()).or_insert(0);
        let index = *slot;
        *slot += 1;
        index
    }

    fn damage(&self, file: &Path, offset: Option<u64>, size: u64, cause: String) -> Damage {
        Damage {
            file: file.to_path_buf(),
            byte_offset: offset,
            file_size: size,
            cause,
            messages_read: self.messages_read,
            last_message: self.last.clone(),
            recovered_from_pages: 0,
        }
    }
}

/// A reader that counts the bytes read through it.
struct Counting<R> {
    inner: R,
    count: Rc<Cell<u64>>,
}

impl<R: Read> Read for Counting<R> {
    fn read(&mut self, buf: &mut [u8]) -> std::io::Result<usize> {
        let n = self.inner.read(buf)?;
        self.count.set(self.count.get() + n as u64);
        Ok(n)
    }
}

/// A zstd-compressed database unpacked into the temporary folder, removed when dropped.
struct TemporaryCopy {
    path: PathBuf,
}

impl TemporaryCopy {
    fn unpack(file: &Path) -> Result<Self> {
        use std::sync::atomic::{AtomicU64, Ordering};
        static COUNTER: AtomicU64 = AtomicU64::new(0);
        let path = std::env::temp_dir().join(format!(
            "sdem-bag-{}-{}.db3",
            std::process::id(),
            COUNTER.fetch_add(1, Ordering::Relaxed)
        ));
        let copy = Self { path };
        let input = std::fs::File::open(file).map_err(|e| Error::io(file, e))?;
        let mut decoder = zstd::Decoder::new(input).map_err(|e| Error::io(file, e))?;
        let mut output = std::fs::File::create(&copy.path).map_err(|e| Error::io(&copy.path, e))?;
        std::io::copy(&mut decoder, &mut output)
            .map_err(|e| Error::parse(file, None, format!("does not decompress (zstd): {e}")))?;
        Ok(copy)
    }
}

impl Drop for TemporaryCopy {
    fn drop(&mut self) {
        let _ = std::fs::remove_file(&self.path);
    }
}

fn has_zstd_extension(path: &Path) -> bool {
    path.extension().is_some_and(|e| e == "zstd")
}

/// The storage of one bag file: by its first bytes (MCAP's magic, SQLite's header), else by
/// its name ([`storage_by_name`]; a `.zstd` file's first bytes are zstd's).
pub(crate) fn storage_of_file(path: &Path) -> Option<Storage> {
    storage_by_magic(path).or_else(|| storage_by_name(path))
}

/// The storage a bag file's name says: `.mcap` or `.db3`, in any case, optionally `.zstd`.
pub(crate) fn storage_by_name(path: &Path) -> Option<Storage> {
    let name = path.file_name()?.to_string_lossy().to_ascii_lowercase();
    let name = name.strip_suffix(".zstd").unwrap_or(&name);
    if name.ends_with(".mcap") {
        Some(Storage::Mcap)
    } else if name.ends_with(".db3") {
        Some(Storage::Sqlite3)
    } else {
        None
    }
}

/// The storage a file's first bytes say: MCAP's magic or SQLite's header.
fn storage_by_magic(path: &Path) -> Option<Storage> {
    magic_storage(&first_bytes(path).ok()?)
}

/// A file's first 16 bytes (fewer for a shorter file): enough for either storage's header.
fn first_bytes(path: &Path) -> std::io::Result<Vec<u8>> {
    use std::io::Read;
    let mut head = Vec::with_capacity(16);
    std::fs::File::open(path)?.take(16).read_to_end(&mut head)?;
    Ok(head)
}

fn files_of_metadata(
    folder: &Path,
    metadata_path: &Path,
    metadata: &Metadata,
) -> Result<(Storage, Vec<PathBuf>)> {
    let storage = match metadata.storage_identifier.as_str() {
        "mcap" => Storage::Mcap,
        "sqlite3" => Storage::Sqlite3,
        other => {
            return Err(Error::parse(
                metadata_path,
                None,
                format!("storage_identifier '{other}' is not one sdem reads (mcap, sqlite3)"),
            ))
        }
    };
    if metadata.relative_file_paths.is_empty() {
        return files_in_folder(folder);
    }
    let mut files = Vec::new();
    for name in &metadata.relative_file_paths {
        let path = folder.join(name);
        if !path.is_file() {
            return Err(Error::Invalid(format!(
                "{} lists {name}, but {} does not exist; copy the whole bag folder",
                metadata_path.display(),
                path.display()
            )));
        }
        files.push(path);
    }
    Ok((storage, files))
}

fn files_in_folder(folder: &Path) -> Result<(Storage, Vec<PathBuf>)> {
    let mut found: Vec<(Storage, PathBuf)> = Vec::new();
    for entry in std::fs::read_dir(folder).map_err(|e| Error::io(folder, e))? {
        let path = entry.map_err(|e| Error::io(folder, e))?.path();
        if let Some(storage) = storage_by_name(&path).filter(|_| path.is_file()) {
            found.push((storage, path));
        }
    }
    found.sort_by(|a, b| a.1.cmp(&b.1));
    let Some(&(storage, _)) = found.first() else {
        return Err(Error::Invalid(format!(
            "{} holds no metadata.yaml and no .mcap or .db3 file: it is not a rosbag2 folder",
            folder.display()
        )));
    };
    if found.iter().any(|(s, _)| *s != storage) {
        return Err(Error::Invalid(format!(
            "{} holds both .mcap and .db3 files and no metadata.yaml to say which make the bag",
            folder.display()
        )));
    }
    Ok((storage, found.into_iter().map(|(_, p)| p).collect()))
}

/// Whether the bag's files (`FILE`) or messages (`MESSAGE`) are zstd-compressed.
fn compression(metadata_path: &Path, metadata: Option<&Metadata>) -> Result<(bool, bool)> {
    let Some(m) = metadata else {
        return Ok((false, false));
    };
    let mode = m.compression_mode.to_ascii_uppercase();
    if mode.is_empty() || mode == "NONE" {
        return Ok((false, false));
    }
    if m.compression_format != "zstd" {
        return Err(Error::parse(
            metadata_path,
            None,
            format!(
                "compression_format '{}' is not one sdem reads (zstd); decompress the bag with \
                 `ros2 bag convert`",
                m.compression_format
            ),
        ));
    }
    match mode.as_str() {
        "FILE" => Ok((true, false)),
        "MESSAGE" => Ok((false, true)),
        other => Err(Error::parse(
            metadata_path,
            None,
            format!("compression_mode '{other}' is not FILE or MESSAGE"),
        )),
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    /// An empty `.mcap` or `.db3` is named empty, not damaged at byte 0 or missing its table of
    /// topics, whether given alone or in a bag folder.
    #[test]
    fn an_empty_storage_file_is_named_empty() {
        let dir = tempfile::tempdir().unwrap();
        for name in ["run.mcap", "run_0.db3"] {
            let path = dir.path().join(name);
            std::fs::write(&path, b"").unwrap();
            let e = Bag::open(&path).unwrap_err().to_string();
            assert!(e.contains(name) && e.contains("is empty (0 bytes)"), "{e}");
            std::fs::remove_file(&path).unwrap();
        }
        let folder = dir.path().join("bag");
        std::fs::create_dir(&folder).unwrap();
        std::fs::write(folder.join("bag_0.mcap"), b"").unwrap();
        let e = Bag::open(&folder).unwrap_err().to_string();
        assert!(e.contains("is empty (0 bytes)"), "{e}");
    }
}
