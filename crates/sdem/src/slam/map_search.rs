//! The searches of a scan against the map that need no prediction, shared by the loop's
//! recovery ([`super::recovery`]) and by [`super::relocalize`] on a saved map: against the
//! merged virtual S-DEM of some nodes on a coarse grid then a fine one, and against the whole
//! map by place; and what a match must show to be taken ([`rejection`]).

use super::predictions::take_prediction_along;
use super::predictions::Prediction;
use super::step::{Attempt, HeadingPrior, PredictionSource, StepStatus};
use super::{ms, ScanInput, SlamOptions};
use crate::doubt::Doubt;
use crate::error::{Error, Result};
use crate::geometry::{pose_from_parts, Attitude, AttitudeSigma, Pose, Vec3};
use crate::localize::{
    localize, seen_through_less, CostConfig, Diagnostics, Localization, LocalizeOptions,
    OffsetPrior, RefinementSummary, SearchWindow,
};
use crate::map::{world_from_query, Descriptor, Map};
use crate::sdem::Sdem;
use crate::search::HeadingWindow;
use nalgebra::Point3;
use std::time::Instant;

/// A stop's match (step 3 of [`Slam::add_scan`]).
#[derive(Debug, Clone)]
pub(super) struct Matched {
    /// The sensor's pose in the world (the prediction's position along a free direction).
    pub world_from_sensor: Pose,
    /// The nodes matched against, with the query cells each one saw.
    pub references: Vec<(usize, usize)>,
    /// Where the search started, and its heading prior.
    pub source: PredictionSource,
    pub heading_prior: HeadingPrior,
    /// The pose the search started from.
    pub predicted: Pose,
    /// The match's cost, refinement, diagnostics and doubts, for the report.
    pub cost: f64,
    /// Cells compared at the best grid candidate (known on both sides).
    pub overlap: usize,
    pub refinement: RefinementSummary,
    pub diagnostics: Diagnostics,
    pub doubts: Vec<Doubt>,
    /// Wall time of the localization, ms.
    pub localize_ms: f64,
}

/// Where a stop was found.
pub(super) enum Located {
    /// Taken: matched against nodes of `segment`.
    Found {
        matched: Matched,
        status: StepStatus,
        segment: usize,
    },
    /// Found nowhere with confidence: the best guess of its pose (`measured`: the odometry's),
    /// the best match tried, and the weak match of the whole map's search, if any (`joins`).
    Lost {
        guess: Pose,
        best: Option<Matched>,
        measured: bool,
        weak: Option<Box<Matched>>,
    },
}

/// A search whose window is wider than this (either horizontal half-size, metres) or whose
/// heading window is wider than [`WIDE_HEADING_DEG`] runs on a coarse grid first
/// ([`COARSE_STEP_M`]), then on the configured step around the coarse optimum.
pub(super) const WIDE_HALF_M: f64 = 0.6;
/// See [`WIDE_HALF_M`], degrees.
pub(super) const WIDE_HEADING_DEG: f64 = 25.0;
/// The wide search prunes candidates with fewer inliers than this: a match it takes must be
/// told from its runner-up.
pub(super) const WIDE_MIN_INLIERS: f64 = 0.15;
/// The coarse grid of a wide search, metres (its heading step follows it).
pub(super) const COARSE_STEP_M: f64 = 0.05;
/// The coarse grid's truncation, metres: twice its step, so that the grid point nearest the
/// optimum (up to half a step and half a heading step off) still finds its cells within it;
/// the fine search then scores with the configured truncation.
pub(super) const COARSE_TRUNCATION_M: f64 = 0.1;
/// The fine search around a coarse optimum: ± this, metres…
pub(super) const FINE_HALF_M: f64 = 0.08;
/// … and ± this, degrees.
pub(super) const FINE_HEADING_DEG: f64 = 3.0;
/// A fine search whose optimum lies on its window's edge is searched again around it at most
/// this many times.
pub(super) const FINE_RECENTRES: usize = 2;

/// A search without a prior prunes candidates with fewer inliers than this share of what a
/// loop closure needs (the coarse grid's cost lies above the basin's bottom).
pub(super) const NO_PRIOR_SEARCH_SHARE: f64 = 0.75;

/// A place searched for a rival to a match taken at another place ([`MapSearch::find_in_map`])
/// is pruned on the coarse grid at twice the cost a rival may have there. In units of each
/// grid's `τ²`, a place's coarse optimum cost at most its fine optimum's plus 0.06 on the 73
/// places searched for 18 relocalizations of the route bench's `revisit` map (1.08–1.15 times
/// it where over 0.15). The cap doubles the fine cost's share and adds this, twice the 0.06
/// measured.
pub(super) const RIVAL_COARSE_EXCESS: f64 = 0.12;

