//! Where the Sun is at a moment: its position in Earth-centred Earth-fixed axes, from which
//! the direction of sunlight anywhere on the planet, the subsolar point and the terminator
//! follow.
//!
//! Algorithm: Meeus, *Astronomical Algorithms* (2nd ed., 1998), chapter 25 (the Sun's
//! apparent position from its geometric mean longitude and anomaly and the equation of the
//! centre, with chapter 22's nutation and the aberration) and chapter 12's sidereal time
//! (apparent, with the equation of the equinoxes): the formulation of NOAA's solar
//! calculator. It leaves out the planets' and the Moon's pull on the Earth (up to 0.008
//! degree in right ascension). Checked against NREL's SPA as `pvlib` implements it
//! (`tools/make_reference_tables.py sun`): the direction of the Sun seen from ten places from
//! 78 S to 70 N at 300 moments between 1990 and 2060 is within 0.0093 degree of it, the
//! 0.01 asked. SPA itself (VSOP87's periodic terms, 0.0003 degree) would need pages of
//! tables for an error no pixel shows; no maintained Rust crate computes the Sun without
//! dependencies of its own, hence this module.
//!
//! Time is UTC, taken as UT1 (they differ by under 0.9 s, 0.004 degree of the Earth's
//! turn) and as terrestrial time for the Sun's motion (69 s off in 2026: 0.0008 degree).

use glam::DVec3;

/// Seconds from the Unix epoch to J2000.0 (2000-01-01 12:00 TT, taken as UTC).
const J2000_UNIX_S: f64 = 946_728_000.0;
/// Terrestrial time less UTC, seconds (69.2 in 2026; 57 in 1990; it drifts by about a
/// second a decade, 0.00001 degree of the Sun's motion).
const DELTA_T_S: f64 = 69.2;
/// Metres in an astronomical unit.
const AU_M: f64 = 149_597_870_700.0;

/// The Sun at a moment.
#[derive(Clone, Copy, Debug, PartialEq)]
pub struct SunPosition {
    /// The Sun's centre from the Earth's, ECEF metres (the Earth's rotation applied).
    pub ecef_m: DVec3,
    /// Apparent right ascension and declination, radians.
    pub right_ascension: f64,
    /// Apparent declination, radians: the subsolar point's geocentric latitude.
    pub declination: f64,
    /// Greenwich apparent sidereal time, radians.
    pub sidereal_time: f64,
}

impl SunPosition {
    /// The Sun at `unix_s` seconds since 1970-01-01 00:00 UTC.
    pub fn at(unix_s: f64) -> Self {
        // The Sun's motion in terrestrial time.
        let t = (unix_s + DELTA_T_S - J2000_UNIX_S) / 86_400.0 / 36_525.0;
        let deg = f64::to_radians;
        // Geometric mean longitude and mean anomaly of the Sun, eccentricity of the orbit.
        let l0 = 280.46646 + t * (36000.76983 + t * 0.0003032);
        let m = deg(357.52911 + t * (35999.05029 - t * 0.0001537));
        let e = 0.016708634 - t * (0.000042037 + t * 0.0000001267);
        // Equation of the centre, true longitude and anomaly.
        let c = (1.914602 - t * (0.004817 + t * 0.000014)) * m.sin()
            + (0.019993 - t * 0.000101) * (2.0 * m).sin()
            + 0.000289 * (3.0 * m).sin();
        let true_longitude = l0 + c;
        let nu = m + deg(c);
        let distance_au = 1.000001018 * (1.0 - e * e) / (1.0 + e * nu.cos());
        // Nutation in longitude and obliquity (Meeus 22, the terms above 0.1").
        let omega = deg(125.04452 - 1934.136261 * t);
        let moon_l = deg(218.3165 + 481267.8813 * t);
        let sun_l = deg(280.4665 + 36000.7698 * t);
        let dpsi =
            (-17.20 * omega.sin() - 1.32 * (2.0 * sun_l).sin() - 0.23 * (2.0 * moon_l).sin()
                + 0.21 * (2.0 * omega).sin())
                / 3600.0;
        let deps = (9.20 * omega.cos() + 0.57 * (2.0 * sun_l).cos() + 0.10 * (2.0 * moon_l).cos()
            - 0.09 * (2.0 * omega).cos())
            / 3600.0;
        // Apparent longitude: nutation and aberration (20.4898" at 1 AU).
        let lambda = deg(true_longitude + dpsi - 20.4898 / 3600.0 / distance_au);
        // Obliquity of the ecliptic, mean (Meeus 22.2) and apparent.
        let eps0 =
            23.0 + (26.0 + (21.448 - t * (46.8150 + t * (0.00059 - t * 0.001813))) / 60.0) / 60.0;
        let eps = deg(eps0 + deps);
        let right_ascension = (eps.cos() * lambda.sin()).atan2(lambda.cos());
        let declination = (eps.sin() * lambda.sin()).asin();
        // Greenwich mean sidereal time (Meeus 12.4, in UT) plus the equation of the equinoxes.
        let ut_days = (unix_s - J2000_UNIX_S) / 86_400.0;
        let gmst =
            280.46061837 + 360.98564736629 * ut_days + t * t * (0.000387933 - t / 38_710_000.0);
        let sidereal_time = deg(gmst + dpsi * eps.cos()).rem_euclid(std::f64::consts::TAU);
        let hour = right_ascension - sidereal_time;
        let (sd, cd) = declination.sin_cos();
        let dir = DVec3::new(cd * hour.cos(), cd * hour.sin(), sd);
        Self {
            ecef_m: dir * distance_au * AU_M,
            right_ascension,
            declination,
            sidereal_time,
        }
    }

