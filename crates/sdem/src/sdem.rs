//! The Sphere-DEM (S-DEM) of Nagatani et al. (2003), Sec. III-B: a grid over the directions around
//! the sensor (azimuth × elevation), each cell holding the range of the nearest return in it.
//!
//! Unlike a DEM over the floor, an S-DEM holds floor, walls and ceiling at once. The grid is
//! *levelled*: points are rotated by the gyro/compass attitude before binning, so azimuth is
//! counted counter-clockwise from the world's +x (compass) axis and elevation up from the
//! horizontal plane, whatever the robot's tilt. Cells with no return are *unknown*, never zero.

use crate::error::{Error, Result};
use crate::geometry::{fast_atan2, AsPoint, Attitude, Vec3};
use serde::{Deserialize, Serialize};

mod cell_means;
mod grid;
mod patch;
mod usable;

pub use grid::{floor_clamped, floor_i32, wrap_column, GridSpec};
pub(crate) use patch::patch_moments;
pub(crate) use usable::no_usable_points;

/// The angular grid of an S-DEM: resolution and extent, in degrees.
#[derive(Debug, Clone, PartialEq, Serialize, Deserialize)]
#[serde(default, deny_unknown_fields)]
pub struct SdemConfig {
    /// Cell size in azimuth and elevation, degrees (paper: 1°, the sensor's step).
    pub resolution_deg: f64,
    /// Lowest azimuth covered, degrees, in [-180, 180).
    pub azimuth_min_deg: f64,
    /// Highest azimuth covered, degrees, in (-180, 180].
    pub azimuth_max_deg: f64,
    /// Lowest elevation covered, degrees, in [-90, 90).
    pub elevation_min_deg: f64,
    /// Highest elevation covered, degrees, in (-90, 90].
    pub elevation_max_deg: f64,
    /// Returns closer than this are ignored, metres.
    pub min_range_m: f64,
    /// How far along its ray a cell's plane is compared with points: false (the default), up to
    /// [`PLANE_REACH_M`] from the cell's return; true, as far as its neighbours on the same
    /// surface lie from it in range, when that is farther ([`SdemConfig::for_scan`] sets it).
    /// A LiDAR's cell 20 m away on the road spans a metre of range, and its nearest return
    /// lies at the near end: with the fixed reach, most points the other scan saw on that road
    /// were mismatches, and the exact search bounded 1.3–1.7 times as many boxes on KITTI
    /// pairs and about 4 times as many on the simulated street pairs (`sdem_sim::sim::street`). On the tilting SICK's scans (a few centimetres a cell) it
    /// changes little, and not for the better (the 50 pairs of `sdem bench`: median error
    /// 0.74 mm against 0.73 mm, largest 3.79 mm against 3.64 mm), so it is not the default.
    pub plane_reach_from_neighbours: bool,
}

impl Default for SdemConfig {
    fn default() -> Self {
        Self {
            resolution_deg: 1.0,
            azimuth_min_deg: -180.0,
            azimuth_max_deg: 180.0,
            elevation_min_deg: -90.0,
            elevation_max_deg: 90.0,
            min_range_m: 0.05,
            plane_reach_from_neighbours: false,
        }
    }
}

/// The finest resolution [`SdemConfig::default_for_scan`] matches a scan to, degrees: finer
/// cells cost time and memory as their count does (a scanner simulated at 0.25° took 814 ms a
/// stop and 1.9 MB a node where 0.5° took 104 ms and 476 kB), and a survey scanner's 0.04° would
/// make a sphere of millions of cells.
pub const MIN_MATCHED_RESOLUTION_DEG: f64 = 0.5;

/// `step_deg` shrunk to the nearest cell size of which a whole number makes a full turn (a
/// billionth of a cell spared for rounding: 1° stays 1°, 0.517° becomes 0.5165°, 697 cells).
pub(crate) fn whole_turn_deg(step_deg: f64) -> f64 {
    360.0 / (360.0 / step_deg - 1e-9).ceil()
}

/// The median distance from the sensor of an S-DEM's points (levelled frame, metres; 0 for
/// none).
pub(crate) fn median_range(points: &[[f32; 3]]) -> f64 {
    let mut ranges: Vec<f32> = points
        .iter()
        .map(|p| (p[0] * p[0] + p[1] * p[1] + p[2] * p[2]).sqrt())
        .collect();
    if ranges.is_empty() {
        return 0.0;
    }
    let middle = ranges.len() / 2;
    *ranges.select_nth_unstable_by(middle, f32::total_cmp).1 as f64
}