/// What a search of the map without a prior found ([`MapSearch::find_in_map_or_weak`]): a
/// match taken, or else its best weak match; `ambiguous` when a match was not taken because
/// another place compares almost as well.
#[derive(Default)]
pub(super) struct PlaceSearch {
    pub found: Option<Located>,
    pub weak: Option<Matched>,
    pub ambiguous: bool,
}

/// A place: a node and up to `nodes` nodes of its segment within `radius_m` of it, merged.
#[derive(Debug, Clone, Copy, PartialEq)]
struct PlaceSize {
    nodes: usize,
    radius_m: f64,
}

/// A place searched over every heading ([`MapSearch::search_every_heading`]): the nodes whose
/// points are merged (seen from the first one's origin), the window's centre (world) and
/// half-size, and the share of its cells a match there must at least find on the coarse grid
/// (0: what a match without a prior needs), with the node of the match taken elsewhere that
/// this share comes from when the place is searched only as its rival.
#[derive(Debug, Clone, Copy)]
pub(super) struct EveryHeading<'n> {
    pub nodes: &'n [usize],
    pub centre: Vec3,
    pub half: [f64; 3],
    pub min_inlier_fraction: f64,
    pub rival_of: Option<usize>,
}

/// How far a compass reading may be off near steel, degrees (the fault bench's disturbed
/// compass: up to ±20°): the widest heading window around a compass.
pub(super) const DISTURBED_COMPASS_DEG: f64 = 25.0;

/// A map and the loop's options: the searches that need no prediction, shared by the loop and
/// by [`super::relocalize`] on a saved map.
pub(super) struct MapSearch<'a> {
    pub map: &'a Map,
    pub config: &'a SlamOptions,
    /// Every heading searched as a full turn, exactly ([`crate::localize::localize`] over
    /// ±180°), for a scan with an attitude reading, instead of at the surfaces' heading
    /// hypotheses: the relocalization's second pass when the first finds nothing.
    pub full_turn: bool,
}

