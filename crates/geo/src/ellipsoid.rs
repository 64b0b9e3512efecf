//! Reference ellipsoids and the conversions on them.
//!
//! The formulas follow Cozzi & Ring, *3D Engine Design for Virtual Globes* (2011), chapter 2,
//! the same derivation Cesium's `Ellipsoid` uses: a geodetic surface point is found by Newton
//! iteration on the scale factor of the ellipsoid gradient, which works for any triaxial body and
//! from the centre region out to any altitude. The test tables in `tests/data` were computed
//! independently with PROJ (pyproj, EPSG:4979 to EPSG:4978).

use glam::{DMat3, DVec3};

use crate::Cartographic;

/// A body's reference ellipsoid, centred at the origin with its axes along x, y and z
/// (z is the rotation axis, x points at longitude 0).
///
/// ```
/// use globus_geo::{Cartographic, Ellipsoid};
/// let p = Ellipsoid::WGS84.cartographic_to_ecef(Cartographic::from_degrees(0.0, 0.0, 0.0));
/// assert!((p.x - 6_378_137.0).abs() < 1e-9);
/// let back = Ellipsoid::WGS84.ecef_to_cartographic(p).unwrap();
/// assert!(back.height_m.abs() < 1e-9);
/// ```
#[derive(Clone, Copy, Debug, PartialEq)]
pub struct Ellipsoid {
    radii: DVec3,
    one_over_radii_squared: DVec3,
}

/// The east, north and up unit vectors at a point, in ECEF.
#[derive(Clone, Copy, Debug, PartialEq)]
pub struct EnuFrame {
    /// Unit vector pointing east (towards increasing longitude).
    pub east: DVec3,
    /// Unit vector pointing north (towards increasing latitude).
    pub north: DVec3,
    /// The geodetic surface normal.
    pub up: DVec3,
}

impl EnuFrame {
    /// The matrix whose columns are east, north, up: it maps ENU offsets to ECEF offsets.
    pub fn world_from_local(&self) -> DMat3 {
        DMat3::from_cols(self.east, self.north, self.up)
    }
}

impl Ellipsoid {
    /// WGS84: a = 6,378,137 m, f = 1 / 298.257223563 (NIMA TR8350.2).
    pub const WGS84: Ellipsoid = Ellipsoid::from_a_f(6_378_137.0, 1.0 / 298.257_223_563);
    /// Mars (IAU 2015 mean equatorial and polar radii).
    pub const MARS: Ellipsoid = Ellipsoid::new(3_396_190.0, 3_396_190.0, 3_376_200.0);
    /// The Moon, as the sphere of IAU mean radius 1,737,400 m.
    pub const MOON: Ellipsoid = Ellipsoid::sphere(1_737_400.0);

    /// An ellipsoid with the given semi-axes along x, y and z, in metres.
    pub const fn new(a_x: f64, a_y: f64, a_z: f64) -> Self {
        Self {
            radii: DVec3::new(a_x, a_y, a_z),
            one_over_radii_squared: DVec3::new(
                1.0 / (a_x * a_x),
                1.0 / (a_y * a_y),
                1.0 / (a_z * a_z),
            ),
        }
    }

    /// A sphere of radius `r` metres.
    pub const fn sphere(r: f64) -> Self {
        Self::new(r, r, r)
    }

    /// An ellipsoid of revolution from its equatorial radius and flattening.
    pub const fn from_a_f(a: f64, f: f64) -> Self {
        Self::new(a, a, a * (1.0 - f))
    }

    /// The semi-axes (x, y, z) in metres.
    pub fn radii(&self) -> DVec3 {
        self.radii
    }

    /// The largest semi-axis, metres.
    pub fn maximum_radius(&self) -> f64 {
        self.radii.max_element()
    }

    /// The smallest semi-axis, metres.
    pub fn minimum_radius(&self) -> f64 {
        self.radii.min_element()
    }

    /// The mean radius `(a_x + a_y + a_z) / 3` (IUGG R1 for an ellipsoid of revolution), metres.
    pub fn mean_radius(&self) -> f64 {
        (self.radii.x + self.radii.y + self.radii.z) / 3.0
    }

