//! A real scan as surfaces: splats (discs on planar patches, balls on clutter) that a scanner
//! elsewhere can see, and the space the scan saw to be empty.

use kiddo::{ImmutableKdTree, SquaredEuclidean};
use nalgebra::{Matrix3, Vector3};
use rayon::prelude::*;
use sdem::error::{Error, Result};
use sdem::geometry::{Pose, Vec3};
use sdem::sdem::SdemConfig;
use std::f64::consts::{FRAC_PI_2, PI, TAU};
use std::num::NonZero;

/// How a real scan becomes surfaces ([`SurfaceModel::new`]).
#[derive(Debug, Clone, PartialEq, serde::Serialize, serde::Deserialize)]
#[serde(default, deny_unknown_fields)]
pub struct ModelConfig {
    /// Returns nearer than this are left out (the robot itself, invalid returns), metres.
    pub min_range_m: f64,
    /// Returns farther than this are left out (a scanner's "no return" value), metres.
    pub max_range_m: f64,
    /// A splat's radius in the scan's own angular steps at its range (on a surface seen
    /// obliquely, along the slope, as the returns spread there): 0.8 covers the half diagonal
    /// (0.71) of the square between four neighbouring returns with a margin, so that the far
    /// side does not show through between them.
    pub footprint_steps: f64,
    /// The neighbourhood a return's surface normal is fitted over: this many angular steps at
    /// its range, and at least [`Self::min_patch_m`].
    pub patch_steps: f64,
    /// The smallest neighbourhood radius of a normal, metres: a patch must be wide against the
    /// scanner's range noise (1 cm for a SICK) for its plane to be a surface and not noise.
    pub min_patch_m: f64,
}

impl Default for ModelConfig {
    fn default() -> Self {
        Self {
            min_range_m: 0.2,
            max_range_m: 1000.0,
            footprint_steps: 0.8,
            patch_steps: 5.0,
            min_patch_m: 0.08,
        }
    }
}

impl ModelConfig {
    /// Checks the settings.
    ///
    /// # Errors
    /// [`Error::Invalid`] naming a field that is not a positive number, or ranges that do not
    /// increase.
    pub fn validate(&self) -> Result<()> {
        for (name, value) in [
            ("max_range_m", self.max_range_m),
            ("footprint_steps", self.footprint_steps),
            ("patch_steps", self.patch_steps),
            ("min_patch_m", self.min_patch_m),
        ] {
            if !(value.is_finite() && value > 0.0) {
                return Err(Error::Invalid(format!(
                    "re-view model: {name} = {value} must be a positive number"
                )));
            }
        }
        if !(self.min_range_m.is_finite()
            && self.min_range_m >= 0.0
            && self.min_range_m < self.max_range_m)
        {
            return Err(Error::Invalid(format!(
                "re-view model: min_range_m = {} must be >= 0 and below max_range_m = {}",
                self.min_range_m, self.max_range_m
            )));
        }
        Ok(())
    }
}

/// One splat: a disc on a planar patch (`normal` a unit vector), or a ball where the
/// neighbourhood is no plane (`normal` zero).
#[derive(Debug, Clone, Copy)]
struct Splat {
    centre: Vector3<f32>,
    normal: Vector3<f32>,
    radius: f32,
    /// Hits on discs within this of the nearest are blended, metres.
    tolerance: f32,
}

/// The fewest neighbours a normal is fitted from.
const MIN_PATCH_POINTS: usize = 8;
/// The most neighbours a normal is fitted from.
const MAX_PATCH_POINTS: usize = 64;
/// A patch is a plane when its smallest spread is at most this share of the middle one
/// (variances), as [`sdem::refine`]'s normals.
const PLANARITY: f64 = 0.25;
/// A disc seen more obliquely than this (cosine between its normal and the ray) is missed:
/// a scanner gets no return from a surface it sees almost edge-on (84°).
const MIN_DISC_COSINE: f32 = 0.1;
/// A disc's radius grows as the returns spread on a surface seen obliquely, up to this factor.
const MAX_OBLIQUE_SPREAD: f64 = 5.0;