impl MapSearch<'_> {
    /// Localizes `query` (the scan levelled by the prediction's attitude) against the merged
    /// virtual S-DEM of `references`, seen from the origin of the first (the node that
    /// overlaps most): its own points keep their full density there, and the other nodes fill
    /// in what it did not see. (Seen from the predicted origin instead, a node's points spread
    /// apart and leave holes: on the 3DTK scans, 1.6 m apart, a quarter of the query's cells
    /// found a reference cell instead of all of them.) A wide window is searched on a coarse
    /// grid first, then on the configured one around the coarse optimum. `checked`: with the
    /// runner-up search; `gate`: no match with fewer inliers than this fraction (the search
    /// prunes above that cost; the configured floor when higher).
    pub(super) fn match_prediction(
        &self,
        scan: &ScanInput,
        query: &Sdem,
        prediction: &Prediction,
        references: Vec<(usize, usize)>,
        checked: bool,
        gate: f64,
    ) -> Result<Matched> {
        let ids: Vec<usize> = references.iter().map(|r| r.0).collect();
        let position = prediction.position;
        let origin = self.map.nodes[ids[0]].position();
        let reference = self
            .map
            .merged_reference(&ids, &origin, &self.config.sdem)?;
        // A wide window, or a search for a runner-up (whose costs, near the cap, prune little),
        // runs on the coarse grid first.
        let wide = prediction.window_half[0].max(prediction.window_half[1]) > WIDE_HALF_M
            || prediction.heading_half > WIDE_HEADING_DEG
            || checked;
        let base = &self.config.localize;
        let options = LocalizeOptions {
            window: SearchWindow::around(&(position - origin), prediction.window_half),
            step_m: if wide {
                base.step_m.max(COARSE_STEP_M)
            } else {
                base.step_m
            },
            heading: HeadingWindow {
                half_range_deg: prediction.heading_half,
                step_deg: None,
            },
            cost: CostConfig {
                prior: prediction.prior_sigma_m.is_finite().then(|| OffsetPrior {
                    offset: (position - origin).into(),
                    sigma_m: prediction.prior_sigma_m,
                }),
                min_inlier_fraction: base.cost.min_inlier_fraction.max(gate),
                truncation_m: if wide {
                    base.cost.truncation_m.max(COARSE_TRUNCATION_M)
                } else {
                    base.cost.truncation_m
                },
                ..base.cost.clone()
            },
            refine: base.refine && !wide,
            runner_up: checked,
            ..base.clone()
        };
        let start = Instant::now();
        let found = localize(&reference, query, &options).map_err(|e| at_scan(e, scan, &ids))?;
        let mut matched = matched_from(&found, origin, references, prediction, ms(start));
        if wide {
            return self.fine(scan, prediction, matched, Some(prediction.attitude.yaw));
        }
        // Along a direction the scans leave free (a ditch's or a corridor's axis), the match's
        // position is the scans' sampling pattern, not the scene: it pulls towards the
        // reference's own origin (a forward-looking scan in a straight corridor came out 20 %
        // short at every step). Where the odometry measured the motion, it decides there, and
        // the edge carries its uncertainty.
        if prediction.measured && matched.diagnostics.flat_direction.is_some() {
            // Along the free direction the refinement and the grid's optimum slide as the
            // sampling pulls them, to the window's edge or beyond the refinement's plausible
            // move: the position there is the odometry's, so neither says the match is wrong.
            matched
                .doubts
                .retain(|d| !matches!(d, Doubt::RefinementFailed { .. } | Doubt::OnWindowEdge));
            take_prediction_along(
                &mut matched.world_from_sensor,
                &mut matched.diagnostics,
                &mut matched.doubts,
                &position,
                prediction.motion_sigma_m,
            );
        }
        Ok(matched)
    }

    /// The fine search around a coarse match: the configured step within ±[`FINE_HALF_M`] and
    /// ±[`FINE_HEADING_DEG`] of it, against the same nodes. A runner-up of the coarse search
    /// is searched the same way around it. On a coarse grid the costs lie above the basins'
    /// bottoms, each by how far its bottom is from the nearest grid point, so the coarse order
    /// of two basins says little: the one whose fine search comes out lower is the match, and
    /// the other a doubt when it compares almost as well. `search_yaw`: the heading the coarse
    /// search levelled the scan with, which the runner-up's heading is relative to (`None`:
    /// the coarse doubt is kept as it is). A doubt about another rotation carries over.
    fn fine(
        &self,
        scan: &ScanInput,
        prediction: &Prediction,
        coarse: Matched,
        search_yaw: Option<f64>,
    ) -> Result<Matched> {
        let mut matched = self.fine_at(scan, prediction, &coarse, &coarse.world_from_sensor)?;
        // A coarse search that took its runner-up (or another basin's candidate) for what the
        // scans saw through names the cheaper optimum as its runner-up: both basins are
        // searched finely alike.
        let rival = (coarse.doubts.iter())
            .find(|d| matches!(d, Doubt::RunnerUp { .. } | Doubt::SeenThrough { .. }));
        let d = &coarse.diagnostics;
        match (
            rival,
            d.runner_up_offset,
            d.runner_up_heading_deg,
            search_yaw,
        ) {
            (Some(_), Some(offset), Some(heading), Some(yaw)) => {
                let origin = self.map.nodes[coarse.references[0].0].position();
                let at = pose_from_parts(
                    origin + Vec3::from(offset),
                    Attitude::new(
                        prediction.attitude.roll,
                        prediction.attitude.pitch,
                        yaw + heading.to_radians(),
                    ),
                );
                let ratio = self.config.localize.ambiguous_cost_ratio;
                let peak = self.config.localize.peak_radius_m;
                match self.fine_at(scan, prediction, &coarse, &at) {
                    Ok(mut r) => {
                        let apart = (r.world_from_sensor.translation.vector
                            - matched.world_from_sensor.translation.vector)
                            .norm();
                        if apart > peak {
                            if better_match(&r, &matched) {
                                std::mem::swap(&mut matched, &mut r);
                            }
                            if r.cost < matched.cost {
                                matched.doubts.push(Doubt::SeenThrough {
                                    distance_m: apart,
                                    cost: r.cost,
                                    seen_through_fraction: r.diagnostics.seen_through_fraction,
                                });
                            } else if r.cost < ratio * matched.cost {
                                matched.doubts.push(Doubt::RunnerUp {
                                    distance_m: apart,
                                    cost: r.cost,
                                    best_cost: matched.cost,
                                });
                            }
                        }
                    }
                    Err(e) if e.is_no_match() => {}
                    Err(e) => return Err(e),
                }
            }
            (Some(doubt), ..) => matched.doubts.push(doubt.clone()),
            _ => {}
        }
        // The coarse optimum on its window's edge: the true pose may lie beyond the window,
        // whatever the fine search around it says.
        matched.doubts.retain(|d| !matches!(d, Doubt::OnWindowEdge));
        matched.doubts.extend(
            (coarse.doubts.into_iter())
                .filter(|d| d.is_other_rotation() || matches!(d, Doubt::OnWindowEdge)),
        );
        matched.predicted = prediction.pose();
        matched.localize_ms += coarse.localize_ms;
        Ok(matched)
    }

    /// The fine search of [`Self::fine`] around `at`; when its optimum lies on the fine
    /// window's edge (the coarse grid's optimum was off the basin's bottom by more than the
    /// fine window), searched again around that optimum, up to [`FINE_RECENTRES`] times.
    fn fine_at(
        &self,
        scan: &ScanInput,
        prediction: &Prediction,
        coarse: &Matched,
        at: &Pose,
    ) -> Result<Matched> {
        let mut at = *at;
        let mut recentres = 0;
        loop {
            let a = crate::geometry::attitude_of(&at);
            let fine = Prediction {
                position: at.translation.vector,
                attitude: Attitude::new(prediction.attitude.roll, prediction.attitude.pitch, a.yaw),
                window_half: [FINE_HALF_M; 3],
                heading_half: FINE_HEADING_DEG,
                prior_sigma_m: f64::INFINITY,
                motion_sigma_m: f64::INFINITY,
                measured: false,
                ..prediction.clone()
            };
            let query =
                Sdem::from_points(scan.points_in_sensor, &fine.attitude, &self.config.sdem)?;
            let matched =
                self.match_prediction(scan, &query, &fine, coarse.references.clone(), false, 0.0)?;
            let on_edge = (matched.doubts.iter()).any(|d| matches!(d, Doubt::OnWindowEdge));
            if !on_edge || recentres >= FINE_RECENTRES {
                return Ok(matched);
            }
            recentres += 1;
            at = matched.world_from_sensor;
        }
    }

    /// Why a match is not taken, in words; `None` when it is. `checked`: the runner-up was
    /// searched, so a match that shares little with the map may be taken when what it shares
    /// is confident (its doubt of few inliers is then dropped); `no_prior`: nothing but the
    /// scans vouches for it, so it needs as many inliers as a loop closure.
    pub(super) fn verdict(
        &self,
        matched: &mut Matched,
        measured: bool,
        checked: bool,
        no_prior: bool,
    ) -> Option<String> {
        let recovery = &self.config.recovery;
        let d = &matched.diagnostics;
        let shared = d.shared_inlier_fraction();
        let inliers = (shared * matched.overlap as f64).round() as usize;
        let shared_holds = checked
            && !no_prior
            && shared >= recovery.min_shared_inlier_fraction
            && inliers >= recovery.min_shared_inliers;
        if shared_holds {
            matched
                .doubts
                .retain(|d| !matches!(d, Doubt::FewInliers { .. }));
        }
        rejection(&matched.doubts, measured).or_else(|| {
            let tracking = self.config.min_tracking_inlier_fraction;
            if !checked && d.inlier_fraction < tracking {
                return Some(format!(
                    "only {:.0} % of the cells match (taken at once from {:.0} %; searched again \
                     wider)",
                    d.inlier_fraction * 100.0,
                    tracking * 100.0
                ));
            }
            // Counted at the refined pose too: on a LiDAR's coarse grid the best candidate
            // lies up to half a step from the pose (see `Diagnostics::refined_inlier_fraction`).
            let needed = self.config.loop_closure.min_inlier_fraction;
            let matching = d.matching_fraction();
            (no_prior && matching < needed).then(|| {
                format!(
                    "only {:.0} % of the cells match (a match without a prior needs {:.0} %)",
                    matching * 100.0,
                    needed * 100.0,
                )
            })
        })
    }

    /// The scan against the merged nodes `nodes` (seen from the first one's origin) over every
    /// heading, and over the tilt when the scan has no attitude reading (the global search of
    /// [`crate::localize`](crate::scan::localize) for scans as they come), within `half`
    /// around `centre` (world), on a coarse grid, then on the configured one around its
    /// optimum. `None` when nothing matches; else the match and whether it is taken (no doubt
    /// at all: no prediction vouches for it).
    pub(super) fn search_every_heading(
        &self,
        scan: &ScanInput,
        place: &EveryHeading,
        source: PredictionSource,
        attempts: &mut Vec<Attempt>,
    ) -> Result<Option<(Matched, bool)>> {
        let start = Instant::now();
        let EveryHeading {
            nodes,
            centre,
            half,
            ..
        } = *place;
        let origin = self.map.nodes[nodes[0]].position();
        let references: Vec<(usize, usize)> = nodes.iter().map(|&n| (n, 0)).collect();
        let prediction = Prediction {
            source,
            position: centre,
            attitude: scan.attitude.unwrap_or_default(),
            heading_prior: HeadingPrior::LastNode,
            heading_half: 180.0,
            window_half: half,
            prior_sigma_m: f64::INFINITY,
            motion_sigma_m: f64::INFINITY,
            measured: false,
        };
        let mut attempt = Attempt::new(&prediction, &references);
        let coarse = self.localize_every_heading(scan, place, &origin);
        let outcome = match coarse.and_then(|found| {
            let coarse = matched_from(&found, origin, references.clone(), &prediction, ms(start));
            // The fine search levels the scan by the coarse match's roll and pitch.
            let a = crate::geometry::attitude_of(&coarse.world_from_sensor);
            let levelled = Prediction {
                attitude: Attitude::new(a.roll, a.pitch, a.yaw),
                ..prediction.clone()
            };
            self.fine(scan, &levelled, coarse, scan.attitude.map(|a| a.yaw))
        }) {
            Ok(mut matched) => {
                let reason = self.verdict(&mut matched, false, true, true);
                attempt.record(&matched, reason);
                Some((matched, attempt.accepted))
            }
            Err(e) if e.is_no_match() => {
                attempt.reason = match place.rival_of {
                    Some(taken) => format!(
                        "no rival to the match at node {taken}: nothing here matches {:.0} % of \
                         the cells on the coarse grid, as a rival would",
                        place.min_inlier_fraction * 100.0,
                    ),
                    None => e.to_string(),
                };
                None
            }
            Err(e) if matches!(e, Error::TooFewPoints { .. } | Error::NoUsablePoints { .. }) => {
                attempt.reason = e.to_string();
                None
            }
            Err(e) => return Err(e),
        };
        attempt.time_ms = ms(start);
        attempts.push(attempt);
        Ok(outcome)
    }

    /// `sdem::localize` of the scan (its reading with the heading unknown, or no reading)
    /// against the merged points of the place's nodes around `origin` (world axes, level), on
    /// the coarse grid, with the runner-up search and no refinement.
    fn localize_every_heading(
        &self,
        scan: &ScanInput,
        place: &EveryHeading,
        origin: &Vec3,
    ) -> Result<Localization> {
        let grid = &self.config.sdem;
        let points: Vec<Point3<f64>> = (place.nodes.iter())
            .flat_map(|&n| self.map.nodes[n].points_in_world())
            .map(|p| Point3::from(p - origin))
            .collect();
        // The world's axes are level where gyro readings levelled the nodes, and the scan is
        // levelled by its own reading. A scan without one levels itself by its surfaces, and
        // then so does the place, so that the two levellings share their bias: the world's
        // axes are the readings' level, or without readings the first scan's axes, and either
        // may lean against the surfaces' (on the KITTI frames by 1–1.5°; taken as level, no
        // frame of the map could be relocalized in it, nor a 3DTK scan in its map).
        let levelled = scan.attitude.is_some()
            && (place.nodes.iter()).all(|&n| self.map.nodes[n].attitude_reading.is_some());
        let level = levelled.then(|| Attitude::default().with_sigma_deg(0.05, 0.05));
        let reference = crate::scan::Scan::with_grid(&points, level, grid)?;
        let query_points: Vec<Point3<f64>> = scan
            .points_in_sensor
            .iter()
            .map(|p| Point3::from(*p))
            .collect();
        // A heading σ of 60° is three σ of a half turn: every heading.
        let unknown_heading = scan.attitude.map(|a| Attitude {
            sigma: AttitudeSigma {
                yaw: 60f64.to_radians(),
                ..a.sigma
            },
            ..a
        });
        let query = crate::scan::Scan::with_grid(&query_points, unknown_heading, grid)?;
        let base = &self.config.localize;
        let mut options = LocalizeOptions {
            window: SearchWindow::around(&(place.centre - origin), place.half),
            step_m: base.step_m.max(COARSE_STEP_M),
            refine: false,
            runner_up: true,
            // Without a prior a match needs as many inliers as a loop closure: the coarse grid
            // prunes what falls well short of it.
            cost: CostConfig {
                min_inlier_fraction: self
                    .no_prior_inlier_fraction()
                    .max(place.min_inlier_fraction),
                truncation_m: base.cost.truncation_m.max(COARSE_TRUNCATION_M),
                ..base.cost.clone()
            },
            ..base.clone()
        };
        let levelled_by_readings = || {
            crate::global::rotation_prior(
                reference.attitude(),
                query.attitude(),
                crate::scan::LEVEL_TOLERANCE,
            )
            .is_none()
        };
        if self.full_turn && levelled_by_readings() {
            // Both levelled by their readings: the heading over a full turn, exactly.
            options.heading.half_range_deg = 180.0;
            return crate::localize::localize(reference.sdem(), query.sdem(), &options);
        }
        crate::scan::localize(&reference, &query, &options)
    }

    /// Relocalization without a prior: the nodes `keep` allows whose place descriptors look
    /// most like the scan's (over every heading), each with its neighbours searched over every
    /// heading around it (at most `max_candidates`, else
    /// [`super::RecoveryOptions::relocalize_candidates`]); the best trusted match, unless
    /// another place compares almost as well. `None` when nothing is found with confidence.
    pub(super) fn find_in_map(
        &self,
        scan: &ScanInput,
        keep: impl Fn(usize) -> bool,
        max_candidates: Option<usize>,
        attempts: &mut Vec<Attempt>,
    ) -> Result<Option<Located>> {
        Ok(self
            .find_in_map_or_weak(scan, keep, max_candidates, attempts)?
            .found)
    }

    /// [`Self::find_in_map`], and when nothing is taken, its best weak match: one with no
    /// doubt that the search found (it matches the share of cells the coarse search prunes
    /// at, [`NO_PRIOR_SEARCH_SHARE`] of a loop closure's) but not the share a match without a
    /// prior needs, unless a match elsewhere compares almost as well. Alone it is not taken;
    /// three of them that agree can be (`joins`).
    pub(super) fn find_in_map_or_weak(
        &self,
        scan: &ScanInput,
        keep: impl Fn(usize) -> bool,
        max_candidates: Option<usize>,
        attempts: &mut Vec<Attempt>,
    ) -> Result<PlaceSearch> {
        let recovery = &self.config.recovery;
        let count = max_candidates.unwrap_or(recovery.relocalize_candidates);
        let small = PlaceSize {
            nodes: recovery.relocalize_place_nodes,
            radius_m: recovery.relocalize_radius_m,
        };
        let first = self.search_places(scan, &keep, count, small, attempts)?;
        let wide = PlaceSize {
            nodes: recovery.relocalize_wide_place_nodes,
            radius_m: recovery.relocalize_wide_radius_m,
        };
        if first.found.is_some() || first.ambiguous || wide == small {
            return Ok(first);
        }
        let second = self.search_places(scan, &keep, count, wide, attempts)?;
        Ok(if second.found.is_some() || second.ambiguous {
            second
        } else {
            PlaceSearch {
                weak: second.weak.or(first.weak),
                ..second
            }
        })
    }

    /// [`Self::find_in_map_or_weak`] with places of one size.
    fn search_places(
        &self,
        scan: &ScanInput,
        keep: &impl Fn(usize) -> bool,
        count: usize,
        size: PlaceSize,
        attempts: &mut Vec<Attempt>,
    ) -> Result<PlaceSearch> {
        let recovery = &self.config.recovery;
        let candidates = self.place_candidates(scan, keep, count, size)?;
        let mut results: Vec<Matched> = Vec::new();
        let mut rivals: Vec<Matched> = Vec::new();
        for (node, distance) in candidates {
            let nodes = self.map.nearby_in_segment(node, size.radius_m, size.nodes);
            // A place searched after a match was taken elsewhere matters only as its rival.
            let taken_best = (results.iter()).min_by(|a, b| a.cost.total_cmp(&b.cost));
            let rival_needs = (taken_best.map(|best| self.rival_inlier_fraction(best.cost)))
                .filter(|&needs| needs > self.no_prior_inlier_fraction())
                .unwrap_or(0.0);
            let place = EveryHeading {
                nodes: &nodes,
                centre: self.map.nodes[node].position(),
                half: recovery.relocalize_window_half_m,
                min_inlier_fraction: rival_needs,
                rival_of: (taken_best.map(|b| b.references[0].0)).filter(|_| rival_needs > 0.0),
            };
            let found = self.search_every_heading(
                scan,
                &place,
                PredictionSource::Relocalization,
                attempts,
            )?;
            if let Some((matched, taken)) = found {
                if let Some(a) = attempts.last_mut() {
                    a.descriptor_distance = Some(distance);
                }
                if taken {
                    results.push(matched);
                } else {
                    rivals.push(matched);
                }
            }
        }
        let ratio = self.config.localize.ambiguous_cost_ratio;
        let segment_of = |m: &Matched| self.map.nodes[m.references[0].0].segment;
        let apart = |m: &Matched, best: &Matched| {
            let apart =
                m.world_from_sensor.translation.vector - best.world_from_sensor.translation.vector;
            segment_of(m) != segment_of(best)
                || apart.norm() > 0.3
                || m.world_from_sensor
                    .rotation
                    .angle_to(&best.world_from_sensor.rotation)
                    > 10f64.to_radians()
        };
        let Some(best) = results.iter().min_by(|a, b| a.cost.total_cmp(&b.cost)) else {
            // Nothing taken: the best weak match, when no other place rivals it.
            let floor = self.no_prior_inlier_fraction();
            let weak = (rivals.iter())
                .filter(|m| m.doubts.is_empty() && m.diagnostics.inlier_fraction >= floor)
                .min_by(|a, b| a.cost.total_cmp(&b.cost))
                .filter(|weak| {
                    !(rivals.iter()).any(|m| apart(m, weak) && m.cost < ratio * weak.cost)
                })
                .cloned();
            return Ok(PlaceSearch {
                found: None,
                weak,
                ambiguous: false,
            });
        };
        let elsewhere = |m: &Matched| apart(m, best);
        let rival = (results.iter().chain(&rivals))
            .filter(|m| elsewhere(m) && m.cost < ratio * best.cost)
            .min_by(|a, b| a.cost.total_cmp(&b.cost));
        if let Some(rival) = rival {
            if let Some(a) = attempts.last_mut() {
                a.reason = format!(
                    "{}another place (node {}) compares almost as well: {:.3e} m² against \
                     {:.3e} m²",
                    if a.reason.is_empty() { "" } else { "; " },
                    rival.references[0].0,
                    rival.cost,
                    best.cost
                );
                a.accepted = false;
            }
            return Ok(PlaceSearch {
                ambiguous: true,
                ..PlaceSearch::default()
            });
        }
        let segment = segment_of(best);
        Ok(PlaceSearch {
            found: Some(found(best.clone(), StepStatus::Relocalized, segment)),
            weak: None,
            ambiguous: false,
        })
    }

    /// The share of its cells a place must match on the coarse grid to rival a match of fine
    /// cost `best_cost`, as the search's cost cap ([`CostConfig::max_match_cost`]; 0 when any
    /// share could): a rival costs at most the ambiguity ratio × `best_cost` at its fine
    /// optimum, and on the coarse grid at most twice that (in units of each grid's `τ²`) plus
    /// [`RIVAL_COARSE_EXCESS`].
    fn rival_inlier_fraction(&self, best_cost: f64) -> f64 {
        let fine = &self.config.localize.cost;
        let share = self.config.localize.ambiguous_cost_ratio * best_cost
            / (fine.truncation_m * fine.truncation_m);
        (1.0 - 2.0 * share - RIVAL_COARSE_EXCESS).max(0.0)
    }

    /// The share of its cells a match without a prior must find on the coarse grid.
    fn no_prior_inlier_fraction(&self) -> f64 {
        let base = self.config.localize.cost.min_inlier_fraction;
        base.max(NO_PRIOR_SEARCH_SHARE * self.config.loop_closure.min_inlier_fraction)
    }

    /// The nodes `keep` allows, most alike to the scan first by place descriptor over every
    /// heading, at most `count`, no two within 0.5 m of each other in one segment (their
    /// places overlap).
    fn place_candidates(
        &self,
        scan: &ScanInput,
        keep: &impl Fn(usize) -> bool,
        count: usize,
        size: PlaceSize,
    ) -> Result<Vec<(usize, f64)>> {
        let level = scan.attitude.unwrap_or_default();
        let query = Sdem::from_points(scan.points_in_sensor, &level, &self.config.sdem)?;
        let descriptor = Descriptor::from_levelled(query.points());
        let mut scored: Vec<(usize, f64)> = (self.map.nodes.iter())
            .filter(|n| keep(n.node_id))
            .filter_map(|n| {
                let place = self
                    .map
                    .place_descriptor(n.node_id, size.radius_m, size.nodes)?;
                Some((n.node_id, descriptor.distance_any_heading(&place)?.0))
            })
            .collect();
        scored.sort_by(|a, b| a.1.total_cmp(&b.1).then(a.0.cmp(&b.0)));
        let mut chosen: Vec<(usize, f64)> = Vec::new();
        for (node, distance) in scored {
            if chosen.len() >= count {
                break;
            }
            let n = &self.map.nodes[node];
            let close = chosen.iter().any(|&(c, _)| {
                let c = &self.map.nodes[c];
                c.segment == n.segment && (c.position() - n.position()).norm() < 0.5
            });
            if !close {
                chosen.push((node, distance));
            }
        }
        Ok(chosen)
    }
}

