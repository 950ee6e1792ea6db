//! Finding a stop in the map: the predictions in turn, a wider window around the best, every
//! heading near the last node, the whole map without a prior (the searches themselves are in
//! [`super::map_search`]).
//!
//! A match is taken only when nothing casts doubt on its shape: no runner-up, no flat cost or
//! covariance, enough of the query's points matched, the refinement converged, the optimum
//! inside the window. The one doubt a match may carry into the map is a direction the scans
//! leave free (a corridor's axis) when the odometry measured the motion along it: the position
//! there is the odometry's, and the pose-graph edge carries the odometry's uncertainty. A stop
//! found nowhere starts a new map segment ([`super::Slam::add_scan`]).

use super::map_search::{
    found, keep_best, nearest, same_nodes, EveryHeading, Located, MapSearch, Matched,
    DISTURBED_COMPASS_DEG, WIDE_MIN_INLIERS,
};
use super::predictions::{measured_along_free, Prediction};
use super::step::{Attempt, PredictionSource, StepStatus};
use super::{ms, ScanInput, Slam};
use crate::doubt::Doubt;
use crate::error::Result;
use crate::geometry::{attitude_of, pose_from_parts, wrap_pi, Attitude, Vec3};
use crate::sdem::Sdem;
use std::time::Instant;

/// Which nodes a prediction is matched against.
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
enum Nodes {
    /// The recent nodes of the segment (the local map).
    Recent,
    /// The nodes of the whole segment near the prediction that see most of the scan.
    Segment,
}

