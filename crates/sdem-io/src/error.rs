//! The errors of reading and writing files: each names the file and, where it has one, the line.

use std::path::PathBuf;

/// What can go wrong reading or writing sdem's files. Each message names the file and, for
/// text, the 1-based line, and says what is wrong and how to fix it, so the command line can
/// print it as one line.
#[derive(Debug, thiserror::Error)]
pub enum Error {
    /// A file could not be opened, read or written.
    #[error("{}: {source}{hint}", path.display())]
    Io {
        /// The file.
        path: PathBuf,
        /// What the operating system said.
        #[source]
        source: std::io::Error,
        /// What the system's words leave out, as seen when the error was made (` (the folder F
        /// does not exist)`, ` (a folder: give a file)`), or empty.
        hint: String,
    },
    /// A file was read but its content is malformed.
    #[error("{}{}: {message}", path.display(), line.map(|l| format!(":{l}")).unwrap_or_default())]
    Parse {
        /// The file.
        path: PathBuf,
        /// The 1-based line, where the problem has one.
        line: Option<usize>,
        /// What is wrong and, where possible, how to fix it.
        message: String,
    },
    /// A request that cannot be carried out as asked (a folder that would be overwritten, data
    /// that cannot be written in the format); the message says which and how to fix it.
    #[error("{0}")]
    Invalid(String),
    /// An error of the algorithms, passed on (an invalid configuration read from a file, …).
    #[error(transparent)]
    Sdem(#[from] sdem::Error),
}

impl Error {
    /// An I/O error on `path`.
    pub fn io(path: impl Into<PathBuf>, source: std::io::Error) -> Self {
        let path = path.into();
        let hint = io_hint(&path, &source);
        Error::Io { path, source, hint }
    }

    /// A parse error in `path` at 1-based `line` (or `None` for the whole file).
    pub fn parse(
        path: impl Into<PathBuf>,
        line: Option<usize>,
        message: impl Into<String>,
    ) -> Self {
        Error::Parse {
            path: path.into(),
            line,
            message: message.into(),
        }
    }
}

/// What the operating system's words leave out, for the errors a user meets most: a path whose
/// folder is missing (the file's own name is not what is wrong), a folder given where a file is
/// wanted, and a full disk (what to do, and that the saved map is whole).
fn io_hint(path: &std::path::Path, source: &std::io::Error) -> String {
    let parent = path.parent().filter(|p| !p.as_os_str().is_empty());
    match source.kind() {
        std::io::ErrorKind::NotFound => match parent {
            Some(folder) if !folder.exists() => {
                format!(" (the folder {} does not exist)", folder.display())
            }
            _ => String::new(),
        },
        std::io::ErrorKind::IsADirectory => " (a folder: give a file)".to_string(),
        std::io::ErrorKind::StorageFull => {
            " (free some space and run again; a map being saved keeps its previous version, \
             and `sdem slam --resume` goes on from it)"
                .to_string()
        }
        _ => String::new(),
    }
}

/// The result of reading or writing a file.
pub type Result<T, E = Error> = std::result::Result<T, E>;

/// An error's text on one line: a message of another crate may spread over lines (ply-rs-bw's
/// tabs), or quote a line break from the file it read (serde_json naming a damaged key), and an
/// error of this crate is one line.
pub(crate) fn one_line(e: &impl std::fmt::Display) -> String {
    e.to_string()
        .split_whitespace()
        .collect::<Vec<_>>()
        .join(" ")
}

#[cfg(test)]
mod tests {
    use super::*;

    /// A missing folder is named, not only the file; a folder given for a file is said to be
    /// one; a missing file in a folder that exists keeps the system's words alone.
    #[test]
    fn io_errors_say_what_the_system_leaves_out() {
        let dir = tempfile::tempdir().unwrap();
        let missing_folder = dir.path().join("nodir/x.mcap");
        let e = Error::io(
            &missing_folder,
            std::fs::File::create(&missing_folder).unwrap_err(),
        );
        assert!(e.to_string().contains("nodir does not exist"), "{e}");
        let folder = dir.path().join("a.ply");
        std::fs::create_dir(&folder).unwrap();
        let e = Error::io(&folder, std::fs::read(&folder).unwrap_err());
        assert!(e.to_string().contains("a folder: give a file"), "{e}");
        let missing_file = dir.path().join("b.ply");
        let e = Error::io(&missing_file, std::fs::read(&missing_file).unwrap_err());
        assert!(!e.to_string().contains("does not exist)"), "{e}");
        let full = std::io::Error::from(std::io::ErrorKind::StorageFull);
        let e = Error::io(dir.path().join("map/map.json"), full);
        assert!(e.to_string().contains("free some space") && e.to_string().contains("--resume"));
    }
}
