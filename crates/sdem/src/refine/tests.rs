//! Unit tests of the refinement's settings and plane fits.

use super::*;

/// The closed-form normal agrees with nalgebra's iterative eigen-decomposition on random
/// patches: flat ones (the normal to 1e-9), and it refuses the lines and blobs nalgebra's
/// eigenvalues call not a surface.
#[test]
fn plane_normal_matches_the_iterative_eigenvectors() {
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
        match plane_normal(&cov, 0.0) {
            Some(n) => {
                assert!(surface, "{l:?}: a normal where nalgebra sees no surface");
                let expected = eigen.eigenvectors.column(order[0]);
                assert!((n.dot(&expected).abs() - 1.0).abs() < 1e-9, "{l:?}");
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
