//! A camera in f64 ECEF: position, orientation, projection and viewport.
//!
//! Conventions (as in Cesium): heading is clockwise from north, pitch is 0 at the local horizon
//! and -90 degrees looking straight down, and the camera looks along its local -Z with +Y up.
//!
//! The projection is a perspective (a vertical field of view) or orthographic (Kaiser's ATC
//! screen, 2.4.3: the height of the visible area in metres; zoom is that size, pan moves the
//! eye). An orthographic camera's rays are parallel: each pixel's ray starts on the eye's
//! plane ([`View::ray`]), and the size of a thing on the screen does not depend on its
//! distance ([`View::pixels_per_metre`]).

use glam::{DMat3, DQuat, DVec3};

use crate::{Cartographic, Ellipsoid};

/// How a [`View`] maps the world onto the screen.
#[derive(Clone, Copy, Debug, Default, PartialEq)]
pub enum Projection {
    /// Rays from the eye through each pixel, spread over [`View::fov_y_rad`].
    #[default]
    Perspective,
    /// Parallel rays along the view direction, from the eye's plane; the viewport shows
    /// `height_m` metres from its top to its bottom edge (the width follows the aspect).
    Orthographic {
        /// Height of the visible area, metres (positive).
        height_m: f64,
    },
}

/// What a frame sees: the eye and its orientation in ECEF (f64), the projection and the
/// viewport size in pixels.
#[derive(Clone, Copy, Debug, PartialEq)]
pub struct View {
    /// Eye position, ECEF metres.
    pub position: DVec3,
    /// Rotation from camera space (looks along -Z, +Y up, +X right) to ECEF.
    pub orientation: DQuat,
    /// Vertical field of view of the perspective, radians (kept, unused, while the
    /// projection is orthographic, so that switching back restores it).
    pub fov_y_rad: f64,
    /// Perspective or orthographic.
    pub projection: Projection,
    /// Viewport width, pixels.
    pub width_px: u32,
    /// Viewport height, pixels.
    pub height_px: u32,
}

impl View {
    /// A camera at a geodetic position looking along `heading_rad` (clockwise from north) and
    /// `pitch_rad` (0 at the horizon, -pi/2 straight down).
    pub fn from_geodetic(
        ellipsoid: &Ellipsoid,
        at: Cartographic,
        heading_rad: f64,
        pitch_rad: f64,
        fov_y_rad: f64,
        width_px: u32,
        height_px: u32,
    ) -> Self {
        let position = ellipsoid.cartographic_to_ecef(at);
        let enu = ellipsoid.enu_frame(at.lon_rad, at.lat_rad);
        let orientation = orientation_from_heading_pitch(&enu, heading_rad, pitch_rad);
        Self {
            position,
            orientation,
            fov_y_rad,
            projection: Projection::Perspective,
            width_px,
            height_px,
        }
    }

    /// The same camera with an orthographic projection showing `height_m` metres from the
    /// top to the bottom of the viewport (at least 1 mm).
    pub fn orthographic(self, height_m: f64) -> Self {
        let height_m = if height_m.is_finite() {
            height_m.max(1e-3)
        } else {
            1e-3
        };
        Self {
            projection: Projection::Orthographic { height_m },
            ..self
        }
    }

    /// The same camera with a perspective projection (its `fov_y_rad`).
    pub fn perspective(self) -> Self {
        Self {
            projection: Projection::Perspective,
            ..self
        }
    }

    /// The height of the orthographic projection's visible area, metres; `None` for a
    /// perspective.
    pub fn ortho_height_m(&self) -> Option<f64> {
        match self.projection {
            Projection::Perspective => None,
            Projection::Orthographic { height_m } => Some(height_m),
        }
    }

    /// A camera at `eye` looking at `target` with `up` as the approximate up direction.
    /// `None` if the eye and target coincide or `up` is parallel to the view direction.
    pub fn look_at(
        eye: DVec3,
        target: DVec3,
        up: DVec3,
        fov_y_rad: f64,
        width_px: u32,
        height_px: u32,
    ) -> Option<Self> {
        let forward = (target - eye).try_normalize()?;
        let right = forward.cross(up).try_normalize()?;
        let cam_up = right.cross(forward);
        let rot = DMat3::from_cols(right, cam_up, -forward);
        Some(Self {
            position: eye,
            orientation: DQuat::from_mat3(&rot).normalize(),
            fov_y_rad,
            projection: Projection::Perspective,
            width_px,
            height_px,
        })
    }

    /// Unit view direction.
    pub fn forward(&self) -> DVec3 {
        self.orientation * DVec3::NEG_Z
    }

    /// Unit camera up.
    pub fn up(&self) -> DVec3 {
        self.orientation * DVec3::Y
    }

