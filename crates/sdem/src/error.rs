//! The library's error type: every failure says what was wrong and where.

use std::path::PathBuf;

/// What can go wrong in sdem. Each variant's message names the problem and, for files, the path
/// and line, so the command line can print it as one line.
#[derive(Debug, thiserror::Error)]
pub enum Error {
    /// A file could not be opened, read or written.
    #[error("{}: {source}", path.display())]
    Io {
        /// The file.
        path: PathBuf,
        /// What the operating system said.
        #[source]
        source: std::io::Error,
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
    /// An option, argument or configuration value is out of its valid range; the message says
    /// which and what range.
    #[error("{0}")]
    Invalid(String),
    /// Input data (points, an attitude) that cannot be used, with what it is and why.
    #[error("{what}: {problem}")]
    InvalidInput {
        /// Which input: `"attitude"`, `"point 17"`, ….
        what: String,
        /// What is wrong with it.
        problem: String,
    },
    /// A scan fills too few S-DEM cells to be localized or to localize against.
    #[error(
        "the scan fills {usable} cells of its S-DEM, fewer than the {needed} a localization \
         compares; check that the points are metres in the sensor frame and within range"
    )]
    TooFewPoints {
        /// Cells that hold a return.
        usable: usize,
        /// The fewest a localization needs.
        needed: usize,
    },
    /// No candidate in the search window shares enough cells with the query.
    #[error(
        "no candidate in the window shares {needed} cells with the query \
         S-DEM ({compared} compared); check the window and the attitudes, or lower the minimum \
         overlap"
    )]
    NoOverlap {
        /// Cells a candidate must share.
        needed: usize,
        /// Query points compared.
        compared: usize,
    },
    /// The best candidate in the window matches too few of the query's points.
    #[error(
        "nothing in the window matches: at the best candidate only \
         {matched} of the query's {compared} compared cells lie within {truncation_m} m of the \
         reference (need {needed}); the scans may not overlap, or the motion lies outside the \
         window"
    )]
    NoMatch {
        /// Compared points within the truncation at the best candidate.
        matched: usize,
        /// Query points compared.
        compared: usize,
        /// The fewest that must match.
        needed: usize,
        /// The truncation distance, metres.
        truncation_m: f64,
    },
    /// The continuous refinement could not be solved (too few points paired, a degenerate
    /// problem, a step beyond its bounds).
    #[error("{reason}")]
    RefinementFailed {
        /// Why.
        reason: String,
    },
    /// A relocalization found no node that the scan matches.
    #[error(
        "the scan matches none of the nodes tried: {}",
        tried.iter().map(|(n, why)| format!("node {n}: {why}")).collect::<Vec<_>>().join("; ")
    )]
    NotFound {
        /// Each node tried, with why it did not match.
        tried: Vec<(usize, String)>,
    },
    /// A step of the stop-and-go loop failed to localize its scan against the map.
    #[error("scan {scan_index} against nodes {nodes:?}: {source}")]
    AtScan {
        /// The scan's index.
        scan_index: usize,
        /// The nodes it was matched against.
        nodes: Vec<usize>,
        /// What went wrong.
        #[source]
        source: Box<Error>,
    },
}

impl Error {
    /// Whether the scans were usable but did not match: nothing in the window overlaps or
    /// matches, the refinement failed, or no node matched. A caller can widen the search, try
    /// other nodes, or keep the scan out of the map; every other error is bad input or options.
    pub fn is_no_match(&self) -> bool {
        match self {
            Error::NoOverlap { .. }
            | Error::NoMatch { .. }
            | Error::RefinementFailed { .. }
            | Error::NotFound { .. } => true,
            Error::AtScan { source, .. } => source.is_no_match(),
            _ => false,
        }
    }

    /// An I/O error on `path`.
    pub fn io(path: impl Into<PathBuf>, source: std::io::Error) -> Self {
        Error::Io {
            path: path.into(),
            source,
        }
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

/// The library's result type.
pub type Result<T, E = Error> = std::result::Result<T, E>;
