//! The sensor unit of Nagatani et al. (2003), Sec. IV: a 2D laser range finder (LRF) whose scan
//! plane is tilted about the sensor's lateral axis, a slide mechanism that lifts it, and a
//! gyro/compass that reads roll, pitch and yaw.
//!
//! Frames. The *sensor frame* has its origin at the LRF's optical centre, which lies on the tilt
//! axis; x forward, y left, z up when the unit stands level. A beam at pan angle `φ` (in the scan
//! plane, counter-clockwise from forward) with the plane tilted up by `θ` points along
//! `(cos θ cos φ, sin φ, sin θ cos φ)`. The lift moves the sensor frame relative to the robot's
//! body frame (`body_from_sensor`), never the points inside it.

use crate::error::{Error, Result};
use crate::geometry::{Attitude, Pose, Vec3};
use nalgebra::{Isometry3, Translation3, UnitQuaternion};
use serde::{Deserialize, Serialize};

/// The sensor model: angular sweep, range limits, noise and the lift. Written as `sensor.toml`
/// beside each dataset.
#[derive(Debug, Clone, PartialEq, Serialize, Deserialize)]
#[serde(default, deny_unknown_fields)]
pub struct SensorConfig {
    /// Lowest tilt of the scan plane, degrees (paper: −45).
    pub tilt_min_deg: f64,
    /// Highest tilt of the scan plane, degrees (paper: 40).
    pub tilt_max_deg: f64,
    /// Tilt step between scan lines, degrees (paper: 1).
    pub tilt_step_deg: f64,
    /// First pan angle in each line, degrees (paper: −90).
    pub pan_min_deg: f64,
    /// Last pan angle in each line, degrees (paper: 90).
    pub pan_max_deg: f64,
    /// Pan step between beams, degrees (paper: 1).
    pub pan_step_deg: f64,
    /// Largest range the LRF returns, metres (SICK: 8).
    pub max_range_m: f64,
    /// Returns closer than this are dropped (the robot itself), metres.
    pub min_range_m: f64,
    /// Returns beyond this are dropped when set (paper: trusted up to 3 m), metres.
    pub trusted_range_m: Option<f64>,
    /// Standard deviation of the Gaussian range noise, metres (SICK: 5 mm).
    pub range_noise_m: f64,
    /// Standard deviation of the gyro's roll and pitch reading, degrees.
    pub tilt_sensor_noise_deg: f64,
    /// Standard deviation of the compass heading reading, degrees.
    pub compass_noise_deg: f64,
    /// The slide mechanism that lifts the LRF.
    pub lift: LiftConfig,
}

impl Default for SensorConfig {
    fn default() -> Self {
        Self {
            tilt_min_deg: -45.0,
            tilt_max_deg: 40.0,
            tilt_step_deg: 1.0,
            pan_min_deg: -90.0,
            pan_max_deg: 90.0,
            pan_step_deg: 1.0,
            max_range_m: 8.0,
            min_range_m: 0.05,
            trusted_range_m: None,
            range_noise_m: 0.005,
            tilt_sensor_noise_deg: 0.05,
            compass_noise_deg: 0.1,
            lift: LiftConfig::default(),
        }
    }
}

/// Number of samples from `min` to `max` inclusive at `step` (all in the same unit).
fn sample_count(min: f64, max: f64, step: f64) -> usize {
    ((max - min) / step + 1e-9).floor() as usize + 1
}

impl SensorConfig {
    /// The S-DEM resolution that matches this scanner: its coarser angular step (tilt or pan),
    /// shrunk so that a whole number of cells makes a full turn. A cell then holds about one
    /// return. Coarser cells keep only the nearest of several returns and thin the scan out;
    /// on the 3DTK scans (0.5° beams, 0.517° lines) 1° cells left the match 3.1° in pitch from
    /// slam6D on scan 1, 0.5165° cells 0.18°. Never finer than 0.1°, the finest grid an S-DEM
    /// of a full sphere may have ([`crate::sdem::MAX_CELLS`]): a survey scanner's 0.04° keeps
    /// the nearest of several returns a cell.
    pub fn matched_sdem_resolution_deg(&self) -> f64 {
        crate::sdem::whole_turn_deg(self.tilt_step_deg.max(self.pan_step_deg).max(0.1))
    }

