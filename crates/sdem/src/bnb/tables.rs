//! The reference S-DEM's lookup tables, built once per localization: the range gates over coarse
//! blocks of cells, and the cells' planes laid out row by row for the cone loop of the bound.

use crate::sdem::wrap_column;
use crate::sdem::{Derived, Sdem};
use rayon::prelude::*;

/// The reference S-DEM's cells as the search reads them: each cell's plane (for the cone loop),
/// and the range gates' extent over coarse blocks of cells (for cones too large to visit).
#[doc(hidden)]
#[derive(Debug, Clone)]
pub struct RangeTables {
    pub(super) n_az: usize,
    pub(super) n_el: usize,
    pub(super) full_circle: bool,
    /// `(min lo, max hi)` of the gates over each block of [`BLOCK`] × [`BLOCK`] cells (of the
    /// stored columns), `block_columns` blocks a row; `(∞, −∞)` where every cell is unknown.
    blocks: Vec<(f32, f32)>,
    block_columns: usize,
    pub(super) global: (f32, f32),
    /// The cells' planes, laid out for the cone loop of `reach_bound` (in `bound`).
    pub(super) planes: PlaneRows,
    pub(super) elevation_min: f32,
    pub(super) azimuth_min: f32,
    pub(super) inv_resolution: f32,
}

/// Side of the blocks of [`RangeTables::blocks`], cells: the cones they answer for (more than
/// [`MAX_CONE_CELLS`]) span a few blocks each way.
///
/// [`MAX_CONE_CELLS`]: super::bound::MAX_CONE_CELLS
const BLOCK: usize = 8;

const EMPTY: (f32, f32) = (f32::INFINITY, f32::NEG_INFINITY);

fn merge(a: (f32, f32), b: (f32, f32)) -> (f32, f32) {
    (a.0.min(b.0), a.1.max(b.1))
}

impl RangeTables {
    /// The tables of `sdem` as the reference: made once, on first use, and kept with it.
    pub fn of(sdem: &Sdem) -> &RangeTables {
        sdem.derived(Derived::RangeTables, || RangeTables::new(sdem))
    }

    /// A sparse table (square windows of every power of two at every cell) took 7–8 ms a
    /// localization to build on the full sphere at 1° (eight levels of 130,000 entries), a
    /// tenth of a bench pair; the cone loop, once vectorized, no longer gained from asking it
    /// before visiting cones of 5–256 cells. Blocks answer for the larger cones.
    pub fn new(reference: &Sdem) -> Self {
        let grid = reference.grid();
        let (n_az, n_el) = (grid.azimuth_cells(), grid.elevation_cells());
        let config = reference.config();
        let full_circle = grid.is_full_circle();
        let width = if full_circle { 2 * n_az } else { n_az };
        let cells = &reference.surfaces().cells;
        let block_columns = width.div_ceil(BLOCK);
        let mut blocks = vec![EMPTY; n_el.div_ceil(BLOCK) * block_columns];
        // A row of blocks at a time, in parallel, beside the planes' rows.
        let (global, planes) = rayon::join(
            || {
                blocks
                    .par_chunks_mut(block_columns)
                    .enumerate()
                    .map(|(b, row)| {
                        let mut global = EMPTY;
                        for e in b * BLOCK..((b + 1) * BLOCK).min(n_el) {
                            for a in 0..width {
                                let c = &cells[e * n_az + if a < n_az { a } else { a - n_az }];
                                // Unknown cells (NaN) leave the block as it is.
                                if c.lo <= c.hi {
                                    row[a / BLOCK] = merge(row[a / BLOCK], (c.lo, c.hi));
                                    global = merge(global, (c.lo, c.hi));
                                }
                            }
                        }
                        global
                    })
                    .reduce(|| EMPTY, merge)
            },
            || PlaneRows::new(cells, n_az, n_el, width),
        );
        Self {
            n_az,
            n_el,
            full_circle,
            blocks,
            block_columns,
            global,
            planes,
            elevation_min: config.elevation_min_deg.to_radians() as f32,
            azimuth_min: config.azimuth_min_deg.to_radians() as f32,
            inv_resolution: (1.0 / config.resolution_deg.to_radians()) as f32,
        }
    }

    /// The index of the cell at row `e`, column `a` (columns wrap on a full circle), or `None`
    /// outside the grid.
    #[inline]
    pub(super) fn cell(&self, e: i32, a: i32) -> Option<usize> {
        if e < 0 || e >= self.n_el as i32 {
            return None;
        }
        let a = if self.full_circle {
            wrap_column(a, self.n_az as i32)
        } else if a < 0 || a >= self.n_az as i32 {
            return None;
        } else {
            a
        };
        Some(e as usize * self.n_az + a as usize)
    }

