//! Why a localization's pose may be wrong: the typed doubts a result carries.
//!
//! A localization succeeds, fails (an [`crate::Error`]), or succeeds with doubts. The doubts are
//! values a caller can act on (widen the window, try other nodes, keep the pose out of the map),
//! not sentences to parse: each says what was seen, with the figures. [`Doubt`]'s `Display`
//! gives the same in words for people.

use serde::Serialize;
use std::fmt;

/// One reason not to trust a localization's pose. A result with any doubt is not trusted
/// ([`crate::localize::Localization::trusted`]).
///
/// Directions are unit vectors in the reference's levelled frame (world axes, origin at the
/// reference sensor).
#[derive(Debug, Clone, PartialEq, Serialize)]
#[serde(tag = "kind", rename_all = "snake_case")]
pub enum Doubt {
    /// Another candidate, beyond the peak radius and not on the optimum's own slope, scores
    /// almost as well: the scene repeats, or the scans share too little to tell the places
    /// apart.
    RunnerUp {
        /// How far the runner-up lies from the optimum, metres.
        distance_m: f64,
        /// Its cost (eq. 1), m².
        cost: f64,
        /// The optimum's cost, m².
        best_cost: f64,
    },
    /// The refinement's covariance is much wider along one direction than across it: the scans
    /// leave the pose free along it (a featureless corridor's axis).
    FlatCovariance {
        /// The direction of the widest σ.
        direction: [f64; 3],
        /// σ along it, metres.
        sigma_m: f64,
        /// σ along the best-constrained direction, metres.
        across_sigma_m: f64,
    },
    /// Hardly any matched surface faces along the direction the refinement fixes worst: the
    /// position along it rests on the noise of the other surfaces' normals, not on geometry (a
    /// featureless corridor or pipe, whose covariance alone can look well conditioned).
    Unconstrained {
        /// The direction (the refinement's least certain).
        direction: [f64; 3],
        /// The share of the matched points on surfaces facing along it within 60°.
        facing_fraction: f64,
        /// The share a trusted pose needs.
        needed_fraction: f64,
    },
    /// The search's cost barely rises along one direction from the optimum.
    FlatCost {
        /// The flattest direction.
        direction: [f64; 3],
        /// How far from the optimum the rise was measured, metres.
        distance_m: f64,
        /// The rise along it, m².
        rise: f64,
        /// The rise along the steepest direction, m².
        across_rise: f64,
    },
    /// Too few of the query's points matched the reference after the refinement.
    FewInliers {
        /// The fraction that matched.
        fraction: f64,
        /// The fraction a trusted match needs.
        trusted_from: f64,
    },
    /// The 6-DoF refinement failed; the pose is the grid search's, unconfirmed by the points.
    RefinementFailed {
        /// Why it failed.
        reason: String,
    },
    /// The optimum lies on the search window's edge: the true pose may lie outside the window.
    OnWindowEdge,
    /// The match tilted one scan against the other by more than their levels allow (three
    /// standard deviations of their roll and pitch, read by a gyro or, without one, found from
    /// the scan's surfaces): a level, or the match, is wrong.
    AttitudeCorrected {
        /// The tilt between the two levelled frames that the match found, degrees.
        tilt_deg: f64,
        /// What the levels allow, degrees.
        three_sigma_deg: f64,
    },
    /// The attitude was unknown, and a rotation other than the one returned, found from the
    /// surface orientations, compares almost as well: the scene looks alike turned (a
    /// rectangular room, a corridor, a single plane).
    AnotherRotation {
        /// The angle between the two rotations, degrees.
        angle_deg: f64,
        /// The other rotation's cost (eq. 1), m².
        cost: f64,
        /// The optimum's cost, m².
        best_cost: f64,
    },
    /// The attitude was unknown, and the scans agree as well turned by another rotation
    /// wherever they overlap there: it only overlaps less. Eq. (1) counts a direction one scan
    /// does not see as a mismatch, so it prefers the rotation that shows more of the scene in
    /// common; a scanner that sees the front half of the sphere, turned round in a corridor,
    /// sees less of what the other saw at its true heading than at the mirrored one. Seeing less
    /// is no evidence against a rotation: the scans cannot tell the two apart.
    UnrefutedRotation {
        /// The angle between the two rotations, degrees.
        angle_deg: f64,
        /// The share of the query's compared points that the reference sees at the other
        /// rotation's best placement.
        overlap_fraction: f64,
        /// The same share at the optimum.
        best_overlap_fraction: f64,
    },
    /// Eq. (1)'s lowest cost lies at another pose, where one scan's returns lie in space the
    /// other scan's beams passed through ([`crate::free_space`]): a wrong basin of a scene that
    /// repeats itself (a corridor's far wall drawn across the corridor). The pose returned is
    /// the best candidate that does not contradict the scans so; eq. (1) alone prefers the other.
    SeenThrough {
        /// How far the cheaper candidate lies from the pose returned, metres.
        distance_m: f64,
        /// Its cost (eq. 1) on the grid it was found on, m².
        cost: f64,
        /// The share of its compared returns that the other scan saw through.
        seen_through_fraction: f64,
    },
    /// A large share of the returns compared at the pose lie where the other scan's beams passed
    /// through ([`crate::free_space`]): the two scans cannot both have been taken from there,
    /// whatever eq. (1) says (it counts a return the other scan could not see and one it saw
    /// through alike). At right poses the share stays small even where the scene changed
    /// between the scans (moved rubble, dust, a person walking by; see
    /// [`crate::localize::SEEN_THROUGH_DOUBT`]); a wrong place in a window that does not hold the
    /// true one (a robot carried off) reaches it.
    FreeSpaceConflict {
        /// The share of the compared returns that the other scan saw through.
        seen_through_fraction: f64,
        /// The share a trusted pose stays below.
        trusted_below: f64,
    },
    /// The scans alone fit a place far from the pose found much better than the pose: the
    /// prediction in the cost (odometry, `--prior`) held the pose away from what the scans say.
    PriorConflict {
        /// How far that place lies from the pose's grid optimum, metres.
        distance_m: f64,
        /// Eq. (1) there, without the prediction's term, m².
        cost: f64,
        /// Eq. (1) at the pose's grid optimum, without the prediction's term, m².
        best_cost: f64,
    },
    /// Along a direction the scans leave free, the position was taken from the prediction
    /// (odometry or the last motion), not from the scans.
    TakenFromPrediction {
        /// The free direction.
        direction: [f64; 3],
        /// How far the prediction's position lies from the match's along it, metres.
        shift_m: f64,
    },
}