impl Slam {
    /// Finds `scan` in the map after the robot's last stop `last` (`None`: no prior at all,
    /// the start of a run in a saved map), trying the predictions against the recent nodes,
    /// the best against the whole segment, a wider window, every heading (without a compass)
    /// and the whole map in turn. Every search tried goes to `attempts`.
    pub(super) fn locate(
        &mut self,
        scan: &ScanInput,
        last: Option<usize>,
        attempts: &mut Vec<Attempt>,
    ) -> Result<Located> {
        let Some(last) = last else {
            let search = self
                .search()
                .find_in_map_or_weak(scan, |_| true, None, attempts)?;
            return Ok(match search.found {
                Some(found) => found,
                None => Located::Lost {
                    guess: pose_from_parts(Vec3::zeros(), scan.attitude.unwrap_or_default()),
                    best: None,
                    measured: false,
                    weak: search.weak.map(Box::new),
                },
            });
        };
        let segment = self.map.nodes[last].segment;
        let predictions = self.predictions(scan, last);
        let mut best: Option<(Matched, Prediction)> = None;
        for (k, prediction) in predictions.iter().enumerate() {
            // Only the first prediction's match may be taken from the quick search: another
            // one (no motion, a neighbour's place) is the best of its window only, and in a
            // corridor that is anywhere along it, so the runner-up is searched for it.
            let tried = self.try_prediction(
                scan,
                prediction,
                Nodes::Recent,
                k > 0
                    || (prediction.source == PredictionSource::NoMotion
                        && self.config.check_no_motion),
                (segment, last),
                attempts,
            )?;
            match tried {
                Some((matched, true)) => {
                    let status = if k == 0 {
                        StepStatus::Tracked
                    } else {
                        StepStatus::Recovered
                    };
                    return Ok(found(matched, status, segment));
                }
                Some((matched, false)) if prediction.measured && self.confirms(&matched) => {
                    // The scans match where the odometry says, and doubt only what a free
                    // direction makes them doubt: the measured motion stands (the step is
                    // doubtful), and no other place is searched — in a corridor another
                    // prediction's window holds a match as good anywhere along it.
                    return Ok(found(matched, StepStatus::Tracked, segment));
                }
                Some((matched, false)) => keep_best(&mut best, matched, prediction),
                None => {}
            }
        }
        // The best prediction (the first when nothing matched) against the whole segment, then
        // in the widest window.
        let base = best.as_ref().map_or(&predictions[0], |b| &b.1).clone();
        let near = self.segment_candidates(segment, &base.position);
        self.upkeep.bring(&mut self.map, &near)?;
        let recovery = &self.config.recovery;
        // With a compass, the widest heading window is what a compass disturbed by steel may
        // be off by; without one, the configured widest.
        let compass = self.compass(scan);
        let widest_heading = match compass {
            Some((_, half)) => half
                .max(DISTURBED_COMPASS_DEG)
                .min(recovery.max_heading_half_deg),
            None => recovery.max_heading_half_deg,
        };
        let mut again = vec![base.with_source(PredictionSource::OtherNodes)];
        // Around a compass the widest window is searched at the compass's own heading window
        // first, then at a disturbed compass's: the wider heading window holds the more wrong
        // basins (on the route bench's long steps without odometry, a compass of σ 2°, the
        // first wrong best of ±25° lay 15–33° from the true heading on five seeds of six).
        for window in recovery.window_stages() {
            if compass.is_some() && !base.measured && base.heading_half < widest_heading {
                again.push(base.grown(&window, base.heading_half));
            }
            again.push(base.grown(&window, widest_heading));
        }
        // Without odometry a lost stop's best match places the new segment: one whose heading
        // the compass allows before any that it does not (a compass is off by degrees, near
        // steel by up to 20°; a basin 25° off is more often a wrong one that costs less).
        let allowed = |m: &Matched| match (compass, &scan.odometry) {
            (Some((yaw, half)), None) => {
                let turn = wrap_pi(attitude_of(&m.world_from_sensor).yaw - yaw);
                turn.abs().to_degrees() <= half
            }
            _ => true,
        };
        for prediction in &again {
            // Against the same nodes the segment's search repeats the recent nodes' — unless
            // that one was the odometry's and found nothing: it asked for as many inliers as
            // tracking needs, and a long step into a new room matches fewer where the odometry
            // says (the best place to start the new segment from, when it comes to that).
            let repeats = prediction.source == PredictionSource::OtherNodes
                && !(base.measured && best.is_none())
                && {
                    let query = self.query_sdem(scan, &prediction.attitude)?;
                    same_nodes(
                        &self.reference_nodes(&query, prediction, segment, last),
                        &self.segment_references(&query, prediction, segment, last),
                    )
                };
            if repeats {
                continue;
            }
            match self.try_prediction(
                scan,
                prediction,
                Nodes::Segment,
                true,
                (segment, last),
                attempts,
            )? {
                Some((matched, true)) => return Ok(found(matched, StepStatus::Recovered, segment)),
                Some((matched, false)) => {
                    let kept = best.as_ref().map(|(b, _)| allowed(b));
                    match (kept, allowed(&matched)) {
                        (Some(true), false) => {}
                        (Some(false), true) => best = Some((matched, prediction.clone())),
                        _ => keep_best(&mut best, matched, prediction),
                    }
                }
                None => {}
            }
        }
        // Without odometry a stop that nothing matched opens its segment at a prediction, a
        // blind guess of the step. A match that shares too little to trust but has no rival
        // and converged places it better (`long-steps` seed 3: a stop 1.79 m on matches 13 %
        // of its cells at its true pose, the constant-velocity prediction 60 cm short): the
        // compass's window is searched for one with the configured floor of inliers instead
        // of the wide search's, which keeps only what could be told from its runner-up.
        if best.is_none() && scan.odometry.is_none() && compass.is_some() {
            let prediction = base.grown(&recovery.max_window_half_m, base.heading_half);
            if let Some(matched) = self.try_guess(scan, &prediction, (segment, last), attempts)? {
                best = Some((matched, prediction));
            }
        }
        if compass.is_none() {
            if let Some(matched) = self.try_every_heading(scan, segment, last, attempts)? {
                return Ok(found(matched, StepStatus::Recovered, segment));
            }
        }
        let search = self
            .search()
            .find_in_map_or_weak(scan, |_| true, None, attempts)?;
        if let Some(found) = search.found {
            return Ok(found);
        }
        // Where the new segment's first node stands is a guess. With odometry (a
        // measurement), the best match when it lies where the odometry allows (the
        // scans place a stop to millimetres in the right basin, the odometry to a few per cent
        // of the step: on the route bench's long steps every such match was within about 1 cm
        // and 0.3° of the truth, the odometry 5–27 cm), with the odometry's position along a
        // direction the scans leave free; else the odometry's pose, heading
        // included (a step's odometry turns by a fraction of a degree off, a compass near steel
        // by degrees). Without odometry: the best match's position, and its heading where the
        // compass allows it (a compass is off by degrees, a match's heading by tenths).
        let measured = predictions.iter().find(|p| p.measured);
        let guess = match (measured, &best) {
            (Some(p), Some((m, _))) if p.allows(&m.world_from_sensor) => measured_along_free(m, p),
            (Some(p), _) => p.pose(),
            (None, best) => {
                let guess = best
                    .as_ref()
                    .map_or_else(|| predictions[0].pose(), |(m, _)| m.world_from_sensor);
                match scan.attitude {
                    Some(a) => {
                        let yaw = match compass {
                            Some((yaw, _)) if !best.as_ref().is_some_and(|(m, _)| allowed(m)) => {
                                yaw
                            }
                            _ => attitude_of(&guess).yaw,
                        };
                        pose_from_parts(
                            guess.translation.vector,
                            Attitude::new(a.roll, a.pitch, yaw),
                        )
                    }
                    None => guess,
                }
            }
        };
        Ok(Located::Lost {
            guess,
            best: best.map(|b| b.0),
            measured: measured.is_some(),
            weak: search.weak.map(Box::new),
        })
    }

