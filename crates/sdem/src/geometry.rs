//! Poses, attitudes and spherical coordinates.
//!
//! Conventions (DESIGN.md): metres and radians, right-handed frames with x forward, y left, z up.
//! A pose is always named after the two frames it relates, `a_from_b`, so that
//! `point_in_a = a_from_b * point_in_b`. Attitude is roll, pitch, yaw with
//! `R = Rz(yaw) · Ry(pitch) · Rx(roll)`.

use nalgebra::{Isometry3, Point3, Rotation3, Translation3, UnitQuaternion, Vector3};
use serde::{Deserialize, Serialize};
use std::borrow::Cow;

/// A 3D vector in metres, in whatever frame its name says.
pub type Vec3 = Vector3<f64>;

/// A rigid transform `a_from_b`.
pub type Pose = Isometry3<f64>;

/// A point in metres as a caller holds one. The functions a robot's program calls with a scan's
/// returns take them as any of these: [`crate::Scan::from_points`], [`crate::Slam::add`],
/// [`crate::slam::relocalize`] (and `sdem_io::SavedMap::relocalize`),
/// [`crate::SdemConfig::for_scan`], [`crate::SlamOptions::for_scan`] and
/// [`crate::sdem::Sdem::from_points`]. So points read from a file (`sdem_io::read_points` gives
/// [`Vec3`]), built with nalgebra's `Point3`, or held as arrays (`[f32; 3]`, as a LiDAR driver
/// gives them) need no conversion first. The lower-level parts (`ScanInput`, `Node::from_scan`,
/// the voxel map) take [`Vec3`].
///
/// ```
/// use nalgebra::Point3;
/// use sdem::geometry::{AsPoint, Vec3};
/// assert_eq!(Point3::new(1.0, 2.0, 3.0).to_vec3(), Vec3::new(1.0, 2.0, 3.0));
/// assert_eq!([1.0f32, 2.0, 3.0].to_vec3(), Vec3::new(1.0, 2.0, 3.0));
/// ```
pub trait AsPoint: Copy + Send + Sync {
    /// The point's coordinates, metres.
    fn to_vec3(&self) -> Vec3;

    /// A slice of points as [`Vec3`]s: borrowed when they are [`Vec3`]s already.
    fn as_vec3s(points: &[Self]) -> Cow<'_, [Vec3]> {
        Cow::Owned(points.iter().map(Self::to_vec3).collect())
    }
}

impl AsPoint for Vec3 {
    fn to_vec3(&self) -> Vec3 {
        *self
    }

    fn as_vec3s(points: &[Self]) -> Cow<'_, [Vec3]> {
        Cow::Borrowed(points)
    }
}

impl AsPoint for Point3<f64> {
    fn to_vec3(&self) -> Vec3 {
        self.coords
    }
}

impl AsPoint for Vector3<f32> {
    fn to_vec3(&self) -> Vec3 {
        self.cast()
    }
}

impl AsPoint for Point3<f32> {
    fn to_vec3(&self) -> Vec3 {
        self.coords.cast()
    }
}

impl AsPoint for [f64; 3] {
    fn to_vec3(&self) -> Vec3 {
        Vec3::from(*self)
    }
}

impl AsPoint for [f32; 3] {
    fn to_vec3(&self) -> Vec3 {
        Vector3::from(*self).cast()
    }
}

/// The attitude of a body relative to the gravity-aligned world axes, in radians, as a
/// measurement: the angles and how far a reading of them can be off ([`AttitudeSigma`]).
///
/// `R = Rz(yaw) · Ry(pitch) · Rx(roll)`: roll about x, then pitch about y, then yaw about z, all
/// about the fixed world axes.
#[derive(Debug, Clone, Copy, PartialEq, Default, Serialize, Deserialize)]
pub struct Attitude {
    /// Rotation about x, radians.
    pub roll: f64,
    /// Rotation about y, radians.
    pub pitch: f64,
    /// Rotation about z (compass heading, counter-clockwise from +x), radians.
    pub yaw: f64,
    /// The reading's standard deviations (not stored in files: a reading read back takes the
    /// defaults).
    #[serde(skip)]
    pub sigma: AttitudeSigma,
}

