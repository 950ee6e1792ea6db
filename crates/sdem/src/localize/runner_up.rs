//! The runner-up search: after the best candidate, the best other place costing nearly as
//! little ([`RunnerUpSearch::run`], the optimum's own slopes passed over), and where the other
//! scan saw through the optimum's returns, the first candidate of another basin it saw through
//! far less ([`RunnerUpSearch::less_seen_through`]).

use super::{query_poses, run_search, seen_through_less, LocalizeOptions};
use crate::bnb;
use crate::cost::Correlator;
use crate::geometry::Vec3;
use crate::sdem::Sdem;
use crate::search::{CandidateGrid, Evaluator, Exclusion};
use nalgebra::UnitQuaternion;

/// What the search for the runner-up continues from: the best candidate's grid, cost and
/// search.
pub(super) struct RunnerUpSearch<'s, 'a> {
    pub(super) grid: &'s CandidateGrid,
    pub(super) correlator: &'s Correlator<'a>,
    pub(super) prepared: Option<&'s bnb::Prepared<'a>>,
    /// What the exact search set aside for it.
    pub(super) reserve: Option<&'s bnb::Reserve>,
    pub(super) full_turn: bool,
    /// The median horizontal range of the query's points ([`crate::search::horizontal_extent`]):
    /// how far a turn moves them, in the translation's terms.
    pub(super) extent: f64,
}

/// What [`RunnerUpSearch::run`] found: the runner-up (cost, offset and heading), the grid it
/// was searched in last, and how many of the optimum's slopes were passed over on the way.
pub(super) struct RunnerUp {
    pub(super) found: Option<(f64, Vec3, f64)>,
    pub(super) outside: CandidateGrid,
    pub(super) slopes_passed: usize,
}

/// How many candidates [`RunnerUpSearch::less_seen_through`] looks at, the runner-up
/// included, each outside the peak radius of the optimum and of those before it. On the
/// `unlevelled` suite (200 pairs, one run each) 1, 2, 3 and 4 placed 133, 135, 136 and 137
/// right; 4 with 30 cm around the rejected ones and 8 with 20 cm found the same 137 in 1.2 and
/// 1.4 times the time of 4 with the peak radius.
const SEEN_THROUGH_BASINS: usize = 4;

/// A runner-up within this many peak radii of the optimum (and turned no more than moves the
/// query's points at their median range that far) is looked at for lying on the optimum's own
/// slope ([`RunnerUpSearch::slope`]); beyond, a slope that long is a wide basin, and the
/// runner-up stands.
const SLOPE_RADII: f64 = 2.0;

/// How many of the optimum's slopes the runner-up search passes over; the candidate it finds
/// after the last is the runner-up, on a slope or not.
const SLOPE_PASSES: usize = 4;

/// The half-width of a slope left out ([`RunnerUpSearch::slope`]), in grid steps: the grid
/// candidates beside its line, at its headings and the next ones either side.
const SLOPE_HALF_WIDTH_STEPS: f64 = 1.5;

impl RunnerUpSearch<'_, '_> {
    /// The best candidate more than the peak radius from the optimum `(grid_offset, heading)`
    /// costing at most the ambiguity ratio × `cost`, and not on one of the optimum's own slopes:
    /// its cost, offset and heading; and the grid it was searched in (the peak's neighbourhood
    /// and the slopes passed over left out).
    ///
    /// A candidate found within [`SLOPE_RADII`] peak radii from which eq. (1) never rises along
    /// the straight line to within a grid step of the optimum is no other place: that line's
    /// neighbourhood is left out ([`Self::slope`]) and the search goes on, at most
    /// [`SLOPE_PASSES`] times. Every candidate outside the peak radius and those slopes is still
    /// searched: exactly by branch-and-bound, from the reserve its first search set aside, and
    /// by the exhaustive oracle, scoring the grid again at each pass (the two flag and pass
    /// over alike); heuristically by coarse-to-fine, searching the grid again.
    pub(super) fn run(
        &self,
        optimum: (Vec3, f64),
        cost: f64,
        config: &LocalizeOptions,
    ) -> RunnerUp {
        // Only a runner-up within the ambiguity ratio matters; capping the search there keeps
        // the exact search cheap.
        let cap = config.ambiguous_cost_ratio * cost;
        let mut outside = self.outside_peak(optimum.0, config);
        let mut found = self.best_outside(&outside, cap, config);
        let mut correlator = None;
        let mut slopes_passed = 0;
        for _ in 0..SLOPE_PASSES {
            let Some(candidate) = found else { break };
            let correlator = correlator.get_or_insert_with(|| self.correlator.clone());
            let Some(slope) = self.slope(correlator, optimum, candidate, config) else {
                break;
            };
            outside.exclude.extend(slope);
            slopes_passed += 1;
            found = self.best_outside(&outside, cap, config);
        }
        RunnerUp {
            found,
            outside,
            slopes_passed,
        }
    }