/// A real scan as surfaces that can be seen again from near where it was taken.
///
/// Each return becomes a splat: a disc in the plane fitted to its neighbours (the return moved
/// onto that plane, which takes most of the scan's own noise out), or a ball where its
/// neighbours lie on no plane (clutter, edges, thin structures). The model is fixed geometry:
/// every view of it sees the same surfaces, so the poses between views are exact.
pub struct SurfaceModel {
    splats: Vec<Splat>,
    /// The scan's angular step, radians (its coarser one).
    step: f64,
    /// The splats' centres, for the clearance of a view's origin.
    tree: ImmutableKdTree<f32, 3>,
    /// How far the scan's own origin saw in each direction: what lies beyond is unknown.
    seen: DepthMap,
}

impl SurfaceModel {
    /// Builds the model of `points_in_sensor` (a real scan, metres, its sensor at the origin).
    ///
    /// The scan's angular step is the grid [`SdemConfig::for_scan`] derives from it (its
    /// coarser sampling step, the finest grid it fills without holes).
    ///
    /// # Errors
    /// [`Error::Invalid`] for invalid settings; [`Error::InvalidInput`] when fewer than 1,000
    /// returns lie within the range limits.
    pub fn new(points_in_sensor: &[Vec3], config: &ModelConfig) -> Result<Self> {
        config.validate()?;
        let points: Vec<Vec3> = points_in_sensor
            .iter()
            .filter(|p| p.iter().all(|v| v.is_finite()))
            .filter(|p| (config.min_range_m..=config.max_range_m).contains(&p.norm()))
            .copied()
            .collect();
        if points.len() < MIN_MODEL_POINTS {
            return Err(Error::InvalidInput {
                what: "the scan to re-view".into(),
                problem: format!(
                    "{} of its points lie within {}–{} m of its sensor; a surface model needs \
                     {MIN_MODEL_POINTS} (are the points metres in the sensor's frame?)",
                    points.len(),
                    config.min_range_m,
                    config.max_range_m
                ),
            });
        }
        let step = SdemConfig::for_scan(&points).resolution_deg.to_radians();
        let coordinates: Vec<[f32; 3]> = points
            .iter()
            .map(|p| [p.x as f32, p.y as f32, p.z as f32])
            .collect();
        let tree = ImmutableKdTree::new_from_slice(&coordinates);
        let splats: Vec<Splat> = points
            .par_iter()
            .map(|p| splat_at(p, &points, &tree, step, config))
            .collect();
        let centres: Vec<[f32; 3]> = splats.iter().map(|s| s.centre.into()).collect();
        let tree = ImmutableKdTree::new_from_slice(&centres);
        let mut model = Self {
            splats,
            step,
            tree,
            seen: DepthMap::empty(),
        };
        model.seen = DepthMap::of(&model, 0.5 * step);
        Ok(model)
    }

    /// The scan's angular step, degrees.
    pub fn step_deg(&self) -> f64 {
        self.step.to_degrees()
    }

    /// The number of splats (the returns within the range limits).
    pub fn len(&self) -> usize {
        self.splats.len()
    }

    /// True when the model holds no splat (never, for a built model).
    pub fn is_empty(&self) -> bool {
        self.splats.is_empty()
    }

    /// The distance from `point` (the scan's frame) to the nearest splat's centre, metres.
    pub fn clearance(&self, point: &Vec3) -> f64 {
        let q = [point.x as f32, point.y as f32, point.z as f32];
        let nearest = self.tree.nearest_one::<SquaredEuclidean>(&q);
        (nearest.distance as f64).sqrt()
    }

    /// True when the scan saw `point` (its frame) to be empty: it lies in front of what the
    /// scan saw in its direction, by `margin_m` at least.
    pub fn seen_empty(&self, point: &Vec3, margin_m: f64) -> bool {
        point.norm() + margin_m <= self.seen.farthest_near(point)
    }

    /// Sees the model from `world_from_view` (the scan's frame is the world): for each ray
    /// (unit vectors in the view's frame) the range to the surface it meets first, when the
    /// way there crosses only space the scan saw to be empty (else no return: the scan cannot
    /// say what a real scanner would have seen there).
    pub fn ranges(&self, world_from_view: &Pose, rays: &[Vec3]) -> Vec<Option<f64>> {
        let buckets = Buckets::new(self, world_from_view, bucket_size(self.step));
        let origin = world_from_view.translation.vector;
        let rotation = world_from_view.rotation;
        rays.par_iter()
            .map_init(Vec::new, |hits, ray| {
                let range = buckets.cast(ray, hits)?;
                let seen = self.seen_along(&origin, &(rotation * ray), range);
                seen.then_some(range)
            })
            .collect()
    }