/// How far [`SdemConfig::for_scan`] widens the scan's own band of elevations, degrees: two scans
/// share one grid, and each is levelled by its own attitude reading, which may tilt it against
/// the scan the band was measured on by a few degrees.
pub const SCAN_ELEVATION_MARGIN_DEG: f64 = 5.0;

/// [`SdemConfig::for_scan`] takes the finest resolution at which at most this fraction of the
/// cells in the scanned band are holes (empty between two known cells at most
/// `MAX_HOLE_RUN` cells away, above and below or left and right): a grid finer than the
/// scanner's coarser angular step leaves rows or columns of cells empty.
pub const MAX_HOLE_FRACTION: f64 = 0.1;

/// An empty cell is a hole when known cells lie within this many cells of it on both sides
/// (above and below, or left and right): a grid of 0.5° over a 16-beam LiDAR's rings, 2° apart,
/// leaves three empty rows between two known ones, and no cell a neighbour above and below to
/// measure its surface by. Longer runs are mostly the scene's (the sky between a lamp and the
/// road), not the sampling's: counted above and below at any length (or up to 8), they changed
/// the grids of the `lidar` suite's solid-state street pairs and lost one of 20.
const MAX_HOLE_RUN: usize = 3;

/// The resolutions [`SdemConfig::for_scan`] tries, finest first, degrees (each shrunk so that
/// whole cells make a full turn).
const RESOLUTIONS_DEG: [f64; 14] = [
    0.1, 0.125, 0.15, 0.2, 0.25, 0.3, 0.4, 0.5, 0.6, 0.75, 1.0, 1.25, 1.5, 2.0,
];

impl SdemConfig {
    /// The grid matched to a scan, derived from its points (sensor frame, metres): the
    /// resolution at which a cell holds about one return, the band of elevations the scanner
    /// covers, and each cell's plane reaching as far as its neighbours
    /// ([`Self::plane_reach_from_neighbours`]). Use it for a LiDAR; the default grid is the
    /// tilting SICK's.
    ///
    /// * **Resolution**: the finest of 0.1°–2° (shrunk so that whole cells make a turn) at which
    ///   at most [`MAX_HOLE_FRACTION`] of the scanned cells are holes: about the scanner's
    ///   coarser angular step (0.5° for a Velodyne HDL-64E, whose 64 lasers lie 0.3–0.5° apart
    ///   and fire every 0.17°; 2° for a 16-beam one whose lasers lie 2° apart; 1° for the tilting
    ///   SICK of the paper). Finer cells would leave rows of holes between the lasers (and no
    ///   surface measurable from a cell's neighbours above and below), coarser ones keep only
    ///   the nearest of several returns.
    /// * **Elevation**: the scan's own band (−25°..+3° for the HDL-64E), widened by
    ///   [`SCAN_ELEVATION_MARGIN_DEG`] each way for the tilt between two levelled scans, in whole
    ///   degrees. A scan levelled by an attitude tilted further loses the points beyond: widen
    ///   `elevation_min_deg`/`elevation_max_deg` (or keep ±90°) for those.
    /// * **Azimuth**: always a full turn, even for a scanner with a narrower field of view: the
    ///   S-DEM is levelled by the compass too, so the sector a scan covers turns with its
    ///   heading (the SICK's ±90° sector, derived from one scan, lost the other scans' points
    ///   beyond it when they were turned 15°).
    ///
    /// Cells outside the extent are unknown either way, so the narrower grid changes no cost: it
    /// saves the memory and time of cells nothing fills. A scan with fewer than 100 usable
    /// points gets [`SdemConfig::default`].
    ///
    /// Both scans of a localization must be built on one grid: derive it once (from the first
    /// scan, or the sensor's typical scan) and build every scan with it
    /// ([`crate::Scan::with_grid`]).
    ///
    /// # Example
    /// ```
    /// use nalgebra::Point3;
    /// use sdem::SdemConfig;
    /// // 32 lasers 1° apart from −20° to +11°, firing every 0.2°: a ring of walls 10 m away.
    /// let points: Vec<Point3<f64>> = (0..32)
    ///     .flat_map(|laser| (0..1800).map(move |k| (laser, k)))
    ///     .map(|(laser, k)| {
    ///         let (el, az) = (((laser as f64) - 20.0).to_radians(), (k as f64 * 0.2).to_radians());
    ///         let r = 10.0 / el.cos();
    ///         Point3::new(r * el.cos() * az.cos(), r * el.cos() * az.sin(), r * el.sin())
    ///     })
    ///     .collect();
    /// let grid = SdemConfig::for_scan(&points);
    /// assert_eq!(grid.resolution_deg, 1.0); // the lasers' spacing, the coarser step
    /// assert_eq!((grid.elevation_min_deg, grid.elevation_max_deg), (-25.0, 16.0));
    /// assert_eq!((grid.azimuth_min_deg, grid.azimuth_max_deg), (-180.0, 180.0));
    /// ```
    pub fn for_scan<P: AsPoint>(points_in_sensor: &[P]) -> Self {
        Self::for_directions(points_in_sensor.iter().map(AsPoint::to_vec3))
    }

