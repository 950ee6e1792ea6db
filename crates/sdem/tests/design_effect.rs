//! Kish's design effect of residuals grouped in patches, which widens the refinement's
//! covariance where neighbouring residuals are correlated.

use rand::SeedableRng;
use rand_distr::{Distribution, Normal};
use sdem::refine::design_effect;

/// `patches` patches of `size` residuals: a shared offset of σ `shared` per patch plus
/// independent noise of σ 1.
fn residuals(patches: u64, size: usize, shared: f64, seed: u64) -> Vec<(u64, f64)> {
    let mut rng = rand_chacha::ChaCha8Rng::seed_from_u64(seed);
    let unit = Normal::new(0.0, 1.0).unwrap();
    let mut out = Vec::new();
    // Patch ids out of order: the function sorts them itself.
    for p in (0..patches).rev() {
        let offset = shared * unit.sample(&mut rng);
        for _ in 0..size {
            out.push((p * 7919 % 1000, offset + unit.sample(&mut rng)));
        }
    }
    out
}

#[test]
fn independent_residuals_have_no_design_effect() {
    let d = design_effect(&mut residuals(400, 20, 0.0, 1));
    assert!((1.0..1.2).contains(&d), "design effect {d}");
}

/// With intra-patch correlation ρ = s²/(s² + 1) the effect is 1 + (m − 1) ρ: for s = 1 and
/// m = 20, 10.5.
#[test]
fn a_shared_offset_per_patch_multiplies_the_variance_as_kish_predicts() {
    let d = design_effect(&mut residuals(400, 20, 1.0, 2));
    assert!((8.5..12.5).contains(&d), "design effect {d}");
}

/// Fully shared residuals count once per patch: the effect is the patch's size.
#[test]
fn residuals_equal_within_each_patch_count_once_per_patch() {
    let mut r: Vec<(u64, f64)> = (0..300u64)
        .flat_map(|p| (0..8).map(move |_| (p, (p as f64 * 0.37).sin())))
        .collect();
    let d = design_effect(&mut r);
    assert!((d - 8.0).abs() < 1e-9, "design effect {d}");
}

#[test]
fn too_few_patches_or_residuals_leave_the_covariance_as_it_is() {
    assert_eq!(design_effect(&mut []), 1.0);
    assert_eq!(design_effect(&mut [(3, 0.5), (3, -0.2), (3, 0.1)]), 1.0);
    assert_eq!(design_effect(&mut [(1, 0.5), (2, -0.2)]), 1.0);
}
