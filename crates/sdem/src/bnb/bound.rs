//! The bound: a lower bound on the cost of every candidate in a box, from where each query point
//! (or group of nearby points) may lie over the box and the cone of reference cells it sees there.

use super::queue::{Node, PointHint};
use super::search::BranchAndBound;
use super::tables::{PlaneRows, RangeTables, LANES};
use crate::geometry::{fast_atan2, Vec3, FAST_ATAN2_MAX_ERROR};
use crate::sdem::{floor_clamped, wrap_column};
use crate::search::CandidateGrid;
use nalgebra::Vector3;

/// A box is bounded from the coarsest grouping whose typical group radius is at most this
/// fraction of the box's reach. Measured with the plane bound (8 cm search cubes; boxes bounded on
/// bench pair 3 / the paper's pair with ±10° of heading): 0.1 → 7,796 / 5,744, 0.3 → 7,796 /
/// 6,136, 0.6 → 12,228 / 9,512, and no faster at 0.2–0.3 (larger groups widen every reach).
const GROUP_REACH_FRACTION: f64 = 0.1;

impl<'a> BranchAndBound<'a> {
    /// A lower bound on the cost of every candidate in `node`, and an estimate of the cost at
    /// its centre (the groups' centres looked up in their cells; only for ordering the search).
    #[doc(hidden)]
    pub fn bound(&self, node: &Node) -> (f64, f64) {
        let (bound, estimate, _) = self.bound_below(node, f64::INFINITY, None);
        (bound, estimate)
    }

    /// [`Self::bound`], cut short once the bound exceeds `limit` (then the partial sum is
    /// returned: a weaker bound, but above the limit all the same).
    ///
    /// Every member of a ball (a query point, or a group of nearby ones around their centre) lies,
    /// at every candidate of the box, within the box's translation of the ball centre's position
    /// at the box's middle candidate, plus the arc the heading interval turns it through, plus the
    /// group's radius. That region sees the reference through a cone of cells; in each, the
    /// distance to the cell's plane can shrink by at most the region's extent along its normal.
    /// The smallest over the cone's cells is a lower bound on the member's term (`τ²` for a cell
    /// the reference does not see, or a range out of the cell's gate).
    ///
    /// Compiled twice: for the baseline x86-64 the build targets (four lanes) and for AVX2
    /// (eight lanes), chosen at run time; both compute the same values, bit for bit (the same
    /// operations in the same order, no fused multiply-add).
    pub(super) fn bound_below(
        &self,
        node: &Node,
        limit: f64,
        parent: Option<&PointHint>,
    ) -> (f64, f64, Option<PointHint>) {
        #[cfg(target_arch = "x86_64")]
        if std::is_x86_feature_detected!("avx2") {
            // SAFETY: the processor has just been found to support AVX2.
            return unsafe { self.bound_below_avx2(node, limit, parent) };
        }
        self.bound_below_any(node, limit, parent)
    }

    /// [`Self::bound_below`] with AVX2 instructions.
    #[cfg(target_arch = "x86_64")]
    #[target_feature(enable = "avx2")]
    #[doc(hidden)]
    pub unsafe fn bound_below_avx2(
        &self,
        node: &Node,
        limit: f64,
        parent: Option<&PointHint>,
    ) -> (f64, f64, Option<PointHint>) {
        self.bound_below_any(node, limit, parent)
    }

