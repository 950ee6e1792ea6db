//! The drivable route through the collapsed building: lines and arcs with where stops go.

use super::wrap_angle;
use std::f64::consts::TAU;

/// Height of the sensor above the flat room floor at the first stop of
/// [`collapsed_building`](super::collapsed_building), metres: the room floor lies at
/// `z = -COLLAPSED_BUILDING_START_HEIGHT_M`.
pub const COLLAPSED_BUILDING_START_HEIGHT_M: f64 = 0.40;

/// Where the room's front wall and the ditch's mouth are, x in metres.
pub(super) const MOUTH_X_M: f64 = 1.0;

/// The most stops [`collapsed_building_stops`](super::collapsed_building_stops) can place along
/// its route.
pub const MAX_STOPS: usize = 40;

/// Turning radius of every bend of the route, metres.
pub(super) const TURN_RADIUS_M: f64 = 1.1;
/// Stops on the loop in the void; the spacing is the loop's length over this.
const LOOP_STEPS: usize = 20;
/// Shortest stretch from the void's entry to the start of the loop, metres.
const MIN_STEM_M: f64 = 1.6;

/// One piece of the route: a straight line or a circular arc (positive angle turns left).
#[derive(Debug, Clone, Copy, PartialEq)]
pub(super) enum Segment {
    Line(f64),
    Arc { radius: f64, angle: f64 },
}

impl Segment {
    pub(super) fn length(&self) -> f64 {
        match *self {
            Segment::Line(l) => l,
            Segment::Arc { radius, angle } => radius * angle.abs(),
        }
    }
}

/// The drivable centre line of the collapsed building for the sensor origin, starting at the
/// world origin heading +x, with where stops go.
#[derive(Debug, Clone, PartialEq)]
pub(super) struct Route {
    segments: Vec<Segment>,
    /// Distance along the route between stops, metres.
    pub(super) spacing_m: f64,
    /// Arc-length range of the ditch, where the lift is lowered.
    low_lift: (f64, f64),
    /// Stops placed exactly (no jitter): the loop's start and its return to the same place.
    pub(super) anchors: [usize; 2],
}

impl Route {
    pub(super) fn length(&self) -> f64 {
        self.segments.iter().map(Segment::length).sum()
    }

    /// Position (x, y) and heading at arc length `s`; before the start and past the end the
    /// first and last segments are extended.
    pub(super) fn at(&self, s: f64) -> ([f64; 2], f64) {
        pose_along(&self.segments, s)
    }

    pub(super) fn lift_is_low(&self, s: f64) -> bool {
        (self.low_lift.0..=self.low_lift.1).contains(&s)
    }
}

/// Position (x, y) and heading at arc length `s` along `segments`, which start at the origin
/// heading +x; before the start and past the end the first and last segments are extended.
pub(super) fn pose_along(segments: &[Segment], s: f64) -> ([f64; 2], f64) {
    let (mut x, mut y, mut yaw) = (0.0f64, 0.0f64, 0.0f64);
    let mut rest = s;
    let n = segments.len();
    for (i, seg) in segments.iter().enumerate() {
        let len = seg.length();
        let ends_here = rest <= len || i + 1 == n;
        let step = if ends_here { rest } else { len };
        match *seg {
            Segment::Line(_) => {
                x += step * yaw.cos();
                y += step * yaw.sin();
            }
            Segment::Arc { radius, angle } => {
                let sign = angle.signum();
                let (cx, cy) = (x - sign * radius * yaw.sin(), y + sign * radius * yaw.cos());
                yaw += sign * step / radius;
                x = cx + sign * radius * yaw.sin();
                y = cy - sign * radius * yaw.cos();
            }
        }
        if ends_here {
            break;
        }
        rest -= len;
    }
    ([x, y], wrap_angle(yaw))
}

/// The route for a ditch with legs `leg1`, `leg2` and a `bend` between them: along the legs
/// with an arc at the bend, into the void, one full loop to the left that comes back to where
/// it began, then straight on. Returns the route and where the loop starts on the void's axis.
pub(super) fn plan_route(leg1: f64, leg2: f64, bend: f64) -> (Route, f64) {
    let r = TURN_RADIUS_M;
    let tangent = r * (0.5 * bend.abs()).tan();
    let line1 = MOUTH_X_M + leg1 - tangent;
    let bend_arc = Segment::Arc {
        radius: r,
        angle: bend,
    };
    let exit = line1 + bend_arc.length() + (leg2 - tangent);
    let spacing = TAU * r / LOOP_STEPS as f64;
    // The loop starts on a stop, so that the stop LOOP_STEPS later is at the same place.
    let loop_stop = ((exit + MIN_STEM_M) / spacing).ceil() as usize;
    let loop_start = loop_stop as f64 * spacing;
    let loop_start_x = loop_start - exit;
    let loop_end = loop_start + TAU * r;
    // Room for MAX_STOPS stops (and their jitter) in all.
    let tail = ((MAX_STOPS - 1) as f64 * spacing + 0.2 - loop_end).max(0.2);
    let route = Route {
        segments: vec![
            Segment::Line(line1),
            bend_arc,
            Segment::Line(leg2 - tangent + loop_start_x),
            Segment::Arc {
                radius: r,
                angle: TAU,
            },
            Segment::Line(tail),
        ],
        spacing_m: spacing,
        low_lift: (MOUTH_X_M, exit),
        anchors: [loop_stop, loop_stop + LOOP_STEPS],
    };
    (route, loop_start_x)
}