    /// Unit camera right.
    pub fn right(&self) -> DVec3 {
        self.orientation * DVec3::X
    }

    /// Width over height.
    pub fn aspect(&self) -> f64 {
        f64::from(self.width_px) / f64::from(self.height_px.max(1))
    }

    /// Pixels per unit of `size / distance` of the perspective: multiply a geometric error by
    /// this and divide by the distance to get its screen-space error in pixels,
    /// `error * height / (distance * 2 tan(fov_y / 2))`. Use
    /// [`View::pixels_per_metre`], which also knows the orthographic projection.
    pub fn sse_factor(&self) -> f64 {
        f64::from(self.height_px) / (2.0 * (self.fov_y_rad * 0.5).tan())
    }

    /// How many pixels one metre across the view spans `distance_m` in front of the eye
    /// (along the view axis): `sse_factor / distance` in perspective, the same everywhere in
    /// an orthographic view.
    pub fn pixels_per_metre(&self, distance_m: f64) -> f64 {
        match self.projection {
            Projection::Perspective => self.sse_factor() / distance_m.max(1e-9),
            Projection::Orthographic { height_m } => f64::from(self.height_px) / height_m,
        }
    }

    /// Normalised device coordinates (-1..1, `y` up) of pixel coordinates.
    fn ndc(&self, x_px: f64, y_px: f64) -> (f64, f64) {
        (
            x_px / f64::from(self.width_px) * 2.0 - 1.0,
            1.0 - y_px / f64::from(self.height_px) * 2.0,
        )
    }

    /// The ray through pixel coordinates (`x` right, `y` down, in pixels from the top-left
    /// corner; pixel centres are at `i + 0.5`): its origin and unit direction. A perspective
    /// ray starts at the eye; an orthographic one on the eye's plane, along the view.
    pub fn ray(&self, x_px: f64, y_px: f64) -> (DVec3, DVec3) {
        let (ndc_x, ndc_y) = self.ndc(x_px, y_px);
        match self.projection {
            Projection::Perspective => {
                let ty = (self.fov_y_rad * 0.5).tan();
                let local = DVec3::new(ndc_x * ty * self.aspect(), ndc_y * ty, -1.0);
                (self.position, (self.orientation * local).normalize())
            }
            Projection::Orthographic { height_m } => {
                let half_h = 0.5 * height_m;
                let local = DVec3::new(ndc_x * half_h * self.aspect(), ndc_y * half_h, 0.0);
                (self.position + self.orientation * local, self.forward())
            }
        }
    }

    /// The unit direction of the ray through pixel coordinates (see [`View::ray`], which
    /// also gives where an orthographic ray starts).
    pub fn ray_direction(&self, x_px: f64, y_px: f64) -> DVec3 {
        self.ray(x_px, y_px).1
    }

    /// Projects an ECEF point to pixel coordinates (same convention as [`View::ray`]).
    /// `None` if the point is behind the eye (behind its plane, orthographic).
    pub fn project(&self, point: DVec3) -> Option<(f64, f64)> {
        let local = self.orientation.inverse() * (point - self.position);
        if local.z >= 0.0 {
            return None;
        }
        let (ndc_x, ndc_y) = match self.projection {
            Projection::Perspective => {
                let ty = (self.fov_y_rad * 0.5).tan();
                (
                    local.x / (-local.z * ty * self.aspect()),
                    local.y / (-local.z * ty),
                )
            }
            Projection::Orthographic { height_m } => {
                let half_h = 0.5 * height_m;
                (local.x / (half_h * self.aspect()), local.y / half_h)
            }
        };
        Some((
            (ndc_x + 1.0) * 0.5 * f64::from(self.width_px),
            (1.0 - ndc_y) * 0.5 * f64::from(self.height_px),
        ))
    }

    /// Where the horizon is seen from: the eye for a perspective; for an orthographic view,
    /// a point a million body radii back along the view axis, from which the visible part of
    /// a body is its whole near side, as the parallel rays see it.
    pub fn occlusion_eye(&self) -> DVec3 {
        match self.projection {
            Projection::Perspective => self.position,
            Projection::Orthographic { .. } => {
                self.position - self.forward() * (self.position.length().max(1.0) * 1e6)
            }
        }
    }

    /// Heading (clockwise from north) and pitch (0 at the horizon) of the view direction at
    /// the camera's geodetic position, radians. `None` at the centre of the body.
    pub fn heading_pitch(&self, ellipsoid: &Ellipsoid) -> Option<(f64, f64)> {
        let enu = ellipsoid.enu_frame_at(self.position)?;
        let f = self.forward();
        let pitch = f.dot(enu.up).clamp(-1.0, 1.0).asin();
        // Looking straight up or down the heading is the direction of the camera's up vector.
        let h_dir = if pitch.abs() > 1.5 {
            self.up() * -pitch.signum()
        } else {
            f
        };
        let heading = h_dir.dot(enu.east).atan2(h_dir.dot(enu.north));
        Some((heading, pitch))
    }
}