    /// [`Self::bound_below`]'s body, inlined into each of its builds. Its steps (the box's
    /// [`BoxFrame`], [`Self::group_level`], [`Self::sum_terms`] with [`place_ball`] and
    /// [`order_class`]) are `#[inline(always)]` too, so each build compiles all of it. The
    /// per-quantity arrays stay local to `sum_terms`: gathered in a struct (or the order class
    /// returned as an `Option`), the bound of 1,259 boxes on the paper's pair took 1–2.5 % longer.
    #[inline(always)]
    #[doc(hidden)]
    pub fn bound_below_any(
        &self,
        node: &Node,
        limit: f64,
        parent: Option<&PointHint>,
    ) -> (f64, f64, Option<PointHint>) {
        let frame = BoxFrame::new(self.grid, node);
        let level = self.group_level(frame.reach);
        let total = self.groups.points as f64;
        // Point by point (level 0), what the parent box learned: its saturated points are
        // counted, not bounded, and the others come largest term first.
        let hint = parent.filter(|_| level == 0);
        // The prediction's term is smallest where the box comes nearest the prediction.
        let prior = self.prototype.prior_bound(&frame.lo, &frame.hi);
        let prior_at_centre = self.prototype.prior_cost(&frame.centre);
        let limit_sum = if limit.is_finite() {
            (limit * (1.0 + 1e-9) - prior) * total + 1e-12
        } else {
            f64::INFINITY
        };
        let terms = self.sum_terms(&frame, level, hint, limit_sum);
        if terms.cut_short {
            return (terms.bound_sum / total + prior, f64::INFINITY, None);
        }
        let hint = terms.classes.map(|classes| PointHint {
            saturated: terms.saturated,
            order: classes.concat(),
        });
        (
            terms.bound_sum / total + prior,
            terms.estimate_sum / total + prior_at_centre,
            hint,
        )
    }

    /// The coarsest grouping whose groups are small against a box of this `reach` (see
    /// [`BoxFrame::reach`]).
    #[inline(always)]
    fn group_level(&self, reach: f64) -> usize {
        (0..self.groups.balls.len())
            .rev()
            .find(|&m| self.groups.typical_radius[m] as f64 <= GROUP_REACH_FRACTION * reach)
            .unwrap_or(0)
    }

    /// The sums of the bounds and estimates of the balls of grouping `level` over the box
    /// `frame` (each times its count), chunk by chunk: first where each ball lies
    /// ([`place_ball`]), then the cone of cells it sees ([`reach_bound`]). Cut short once the
    /// bound's sum passes `limit_sum`. At level 0 the balls come in the order `hint` gives, its
    /// saturated points counted and not bounded, and the terms are sorted into classes for the
    /// child boxes.
    #[inline(always)]
    fn sum_terms(
        &self,
        frame: &BoxFrame,
        level: usize,
        hint: Option<&PointHint>,
        limit_sum: f64,
    ) -> Terms {
        let balls = &self.groups.balls[level];
        let tables = self.tables;
        let planes = self.reference.surfaces();
        let truncation_sq = self.truncation_sq;
        let (half, t) = (frame.half, frame.t);
        let mut saturated = hint.map_or(0, |h| h.saturated);
        let mut bound_sum = truncation_sq as f64 * saturated as f64;
        let mut estimate_sum = bound_sum;
        if bound_sum > limit_sum {
            return Terms::cut(bound_sum);
        }
        // The child boxes' order: the terms found here, in four classes, largest first.
        let mut classes: Option<[Vec<u32>; 4]> = (level == 0).then(Default::default);
        // One array per quantity, so the compiler vectorizes the geometry.
        let mut bx = [0f32; CHUNK];
        let mut by = [0f32; CHUNK];
        let mut bz = [0f32; CHUNK];
        let mut br = [0f32; CHUNK];
        let mut bh = [0f32; CHUNK];
        let mut ux = [0f32; CHUNK];
        let mut uy = [0f32; CHUNK];
        let mut uz = [0f32; CHUNK];
        let mut ranges = [0f32; CHUNK];
        let mut horizontals = [0f32; CHUNK];
        let mut laterals = [0f32; CHUNK];
        let mut reaches = [0f32; CHUNK];
        let mut nears = [0f32; CHUNK];
        let mut fars = [0f32; CHUNK];
        let mut spreads = [0f32; CHUNK];
        let mut cells = [[0i32; 6]; CHUNK];
        let order = hint.map(|h| h.order.as_slice());
        let n = order.map_or(balls.cx.len(), <[u32]>::len);
        let ball = |j: usize| order.map_or(j, |o| o[j] as usize);
        for start in (0..n).step_by(CHUNK) {
            let len = CHUNK.min(n - start);
            for i in 0..len {
                let k = ball(start + i);
                (bx[i], by[i], bz[i]) = (balls.cx[k], balls.cy[k], balls.cz[k]);
                (br[i], bh[i]) = (balls.radius[k], balls.horizontal[k]);
            }
            for i in 0..len {
                let p = place_ball([bx[i], by[i], bz[i]], br[i], bh[i], frame, tables);
                (ux[i], uy[i], uz[i]) = (p.u[0], p.u[1], p.u[2]);
                (ranges[i], horizontals[i]) = (p.range, p.horizontal);
                (laterals[i], reaches[i]) = (p.lateral, p.reach);
                (nears[i], fars[i], spreads[i]) = (p.near, p.far, p.spread);
                cells[i] = p.cells;
            }
            for i in 0..len {
                let k = ball(start + i);
                let count = balls.count[k] as f64;
                let [e0, e1, a0, a1, ec, ac] = cells[i];
                let g = Reach {
                    term: ConeTerm {
                        x: [ux[i], uy[i], uz[i]],
                        arm: [ux[i] - t.x, uy[i] - t.y],
                        half: [half.x, half.y, half.z],
                        turn: frame.turn,
                        spread: spreads[i],
                        gate: (nears[i], fars[i]),
                        truncation_sq,
                    },
                    range: ranges[i],
                    holds_origin: ranges[i] <= reaches[i] * 1.0001,
                    holds_axis: horizontals[i] <= laterals[i] * 1.0001,
                    e0,
                    e1,
                    a0,
                    a1,
                    ec,
                    ac,
                };
                let (lb, at_centre) = reach_bound(tables, planes, &g);
                estimate_sum += at_centre as f64 * count;
                bound_sum += lb as f64 * count;
                if let Some(classes) = classes.as_mut() {
                    if lb >= truncation_sq {
                        saturated += 1;
                    } else {
                        classes[order_class(lb, truncation_sq)].push(k as u32);
                    }
                }
            }
            if bound_sum > limit_sum {
                return Terms::cut(bound_sum);
            }
        }
        Terms {
            bound_sum,
            estimate_sum,
            saturated,
            classes,
            cut_short: false,
        }
    }
}

