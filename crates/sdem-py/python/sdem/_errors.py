"""The exceptions sdem raises: ``sdem.Error`` and one subclass per cause a caller can act on.

They mirror the Rust library's ``sdem::Error`` variants (and ``sdem_io::Error`` for files), and
carry each variant's fields as attributes. A localization that succeeds with doubts raises
nothing: its result says ``trusted == False``.
"""

from __future__ import annotations

__all__ = [
    "Error",
    "InvalidError",
    "InvalidInputError",
    "TooFewPointsError",
    "NoUsablePointsError",
    "TooManyCandidatesError",
    "MatchError",
    "NoOverlapError",
    "NoMatchError",
    "NoSurfacesError",
    "RefinementFailedError",
    "NotFoundError",
    "AtScanError",
    "NodeStoreError",
    "FileError",
    "ParseError",
]


class Error(Exception):
    """Every error sdem raises. ``is_no_match`` is True when the scans were usable but did not
    match (``sdem::Error::is_no_match``): widen the search, try other nodes, or keep the scan
    out of the map; otherwise the input or the options were bad."""

    is_no_match: bool = False


class InvalidError(Error, ValueError):
    """An option or configuration value is out of its valid range, or a request cannot be
    carried out as asked; the message says which and how to fix it (``Error::Invalid``)."""


class InvalidInputError(Error, ValueError):
    """Input data that cannot be used: points that are not an ``(N, 3)`` float array, an
    infinite coordinate, a non-finite attitude (``Error::InvalidInput``).

    Attributes:
        what: which input (``"points"``, ``"point 17"``, ``"attitude"``, ...).
        problem: what is wrong with it.
    """

    what: str
    problem: str


class TooFewPointsError(Error, ValueError):
    """A scan fills too few S-DEM cells to be localized or to localize against
    (``Error::TooFewPoints``).

    Attributes:
        usable: cells that hold a return.
        needed: the fewest a localization needs.
    """

    usable: int
    needed: int


class NoUsablePointsError(TooFewPointsError):
    """A scan of which the S-DEM grid can use no point (``Error::NoUsablePoints``): it is
    empty, none of its points is finite, they all lie at the sensor's origin (within the grid's
    minimum range), or outside the grid. A ``TooFewPointsError`` with ``usable == 0``; raised
    by ``Scan`` and ``Map.localize`` alike, and worded as ``sdem localize`` words it.

    Attributes:
        reason: why no point is usable, with the counts.
    """

    reason: str


class TooManyCandidatesError(InvalidError):
    """The exhaustive search's grid holds more candidates than ``max_exhaustive_candidates``;
    refused before any is scored (``Error::TooManyCandidates``). Shrink the window, coarsen the
    step or narrow the heading window, or use the branch-and-bound search (the same minimum).

    Attributes:
        candidates: candidates in the grid.
        grid: positions along x, y and z, and headings.
        limit: the most the exhaustive search scores.
    """

    candidates: int
    grid: list[int]
    limit: int


class MatchError(Error):
    """The scans were usable but did not match (every error whose ``is_no_match`` is True,
    except ``AtScanError``, which carries one as its ``source``)."""

    is_no_match = True


class NoOverlapError(MatchError):
    """No candidate in the search window shares enough cells with the query at a cost low
    enough to be a match (``Error::NoOverlap``).

    Attributes:
        needed: cells a candidate must share.
        compared: query points compared.
        max_cost_m2: the highest cost a match may have, m².
    """

    needed: int
    compared: int
    max_cost_m2: float


class NoMatchError(MatchError):
    """The best candidate in the window matches too few of the query's points: the scans may
    not overlap, or the motion lies outside the window (``Error::NoMatch``).

    Attributes:
        matched: compared points within the truncation at the best candidate.
        compared: query points compared.
        needed: the fewest that must match.
        truncation_m: the truncation distance, metres.
    """

    matched: int
    compared: int
    needed: int
    truncation_m: float


class NoSurfacesError(MatchError):
    """Without an attitude reading, a scan shows no surface whose orientation can be measured
    to find the rotation from (``Error::NoSurfaces``).

    Attributes:
        which: ``"reference"`` or ``"query"``.
    """

    which: str


class RefinementFailedError(MatchError):
    """The continuous refinement could not be solved (``Error::RefinementFailed``).

    Attributes:
        reason: why.
    """

    reason: str


class NotFoundError(MatchError):
    """A relocalization found no node that the scan matches (``Error::NotFound``).

    Attributes:
        tried: each node tried, as ``(node_id, why it did not match)``.
    """

    tried: list[tuple[int, str]]


class AtScanError(Error):
    """A step of the loop failed to localize its scan against the map; the map is unchanged
    (``Error::AtScan``). The step's own error is ``source`` (and ``__cause__``).

    Attributes:
        scan_index: the scan's index.
        nodes: the nodes it was matched against.
        source: the step's error, an ``sdem.Error``.
        is_no_match: whether ``source`` is a no-match.
    """

    scan_index: int
    nodes: list[int]
    source: Error


class NodeStoreError(Error, OSError):
    """The store that keeps the points of nodes far from the robot on disk could not keep or
    give one back (``Error::NodeStore``); the map is as it was before the step.

    Attributes:
        node_id: the node.
        reason: what the store said.
    """

    node_id: int
    reason: str


class FileError(Error, OSError):
    """A file could not be opened, read or written (``sdem_io::Error::Io``): an ``OSError``
    with ``errno``, ``strerror`` and ``filename``."""


class ParseError(Error, ValueError):
    """A file was read but its content is malformed (``sdem_io::Error::Parse``).

    Attributes:
        path: the file.
        line: the 1-based line, or ``None`` for the whole file.
        message: what is wrong and, where possible, how to fix it.
    """

    path: str
    line: int | None
    message: str