    /// Whether `candidate` lies on the optimum's own slope: within [`SLOPE_RADII`] peak radii
    /// (in offset, and in heading as many heading steps as that is translation steps), and eq.
    /// (1) never rises along the straight line from it towards the optimum (offset and heading
    /// together, scored at every grid step of either) until the line is within one step of the
    /// optimum in both: there the continuous minimum, which lies between the grid candidates,
    /// may be passed. If so, the neighbourhood of that line outside the peak radius to leave
    /// out: balls of [`SLOPE_HALF_WIDTH_STEPS`] grid steps about the points scored, each at the
    /// grid headings next to the line's there. In a heading window short of a full turn the line
    /// turns within the window.
    fn slope(
        &self,
        correlator: &mut Correlator,
        (grid_offset, heading): (Vec3, f64),
        (cost, at, yaw): (f64, Vec3, f64),
        config: &LocalizeOptions,
    ) -> Option<Vec<Exclusion>> {
        let step = self.grid.step;
        let away = at - grid_offset;
        let distance = away.norm();
        let reach = SLOPE_RADII * config.peak_radius_m;
        let turn = if self.full_turn {
            crate::geometry::wrap_pi(yaw - heading)
        } else {
            yaw - heading
        };
        let heading_step = match self.grid.yaws.as_slice() {
            [a, b, ..] => (b - a).abs(),
            _ => f64::INFINITY,
        };
        let turn_steps = turn.abs() / heading_step;
        // A turn reaches as far as a move: it moves the points at the query's median range by
        // `reach` at most.
        if distance > reach || turn.abs() * self.extent > reach {
            return None;
        }
        let steps = (distance / step).max(turn_steps).ceil().max(1.0) as usize;
        let radius = SLOPE_HALF_WIDTH_STEPS * step;
        let last_heading = self.grid.counts[3] - 1;
        let mut balls = Vec::new();
        let mut last = cost;
        for k in 0..steps {
            let f = 1.0 - k as f64 / steps as f64;
            let (point, point_heading) = (grid_offset + away * f, heading + turn * f);
            let near = f * distance <= step * (1.0 + 1e-9)
                && (f * turn).abs() <= heading_step * (1.0 + 1e-9);
            if near {
                // A candidate next to the optimum (a peak radius under a grid step) shows no
                // slope: it stays the runner-up.
                if k == 0 {
                    return None;
                }
                break;
            }
            if k > 0 {
                // Scoring stops once the sum passes the last cost: the line rises.
                let c = correlator
                    .evaluate_capped(&point, point_heading, last)?
                    .cost;
                if c.is_nan() || c > last {
                    return None;
                }
                last = c;
            }
            if f * distance + radius > config.peak_radius_m {
                let h = self.nearest_heading(point_heading);
                let headings = [h.saturating_sub(1), (h + 1).min(last_heading)];
                balls.push(Exclusion::at_headings(point, radius, headings));
                // On a full turn the first and the last heading are neighbours too.
                if self.full_turn && last_heading > 0 && (h == 0 || h == last_heading) {
                    let across = last_heading - h;
                    balls.push(Exclusion::at_headings(point, radius, [across, across]));
                }
            }
        }
        Some(balls)
    }

    /// The index of the grid heading nearest `heading`.
    fn nearest_heading(&self, heading: f64) -> usize {
        let gap = |y: f64| crate::geometry::wrap_pi(y - heading).abs();
        (0..self.grid.yaws.len())
            .min_by(|&a, &b| gap(self.grid.yaws[a]).total_cmp(&gap(self.grid.yaws[b])))
            .unwrap_or(0)
    }

    /// The grid without the peak radius around `grid_offset` (the optimum's neighbourhood).
    fn outside_peak(&self, grid_offset: Vec3, config: &LocalizeOptions) -> CandidateGrid {
        let mut outside = self.grid.clone();
        outside.exclude = vec![Exclusion::ball(grid_offset, config.peak_radius_m)];
        outside
    }

    /// The best candidate of `outside` costing at most `cap`: its cost, offset and heading.
    fn best_outside(
        &self,
        outside: &CandidateGrid,
        cap: f64,
        config: &LocalizeOptions,
    ) -> Option<(f64, Vec3, f64)> {
        let second = match (self.reserve, self.prepared) {
            (Some(reserve), Some(prepared)) => bnb::runner_up(prepared, outside, cap, reserve).0,
            _ => {
                let mut e = Evaluator::new(self.correlator.clone(), outside);
                run_search(&mut e, self.prepared, config, self.full_turn, cap, None).0
            }
        };
        second.map(|(c, flat)| {
            let idx = outside.index(flat);
            (c, outside.offset(idx), outside.yaw(idx))
        })
    }

    /// The first of the candidates below the ambiguity ratio × the optimum's cost, best first,
    /// each in `outside` (the grid [`Self::run`] searched last: the optimum's neighbourhood and
    /// its slopes left out) and outside the earlier ones' neighbourhoods, whose returns the other
    /// scan saw through far less than the optimum's (`seen_through`, [`seen_through_less`]):
    /// its grid offset. The `runner_up` is the first; at most [`SEEN_THROUGH_BASINS`] are
    /// looked at. Each later one is searched from the reserve the first search set aside for
    /// the runner-up (exact, the cap being the reserve's ratio); without a reserve (the search
    /// modes other than branch-and-bound) each is a search of the whole grid.
    pub(super) fn less_seen_through(
        &self,
        reference: &Sdem,
        query: &Sdem,
        mut outside: CandidateGrid,
        (cost, seen_through): (f64, f64),
        runner_up: Option<(f64, Vec3, f64)>,
        config: &LocalizeOptions,
    ) -> Option<Vec3> {
        let cap = config.ambiguous_cost_ratio * cost;
        let mut next = runner_up;
        for looked_at in 1..=SEEN_THROUGH_BASINS {
            let (_, offset, heading) = next?;
            let turn = UnitQuaternion::from_axis_angle(&Vec3::z_axis(), heading);
            let (_, pose) = query_poses(reference, query, offset, turn);
            let share = crate::free_space::free_space(reference, query, &pose).fraction();
            if seen_through_less(share, seen_through) {
                return Some(offset);
            }
            if looked_at == SEEN_THROUGH_BASINS {
                break;
            }
            outside
                .exclude
                .push(Exclusion::ball(offset, config.peak_radius_m));
            next = self.best_outside(&outside, cap, config);
        }
        None
    }
}