/// How far an attitude reading can be off: standard deviations, radians.
///
/// The defaults: 0.5° for roll and pitch (a gyro levelled by gravity) and 3.5° for the heading
/// (a compass near steel; two readings at 3σ then differ by up to ±15°).
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct AttitudeSigma {
    /// σ of roll and of pitch, radians.
    pub roll_pitch: f64,
    /// σ of the heading (yaw), radians.
    pub yaw: f64,
}

impl Default for AttitudeSigma {
    fn default() -> Self {
        Self {
            roll_pitch: 0.5f64.to_radians(),
            yaw: 3.5f64.to_radians(),
        }
    }
}

impl Attitude {
    /// An attitude from angles in radians.
    pub fn new(roll: f64, pitch: f64, yaw: f64) -> Self {
        Self {
            roll,
            pitch,
            yaw,
            sigma: AttitudeSigma::default(),
        }
    }

    /// The same reading with its standard deviations, degrees: `roll_pitch_deg` for roll and for
    /// pitch, `yaw_deg` for the heading.
    ///
    /// # Example
    /// ```
    /// use sdem::Attitude;
    /// // A gyro good to 0.2°, a compass near steel good to 20° only.
    /// let reading = Attitude::from_degrees(1.0, -2.0, 90.0).with_sigma_deg(0.2, 20.0);
    /// assert!((reading.sigma.yaw.to_degrees() - 20.0).abs() < 1e-12);
    /// ```
    pub fn with_sigma_deg(self, roll_pitch_deg: f64, yaw_deg: f64) -> Self {
        Self {
            sigma: AttitudeSigma {
                roll_pitch: roll_pitch_deg.to_radians(),
                yaw: yaw_deg.to_radians(),
            },
            ..self
        }
    }

    /// An attitude from angles in degrees.
    ///
    /// # Example
    /// ```
    /// let a = sdem::geometry::Attitude::from_degrees(0.0, 8.0, 90.0);
    /// assert!((a.pitch.to_degrees() - 8.0).abs() < 1e-12);
    /// ```
    pub fn from_degrees(roll_deg: f64, pitch_deg: f64, yaw_deg: f64) -> Self {
        Self::new(
            roll_deg.to_radians(),
            pitch_deg.to_radians(),
            yaw_deg.to_radians(),
        )
    }

    /// The angles in degrees, as `[roll, pitch, yaw]`.
    pub fn to_degrees(&self) -> [f64; 3] {
        [
            self.roll.to_degrees(),
            self.pitch.to_degrees(),
            self.yaw.to_degrees(),
        ]
    }

    /// The rotation `world_from_body` (without translation).
    pub fn rotation(&self) -> Rotation3<f64> {
        // nalgebra's from_euler_angles(r, p, y) is Rz(y) * Ry(p) * Rx(r).
        Rotation3::from_euler_angles(self.roll, self.pitch, self.yaw)
    }

    /// The attitude of a rotation `world_from_body`.
    pub fn from_rotation(rotation: &Rotation3<f64>) -> Self {
        let (roll, pitch, yaw) = rotation.euler_angles();
        Self::new(roll, pitch, yaw)
    }

    /// The attitude of a unit quaternion `world_from_body`.
    pub fn from_quaternion(q: &UnitQuaternion<f64>) -> Self {
        Self::from_rotation(&q.to_rotation_matrix())
    }

    /// True when all three angles are finite numbers.
    pub fn is_finite(&self) -> bool {
        self.roll.is_finite() && self.pitch.is_finite() && self.yaw.is_finite()
    }

    /// Whether the standard deviations are positive numbers.
    pub fn sigma_is_valid(&self) -> bool {
        [self.sigma.roll_pitch, self.sigma.yaw]
            .iter()
            .all(|s| s.is_finite() && *s > 0.0)
    }
}

/// A pose from a translation and an attitude.
pub fn pose_from_parts(translation: Vec3, attitude: Attitude) -> Pose {
    Isometry3::from_parts(
        Translation3::from(translation),
        UnitQuaternion::from_rotation_matrix(&attitude.rotation()),
    )
}

/// The attitude (roll, pitch, yaw) of a pose's rotation.
pub fn attitude_of(pose: &Pose) -> Attitude {
    Attitude::from_quaternion(&pose.rotation)
}