    /// True when the ray from `origin` along `direction` (world) crosses only space the scan saw
    /// empty up to near `range`, where it meets a surface.
    fn seen_along(&self, origin: &Vec3, direction: &Vec3, range: f64) -> bool {
        // The last stretch is the surface's own neighbourhood: a return lies on it, within
        // the noise and the splats' spread.
        let end = range - (0.03 + 0.05 * range);
        let mut s = 0.0;
        while s < end {
            let x = origin + direction * s;
            let distance = x.norm();
            let slack = 0.02 + 2.0 * distance * self.step;
            if distance > self.seen.farthest_near(&x) + slack {
                return false;
            }
            // The next sample one depth-map cell further as the scan's origin sees the ray: a
            // ray running away from that origin crosses few cells however long it is.
            let sine = direction.cross(&x).norm() / distance.max(1e-9);
            s += (self.seen.size * distance / sine.max(1e-6)).max(end / MAX_SEEN_SAMPLES);
        }
        true
    }
}

/// The most points of a ray [`SurfaceModel::seen_along`] checks (a thin pole 4 m away still
/// falls between none of them on a ray 1 m from the scan's origin).
const MAX_SEEN_SAMPLES: f64 = 24.0;

/// The fewest returns a model is built from.
const MIN_MODEL_POINTS: usize = 1000;

/// The splat of return `p`: a disc in the plane of its neighbours, or a ball.
fn splat_at(
    p: &Vec3,
    points: &[Vec3],
    tree: &ImmutableKdTree<f32, 3>,
    step: f64,
    config: &ModelConfig,
) -> Splat {
    let range = p.norm();
    let spacing = range * step;
    let reach = (config.patch_steps * spacing).max(config.min_patch_m);
    let q = [p.x as f32, p.y as f32, p.z as f32];
    let near = tree.nearest_n_within::<SquaredEuclidean>(
        &q,
        (reach * reach) as f32,
        NonZero::new(MAX_PATCH_POINTS).expect("nonzero"),
        false,
    );
    let ball = |radius: f64| Splat {
        centre: p.cast::<f32>(),
        normal: Vector3::zeros(),
        radius: radius as f32,
        tolerance: 0.0,
    };
    let footprint = config.footprint_steps * spacing;
    if near.len() < MIN_PATCH_POINTS {
        return ball(footprint);
    }
    let mut mean = Vec3::zeros();
    for n in &near {
        mean += points[n.item as usize];
    }
    mean /= near.len() as f64;
    let mut cov = Matrix3::zeros();
    for n in &near {
        let d = points[n.item as usize] - mean;
        cov += d * d.transpose();
    }
    cov /= near.len() as f64;
    let eigen = cov.symmetric_eigen();
    let mut order = [0usize, 1, 2];
    order.sort_by(|&a, &b| eigen.eigenvalues[a].total_cmp(&eigen.eigenvalues[b]));
    let (l0, l1) = (
        eigen.eigenvalues[order[0]].max(0.0),
        eigen.eigenvalues[order[1]],
    );
    // A line (a floor seen edge-on, a pole) spreads across by no more than a step: no plane.
    if !(l1 > 0.0 && l0 <= PLANARITY * l1 && l1.sqrt() >= 0.5 * spacing) {
        return ball(footprint);
    }
    let normal: Vec3 = eigen.eigenvectors.column(order[0]).into_owned().normalize();
    let cosine = (normal.dot(p) / range).abs();
    let centre = p - normal * normal.dot(&(p - mean));
    let radius = footprint * (1.0 / cosine.max(1e-9)).min(MAX_OBLIQUE_SPREAD);
    Splat {
        centre: centre.cast::<f32>(),
        normal: normal.cast::<f32>(),
        radius: radius as f32,
        tolerance: (0.01f64).max(3.0 * l0.sqrt()).max(0.3 * radius) as f32,
    }
}

/// The angular size of a bucket of splats, radians: the scan's step, within 0.25°–2°.
fn bucket_size(step: f64) -> f64 {
    step.clamp(0.25f64.to_radians(), 2f64.to_radians())
}

