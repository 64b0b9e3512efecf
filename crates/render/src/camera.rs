//! [`FrameCamera`]: the camera one frame is drawn with, for camera-relative rendering with
//! reversed-Z and an infinite far plane.
//!
//! The origin of everything drawn is the eye, in f64 ECEF. The view matrix holds only the
//! camera's rotation: positions reach the GPU already relative to the eye (subtracted in f64,
//! then rounded to f32), so no matrix ever contains a planet-sized translation and nothing
//! drawn through this camera jitters, at 1 m above the ground or anywhere else.
//! The projection maps view depth `z` (negative in front) to `near / -z`: 1 at the near
//! plane, approaching 0 at infinity, which spreads f32 depth precision evenly in log space.
//! An orthographic view ([`globus_geo::Projection::Orthographic`]) cannot divide by the depth:
//! its depth is linear, `(far - d) / (far - near)` (still 1 at the near plane and nearer is
//! greater), over a far plane the caller sets as tight as it can ([`FrameCamera::with_far_m`]),
//! and its clip `w` is 1.
//!
//! ```text
//!  world (f64 ECEF) ──(− origin, f64, then f32)──> eye-relative ──view──> camera ──proj──> clip
//! ```

use glam::{DMat4, DVec2, DVec3, DVec4, Mat4, Vec3};
use globus_geo::View;

/// The camera of one frame: origin, matrices, near plane and viewport.
#[derive(Clone, Copy, Debug, PartialEq)]
pub struct FrameCamera {
    view: View,
    near_m: f64,
    /// Far plane of an orthographic view, metres (infinite for a perspective).
    far_m: f64,
    /// Projection * camera-from-world rotation, f64.
    clip_from_eye: DMat4,
}

impl FrameCamera {
    /// The camera of `view` with the near plane at `near_m` metres. An orthographic view
    /// gets its far plane past the plane through the world's origin (a body's centre) square
    /// to the view, by 2 % of the eye's distance from it: all of a body's near side the view
    /// looks at. [`FrameCamera::with_far_m`] sets a tighter one.
    pub fn new(view: &View, near_m: f64) -> Self {
        let centre_depth = -view.position.dot(view.forward());
        let far_m = centre_depth.max(0.0) + 0.02 * view.position.length() + near_m + 1.0;
        Self::with_far_m(view, near_m, far_m)
    }

    /// The camera of `view` with the near plane at `near_m` and, for an orthographic view,
    /// the far plane at `far_m` metres (its depth resolution is about `far_m * 6e-8`;
    /// nothing beyond it is drawn). A perspective's far plane is always at infinity.
    pub fn with_far_m(view: &View, near_m: f64, far_m: f64) -> Self {
        let camera_from_world = DMat4::from_quat(view.orientation.inverse());
        let far_m = if view.ortho_height_m().is_some() {
            far_m.max(near_m * 2.0 + 1.0)
        } else {
            f64::INFINITY
        };
        Self {
            view: *view,
            near_m,
            far_m,
            clip_from_eye: projection(view, near_m, far_m) * camera_from_world,
        }
    }

    /// Whether the projection is orthographic (depth linear between the near and far planes).
    pub fn is_orthographic(&self) -> bool {
        self.view.ortho_height_m().is_some()
    }

    /// The far plane, metres: infinite for a perspective.
    pub fn far_m(&self) -> f64 {
        self.far_m
    }

    /// The depth-buffer value (reversed-Z) of something `distance_m` in front of the eye
    /// along the view axis.
    pub fn depth_at(&self, distance_m: f64) -> f64 {
        if self.is_orthographic() {
            (self.far_m - distance_m) / (self.far_m - self.near_m)
        } else {
            self.near_m / distance_m
        }
    }

    /// How many pixels one metre across the view spans `distance_m` in front of the eye
    /// ([`View::pixels_per_metre`]).
    pub fn pixels_per_metre(&self, distance_m: f64) -> f64 {
        self.view.pixels_per_metre(distance_m)
    }

    /// The view it was made from (eye, orientation, field of view, viewport).
    pub fn view(&self) -> &View {
        &self.view
    }

    /// The camera-relative origin: the eye, ECEF metres. Everything drawn is placed relative
    /// to it ([`FrameCamera::relative`]).
    pub fn origin(&self) -> DVec3 {
        self.view.position
    }

    /// Distance of the near plane, metres.
    pub fn near_m(&self) -> f64 {
        self.near_m
    }

    /// Viewport width and height, pixels.
    pub fn viewport_px(&self) -> (u32, u32) {
        (self.view.width_px, self.view.height_px)
    }

    /// `world - origin` computed in f64 and rounded once to f32: the only way a world point
    /// should reach a shader.
    pub fn relative(&self, world: DVec3) -> Vec3 {
        (world - self.view.position).as_vec3()
    }

    /// The view matrix: camera-from-world rotation only (it applies to eye-relative offsets).
    pub fn view_matrix(&self) -> Mat4 {
        DMat4::from_quat(self.view.orientation.inverse()).as_mat4()
    }