    /// One prediction: the reference nodes of `segment` near it (`nodes` says which), the
    /// exact search in its window, and the verdict. `None` when nothing in the window matches;
    /// else the match and whether it is taken. Without `checked` the search is the quick one
    /// (no runner-up search); with it, it looks for a runner-up, and may take a match that
    /// shares little with the map but that little with confidence. `(segment, last)`: the
    /// segment searched and the robot's last node.
    fn try_prediction(
        &self,
        scan: &ScanInput,
        prediction: &Prediction,
        nodes: Nodes,
        checked: bool,
        (segment, last): (usize, usize),
        attempts: &mut Vec<Attempt>,
    ) -> Result<Option<(Matched, bool)>> {
        let start = Instant::now();
        let query = self.query_sdem(scan, &prediction.attitude)?;
        let references = match nodes {
            Nodes::Recent => self.reference_nodes(&query, prediction, segment, last),
            Nodes::Segment => self.segment_references(&query, prediction, segment, last),
        };
        // A prediction's window against the recent nodes takes no match with fewer inliers
        // than tracking needs, runner-up searched or not (a step beyond the window matches a
        // wrong optimum inside it with a third of the points); the wide one none that could
        // not be told from its runner-up; a search of the whole segment for a partial overlap
        // keeps the configured floor, and may take a match that shares little but that little
        // with confidence.
        let partial = nodes == Nodes::Segment;
        let gate = match (partial, prediction.source) {
            (false, _) => self.config.min_tracking_inlier_fraction,
            (true, PredictionSource::WiderWindow) => WIDE_MIN_INLIERS,
            (true, _) => 0.0,
        };
        let search = self.search();
        let found = self.search_recorded(
            scan,
            prediction,
            (query, references),
            (checked, gate),
            (attempts, start),
            |matched| search.verdict(matched, prediction.measured, partial, false),
        )?;
        Ok(found.map(|(matched, reason)| (matched, reason.is_none())))
    }

    /// A place for a lost stop's segment to start from, never a match: `prediction`'s window
    /// against the nodes of `segment` that see most of the scan, with the runner-up search and
    /// only the configured floor of inliers. `Some` when the match found there doubts only how
    /// little it shares (a cheaper place whose surfaces the map saw through is no rival:
    /// [`Doubt::SeenThrough`]).
    fn try_guess(
        &self,
        scan: &ScanInput,
        prediction: &Prediction,
        (segment, last): (usize, usize),
        attempts: &mut Vec<Attempt>,
    ) -> Result<Option<Matched>> {
        let start = Instant::now();
        let query = self.query_sdem(scan, &prediction.attitude)?;
        let references = self.segment_references(&query, prediction, segment, last);
        let unique = |m: &Matched| {
            (m.doubts.iter())
                .all(|d| matches!(d, Doubt::FewInliers { .. } | Doubt::SeenThrough { .. }))
        };
        let found = self.search_recorded(
            scan,
            prediction,
            (query, references),
            (true, 0.0),
            (attempts, start),
            |matched| {
                Some(if unique(matched) {
                    "the new segment's place only: too few inliers to trust".to_string()
                } else {
                    "not even the new segment's place: doubts beyond too few inliers".to_string()
                })
            },
        )?;
        Ok(found.map(|(matched, _)| matched).filter(|m| unique(m)))
    }

