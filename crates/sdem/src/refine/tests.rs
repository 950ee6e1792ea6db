//! Unit tests of the refinement's settings and plane fits.

use super::*;
use nalgebra::Matrix3;

/// The closed-form normal and `λ0` agree with nalgebra's iterative eigen-decomposition on random
/// patches: flat ones (the normal to 1e-9), and it refuses the lines and blobs nalgebra's
/// eigenvalues call not a surface.
#[test]
fn plane_fit_matches_the_iterative_eigenvectors() {
    use rand::{Rng, SeedableRng};
    let mut rng = rand_chacha::ChaCha8Rng::seed_from_u64(3);
    let (mut flat, mut refused) = (0, 0);
    for _ in 0..2000 {
        let rotation = Rotation3::new(Vec3::new(
            rng.random_range(-3.0..3.0),
            rng.random_range(-3.0..3.0),
            rng.random_range(-3.0..3.0),
        ));
        let scale: f64 = 10f64.powf(rng.random_range(-6.0..0.0));
        let mut l = [
            scale * rng.random_range(0.0..0.3),
            scale * rng.random_range(0.1..1.0),
            scale * rng.random_range(0.1..1.0),
        ];
        l.sort_by(f64::total_cmp);
        let cov = rotation.matrix()
            * Matrix3::from_diagonal(&Vec3::new(l[0], l[1], l[2]))
            * rotation.matrix().transpose();
        let eigen = cov.symmetric_eigen();
        let mut order = [0usize, 1, 2];
        order.sort_by(|&a, &b| eigen.eigenvalues[a].total_cmp(&eigen.eigenvalues[b]));
        let (l0, l1) = (eigen.eigenvalues[order[0]], eigen.eigenvalues[order[1]]);
        let surface = l1 > 0.0 && l0 <= 0.25 * l1;
        // Too close to the threshold to tell apart by rounding: skipped.
        if (l0 / l1 - 0.25).abs() < 1e-9 {
            continue;
        }
        match super::normals::plane_fit(&cov, 0.0) {
            Some((n, thickness_sq)) => {
                assert!(surface, "{l:?}: a normal where nalgebra sees no surface");
                let expected = eigen.eigenvectors.column(order[0]);
                assert!((n.dot(&expected).abs() - 1.0).abs() < 1e-9, "{l:?}");
                assert!(
                    (thickness_sq - l0).abs() <= 1e-9 * l1,
                    "{thickness_sq} against {l0}"
                );
                flat += 1;
            }
            None => {
                assert!(!surface, "{l:?}: no normal where nalgebra sees a surface");
                refused += 1;
            }
        }
    }
    assert!(
        flat > 500 && refused > 500,
        "{flat} flat, {refused} refused"
    );
}

#[test]
fn bad_settings_are_refused_by_name() {
    for name in [
        "kernel_scale_m",
        "max_correspondence_m",
        "max_rotation_deg",
        "max_translation_m",
        "converged_step",
    ] {
        for bad in [0.0, -1.0, f64::NAN, f64::INFINITY] {
            let mut config = RefineConfig::default();
            match name {
                "kernel_scale_m" => config.kernel_scale_m = bad,
                "max_correspondence_m" => config.max_correspondence_m = bad,
                "max_rotation_deg" => config.max_rotation_deg = bad,
                "converged_step" => config.converged_step = bad,
                _ => config.max_translation_m = bad,
            }
            let e = config.validate().unwrap_err().to_string();
            assert!(e.contains(name), "{e}");
        }
    }
    let none = RefineConfig {
        max_iterations: 0,
        ..Default::default()
    };
    let e = none.validate().unwrap_err().to_string();
    assert!(e.contains("max_iterations = 0"), "{e}");
    for bad in [-0.5, 2.5, f64::NAN, f64::INFINITY] {
        let config = RefineConfig {
            blend_radius_cells: bad,
            ..Default::default()
        };
        let e = config.validate().unwrap_err().to_string();
        assert!(e.contains("blend_radius_cells"), "{e}");
    }
    for fine in [0.0, 1.0, 2.0] {
        let config = RefineConfig {
            blend_radius_cells: fine,
            ..Default::default()
        };
        config.validate().unwrap();
    }
    RefineConfig::default().validate().unwrap();
}

/// A patch's thickness is the scatter of its points about their plane: about the range noise's
/// variance on a wall seen head-on with 5 mm of noise, nothing on a noise-free one; and a
/// residual against a patch weighs `s² / (s² + thickness²)`.
#[test]
fn thickness_is_the_scatter_about_the_plane_and_weighs_residuals_down() {
    use crate::geometry::{direction, Attitude};
    use crate::sdem::{Sdem, SdemConfig};
    use rand::{Rng, SeedableRng};
    let wall = |noise_m: f64| {
        let mut rng = rand_chacha::ChaCha8Rng::seed_from_u64(5);
        let points: Vec<Vec3> = (-30..30)
            .flat_map(|i| (-20..20).map(move |j| (i, j)))
            .map(|(i, j)| {
                let d = direction((i as f64).to_radians(), (j as f64).to_radians());
                let noise = noise_m * rng.sample::<f64, _>(rand_distr::StandardNormal);
                d * (2.0 / d.x + noise)
            })
            .collect();
        let sdem = Sdem::from_points(&points, &Attitude::default(), &SdemConfig::default())
            .expect("a wall");
        let normals = SurfaceNormals::new(&sdem, 2);
        let mut t: Vec<f32> = (normals.thickness_sq.iter().copied())
            .filter(|t| t.is_finite())
            .collect();
        assert!(t.len() > 1500, "{} patches fitted", t.len());
        t.sort_by(f32::total_cmp);
        t[t.len() / 2] as f64
    };
    let noisy = wall(0.005);
    assert!(
        (0.5 * 2.5e-5..=1.5 * 2.5e-5).contains(&noisy),
        "median thickness² {noisy} against the noise's 2.5e-5 m²"
    );
    let clean = wall(0.0);
    assert!(
        clean < 1e-8,
        "median thickness² {clean} on a noise-free wall"
    );
    assert_eq!(thickness_weight(0.0, 0.02), 1.0);
    assert!((thickness_weight(4e-4, 0.02) - 0.5).abs() < 1e-12);
    assert!(thickness_weight(1e-2, 0.02) < 0.04);
    assert_eq!(thickness_weight(f64::NAN, 0.02), 1.0);
}