    /// The projection: reversed-Z (1 at the near plane), infinite far plane, for a 32-bit
    /// float depth buffer compared with `Greater`.
    pub fn projection_matrix(&self) -> Mat4 {
        projection(&self.view, self.near_m, self.far_m).as_mat4()
    }

    /// Projection times view: eye-relative offsets (ECEF axes) to clip space. What the
    /// terrain shader uses; overlays multiply [`FrameCamera::relative`] positions by it.
    pub fn clip_from_eye(&self) -> Mat4 {
        self.clip_from_eye.as_mat4()
    }

    /// The inverse of [`FrameCamera::clip_from_eye`]: clip space to eye-relative direction.
    pub fn eye_from_clip(&self) -> Mat4 {
        self.clip_from_eye.inverse().as_mat4()
    }

    /// Where a world point is drawn, in pixels from the top-left corner (`x` right, `y`
    /// down; pixel centres at `i + 0.5`), and its depth in the reversed-Z depth buffer.
    /// `None` for points behind the near plane.
    pub fn project_with_depth(&self, world: DVec3) -> Option<(DVec2, f64)> {
        let offset = world - self.view.position;
        let clip = self.clip_from_eye * DVec4::new(offset.x, offset.y, offset.z, 1.0);
        if clip.w <= 0.0 {
            return None;
        }
        let ndc = clip.truncate() / clip.w;
        if ndc.z > 1.0 {
            return None;
        }
        let (w, h) = (
            f64::from(self.view.width_px),
            f64::from(self.view.height_px),
        );
        Some((
            DVec2::new((ndc.x + 1.0) * 0.5 * w, (1.0 - ndc.y) * 0.5 * h),
            ndc.z,
        ))
    }

    /// Where a world point is drawn, in pixels (see [`FrameCamera::project_with_depth`]).
    pub fn project(&self, world: DVec3) -> Option<DVec2> {
        self.project_with_depth(world).map(|(px, _)| px)
    }

    /// The unit direction of the ray through a pixel position (same convention).
    pub fn ray_direction(&self, x_px: f64, y_px: f64) -> DVec3 {
        self.view.ray_direction(x_px, y_px)
    }

    /// The ray through a pixel position: origin and unit direction ([`View::ray`]).
    pub fn ray(&self, x_px: f64, y_px: f64) -> (DVec3, DVec3) {
        self.view.ray(x_px, y_px)
    }

    /// The world point at pixel (`x_px`, `y_px`) whose reversed-Z depth is `depth` (as read
    /// from the depth buffer). `None` for depth 0 (nothing drawn there: infinitely far, or
    /// at an orthographic view's far plane).
    pub fn unproject(&self, x_px: f64, y_px: f64, depth: f64) -> Option<DVec3> {
        if depth.is_nan() || depth <= 0.0 {
            return None;
        }
        let (origin, dir) = self.ray(x_px, y_px);
        if self.is_orthographic() {
            let along_axis = self.far_m - depth * (self.far_m - self.near_m);
            return Some(origin + dir * along_axis);
        }
        // depth = near / distance along the view axis.
        let along_axis = self.near_m / depth;
        let cos = dir.dot(self.view.forward());
        (cos > 0.0).then(|| origin + dir * (along_axis / cos))
    }
}

fn projection(view: &View, near_m: f64, far_m: f64) -> DMat4 {
    let aspect = view.aspect();
    if let Some(height_m) = view.ortho_height_m() {
        // x, y: the visible rectangle to -1..1; z: 1 at the near plane, 0 at the far one.
        let (sx, sy) = (2.0 / (height_m * aspect), 2.0 / height_m);
        let range = far_m - near_m;
        return DMat4::from_cols(
            DVec4::new(sx, 0.0, 0.0, 0.0),
            DVec4::new(0.0, sy, 0.0, 0.0),
            DVec4::new(0.0, 0.0, 1.0 / range, 0.0),
            DVec4::new(0.0, 0.0, far_m / range, 1.0),
        );
    }
    let f = 1.0 / (view.fov_y_rad * 0.5).tan();
    DMat4::from_cols(
        DVec4::new(f / aspect, 0.0, 0.0, 0.0),
        DVec4::new(0.0, f, 0.0, 0.0),
        DVec4::new(0.0, 0.0, 0.0, -1.0),
        DVec4::new(0.0, 0.0, near_m, 0.0),
    )
}

/// A near plane for a camera `height_above_ground_m` above the terrain: a fifth of that
/// height (so the ground is never clipped) between 1 cm and `cap_m`. With reversed-Z in a
/// float buffer and a 0..1 depth range (Vulkan, Metal, Direct3D) the depth precision is
/// relative to the distance whatever the near plane (depth is `near / distance`, and floats
/// are as fine at 1e-9 as at 1), so [`NEAR_PLANE_CAP_M`] keeps it small and overlays a few
/// metres from the eye are drawn at any altitude. OpenGL's -1..1 depth range moves depth
/// next to -1, where floats are coarse: there the near plane must grow with the height
/// ([`NEAR_PLANE_CAP_GL_M`]).
pub fn near_plane_m(height_above_ground_m: f64, cap_m: f64) -> f64 {
    (height_above_ground_m * 0.2).clamp(0.01, cap_m.max(0.01))
}

