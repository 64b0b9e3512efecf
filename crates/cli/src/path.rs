//! Camera paths for `globus bench`: keyframes in time, interpolated smoothly.
//!
//! ```json
//! {"keyframes": [
//!   {"t": 0,  "lon": 7.6, "lat": 46.0, "alt": 12756274, "heading": 0, "pitch": -90},
//!   {"t": 12, "lon": 7.6, "lat": 46.0, "agl": 1000,     "heading": 0, "pitch": -90}
//! ]}
//! ```
//!
//! `alt` is metres above the ellipsoid; `agl` is metres above the ground under the keyframe.
//! Between keyframes every channel follows a Catmull-Rom spline (continuous velocity), with
//! altitude interpolated in log space so dives slow down as they approach the ground, and
//! heading along the shorter way round.

use anyhow::{Context, bail};
use serde::Deserialize;

/// One keyframe as written in the file.
#[derive(Clone, Copy, Debug, Deserialize, PartialEq)]
pub struct Keyframe {
    /// Time, seconds.
    pub t: f64,
    /// Longitude, degrees.
    pub lon: f64,
    /// Latitude, degrees.
    pub lat: f64,
    /// Altitude above the ellipsoid, metres.
    pub alt: Option<f64>,
    /// Altitude above the ground, metres.
    pub agl: Option<f64>,
    /// Heading, degrees clockwise from north.
    pub heading: f64,
    /// Pitch, degrees (0 horizon, -90 down).
    pub pitch: f64,
}

#[derive(Deserialize)]
struct PathFile {
    keyframes: Vec<Keyframe>,
}

/// A camera pose at one time.
#[derive(Clone, Copy, Debug, PartialEq)]
pub struct Pose {
    /// Longitude, degrees.
    pub lon: f64,
    /// Latitude, degrees.
    pub lat: f64,
    /// Altitude above the ellipsoid, metres.
    pub alt: f64,
    /// Heading, degrees.
    pub heading: f64,
    /// Pitch, degrees.
    pub pitch: f64,
}

/// A path with every altitude resolved to metres above the ellipsoid.
#[derive(Clone, Debug)]
pub struct CameraPath {
    times: Vec<f64>,
    /// lon, lat, ln(alt), unwrapped heading, pitch.
    channels: Vec<[f64; 5]>,
}

impl CameraPath {
    /// Parses a path file; `ground_m(lon_deg, lat_deg)` resolves `agl` keyframes.
    pub fn parse(
        text: &str,
        origin: &str,
        ground_m: impl Fn(f64, f64) -> f64,
    ) -> anyhow::Result<Self> {
        let file: PathFile =
            serde_json::from_str(text).with_context(|| format!("{origin} is not a camera path"))?;
        if file.keyframes.is_empty() {
            bail!("{origin} has no keyframes");
        }
        let mut times = Vec::new();
        let mut channels: Vec<[f64; 5]> = Vec::new();
        for (i, k) in file.keyframes.iter().enumerate() {
            crate::geo_cmd::check_lon_lat(k.lon, k.lat)
                .with_context(|| format!("{origin}, keyframe {i}"))?;
            if !(-90.0..=90.0).contains(&k.pitch) {
                bail!(
                    "{origin}, keyframe {i}: pitch {} is outside -90..90",
                    k.pitch
                );
            }
            let alt = match (k.alt, k.agl) {
                (Some(a), None) => a,
                (None, Some(g)) => ground_m(k.lon, k.lat) + g,
                _ => bail!("{origin}, keyframe {i}: give exactly one of alt and agl"),
            };
            if alt.is_nan() || alt <= 0.0 {
                bail!("{origin}, keyframe {i}: altitude {alt} m must be above the ellipsoid");
            }
            if let Some(&last) = times.last()
                && k.t <= last
            {
                bail!("{origin}, keyframe {i}: times must increase");
            }
            let mut heading = k.heading;
            if let Some(prev) = channels.last() {
                heading = prev[3] + (heading - prev[3] + 540.0).rem_euclid(360.0) - 180.0;
            }
            times.push(k.t);
            channels.push([k.lon, k.lat, alt.ln(), heading, k.pitch]);
        }
        Ok(Self { times, channels })
    }

    /// Time of the last keyframe, seconds.
    pub fn duration(&self) -> f64 {
        self.times.last().copied().unwrap_or(0.0)
    }

    /// The pose at time `t` (clamped to the path).
    pub fn pose(&self, t: f64) -> Pose {
        let n = self.times.len();
        let c = if n == 1 || t <= self.times[0] {
            self.channels[0]
        } else if t >= self.times[n - 1] {
            self.channels[n - 1]
        } else {
            let i = self.times.partition_point(|&x| x <= t) - 1;
            let (t0, t1) = (self.times[i], self.times[i + 1]);
            let s = (t - t0) / (t1 - t0);
            let p0 = self.channels[i.saturating_sub(1)];
            let p1 = self.channels[i];
            let p2 = self.channels[i + 1];
            let p3 = self.channels[(i + 2).min(n - 1)];
            std::array::from_fn(|k| catmull_rom(p0[k], p1[k], p2[k], p3[k], s))
        };
        Pose {
            lon: c[0],
            lat: c[1].clamp(-90.0, 90.0),
            alt: c[2].exp(),
            heading: c[3].rem_euclid(360.0),
            pitch: c[4].clamp(-90.0, 90.0),
        }
    }
}

fn catmull_rom(p0: f64, p1: f64, p2: f64, p3: f64, s: f64) -> f64 {
    let s2 = s * s;
    let s3 = s2 * s;
    0.5 * (2.0 * p1
        + (p2 - p0) * s
        + (2.0 * p0 - 5.0 * p1 + 4.0 * p2 - p3) * s2
        + (3.0 * p1 - p0 - 3.0 * p2 + p3) * s3)
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn passes_through_keyframes_and_unwraps_heading() {
        let text = r#"{"keyframes": [
            {"t": 0, "lon": 0, "lat": 0, "alt": 1000000, "heading": 350, "pitch": -90},
            {"t": 10, "lon": 10, "lat": 5, "agl": 100, "heading": 10, "pitch": 0}
        ]}"#;
        let p = CameraPath::parse(text, "test", |_, _| 50.0).unwrap();
        assert_eq!(p.duration(), 10.0);
        let end = p.pose(10.0);
        assert!((end.alt - 150.0).abs() < 1e-6);
        let mid = p.pose(5.0);
        // Heading goes through north (0), not through south.
        assert!(mid.heading < 5.0 || mid.heading > 355.0, "{}", mid.heading);
        // Log-space altitude: the midpoint is the geometric mean.
        assert!((mid.alt - (1e6f64 * 150.0).sqrt()).abs() < 1.0);
    }

    #[test]
    fn rejects_bad_paths_with_one_line() {
        for bad in [
            "{}",
            r#"{"keyframes": []}"#,
            r#"{"keyframes": [{"t": 0, "lon": 0, "lat": 95, "alt": 1, "heading": 0, "pitch": 0}]}"#,
            r#"{"keyframes": [{"t": 0, "lon": 0, "lat": 0, "heading": 0, "pitch": 0}]}"#,
        ] {
            let e = CameraPath::parse(bad, "p.json", |_, _| 0.0).unwrap_err();
            assert!(format!("{e:#}").contains("p.json"), "{e:#}");
        }
    }
}
