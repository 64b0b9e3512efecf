//! Horizon culling against an ellipsoid, after Cesium's `EllipsoidalOccluder`
//! (K. Ring, "Horizon Culling", cesium.com blog, 2013, and Cesium's implementation).
//!
//! Everything happens in *scaled space*, where the occluding ellipsoid becomes the unit sphere.
//! A tile is summarised by one *horizon culling point*: a point in scaled space, in the
//! direction of the tile, so far out that whenever it is hidden behind the unit sphere, every
//! point of the tile is hidden too. The test per tile is then a handful of multiplications.
//!
//! The occluder must be a body that really is solid: use the ellipsoid grown (or shrunk) by the
//! lowest height the terrain can have, so that no terrain is ever below it. Points below the
//! occluder's surface are treated as if they were on it, which only makes culling rarer: the
//! test is conservative and never culls anything visible.

use glam::DVec3;

use crate::Ellipsoid;

/// Horizon test for one camera position against one occluding ellipsoid.
#[derive(Clone, Copy, Debug, PartialEq)]
pub struct EllipsoidalOccluder {
    inv_radii: DVec3,
    camera_scaled: DVec3,
    /// `|camera_scaled|^2 - 1`: squared distance to the horizon in scaled space; negative
    /// when the camera is inside the occluder.
    vh_mag_sq: f64,
}

impl EllipsoidalOccluder {
    /// The occluder `body` seen from `camera_position` (ECEF metres).
    pub fn new(body: &Ellipsoid, camera_position: DVec3) -> Self {
        let inv_radii = DVec3::ONE / body.radii();
        let camera_scaled = camera_position * inv_radii;
        Self {
            inv_radii,
            camera_scaled,
            vh_mag_sq: camera_scaled.length_squared() - 1.0,
        }
    }

    /// Whether an ECEF point may be visible (not hidden behind the body).
    pub fn is_point_visible(&self, point: DVec3) -> bool {
        self.is_scaled_point_visible(point * self.inv_radii)
    }

    /// Whether a point given in scaled space (a horizon culling point) may be visible.
    pub fn is_scaled_point_visible(&self, scaled: DVec3) -> bool {
        if self.vh_mag_sq <= 0.0 {
            // The camera is inside the occluder: it cannot be trusted to hide anything.
            return true;
        }
        let vt = scaled - self.camera_scaled;
        let vt_dot_vc = -vt.dot(self.camera_scaled);
        let occluded = vt_dot_vc > self.vh_mag_sq
            && vt_dot_vc * vt_dot_vc / vt.length_squared() > self.vh_mag_sq;
        !occluded
    }

    /// The horizon culling point of a set of ECEF `points`, in the scaled space of `body`,
    /// along the scaled direction of `direction` (usually the tile's centre).
    ///
    /// `None` when no finite point works (the set spans too much of the body, for example a
    /// level-0 tile); such tiles are simply never horizon-culled.
    pub fn horizon_culling_point(
        body: &Ellipsoid,
        direction: DVec3,
        points: impl IntoIterator<Item = DVec3>,
    ) -> Option<DVec3> {
        let inv_radii = DVec3::ONE / body.radii();
        let scaled_dir = (direction * inv_radii).try_normalize()?;
        let mut magnitude: f64 = 0.0;
        for p in points {
            let m = required_magnitude(p * inv_radii, scaled_dir)?;
            magnitude = magnitude.max(m);
        }
        (magnitude > 0.0 && magnitude.is_finite()).then_some(scaled_dir * magnitude)
    }
}

