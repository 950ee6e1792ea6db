//! `sensor_msgs/PointCloud2` → points: any field layout with `x`, `y`, `z` as float32 or
//! float64, `point_step` and `row_step` honoured, either byte order, organized or not.

use super::messages::{PointCloud2, PointField};
use sdem::geometry::Vec3;

const FLOAT32: u8 = 7;
const FLOAT64: u8 = 8;

/// The points of a cloud, in its frame, and what was dropped.
#[derive(Debug, Clone, PartialEq, Default)]
pub struct CloudPoints {
    /// The points with three finite coordinates, metres, in the cloud's frame.
    pub points: Vec<Vec3>,
    /// Points with a NaN or infinite coordinate (no return), dropped.
    pub dropped_non_finite: usize,
    /// Points at exactly the origin (how some drivers write "no return"), dropped.
    pub dropped_at_origin: usize,
}

/// Where one coordinate lies in a point, and its width.
#[derive(Debug, Clone, Copy)]
struct Coordinate {
    offset: usize,
    double: bool,
}

fn name_of(datatype: u8) -> &'static str {
    match datatype {
        1 => "INT8",
        2 => "UINT8",
        3 => "INT16",
        4 => "UINT16",
        5 => "INT32",
        6 => "UINT32",
        7 => "FLOAT32",
        8 => "FLOAT64",
        _ => "an unknown datatype",
    }
}

fn coordinate(fields: &[PointField], name: &str, point_step: usize) -> Result<Coordinate, String> {
    let Some(field) = fields.iter().find(|f| f.name == name) else {
        let names: Vec<&str> = fields.iter().map(|f| f.name.as_str()).collect();
        return Err(format!(
            "the cloud has no '{name}' field (its fields: {}); sdem needs x, y and z \
             coordinates: choose the topic of the 3D points with --scan-topic",
            if names.is_empty() {
                "none".to_string()
            } else {
                names.join(", ")
            }
        ));
    };
    let double = match field.datatype {
        FLOAT32 => false,
        FLOAT64 => true,
        other => {
            return Err(format!(
                "field '{name}' is {} ({other}); sdem reads x, y and z as FLOAT32 or FLOAT64",
                name_of(other)
            ))
        }
    };
    let size = if double { 8 } else { 4 };
    let offset = field.offset as usize;
    if offset + size > point_step {
        return Err(format!(
            "field '{name}' at offset {offset} ({size} bytes) does not fit in a point of \
             point_step {point_step} bytes"
        ));
    }
    Ok(Coordinate { offset, double })
}

fn read(point: &[u8], c: Coordinate, big_endian: bool) -> f64 {
    if c.double {
        let b: [u8; 8] = point[c.offset..c.offset + 8].try_into().unwrap_or([0; 8]);
        if big_endian {
            f64::from_be_bytes(b)
        } else {
            f64::from_le_bytes(b)
        }
    } else {
        let b: [u8; 4] = point[c.offset..c.offset + 4].try_into().unwrap_or([0; 4]);
        f64::from(if big_endian {
            f32::from_be_bytes(b)
        } else {
            f32::from_le_bytes(b)
        })
    }
}

/// Where `x`, `y` and `z` lie in a cloud's points, checked against its size.
#[derive(Debug, Clone, Copy)]
pub struct CloudLayout {
    coordinates: [Coordinate; 3],
    point_step: usize,
    row_step: usize,
    row_bytes: usize,
    height: usize,
    big_endian: bool,
}

impl CloudLayout {
    /// The layout of `cloud`.
    ///
    /// # Errors
    /// In words: no `x`, `y` or `z` field, one that is not FLOAT32/FLOAT64 or does not fit in
    /// `point_step`, a `row_step` shorter than a row, or data shorter than `height` rows.
    pub fn of(cloud: &PointCloud2) -> Result<Self, String> {
        let point_step = cloud.point_step as usize;
        let (width, height) = (cloud.width as usize, cloud.height as usize);
        let x = coordinate(&cloud.fields, "x", point_step)?;
        let y = coordinate(&cloud.fields, "y", point_step)?;
        let z = coordinate(&cloud.fields, "z", point_step)?;
        let row_bytes = width
            .checked_mul(point_step)
            .ok_or("width × point_step overflows")?;
        let row_step = cloud.row_step as usize;
        if height > 0 && row_step < row_bytes {
            return Err(format!(
                "row_step {row_step} is shorter than a row of {width} points × point_step \
                 {point_step} = {row_bytes} bytes"
            ));
        }
        let needed = match height {
            0 => 0,
            h => (h - 1)
                .checked_mul(row_step)
                .and_then(|n| n.checked_add(row_bytes))
                .ok_or("height × row_step overflows")?,
        };
        if cloud.data.len() < needed {
            return Err(format!(
                "the data holds {} bytes, fewer than the {needed} of {height} rows of {width} \
                 points (row_step {row_step}, point_step {point_step})",
                cloud.data.len()
            ));
        }
        Ok(Self {
            coordinates: [x, y, z],
            point_step,
            row_step,
            row_bytes,
            height,
            big_endian: cloud.is_bigendian,
        })
    }