    /// Checks every field for a usable value; the message names the field and the fix.
    pub fn validate(&self) -> Result<()> {
        let finite = [
            ("tilt_min_deg", self.tilt_min_deg),
            ("tilt_max_deg", self.tilt_max_deg),
            ("tilt_step_deg", self.tilt_step_deg),
            ("pan_min_deg", self.pan_min_deg),
            ("pan_max_deg", self.pan_max_deg),
            ("pan_step_deg", self.pan_step_deg),
            ("max_range_m", self.max_range_m),
            ("min_range_m", self.min_range_m),
            ("range_noise_m", self.range_noise_m),
            ("tilt_sensor_noise_deg", self.tilt_sensor_noise_deg),
            ("compass_noise_deg", self.compass_noise_deg),
        ];
        for (name, value) in finite {
            if !value.is_finite() {
                return Err(Error::Invalid(format!(
                    "sensor: {name} is {value}; it must be a finite number"
                )));
            }
        }
        if self.tilt_step_deg <= 0.0 || self.pan_step_deg <= 0.0 {
            return Err(Error::Invalid(
                "sensor: tilt_step_deg and pan_step_deg must be > 0".into(),
            ));
        }
        // The S-DEM is matched to the coarser step (`matched_sdem_resolution_deg`); named here,
        // a step too coarse for a cell says which key to mend.
        for (name, value) in [
            ("tilt_step_deg", self.tilt_step_deg),
            ("pan_step_deg", self.pan_step_deg),
        ] {
            if value > 45.0 {
                return Err(Error::Invalid(format!(
                    "sensor: {name} is {value}°; the S-DEM's cells are matched to the scanner's \
                     coarser step and may be at most 45°"
                )));
            }
        }
        if self.tilt_min_deg > self.tilt_max_deg || self.pan_min_deg > self.pan_max_deg {
            return Err(Error::Invalid(
                "sensor: tilt_min_deg/pan_min_deg must not exceed tilt_max_deg/pan_max_deg".into(),
            ));
        }
        let angles = [
            ("tilt_min_deg", self.tilt_min_deg, 90.0),
            ("tilt_max_deg", self.tilt_max_deg, 90.0),
            ("pan_min_deg", self.pan_min_deg, 180.0),
            ("pan_max_deg", self.pan_max_deg, 180.0),
        ];
        for (name, value, limit) in angles {
            if value.abs() > limit {
                return Err(Error::Invalid(format!(
                    "sensor: {name} is {value}; tilt must lie in [-90, 90] and pan in [-180, 180] \
                     degrees"
                )));
            }
        }
        if self.min_range_m < 0.0 || self.max_range_m <= self.min_range_m {
            return Err(Error::Invalid(
                "sensor: need 0 <= min_range_m < max_range_m".into(),
            ));
        }
        if let Some(t) = self.trusted_range_m {
            if !t.is_finite() || t <= self.min_range_m {
                return Err(Error::Invalid(format!(
                    "sensor: trusted_range_m is {t}; it must be a finite range above min_range_m"
                )));
            }
        }
        let noises = [
            ("range_noise_m", self.range_noise_m),
            ("tilt_sensor_noise_deg", self.tilt_sensor_noise_deg),
            ("compass_noise_deg", self.compass_noise_deg),
        ];
        for (name, value) in noises {
            if value < 0.0 {
                return Err(Error::Invalid(format!(
                    "sensor: {name} is {value}; noise levels must be >= 0"
                )));
            }
        }
        if self.range_noise_m >= self.max_range_m {
            return Err(Error::Invalid(format!(
                "sensor: range_noise_m is {} m, not below max_range_m ({} m): the returns would \
                 be noise (the SICK's is 0.005 m)",
                self.range_noise_m, self.max_range_m
            )));
        }
        self.lift.validate()
    }

