//! Terrain queries against the loaded tiles: heights, normals and ray picks.
//!
//! Heights follow Kaiser (2018, 3.2.3): bilinear interpolation of four samples of one level,
//! the finest whose four samples around the point are all loaded. The samples are addressed
//! in the level's global grid (every engine tile is a corner grid of
//! [`MESH_SEGMENTS`]` + 1` samples, neighbours sharing their edge samples), not through the
//! tile that contains the point, so the answer depends only on the position and on what is
//! loaded: the same on both sides of a tile edge, whichever tile might be asked. A sample on
//! an edge is read from the tile to its east (south), or the one to its west (north) if that
//! one is not loaded.
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
use globus_tiling::{TileKey, TilingScheme};

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

/// Samples per tile side minus one.
const CELLS: u64 = MESH_SEGMENTS as u64;

/// The height of one global sample of `level` and the geometric error of the tile it was
/// read from: the tile that owns it or, on an edge, the neighbour that shares it.
fn sample(layer: &TerrainLayer, level: u8, gi: u64, gj: u64) -> Option<(f32, f64)> {
    let scheme = TilingScheme::Geographic;
    let (ntx, nty) = (scheme.tiles_x(level), scheme.tiles_y(level));
    let read = |tx: u64, ty: u64| {
        let key = TileKey::try_new(level, tx as u32, ty as u32)?;
        let data = layer.get(key)?;
        let (i, j) = (gi - tx * CELLS, gj - ty * CELLS);
        Some((
            data.tile.height_at(i as i32, j as i32),
            data.tile.geometric_error_m,
        ))
    };
    let owner = |g: u64, n: u64| (g / CELLS).min(n - 1);
    let (tx, ty) = (owner(gi, ntx), owner(gj, nty));
    // Candidates: the owner, and the neighbours that share the sample on an edge.
    let xs = [Some(tx), (tx > 0 && gi == tx * CELLS).then(|| tx - 1)];
    let ys = [Some(ty), (ty > 0 && gj == ty * CELLS).then(|| ty - 1)];
    for y in ys.into_iter().flatten() {
        for x in xs.into_iter().flatten() {
            if let Some(h) = read(x, y) {
                return Some(h);
            }
        }
    }
    None
}

/// The deepest level whose tile containing the point is loaded (walking down from a root).
fn deepest_loaded(layer: &TerrainLayer, lon_rad: f64, lat_rad: f64) -> Option<u8> {
    let scheme = TilingScheme::Geographic;
    let mut best = None;
    for level in 0..=layer.max_level() {
        let key = scheme.tile_at(lon_rad, lat_rad, level)?;
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
    let scheme = TilingScheme::Geographic;
    for level in (0..=deepest).rev() {
        let cols = scheme.tiles_x(level) * CELLS;
        let rows = scheme.tiles_y(level) * CELLS;
        let x = ((lon_rad + PI) / (2.0 * PI)).clamp(0.0, 1.0) * cols as f64;
        let y = ((FRAC_PI_2 - lat_rad) / PI).clamp(0.0, 1.0) * rows as f64;
        let (i0, j0) = (
            (x.floor() as u64).min(cols - 1),
            (y.floor() as u64).min(rows - 1),
        );
        let (fx, fy) = (x - i0 as f64, y - j0 as f64);
        let corners = [(i0, j0), (i0 + 1, j0), (i0, j0 + 1), (i0 + 1, j0 + 1)];
        let mut h = [0.0f64; 4];
        let mut error_m: f64 = 0.0;
        let mut complete = true;
        for (k, &(gi, gj)) in corners.iter().enumerate() {
            match sample(layer, level, gi, gj) {
                Some((v, e)) => {
                    h[k] = f64::from(v);
                    error_m = error_m.max(e);
                }
                None => {
                    complete = false;
                    break;
                }
            }
        }
        if complete {
            let top = h[0] * (1.0 - fx) + h[1] * fx;
            let bottom = h[2] * (1.0 - fx) + h[3] * fx;
            return Some(TerrainHeight {
                height_m: top * (1.0 - fy) + bottom * fy,
                level,
                error_m,
            });
        }
    }
    None
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
    let scheme = TilingScheme::Geographic;
    let step = PI / (scheme.tiles_y(centre.level) * CELLS) as f64;
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