    /// The same ellipsoid grown (or, for negative `height_m`, shrunk) by `height_m` on every axis.
    pub fn grown(&self, height_m: f64) -> Self {
        Self::new(
            self.radii.x + height_m,
            self.radii.y + height_m,
            self.radii.z + height_m,
        )
    }

    /// The geodetic surface normal for a longitude and latitude.
    pub fn geodetic_normal_from_lon_lat(&self, lon_rad: f64, lat_rad: f64) -> DVec3 {
        let (sin_lat, cos_lat) = lat_rad.sin_cos();
        let (sin_lon, cos_lon) = lon_rad.sin_cos();
        DVec3::new(cos_lat * cos_lon, cos_lat * sin_lon, sin_lat)
    }

    /// The geodetic surface normal of the ellipsoid through `position`'s scaled direction
    /// (exact for points on the surface). `None` at the centre.
    pub fn geodetic_normal(&self, position: DVec3) -> Option<DVec3> {
        (position * self.one_over_radii_squared).try_normalize()
    }

    /// Cartographic to ECEF.
    pub fn cartographic_to_ecef(&self, c: Cartographic) -> DVec3 {
        let n = self.geodetic_normal_from_lon_lat(c.lon_rad, c.lat_rad);
        let k = self.radii * self.radii * n;
        let gamma = n.dot(k).sqrt();
        k / gamma + n * c.height_m
    }

    /// ECEF to cartographic. `None` only very near the centre of the body, where the geodetic
    /// latitude is undefined.
    pub fn ecef_to_cartographic(&self, position: DVec3) -> Option<Cartographic> {
        let surface = self.scale_to_geodetic_surface(position)?;
        let n = self.geodetic_normal(surface)?;
        let h = position - surface;
        let height_m = h.length().copysign(h.dot(position));
        let lon_rad = n.y.atan2(n.x);
        let lat_rad = n.z.atan2(n.x.hypot(n.y));
        Some(Cartographic {
            lon_rad,
            lat_rad,
            height_m,
        })
    }

    /// The point on the surface whose normal passes through `position` (the foot of the
    /// geodetic normal). `None` near the centre of the body.
    pub fn scale_to_geodetic_surface(&self, position: DVec3) -> Option<DVec3> {
        let r2 = self.one_over_radii_squared;
        let p2 = position * position * r2;
        let squared_norm = p2.x + p2.y + p2.z;
        if !squared_norm.is_finite() || squared_norm < 1e-20 {
            return None;
        }
        // Start from the radial projection and find lambda with
        // sum(p_i^2 / a_i^2 / (1 + lambda / a_i^2)^2) = 1 (Newton on lambda).
        let ratio = (1.0 / squared_norm).sqrt();
        let radial = position * ratio;
        let gradient = radial * r2 * 2.0;
        let mut lambda = (1.0 - ratio) * position.length() / (0.5 * gradient.length());
        for _ in 0..64 {
            let m = DVec3::ONE / (DVec3::ONE + lambda * r2);
            let m2 = m * m;
            let func = (p2 * m2).element_sum() - 1.0;
            let derivative = -2.0 * (p2 * m2 * m * r2).element_sum();
            let correction = func / derivative;
            lambda -= correction;
            if func.abs() < 1e-15 {
                break;
            }
        }
        let m = DVec3::ONE / (DVec3::ONE + lambda * r2);
        let s = position * m;
        s.is_finite().then_some(s)
    }

    /// The point on the surface straight below (or above) along the ray from the centre.
    pub fn scale_to_geocentric_surface(&self, position: DVec3) -> Option<DVec3> {
        let p2 = position * position * self.one_over_radii_squared;
        let squared_norm = p2.element_sum();
        (squared_norm > 0.0).then(|| position / squared_norm.sqrt())
    }

    /// East, north and up at a longitude and latitude. Well defined at the poles, where
    /// "east" is the direction of increasing longitude for the given longitude.
    pub fn enu_frame(&self, lon_rad: f64, lat_rad: f64) -> EnuFrame {
        let (sin_lat, cos_lat) = lat_rad.sin_cos();
        let (sin_lon, cos_lon) = lon_rad.sin_cos();
        EnuFrame {
            east: DVec3::new(-sin_lon, cos_lon, 0.0),
            north: DVec3::new(-sin_lat * cos_lon, -sin_lat * sin_lon, cos_lat),
            up: DVec3::new(cos_lat * cos_lon, cos_lat * sin_lon, sin_lat),
        }
    }