/// What [`BranchAndBound::sum_terms`] found: the sums of the balls' bounds and estimates (each
/// times its count) and, at level 0, the saturated points and the others' order classes.
struct Terms {
    bound_sum: f64,
    estimate_sum: f64,
    saturated: u32,
    classes: Option<[Vec<u32>; 4]>,
    /// The bound's sum passed the limit: `bound_sum` is partial, the rest is not meaningful.
    cut_short: bool,
}

impl Terms {
    /// The sums cut short at a partial bound `bound_sum`.
    #[inline(always)]
    fn cut(bound_sum: f64) -> Self {
        Self {
            bound_sum,
            estimate_sum: f64::INFINITY,
            saturated: 0,
            classes: None,
            cut_short: true,
        }
    }
}

/// A box of candidates as every ball sees it: its middle candidate, and how far the box's
/// translation and heading interval move a point from where it lies there.
struct BoxFrame {
    /// The box's lowest, highest and middle translations.
    lo: Vec3,
    hi: Vec3,
    centre: Vec3,
    /// The translation's half-extent per axis (and a rounding margin).
    half: Vector3<f32>,
    /// The middle candidate: its translation, and the sine and cosine of its heading.
    t: Vector3<f32>,
    sin: f32,
    cos: f32,
    /// A point at horizontal distance h turns through at most `chord · h` from its position at
    /// the middle heading.
    chord: f32,
    /// `(1 − cos δ, sin δ)` of the heading interval's half-width δ.
    turn: (f32, f32),
    /// The translation's radius plus the chord: what the groups' radii are compared against.
    reach: f64,
}

