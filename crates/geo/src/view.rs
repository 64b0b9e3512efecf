//! A camera in f64 ECEF: position, orientation, vertical field of view and viewport.
//!
//! Conventions (as in Cesium): heading is clockwise from north, pitch is 0 at the local horizon
//! and -90 degrees looking straight down, and the camera looks along its local -Z with +Y up.

use glam::{DMat3, DQuat, DVec3};

use crate::{Cartographic, Ellipsoid};

/// What a frame sees: the eye and its orientation in ECEF (f64), the vertical field of view
/// and the viewport size in pixels.
#[derive(Clone, Copy, Debug, PartialEq)]
pub struct View {
    /// Eye position, ECEF metres.
    pub position: DVec3,
    /// Rotation from camera space (looks along -Z, +Y up, +X right) to ECEF.
    pub orientation: DQuat,
    /// Vertical field of view, radians.
    pub fov_y_rad: f64,
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
            width_px,
            height_px,
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

    /// Pixels per unit of `size / distance`: multiply a geometric error by this and divide by
    /// the distance to get its screen-space error in pixels,
    /// `error * height / (distance * 2 tan(fov_y / 2))`.
    pub fn sse_factor(&self) -> f64 {
        f64::from(self.height_px) / (2.0 * (self.fov_y_rad * 0.5).tan())
    }

    /// The unit direction of the ray through pixel coordinates (`x` right, `y` down, in
    /// pixels from the top-left corner; pixel centres are at `i + 0.5`).
    pub fn ray_direction(&self, x_px: f64, y_px: f64) -> DVec3 {
        let ty = (self.fov_y_rad * 0.5).tan();
        let ndc_x = x_px / f64::from(self.width_px) * 2.0 - 1.0;
        let ndc_y = 1.0 - y_px / f64::from(self.height_px) * 2.0;
        let local = DVec3::new(ndc_x * ty * self.aspect(), ndc_y * ty, -1.0);
        (self.orientation * local).normalize()
    }

    /// Projects an ECEF point to pixel coordinates (same convention as [`View::ray_direction`]).
    /// `None` if the point is behind the eye.
    pub fn project(&self, point: DVec3) -> Option<(f64, f64)> {
        let local = self.orientation.inverse() * (point - self.position);
        if local.z >= 0.0 {
            return None;
        }
        let ty = (self.fov_y_rad * 0.5).tan();
        let ndc_x = local.x / (-local.z * ty * self.aspect());
        let ndc_y = local.y / (-local.z * ty);
        Some((
            (ndc_x + 1.0) * 0.5 * f64::from(self.width_px),
            (1.0 - ndc_y) * 0.5 * f64::from(self.height_px),
        ))
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
