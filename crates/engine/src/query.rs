//! Terrain queries against the loaded tiles: heights, normals and ray picks.
//!
//! Heights follow Kaiser (2018, 3.2.3): bilinear interpolation of four samples of the finest
//! loaded tile containing the point (every engine tile is a corner grid of
//! [`MESH_SEGMENTS`]` + 1` samples, neighbours of a level sharing their edge samples, but
//! where a reduced polar row meets a row of narrower tiles, whose edge has twice the
//! samples). A point on an edge belongs to the tile to its east (south), as
//! [`GLOBE_SCHEME`]'s `tile_at` says, so the answer depends only on the position and on what
//! is loaded.
//!
//! Normals come from heights around the point one sample spacing away (the eight-point fan
//! of Kaiser 3.2.3 reduced to central differences), on the drawn (exaggerated) surface.
//!
//! Ray picks march the ray against the drawn surface of the loaded tiles between the shells
//! of its lowest and highest possible heights, in steps no longer than a fraction of the
//! height above the ground, and bisect the crossing.

use std::f64::consts::{FRAC_PI_2, PI};

use globus_geo::{Cartographic, DVec3, Ellipsoid};
use globus_stream::TerrainLayer;
use globus_terrain::grid::MESH_SEGMENTS;
use globus_tiling::GLOBE_SCHEME;

/// A height read from the loaded terrain.
#[derive(Clone, Copy, Debug, PartialEq)]
pub struct TerrainHeight {
    height_m: f64,
    level: u8,
    error_m: f64,
}

impl TerrainHeight {
    /// True height above the ellipsoid, metres (not exaggerated).
    pub fn height_m(&self) -> f64 {
        self.height_m
    }

    /// The level of the tiles whose samples it was interpolated from.
    pub fn level(&self) -> u8 {
        self.level
    }

    /// The largest geometric error of those tiles, true metres: how far their surface may be
    /// from the full-resolution ground it stands for.
    pub fn error_m(&self) -> f64 {
        self.error_m
    }
}

/// The deepest level whose tile containing the point is loaded (walking down from a root).
fn deepest_loaded(layer: &TerrainLayer, lon_rad: f64, lat_rad: f64) -> Option<u8> {
    let mut best = None;
    for level in 0..=layer.max_level() {
        let key = GLOBE_SCHEME.tile_at(lon_rad, lat_rad, level)?;
        if layer.get(key).is_none() {
            break;
        }
        best = Some(level);
    }
    best
}

/// The best known ground height at a longitude and latitude (radians), true metres: the
/// source's own full-resolution answer if it has one (the procedural planet), else the
/// loaded tiles' ([`height_at`]), else 0.
pub(crate) fn ground_height_m(layer: &TerrainLayer, lon_rad: f64, lat_rad: f64) -> f64 {
    if let Some(h) = layer.source().height_at(lon_rad, lat_rad) {
        return h;
    }
    height_at(layer, lon_rad, lat_rad).map_or(0.0, |h| h.height_m())
}

/// The height at a longitude and latitude (radians) from the finest loaded tiles around it.
pub(crate) fn height_at(layer: &TerrainLayer, lon_rad: f64, lat_rad: f64) -> Option<TerrainHeight> {
    if !lon_rad.is_finite() || lat_rad.is_nan() || lat_rad.abs() > FRAC_PI_2 {
        return None;
    }
    let deepest = deepest_loaded(layer, lon_rad, lat_rad)?;
    let key = GLOBE_SCHEME.tile_at(lon_rad, lat_rad, deepest)?;
    let data = layer.get(key)?;
    let (u, v) = data.tile.rect.uv(lon_rad, lat_rad);
    let cells = f64::from(MESH_SEGMENTS);
    let (x, y) = ((u * cells).clamp(0.0, cells), (v * cells).clamp(0.0, cells));
    let (i0, j0) = (
        (x.floor() as i32).min(MESH_SEGMENTS as i32 - 1),
        (y.floor() as i32).min(MESH_SEGMENTS as i32 - 1),
    );
    let (fx, fy) = (x - f64::from(i0), y - f64::from(j0));
    let h = |i: i32, j: i32| f64::from(data.tile.height_at(i, j));
    let top = h(i0, j0) * (1.0 - fx) + h(i0 + 1, j0) * fx;
    let bottom = h(i0, j0 + 1) * (1.0 - fx) + h(i0 + 1, j0 + 1) * fx;
    Some(TerrainHeight {
        height_m: top * (1.0 - fy) + bottom * fy,
        level: deepest,
        error_m: data.tile.geometric_error_m,
    })
}