    /// The default grid (the tilting SICK's: a whole sphere, each cell's plane from its own
    /// returns) at the resolution [`Self::for_scan`] derives from a scan, but never finer than
    /// [`MIN_MATCHED_RESOLUTION_DEG`]: for a scanner that is no LiDAR, whose dataset has no
    /// `sensor.toml` to say its steps. A nodding laser sampling at 0.5° (3DTK's example scans)
    /// gets 0.6°: on the default 1° both of its later scans opened segments, on 0.6° the three
    /// map in one. The paper's sweep, at 1°, gets the default. A scan of fewer than 100 usable
    /// points gets [`SdemConfig::default`].
    ///
    /// # Example
    /// ```
    /// use sdem::geometry::Vec3;
    /// use sdem::SdemConfig;
    /// // A nodding laser's half sphere, 0.5° beams in lines 0.5° apart, walls 3 m away.
    /// let points: Vec<Vec3> = (0..170)
    ///     .flat_map(|line| (0..361).map(move |beam| (line, beam)))
    ///     .map(|(line, beam)| {
    ///         let (pitch, pan) = ((line as f64 * 0.5 - 45.0).to_radians(), (beam as f64 * 0.5 - 90.0).to_radians());
    ///         Vec3::new(pitch.cos() * pan.cos(), pan.sin(), pitch.sin() * pan.cos()) * 3.0
    ///     })
    ///     .collect();
    /// let grid = SdemConfig::default_for_scan(&points);
    /// assert!(grid.resolution_deg < 1.0 && grid.resolution_deg >= 0.5);
    /// assert_eq!(grid.elevation_min_deg, SdemConfig::default().elevation_min_deg);
    /// ```
    pub fn default_for_scan<P: AsPoint>(points_in_sensor: &[P]) -> Self {
        Self {
            resolution_deg: (Self::for_scan(points_in_sensor).resolution_deg)
                .max(whole_turn_deg(MIN_MATCHED_RESOLUTION_DEG)),
            ..Self::default()
        }
    }