impl BoxFrame {
    /// The frame of `node`'s candidates in `grid`.
    #[inline(always)]
    fn new(grid: &CandidateGrid, node: &Node) -> Self {
        let lo = grid.offset(node.lo);
        let hi = grid.offset(node.hi);
        let centre = (lo + hi) * 0.5;
        let half = ((hi - lo) * 0.5).map(|v| v as f32 + 1e-5);
        let translation_radius = half.norm();
        let (yaw_lo, yaw_hi) = (grid.yaws[node.lo[3]], grid.yaws[node.hi[3]]);
        let yaw_centre = 0.5 * (yaw_lo + yaw_hi);
        let chord = (2.0 * (0.25 * (yaw_hi - yaw_lo)).sin() * (1.0 + 1e-6)) as f32;
        let delta = 0.5 * (yaw_hi - yaw_lo);
        let turn = (
            ((1.0 - delta.cos()) * (1.0 + 1e-6)) as f32,
            (delta.sin() * (1.0 + 1e-6)) as f32,
        );
        let (sin, cos) = yaw_centre.sin_cos();
        Self {
            lo,
            hi,
            centre,
            half,
            t: centre.cast::<f32>(),
            sin: sin as f32,
            cos: cos as f32,
            chord,
            turn,
            reach: translation_radius as f64 + chord as f64,
        }
    }
}

/// The balls are bounded this many at a time: their geometry first, then their cones.
const CHUNK: usize = 64;

/// One ball placed over a box (see [`place_ball`]).
struct Placed {
    /// Its centre at the box's middle candidate, that centre's range and horizontal distance.
    u: [f32; 3],
    range: f32,
    horizontal: f32,
    /// What [`footprint`] found: its members' reach, laterally and in all, and their ranges.
    lateral: f32,
    reach: f32,
    near: f32,
    far: f32,
    /// The group's radius with a rounding margin.
    spread: f32,
    /// The cone's cell rows and columns and the centre's cell (see [`Reach`]).
    cells: [i32; 6],
}

/// Where the members of a ball (centre `c` as grouped, radius `radius`, farthest member
/// `horizontal` from the z axis) may lie over the box `frame`, and the cone of cells of `tables`
/// that sees them there.
#[inline(always)]
fn place_ball(
    c: [f32; 3],
    radius: f32,
    horizontal: f32,
    frame: &BoxFrame,
    tables: &RangeTables,
) -> Placed {
    let (half, t, sin, cos) = (frame.half, frame.t, frame.sin, frame.cos);
    let margin = 2.0 * FAST_ATAN2_MAX_ERROR;
    let [x, y, z] = c;
    let u0 = cos * x - sin * y + t.x;
    let u1 = sin * x + cos * y + t.y;
    let u2 = z + t.z;
    // A group member turns about the query origin with its centre, so its offset from the centre
    // keeps its length.
    let spread = radius + 1e-4;
    let arc = frame.chord * horizontal;
    let horizontal = (u0 * u0 + u1 * u1).sqrt();
    let range = (horizontal * horizontal + u2 * u2).sqrt();
    let Footprint {
        lowest,
        highest,
        beta,
        near,
        far,
        reach,
        lateral,
    } = footprint(
        [u0, u1, u2],
        [horizontal, range],
        [half.x, half.y, half.z],
        arc,
        spread,
    );
    let elevation = fast_atan2(u2, horizontal);
    let azimuth = fast_atan2(u1, u0);
    let el = (elevation - tables.elevation_min) * tables.inv_resolution;
    let az = (azimuth - tables.azimuth_min) * tables.inv_resolution;
    let db = (beta + margin) * tables.inv_resolution;
    Placed {
        u: [u0, u1, u2],
        range,
        horizontal,
        lateral,
        reach,
        near,
        far,
        spread,
        cells: [
            floor_clamped((lowest - margin - tables.elevation_min) * tables.inv_resolution),
            floor_clamped((highest + margin - tables.elevation_min) * tables.inv_resolution),
            floor_clamped(az - db),
            floor_clamped(az + db),
            floor_clamped(el),
            floor_clamped(az),
        ],
    }
}

/// Which of the child boxes' four order classes an unsaturated ball's bound `lb` (below `τ²`)
/// falls in, largest first.
#[inline(always)]
fn order_class(lb: f32, truncation_sq: f32) -> usize {
    if lb >= 0.25 * truncation_sq {
        0
    } else if lb >= 0.0625 * truncation_sq {
        1
    } else if lb > 0.0 {
        2
    } else {
        3
    }
}

