//! Geodetic coordinates: longitude, latitude (radians) and height above the ellipsoid (metres).

/// A position given as geodetic longitude and latitude in radians and height above the
/// ellipsoid in metres (not above mean sea level: no geoid is applied).
#[derive(Clone, Copy, Debug, PartialEq, Default)]
pub struct Cartographic {
    /// Longitude, radians, east positive, normally in `[-pi, pi]`.
    pub lon_rad: f64,
    /// Geodetic latitude, radians, north positive, in `[-pi/2, pi/2]`.
    pub lat_rad: f64,
    /// Height above the ellipsoid surface along its normal, metres.
    pub height_m: f64,
}

impl Cartographic {
    /// A position from radians and metres.
    pub const fn new(lon_rad: f64, lat_rad: f64, height_m: f64) -> Self {
        Self {
            lon_rad,
            lat_rad,
            height_m,
        }
    }

    /// A position from degrees and metres (the units of files and the command line).
    pub fn from_degrees(lon_deg: f64, lat_deg: f64, height_m: f64) -> Self {
        Self::new(lon_deg.to_radians(), lat_deg.to_radians(), height_m)
    }

    /// Longitude in degrees.
    pub fn lon_deg(&self) -> f64 {
        self.lon_rad.to_degrees()
    }

    /// Latitude in degrees.
    pub fn lat_deg(&self) -> f64 {
        self.lat_rad.to_degrees()
    }
}