    /// Unit vector from the Earth's centre towards the Sun, ECEF.
    pub fn direction(&self) -> DVec3 {
        self.ecef_m.normalize()
    }

    /// Unit vector towards the Sun from `observer` (ECEF metres): parallax included.
    pub fn direction_from(&self, observer: DVec3) -> DVec3 {
        (self.ecef_m - observer).normalize()
    }

    /// The subsolar point: longitude and geocentric latitude, radians.
    pub fn subsolar_lon_lat(&self) -> (f64, f64) {
        let d = self.direction();
        (d.y.atan2(d.x), self.declination)
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn meeus_example_25a() {
        // 1992 October 13.0 TD: apparent right ascension 198.38083, declination -7.78507
        // degrees (Meeus, example 25.a). 0 h TD that day is 1992-10-13 00:00 less ΔT (59 s).
        let unix = 718_934_400.0 - 59.0;
        let s = SunPosition::at(unix);
        assert!((s.right_ascension.to_degrees().rem_euclid(360.0) - 198.38083).abs() < 1e-3);
        assert!((s.declination.to_degrees() - -7.78507).abs() < 1e-3);
    }

    #[test]
    fn sidereal_time_matches_meeus_example_12a() {
        // 1987 April 10, 0 h UT: mean sidereal time 13h10m46.3668s (197.693195 degrees);
        // apparent 13h10m46.1351s.
        let s = SunPosition::at(545_011_200.0);
        let apparent = (13.0 + (10.0 + 46.1351 / 60.0) / 60.0) * 15.0;
        assert!(
            (s.sidereal_time.to_degrees() - apparent).abs() < 2e-4,
            "{}",
            s.sidereal_time.to_degrees()
        );
    }

    #[test]
    fn the_subsolar_point_follows_the_seasons_and_the_day() {
        // June solstice 2026 (21 June 08:24 UTC): the Sun over the Tropic of Cancer; at
        // 12:00 UTC near the Greenwich meridian (less the equation of time, -1.8 minutes).
        let s = SunPosition::at(1_782_043_200.0);
        let (lon, lat) = s.subsolar_lon_lat();
        assert!(
            (lat.to_degrees() - 23.44).abs() < 0.01,
            "{}",
            lat.to_degrees()
        );
        assert!(
            (lon.to_degrees() - 0.45).abs() < 0.05,
            "{}",
            lon.to_degrees()
        );
        assert!((s.ecef_m.length() / AU_M - 1.0163).abs() < 1e-3);
        // Equinox 2026 (20 March 14:46 UTC): over the equator.
        let (_, lat) = SunPosition::at(1_774_017_960.0).subsolar_lon_lat();
        assert!(lat.to_degrees().abs() < 0.01, "{}", lat.to_degrees());
    }
}
