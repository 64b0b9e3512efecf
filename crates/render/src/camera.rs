//! Camera matrices for camera-relative rendering with reversed-Z and an infinite far plane.
//!
//! The view matrix holds only the camera's rotation: positions reach the GPU already relative
//! to the eye (computed in f64), so the matrix never contains a planet-sized translation.
//! The projection maps view depth `z` (negative in front) to `near / -z`: 1 at the near plane,
//! approaching 0 at infinity, which spreads f32 depth precision evenly in log space.

use glam::{DMat4, DVec4, Mat4};
use globus_geo::View;

/// The two matrices the shaders use.
#[derive(Clone, Copy, Debug, PartialEq)]
pub struct CameraMatrices {
    /// Projection * camera-from-world rotation: eye-relative ECEF offset to clip space.
    pub clip_from_eye: Mat4,
    /// Its inverse: clip space to eye-relative direction.
    pub eye_from_clip: Mat4,
}

impl CameraMatrices {
    /// The matrices of `view` with the near plane at `near_m`.
    pub fn new(view: &View, near_m: f64) -> Self {
        let f = 1.0 / (view.fov_y_rad * 0.5).tan();
        let aspect = view.aspect();
        let projection = DMat4::from_cols(
            DVec4::new(f / aspect, 0.0, 0.0, 0.0),
            DVec4::new(0.0, f, 0.0, 0.0),
            DVec4::new(0.0, 0.0, 0.0, -1.0),
            DVec4::new(0.0, 0.0, near_m, 0.0),
        );
        let camera_from_world = DMat4::from_quat(view.orientation.inverse());
        let clip_from_eye = projection * camera_from_world;
        Self {
            clip_from_eye: clip_from_eye.as_mat4(),
            eye_from_clip: clip_from_eye.inverse().as_mat4(),
        }
    }
}

/// A near plane for a camera `height_above_ground_m` above the terrain: a fraction of that
/// height, so the ground is never clipped, between 1 cm and 10 km.
pub fn near_plane_m(height_above_ground_m: f64) -> f64 {
    (height_above_ground_m * 0.2).clamp(0.01, 10_000.0)
}

#[cfg(test)]
mod tests {
    use super::*;
    use glam::Vec4;
    use globus_geo::{Cartographic, Ellipsoid};

    #[test]
    fn reversed_z_maps_near_to_one_and_far_towards_zero() {
        let view = View::from_geodetic(
            &Ellipsoid::WGS84,
            Cartographic::from_degrees(7.6, 46.0, 1.0),
            0.0,
            0.0,
            60f64.to_radians(),
            800,
            600,
        );
        let m = CameraMatrices::new(&view, 0.5);
        let depth = |d: f64| {
            let p = (view.forward() * d).as_vec3();
            let c = m.clip_from_eye * Vec4::new(p.x, p.y, p.z, 1.0);
            c.z / c.w
        };
        assert!((depth(0.5) - 1.0).abs() < 1e-5);
        assert!(depth(1.0e7) > 0.0 && depth(1.0e7) < 1e-6);
        // Ground at 1 m and 1.001 m get distinct depths (no z-fighting at 1 m altitude).
        assert!(depth(1.0) > depth(1.001));
        // And the limb, 10,000 km away, is still in front of infinity.
        assert!(depth(1.0e7) > depth(1.001e7));
    }
}