/// The unit normal of the drawn surface (heights times `exaggeration`) at a longitude and
/// latitude, from heights one sample spacing of the level they came from to each side.
pub(crate) fn normal_at(
    layer: &TerrainLayer,
    ellipsoid: &Ellipsoid,
    exaggeration: f64,
    lon_rad: f64,
    lat_rad: f64,
) -> Option<DVec3> {
    let centre = height_at(layer, lon_rad, lat_rad)?;
    let step = PI / (GLOBE_SCHEME.tiles_y(centre.level) * u64::from(MESH_SEGMENTS)) as f64;
    let point = |lon: f64, lat: f64| {
        let lat = lat.clamp(-FRAC_PI_2, FRAC_PI_2);
        let h = height_at(layer, lon, lat).map_or(centre.height_m, |t| t.height_m);
        ellipsoid.cartographic_to_ecef(Cartographic::new(lon, lat, h * exaggeration))
    };
    let east = point(lon_rad + step, lat_rad) - point(lon_rad - step, lat_rad);
    let north = point(lon_rad, lat_rad + step) - point(lon_rad, lat_rad - step);
    let up = ellipsoid.geodetic_normal_from_lon_lat(lon_rad, lat_rad);
    Some(
        east.cross(north)
            .try_normalize()
            .filter(|n| n.dot(up) > 0.0)
            .unwrap_or(up),
    )
}

/// The first point where a ray meets a surface of heights `ground(lon, lat)` metres above
/// `ellipsoid` (radians; `None` where the surface is unknown: treated as `lowest_m`), the
/// surface lying between `lowest_m` and `highest_m`. `None` if it misses. What
/// [`crate::Globe::ray_pick`] does on the loaded terrain; for [`crate::Ground`]s of one's
/// own.
pub fn ray_march(
    ellipsoid: &Ellipsoid,
    ground: impl Fn(f64, f64) -> Option<f64>,
    (lowest_m, highest_m): (f64, f64),
    origin: DVec3,
    direction: DVec3,
) -> Option<DVec3> {
    let dir = direction.try_normalize()?;
    let top = ellipsoid.grown(highest_m.max(lowest_m));
    // Where the ray is inside the shell of the highest point.
    let (enter, leave) = top.intersect_ray(origin, dir)?;
    if leave < 0.0 {
        return None;
    }
    // The ray leaves the body at the lowest shell's far side at the latest.
    let end = match ellipsoid.grown(lowest_m).intersect_ray(origin, dir) {
        Some((t0, _)) if t0 > 0.0 => t0,
        _ => leave,
    };
    let above = |t: f64| -> Option<f64> {
        let c = ellipsoid.ecef_to_cartographic(origin + dir * t)?;
        let g = ground(c.lon_rad, c.lat_rad).unwrap_or(lowest_m);
        Some(c.height_m - g)
    };
    let mut t = enter.max(0.0);
    let mut h = above(t)?;
    if h <= 0.0 {
        return Some(origin + dir * t);
    }
    let span = (end - t).max(0.0);
    let min_step = (span * 1e-6).max(0.01);
    while t < end {
        // Terrain rarely rises faster than 3 m per metre of ray: step a third of the height.
        let step = (h / 3.0).max(min_step).min(end - t).max(min_step);
        let next = t + step;
        let hn = above(next)?;
        if hn <= 0.0 {
            let (mut a, mut b) = (t, next);
            for _ in 0..60 {
                let m = 0.5 * (a + b);
                if above(m)? > 0.0 {
                    a = m;
                } else {
                    b = m;
                }
                if b - a < 1e-4 {
                    break;
                }
            }
            return Some(origin + dir * b);
        }
        t = next;
        h = hn;
    }
    None
}