impl Doubt {
    /// Whether this doubt concerns the match itself (a repeated or flat cost, too few points,
    /// a failed refinement, surfaces where the other scan saw through), as opposed to where the
    /// search looked, what the attitude readings allow, or what the loop did with the result.
    /// Such a match is `ambiguous` in [`crate::localize::Diagnostics`].
    pub fn is_ambiguity(&self) -> bool {
        !matches!(
            self,
            Doubt::OnWindowEdge
                | Doubt::TakenFromPrediction { .. }
                | Doubt::PriorConflict { .. }
                | Doubt::AttitudeCorrected { .. }
        )
    }

    /// Whether this doubt says the scans allow another rotation than the one returned
    /// ([`Doubt::AnotherRotation`], [`Doubt::UnrefutedRotation`]): a search that refines the
    /// pose afterwards, within the rotation found, keeps it.
    pub fn is_other_rotation(&self) -> bool {
        matches!(
            self,
            Doubt::AnotherRotation { .. } | Doubt::UnrefutedRotation { .. }
        )
    }

    /// A short name for the kind, as the JSON's `kind` field spells it.
    pub fn kind(&self) -> &'static str {
        match self {
            Doubt::RunnerUp { .. } => "runner_up",
            Doubt::FlatCovariance { .. } => "flat_covariance",
            Doubt::FlatCost { .. } => "flat_cost",
            Doubt::Unconstrained { .. } => "unconstrained",
            Doubt::FewInliers { .. } => "few_inliers",
            Doubt::RefinementFailed { .. } => "refinement_failed",
            Doubt::OnWindowEdge => "on_window_edge",
            Doubt::AttitudeCorrected { .. } => "attitude_corrected",
            Doubt::AnotherRotation { .. } => "another_rotation",
            Doubt::UnrefutedRotation { .. } => "unrefuted_rotation",
            Doubt::SeenThrough { .. } => "seen_through",
            Doubt::FreeSpaceConflict { .. } => "free_space_conflict",
            Doubt::TakenFromPrediction { .. } => "taken_from_prediction",
            Doubt::PriorConflict { .. } => "prior_conflict",
        }
    }
}