    /// [`Self::for_scan`], which takes vectors too.
    #[deprecated(
        since = "0.1.0",
        note = "use SdemConfig::for_scan, which takes vectors too"
    )]
    pub fn for_points(points_in_sensor: &[Vec3]) -> Self {
        Self::for_scan(points_in_sensor)
    }

    fn for_directions(points: impl Iterator<Item = Vec3>) -> Self {
        let default = Self::default();
        // Azimuth in [0, 360) and elevation in [-90, 90], degrees.
        let directions: Vec<(f64, f64)> = points
            .filter(|p| p.iter().all(|v| v.is_finite()) && p.norm() >= default.min_range_m)
            .map(|p| {
                let (x, y, z) = (p.x as f32, p.y as f32, p.z as f32);
                let az = (fast_atan2(y, x) as f64).to_degrees().rem_euclid(360.0);
                let el = fast_atan2(z, (x * x + y * y).sqrt()) as f64;
                (az, el.to_degrees())
            })
            .collect();
        if directions.len() < 100 {
            return default;
        }
        let (el_lo, el_hi) = directions
            .iter()
            .fold((90f64, -90f64), |(lo, hi), d| (lo.min(d.1), hi.max(d.1)));
        // No grid finer than one return per cell on average can be free of holes: the covered
        // solid angle (in 1° cells) over the points bounds the resolution from below.
        let covered_deg2 = occupied_cells(&directions, 1.0, el_lo) as f64;
        let finest = (covered_deg2 / directions.len() as f64).sqrt();
        let resolution_deg = RESOLUTIONS_DEG
            .iter()
            .map(|&r| whole_turn_deg(r))
            .filter(|&r| r >= 0.9 * finest)
            .find(|&r| hole_fraction(&directions, r, el_lo) <= MAX_HOLE_FRACTION)
            .unwrap_or(2.0);
        let margin = SCAN_ELEVATION_MARGIN_DEG;
        Self {
            resolution_deg,
            // Whole degrees (a thousandth of a degree spared for the angles' rounding).
            elevation_min_deg: (el_lo - margin + 1e-3).floor().max(-90.0),
            elevation_max_deg: (el_hi + margin - 1e-3).ceil().min(90.0),
            plane_reach_from_neighbours: true,
            ..default
        }
    }

    /// Checks that the grid is well formed (positive resolution, non-empty extent inside the
    /// sphere).
    pub fn validate(&self) -> Result<()> {
        let all_finite = [
            self.resolution_deg,
            self.azimuth_min_deg,
            self.azimuth_max_deg,
            self.elevation_min_deg,
            self.elevation_max_deg,
            self.min_range_m,
        ]
        .iter()
        .all(|v| v.is_finite());
        if !all_finite || self.resolution_deg <= 0.0 || self.resolution_deg > 45.0 {
            return Err(Error::Invalid(format!(
                "S-DEM resolution {}° must be a finite angle in (0, 45]",
                self.resolution_deg
            )));
        }
        if !(-180.0 <= self.azimuth_min_deg
            && self.azimuth_min_deg < self.azimuth_max_deg
            && self.azimuth_max_deg <= 180.0)
        {
            return Err(Error::Invalid(format!(
                "S-DEM azimuth extent {}..{}° must satisfy -180 <= min < max <= 180",
                self.azimuth_min_deg, self.azimuth_max_deg
            )));
        }
        if !(-90.0 <= self.elevation_min_deg
            && self.elevation_min_deg < self.elevation_max_deg
            && self.elevation_max_deg <= 90.0)
        {
            return Err(Error::Invalid(format!(
                "S-DEM elevation extent {}..{}° must satisfy -90 <= min < max <= 90",
                self.elevation_min_deg, self.elevation_max_deg
            )));
        }
        if self.min_range_m < 0.0 {
            return Err(Error::Invalid("S-DEM min_range_m must be >= 0".into()));
        }
        let span_deg = (self.azimuth_max_deg - self.azimuth_min_deg)
            * (self.elevation_max_deg - self.elevation_min_deg);
        let cells = span_deg / (self.resolution_deg * self.resolution_deg);
        if cells > MAX_CELLS as f64 * (1.0 + 1e-9) {
            // Rounded up to a thousandth of a degree, so that the figure given passes.
            let finest = ((span_deg / MAX_CELLS as f64).sqrt() * 1e3).ceil() / 1e3;
            return Err(Error::Invalid(format!(
                "S-DEM resolution {}° over azimuth {}..{}° and elevation {}..{}° makes {:.3e} \
                 cells, more than the {MAX_CELLS} an S-DEM may have (a full sphere at 0.1°, \
                 the finest step a scanner's grid is derived at); use a resolution of at least \
                 {}° (or thin the scan)",
                self.resolution_deg,
                self.azimuth_min_deg,
                self.azimuth_max_deg,
                self.elevation_min_deg,
                self.elevation_max_deg,
                cells,
                finest,
            )));
        }
        Ok(())
    }
}

/// The most cells an S-DEM's grid may have: a full sphere at 0.1°, the finest step
/// [`SdemConfig::for_scan`] derives. Each cell holds a range, a plane and the search's tables
/// (on the order of a hundred bytes), so a grid of 0.001° (65 billion cells) asked for
/// hundreds of gigabytes and aborted the process; 6.5 million cells stay under a gigabyte.
pub const MAX_CELLS: usize = 3600 * 1800;

/// The fraction of the cells of a grid of `resolution_deg` in the band the `directions`
/// (azimuth in [0, 360), elevation, degrees) cover that are holes: empty, with a known cell
/// within [`MAX_HOLE_RUN`] cells above and below it or to its left and right. Among the empty
/// cells and the known ones.
fn hole_fraction(directions: &[(f64, f64)], resolution_deg: f64, elevation_min: f64) -> f64 {
    let (known, rows, columns) = occupancy(directions, resolution_deg, elevation_min);
    let at = |e: usize, a: usize| known[e * columns + a % columns];
    // Whether a known cell lies within `MAX_HOLE_RUN` cells of (e, a) along (de, da).
    let known_within = |e: usize, a: usize, de: isize, da: isize| {
        (1..=MAX_HOLE_RUN as isize).any(|k| {
            let row = e as isize + de * k;
            let column = (a + columns) as isize + da * k;
            (0..rows as isize).contains(&row) && at(row as usize, column as usize)
        })
    };
    let (mut holes, mut filled) = (0usize, 0usize);
    for e in 0..rows {
        for a in 0..columns {
            if at(e, a) {
                filled += 1;
            } else if (known_within(e, a, -1, 0) && known_within(e, a, 1, 0))
                || (known_within(e, a, 0, -1) && known_within(e, a, 0, 1))
            {
                holes += 1;
            }
        }
    }
    holes as f64 / (holes + filled).max(1) as f64
}

