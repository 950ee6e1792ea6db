//! Primitives: oriented boxes, ellipsoids and the solids made of them, with exact ray tests.

use super::EPS;
use nalgebra::Rotation3;
use sdem::error::{Error, Result};
use sdem::geometry::Vec3;

/// A box with its own orientation: the building block of free space and of solid obstacles.
#[derive(Debug, Clone, PartialEq)]
pub struct OrientedBox {
    pub(super) center: Vec3,
    pub(super) half_extents: Vec3,
    pub(super) world_from_box: Rotation3<f64>,
}

impl OrientedBox {
    /// A box centred at `center` (world, metres) with `half_extents` along its own axes, turned
    /// by `world_from_box`.
    ///
    /// # Errors
    /// [`Error::Invalid`] when a value is not finite or a half extent is not positive.
    pub fn new(center: Vec3, half_extents: Vec3, world_from_box: Rotation3<f64>) -> Result<Self> {
        let finite = center
            .iter()
            .chain(world_from_box.matrix().iter())
            .all(|v| v.is_finite());
        let positive = half_extents.iter().all(|h| h.is_finite() && *h > 0.0);
        if finite && positive {
            Ok(Self::build(center, half_extents, world_from_box))
        } else {
            Err(Error::Invalid(format!(
                "box: need a finite centre and rotation and positive half extents \
                 (got centre {center:?}, half extents {half_extents:?})"
            )))
        }
    }

    /// An axis-aligned box between the corners `min` and `max`.
    ///
    /// # Errors
    /// [`Error::Invalid`] unless `min < max` on every axis.
    pub fn axis_aligned(min: Vec3, max: Vec3) -> Result<Self> {
        Self::new((min + max) * 0.5, (max - min) * 0.5, Rotation3::identity())
    }

    /// A box from values the caller knows to be valid.
    pub(super) fn build(center: Vec3, half_extents: Vec3, world_from_box: Rotation3<f64>) -> Self {
        debug_assert!(half_extents.iter().all(|h| *h > 0.0));
        Self {
            center,
            half_extents,
            world_from_box,
        }
    }

    /// The centre, world frame, metres.
    pub fn center(&self) -> &Vec3 {
        &self.center
    }

    /// Half the size along each of the box's own axes, metres.
    pub fn half_extents(&self) -> &Vec3 {
        &self.half_extents
    }

    /// The rotation `world_from_box`.
    pub fn rotation(&self) -> &Rotation3<f64> {
        &self.world_from_box
    }

    fn to_local(&self, p: &Vec3) -> Vec3 {
        self.world_from_box
            .inverse_transform_vector(&(p - self.center))
    }

    /// True when `p` lies inside the box or on its surface (within 1 nm).
    pub fn contains(&self, p: &Vec3) -> bool {
        let local = self.to_local(p);
        (0..3).all(|i| local[i].abs() <= self.half_extents[i] + EPS)
    }

    /// True when `p` lies strictly inside the box.
    fn contains_strictly(&self, p: &Vec3) -> bool {
        let local = self.to_local(p);
        (0..3).all(|i| local[i].abs() < self.half_extents[i])
    }

    /// The parameters `(t_in, t_out)` where the line `origin + t · direction` enters and leaves
    /// the box (slab method, exact), or `None` when it misses. `t_in` is negative when `origin`
    /// is inside.
    pub fn ray_interval(&self, origin: &Vec3, direction: &Vec3) -> Option<(f64, f64)> {
        let o = self.to_local(origin);
        let d = self.world_from_box.inverse_transform_vector(direction);
        let (mut t_in, mut t_out) = (f64::NEG_INFINITY, f64::INFINITY);
        for i in 0..3 {
            let h = self.half_extents[i];
            if d[i] == 0.0 {
                if o[i].abs() > h {
                    return None;
                }
                continue;
            }
            let a = (-h - o[i]) / d[i];
            let b = (h - o[i]) / d[i];
            t_in = t_in.max(a.min(b));
            t_out = t_out.min(a.max(b));
        }
        (t_in <= t_out).then_some((t_in, t_out))
    }

    /// Euclidean distance from `p` to the box (0 inside).
    pub fn distance_to(&self, p: &Vec3) -> f64 {
        let local = self.to_local(p);
        Vec3::from_fn(|i, _| (local[i].abs() - self.half_extents[i]).max(0.0)).norm()
    }

    /// Half the box's vertical extent (its world AABB is `center.z ± this`).
    pub(super) fn half_height(&self) -> f64 {
        let m = self.world_from_box.matrix();
        (0..3).map(|i| m[(2, i)].abs() * self.half_extents[i]).sum()
    }
}

/// An ellipsoid (a rock): a unit sphere scaled by `radii` along its own axes and turned.
#[derive(Debug, Clone, PartialEq)]
pub struct Ellipsoid {
    center: Vec3,
    radii: Vec3,
    world_from_ellipsoid: Rotation3<f64>,
}

impl Ellipsoid {
    /// An ellipsoid centred at `center` with semi-axes `radii` along its own axes, turned by
    /// `world_from_ellipsoid`.
    ///
    /// # Errors
    /// [`Error::Invalid`] when a value is not finite or a radius is not positive.
    pub fn new(center: Vec3, radii: Vec3, world_from_ellipsoid: Rotation3<f64>) -> Result<Self> {
        let finite = center
            .iter()
            .chain(world_from_ellipsoid.matrix().iter())
            .all(|v| v.is_finite());
        let positive = radii.iter().all(|r| r.is_finite() && *r > 0.0);
        if finite && positive {
            Ok(Self::build(center, radii, world_from_ellipsoid))
        } else {
            Err(Error::Invalid(format!(
                "ellipsoid: need a finite centre and rotation and positive radii \
                 (got centre {center:?}, radii {radii:?})"
            )))
        }
    }