/// Where a ball's members may lie over a box, seen from the reference's origin (see
/// [`footprint`]); angles in radians, before the arctangent's error.
struct Footprint {
    lowest: f32,
    highest: f32,
    /// Azimuth half-width about the centre's azimuth.
    beta: f32,
    /// The members' ranges lie in `[near, far]`.
    near: f32,
    far: f32,
    /// Every member lies within this of the centre, and within `lateral` of it horizontally.
    reach: f32,
    lateral: f32,
}

/// The directions and ranges at which a ball's members may lie over a box. The members lie within
/// `half` (the box's translation), plus `arc` horizontally (the heading turns them about the
/// vertical), plus `spread` (the group's radius, any direction) of the centre `u`, which lies at
/// `[horizontal, range]` from the z axis and the origin.
///
/// A horizontal offset w (w_t across the ray, w_r along it) turns the direction by
/// atan(w_t / (h + w_r)): the box's support across and along the ray plus the arc and the spread
/// bound both parts. Height varies by at most `half.z` + `spread`, distance from the z axis by
/// |half_xy| + `arc` + `spread`, so the elevations lie between the corners' of that rectangle. An
/// offset w changes the range by at least its part along the ray (the box's support along it plus
/// the arc and the spread) and at most to √((r + w_∥)² + |w|²). Tighter than the ball around all
/// of it: on the bench pairs 25 % less time, with the same minima.
#[inline(always)]
fn footprint(
    u: [f32; 3],
    [horizontal, range]: [f32; 2],
    half: [f32; 3],
    arc: f32,
    spread: f32,
) -> Footprint {
    let (across_ray, along_ray) = if horizontal > 0.0 {
        let (s, c) = ((u[1] / horizontal).abs(), (u[0] / horizontal).abs());
        (half[0] * s + half[1] * c, half[0] * c + half[1] * s)
    } else {
        let h = (half[0] * half[0] + half[1] * half[1]).sqrt();
        (h, h)
    };
    let turned = arc + spread;
    // tan ψ ≤ w_t / (h − w_r) ≥ ψ; where the members may stand on the z axis it is not
    // positive, and every azimuth is seen (`Reach::holds_axis`).
    let beta = (across_ray + turned) / (horizontal - along_ray - turned);
    let vertical = half[2] + spread;
    let lateral = (half[0] * half[0] + half[1] * half[1]).sqrt() + turned;
    let (z_lo, z_hi) = (u[2] - vertical, u[2] + vertical);
    let (h_lo, h_hi) = ((horizontal - lateral).max(0.0), horizontal + lateral);
    let lowest = fast_atan2(z_lo, if z_lo >= 0.0 { h_hi } else { h_lo });
    let highest = fast_atan2(z_hi, if z_hi >= 0.0 { h_lo } else { h_hi });
    let along =
        (half[0] * u[0].abs() + half[1] * u[1].abs() + half[2] * u[2].abs()) / range + turned;
    let reach = (half[0] * half[0] + half[1] * half[1] + half[2] * half[2]).sqrt() + turned;
    Footprint {
        lowest,
        highest,
        beta,
        near: range - along,
        far: ((range + along) * (range + along) + reach * reach).sqrt(),
        reach,
        lateral,
    }
}

/// Where a ball's members may be over a box of candidates (see [`BranchAndBound::bound_below`]).
struct Reach {
    /// What a cell's term depends on.
    term: ConeTerm,
    /// The centre's range.
    range: f32,
    /// The ball holds the origin, or the z axis (then it sees every direction, or every azimuth).
    holds_origin: bool,
    holds_axis: bool,
    /// The cone's cell rows and columns (unclamped), and the centre's cell.
    e0: i32,
    e1: i32,
    a0: i32,
    a1: i32,
    ec: i32,
    ac: i32,
}