/// The cells of a grid of `resolution_deg` that the `directions` fill.
fn occupied_cells(directions: &[(f64, f64)], resolution_deg: f64, elevation_min: f64) -> usize {
    let (known, _, _) = occupancy(directions, resolution_deg, elevation_min);
    known.iter().filter(|&&k| k).count()
}

/// Which cells of a grid of `resolution_deg` over a full turn, from `elevation_min` up, the
/// `directions` (azimuth in [0, 360), elevation, degrees) fill: row by row, with the number of
/// rows and columns.
fn occupancy(
    directions: &[(f64, f64)],
    resolution_deg: f64,
    elevation_min: f64,
) -> (Vec<bool>, usize, usize) {
    let columns = (360.0 / resolution_deg).round() as usize;
    let rows = directions
        .iter()
        .map(|d| ((d.1 - elevation_min) / resolution_deg) as usize)
        .max()
        .unwrap_or(0)
        + 1;
    let mut known = vec![false; rows * columns];
    for &(az, el) in directions {
        let a = ((az / resolution_deg) as usize).min(columns - 1);
        let e = (((el - elevation_min) / resolution_deg) as usize).min(rows - 1);
        known[e * columns + a] = true;
    }
    (known, rows, columns)
}

/// A Sphere-DEM: the nearest range in each direction cell around the sensor, in the levelled
/// frame (world axes, origin at the sensor).
///
/// Besides the range grid it keeps the exact levelled point behind each known cell (its
/// *boundary point*, paper Sec. III-C), which virtual S-DEMs re-project.
#[derive(Debug, Clone)]
pub struct Sdem {
    spec: GridSpec,
    config: SdemConfig,
    /// Range per cell, metres; NaN for unknown.
    ranges: Vec<f32>,
    /// Boundary point of each known cell, levelled frame, metres.
    points: Vec<[f32; 3]>,
    /// The cell of each boundary point, ascending.
    cells: Vec<u32>,
    /// Per boundary point, the mean of its cell's returns on the nearest surface.
    surface_points: Vec<[f32; 3]>,
    /// The surface model, made on first use (a function of the fields above).
    surface: std::sync::OnceLock<CellSurfaces>,
    /// What other modules derive from this S-DEM, made on first use ([`Sdem::derived`]).
    derived: [DerivedSlot; 2],
    /// The attitude reading the points were levelled with (`world_from_sensor`'s rotation).
    attitude: Attitude,
}

impl PartialEq for Sdem {
    fn eq(&self, other: &Self) -> bool {
        self.spec == other.spec
            && self.config == other.config
            && self.attitude == other.attitude
            && self.cells == other.cells
            && self.points == other.points
            && self.surface_points == other.surface_points
            && self
                .ranges
                .iter()
                .zip(&other.ranges)
                .all(|(a, b)| a.to_bits() == b.to_bits())
    }
}

/// The surface in each known cell of an S-DEM, as a plane through its boundary point, with the
/// ranges along the cell's directions at which a point may be compared with it.
///
/// A 1° cell of a floor seen at a glancing angle spans decimetres of range; comparing a point's
/// range with the cell's one return would count that spread as error. Measured from the cell's
/// plane (its normal from the neighbouring cells' points), the same point is as far as it really
/// is from the surface: the range difference times the cosine of the angle of incidence.
#[derive(Debug, Clone)]
pub struct CellSurfaces {
    /// Per cell; the normal is NaN where the cell is unknown.
    #[doc(hidden)]
    pub cells: Vec<CellPlane>,
}

/// The plane of one cell.
#[derive(Debug, Clone, Copy)]
#[doc(hidden)]
pub struct CellPlane {
    /// Unit normal, pointing away from the sensor (NaN: unknown cell).
    pub n: [f32; 3],
    /// `n · p` (> 0) for the cell's boundary point `p`.
    pub d: f32,
    /// A point of the cell's directions is compared with the plane only at ranges in
    /// `[lo, hi]`: the plane's ranges over the cell's corners (kept within [`PLANE_REACH_M`] of
    /// the return, or of its neighbours' ranges with
    /// [`SdemConfig::plane_reach_from_neighbours`]), widened by [`PLANE_GATE_M`]. Beyond, it
    /// lies far along the ray from anything the scan saw, whatever its distance to the plane: a
    /// mismatch.
    pub lo: f32,
    /// See `lo`.
    pub hi: f32,
}

/// The plane's ranges in a cell are kept within this of the cell's return, metres: beyond it the
/// plane is extrapolated past what the scan saw.
pub const PLANE_REACH_M: f32 = 0.10;

