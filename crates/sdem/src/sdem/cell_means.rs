//! Each cell's surface point: the mean of its returns on the nearest surface.
//!
//! An S-DEM keeps the nearest return of each cell (Nagatani et al. 2003, Sec. III-A): right for
//! what the cell's ray is blocked by, but as a point on the surface the least of several noisy
//! returns is biased towards the sensor (by 0.56 σ for two returns, 0.85 σ for three), and a
//! scanner whose beams outnumber the cells puts several returns in many of them: a nodding SICK
//! at 1° where its lines crowd together away from straight ahead, a LiDAR's 0.18° firings in
//! 0.5° cells. The bias moves each surface towards the sensor that saw it, so two scans taken
//! from different places see it in different places. The refinement compares the cells' means
//! instead: unbiased, and less noisy.

/// Returns within this many standard deviations of the range noise behind a cell's nearest
/// lie on its surface.
const NOISE_SIGMAS: f32 = 4.0;
/// The least tolerance, metres: a noise-free scan still has its surfaces' slope within a cell.
const MIN_TOLERANCE_M: f32 = 0.01;
/// The largest tolerance, metres: beyond it a return lies on another surface.
const MAX_TOLERANCE_M: f32 = 0.2;

/// For each known cell (`cells`, ascending, with `nearest[cell]` its nearest range), the mean of
/// its returns that lie within the tolerance behind the nearest; `points[i]` fell in
/// `point_cells[i]` (`u32::MAX`: none) at range `point_ranges[i]`.
///
/// The tolerance is [`NOISE_SIGMAS`] times the scan's range noise, estimated as the median
/// over the cells with several returns of their ranges' standard deviation (within
/// [`MIN_TOLERANCE_M`], [`MAX_TOLERANCE_M`]): a SICK's 5 mm makes 2 cm, a Velodyne's 2 cm 8 cm.
pub(super) fn surface_points(
    points: &[[f32; 3]],
    point_cells: &[u32],
    point_ranges: &[f32],
    nearest: &[f32],
    cells: &[u32],
) -> Vec<[f32; 3]> {
    let tolerance = tolerance(point_cells, point_ranges, nearest.len());
    let mut sums = vec![[0f64; 4]; nearest.len()];
    for ((p, &cell), &r) in points.iter().zip(point_cells).zip(point_ranges) {
        let Some(&first) = nearest.get(cell as usize) else {
            continue;
        };
        if r >= first && r <= first + tolerance {
            let s = &mut sums[cell as usize];
            s[0] += p[0] as f64;
            s[1] += p[1] as f64;
            s[2] += p[2] as f64;
            s[3] += 1.0;
        }
    }
    cells
        .iter()
        .map(|&c| {
            let s = sums[c as usize];
            let n = s[3].max(1.0);
            [(s[0] / n) as f32, (s[1] / n) as f32, (s[2] / n) as f32]
        })
        .collect()
}

/// The tolerance behind a cell's nearest return, metres (see [`surface_points`]).
fn tolerance(point_cells: &[u32], point_ranges: &[f32], cell_count: usize) -> f32 {
    let mut moments = vec![[0f64; 3]; cell_count];
    for (&cell, &r) in point_cells.iter().zip(point_ranges) {
        if let Some(m) = moments.get_mut(cell as usize) {
            m[0] += 1.0;
            m[1] += r as f64;
            m[2] += (r as f64) * (r as f64);
        }
    }
    let mut deviations: Vec<f32> = moments
        .iter()
        .filter(|m| m[0] >= 2.0)
        .map(|m| {
            let mean = m[1] / m[0];
            (((m[2] - m[0] * mean * mean) / (m[0] - 1.0)).max(0.0)).sqrt() as f32
        })
        .collect();
    if deviations.is_empty() {
        return MIN_TOLERANCE_M;
    }
    let middle = deviations.len() / 2;
    let (_, median, _) = deviations.select_nth_unstable_by(middle, f32::total_cmp);
    (NOISE_SIGMAS * *median).clamp(MIN_TOLERANCE_M, MAX_TOLERANCE_M)
}

#[cfg(test)]
mod tests {
    use crate::geometry::{direction, Attitude, Vec3};
    use crate::sdem::{Sdem, SdemConfig};
    use rand::{Rng, SeedableRng};

    /// A wall 3 m ahead seen at 0.25° steps with 5 mm of range noise (16 returns a 1° cell),
    /// and a second wall 40 cm behind showing in every fourth cell: the nearest return of a
    /// cell lies well in front of the wall, the cell's mean on it, and the wall behind is
    /// left out.
    #[test]
    fn a_cells_mean_lies_on_its_nearest_surface() {
        let mut rng = rand_chacha::ChaCha8Rng::seed_from_u64(4);
        let mut points = Vec::new();
        for i in -80..80 {
            for j in -40..40 {
                let d = direction(
                    (i as f64 * 0.25).to_radians(),
                    (j as f64 * 0.25).to_radians(),
                );
                let noise = 0.005 * rng.sample::<f64, _>(rand_distr::StandardNormal);
                let behind = (i + 80) % 16 == 0 && j % 4 == 0;
                let wall = if behind { 3.4 } else { 3.0 };
                points.push(d * (wall / d.x + noise));
            }
        }
        let sdem =
            Sdem::from_points(&points, &Attitude::default(), &SdemConfig::default()).unwrap();
        let offset = |p: &[f32; 3]| {
            let p = Vec3::new(p[0] as f64, p[1] as f64, p[2] as f64);
            // Along the ray, from the wall 3 m ahead.
            p.norm() * (1.0 - 3.0 / p.x)
        };
        let mean = |v: &[[f32; 3]]| v.iter().map(offset).sum::<f64>() / v.len() as f64;
        let (nearest, surface) = (mean(sdem.points()), mean(sdem.surface_points()));
        assert!(
            nearest < -0.007,
            "nearest returns {:.2} mm off the wall",
            nearest * 1e3
        );
        assert!(
            surface.abs() < 0.0005,
            "cell means {:.2} mm off the wall",
            surface * 1e3
        );
        let worst = sdem
            .surface_points()
            .iter()
            .map(|p| offset(p).abs())
            .fold(0.0, f64::max);
        assert!(
            worst < 0.01,
            "a cell mean {:.1} mm off the wall",
            worst * 1e3
        );
    }
}