/// What the term of a cell's plane depends on, for one ball over one box (see [`reach_bound`]).
struct ConeTerm {
    /// The ball centre's position at the box's middle candidate.
    x: [f32; 3],
    /// Its horizontal offset from the query's origin there (the arm the heading turns).
    arm: [f32; 2],
    /// The box's translation half-extent per axis.
    half: [f32; 3],
    /// `(1 − cos δ, sin δ)` of the heading interval's half-width δ.
    turn: (f32, f32),
    /// The group's own radius (and a rounding margin).
    spread: f32,
    /// The members' ranges lie within this interval.
    gate: (f32, f32),
    truncation_sq: f32,
}

impl ConeTerm {
    /// The lower bound over one cell: the members' distance to the cell's plane can shrink by
    /// at most the region's extent along its normal; `τ²` for an unknown cell (NaN or an empty
    /// gate) and a gate the members cannot reach. Written without branches (the gate selects)
    /// and with plain comparisons, not `f32::max`/`min`, so that the cone loop is vectorized
    /// into packed instructions: it is most of the search's time.
    #[inline(always)]
    fn term(&self, n: [f32; 3], d: f32, lo: f32, hi: f32) -> f32 {
        let (one_minus_cos, sin) = self.turn;
        let (r_lo, r_hi) = self.gate;
        let reachable = lo <= r_hi && hi >= r_lo;
        // Turning by θ (|θ| ≤ δ) from the middle heading moves the centre by
        // (cos θ − 1) arm + sin θ (ẑ × arm): along the normal, at most this.
        let radial = (n[0] * self.arm[0] + n[1] * self.arm[1]).abs();
        let tangential = (n[1] * self.arm[0] - n[0] * self.arm[1]).abs();
        let along_normal = self.half[0] * n[0].abs()
            + self.half[1] * n[1].abs()
            + self.half[2] * n[2].abs()
            + one_minus_cos * radial
            + sin * tangential
            + self.spread;
        let distance = (n[0] * self.x[0] + n[1] * self.x[1] + n[2] * self.x[2] - d).abs();
        let gap = distance - along_normal;
        let v = if gap > 0.0 { gap } else { 0.0 };
        let squared = v * v;
        let squared = if squared < self.truncation_sq {
            squared
        } else {
            self.truncation_sq
        };
        if reachable {
            squared
        } else {
            self.truncation_sq
        }
    }

    /// The [`Self::term`]s of the [`LANES`] cells from `start` on (those from `valid` on count
    /// `τ²`), one array per quantity, so that it is vectorized.
    #[inline(always)]
    fn lanes(&self, rows: &PlaneRows, start: usize, valid: usize) -> [f32; LANES] {
        let lane = |v: &[f32]| -> [f32; LANES] {
            v[start..start + LANES].try_into().expect("LANES cells")
        };
        let (nx, ny, nz) = (lane(&rows.nx), lane(&rows.ny), lane(&rows.nz));
        let (d, lo, hi) = (lane(&rows.d), lane(&rows.lo), lane(&rows.hi));
        let mut out = [0f32; LANES];
        for j in 0..LANES {
            let t = self.term([nx[j], ny[j], nz[j]], d[j], lo[j], hi[j]);
            out[j] = if j < valid { t } else { self.truncation_sq };
        }
        out
    }
}

/// The smallest of `lanes`, by halving (so that it stays in vector registers).
#[inline(always)]
fn lanes_min(mut out: [f32; LANES]) -> f32 {
    let mut width = LANES;
    while width > 1 {
        width /= 2;
        for j in 0..width {
            out[j] = if out[j + width] < out[j] {
                out[j + width]
            } else {
                out[j]
            };
        }
    }
    out[0]
}

/// Cones of up to this many cells are bounded cell by cell, from each cell's plane; larger ones
/// from the range tables alone (whether any cell could compare the members at all). Boxes bounded
/// on bench pair 3 / the paper's pair with ±10° of heading: 16 → 23,236 / 20,032, 64 → 11,444 /
/// 7,928, 256 → 7,796 / 5,744, 1,024 → 8,052 / 5,424 (no faster).
pub(super) const MAX_CONE_CELLS: i32 = 256;