    /// One search of `prediction`'s window (`query` against `references`; `(checked, gate)`
    /// as [`MapSearch::match_prediction`] takes them), recorded in `attempts` with `verdict`'s
    /// reason (`None`: taken) and the time since `start` (the query and references built).
    /// `None` when nothing in the window matches.
    fn search_recorded(
        &self,
        scan: &ScanInput,
        prediction: &Prediction,
        (query, references): (Sdem, Vec<(usize, usize)>),
        (checked, gate): (bool, f64),
        (attempts, start): (&mut Vec<Attempt>, Instant),
        verdict: impl FnOnce(&mut Matched) -> Option<String>,
    ) -> Result<Option<(Matched, Option<String>)>> {
        let mut attempt = Attempt::new(prediction, &references);
        let outcome = match (self.search())
            .match_prediction(scan, &query, prediction, references, checked, gate)
        {
            Ok(mut matched) => {
                let reason = verdict(&mut matched);
                attempt.record(&matched, reason.clone());
                Some((matched, reason))
            }
            Err(e) if e.is_no_match() => {
                attempt.reason = e.to_string();
                None
            }
            Err(e) => return Err(e),
        };
        attempt.time_ms = ms(start);
        attempts.push(attempt);
        Ok(outcome)
    }

    /// Whether a match from the odometry's prediction confirms it: as many of the scan's
    /// points match as tracking needs, and its only doubts are the ones a direction the scans
    /// leave free brings (flat cost or covariance, nothing facing that way, the refinement
    /// sliding beyond its plausible move, the optimum on the window's edge).
    fn confirms(&self, matched: &Matched) -> bool {
        matched.diagnostics.inlier_fraction >= self.config.min_tracking_inlier_fraction
            && matched.doubts.iter().all(|d| {
                matches!(
                    d,
                    Doubt::FlatCost { .. }
                        | Doubt::FlatCovariance { .. }
                        | Doubt::Unconstrained { .. }
                        | Doubt::RefinementFailed { .. }
                        | Doubt::OnWindowEdge
                        | Doubt::TakenFromPrediction { .. }
                )
            })
    }

    /// The scan's S-DEM levelled by `attitude`; [`Error::NoUsablePoints`], saying why, when no
    /// point is usable.
    fn query_sdem(&self, scan: &ScanInput, attitude: &Attitude) -> Result<Sdem> {
        Sdem::from_usable_points(scan.points_in_sensor, attitude, &self.config.sdem)
            .map_err(|e| e.of_scan(scan.scan_index))
    }

    /// The nodes to match a scan predicted by `prediction` against: the recent nodes of
    /// `segment` near the prediction that see what the scan sees there (most overlap first,
    /// at most [`super::SlamOptions::max_reference_nodes`]); the nearest of them when none
    /// does (the search then says why).
    fn reference_nodes(
        &self,
        query: &Sdem,
        prediction: &Prediction,
        segment: usize,
        last: usize,
    ) -> Vec<(usize, usize)> {
        let recent = self.recent_nodes(segment, last);
        let near: Vec<usize> = (recent.iter().copied())
            .filter(|&id| {
                let d = self.map.nodes[id].position() - prediction.position;
                d.norm() <= self.config.reference_radius_m + prediction.window_half[0]
            })
            .collect();
        self.most_overlapping(&near, &recent, query, prediction)
    }

    /// The nodes of `segment` within [`super::RecoveryOptions::other_nodes_radius_m`] of the
    /// prediction that see most of what the scan sees there.
    fn segment_references(
        &self,
        query: &Sdem,
        prediction: &Prediction,
        segment: usize,
        last: usize,
    ) -> Vec<(usize, usize)> {
        let near = self.segment_candidates(segment, &prediction.position);
        // Counted with the window's tolerance: the prediction may be that far off.
        let tolerance = 0.2 + prediction.window_half[0].max(prediction.window_half[1]);
        let references: Vec<(usize, usize)> = (self.map)
            .overlaps_among(
                near.iter().copied(),
                query,
                &prediction.position,
                f64::INFINITY,
                tolerance,
            )
            .into_iter()
            .filter(|&(_, cells)| cells >= self.config.min_reference_overlap_cells)
            .take(2 * self.config.max_reference_nodes)
            .collect();
        if references.is_empty() {
            return self.most_overlapping(
                &near,
                &self.recent_nodes(segment, last),
                query,
                prediction,
            );
        }
        references
    }