    /// The tilt angle of each scan line, degrees.
    pub fn tilt_angles_deg(&self) -> Vec<f64> {
        let n = sample_count(self.tilt_min_deg, self.tilt_max_deg, self.tilt_step_deg);
        (0..n)
            .map(|i| self.tilt_min_deg + i as f64 * self.tilt_step_deg)
            .collect()
    }

    /// The number of beams in one scan line.
    pub fn pan_count(&self) -> usize {
        sample_count(self.pan_min_deg, self.pan_max_deg, self.pan_step_deg)
    }

    /// The farthest range kept: the trusted range when set, else the LRF's maximum.
    pub fn usable_range_m(&self) -> f64 {
        self.trusted_range_m
            .map_or(self.max_range_m, |t| t.min(self.max_range_m))
    }
}

/// The unit direction, in the sensor frame, of the beam at `pan` inside a scan plane tilted up by
/// `tilt` (both radians).
pub fn beam_direction(tilt: f64, pan: f64) -> Vec3 {
    let (st, ct) = tilt.sin_cos();
    let (sp, cp) = pan.sin_cos();
    Vec3::new(ct * cp, sp, st * cp)
}

/// The slide mechanism that lifts the LRF (paper Fig. 6, eq. 2–3).
///
/// The paper's figure is not legible in our copy; we model the usual form of such a mechanism: a
/// trapezoidal screw drives a slider a distance `u` (read by the motor's encoder) along the base,
/// and two links of length `l` crossing as a scissor raise the sensor. The sensor then sits at
/// `x = u / 2` (eq. 2) and `z = sqrt(l² − u²/4)` (eq. 3) above the mount point, so sliding out
/// lowers it.
#[derive(Debug, Clone, PartialEq, Serialize, Deserialize)]
#[serde(default, deny_unknown_fields)]
pub struct LiftConfig {
    /// Length of each scissor link, metres.
    pub link_length_m: f64,
    /// Smallest slide `u`, metres (sensor highest).
    pub slide_min_m: f64,
    /// Largest slide `u`, metres (sensor lowest).
    pub slide_max_m: f64,
    /// Where the mechanism's base pivot sits in the body frame, metres `[x, y, z]`.
    pub mount_in_body_m: [f64; 3],
}

impl Default for LiftConfig {
    fn default() -> Self {
        Self {
            link_length_m: 0.30,
            slide_min_m: 0.20,
            slide_max_m: 0.58,
            mount_in_body_m: [0.0, 0.0, 0.12],
        }
    }
}

impl LiftConfig {
    /// Checks the geometry: a positive link, and a slide range the links can reach.
    pub fn validate(&self) -> Result<()> {
        let ok = self.link_length_m.is_finite()
            && self.link_length_m > 0.0
            && self.slide_min_m.is_finite()
            && self.slide_max_m.is_finite()
            && 0.0 <= self.slide_min_m
            && self.slide_min_m <= self.slide_max_m
            && self.slide_max_m < 2.0 * self.link_length_m
            && self.mount_in_body_m.iter().all(|v| v.is_finite());
        if ok {
            Ok(())
        } else {
            Err(Error::Invalid(format!(
                "sensor.lift: need link_length_m > 0 and 0 <= slide_min_m <= slide_max_m < 2 * link_length_m \
                 (got link {} m, slide {}..{} m)",
                self.link_length_m, self.slide_min_m, self.slide_max_m
            )))
        }
    }

    /// The sensor's offset from the mount point for slide `u` (paper eq. 2–3), metres `[x, z]`.
    pub fn offset(&self, slide_m: f64) -> Result<[f64; 2]> {
        if !(self.slide_min_m - 1e-9..=self.slide_max_m + 1e-9).contains(&slide_m) {
            return Err(Error::Invalid(format!(
                "lift slide {slide_m} m is outside the mechanism's range {}..{} m",
                self.slide_min_m, self.slide_max_m
            )));
        }
        let half = 0.5 * slide_m;
        // Eq. (2) and (3).
        let x = half;
        let z = (self.link_length_m * self.link_length_m - half * half).sqrt();
        Ok([x, z])
    }

