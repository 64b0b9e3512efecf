//! [`CameraSpec`]: a camera as people write it down (degrees, metres, heading and pitch).

use globus_geo::{Cartographic, View};

use crate::Globe;

/// A camera in the convention of the command line and of CesiumJS's `setView`: degrees,
/// metres, heading clockwise from north, pitch 0 at the horizon and -90 straight down.
#[derive(Clone, Copy, Debug, PartialEq)]
pub struct CameraSpec {
    /// Longitude, degrees.
    pub lon_deg: f64,
    /// Latitude, degrees.
    pub lat_deg: f64,
    /// Altitude, metres (above the ellipsoid, or above the ground if `above_ground`).
    pub alt_m: f64,
    /// Heading, degrees clockwise from north.
    pub heading_deg: f64,
    /// Pitch, degrees (0 horizon, -90 down).
    pub pitch_deg: f64,
    /// Whether `alt_m` is above the (drawn) ground under the camera.
    pub above_ground: bool,
}

impl CameraSpec {
    /// The view of this camera on `globe` with a vertical field of view of `fov_y_deg`
    /// degrees and a viewport of `width` x `height` pixels. Above the ground, the ground is
    /// the best the globe knows now ([`Globe::drawn_ground_m`]).
    pub fn view(&self, globe: &Globe, fov_y_deg: f64, width: u32, height: u32) -> View {
        let e = globe.ellipsoid();
        let (lon, lat) = (self.lon_deg.to_radians(), self.lat_deg.to_radians());
        let alt = if self.above_ground {
            globe.drawn_ground_m(lon, lat) + self.alt_m
        } else {
            self.alt_m
        };
        View::from_geodetic(
            &e,
            Cartographic::new(lon, lat, alt),
            self.heading_deg.to_radians(),
            self.pitch_deg.to_radians(),
            fov_y_deg.to_radians(),
            width,
            height,
        )
    }

    /// The orthographic top-down view (Kaiser's ATC screen) centred on this camera's
    /// longitude and latitude with its heading, showing `height_m` metres of ground from the
    /// top to the bottom of the viewport. The altitude and pitch do not apply: the eye looks
    /// straight down from [`crate::ORTHO_EYE_HEIGHT_M`] (or 1 km above the
    /// ground where that is higher).
    pub fn orthographic_view(
        &self,
        globe: &Globe,
        height_m: f64,
        fov_y_deg: f64,
        width: u32,
        height: u32,
    ) -> View {
        let e = globe.ellipsoid();
        let (lon, lat) = (self.lon_deg.to_radians(), self.lat_deg.to_radians());
        let eye_m = crate::ORTHO_EYE_HEIGHT_M.max(globe.drawn_ground_m(lon, lat) + 1_000.0);
        View::from_geodetic(
            &e,
            Cartographic::new(lon, lat, eye_m),
            self.heading_deg.to_radians(),
            -std::f64::consts::FRAC_PI_2,
            fov_y_deg.to_radians(),
            width,
            height,
        )
        .orthographic(height_m)
    }
}