/// The normal equations weigh each residual by its reference patch's thickness: on a wall with
/// 1 cm of range noise (`λ0` about 1e-4 m², a weight of about 0.8 at the kernel's 2 cm) the summed
/// weights and the information come out about a fifth below what the same pairs give with every
/// patch taken as thin, and the inliers are the same.
#[test]
fn the_normal_equations_weigh_each_residual_by_its_patch() {
    use crate::geometry::{direction, Attitude};
    use crate::sdem::{Sdem, SdemConfig};
    use rand::{Rng, SeedableRng};
    let mut rng = rand_chacha::ChaCha8Rng::seed_from_u64(9);
    let points: Vec<Vec3> = (-30..30)
        .flat_map(|i| (-20..20).map(move |j| (i, j)))
        .map(|(i, j)| {
            let d = direction((i as f64).to_radians(), (j as f64).to_radians());
            let noise = 0.01 * rng.sample::<f64, _>(rand_distr::StandardNormal);
            d * (2.0 / d.x + noise)
        })
        .collect();
    let sdem =
        Sdem::from_points(&points, &Attitude::default(), &SdemConfig::default()).expect("a wall");
    let config = RefineConfig::default();
    let thick = SurfaceNormals::new(&sdem, 2);
    let mut thin = thick.clone();
    thin.thickness_sq.iter_mut().for_each(|t| *t = 0.0);
    let query = sdem.surface_points();
    let sums = |normals: &SurfaceNormals| {
        let pairing = Pairing {
            reference: &sdem,
            normals,
            config: &config,
        };
        let pose = (nalgebra::Matrix3::identity(), nalgebra::Vector3::zeros());
        let mut pairs = vec![u32::MAX; query.len()];
        let mut planes = vec![[f32::NAN; 6]; query.len()];
        let gate = Gate::new(&config, sdem.grid(), true);
        let scale = config.kernel_scale_m;
        let (h, _, _, wsum, inliers) = (query.chunks(CHUNK))
            .zip(pairs.chunks_mut(CHUNK))
            .zip(planes.chunks_mut(CHUNK))
            .map(|((q, p), l)| pairing.accumulate(&pose, q, p, l, true, scale, gate))
            .fold(NormalEquations::default(), NormalEquations::merged)
            .parts();
        (h.trace(), wsum, inliers)
    };
    let (h_thick, w_thick, inliers_thick) = sums(&thick);
    let (h_thin, w_thin, inliers_thin) = sums(&thin);
    assert!(inliers_thin > 1500, "{inliers_thin} inliers");
    assert_eq!(inliers_thick, inliers_thin);
    for (what, ratio) in [
        ("weights", w_thick / w_thin),
        ("information", h_thick / h_thin),
    ] {
        assert!(
            (0.7..0.9).contains(&ratio),
            "{what}: {ratio} of the thin patches'"
        );
    }
}

/// A refined pose that turned by Δθ from the grid's may have moved by the configured 10 cm plus
/// what that turn moves the points at their median range: the grid, searched at the readings'
/// tilt, shifted its offset to make up for the tilt the refinement takes out (3DTK's third
/// scan: 10.4 cm with a turn of 2.26°, points 1.6 m away). Without the turn, or beyond it, the
/// move is refused.
#[test]
fn a_move_that_makes_up_for_a_turn_is_plausible() {
    let config = RefineConfig::default();
    let initial = Isometry3::identity();
    // Points 4 m from the sensor: a turn of 2° moves them 14 cm.
    let points: Vec<[f32; 3]> = (0..100)
        .map(|i| {
            let a = (i as f32).to_radians() * 3.0;
            [4.0 * a.cos(), 4.0 * a.sin(), 0.0]
        })
        .collect();
    let turned = Rotation3::from_axis_angle(&Vec3::y_axis(), 2f64.to_radians());
    let straight = Rotation3::identity();
    let moved = |cm: f64| Vec3::new(0.0, 0.0, cm / 100.0);
    // 12 cm: within 10 cm + 4 m × 2° with the turn, beyond 10 cm without it.
    assert!(check_plausible(&initial, &turned, &moved(12.0), None, &points, &config).is_ok());
    let err = check_plausible(&initial, &straight, &moved(12.0), None, &points, &config)
        .unwrap_err()
        .to_string();
    assert!(err.contains("moved 12.0 cm"), "{err}");
    // 19 cm is within 10 cm + the turn's share, which is held to 10 cm (4 m × 2° would be 14);
    // 21 cm is beyond, and the message says how far it may go.
    assert!(check_plausible(&initial, &turned, &moved(19.0), None, &points, &config).is_ok());
    let err = check_plausible(&initial, &turned, &moved(21.0), None, &points, &config)
        .unwrap_err()
        .to_string();
    assert!(err.contains("plausible 20.0 cm"), "{err}");
    // Within 10 cm, with or without a turn; and no points: the configured move alone.
    assert!(check_plausible(&initial, &straight, &moved(9.0), None, &[], &config).is_ok());
    assert!(check_plausible(&initial, &turned, &moved(12.0), None, &[], &config).is_err());
}
