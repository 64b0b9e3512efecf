//! [`GeoRect`]: a longitude/latitude rectangle in radians.

use std::f64::consts::{FRAC_PI_2, PI};

/// A rectangle of longitude and latitude, radians, `west < east` (tiles never cross the
/// antimeridian: it is a tile border in both schemes).
#[derive(Clone, Copy, Debug, PartialEq)]
pub struct GeoRect {
    /// Western edge, radians.
    pub west: f64,
    /// Southern edge, radians.
    pub south: f64,
    /// Eastern edge, radians.
    pub east: f64,
    /// Northern edge, radians.
    pub north: f64,
}

impl GeoRect {
    /// The whole globe.
    pub const WORLD: GeoRect = GeoRect {
        west: -PI,
        south: -FRAC_PI_2,
        east: PI,
        north: FRAC_PI_2,
    };

    /// A rectangle from degrees.
    pub fn from_degrees(west: f64, south: f64, east: f64, north: f64) -> Self {
        Self {
            west: west.to_radians(),
            south: south.to_radians(),
            east: east.to_radians(),
            north: north.to_radians(),
        }
    }

    /// Width in radians of longitude.
    pub fn width(&self) -> f64 {
        self.east - self.west
    }

    /// Height in radians of latitude.
    pub fn height(&self) -> f64 {
        self.north - self.south
    }

    /// The centre (longitude, latitude), radians.
    pub fn centre(&self) -> (f64, f64) {
        (
            (self.west + self.east) * 0.5,
            (self.south + self.north) * 0.5,
        )
    }

    /// Whether the rectangle contains a point (edges included).
    pub fn contains(&self, lon_rad: f64, lat_rad: f64) -> bool {
        lon_rad >= self.west
            && lon_rad <= self.east
            && lat_rad >= self.south
            && lat_rad <= self.north
    }

    /// The position of (lon, lat) inside the rectangle as (u, v) in [0, 1], u eastwards and
    /// v southwards (v = 0 on the northern edge, matching image rows).
    pub fn uv(&self, lon_rad: f64, lat_rad: f64) -> (f64, f64) {
        (
            (lon_rad - self.west) / self.width(),
            (self.north - lat_rad) / self.height(),
        )
    }

    /// The longitude and latitude at (u, v) (see [`GeoRect::uv`]).
    pub fn lon_lat_at(&self, u: f64, v: f64) -> (f64, f64) {
        (self.west + u * self.width(), self.north - v * self.height())
    }

    /// The edges in degrees: west, south, east, north.
    pub fn to_degrees(&self) -> [f64; 4] {
        [
            self.west.to_degrees(),
            self.south.to_degrees(),
            self.east.to_degrees(),
            self.north.to_degrees(),
        ]
    }
}