    pub(super) fn build(center: Vec3, radii: Vec3, world_from_ellipsoid: Rotation3<f64>) -> Self {
        debug_assert!(radii.iter().all(|r| *r > 0.0));
        Self {
            center,
            radii,
            world_from_ellipsoid,
        }
    }

    /// The centre, world frame, metres.
    pub fn center(&self) -> &Vec3 {
        &self.center
    }

    /// The semi-axes along the ellipsoid's own axes, metres.
    pub fn radii(&self) -> &Vec3 {
        &self.radii
    }

    /// `p` in the frame where the ellipsoid is the unit sphere.
    fn to_unit(&self, p: &Vec3) -> Vec3 {
        self.world_from_ellipsoid
            .inverse_transform_vector(&(p - self.center))
            .component_div(&self.radii)
    }

    /// The parameters `(t_in, t_out)` where the line `origin + t · direction` enters and leaves
    /// the ellipsoid, or `None` when it misses.
    pub fn ray_interval(&self, origin: &Vec3, direction: &Vec3) -> Option<(f64, f64)> {
        let o = self.to_unit(origin);
        let d = self
            .world_from_ellipsoid
            .inverse_transform_vector(direction)
            .component_div(&self.radii);
        let a = d.norm_squared();
        if a == 0.0 {
            return None;
        }
        let b = o.dot(&d);
        let c = o.norm_squared() - 1.0;
        let disc = b * b - a * c;
        if disc < 0.0 {
            return None;
        }
        let s = disc.sqrt();
        Some(((-b - s) / a, (-b + s) / a))
    }

    /// True when `p` lies strictly inside.
    pub fn contains(&self, p: &Vec3) -> bool {
        self.to_unit(p).norm_squared() < 1.0
    }

    /// Half the vertical extent (exact support of the ellipsoid along z).
    fn half_height(&self) -> f64 {
        let m = self.world_from_ellipsoid.matrix();
        (0..3)
            .map(|i| (m[(2, i)] * self.radii[i]).powi(2))
            .sum::<f64>()
            .sqrt()
    }
}

/// A solid obstacle inside the air.
#[derive(Debug, Clone, PartialEq)]
pub enum Solid {
    /// An oriented box: a rubble block, a slab, a column, a shelf.
    Box(OrientedBox),
    /// An ellipsoid: a rock.
    Ellipsoid(Ellipsoid),
}

impl Solid {
    /// The parameters where the line `origin + t · direction` enters and leaves the solid.
    pub fn ray_interval(&self, origin: &Vec3, direction: &Vec3) -> Option<(f64, f64)> {
        match self {
            Solid::Box(b) => b.ray_interval(origin, direction),
            Solid::Ellipsoid(e) => e.ray_interval(origin, direction),
        }
    }

    /// True when `p` lies strictly inside the solid (its surface counts as free).
    pub fn contains(&self, p: &Vec3) -> bool {
        match self {
            Solid::Box(b) => b.contains_strictly(p),
            Solid::Ellipsoid(e) => e.contains(p),
        }
    }

    pub(super) fn center(&self) -> &Vec3 {
        match self {
            Solid::Box(b) => &b.center,
            Solid::Ellipsoid(e) => &e.center,
        }
    }

    /// Moves the solid vertically so that its lowest point lies 40 % of its half height below
    /// `base`.
    pub(super) fn rest_on(&mut self, base: f64) {
        let (lo, hi) = self.z_range();
        let dz = base + 0.6 * 0.5 * (hi - lo) - 0.5 * (lo + hi);
        match self {
            Solid::Box(b) => b.center.z += dz,
            Solid::Ellipsoid(e) => e.center.z += dz,
        }
    }

    /// Radius of a sphere around [`Self::center`] that holds the solid.
    pub(super) fn bounding_radius(&self) -> f64 {
        match self {
            Solid::Box(b) => b.half_extents.norm(),
            Solid::Ellipsoid(e) => e.radii.max(),
        }
    }

    /// Lowest and highest z of the solid (exact for ellipsoids, the AABB for boxes).
    pub(super) fn z_range(&self) -> (f64, f64) {
        let (z, h) = match self {
            Solid::Box(b) => (b.center.z, b.half_height()),
            Solid::Ellipsoid(e) => (e.center.z, e.half_height()),
        };
        (z - h, z + h)
    }

    /// A distance from `p` to the solid that never exceeds the true one.
    pub(super) fn distance_lower_bound(&self, p: &Vec3) -> f64 {
        match self {
            Solid::Box(b) => b.distance_to(p),
            Solid::Ellipsoid(e) => ((p - e.center).norm() - e.radii.max()).max(0.0),
        }
    }

    /// Distance along a unit ray to the solid's surface; 0 when `origin` is inside.
    pub(super) fn hit_distance(&self, origin: &Vec3, direction: &Vec3) -> Option<f64> {
        if !sphere_may_hit(self.center(), self.bounding_radius(), origin, direction) {
            return None;
        }
        let (t_in, t_out) = self.ray_interval(origin, direction)?;
        (t_out > EPS).then_some(t_in.max(0.0))
    }
}

/// Cheap rejection: false when the unit ray cannot touch the sphere.
fn sphere_may_hit(center: &Vec3, radius: f64, origin: &Vec3, direction: &Vec3) -> bool {
    let oc = center - origin;
    let along = oc.dot(direction);
    if along < -radius {
        return false;
    }
    oc.norm_squared() - along * along <= radius * radius + EPS
}