/// Largest near plane with a 0..1 depth range, metres.
pub const NEAR_PLANE_CAP_M: f64 = 1.0;

/// Largest near plane on OpenGL, metres.
pub const NEAR_PLANE_CAP_GL_M: f64 = 10_000.0;

#[cfg(test)]
mod tests {
    use super::*;
    use glam::Vec4;
    use globus_geo::{Cartographic, Ellipsoid};

    fn view_at(lon: f64, lat: f64, h: f64) -> View {
        View::from_geodetic(
            &Ellipsoid::WGS84,
            Cartographic::from_degrees(lon, lat, h),
            0.4,
            -0.3,
            60f64.to_radians(),
            800,
            600,
        )
    }

    #[test]
    fn reversed_z_maps_near_to_one_and_far_towards_zero() {
        let view = view_at(7.6, 46.0, 1.0);
        let camera = FrameCamera::new(&view, 0.5);
        let m = camera.clip_from_eye();
        let depth = |d: f64| {
            let p = (view.forward() * d).as_vec3();
            let c = m * Vec4::new(p.x, p.y, p.z, 1.0);
            c.z / c.w
        };
        assert!((depth(0.5) - 1.0).abs() < 1e-5);
        assert!(depth(1.0e7) > 0.0 && depth(1.0e7) < 1e-6);
        // Ground at 1 m and 1.001 m get distinct depths (no z-fighting at 1 m altitude).
        assert!(depth(1.0) > depth(1.001));
        // And the limb, 10,000 km away, is still in front of infinity.
        assert!(depth(1.0e7) > depth(1.001e7));
        // The product of the public matrices is the one the shaders get.
        let product = camera.projection_matrix() * camera.view_matrix();
        assert!(product.abs_diff_eq(m, 1e-6), "{product} vs {m}");
    }

    #[test]
    fn projection_agrees_with_the_view_and_depth_unprojects() {
        let view = view_at(-71.0, -89.99, 1.0);
        let camera = FrameCamera::new(&view, 0.2);
        for (x, y, d) in [
            (10.5, 20.25, 3.0),
            (400.0, 300.0, 1234.5),
            (799.0, 1.0, 2e6),
        ] {
            let world = view.position + view.ray_direction(x, y) * d;
            let (px, depth) = camera.project_with_depth(world).expect("in front");
            let by_view = view.project(world).expect("in front");
            assert!((px.x - x).abs() < 1e-6 && (px.y - y).abs() < 1e-6, "{px}");
            assert!((px.x - by_view.0).abs() < 1e-6 && (px.y - by_view.1).abs() < 1e-6);
            let back = camera.unproject(x, y, depth).expect("depth > 0");
            assert!((back - world).length() < 1e-6 * d, "{back} vs {world}");
        }
        // Behind the eye: not drawn.
        assert!(camera.project(view.position - view.forward()).is_none());
        assert!(camera.unproject(1.0, 1.0, 0.0).is_none());
    }

    #[test]
    fn orthographic_depth_is_linear_and_unprojects() {
        let view = View::from_geodetic(
            &Ellipsoid::WGS84,
            Cartographic::from_degrees(8.5, 47.4, 50_000.0),
            0.2,
            -std::f64::consts::FRAC_PI_2,
            1.0,
            800,
            600,
        )
        .orthographic(40_000.0);
        let camera = FrameCamera::with_far_m(&view, 1.0, 80_001.0);
        assert!(camera.is_orthographic());
        assert!((camera.depth_at(1.0) - 1.0).abs() < 1e-12);
        assert!(camera.depth_at(80_001.0).abs() < 1e-12);
        for (x, y, d) in [
            (0.5, 0.5, 2.0),
            (400.0, 300.0, 50_000.0),
            (799.5, 10.0, 79_000.0),
        ] {
            let (origin, dir) = view.ray(x, y);
            let world = origin + dir * d;
            let (px, depth) = camera.project_with_depth(world).expect("in front");
            assert!((px.x - x).abs() < 1e-6 && (px.y - y).abs() < 1e-6, "{px}");
            assert!((depth - camera.depth_at(d)).abs() < 1e-12, "{depth}");
            let back = camera.unproject(x, y, depth).expect("depth > 0");
            assert!((back - world).length() < 1e-6, "{back} vs {world}");
        }
        // The shaders' f32 matrix agrees: the pixel does not move with depth.
        let m = camera.clip_from_eye();
        let (origin, dir) = view.ray(600.0, 150.0);
        for d in [10.0f64, 60_000.0] {
            let p = (origin + dir * d - view.position).as_vec3();
            let c = m * Vec4::new(p.x, p.y, p.z, 1.0);
            assert!((c.w - 1.0).abs() < 1e-6);
            assert!((c.x - 0.5).abs() < 1e-5 && (c.y - 0.5).abs() < 1e-5, "{c}");
        }
        // The default far plane holds the near side of the Earth.
        let wide = FrameCamera::new(&view.orthographic(1.2e7), 1.0);
        assert!(
            wide.far_m() > 6.4e6 && wide.far_m() < 6.7e6,
            "{}",
            wide.far_m()
        );
    }
}