/// A lower bound on the term of every member of a ball over the box (see
/// [`BranchAndBound::bound_below`]).
#[inline(always)]
fn reach_bound(tables: &RangeTables, planes: &crate::sdem::CellSurfaces, g: &Reach) -> (f32, f32) {
    let p = &g.term;
    let (truncation_sq, (r_lo, r_hi)) = (p.truncation_sq, p.gate);
    // The centre's own cell: the estimate (the squared distance there), and for a point on a
    // surface often a bound of 0 at once.
    let centre_cell = tables.cell(g.ec, g.ac);
    let centre = centre_cell.map(|c| &planes.cells[c]);
    let estimate = centre_cell
        .and_then(|c| planes.squared_distance(c, p.x, g.range))
        .map_or(truncation_sq, |e2| e2.min(truncation_sq));
    if g.holds_origin {
        // Any direction, any range: the reference's whole extent.
        let (min, max) = tables.global;
        return (if min > max { truncation_sq } else { 0.0 }, estimate);
    }
    let last_row = tables.n_el as i32 - 1;
    if g.e1 < 0 || g.e0 > last_row {
        return (truncation_sq, estimate);
    }
    let (e0, e1) = (g.e0.max(0), g.e1.min(last_row));
    let n_az = tables.n_az as i32;
    let (mut a0, mut a1) = (g.a0, g.a1);
    if g.holds_axis || (tables.full_circle && a1 - a0 + 1 >= n_az) {
        (a0, a1) = (0, n_az - 1);
    } else if tables.full_circle {
        // Columns run from a0 in [0, n_az) for at most n_az - 1 more, so wrap at most once.
        let start = wrap_column(a0, n_az);
        (a0, a1) = (start, start + (a1 - a0));
    } else {
        if a1 < 0 || a0 >= n_az {
            return (truncation_sq, estimate);
        }
        (a0, a1) = (a0.max(0), a1.min(n_az - 1));
    }
    let rows = &tables.planes;
    let mut best = truncation_sq;
    if let Some(c) = centre {
        // One cell: its 24 bytes, not a line of each of the rows' six arrays.
        best = p.term(c.n, c.d, c.lo, c.hi);
        if best == 0.0 {
            return (0.0, estimate);
        }
    }
    if e0 == e1 && a0 == a1 {
        // A single cell: the centre's (or one outside the grid).
        return (best, estimate);
    }
    let cone_cells = (e1 - e0 + 1) * (a1 - a0 + 1);
    if cone_cells > MAX_CONE_CELLS {
        // Too many cells to visit: whether any gate near the cone reaches the members' ranges
        // (if none does, every cell costs τ²), else 0.
        let cone = (e0 as usize, e1 as usize, a0 as usize, a1 as usize);
        return (
            if tables.reaches(cone, r_lo, r_hi) {
                0.0
            } else {
                truncation_sq
            },
            estimate,
        );
    }
    // Columns a0..=a1 of a row are one run of the stored row (see `PlaneRows`).
    // The cells' terms are kept lane by lane over the whole cone, and the lanes brought to one
    // at its end: a row of a small cone is one run of lanes, and bringing each run to one
    // cost 10 M of the bound's 364 M instructions a bench pair (callgrind).
    let len = (a1 - a0 + 1) as usize;
    let mut lowest = [best; LANES];
    for e in e0..=e1 {
        let row = e as usize * rows.stride + a0 as usize;
        for k in (0..len).step_by(LANES) {
            let t = p.lanes(rows, row + k, len - k);
            for j in 0..LANES {
                lowest[j] = if t[j] < lowest[j] { t[j] } else { lowest[j] };
            }
        }
        if lowest.contains(&0.0) {
            return (0.0, estimate);
        }
    }
    (lanes_min(lowest), estimate)
}

#[cfg(test)]
mod tests {
    use super::*;
    use crate::geometry::FAST_ATAN2_MAX_ERROR;
    use rand::SeedableRng;