/// The camera orientation for a heading and pitch in an east-north-up frame.
pub(crate) fn orientation_from_heading_pitch(
    enu: &crate::EnuFrame,
    heading_rad: f64,
    pitch_rad: f64,
) -> DQuat {
    let (sh, ch) = heading_rad.sin_cos();
    let (sp, cp) = pitch_rad.sin_cos();
    let horizontal = enu.north * ch + enu.east * sh;
    let forward = horizontal * cp + enu.up * sp;
    let right = enu.east * ch - enu.north * sh;
    let up = right.cross(forward);
    DQuat::from_mat3(&DMat3::from_cols(right, up, -forward)).normalize()
}

#[cfg(test)]
mod tests {
    use super::*;
    use approx::assert_relative_eq;

    #[test]
    fn heading_and_pitch_round_trip() {
        let e = Ellipsoid::WGS84;
        for (h, p) in [(0.0, 0.0), (90.0, -30.0), (-135.0, 45.0), (180.0, -89.0)] {
            let v = View::from_geodetic(
                &e,
                Cartographic::from_degrees(7.6, 46.0, 1000.0),
                f64::to_radians(h),
                f64::to_radians(p),
                1.0,
                100,
                100,
            );
            let (hh, pp) = v.heading_pitch(&e).unwrap();
            let dh = (hh.to_degrees() - h + 540.0).rem_euclid(360.0) - 180.0;
            assert!(dh.abs() < 1e-9, "{h} {p}: {}", hh.to_degrees());
            assert_relative_eq!(pp.to_degrees(), p, epsilon = 1e-9);
        }
    }

    #[test]
    fn heading_zero_looks_north_and_pitch_down_looks_at_centre() {
        let e = Ellipsoid::WGS84;
        let at = Cartographic::from_degrees(0.0, 0.0, 1000.0);
        let v = View::from_geodetic(&e, at, 0.0, 0.0, 1.0, 10, 10);
        assert_relative_eq!(v.forward().z, 1.0, epsilon = 1e-12);
        let down = View::from_geodetic(&e, at, 0.0, -std::f64::consts::FRAC_PI_2, 1.0, 10, 10);
        assert_relative_eq!(down.forward().x, -1.0, epsilon = 1e-12);
    }

    #[test]
    fn orthographic_rays_are_parallel_and_sizes_do_not_shrink() {
        let v = View::from_geodetic(
            &Ellipsoid::WGS84,
            Cartographic::from_degrees(7.6, 46.0, 50_000.0),
            0.4,
            -std::f64::consts::FRAC_PI_2,
            1.0,
            800,
            600,
        )
        .orthographic(30_000.0);
        // Corner rays start 20 km right / 15 km up of the eye (aspect 4:3) and all point
        // along the view.
        let (o, d) = v.ray(800.0, 0.0);
        assert_relative_eq!(d.dot(v.forward()), 1.0, epsilon = 1e-12);
        let off = o - v.position;
        assert_relative_eq!(off.dot(v.right()), 20_000.0, epsilon = 1e-6);
        assert_relative_eq!(off.dot(v.up()), 15_000.0, epsilon = 1e-6);
        // A point's pixel does not depend on its depth.
        for depth in [10.0, 1e4, 1e6] {
            let (x, y) = v.project(o + d * depth).unwrap();
            assert_relative_eq!(x, 800.0, epsilon = 1e-6);
            assert_relative_eq!(y, 0.0, epsilon = 1e-6);
        }
        assert!(v.project(o - d).is_none(), "behind the eye's plane");
        assert_relative_eq!(v.pixels_per_metre(1.0), 0.02);
        assert_relative_eq!(v.pixels_per_metre(1e6), 0.02);
        // Back to the same perspective.
        assert_eq!(v.perspective().ray(400.0, 300.0).0, v.position);
    }

    #[test]
    fn project_inverts_ray_direction() {
        let v = View::from_geodetic(
            &Ellipsoid::WGS84,
            Cartographic::from_degrees(7.6, 46.0, 1000.0),
            0.3,
            -0.2,
            1.0,
            640,
            480,
        );
        let dir = v.ray_direction(100.5, 400.25);
        let (x, y) = v.project(v.position + dir * 1234.0).unwrap();
        assert_relative_eq!(x, 100.5, epsilon = 1e-6);
        assert_relative_eq!(y, 400.25, epsilon = 1e-6);
    }
}