/// The `count` nodes of `ids` nearest `position`, nearest first.
pub(super) fn nearest(map: &Map, ids: &[usize], position: &Vec3, count: usize) -> Vec<usize> {
    let mut by_distance: Vec<(usize, f64)> = (ids.iter())
        .map(|&id| (id, (map.nodes[id].position() - position).norm()))
        .collect();
    by_distance.sort_by(|a, b| a.1.total_cmp(&b.1).then(a.0.cmp(&b.0)));
    by_distance
        .into_iter()
        .take(count)
        .map(|(id, _)| id)
        .collect()
}

/// Whether two lists of reference nodes name the same nodes.
pub(super) fn same_nodes(a: &[(usize, usize)], b: &[(usize, usize)]) -> bool {
    let ids = |v: &[(usize, usize)]| {
        let mut ids: Vec<usize> = v.iter().map(|r| r.0).collect();
        ids.sort_unstable();
        ids
    };
    ids(a) == ids(b)
}

/// Whether `a` is a better match than `b`: the one whose returns the other scans saw through
/// far less ([`crate::localize::seen_through_less`]: a basin whose surfaces stand where the
/// map's beams passed is no place the scan was taken); else the cheaper.
pub(super) fn better_match(a: &Matched, b: &Matched) -> bool {
    let (a_through, b_through) = (
        a.diagnostics.seen_through_fraction,
        b.diagnostics.seen_through_fraction,
    );
    if seen_through_less(a_through, b_through) {
        true
    } else if seen_through_less(b_through, a_through) {
        false
    } else {
        a.cost < b.cost
    }
}

