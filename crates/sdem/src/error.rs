//! The library's error type: every failure says what was wrong and where, with its figures.

/// What can go wrong in sdem's algorithms: a variant per cause a caller can act on, each with
/// its figures, and a message that can be printed as one line. (Files have their own errors, in
/// `sdem-io`.)
#[derive(Debug, thiserror::Error)]
pub enum Error {
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
    /// A scan of which the S-DEM grid can use no point, with why
    /// ([`crate::sdem::Sdem::from_usable_points`]): it is empty, none of its points is finite,
    /// every one lies within the grid's minimum range of the sensor's origin, or none lies in
    /// the grid's extent. A scan that fills some cells but too few is [`Error::TooFewPoints`].
    #[error(
        "the scan has no usable point: {reason}; check that it holds the scan's points, in \
         metres in the sensor frame"
    )]
    NoUsablePoints {
        /// Why no point fills a cell, with the counts.
        reason: String,
    },
    /// A scan fills too few S-DEM cells to be localized or to localize against.
    #[error(
        "the scan fills {usable} {} of its S-DEM, fewer than the {needed} a localization \
         compares; check that the points are metres in the sensor frame and within range",
        if *.usable == 1 { "cell" } else { "cells" }
    )]
    TooFewPoints {
        /// Cells that hold a return.
        usable: usize,
        /// The fewest a localization needs.
        needed: usize,
    },
    /// No candidate in the search window shares enough cells with the query at a cost low
    /// enough to be a match ([`crate::cost::CostConfig::max_match_cost`]).
    #[error(
        "no candidate in the window matches: none shares {needed} cells with the query \
         S-DEM ({compared} compared) at a cost of at most {max_cost_m2:.5} m²; check the window \
         and the attitudes, or lower the minimum overlap"
    )]
    NoOverlap {
        /// Cells a candidate must share.
        needed: usize,
        /// Query points compared.
        compared: usize,
        /// The highest cost a match may have, m².
        max_cost_m2: f64,
    },
    /// The exhaustive search's grid holds more candidates than
    /// [`crate::localize::LocalizeOptions::max_exhaustive_candidates`]: it is refused before
    /// any is scored.
    #[error(
        "the exhaustive search would score {candidates} candidates ({} × {} × {} positions × {} \
         headings), more than its limit of {limit} (about a minute on 2 cores); use a smaller \
         window, a coarser step or a narrower heading window, or the branch-and-bound search, \
         which finds the same minimum",
        grid[0], grid[1], grid[2], grid[3]
    )]
    TooManyCandidates {
        /// Candidates in the grid.
        candidates: usize,
        /// The grid: positions along x, y and z, and headings.
        grid: [usize; 4],
        /// The most the exhaustive search scores.
        limit: usize,
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
    /// The attitude of a scan is unknown, and too few of its cells show a surface whose
    /// orientation can be measured to find the rotation between the scans from them.
    #[error(
        "without an attitude reading the rotation between the scans comes from their surfaces' \
         orientations, and the {which} shows no surface whose orientation can be measured \
         (isolated returns); give the scans' attitude readings"
    )]
    NoSurfaces {
        /// `"reference"` or `"query"`.
        which: &'static str,
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
    /// The node store ([`crate::store::NodeStore`]) could not keep or give back a node's
    /// points (a full disk, a removed or damaged file): the step that needed them failed, and
    /// the map is as it was before it.
    #[error("node {node_id}'s points in the node store: {reason}")]
    NodeStore {
        /// The node.
        node_id: usize,
        /// What the store said.
        reason: String,
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
    /// This error, naming scan `scan_index` where it says why a scan has no usable point
    /// (the loop's scans are told apart by their index); any other error as it is.
    pub(crate) fn of_scan(self, scan_index: usize) -> Self {
        match self {
            Error::NoUsablePoints { reason } => Error::NoUsablePoints {
                reason: format!("{reason} (scan {scan_index})"),
            },
            e => e,
        }
    }

    /// Whether the scans were usable but did not match: nothing in the window overlaps or
    /// matches, the refinement failed, or no node matched. A caller can widen the search, try
    /// other nodes, or keep the scan out of the map; every other error is bad input or options.
    pub fn is_no_match(&self) -> bool {
        match self {
            Error::NoOverlap { .. }
            | Error::NoMatch { .. }
            | Error::RefinementFailed { .. }
            | Error::NoSurfaces { .. }
            | Error::NotFound { .. } => true,
            Error::AtScan { source, .. } => source.is_no_match(),
            _ => false,
        }
    }
}

/// The library's result type.
pub type Result<T, E = Error> = std::result::Result<T, E>;
