//! Frustum planes of a [`View`] and culling tests against them.
//!
//! The far plane is at infinity (the renderer uses reversed-Z with an infinite far plane), so
//! a frustum has five planes: near, left, right, bottom, top. Plane normals point inwards.
//! An orthographic view's frustum is a box open at the far end: its side planes are parallel
//! to the view direction.

use glam::DVec3;

use crate::{BoundingSphere, OrientedBox, View};

/// Where a volume lies relative to a plane or frustum.
#[derive(Clone, Copy, Debug, PartialEq, Eq)]
pub enum Intersection {
    /// Entirely on the outer (culled) side.
    Outside,
    /// Crosses the boundary.
    Intersecting,
    /// Entirely on the inner side.
    Inside,
}

/// A plane `normal . p + d = 0`; points with positive signed distance are "inside".
#[derive(Clone, Copy, Debug, PartialEq)]
pub struct Plane {
    /// Unit normal, pointing to the inside.
    pub normal: DVec3,
    /// Offset: `-normal . point_on_plane`.
    pub d: f64,
}

impl Plane {
    /// A plane from its unit normal and offset.
    pub const fn new(normal: DVec3, d: f64) -> Self {
        Self { normal, d }
    }

    /// The plane through `point` with unit `normal`.
    pub fn from_point_normal(point: DVec3, normal: DVec3) -> Self {
        Self {
            normal,
            d: -normal.dot(point),
        }
    }

    /// Signed distance of `p`, positive inside.
    pub fn signed_distance(&self, p: DVec3) -> f64 {
        self.normal.dot(p) + self.d
    }
}

/// The five planes (near, left, right, bottom, top) of a view with an infinite far plane.
#[derive(Clone, Copy, Debug, PartialEq)]
pub struct Frustum {
    /// Near, left, right, bottom, top; normals point inwards.
    pub planes: [Plane; 5],
}

impl Frustum {
    /// The frustum of `view` with the near plane `near_m` metres in front of the eye.
    pub fn from_view(view: &View, near_m: f64) -> Self {
        if let Some(height_m) = view.ortho_height_m() {
            let (hx, hy) = (0.5 * height_m * view.aspect(), 0.5 * height_m);
            let rot = view.orientation;
            let eye = view.position;
            let (right, up, forward) = (rot * DVec3::X, rot * DVec3::Y, rot * DVec3::NEG_Z);
            return Self {
                planes: [
                    Plane::from_point_normal(eye + forward * near_m, forward),
                    Plane::from_point_normal(eye - right * hx, right),
                    Plane::from_point_normal(eye + right * hx, -right),
                    Plane::from_point_normal(eye - up * hy, up),
                    Plane::from_point_normal(eye + up * hy, -up),
                ],
            };
        }
        let ty = (view.fov_y_rad * 0.5).tan();
        let tx = ty * view.aspect();
        let rot = view.orientation;
        let eye = view.position;
        // Inward normals in camera space (camera looks along -Z, +Y up, +X right).
        let local = [
            DVec3::new(0.0, 0.0, -1.0),
            DVec3::new(1.0, 0.0, -tx),
            DVec3::new(-1.0, 0.0, -tx),
            DVec3::new(0.0, 1.0, -ty),
            DVec3::new(0.0, -1.0, -ty),
        ];
        let planes = local.map(|n| {
            let normal = rot * n.normalize();
            Plane::from_point_normal(eye, normal)
        });
        let mut frustum = Self { planes };
        frustum.planes[0].d -= near_m;
        frustum
    }

    /// Classifies an oriented box against all planes.
    pub fn intersect_box(&self, b: &OrientedBox) -> Intersection {
        let mut all_inside = true;
        for plane in &self.planes {
            match b.intersect_plane(plane) {
                Intersection::Outside => return Intersection::Outside,
                Intersection::Intersecting => all_inside = false,
                Intersection::Inside => {}
            }
        }
        if all_inside {
            Intersection::Inside
        } else {
            Intersection::Intersecting
        }
    }

    /// Classifies a sphere against all planes.
    pub fn intersect_sphere(&self, s: &BoundingSphere) -> Intersection {
        let mut all_inside = true;
        for plane in &self.planes {
            match s.intersect_plane(plane) {
                Intersection::Outside => return Intersection::Outside,
                Intersection::Intersecting => all_inside = false,
                Intersection::Inside => {}
            }
        }
        if all_inside {
            Intersection::Inside
        } else {
            Intersection::Intersecting
        }
    }

    /// Whether a box is wholly outside the frustum, given a sphere that contains it: the
    /// sphere settles each plane it is wholly inside or outside of, and only the planes it
    /// straddles are tested with the box (the box's test costs four dot products a plane,
    /// the sphere's one). The answer is the box's own: a box inside its sphere is outside a
    /// plane only where the sphere is not wholly inside it.
    pub fn culls(&self, s: &BoundingSphere, b: &OrientedBox) -> bool {
        self.planes
            .iter()
            .any(|plane| match s.intersect_plane(plane) {
                Intersection::Outside => true,
                Intersection::Inside => false,
                Intersection::Intersecting => b.intersect_plane(plane) == Intersection::Outside,
            })
    }