    /// The slide `u` that puts the sensor at `height` above the mount point (the inverse of eq. 3).
    pub fn slide_for_height(&self, height_m: f64) -> Result<f64> {
        let l = self.link_length_m;
        if !(0.0..=l).contains(&height_m) {
            return Err(Error::Invalid(format!(
                "lift height {height_m} m is outside 0..{l} m"
            )));
        }
        let slide = 2.0 * (l * l - height_m * height_m).sqrt();
        self.offset(slide).map(|_| slide)
    }

    /// `body_from_sensor` for slide `u`: a pure translation (the lift does not rotate the LRF).
    pub fn body_from_sensor(&self, slide_m: f64) -> Result<Pose> {
        let [x, z] = self.offset(slide_m)?;
        let m = self.mount_in_body_m;
        Ok(Isometry3::from_parts(
            Translation3::new(m[0] + x, m[1], m[2] + z),
            UnitQuaternion::identity(),
        ))
    }
}

/// One line of a raw sweep: the scan plane at one tilt.
#[derive(Debug, Clone, PartialEq)]
pub struct SweepLine {
    /// Tilt of the scan plane, degrees (positive up).
    pub tilt_deg: f64,
    /// The gyro/compass reading while the line was taken.
    pub attitude: Attitude,
    /// Range of each beam over pan, metres; `NaN` where there was no return.
    pub ranges: Vec<f32>,
}

/// A raw tilting-LRF sweep as the hardware produces it: per tilt line the tilt angle, the
/// attitude and the ranges over pan, plus the lift's slide.
#[derive(Debug, Clone, PartialEq)]
pub struct Sweep {
    /// First pan angle of every line, degrees.
    pub pan_min_deg: f64,
    /// Pan step, degrees.
    pub pan_step_deg: f64,
    /// The lift's slide `u` during the sweep, metres.
    pub lift_slide_m: f64,
    /// The scan lines, in the order taken.
    pub lines: Vec<SweepLine>,
}

impl Sweep {
    /// Checks that every line has the same beam count and finite angles.
    pub fn validate(&self) -> Result<()> {
        if !(self.pan_min_deg.is_finite()
            && self.pan_step_deg.is_finite()
            && self.pan_step_deg > 0.0)
        {
            return Err(Error::Invalid(
                "sweep: pan_min_deg must be finite and pan_step_deg > 0".into(),
            ));
        }
        if !self.lift_slide_m.is_finite() {
            return Err(Error::Invalid("sweep: lift slide must be finite".into()));
        }
        let count = self.lines.first().map_or(0, |l| l.ranges.len());
        for (i, line) in self.lines.iter().enumerate() {
            if line.ranges.len() != count {
                return Err(Error::Invalid(format!(
                    "sweep: line {i} has {} ranges, line 0 has {count}",
                    line.ranges.len()
                )));
            }
            if !line.tilt_deg.is_finite() || !line.attitude.is_finite() {
                return Err(Error::Invalid(format!(
                    "sweep: line {i} has a non-finite tilt or attitude"
                )));
            }
        }
        Ok(())
    }

    /// The returns as points in the sensor frame, metres; beams with no return are skipped.
    pub fn points_in_sensor(&self) -> Vec<Vec3> {
        let mut points = Vec::new();
        for line in &self.lines {
            let tilt = line.tilt_deg.to_radians();
            for (k, &r) in line.ranges.iter().enumerate() {
                if r.is_finite() && r > 0.0 {
                    let pan = (self.pan_min_deg + k as f64 * self.pan_step_deg).to_radians();
                    points.push(beam_direction(tilt, pan) * r as f64);
                }
            }
        }
        points
    }

    /// The attitude for the whole sweep: the mean of the lines' readings (the robot stands still
    /// while it sweeps). Yaw is averaged on the circle.
    pub fn mean_attitude(&self) -> Attitude {
        let n = self.lines.len().max(1) as f64;
        let (mut roll, mut pitch, mut ys, mut yc) = (0.0, 0.0, 0.0, 0.0);
        for line in &self.lines {
            roll += line.attitude.roll;
            pitch += line.attitude.pitch;
            ys += line.attitude.yaw.sin();
            yc += line.attitude.yaw.cos();
        }
        Attitude::new(roll / n, pitch / n, ys.atan2(yc))
    }
}

