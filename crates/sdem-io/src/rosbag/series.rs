//! Stamped series (poses, orientations, joint angles) and their value at any stamp inside
//! their span: linear in translation and angle, spherical-linear (slerp) in rotation.

use sdem::geometry::Pose;

/// Why a series has no value at a stamp.
#[derive(Debug, Clone, PartialEq)]
pub enum OutOfSpan {
    /// The series holds nothing.
    Empty,
    /// The stamp lies this many seconds before the first sample.
    Before {
        /// Seconds before the first sample.
        seconds: f64,
    },
    /// The stamp lies this many seconds after the last sample.
    After {
        /// Seconds after the last sample.
        seconds: f64,
    },
    /// The samples around the stamp lie this many seconds apart: a dropout.
    Gap {
        /// Seconds between the two samples around the stamp.
        seconds: f64,
    },
}

impl std::fmt::Display for OutOfSpan {
    fn fmt(&self, f: &mut std::fmt::Formatter<'_>) -> std::fmt::Result {
        match self {
            OutOfSpan::Empty => write!(f, "it holds no message"),
            OutOfSpan::Before { seconds } => {
                write!(f, "its first message comes {seconds:.3} s after this stamp")
            }
            OutOfSpan::After { seconds } => {
                write!(f, "its last message comes {seconds:.3} s before this stamp")
            }
            OutOfSpan::Gap { seconds } => {
                write!(
                    f,
                    "its messages around this stamp lie {seconds:.3} s apart (a dropout)"
                )
            }
        }
    }
}

/// Samples sorted by stamp (nanoseconds), with how far a stamp may lie from them.
#[derive(Debug, Clone)]
pub struct Series<T> {
    stamps: Vec<i64>,
    values: Vec<T>,
    /// The longest interval, nanoseconds, across which values are interpolated, and how far
    /// beyond either end the end value is held.
    tolerance_ns: i64,
}

/// The least tolerance, seconds: a value is held this far beyond the ends and interpolated
/// across gaps this long whatever the rate.
const MIN_TOLERANCE_S: f64 = 0.25;
/// The tolerance in sampling intervals (the median one) when that is longer.
const TOLERANCE_INTERVALS: f64 = 5.0;

impl<T: Clone> Series<T> {
    /// A series from unsorted samples; of samples with the same stamp the last is kept. The
    /// tolerance is the longer of 0.25 s and five median sampling intervals.
    pub fn new(mut samples: Vec<(i64, T)>) -> Self {
        samples.sort_by_key(|(t, _)| *t);
        let mut stamps: Vec<i64> = Vec::with_capacity(samples.len());
        let mut values: Vec<T> = Vec::with_capacity(samples.len());
        for (t, v) in samples {
            if stamps.last() == Some(&t) {
                *values.last_mut().expect("a stamp has its value") = v;
            } else {
                stamps.push(t);
                values.push(v);
            }
        }
        let mut intervals: Vec<i64> = stamps.windows(2).map(|w| w[1] - w[0]).collect();
        intervals.sort_unstable();
        let median = intervals.get(intervals.len() / 2).copied().unwrap_or(0) as f64;
        let tolerance_ns = (MIN_TOLERANCE_S * 1e9).max(TOLERANCE_INTERVALS * median) as i64;
        Self {
            stamps,
            values,
            tolerance_ns,
        }
    }

    /// The first and last stamps.
    pub fn span(&self) -> Option<(i64, i64)> {
        Some((*self.stamps.first()?, *self.stamps.last()?))
    }

    /// The value at `stamp`: `blend(a, b, f)` between the samples around it, or the end value
    /// within the tolerance beyond an end.
    ///
    /// # Errors
    /// [`OutOfSpan`] beyond the tolerance, or across a gap longer than it.
    pub fn at(&self, stamp: i64, blend: impl Fn(&T, &T, f64) -> T) -> Result<T, OutOfSpan> {
        let (first, last) = self.span().ok_or(OutOfSpan::Empty)?;
        let seconds = |ns: i64| ns as f64 * 1e-9;
        if stamp <= first {
            return if first - stamp <= self.tolerance_ns {
                Ok(self.values[0].clone())
            } else {
                Err(OutOfSpan::Before {
                    seconds: seconds(first - stamp),
                })
            };
        }
        if stamp >= last {
            return if stamp - last <= self.tolerance_ns {
                Ok(self.values[self.values.len() - 1].clone())
            } else {
                Err(OutOfSpan::After {
                    seconds: seconds(stamp - last),
                })
            };
        }
        let after = self.stamps.partition_point(|&t| t <= stamp);
        let (t0, t1) = (self.stamps[after - 1], self.stamps[after]);
        if t0 == stamp {
            return Ok(self.values[after - 1].clone());
        }
        if t1 - t0 > self.tolerance_ns {
            return Err(OutOfSpan::Gap {
                seconds: seconds(t1 - t0),
            });
        }
        let f = (stamp - t0) as f64 / (t1 - t0) as f64;
        Ok(blend(&self.values[after - 1], &self.values[after], f))
    }
}

/// Interpolates two poses: translation linearly, rotation by slerp.
pub fn blend_pose(a: &Pose, b: &Pose, f: f64) -> Pose {
    let translation = a.translation.vector.lerp(&b.translation.vector, f);
    let rotation = a
        .rotation
        .try_slerp(&b.rotation, f, 1e-12)
        .unwrap_or(if f < 0.5 { a.rotation } else { b.rotation });
    Pose::from_parts(translation.into(), rotation)
}

/// Interpolates two numbers linearly.
pub fn blend_f64(a: &f64, b: &f64, f: f64) -> f64 {
    a + (b - a) * f
}

#[cfg(test)]
mod tests {
    use super::*;
    use nalgebra::{UnitQuaternion, Vector3};

    const S: i64 = 1_000_000_000;

    #[test]
    fn poses_interpolate_by_slerp_and_hold_within_the_tolerance() {
        let a = Pose::identity();
        let b = Pose::from_parts(
            Vector3::new(2.0, 0.0, 0.0).into(),
            UnitQuaternion::from_euler_angles(0.0, 0.0, 1.0),
        );
        let s = Series::new(vec![(2 * S / 10, b), (0, a)]);
        let mid = s.at(S / 10, blend_pose).unwrap();
        assert!((mid.translation.vector.x - 1.0).abs() < 1e-12);
        assert!((mid.rotation.euler_angles().2 - 0.5).abs() < 1e-12);
        assert_eq!(s.at(-S / 10, blend_pose).unwrap(), a);
        assert!(matches!(
            s.at(-2 * S, blend_pose),
            Err(OutOfSpan::Before { seconds }) if (seconds - 2.0).abs() < 1e-9
        ));
        assert!(matches!(
            s.at(2 * S, blend_pose),
            Err(OutOfSpan::After { .. })
        ));
    }

    #[test]
    fn a_dropout_longer_than_the_tolerance_is_refused() {
        let samples: Vec<(i64, f64)> = (0..10)
            .map(|i| (i * S / 50, i as f64))
            .chain([(3 * S, 99.0)])
            .collect();
        let s = Series::new(samples);
        assert!((s.at(S / 100, blend_f64).unwrap() - 0.5).abs() < 1e-12);
        assert!(matches!(s.at(2 * S, blend_f64), Err(OutOfSpan::Gap { .. })));
        assert!(matches!(
            Series::<f64>::new(vec![]).at(0, blend_f64),
            Err(OutOfSpan::Empty)
        ));
    }
}