    /// Calls `visit` with every point of `data` (the cloud's), NaN and all.
    fn for_each(&self, data: &[u8], mut visit: impl FnMut(Vec3)) {
        let [x, y, z] = self.coordinates;
        let big = self.big_endian;
        for row in 0..self.height {
            let start = row * self.row_step;
            let points = data[start..start + self.row_bytes].chunks_exact(self.point_step.max(1));
            for point in points {
                visit(Vec3::new(
                    read(point, x, big),
                    read(point, y, big),
                    read(point, z, big),
                ));
            }
        }
    }

    /// The points of `cloud` (of this layout), in its frame, without those that have no
    /// return (a NaN or infinite coordinate, or all three exactly 0).
    pub fn points(&self, cloud: &PointCloud2) -> CloudPoints {
        let mut out = CloudPoints::default();
        self.for_each(cloud.data, |p| {
            if !(p.x.is_finite() && p.y.is_finite() && p.z.is_finite()) {
                out.dropped_non_finite += 1;
            } else if p == Vec3::zeros() {
                out.dropped_at_origin += 1;
            } else {
                out.points.push(p);
            }
        });
        out
    }

    /// How many points of `cloud` (of this layout) have a return.
    pub fn count_returns(&self, cloud: &PointCloud2) -> usize {
        let mut n = 0;
        self.for_each(cloud.data, |p| {
            if p.x.is_finite() && p.y.is_finite() && p.z.is_finite() && p != Vec3::zeros() {
                n += 1;
            }
        });
        n
    }
}

/// The points of `cloud`, in its frame, without those that have no return; see
/// [`CloudLayout::of`] for the errors.
#[cfg(test)]
fn cloud_points(cloud: &PointCloud2) -> Result<CloudPoints, String> {
    CloudLayout::of(cloud).map(|layout| layout.points(cloud))
}

#[cfg(test)]
mod tests {
    use super::*;
    use crate::rosbag::messages::Header;

    fn field(name: &str, offset: u32, datatype: u8) -> PointField {
        PointField {
            name: name.into(),
            offset,
            datatype,
            count: 1,
        }
    }

    fn cloud<'a>(
        fields: Vec<PointField>,
        point_step: u32,
        width: u32,
        height: u32,
        row_step: u32,
        big: bool,
        data: &'a [u8],
    ) -> PointCloud2<'a> {
        PointCloud2 {
            header: Header {
                stamp_ns: 0,
                frame_id: "lidar".into(),
            },
            height,
            width,
            fields,
            is_bigendian: big,
            point_step,
            row_step,
            data,
        }
    }

    #[test]
    fn float64_big_endian_organized_with_padding_and_nan() {
        // z, intensity, y, x in doubles (an odd order), 40-byte points, rows padded by 8 bytes.
        let fields = vec![
            field("z", 0, FLOAT64),
            field("intensity", 8, FLOAT32),
            field("y", 16, FLOAT64),
            field("x", 24, FLOAT64),
        ];
        let points = [
            [1.0, 2.0, 3.0],
            [f64::NAN, 0.0, 0.0],
            [0.0, 0.0, 0.0],
            [-4.0, 5.5, 0.25],
        ];
        let mut data = Vec::new();
        for (i, p) in points.iter().enumerate() {
            data.extend_from_slice(&p[2].to_be_bytes());
            data.extend_from_slice(&[0; 8]);
            data.extend_from_slice(&p[1].to_be_bytes());
            data.extend_from_slice(&p[0].to_be_bytes());
            data.extend_from_slice(&[0; 8]);
            if i % 2 == 1 {
                data.extend_from_slice(&[0xAA; 8]);
            }
        }
        let c = cloud(fields, 40, 2, 2, 88, true, &data);
        let got = cloud_points(&c).unwrap();
        assert_eq!(
            got.points,
            vec![Vec3::new(1.0, 2.0, 3.0), Vec3::new(-4.0, 5.5, 0.25)]
        );
        assert_eq!((got.dropped_non_finite, got.dropped_at_origin), (1, 1));
    }

    #[test]
    fn a_cloud_without_z_is_refused_naming_its_fields() {
        let fields = vec![field("x", 0, FLOAT32), field("y", 4, FLOAT32)];
        let e = cloud_points(&cloud(fields, 8, 1, 1, 8, false, &[0; 8])).unwrap_err();
        assert!(e.contains("no 'z' field") && e.contains("x, y"), "{e}");
    }

    #[test]
    fn bad_layouts_are_refused() {
        let xyz = |t| vec![field("x", 0, t), field("y", 4, t), field("z", 8, t)];
        let e = cloud_points(&cloud(xyz(3), 12, 1, 1, 12, false, &[0; 12])).unwrap_err();
        assert!(e.contains("INT16"), "{e}");
        let e = cloud_points(&cloud(xyz(FLOAT32), 8, 1, 1, 8, false, &[0; 8])).unwrap_err();
        assert!(e.contains("does not fit"), "{e}");
        let e = cloud_points(&cloud(xyz(FLOAT32), 12, 2, 1, 12, false, &[0; 24])).unwrap_err();
        assert!(e.contains("row_step"), "{e}");
        let e = cloud_points(&cloud(xyz(FLOAT32), 12, 2, 2, 24, false, &[0; 40])).unwrap_err();
        assert!(e.contains("fewer than"), "{e}");
    }
}