    /// Every position a member can take over a box (the translation box's corners and inside,
    /// plus a horizontal arc and an offset of up to the spread in any direction) lies in the
    /// directions and ranges [`footprint`] gives, near and far, level and steep, wide boxes and
    /// thin ones.
    #[test]
    fn footprint_holds_every_position_of_the_members() {
        use rand::Rng;
        let mut rng = rand_chacha::ChaCha8Rng::seed_from_u64(7);
        let margin = 2.0 * FAST_ATAN2_MAX_ERROR as f64 + 1e-5;
        let mut azimuth_checked = 0;
        for _ in 0..2000 {
            let range = rng.random_range(0.3..6.0f64);
            let elevation = rng.random_range(-1.5..1.5f64);
            let azimuth = rng.random_range(-3.1..3.1f64);
            let u = [
                range * elevation.cos() * azimuth.cos(),
                range * elevation.cos() * azimuth.sin(),
                range * elevation.sin(),
            ];
            let half = [0, 1, 2].map(|_| rng.random_range(0.0..0.3f64));
            let arc = rng.random_range(0.0..0.2f64);
            let spread = rng.random_range(0.0..0.05f64);
            let horizontal = u[0].hypot(u[1]);
            let f = footprint(
                u.map(|v| v as f32),
                [horizontal as f32, range as f32],
                half.map(|v| v as f32),
                arc as f32,
                spread as f32,
            );
            let (lowest, highest, beta) = (f.lowest as f64, f.highest as f64, f.beta as f64);
            let (near, far) = (f.near as f64, f.far as f64);
            let (reach, lateral) = (f.reach as f64, f.lateral as f64);
            // As `bound_below` decides whether every azimuth is seen.
            let stands_off_axis = horizontal > lateral * 1.0001;
            azimuth_checked += stands_off_axis as usize;
            for k in 0..64 {
                // Corners of the box first, then anywhere in it; the offset on its sphere.
                let a: [f64; 3] = std::array::from_fn(|i| {
                    let side = if k < 8 {
                        if (k >> i) & 1 == 1 {
                            1.0
                        } else {
                            -1.0
                        }
                    } else {
                        rng.random_range(-1.0..1.0)
                    };
                    side * half[i]
                });
                let w: [f64; 3] = std::array::from_fn(|_| rng.random_range(-1.0..1.0f64));
                let norm = (w[0] * w[0] + w[1] * w[1] + w[2] * w[2]).sqrt().max(1e-12);
                let heading = rng.random_range(-3.2..3.2f64);
                let b = [arc * heading.cos(), arc * heading.sin(), 0.0];
                let x: [f64; 3] =
                    std::array::from_fn(|i| u[i] + a[i] + b[i] + w[i] / norm * spread);
                let offset: [f64; 3] = std::array::from_fn(|i| x[i] - u[i]);
                let slack = 1e-5 * range;
                assert!(
                    offset[0].hypot(offset[1]).hypot(offset[2]) <= reach + slack
                        && offset[0].hypot(offset[1]) <= lateral + slack,
                    "offset {offset:?} beyond {reach} (horizontally {lateral}) (u {u:?}, \
                     half {half:?}, arc {arc}, spread {spread})"
                );
                let h = x[0].hypot(x[1]);
                let r = h.hypot(x[2]);
                assert!(
                    r >= near - 1e-5 * range && r <= far + 1e-5 * range,
                    "range {r} outside [{near}, {far}] (u {u:?}, half {half:?}, arc {arc}, \
                     spread {spread})"
                );
                let e = x[2].atan2(h);
                assert!(
                    e >= lowest - margin && e <= highest + margin,
                    "elevation {e} outside [{lowest}, {highest}] (u {u:?}, half {half:?}, \
                     arc {arc}, spread {spread})"
                );
                if stands_off_axis {
                    let turn = (x[1].atan2(x[0]) - u[1].atan2(u[0]) + 3.0 * std::f64::consts::PI)
                        .rem_euclid(2.0 * std::f64::consts::PI)
                        - std::f64::consts::PI;
                    assert!(
                        turn.abs() <= beta + margin,
                        "azimuth {turn} beyond ±{beta} (u {u:?}, half {half:?}, arc {arc}, spread {spread})"
                    );
                }
            }
        }
        assert!(
            azimuth_checked > 1000,
            "{azimuth_checked} of 2000 off the axis"
        );
    }
}