/// The splats as a view sees them: each listed in every bucket (of a grid over azimuth and
/// elevation in the view's frame) its angular extent touches, so that a ray tests only the
/// splats of its bucket.
struct Buckets {
    size: f64,
    columns: usize,
    rows: usize,
    /// Per bucket, where its splats start in `items` (compressed rows).
    starts: Vec<u32>,
    items: Vec<u32>,
    /// The splats in the view's frame.
    local: Vec<Splat>,
}

impl Buckets {
    fn new(model: &SurfaceModel, world_from_view: &Pose, size: f64) -> Self {
        let columns = (TAU / size).ceil() as usize;
        let rows = (PI / size).ceil() as usize;
        let view_from_world = world_from_view.inverse();
        let rotation = view_from_world.rotation.to_rotation_matrix().into_inner();
        let translation = view_from_world.translation.vector;
        let (r32, t32) = (rotation.cast::<f32>(), translation.cast::<f32>());
        let local: Vec<Splat> = (model.splats.par_iter())
            .map(|s| Splat {
                centre: r32 * s.centre + t32,
                normal: r32 * s.normal,
                ..*s
            })
            .collect();
        let extents: Vec<Option<[i64; 4]>> = local
            .par_iter()
            .map(|s| angular_extent(s, size, columns, rows))
            .collect();
        let mut counts = vec![0u32; columns * rows + 1];
        for_each_bucket(&extents, columns, |_, b| counts[b + 1] += 1);
        for b in 0..columns * rows {
            counts[b + 1] += counts[b];
        }
        let starts = counts;
        let mut fill = starts.clone();
        let mut items = vec![0u32; *starts.last().expect("one bucket") as usize];
        for_each_bucket(&extents, columns, |i, b| {
            items[fill[b] as usize] = i as u32;
            fill[b] += 1;
        });
        Self {
            size,
            columns,
            rows,
            starts,
            items,
            local,
        }
    }

    /// The bucket of a unit ray.
    fn bucket(&self, ray: &Vector3<f32>) -> usize {
        let azimuth = (ray.y as f64).atan2(ray.x as f64) + PI;
        let elevation = (ray.z as f64).clamp(-1.0, 1.0).asin() + FRAC_PI_2;
        let column = ((azimuth / self.size) as usize).min(self.columns - 1);
        let row = ((elevation / self.size) as usize).min(self.rows - 1);
        row * self.columns + column
    }

    /// The range along `ray` (unit, view frame) to the surface it meets first: the nearest hit,
    /// blended with the hits on discs within its tolerance (the scan's surface, sampled by
    /// overlapping discs, each a little off); `hits` is scratch space.
    fn cast(&self, ray: &Vec3, hits: &mut Vec<(f32, f32, f32, bool)>) -> Option<f64> {
        let d = ray.cast::<f32>();
        let b = self.bucket(&d);
        hits.clear();
        for &i in &self.items[self.starts[b] as usize..self.starts[b + 1] as usize] {
            let s = &self.local[i as usize];
            let disc = s.normal != Vector3::zeros();
            let t = if disc {
                let cosine = s.normal.dot(&d);
                if cosine.abs() < MIN_DISC_COSINE {
                    continue;
                }
                s.normal.dot(&s.centre) / cosine
            } else {
                d.dot(&s.centre)
            };
            if t <= 0.0 {
                continue;
            }
            let off_sq = (d * t - s.centre).norm_squared();
            let r_sq = s.radius * s.radius;
            if disc {
                if off_sq > r_sq {
                    continue;
                }
                let w = 1.0 - off_sq / r_sq;
                hits.push((t, w * w + 1e-3, s.tolerance, true));
            } else {
                // A ball: the ray meets its near side.
                let along = d.dot(&s.centre);
                let across_sq = s.centre.norm_squared() - along * along;
                if across_sq > r_sq {
                    continue;
                }
                hits.push((along - (r_sq - across_sq).sqrt(), 1.0, 0.0, false));
            }
        }
        let nearest = hits.iter().copied().min_by(|a, b| a.0.total_cmp(&b.0))?;
        if !nearest.3 {
            return Some(nearest.0 as f64);
        }
        let limit = nearest.0 + nearest.2;
        let (mut sum, mut weight) = (0.0f64, 0.0f64);
        for &(t, w, _, disc) in hits.iter() {
            if disc && t <= limit {
                sum += (w * t) as f64;
                weight += w as f64;
            }
        }
        Some(sum / weight)
    }
}