    /// The nodes of `segment` within [`super::RecoveryOptions::other_nodes_radius_m`] of
    /// `position`, at most [`super::GrowthOptions::recovery_candidate_nodes`], the nearest.
    fn segment_candidates(&self, segment: usize, position: &Vec3) -> Vec<usize> {
        let radius = self.config.recovery.other_nodes_radius_m;
        let limit = self.config.growth.recovery_candidate_nodes;
        self.candidates_near((segment, position), radius, limit, |_| true)
    }

    /// Of `candidates`, the nodes whose points explain at least
    /// [`super::SlamOptions::min_reference_overlap_cells`] of the query's cells at the
    /// prediction, most first, at most [`super::SlamOptions::max_reference_nodes`]; else the
    /// nodes of `fallback` nearest the prediction.
    fn most_overlapping(
        &self,
        candidates: &[usize],
        fallback: &[usize],
        query: &Sdem,
        prediction: &Prediction,
    ) -> Vec<(usize, usize)> {
        let references: Vec<(usize, usize)> = (self.map)
            .overlaps_among(
                candidates.iter().copied(),
                query,
                &prediction.position,
                f64::INFINITY,
                0.2,
            )
            .into_iter()
            .filter(|&(_, cells)| cells >= self.config.min_reference_overlap_cells)
            .take(self.config.max_reference_nodes)
            .collect();
        if !references.is_empty() {
            return references;
        }
        nearest(
            &self.map,
            fallback,
            &prediction.position,
            self.config.max_reference_nodes,
        )
        .into_iter()
        .map(|id| (id, 0))
        .collect()
    }

    /// The last [`crate::map::LoopClosureConfig::min_node_separation`] nodes of `segment` up
    /// to `last` (the local map; older ones are loop closure's), `last` always among them.
    pub(super) fn recent_nodes(&self, segment: usize, last: usize) -> Vec<usize> {
        let count = self.config.loop_closure.min_node_separation.max(1);
        let mut recent: Vec<usize> = (0..=last)
            .rev()
            .filter(|&id| self.map.nodes[id].segment == segment)
            .take(count)
            .collect();
        if !recent.contains(&last) {
            recent.push(last);
        }
        recent
    }

    /// Every heading (and the tilt, without an attitude reading) near the last node: the
    /// scan against the nodes of `segment` nearest `last`, in the widest window around it.
    fn try_every_heading(
        &self,
        scan: &ScanInput,
        segment: usize,
        last: usize,
        attempts: &mut Vec<Attempt>,
    ) -> Result<Option<Matched>> {
        let recovery = &self.config.recovery;
        let centre = self.map.nodes[last].position();
        let recent = self.recent_nodes(segment, last);
        let nodes = nearest(&self.map, &recent, &centre, recovery.every_heading_nodes);
        let place = EveryHeading {
            nodes: &nodes,
            centre,
            half: recovery.max_window_half_m,
            min_inlier_fraction: 0.0,
            rival_of: None,
        };
        let found = self.search().search_every_heading(
            scan,
            &place,
            PredictionSource::EveryHeading,
            attempts,
        )?;
        Ok(found.filter(|(_, taken)| *taken).map(|(m, _)| m))
    }

    /// The map and options a search without a prediction needs.
    pub(super) fn search(&self) -> MapSearch<'_> {
        MapSearch {
            map: &self.map,
            config: &self.config,
            full_turn: false,
        }
    }
}

impl Attempt {
    /// A search of `prediction` against `references`, not run yet.
    pub(super) fn new(prediction: &Prediction, references: &[(usize, usize)]) -> Self {
        Self {
            source: prediction.source,
            nodes: references.iter().map(|r| r.0).collect(),
            window_half_m: prediction.window_half,
            heading_half_deg: prediction.heading_half,
            descriptor_distance: None,
            cost: None,
            inlier_fraction: None,
            doubts: Vec::new(),
            accepted: false,
            reason: String::new(),
            time_ms: 0.0,
        }
    }

    /// Records what the search found and the verdict (`None`: taken).
    pub(super) fn record(&mut self, matched: &Matched, reason: Option<String>) {
        self.cost = Some(matched.cost);
        self.inlier_fraction = Some(matched.diagnostics.inlier_fraction);
        self.doubts = matched.doubts.clone();
        self.accepted = reason.is_none();
        self.reason = reason.unwrap_or_default();
    }
}