/// A point is compared with a cell's plane at ranges up to this beyond the plane's interval in
/// the cell, metres.
pub const PLANE_GATE_M: f32 = 0.10;

impl CellSurfaces {
    /// The squared distance of `x` (at range `range = |x|`, in `cell`'s directions) from the
    /// cell's plane, `∞` where the range is out of the cell's gate, `None` for an unknown cell.
    #[inline(always)]
    #[doc(hidden)]
    pub fn squared_distance(&self, cell: usize, x: [f32; 3], range: f32) -> Option<f32> {
        let c = &self.cells[cell];
        if c.n[0].is_nan() {
            return None;
        }
        if !(range >= c.lo && range <= c.hi) {
            return Some(f32::INFINITY);
        }
        let e = c.n[0] * x[0] + c.n[1] * x[1] + c.n[2] * x[2] - c.d;
        Some(e * e)
    }

    fn new(sdem: &Sdem) -> Self {
        let spec = &sdem.spec;
        let (n_az, n_el) = (spec.azimuth_cells() as i64, spec.elevation_cells() as i64);
        let full_circle = spec.is_full_circle();
        let unknown = CellPlane {
            n: [f32::NAN; 3],
            d: f32::NAN,
            lo: f32::NAN,
            hi: f32::NAN,
        };
        let mut cells = vec![unknown; spec.len()];
        let mut index = vec![u32::MAX; spec.len()];
        for (i, &c) in sdem.cells.iter().enumerate() {
            index[c as usize] = i as u32;
        }
        let point_at = |e: i64, a: i64| -> Option<Vec3> {
            if e < 0 || e >= n_el {
                return None;
            }
            let a = if full_circle {
                wrap_column(a as i32, n_az as i32) as i64
            } else if a < 0 || a >= n_az {
                return None;
            } else {
                a
            };
            let i = index[(e * n_az + a) as usize];
            (i != u32::MAX).then(|| {
                let p = sdem.points[i as usize];
                Vec3::new(p[0] as f64, p[1] as f64, p[2] as f64)
            })
        };
        let res = spec.resolution();
        for (i, &cell) in sdem.cells.iter().enumerate() {
            let (e, a) = (cell as i64 / n_az, cell as i64 % n_az);
            let p = sdem.points[i];
            let p = Vec3::new(p[0] as f64, p[1] as f64, p[2] as f64);
            let range = p.norm();
            // Neighbours on the same surface: within a few cells' spread of this range.
            let near =
                |q: Option<Vec3>| q.filter(|q| (q.norm() - range).abs() < 0.05 + 0.1 * range);
            let tangent = |a: Option<Vec3>, b: Option<Vec3>| match (near(a), near(b)) {
                (Some(a), Some(b)) => Some(b - a),
                (Some(a), None) => Some(p - a),
                (None, Some(b)) => Some(b - p),
                (None, None) => None,
            };
            let neighbours = [
                point_at(e, a - 1),
                point_at(e, a + 1),
                point_at(e - 1, a),
                point_at(e + 1, a),
            ];
            let along = tangent(neighbours[0], neighbours[1]);
            let across = tangent(neighbours[2], neighbours[3]);
            // How far in range the neighbours on the same surface lie.
            let spread = if sdem.config.plane_reach_from_neighbours {
                neighbours
                    .iter()
                    .filter_map(|&q| near(q))
                    .map(|q| (q.norm() - range).abs())
                    .fold(0.0f64, f64::max)
            } else {
                0.0
            };
            let ray = p / range;
            let mut normal = match (along, across) {
                (Some(u), Some(v)) => {
                    let n = u.cross(&v);
                    let len = n.norm();
                    if len > 1e-12 {
                        n / len
                    } else {
                        ray
                    }
                }
                // A plane facing the sensor where the neighbours do not tell.
                _ => ray,
            };
            if normal.dot(&ray) < 0.0 {
                normal = -normal;
            }
            let d = normal.dot(&p);
            // The plane's range at the cell's corners, kept near the return.
            let (az0, el0) = spec.cell_center(cell as usize);
            let (mut lo, mut hi) = (range, range);
            for (da, de) in [(-0.5, -0.5), (0.5, -0.5), (-0.5, 0.5), (0.5, 0.5)] {
                let u = crate::geometry::direction(az0 + da * res, el0 + de * res);
                let nu = normal.dot(&u);
                let r = if nu > 1e-9 { d / nu } else { f64::INFINITY };
                lo = lo.min(r);
                hi = hi.max(r);
            }
            let reach = (PLANE_REACH_M as f64).max(spread);
            let gate = PLANE_GATE_M as f64;
            cells[cell as usize] = CellPlane {
                n: [normal.x as f32, normal.y as f32, normal.z as f32],
                d: d as f32,
                lo: (lo.max(range - reach) - gate) as f32,
                hi: (hi.min(range + reach) + gate) as f32,
            };
        }
        Self { cells }
    }
}