/// The buckets a splat's angular extent touches: `[row_lo, row_hi, column_lo, column_hi]`
/// (columns may run past the grid's ends: they wrap), or `None` when the splat is too near to
/// bucket (the view stands in it).
fn angular_extent(s: &Splat, size: f64, columns: usize, rows: usize) -> Option<[i64; 4]> {
    let c = s.centre.cast::<f64>();
    let distance = c.norm();
    let radius = s.radius as f64;
    if distance <= 1.2 * radius {
        return None;
    }
    let spread = (radius / distance).asin();
    let elevation = (c.z / distance).asin();
    let azimuth = c.y.atan2(c.x);
    let (lo, hi) = (elevation - spread, elevation + spread);
    let row = |e: f64| (((e + FRAC_PI_2) / size).floor() as i64).clamp(0, rows as i64 - 1);
    let steepest = lo.abs().max(hi.abs());
    let (column_lo, column_hi) = if steepest >= FRAC_PI_2 - 1e-6 {
        (0, columns as i64 - 1)
    } else {
        let half = spread / steepest.cos();
        if half >= PI {
            (0, columns as i64 - 1)
        } else {
            let column = |a: f64| ((a + PI) / size).floor() as i64;
            (column(azimuth - half), column(azimuth + half))
        }
    };
    Some([row(lo), row(hi), column_lo, column_hi])
}

/// Calls `f(splat, bucket)` for every bucket each splat's extent touches.
fn for_each_bucket(extents: &[Option<[i64; 4]>], columns: usize, mut f: impl FnMut(usize, usize)) {
    let n = columns as i64;
    for (i, extent) in extents.iter().enumerate() {
        let Some([r0, r1, c0, c1]) = *extent else {
            continue;
        };
        let wide = c1 - c0 + 1 >= n;
        for r in r0..=r1 {
            if wide {
                for c in 0..n {
                    f(i, (r * n + c) as usize);
                }
            } else {
                for c in c0..=c1 {
                    f(i, (r * n + c.rem_euclid(n)) as usize);
                }
            }
        }
    }
}

/// The range the model shows from the scan's own origin, per cell of a grid over azimuth and
/// elevation (infinite where nothing was seen).
struct DepthMap {
    size: f64,
    columns: usize,
    rows: usize,
    ranges: Vec<f32>,
}

impl DepthMap {
    fn empty() -> Self {
        Self {
            size: PI,
            columns: 2,
            rows: 1,
            ranges: vec![f32::INFINITY; 2],
        }
    }

    /// The model seen from its origin at cells of `size` radians.
    fn of(model: &SurfaceModel, size: f64) -> Self {
        let columns = (TAU / size).ceil() as usize;
        let rows = (PI / size).ceil() as usize;
        let buckets = Buckets::new(model, &Pose::identity(), bucket_size(model.step));
        let ranges = (0..rows * columns)
            .into_par_iter()
            .map_init(Vec::new, |hits, cell| {
                let (row, column) = (cell / columns, cell % columns);
                let elevation = (row as f64 + 0.5) * size - FRAC_PI_2;
                let azimuth = (column as f64 + 0.5) * size - PI;
                let ray = sdem::geometry::direction(azimuth, elevation);
                buckets.cast(&ray, hits).map_or(f32::INFINITY, |r| r as f32)
            })
            .collect();
        Self {
            size,
            columns,
            rows,
            ranges,
        }
    }

    /// The farthest range seen in the cell of `point`'s direction and its eight neighbours:
    /// a point beyond it lies behind what the scan saw.
    fn farthest_near(&self, point: &Vec3) -> f64 {
        let norm = point.norm();
        if norm == 0.0 {
            return f64::INFINITY;
        }
        let azimuth = point.y.atan2(point.x) + PI;
        let elevation = (point.z / norm).clamp(-1.0, 1.0).asin() + FRAC_PI_2;
        let column = ((azimuth / self.size) as i64).min(self.columns as i64 - 1);
        let row = ((elevation / self.size) as i64).min(self.rows as i64 - 1);
        let mut farthest = 0f32;
        for r in (row - 1).max(0)..=(row + 1).min(self.rows as i64 - 1) {
            for c in column - 1..=column + 1 {
                let c = c.rem_euclid(self.columns as i64);
                farthest = farthest.max(self.ranges[(r as usize) * self.columns + c as usize]);
            }
        }
        farthest as f64
    }
}