/// How far along `scaled_dir` a point must be so that it sees the same horizon cone as
/// `scaled` (both in scaled space). `None` if no point in that direction does.
fn required_magnitude(scaled: DVec3, scaled_dir: DVec3) -> Option<f64> {
    let mag_sq = scaled.length_squared();
    let mag = mag_sq.sqrt();
    let direction = scaled / mag;
    if !direction.is_finite() {
        return None;
    }
    // Points under the surface are hidden whenever their surface point is; using the surface
    // point instead keeps the test conservative.
    let mag_sq = mag_sq.max(1.0);
    let mag = mag.max(1.0);
    let cos_alpha = direction.dot(scaled_dir);
    let sin_alpha = direction.cross(scaled_dir).length();
    let cos_beta = 1.0 / mag;
    let sin_beta = (mag_sq - 1.0).sqrt() * cos_beta;
    let denom = cos_alpha * cos_beta - sin_alpha * sin_beta;
    (denom > 1e-12).then(|| 1.0 / denom)
}

#[cfg(test)]
mod tests {
    use super::*;
    use crate::Cartographic;

    /// Ground truth: the segment from the eye to `p` does not pass through the body.
    fn line_of_sight(body: &Ellipsoid, eye: DVec3, p: DVec3) -> bool {
        match body.intersect_ray(eye, p - eye) {
            None => true,
            Some((t0, t1)) => t1 <= 1e-9 || t0 >= 1.0 - 1e-9,
        }
    }

    #[test]
    fn far_side_point_is_hidden_near_side_visible() {
        let e = Ellipsoid::WGS84;
        let eye = DVec3::new(20_000_000.0, 0.0, 0.0);
        let occ = EllipsoidalOccluder::new(&e, eye);
        assert!(occ.is_point_visible(DVec3::new(6_400_000.0, 0.0, 0.0)));
        assert!(!occ.is_point_visible(DVec3::new(-6_400_000.0, 0.0, 0.0)));
    }

    #[test]
    fn level_zero_sized_sets_have_no_point() {
        let e = Ellipsoid::WGS84;
        let pts = [
            e.cartographic_to_ecef(Cartographic::from_degrees(-180.0, 0.0, 0.0)),
            e.cartographic_to_ecef(Cartographic::from_degrees(0.0, 0.0, 0.0)),
        ];
        assert!(EllipsoidalOccluder::horizon_culling_point(&e, DVec3::NEG_Y, pts).is_none());
    }

    mod conservative {
        use super::*;
        use proptest::prelude::*;

        proptest! {
            #![proptest_config(ProptestConfig::with_cases(2000))]
            /// A patch of surface points around a random centre, seen from a random camera:
            /// whenever any point of the patch has a line of sight, the patch is not culled.
            #[test]
            fn never_culls_a_visible_point(
                cam_lon in -180.0f64..180.0, cam_lat in -90.0f64..90.0,
                cam_h in 1.0f64..4e7,
                lon in -180.0f64..180.0, lat in -89.0f64..89.0,
                size_deg in 0.0001f64..20.0,
                heights in proptest::collection::vec(0.0f64..9000.0, 9),
            ) {
                let body = Ellipsoid::WGS84;
                let eye = body.cartographic_to_ecef(Cartographic::from_degrees(cam_lon, cam_lat, cam_h));
                let pts: Vec<DVec3> = (0..9).map(|i| {
                    let (u, v) = ((i % 3) as f64 - 1.0, (i / 3) as f64 - 1.0);
                    body.cartographic_to_ecef(Cartographic::from_degrees(
                        lon + u * size_deg * 0.5, (lat + v * size_deg * 0.5).clamp(-90.0, 90.0), heights[i]))
                }).collect();
                let centre = body.cartographic_to_ecef(Cartographic::from_degrees(lon, lat, 0.0));
                let occ = EllipsoidalOccluder::new(&body, eye);
                if let Some(hp) = EllipsoidalOccluder::horizon_culling_point(&body, centre, pts.iter().copied()) {
                    let any_visible = pts.iter().any(|p| line_of_sight(&body, eye, *p));
                    if any_visible {
                        prop_assert!(occ.is_scaled_point_visible(hp));
                    }
                }
                for p in &pts {
                    if line_of_sight(&body, eye, *p) {
                        prop_assert!(occ.is_point_visible(*p));
                    }
                }
            }
        }
    }
}