/// Where a ray, near distance `t0` along it, meets the drawn surface: the crossing between
/// `t0 - margin` and `t0 + margin` nearest `t0`, bisected; `None` if there is none there.
pub(crate) fn refine_hit(
    ellipsoid: &Ellipsoid,
    ground: impl Fn(f64, f64) -> Option<f64>,
    origin: DVec3,
    dir: DVec3,
    t0: f64,
    margin: f64,
) -> Option<DVec3> {
    let above = |t: f64| -> Option<f64> {
        let c = ellipsoid.ecef_to_cartographic(origin + dir * t)?;
        Some(c.height_m - ground(c.lon_rad, c.lat_rad)?)
    };
    let h0 = above(t0)?;
    // Walk away from t0 in both directions in growing steps until the sign flips.
    let mut step = (margin / 64.0).max(1e-3);
    let mut found = None;
    while step <= margin {
        for t in [t0 + step, t0 - step] {
            if t > 0.0 && above(t).is_some_and(|h| (h > 0.0) != (h0 > 0.0)) {
                found = Some(t);
                break;
            }
        }
        if found.is_some() {
            break;
        }
        step *= 2.0;
    }
    let other = found?;
    let (mut a, mut b) = (t0.min(other), t0.max(other));
    let front_above = above(a)? > 0.0;
    for _ in 0..60 {
        let m = 0.5 * (a + b);
        if (above(m)? > 0.0) == front_above {
            a = m;
        } else {
            b = m;
        }
        if b - a < 1e-4 {
            break;
        }
    }
    Some(origin + dir * (0.5 * (a + b)))
}

#[cfg(test)]
mod tests {
    use super::*;

    /// Rolling hills of 200 m on the unit-scale WGS84: a ray from 3 km up at 10 degrees below
    /// the horizon meets them where the analytic surface is.
    #[test]
    fn a_ray_meets_rolling_hills_where_they_are() {
        let e = Ellipsoid::WGS84;
        let hills =
            |lon: f64, lat: f64| Some(100.0 + 100.0 * (lon * 3000.0).sin() * (lat * 2000.0).cos());
        let eye = e.cartographic_to_ecef(Cartographic::from_degrees(7.0, 46.0, 3000.0));
        let enu = e.enu_frame(7f64.to_radians(), 46f64.to_radians());
        let dir =
            (enu.north * 10f64.to_radians().cos() - enu.up * 10f64.to_radians().sin()).normalize();
        let hit = ray_march(&e, hills, (0.0, 200.0), eye, dir).expect("hits the hills");
        let c = e.ecef_to_cartographic(hit).expect("on the body");
        let ground = hills(c.lon_rad, c.lat_rad).expect("everywhere");
        assert!(
            (c.height_m - ground).abs() < 0.01,
            "{} vs {ground}",
            c.height_m
        );
        // No crossing before: the ray stays above the ground on the way.
        let t_hit = (hit - eye).length();
        for k in 1..200 {
            let p = eye + dir * (t_hit * f64::from(k) / 200.0);
            let c = e.ecef_to_cartographic(p).expect("on the body");
            assert!(c.height_m > hills(c.lon_rad, c.lat_rad).expect("everywhere") - 0.01);
        }
        // Refining from a nearby estimate finds the same point.
        let refined = refine_hit(&e, hills, eye, dir, t_hit + 7.0, 50.0).expect("near");
        assert!(
            (refined - hit).length() < 0.01,
            "{}",
            (refined - hit).length()
        );
        // Upwards: nothing.
        assert!(ray_march(&e, hills, (0.0, 200.0), eye, enu.up).is_none());
    }
}
