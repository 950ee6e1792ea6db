//! Whether a search's optimum lies on the edge of the caller's window, so that the true pose may
//! lie beyond it ([`crate::doubt::Doubt::OnWindowEdge`]).

use crate::geometry::Vec3;
use crate::search::{CandidateGrid, Index, SearchWindow};

/// Whether a grid optimum on the searched grid's edge (`idx`) lies on the edge of `edges`, the
/// caller's window, which holds the searched one (a search around a candidate of another basin
/// covers a small window inside it).
///
/// Without a refinement (`refined: None`), where the caller's window holds no candidate a step
/// beyond it on that side (a heading edge always: the searched headings are the caller's). An
/// optimum on a small window's edge well inside the caller's is a neighbour of the candidate
/// searched around, not a pose the window cut off. Where the searched window is the caller's,
/// every edge counts.
///
/// With a refinement (its offset and heading correction), when the refined pose lies within
/// half a step (at most [`EDGE_MARGIN_M`]) of the caller's edge it was found on, or beyond. A
/// grid coarser than the pose's precision (a LiDAR's 15–25 cm) puts an optimum well inside the
/// window on its last candidate (with ±15 cm of height at 25 cm steps every candidate is an
/// edge): the refinement, which the window does not bound, says where the pose is.
pub(super) fn stays_on_edge(
    grid: &CandidateGrid,
    idx: Index,
    full_turn: bool,
    edges: &SearchWindow,
    refined: Option<(Vec3, f64)>,
) -> bool {
    (0..4).any(|a| {
        let (low_edge, high_edge) = (idx[a] == 0, idx[a] + 1 == grid.counts[a]);
        if grid.counts[a] <= 1 || !(low_edge || high_edge) || (a == 3 && full_turn) {
            return false;
        }
        let Some((offset, heading)) = refined else {
            if a == 3 {
                return true;
            }
            let at = grid.offset(idx)[a];
            return (low_edge && at - grid.step < edges.min[a] - 1e-9)
                || (high_edge && at + grid.step > edges.max[a] + 1e-9);
        };
        let (value, lo, hi, half) = if a < 3 {
            (
                offset[a],
                edges.min[a],
                edges.max[a],
                (0.5 * grid.step).min(EDGE_MARGIN_M),
            )
        } else {
            let (first, last) = (grid.yaws[0], grid.yaws[grid.yaws.len() - 1]);
            (heading, first, last, 0.5 * (grid.yaws[1] - first).abs())
        };
        (low_edge && value <= lo + half) || (high_edge && value >= hi - half)
    })
}

/// A refined position this close to the window's edge (or half a step, if less) is on it,
/// metres: the refinement is millimetre-precise, and a basin whose bottom lies a few
/// centimetres inside the window is not cut by it.
const EDGE_MARGIN_M: f64 = 0.02;
#[cfg(test)]
mod tests {
    use super::*;

    /// An unrefined optimum on the edge of a small window searched inside the caller's (around
    /// a candidate of another basin) is on the caller's edge only where the caller's window
    /// holds no candidate a step beyond it; a heading edge is always the caller's, and a full
    /// turn has none. Where the searched window is the caller's, every edge counts.
    #[test]
    fn an_unrefined_optimum_is_on_the_edge_only_where_the_edge_is_the_callers() {
        let caller = SearchWindow {
            min: [-0.6, -0.6, -0.3],
            max: [0.6, 0.6, 0.3],
        };
        let yaws = vec![-0.02, 0.0, 0.02];
        let small = |centre: Vec3| {
            // As `not_seen_through` clips it.
            let window = SearchWindow::around(&centre, [0.05; 3]).clipped_to(&caller);
            (
                CandidateGrid::new(&window, 0.05, yaws.clone()).unwrap(),
                window,
            )
        };
        let (grid, inside) = small(Vec3::new(0.1, -0.2, 0.0));
        assert_eq!(grid.counts, [3, 3, 3, 3]);
        let edges = [
            [0, 1, 1, 1],
            [2, 1, 1, 1],
            [1, 0, 1, 1],
            [1, 2, 1, 1],
            [1, 1, 0, 1],
            [1, 1, 2, 1],
        ];
        for idx in edges {
            assert!(!stays_on_edge(&grid, idx, false, &caller, None), "{idx:?}");
            // The same window searched as the caller's own: its edges are the caller's.
            assert!(stays_on_edge(&grid, idx, false, &inside, None), "{idx:?}");
        }
        assert!(!stays_on_edge(&grid, [1, 1, 1, 1], false, &inside, None));
        assert!(stays_on_edge(&grid, [1, 1, 1, 0], false, &caller, None));
        assert!(!stays_on_edge(&grid, [1, 1, 1, 0], true, &caller, None));
        // Clipped at the caller's highest x: that side is the caller's edge, the lowest is not.
        let (grid, _) = small(Vec3::new(0.58, 0.0, 0.0));
        let last = grid.counts[0] - 1;
        assert!(last >= 1, "{:?}", grid.counts);
        assert!(stays_on_edge(&grid, [last, 1, 1, 1], false, &caller, None));
        assert!(!stays_on_edge(&grid, [0, 1, 1, 1], false, &caller, None));
        // Not clipped, its lowest candidate the caller's first (the window's bound a rounding
        // inside the caller's): on the caller's edge. One step further in: not.
        let (grid, _) = small(Vec3::new(-0.55 + 1e-12, 0.0, 0.0));
        assert!(stays_on_edge(&grid, [0, 1, 1, 1], false, &caller, None));
        let (grid, _) = small(Vec3::new(-0.5, 0.0, 0.0));
        assert!(!stays_on_edge(&grid, [0, 1, 1, 1], false, &caller, None));
    }
}