/// Keeps `matched` (of `prediction`) in `best` when it is the better match ([`better_match`]).
pub(super) fn keep_best(
    best: &mut Option<(Matched, Prediction)>,
    matched: Matched,
    prediction: &Prediction,
) {
    if best.as_ref().is_none_or(|(b, _)| better_match(&matched, b)) {
        *best = Some((matched, prediction.clone()));
    }
}

/// A taken match of `segment` with `status`.
pub(super) fn found(matched: Matched, status: StepStatus, segment: usize) -> Located {
    Located::Found {
        matched,
        status,
        segment,
    }
}

/// The match of a localization against a reference S-DEM with world axes centred on `origin`.
pub(super) fn matched_from(
    found: &Localization,
    origin: Vec3,
    references: Vec<(usize, usize)>,
    prediction: &Prediction,
    localize_ms: f64,
) -> Matched {
    Matched {
        world_from_sensor: world_from_query(&origin, found),
        references,
        source: prediction.source,
        heading_prior: prediction.heading_prior,
        predicted: prediction.pose(),
        cost: found.cost,
        overlap: found.overlap,
        refinement: RefinementSummary::new(found.refined, found.refinement.as_ref()),
        diagnostics: found.diagnostics.clone(),
        doubts: found.doubts.clone(),
        localize_ms,
    }
}

/// Why a match is not taken, in words; `None` when it is. Only a free direction whose position
/// a measured motion (the odometry) set may stay in doubt.
pub(super) fn rejection(doubts: &[Doubt], measured: bool) -> Option<String> {
    let taken_along = doubts
        .iter()
        .any(|d| matches!(d, Doubt::TakenFromPrediction { .. }));
    let why: Vec<String> = (doubts.iter())
        .filter(|d| match d {
            Doubt::TakenFromPrediction { .. } => false,
            Doubt::FlatCovariance { .. } | Doubt::FlatCost { .. } | Doubt::Unconstrained { .. } => {
                !(measured && taken_along)
            }
            _ => true,
        })
        .map(|d| format!("{}: {d}", d.kind()))
        .collect();
    (!why.is_empty()).then(|| why.join("; "))
}

/// A search that found no match at scan `scan`, naming the nodes it was matched against.
pub(super) fn at_scan(e: Error, scan: &ScanInput, nodes: &[usize]) -> Error {
    if e.is_no_match() {
        Error::AtScan {
            scan_index: scan.scan_index,
            nodes: nodes.to_vec(),
            source: Box::new(e),
        }
    } else {
        e
    }
}