impl Sdem {
    /// Builds an S-DEM from points in the sensor frame and the sensor's attitude reading,
    /// keeping the nearest return per cell. The S-DEM keeps the attitude ([`Self::attitude`]):
    /// a localization reads it from there, so the levelling and the pose cannot disagree.
    ///
    /// # Arguments
    /// * `points_in_sensor` — the scan, sensor frame, metres ([`AsPoint`]: nalgebra points or
    ///   vectors, or arrays). Non-finite points are skipped.
    /// * `attitude` — the gyro/compass reading; its rotation takes the sensor frame to the
    ///   levelled frame (`Attitude::default()` for points already levelled).
    /// * `config` — grid resolution and extent.
    ///
    /// # Example
    /// ```
    /// use sdem::geometry::{Attitude, Vec3};
    /// use sdem::sdem::{Sdem, SdemConfig};
    /// let points = vec![Vec3::new(2.0, 0.0, 0.0), Vec3::new(1.0, 0.0, 0.0)];
    /// let attitude = Attitude::from_degrees(0.0, 0.0, 90.0);
    /// let s = Sdem::from_points(&points, &attitude, &SdemConfig::default()).unwrap();
    /// assert_eq!(s.known_cells(), 1); // both points fall into the same cell: the nearest stays
    /// let (az, _el) = s.grid().cell_center(s.cells()[0] as usize);
    /// assert!((az.to_degrees() - 90.5).abs() < 1e-3); // levelled: the compass turned it to +y
    /// ```
    pub fn from_points<P: AsPoint>(
        points_in_sensor: &[P],
        attitude: &Attitude,
        config: &SdemConfig,
    ) -> Result<Self> {
        let spec = GridSpec::new(config)?;
        let level_from_sensor = attitude.rotation();
        let levelled: Vec<[f32; 3]> = points_in_sensor
            .iter()
            .map(AsPoint::to_vec3)
            .filter(|p| p.iter().all(|v| v.is_finite()))
            .map(|p| {
                let q = level_from_sensor * p;
                [q.x as f32, q.y as f32, q.z as f32]
            })
            .collect();
        Ok(Self::from_levelled(
            spec,
            config.clone(),
            &levelled,
            *attitude,
        ))
    }

    /// Builds the S-DEMs of two scans side by side ([`Self::from_points`] for each, on two
    /// cores): a localization's reference and query.
    ///
    /// # Errors
    /// The first of the two builds' errors (an invalid configuration).
    pub fn pair_from_points(
        reference: (&[Vec3], &Attitude),
        query: (&[Vec3], &Attitude),
        config: &SdemConfig,
    ) -> Result<(Self, Self)> {
        let (r, q) = rayon::join(
            || Self::from_points(reference.0, reference.1, config),
            || Self::from_points(query.0, query.1, config),
        );
        Ok((r?, q?))
    }

    /// Builds an S-DEM on `spec` from points already in the levelled frame, nearest per cell.
    fn from_levelled(
        spec: GridSpec,
        config: SdemConfig,
        points: &[[f32; 3]],
        attitude: Attitude,
    ) -> Self {
        let mut ranges = vec![f32::NAN; spec.len()];
        let mut best: Vec<u32> = vec![u32::MAX; spec.len()];
        let min_range = config.min_range_m as f32;
        // Binned a chunk at a time by `cells_of` (vectorized; the same cells as `cell_of`, bit
        // for bit): a pair of KITTI scans (120,000 points each) took about 10 ms one `cell_of`
        // at a time, 5 ms so.
        const CHUNK: usize = 1024;
        let (mut xs, mut ys, mut zs) = ([0f32; CHUNK], [0f32; CHUNK], [0f32; CHUNK]);
        let (mut chunk_cells, mut chunk_ranges) = ([0u32; CHUNK], [0f32; CHUNK]);
        // Every point's cell and range, for the cells' means.
        let mut point_cells = Vec::with_capacity(points.len());
        let mut point_ranges = Vec::with_capacity(points.len());
        for (k, chunk) in points.chunks(CHUNK).enumerate() {
            let n = chunk.len();
            for (i, p) in chunk.iter().enumerate() {
                (xs[i], ys[i], zs[i]) = (p[0], p[1], p[2]);
            }
            spec.cells_of(
                &xs[..n],
                &ys[..n],
                &zs[..n],
                &mut chunk_cells[..n],
                &mut chunk_ranges[..n],
            );
            point_cells.extend_from_slice(&chunk_cells[..n]);
            point_ranges.extend_from_slice(&chunk_ranges[..n]);
            for i in 0..n {
                let (cell, r) = (chunk_cells[i], chunk_ranges[i]);
                if cell == u32::MAX {
                    continue;
                }
                let c = cell as usize;
                if r >= min_range && (ranges[c].is_nan() || r < ranges[c]) {
                    ranges[c] = r;
                    best[c] = (k * CHUNK + i) as u32;
                }
            }
        }
        let mut kept_points = Vec::new();
        let mut cells = Vec::new();
        for (cell, &i) in best.iter().enumerate() {
            if i != u32::MAX {
                kept_points.push(points[i as usize]);
                cells.push(cell as u32);
            }
        }
        let surface_points =
            cell_means::surface_points(points, &point_cells, &point_ranges, &ranges, &cells);
        Self {
            spec,
            config,
            ranges,
            points: kept_points,
            cells,
            surface_points,
            surface: std::sync::OnceLock::new(),
            derived: Default::default(),
            attitude,
        }
    }