/// A pose as people and JSON read it: metres and degrees.
///
/// This is the `{"x","y","z","roll_deg","pitch_deg","yaw_deg"}` object of DESIGN.md.
#[derive(Debug, Clone, Copy, PartialEq, Serialize, Deserialize)]
pub struct PoseRecord {
    /// Translation x, metres.
    pub x: f64,
    /// Translation y, metres.
    pub y: f64,
    /// Translation z, metres.
    pub z: f64,
    /// Roll, degrees.
    pub roll_deg: f64,
    /// Pitch, degrees.
    pub pitch_deg: f64,
    /// Yaw, degrees.
    pub yaw_deg: f64,
}

impl From<&Pose> for PoseRecord {
    fn from(pose: &Pose) -> Self {
        let t = pose.translation.vector;
        let [roll_deg, pitch_deg, yaw_deg] = attitude_of(pose).to_degrees();
        Self {
            x: t.x,
            y: t.y,
            z: t.z,
            roll_deg,
            pitch_deg,
            yaw_deg,
        }
    }
}

impl From<&PoseRecord> for Pose {
    fn from(r: &PoseRecord) -> Self {
        pose_from_parts(
            Vec3::new(r.x, r.y, r.z),
            Attitude::from_degrees(r.roll_deg, r.pitch_deg, r.yaw_deg),
        )
    }
}

/// The translation error (metres) and rotation error (radians) of `estimate` against `truth`.
pub fn pose_error(truth: &Pose, estimate: &Pose) -> (f64, f64) {
    let delta = truth.inverse() * estimate;
    (delta.translation.vector.norm(), delta.rotation.angle())
}

/// The angle `a` (radians) wrapped into [−π, π).
pub fn wrap_pi(a: f64) -> f64 {
    (a + std::f64::consts::PI).rem_euclid(std::f64::consts::TAU) - std::f64::consts::PI
}

/// The unit direction of an azimuth (counter-clockwise from +x) and an elevation (up from the
/// horizontal plane), both radians.
pub fn direction(azimuth: f64, elevation: f64) -> Vec3 {
    let (se, ce) = elevation.sin_cos();
    let (sa, ca) = azimuth.sin_cos();
    Vec3::new(ce * ca, ce * sa, se)
}

/// Azimuth in [-π, π), elevation in [-π/2, π/2] and range of a point; `None` at the origin.
pub fn spherical(point: &Vec3) -> Option<(f64, f64, f64)> {
    let range = point.norm();
    if range <= 0.0 || !range.is_finite() {
        return None;
    }
    let mut azimuth = point.y.atan2(point.x);
    if azimuth >= std::f64::consts::PI {
        azimuth -= 2.0 * std::f64::consts::PI;
    }
    let elevation = (point.z / range).clamp(-1.0, 1.0).asin();
    Some((azimuth, elevation, range))
}

/// Largest error of [`fast_atan2`] against the exact `atan2`, radians (measured over the circle;
/// the bound used by searches that must stay exact is this with a margin).
pub const FAST_ATAN2_MAX_ERROR: f32 = 1e-5;

/// `x.floor() as i64`, without the library call `floor` becomes on CPUs without SSE4.1 (it is
/// on the hot path of every cell lookup). Equal to it for every `f32`, NaN included (0).
#[inline]
pub fn floor_i64(x: f32) -> i64 {
    let i = x as i64;
    if (i as f32) > x {
        i.saturating_sub(1)
    } else {
        i
    }
}

/// `atan2(y, x)` in single precision from a degree-11 minimax polynomial: 2e-6 rad at most from
/// the exact value, and several times faster than the library call. Every S-DEM binning goes
/// through it, so all searches see one and the same grid.
// Selects instead of branches, so loops over many points vectorize.
#[inline(always)]
pub fn fast_atan2(y: f32, x: f32) -> f32 {
    let (ax, ay) = (x.abs(), y.abs());
    let big = ax.max(ay);
    // 0 at the origin; 0/0 would give NaN.
    let a = if big == 0.0 { 0.0 } else { ax.min(ay) / big };
    let s = a * a;
    let r = a
        * (0.999_977_26
            + s * (-0.332_623_47
                + s * (0.193_543_46
                    + s * (-0.116_432_87 + s * (0.052_653_32 + s * -0.011_721_2)))));
    let r = if ay > ax {
        std::f32::consts::FRAC_PI_2 - r
    } else {
        r
    };
    let r = if x < 0.0 { std::f32::consts::PI - r } else { r };
    if y < 0.0 {
        -r
    } else {
        r
    }
}