    /// Whether any gate over (at least) rows `e0..=e1` and columns `a0..=a1` (columns may run
    /// past `n_az` on a full circle; `a1 < width`) reaches a range in `r_lo..=r_hi`: whether the
    /// span `(min lo, max hi)` of their gates meets it. It stops at the first block at which the
    /// span meets it: the span only grows block by block, so that is the whole window's answer.
    /// A box of relocalization (±2 m, every heading) makes cones of most of the sphere, a few
    /// thousand blocks, and the first few nearly always answer.
    pub(super) fn reaches(
        &self,
        (e0, e1, a0, a1): (usize, usize, usize, usize),
        r_lo: f32,
        r_hi: f32,
    ) -> bool {
        let mut acc = EMPTY;
        for be in e0 / BLOCK..=e1 / BLOCK {
            let row = &self.blocks[be * self.block_columns..][..self.block_columns];
            for &b in &row[a0 / BLOCK..=a1 / BLOCK] {
                acc = merge(acc, b);
                if acc.0 <= r_hi && acc.1 >= r_lo {
                    return true;
                }
            }
        }
        // Also where a range is NaN, as `!(min > r_hi || max < r_lo)` over the whole window.
        !(acc.0 > r_hi || acc.1 < r_lo)
    }
}

/// Cells a cone's row is read at a time in `reach_bound` (in `bound`).
pub(super) const LANES: usize = 8;

/// The reference's cell planes (see [`crate::sdem::CellPlane`]), one array per quantity, so that
/// the cells of a cone's row are bounded [`LANES`] at a time (the compiler vectorizes it). Rows are
/// stored `stride` apart: the table's columns (twice the azimuth cells on a full circle, so a
/// window that wraps is one run), then [`LANES`] unknown cells, so a row can be read past its end.
/// An unknown cell has a zero normal and an empty gate (`lo` = ∞, `hi` = −∞): it costs `τ²`.
#[derive(Debug, Clone)]
pub(super) struct PlaneRows {
    pub(super) stride: usize,
    pub(super) nx: Vec<f32>,
    pub(super) ny: Vec<f32>,
    pub(super) nz: Vec<f32>,
    pub(super) d: Vec<f32>,
    pub(super) lo: Vec<f32>,
    pub(super) hi: Vec<f32>,
}

impl PlaneRows {
    fn new(cells: &[crate::sdem::CellPlane], n_az: usize, n_el: usize, width: usize) -> Self {
        let stride = width + LANES;
        let len = n_el * stride;
        let mut out = Self {
            stride,
            nx: vec![0.0; len],
            ny: vec![0.0; len],
            nz: vec![0.0; len],
            d: vec![0.0; len],
            lo: vec![f32::INFINITY; len],
            hi: vec![f32::NEG_INFINITY; len],
        };
        // Row by row in parallel.
        (
            out.nx.par_chunks_mut(stride),
            out.ny.par_chunks_mut(stride),
            out.nz.par_chunks_mut(stride),
            out.d.par_chunks_mut(stride),
            out.lo.par_chunks_mut(stride),
            out.hi.par_chunks_mut(stride),
        )
            .into_par_iter()
            .enumerate()
            .for_each(|(e, (nx, ny, nz, d, lo, hi))| {
                for a in 0..width {
                    let c = &cells[e * n_az + if a < n_az { a } else { a - n_az }];
                    if c.n[0].is_nan() {
                        continue;
                    }
                    (nx[a], ny[a], nz[a]) = (c.n[0], c.n[1], c.n[2]);
                    (d[a], lo[a], hi[a]) = (c.d, c.lo, c.hi);
                }
            });
        out
    }
}

#[cfg(test)]
mod tests {
    use super::*;
    use crate::geometry::Attitude;
    use rand::{Rng, SeedableRng};

    /// The span of the gates over every block the window touches, read to the end.
    fn span(t: &RangeTables, (e0, e1, a0, a1): (usize, usize, usize, usize)) -> (f32, f32) {
        let mut acc = EMPTY;
        for be in e0 / BLOCK..=e1 / BLOCK {
            for ba in a0 / BLOCK..=a1 / BLOCK {
                acc = merge(acc, t.blocks[be * t.block_columns + ba]);
            }
        }
        acc
    }

    /// Stopping at the first block whose span meets the ranges gives the answer of the whole
    /// window, for windows small and large and ranges that do and do not meet it.
    #[test]
    fn reaches_answers_as_the_whole_windows_span() {
        let points = crate::test_scenes::room(0.05);
        let cfg = crate::sdem::SdemConfig::default();
        let sdem = Sdem::from_points(&points, &Attitude::default(), &cfg).unwrap();
        let t = RangeTables::new(&sdem);
        let width = t.block_columns * BLOCK;
        let mut rng = rand_chacha::ChaCha8Rng::seed_from_u64(3);
        let (mut met, mut missed) = (0, 0);
        for _ in 0..20_000 {
            let e0 = rng.random_range(0..t.n_el);
            let e1 = rng.random_range(e0..t.n_el);
            let a0 = rng.random_range(0..t.n_az);
            let a1 = rng.random_range(a0..(a0 + t.n_az).min(width));
            let r_lo = rng.random_range(0.0..5.0f32);
            let r_hi = r_lo + rng.random_range(0.0..1.0f32);
            let window = (e0, e1, a0, a1);
            let (min, max) = span(&t, window);
            let expected = !(min > r_hi || max < r_lo);
            assert_eq!(
                t.reaches(window, r_lo, r_hi),
                expected,
                "window {window:?}, ranges {r_lo}..{r_hi}, span {min}..{max}"
            );
            if expected {
                met += 1;
            } else {
                missed += 1;
            }
        }
        assert!(met > 1_000 && missed > 1_000, "{met} met, {missed} missed");
        assert!(t.reaches((0, 0, 0, 0), f32::NAN, f32::NAN));
    }
}
