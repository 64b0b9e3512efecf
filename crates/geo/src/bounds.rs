//! Bounding volumes for tiles: spheres and oriented boxes, both in f64 ECEF.

use glam::{DMat3, DVec3};

use crate::frustum::{Intersection, Plane};

/// A sphere that contains a set of points.
#[derive(Clone, Copy, Debug, PartialEq)]
pub struct BoundingSphere {
    /// Centre, ECEF metres.
    pub centre: DVec3,
    /// Radius, metres.
    pub radius: f64,
}

impl BoundingSphere {
    /// The sphere centred on the middle of the points' axis-aligned box, with the radius that
    /// reaches the farthest point. Not minimal, but tight for tile-shaped point sets and cheap.
    /// `None` for an empty set.
    pub fn from_points(points: impl IntoIterator<Item = DVec3> + Clone) -> Option<Self> {
        let mut iter = points.clone().into_iter();
        let first = iter.next()?;
        let (min, max) = iter.fold((first, first), |(lo, hi), p| (lo.min(p), hi.max(p)));
        let centre = (min + max) * 0.5;
        let radius_sq = points
            .into_iter()
            .map(|p| p.distance_squared(centre))
            .fold(0.0, f64::max);
        Some(Self {
            centre,
            radius: radius_sq.sqrt(),
        })
    }

    /// Distance from `point` to the sphere's surface, 0 inside.
    pub fn distance_to(&self, point: DVec3) -> f64 {
        (point.distance(self.centre) - self.radius).max(0.0)
    }

    /// Which side of `plane` the sphere is on.
    pub fn intersect_plane(&self, plane: &Plane) -> Intersection {
        let d = plane.signed_distance(self.centre);
        if d < -self.radius {
            Intersection::Outside
        } else if d > self.radius {
            Intersection::Inside
        } else {
            Intersection::Intersecting
        }
    }
}

/// A box with arbitrary orientation: a centre, three orthonormal axes and the half-extent
/// along each. Stored with unit axes so culling and distance need no square roots.
#[derive(Clone, Copy, Debug, PartialEq)]
pub struct OrientedBox {
    /// Centre, ECEF metres.
    pub centre: DVec3,
    /// Orthonormal axes (columns).
    pub axes: DMat3,
    /// Half-extent along each axis, metres (non-negative).
    pub half_extents: DVec3,
}

impl OrientedBox {
    /// A box from its centre, orthonormal `axes` (columns) and half-extents.
    pub fn new(centre: DVec3, axes: DMat3, half_extents: DVec3) -> Self {
        Self {
            centre,
            axes,
            half_extents: half_extents.abs(),
        }
    }

    /// The smallest box with the given orthonormal `axes` (columns) containing all points.
    /// `None` for an empty set.
    pub fn from_points_with_axes(
        axes: DMat3,
        points: impl IntoIterator<Item = DVec3>,
    ) -> Option<Self> {
        let to_local = axes.transpose();
        let mut iter = points.into_iter();
        let first = to_local * iter.next()?;
        let (min, max) = iter.fold((first, first), |(lo, hi), p| {
            let l = to_local * p;
            (lo.min(l), hi.max(l))
        });
        Some(Self {
            centre: axes * ((min + max) * 0.5),
            axes,
            half_extents: (max - min) * 0.5,
        })
    }

    /// The half-axis vectors (axes scaled by the half-extents) as matrix columns.
    pub fn half_axes(&self) -> DMat3 {
        DMat3::from_cols(
            self.axes.x_axis * self.half_extents.x,
            self.axes.y_axis * self.half_extents.y,
            self.axes.z_axis * self.half_extents.z,
        )
    }

    /// The same box grown by `margin_m` on every side.
    pub fn grown(&self, margin_m: f64) -> Self {
        Self {
            half_extents: self.half_extents + DVec3::splat(margin_m),
            ..*self
        }
    }

    /// The eight corners.
    pub fn corners(&self) -> [DVec3; 8] {
        let h = self.half_axes();
        let (u, v, w) = (h.x_axis, h.y_axis, h.z_axis);
        let c = self.centre;
        [
            c - u - v - w,
            c + u - v - w,
            c - u + v - w,
            c + u + v - w,
            c - u - v + w,
            c + u - v + w,
            c - u + v + w,
            c + u + v + w,
        ]
    }