impl fmt::Display for Doubt {
    fn fmt(&self, f: &mut fmt::Formatter<'_>) -> fmt::Result {
        match self {
            Doubt::RunnerUp {
                distance_m,
                cost,
                best_cost,
            } => write!(
                f,
                "a candidate {:.0} cm away scores {cost:.3e} m² against the best {best_cost:.3e} m²",
                distance_m * 100.0
            ),
            Doubt::FlatCovariance {
                direction: v,
                sigma_m,
                across_sigma_m,
            } => write!(
                f,
                "the cost is flat along ({:.2}, {:.2}, {:.2}): σ {:.2} mm there against {:.2} mm \
                 across",
                v[0],
                v[1],
                v[2],
                sigma_m * 1e3,
                across_sigma_m * 1e3
            ),
            Doubt::Unconstrained {
                direction: v,
                facing_fraction,
                needed_fraction,
            } => write!(
                f,
                "nothing fixes the position along ({:.2}, {:.2}, {:.2}): only {:.1} % of the \
                 matched points lie on surfaces facing that way (a trusted pose needs {:.1} %)",
                v[0],
                v[1],
                v[2],
                facing_fraction * 100.0,
                needed_fraction * 100.0
            ),
            Doubt::FlatCost {
                direction: v,
                distance_m,
                rise,
                across_rise,
            } => write!(
                f,
                "the cost is flat along ({:.2}, {:.2}, {:.2}): {:.0} cm away it rises {:.2e} m², \
                 against {:.2e} m² across",
                v[0],
                v[1],
                v[2],
                distance_m * 100.0,
                rise,
                across_rise
            ),
            Doubt::FewInliers {
                fraction,
                trusted_from,
            } => write!(
                f,
                "only {:.0} % of the query's points matched the reference (trusted from {:.0} %): \
                 too little in common",
                fraction * 100.0,
                trusted_from * 100.0
            ),
            Doubt::RefinementFailed { reason } => write!(
                f,
                "the 6-DoF refinement failed ({reason}); the pose is the grid's, unconfirmed by \
                 the points"
            ),
            Doubt::OnWindowEdge => write!(
                f,
                "the optimum lies on the search window's edge: the true pose may lie outside it"
            ),
            Doubt::AttitudeCorrected {
                tilt_deg,
                three_sigma_deg,
            } => write!(
                f,
                "the match tilts the scans {tilt_deg:.2}° against each other, beyond the \
                 {three_sigma_deg:.2}° their levels allow (roll and pitch, read or found from \
                 the surfaces): a level or the match is wrong"
            ),
            Doubt::AnotherRotation {
                angle_deg,
                cost,
                best_cost,
            } => write!(
                f,
                "the scans compare almost as well turned {angle_deg:.0}° from the pose found \
                 ({cost:.3e} m² against {best_cost:.3e} m²): the scene looks alike turned"
            ),
            Doubt::UnrefutedRotation {
                angle_deg,
                overlap_fraction,
                best_overlap_fraction,
            } => write!(
                f,
                "turned {angle_deg:.0}° from the pose found the scans agree as well where they \
                 overlap, but overlap less ({:.0} % of the query's points against {:.0} %): \
                 the scans cannot tell the two rotations apart (a corridor seen from its other \
                 end)",
                overlap_fraction * 100.0,
                best_overlap_fraction * 100.0
            ),
            Doubt::SeenThrough {
                distance_m,
                cost,
                seen_through_fraction,
            } => write!(
                f,
                "a candidate {:.0} cm away costs less ({cost:.3e} m²), but {:.0} % of the \
                 returns it compares lie where the other scan saw through: the pose is the best \
                 candidate that does not contradict the scans so",
                distance_m * 100.0,
                seen_through_fraction * 100.0
            ),
            Doubt::FreeSpaceConflict {
                seen_through_fraction,
                trusted_below,
            } => write!(
                f,
                "{:.0} % of the returns compared lie where the other scan's beams passed \
                 (trusted below {:.0} %): the scans cannot both have been taken from this pose",
                seen_through_fraction * 100.0,
                trusted_below * 100.0
            ),
            Doubt::PriorConflict {
                distance_m,
                cost,
                best_cost,
            } => write!(
                f,
                "the scans alone fit a place {:.0} cm away far better ({cost:.3e} m² against \
                 {best_cost:.3e} m² here): the prediction, not the scans, put the pose here",
                distance_m * 100.0
            ),
            Doubt::TakenFromPrediction {
                direction: v,
                shift_m,
            } => write!(
                f,
                "along ({:.2}, {:.2}, {:.2}) the position is the prediction's ({:+.1} cm from the \
                 match's)",
                v[0],
                v[1],
                v[2],
                shift_m * 100.0
            ),
        }
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn the_json_names_the_kind_beside_the_figures() {
        let doubt = Doubt::FewInliers {
            fraction: 0.2,
            trusted_from: 0.25,
        };
        let json = serde_json::to_value(&doubt).unwrap();
        assert_eq!(json["kind"], "few_inliers");
        assert_eq!(json["fraction"], 0.2);
        assert_eq!(json["trusted_from"], 0.25);
        assert!(doubt
            .to_string()
            .starts_with("only 20 % of the query's points"));
        // Every kind: the JSON's tag (serde's renaming) is what `kind` says, the figures sit
        // beside it, and only the doubts about where the search looked or what the loop took
        // from the prediction are not about the match's shape.
        let all = [
            (
                Doubt::RunnerUp {
                    distance_m: 0.3,
                    cost: 2e-3,
                    best_cost: 1e-3,
                },
                "runner_up",
                true,
            ),
            (
                Doubt::FlatCovariance {
                    direction: [1.0, 0.0, 0.0],
                    sigma_m: 0.05,
                    across_sigma_m: 0.001,
                },
                "flat_covariance",
                true,
            ),
            (
                Doubt::Unconstrained {
                    direction: [1.0, 0.0, 0.0],
                    facing_fraction: 0.001,
                    needed_fraction: 0.02,
                },
                "unconstrained",
                true,
            ),
            (
                Doubt::FlatCost {
                    direction: [0.0, 1.0, 0.0],
                    distance_m: 0.1,
                    rise: 1e-6,
                    across_rise: 1e-3,
                },
                "flat_cost",
                true,
            ),
            (doubt, "few_inliers", true),
            (
                Doubt::RefinementFailed {
                    reason: "diverged".into(),
                },
                "refinement_failed",
                true,
            ),
            (Doubt::OnWindowEdge, "on_window_edge", false),
            (
                Doubt::AnotherRotation {
                    angle_deg: 180.0,
                    cost: 1.05e-3,
                    best_cost: 1e-3,
                },
                "another_rotation",
                true,
            ),
            (
                Doubt::UnrefutedRotation {
                    angle_deg: 180.0,
                    overlap_fraction: 0.25,
                    best_overlap_fraction: 0.9,
                },
                "unrefuted_rotation",
                true,
            ),
            (
                Doubt::AttitudeCorrected {
                    tilt_deg: 4.0,
                    three_sigma_deg: 2.1,
                },
                "attitude_corrected",
                false,
            ),
            (
                Doubt::TakenFromPrediction {
                    direction: [1.0, 0.0, 0.0],
                    shift_m: 0.04,
                },
                "taken_from_prediction",
                false,
            ),
            (
                Doubt::SeenThrough {
                    distance_m: 1.2,
                    cost: 1.5e-3,
                    seen_through_fraction: 0.2,
                },
                "seen_through",
                true,
            ),
            (
                Doubt::FreeSpaceConflict {
                    seen_through_fraction: 0.31,
                    trusted_below: 0.25,
                },
                "free_space_conflict",
                true,
            ),
            (
                Doubt::PriorConflict {
                    distance_m: 0.34,
                    cost: 4.5e-4,
                    best_cost: 1.6e-3,
                },
                "prior_conflict",
                false,
            ),
        ];
        for (doubt, kind, ambiguity) in &all {
            let json = serde_json::to_value(doubt).unwrap();
            assert_eq!(json["kind"], *kind, "{doubt:?}");
            assert_eq!(doubt.kind(), *kind);
            assert_eq!(doubt.is_ambiguity(), *ambiguity, "{doubt:?}");
            // The kind and the variant's fields, nothing else.
            let fields = json.as_object().unwrap().len() - 1;
            let expected = match doubt {
                Doubt::OnWindowEdge => 0,
                Doubt::RefinementFailed { .. } => 1,
                Doubt::FewInliers { .. }
                | Doubt::TakenFromPrediction { .. }
                | Doubt::AttitudeCorrected { .. }
                | Doubt::FreeSpaceConflict { .. } => 2,
                Doubt::RunnerUp { .. }
                | Doubt::FlatCovariance { .. }
                | Doubt::Unconstrained { .. }
                | Doubt::AnotherRotation { .. }
                | Doubt::UnrefutedRotation { .. }
                | Doubt::SeenThrough { .. }
                | Doubt::PriorConflict { .. } => 3,
                Doubt::FlatCost { .. } => 4,
            };
            assert_eq!(fields, expected, "{json}");
            assert!(!doubt.to_string().is_empty());
        }
    }
}
