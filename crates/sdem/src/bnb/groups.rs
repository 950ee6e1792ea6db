//! The query's points grouped at several scales (cubes of 2, 4, 8 … cm), so that large boxes are
//! bounded from a few hundred groups instead of every point.

use crate::sdem::floor_i32;

/// One query point, or a group of nearby ones that share a bound.
#[derive(Clone, Copy, Debug)]
struct Group {
    center: [f32; 3],
    radius: f32,
    /// Horizontal distance of the farthest member from the z axis (for the heading chord).
    horizontal: f32,
    count: u32,
}

/// The query's points at several groupings: level 0 one point per group; level `m` the points in
/// one cube of side `2^m` cm.
#[doc(hidden)]
pub struct QueryGroups {
    /// The groups of each level, one field per array (for the vectorized bound).
    pub(super) balls: Vec<Balls>,
    /// The 75th-percentile group radius of each level, metres.
    pub(super) typical_radius: Vec<f32>,
    /// The number of query points (the sum of every level's counts).
    pub(super) points: usize,
}

impl QueryGroups {
    /// Groups `points` (the points the cost compares) at `levels` levels.
    pub fn new(points: &[[f32; 3]], levels: usize) -> Self {
        // A run of `(cube, point)` keys: one group, its members in the points' order.
        let make = |run: &[([i32; 3], usize)]| -> Group {
            let members = || run.iter().map(|&(_, i)| i);
            let mut c = [0f64; 3];
            for i in members() {
                for a in 0..3 {
                    c[a] += points[i][a] as f64;
                }
            }
            let n = run.len() as f64;
            let center = [(c[0] / n) as f32, (c[1] / n) as f32, (c[2] / n) as f32];
            let mut radius = 0f32;
            let mut horizontal = 0f32;
            for i in members() {
                let p = points[i];
                let d = ((p[0] - center[0]).powi(2)
                    + (p[1] - center[1]).powi(2)
                    + (p[2] - center[2]).powi(2))
                .sqrt();
                radius = radius.max(d);
                horizontal = horizontal.max((p[0] * p[0] + p[1] * p[1]).sqrt());
            }
            // Rounding margin: the members' distance was computed in f32.
            Group {
                center,
                radius: if run.len() == 1 {
                    0.0
                } else {
                    radius * (1.0 + 1e-5) + 1e-6
                },
                horizontal,
                count: run.len() as u32,
            }
        };
        let mut out = Vec::new();
        let mut typical = Vec::new();
        for m in 0..levels.max(1) {
            let mut keys: Vec<([i32; 3], usize)> = if m == 0 {
                (0..points.len()).map(|i| ([i as i32, 0, 0], i)).collect()
            } else {
                let side = 0.01 * (1u32 << m) as f32;
                points
                    .iter()
                    .enumerate()
                    .map(|(i, p)| (p.map(|c| floor_i32(c / side)), i))
                    .collect()
            };
            keys.sort_unstable();
            // In the order of their places (level 0: the S-DEM's cells, as the cost chose the
            // points; coarser: the cubes' raster order), so that one ball after another reads
            // neighbouring cells of the reference. Its planes and rows (~5 MB on the full
            // sphere) do not fit the L2 cache: on the 50 bench pairs this order took 6 % less
            // CPU (5.86-5.96 s against 6.21-6.36 s) than a scrambled one, which made a partial
            // bound a fairer sample, cut short a little sooner.
            let groups: Vec<Group> = keys.chunk_by(|a, b| a.0 == b.0).map(make).collect();
            // A level that hardly groups anything would only lose the finer level's detail.
            if out
                .last()
                .is_some_and(|finer: &Vec<Group>| groups.len() * 5 > finer.len() * 4)
            {
                continue;
            }
            let mut radii: Vec<f32> = groups.iter().map(|g| g.radius).collect();
            radii.sort_by(f32::total_cmp);
            typical.push(radii.get(radii.len() * 3 / 4).copied().unwrap_or(0.0));
            out.push(groups);
        }
        let balls = out
            .into_iter()
            .map(|groups| Balls {
                cx: groups.iter().map(|g| g.center[0]).collect(),
                cy: groups.iter().map(|g| g.center[1]).collect(),
                cz: groups.iter().map(|g| g.center[2]).collect(),
                radius: groups.iter().map(|g| g.radius).collect(),
                horizontal: groups.iter().map(|g| g.horizontal).collect(),
                count: groups.iter().map(|g| g.count).collect(),
            })
            .collect();
        Self {
            balls,
            typical_radius: typical,
            points: points.len(),
        }
    }
}

/// The fields of one grouping's [`Group`]s, one array each.
pub(super) struct Balls {
    pub(super) cx: Vec<f32>,
    pub(super) cy: Vec<f32>,
    pub(super) cz: Vec<f32>,
    pub(super) radius: Vec<f32>,
    pub(super) horizontal: Vec<f32>,
    pub(super) count: Vec<u32>,
}