#[cfg(test)]
mod tests {
    use super::*;
    use approx::assert_relative_eq;

    #[test]
    fn the_matched_sdem_resolution_is_the_coarser_step_dividing_a_turn() {
        let paper = SensorConfig::default();
        assert_eq!(paper.matched_sdem_resolution_deg(), 1.0);
        let nodding = SensorConfig {
            tilt_step_deg: 0.517,
            pan_step_deg: 0.5,
            ..SensorConfig::default()
        };
        let r = nodding.matched_sdem_resolution_deg();
        // 697 cells of 0.5165° make a turn; never coarser than the scanner's coarser step.
        assert_relative_eq!(r * 697.0, 360.0, epsilon = 1e-9);
        assert!(r <= 0.517 && r > 0.516, "{r}");
        let fine = SensorConfig {
            tilt_step_deg: 0.25,
            pan_step_deg: 0.25,
            ..SensorConfig::default()
        };
        assert_eq!(fine.matched_sdem_resolution_deg(), 0.25);
        // A survey scanner's 0.04°: the finest grid a full sphere may have.
        let survey = SensorConfig {
            tilt_step_deg: 0.04,
            pan_step_deg: 0.04,
            ..SensorConfig::default()
        };
        let r = survey.matched_sdem_resolution_deg();
        assert_relative_eq!(r, 0.1, epsilon = 1e-12);
        let grid = crate::sdem::SdemConfig {
            resolution_deg: r,
            ..Default::default()
        };
        assert!(grid.validate().is_ok());
    }

    #[test]
    fn paper_sweep_has_86_lines_of_181_beams() {
        let cfg = SensorConfig::default();
        cfg.validate().unwrap();
        assert_eq!(cfg.tilt_angles_deg().len(), 86);
        assert_eq!(cfg.pan_count(), 181);
    }

    /// A step too coarse for an S-DEM cell is refused by its key, not by the S-DEM grid's
    /// resolution the loop derives from it later.
    #[test]
    fn a_step_coarser_than_a_cell_may_be_is_named() {
        let cfg = SensorConfig {
            pan_step_deg: 90.0,
            ..Default::default()
        };
        let e = cfg.validate().unwrap_err().to_string();
        assert!(e.contains("pan_step_deg is 90°"), "{e}");
        // So is a range noise as large as the range (a simulated run of nothing but noise).
        let cfg = SensorConfig {
            range_noise_m: 1e9,
            ..Default::default()
        };
        let e = cfg.validate().unwrap_err().to_string();
        assert!(e.contains("range_noise_m is 1000000000 m"), "{e}");
    }

    #[test]
    fn beam_geometry() {
        assert_relative_eq!(beam_direction(0.0, 0.0), Vec3::x(), epsilon = 1e-12);
        let up = beam_direction(30f64.to_radians(), 0.0);
        assert_relative_eq!(up.z, 0.5, epsilon = 1e-12);
        // At pan ±90° every tilt looks straight sideways.
        let side = beam_direction(0.7, std::f64::consts::FRAC_PI_2);
        assert_relative_eq!(side, Vec3::y(), epsilon = 1e-12);
    }

    #[test]
    fn lift_kinematics_round_trip() {
        let lift = LiftConfig::default();
        for &h in &[0.1, 0.2, 0.28] {
            let u = lift.slide_for_height(h).unwrap();
            let [_, z] = lift.offset(u).unwrap();
            assert_relative_eq!(z, h, epsilon = 1e-12);
        }
        assert!(lift.offset(lift.slide_max_m + 0.1).is_err());
        assert!(lift.slide_for_height(0.0).is_err());
    }

    #[test]
    fn invalid_configs_are_rejected() {
        let mut cfg = SensorConfig {
            tilt_step_deg: 0.0,
            ..Default::default()
        };
        assert!(cfg.validate().is_err());
        cfg.tilt_step_deg = 1.0;
        cfg.range_noise_m = f64::NAN;
        assert!(cfg.validate().is_err());
    }
}