    /// East, north and up at an ECEF position (from its geodetic longitude and latitude).
    pub fn enu_frame_at(&self, position: DVec3) -> Option<EnuFrame> {
        let c = self.ecef_to_cartographic(position)?;
        Some(self.enu_frame(c.lon_rad, c.lat_rad))
    }

    /// Intersection of a ray with the ellipsoid: the distances along the (not necessarily unit)
    /// direction to the entry and exit points, `t_near <= t_far`. A ray starting inside has a
    /// negative `t_near`. `None` when the line misses or the direction is zero.
    pub fn intersect_ray(&self, origin: DVec3, direction: DVec3) -> Option<(f64, f64)> {
        let inv = DVec3::ONE / self.radii;
        let o = origin * inv;
        let d = direction * inv;
        let a = d.length_squared();
        if a == 0.0 {
            return None;
        }
        let b = o.dot(d);
        let c = o.length_squared() - 1.0;
        let disc = b * b - a * c;
        if disc < 0.0 {
            return None;
        }
        // Numerically stable form of the quadratic roots.
        let q = -(b + disc.sqrt().copysign(b));
        let (t0, t1) = if q == 0.0 { (0.0, 0.0) } else { (q / a, c / q) };
        let (t_near, t_far) = if t0 <= t1 { (t0, t1) } else { (t1, t0) };
        (t_far >= 0.0).then_some((t_near, t_far))
    }

    /// The first point where a ray from `origin` along `direction` enters the ellipsoid, if the
    /// ray starts outside and hits it.
    pub fn ray_hit(&self, origin: DVec3, direction: DVec3) -> Option<DVec3> {
        let (t_near, _) = self.intersect_ray(origin, direction)?;
        (t_near >= 0.0).then(|| origin + direction * t_near)
    }

    /// Great-circle distance in metres between two positions, on the sphere of this
    /// ellipsoid's mean radius (within 0.5 % of the geodesic on WGS84).
    ///
    /// ```
    /// use globus_geo::{Cartographic, Ellipsoid};
    /// // A quarter of the equator.
    /// let d = Ellipsoid::sphere(1.0).great_circle_distance(
    ///     Cartographic::from_degrees(0.0, 0.0, 0.0),
    ///     Cartographic::from_degrees(90.0, 0.0, 0.0),
    /// );
    /// assert!((d - std::f64::consts::FRAC_PI_2).abs() < 1e-12);
    /// ```
    pub fn great_circle_distance(&self, a: Cartographic, b: Cartographic) -> f64 {
        central_angle(a, b) * self.mean_radius()
    }
}

/// Central angle between two positions in radians, as `atan2(|n1 x n2|, n1 . n2)` of their
/// unit position vectors on the sphere: well conditioned for tiny and antipodal separations
/// alike (the haversine form loses digits near antipodes).
fn central_angle(a: Cartographic, b: Cartographic) -> f64 {
    let unit = |c: Cartographic| {
        let (sl, cl) = c.lat_rad.sin_cos();
        let (so, co) = c.lon_rad.sin_cos();
        DVec3::new(cl * co, cl * so, sl)
    };
    let (na, nb) = (unit(a), unit(b));
    na.cross(nb).length().atan2(na.dot(nb))
}

#[cfg(test)]
mod tests {
    use super::*;
    use approx::assert_relative_eq;

    mod cartographic_to_ecef {
        use super::*;

        #[test]
        fn north_pole_is_on_the_minor_axis() {
            let p = Ellipsoid::WGS84
                .cartographic_to_ecef(Cartographic::from_degrees(123.0, 90.0, 100.0));
            assert!(p.x.abs() < 1e-9 && p.y.abs() < 1e-9);
            assert_relative_eq!(p.z, 6_356_752.314_245_179 + 100.0, epsilon = 1e-6);
        }
    }

    mod ecef_to_cartographic {
        use super::*;