#[cfg(test)]
mod tests {
    #[test]
    fn floor_i64_equals_the_library_floor() {
        let special = [
            0.0f32,
            -0.0,
            0.5,
            -0.5,
            1.0,
            -1.0,
            -1e-30,
            8_388_607.5,
            -8_388_609.0,
            3e20,
            -3e20,
        ];
        for x in special {
            assert_eq!(super::floor_i64(x), x.floor() as i64, "{x}");
        }
        assert_eq!(super::floor_i64(f32::NAN), 0);
        let mut x = -1000.0f32;
        while x < 1000.0 {
            assert_eq!(super::floor_i64(x), x.floor() as i64, "{x}");
            x += 0.013_7;
        }
    }

    #[test]
    fn fast_atan2_is_within_its_bound() {
        let mut worst = 0f64;
        for i in 0..200_000 {
            let t = i as f64 / 200_000.0 * std::f64::consts::TAU - std::f64::consts::PI;
            for radius in [0.05, 1.0, 9.0] {
                let (y, x) = ((t.sin() * radius) as f32, (t.cos() * radius) as f32);
                let e = (super::fast_atan2(y, x) as f64 - (y as f64).atan2(x as f64)).abs();
                worst = worst.max(e);
            }
        }
        assert!(
            worst < super::FAST_ATAN2_MAX_ERROR as f64 / 2.0,
            "worst {worst}"
        );
        assert_eq!(super::fast_atan2(0.0, 0.0), 0.0);
    }

    use super::*;
    use approx::assert_relative_eq;

    #[test]
    fn attitude_is_zyx() {
        let a = Attitude::from_degrees(10.0, -20.0, 30.0);
        let expected = Rotation3::from_axis_angle(&Vector3::z_axis(), a.yaw)
            * Rotation3::from_axis_angle(&Vector3::y_axis(), a.pitch)
            * Rotation3::from_axis_angle(&Vector3::x_axis(), a.roll);
        assert_relative_eq!(a.rotation(), expected, epsilon = 1e-12);
        let back = Attitude::from_rotation(&a.rotation());
        assert_relative_eq!(back.roll, a.roll, epsilon = 1e-12);
        assert_relative_eq!(back.pitch, a.pitch, epsilon = 1e-12);
        assert_relative_eq!(back.yaw, a.yaw, epsilon = 1e-12);
    }

    #[test]
    fn positive_pitch_points_x_down() {
        // Rotating +x about +y by a positive angle moves it towards -z (right-hand rule).
        let r = Attitude::from_degrees(0.0, 10.0, 0.0).rotation();
        assert!((r * Vec3::x()).z < 0.0);
    }

    #[test]
    fn spherical_round_trip() {
        for &(az, el) in &[(0.3, 0.2), (-3.0, -1.2), (2.0, 1.5), (-0.1, 0.0)] {
            let p = direction(az, el) * 2.5;
            let (a, e, r) = spherical(&p).unwrap();
            assert_relative_eq!(a, az, epsilon = 1e-12);
            assert_relative_eq!(e, el, epsilon = 1e-12);
            assert_relative_eq!(r, 2.5, epsilon = 1e-12);
        }
        assert!(spherical(&Vec3::zeros()).is_none());
    }

    #[test]
    fn pose_record_round_trip() {
        let pose = pose_from_parts(
            Vec3::new(0.22, 0.36, 0.05),
            Attitude::from_degrees(1.0, 8.0, -30.0),
        );
        let record = PoseRecord::from(&pose);
        let back = Pose::from(&record);
        let (dt, dr) = pose_error(&pose, &back);
        assert!(dt < 1e-12 && dr < 1e-9);
        assert_relative_eq!(record.pitch_deg, 8.0, epsilon = 1e-9);
    }
}