    /// The *virtual S-DEM* (paper Sec. III-C, Fig. 4): this S-DEM's boundary points seen from
    /// another origin, `origin` in this S-DEM's levelled frame, keeping the nearest per cell
    /// (a z-buffer, so nearer surfaces occlude farther ones).
    pub fn virtual_at(&self, origin: &Vec3) -> Sdem {
        let o = [origin.x as f32, origin.y as f32, origin.z as f32];
        let moved: Vec<[f32; 3]> = self
            .points
            .iter()
            .map(|p| [p[0] - o[0], p[1] - o[1], p[2] - o[2]])
            .collect();
        Self::from_levelled(self.spec, self.config.clone(), &moved, self.attitude)
    }

    /// The attitude reading this S-DEM was levelled with.
    pub fn attitude(&self) -> &Attitude {
        &self.attitude
    }

    /// The grid geometry.
    pub fn grid(&self) -> &GridSpec {
        &self.spec
    }

    /// The configuration it was built with.
    pub fn config(&self) -> &SdemConfig {
        &self.config
    }

    /// Range of every cell, metres, NaN where unknown.
    pub fn ranges(&self) -> &[f32] {
        &self.ranges
    }

    /// The range of one cell, or `None` where it is unknown (or out of the grid).
    pub fn range(&self, cell: usize) -> Option<f32> {
        self.ranges.get(cell).copied().filter(|r| !r.is_nan())
    }

    /// The boundary points (levelled frame), one per known cell, in cell order.
    pub fn points(&self) -> &[[f32; 3]] {
        &self.points
    }

    /// Per boundary point, the mean of its cell's returns on the nearest surface (those within
    /// four times the scan's range noise behind the nearest): where the surface is, where the
    /// nearest of several noisy returns lies in front of it. The refinement compares these.
    pub fn surface_points(&self) -> &[[f32; 3]] {
        &self.surface_points
    }

    /// The known cells, ascending; `cells()[i]` holds `points()[i]`.
    pub fn cells(&self) -> &[u32] {
        &self.cells
    }

    /// Number of known cells.
    pub fn known_cells(&self) -> usize {
        self.cells.len()
    }

    /// The surface model of the known cells (made once, on first use).
    pub fn surfaces(&self) -> &CellSurfaces {
        self.surface.get_or_init(|| CellSurfaces::new(self))
    }

    /// What the module owning `T` derives from this S-DEM in `slot`: made by `make` on first use
    /// and kept with the S-DEM, so that localizing several queries (or one query under several
    /// rotations) against one reference makes it once. Typed by its owner, so that this module
    /// depends on none of them.
    pub(crate) fn derived<T: std::any::Any + Send + Sync>(
        &self,
        slot: Derived,
        make: impl FnOnce() -> T,
    ) -> &T {
        self.derived[slot as usize]
            .get_or_init(|| std::sync::Arc::new(make()))
            .downcast_ref::<T>()
            .expect("each slot holds the one type its owner puts there")
    }
}

/// One slot of data derived from an S-DEM and kept with it.
type DerivedSlot = std::sync::OnceLock<std::sync::Arc<dyn std::any::Any + Send + Sync>>;

/// The slots of [`Sdem::derived`], one per owner.
#[derive(Debug, Clone, Copy)]
pub(crate) enum Derived {
    /// The refinement's surface normals with their radius ([`crate::refine::SurfaceNormals::of`]).
    SurfaceNormals = 0,
    /// The exact search's tables ([`crate::bnb::RangeTables::of`]).
    RangeTables = 1,
}

#[cfg(test)]
mod tests;