    /// The radius of the box's projection onto a unit `normal` (its "effective radius").
    #[inline]
    fn projected_radius(&self, normal: DVec3) -> f64 {
        (self.axes.transpose() * normal)
            .abs()
            .dot(self.half_extents)
    }

    /// Which side of `plane` the box is on.
    #[inline]
    pub fn intersect_plane(&self, plane: &Plane) -> Intersection {
        let r = self.projected_radius(plane.normal);
        let d = plane.signed_distance(self.centre);
        if d < -r {
            Intersection::Outside
        } else if d > r {
            Intersection::Inside
        } else {
            Intersection::Intersecting
        }
    }

    /// Euclidean distance from `point` to the box, 0 inside.
    #[inline]
    pub fn distance_to(&self, point: DVec3) -> f64 {
        self.distance_squared_to(point).sqrt()
    }

    /// The point of the box nearest to `point` (`point` itself inside).
    pub fn closest_point(&self, point: DVec3) -> DVec3 {
        let local = self.axes.transpose() * (point - self.centre);
        self.centre + self.axes * local.clamp(-self.half_extents, self.half_extents)
    }

    /// Squared distance from `point` to the box, 0 inside.
    #[inline]
    pub fn distance_squared_to(&self, point: DVec3) -> f64 {
        let local = self.axes.transpose() * (point - self.centre);
        let excess = (local.abs() - self.half_extents).max(DVec3::ZERO);
        excess.length_squared()
    }

    /// A sphere that contains the box.
    pub fn bounding_sphere(&self) -> BoundingSphere {
        BoundingSphere {
            centre: self.centre,
            radius: self.half_extents.length(),
        }
    }

    /// Whether `point` lies inside the box (with a tolerance in metres).
    pub fn contains(&self, point: DVec3, tolerance_m: f64) -> bool {
        self.distance_squared_to(point) <= tolerance_m * tolerance_m
    }
}

#[cfg(test)]
mod tests {
    use super::*;
    use approx::assert_relative_eq;

    #[test]
    fn sphere_contains_its_points() {
        let pts = [DVec3::ZERO, DVec3::X * 2.0, DVec3::new(1.0, 1.0, 0.0)];
        let s = BoundingSphere::from_points(pts).unwrap();
        for p in pts {
            assert!(p.distance(s.centre) <= s.radius + 1e-12);
        }
        assert!(BoundingSphere::from_points(std::iter::empty::<DVec3>()).is_none());
    }

    #[test]
    fn box_distance_is_euclidean() {
        let b = OrientedBox::from_points_with_axes(
            DMat3::IDENTITY,
            [DVec3::splat(-1.0), DVec3::splat(1.0)],
        )
        .unwrap();
        assert_relative_eq!(b.distance_to(DVec3::new(4.0, 0.0, 0.0)), 3.0);
        assert_relative_eq!(b.distance_to(DVec3::new(2.0, 2.0, 0.0)), 2f64.sqrt());
        assert_eq!(b.distance_to(DVec3::new(0.5, 0.5, 0.5)), 0.0);
    }

    #[test]
    fn rotated_box_contains_its_points_and_sphere_contains_box() {
        let axes = DMat3::from_quat(glam::DQuat::from_euler(glam::EulerRot::XYZ, 0.3, 0.7, 1.1));
        let pts: Vec<DVec3> = (0..50)
            .map(|i| {
                let t = i as f64;
                DVec3::new(t.sin() * 5.0, (t * 0.7).cos() * 2.0, (t * 1.3).sin())
            })
            .collect();
        let b = OrientedBox::from_points_with_axes(axes, pts.iter().copied()).unwrap();
        let s = b.bounding_sphere();
        for p in &pts {
            assert!(b.contains(*p, 1e-9));
        }
        for c in b.corners() {
            assert!(c.distance(s.centre) <= s.radius + 1e-9);
        }
    }

    #[test]
    fn plane_sides() {
        let b = OrientedBox::from_points_with_axes(
            DMat3::IDENTITY,
            [DVec3::splat(-1.0), DVec3::splat(1.0)],
        )
        .unwrap();
        let p = Plane::new(DVec3::X, -5.0); // x >= 5 is inside
        assert_eq!(b.intersect_plane(&p), Intersection::Outside);
        let p = Plane::new(DVec3::X, 5.0); // x >= -5
        assert_eq!(b.intersect_plane(&p), Intersection::Inside);
        let p = Plane::new(DVec3::X, 0.5);
        assert_eq!(b.intersect_plane(&p), Intersection::Intersecting);
    }
}