    /// Whether a point is inside all planes.
    pub fn contains_point(&self, p: DVec3) -> bool {
        self.planes.iter().all(|pl| pl.signed_distance(p) >= 0.0)
    }
}

#[cfg(test)]
mod tests {
    use super::*;
    use crate::{Cartographic, Ellipsoid};
    use glam::DMat3;

    fn view() -> View {
        View::from_geodetic(
            &Ellipsoid::WGS84,
            Cartographic::from_degrees(7.6, 46.0, 10_000.0),
            0.0,
            0.0,
            60f64.to_radians(),
            1920,
            1080,
        )
    }

    #[test]
    fn point_ahead_is_inside_and_behind_is_outside() {
        let v = view();
        let f = Frustum::from_view(&v, 1.0);
        assert!(f.contains_point(v.position + v.forward() * 100.0));
        assert!(!f.contains_point(v.position - v.forward() * 100.0));
        assert!(!f.contains_point(v.position + v.forward() * 0.5));
        // 29 degrees up is inside a 60 degree vertical field of view, 31 is not.
        for (deg, inside) in [(29.0f64, true), (31.0, false)] {
            let dir = v.forward() * deg.to_radians().cos() + v.up() * deg.to_radians().sin();
            assert_eq!(f.contains_point(v.position + dir * 1e4), inside, "{deg}");
        }
    }

    #[test]
    fn orthographic_frustum_is_a_box_along_the_view() {
        let v = view().orthographic(2_000.0);
        let f = Frustum::from_view(&v, 1.0);
        // 1920x1080: the box is 3,555.6 m wide and 2,000 m high, at any depth.
        for depth in [10.0, 1e5, 1e7] {
            let ahead = v.position + v.forward() * depth;
            assert!(f.contains_point(ahead + v.right() * 1_770.0 + v.up() * 990.0));
            assert!(!f.contains_point(ahead + v.right() * 1_785.0));
            assert!(!f.contains_point(ahead - v.up() * 1_010.0));
        }
        assert!(!f.contains_point(v.position + v.forward() * 0.5));
    }

    /// `culls` gives the box's own answer, over boxes of every size and orientation
    /// around the frustum's edges.
    #[test]
    fn culling_with_the_sphere_first_is_the_box_test() {
        let v = view();
        let f = Frustum::from_view(&v, 1.0);
        // A small deterministic generator (xorshift), uniform in [-1, 1).
        let mut state = 0x9e37_79b9_7f4a_7c15u64;
        let mut r = || {
            state ^= state << 13;
            state ^= state >> 7;
            state ^= state << 17;
            (state >> 11) as f64 / (1u64 << 52) as f64 - 1.0
        };
        let (mut culled, mut kept) = (0, 0);
        for _ in 0..20_000 {
            let centre = v.position
                + v.forward() * (r() * 3_000.0 + 2_000.0)
                + v.right() * r() * 3_000.0
                + v.up() * r() * 2_000.0;
            let axes = DMat3::from_euler(glam::EulerRot::XYZ, r() * 3.2, r() * 3.2, r() * 3.2);
            let half_extents = DVec3::new(r(), r(), r()).abs() * 800.0 + DVec3::splat(1.0);
            let b = OrientedBox {
                centre,
                axes,
                half_extents,
            };
            let s = BoundingSphere {
                centre,
                radius: half_extents.length() * (1.0 + r().abs()),
            };
            let want = f.intersect_box(&b) == Intersection::Outside;
            assert_eq!(f.culls(&s, &b), want, "{b:?} in {s:?}");
            if want {
                culled += 1;
            } else {
                kept += 1;
            }
        }
        assert!(
            culled > 2_000 && kept > 2_000,
            "{culled} culled, {kept} kept"
        );
    }

    #[test]
    fn box_straddling_side_plane_intersects() {
        let v = view();
        let f = Frustum::from_view(&v, 1.0);
        let centre = v.position + v.forward() * 1000.0;
        let inside = OrientedBox {
            centre,
            axes: DMat3::IDENTITY,
            half_extents: DVec3::splat(1.0),
        };
        assert_eq!(f.intersect_box(&inside), Intersection::Inside);
        let big = OrientedBox {
            centre,
            axes: DMat3::IDENTITY,
            half_extents: DVec3::splat(5000.0),
        };
        assert_eq!(f.intersect_box(&big), Intersection::Intersecting);
        let behind = OrientedBox {
            centre: v.position - v.forward() * 1000.0,
            axes: DMat3::IDENTITY,
            half_extents: DVec3::splat(10.0),
        };
        assert_eq!(f.intersect_box(&behind), Intersection::Outside);
    }
}