        #[test]
        fn centre_has_no_geodetic_position() {
            assert!(Ellipsoid::WGS84.ecef_to_cartographic(DVec3::ZERO).is_none());
        }

        #[test]
        fn poles_round_trip() {
            for lat in [90.0, -90.0, 89.999_999_9, -89.999_999_9] {
                for h in [-500.0, 0.0, 1.0, 40_000_000.0] {
                    let c = Cartographic::from_degrees(45.0, lat, h);
                    let p = Ellipsoid::WGS84.cartographic_to_ecef(c);
                    let back = Ellipsoid::WGS84.ecef_to_cartographic(p).unwrap();
                    let p2 = Ellipsoid::WGS84.cartographic_to_ecef(back);
                    assert!((p - p2).length() < 1e-6, "{lat} {h}: {}", (p - p2).length());
                    assert_relative_eq!(back.height_m, h, epsilon = 1e-6);
                }
            }
        }

        #[test]
        fn works_on_other_bodies() {
            for body in [
                Ellipsoid::MARS,
                Ellipsoid::MOON,
                Ellipsoid::new(3.0, 2.0, 1.0),
            ] {
                let c = Cartographic::from_degrees(-30.0, 20.0, 0.25);
                let p = body.cartographic_to_ecef(c);
                let back = body.ecef_to_cartographic(p).unwrap();
                assert_relative_eq!(back.height_m, 0.25, epsilon = 1e-9);
                assert_relative_eq!(back.lat_rad, c.lat_rad, epsilon = 1e-12);
            }
        }
    }

    mod enu_frame {
        use super::*;

        #[test]
        fn is_orthonormal_and_right_handed_everywhere() {
            for (lon, lat) in [(0.0, 0.0), (179.9, 89.9), (-180.0, -90.0), (12.0, 90.0)] {
                let f = Ellipsoid::WGS84.enu_frame(f64::to_radians(lon), f64::to_radians(lat));
                assert_relative_eq!(f.east.cross(f.north).dot(f.up), 1.0, epsilon = 1e-12);
                assert!(f.east.dot(f.north).abs() < 1e-12);
            }
        }
    }

    mod intersect_ray {
        use super::*;

        #[test]
        fn ray_towards_centre_hits_at_altitude() {
            let e = Ellipsoid::WGS84;
            let origin = DVec3::new(7_378_137.0, 0.0, 0.0);
            let hit = e.ray_hit(origin, DVec3::NEG_X).unwrap();
            assert_relative_eq!(hit.x, 6_378_137.0, epsilon = 1e-6);
        }

        #[test]
        fn ray_away_misses() {
            let origin = DVec3::new(7_378_137.0, 0.0, 0.0);
            assert!(Ellipsoid::WGS84.intersect_ray(origin, DVec3::X).is_none());
            assert!(Ellipsoid::WGS84.intersect_ray(origin, DVec3::Y).is_none());
        }

        #[test]
        fn ray_from_inside_exits() {
            let (t0, t1) = Ellipsoid::sphere(1.0)
                .intersect_ray(DVec3::ZERO, DVec3::X)
                .unwrap();
            assert_relative_eq!(t0, -1.0);
            assert_relative_eq!(t1, 1.0);
        }
    }

    mod great_circle_distance {
        use super::*;

        #[test]
        fn antipodes_are_half_a_circumference_apart() {
            let e = Ellipsoid::sphere(6_371_000.0);
            let d = e.great_circle_distance(
                Cartographic::from_degrees(179.0, 10.0, 0.0),
                Cartographic::from_degrees(-1.0, -10.0, 0.0),
            );
            assert_relative_eq!(d, std::f64::consts::PI * 6_371_000.0, epsilon = 1e-6);
        }

        #[test]
        fn paris_to_new_york() {
            // Haversine with R = 6371 km gives 5837 km (a commonly quoted reference value).
            let e = Ellipsoid::sphere(6_371_000.0);
            let d = e.great_circle_distance(
                Cartographic::from_degrees(2.3522, 48.8566, 0.0),
                Cartographic::from_degrees(-74.0060, 40.7128, 0.0),
            );
            assert!((d - 5_837_000.0).abs() < 2_000.0, "{d}");
        }
    }
}
