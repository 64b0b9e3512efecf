//! Geometry ready to draw: positions checked, lines densified along geodesics or rhumb lines,
//! rings unwrapped across the antimeridian (and closed over a pole they enclose), polygons
//! triangulated with `earcut` (the georust port of mapbox/earcut) in longitude/latitude.
//!
//! Longitudes stay *unwrapped*: along a line or ring each one is within 180 degrees of the
//! previous, so a line from 179 E to 179 W reads 179 -> 181 and a polygon over the
//! antimeridian is one simple polygon; the draping code ([`crate::drape`]) places it on tiles
//! shifted by whole turns. A ring that winds once around a pole (its unwrapped longitudes
//! end a whole turn from where they began) is closed along that pole's latitude, so the
//! polygon covers the cap; Natural Earth's Antarctica, drawn along the -90 parallel from 180
//! to -180, is already such a polygon.
//!
//! Densification is adaptive: a piece is split at its true midpoint (geographiclib's
//! geodesic, or the rhumb line through isometric latitude) until the straight interpolation
//! that will draw it (linear in longitude/latitude for draped geometry, the 3D chord for
//! geometry at altitude) passes within the tolerance of that midpoint.

use geographiclib_rs::{DirectGeodesic, Geodesic, InverseGeodesic};
use globus_geo::{Cartographic, DVec3, Ellipsoid};

use crate::style::PathKind;

/// Longitude (degrees, unwrapped), latitude (degrees), height (metres).
pub type Position = [f64; 3];

/// How the drawn geometry joins two vertices.
#[derive(Clone, Copy, Debug, PartialEq, Eq)]
pub enum Straight {
    /// Linear in longitude and latitude (geometry draped on tiles).
    LonLat,
    /// The straight 3D chord (geometry at altitude).
    Chord,
}

/// What is wrong with a position, line or ring.
#[derive(Clone, Debug, PartialEq, thiserror::Error)]
pub enum GeometryError {
    /// Fewer than two numbers.
    #[error("a position with {0} numbers")]
    ShortPosition(usize),
    /// NaN or infinite.
    #[error("a position that is not finite: {0:?}")]
    NotFinite(Vec<f64>),
    /// Longitude or latitude beyond their range.
    #[error("a position out of range: lon {lon}, lat {lat}")]
    OutOfRange {
        /// Degrees.
        lon: f64,
        /// Degrees.
        lat: f64,
    },
    /// A height beyond 10,000 km.
    #[error("a height of {0} m")]
    Height(f64),
    /// A line without two distinct positions.
    #[error("a line with fewer than two distinct positions")]
    ShortLine,
    /// A ring of fewer than four positions.
    #[error("a ring of {0} positions (at least 4)")]
    ShortRing(usize),
    /// First and last positions differ.
    #[error("an unclosed ring: it starts at {first:?} and ends at {last:?}")]
    Unclosed {
        /// Longitude, latitude.
        first: [f64; 2],
        /// Longitude, latitude.
        last: [f64; 2],
    },
    /// A ring winding round a pole more than once.
    #[error("a ring winding {0:.0} degrees around a pole")]
    Winding(f64),
    /// Fewer than three distinct positions.
    #[error("a ring with fewer than three distinct positions")]
    FewDistinct,
    /// All positions on one line.
    #[error("a ring without area (all its positions on one line)")]
    NoArea,
}

/// Deepest halving of one piece (2^12 pieces per input segment).
const MAX_SPLIT_DEPTH: u32 = 12;

/// Checks one GeoJSON position: two or three finite numbers, longitude in [-180, 180] and
/// latitude in [-90, 90].
pub fn position(p: &[f64]) -> Result<Position, GeometryError> {
    let (lon, lat) = match p {
        [lon, lat, ..] => (*lon, *lat),
        _ => return Err(GeometryError::ShortPosition(p.len())),
    };
    let h = p.get(2).copied().unwrap_or(0.0);
    if !(lon.is_finite() && lat.is_finite() && h.is_finite()) {
        return Err(GeometryError::NotFinite(p.to_vec()));
    }
    if !(-180.0..=180.0).contains(&lon) || !(-90.0..=90.0).contains(&lat) {
        return Err(GeometryError::OutOfRange { lon, lat });
    }
    if h.abs() > 1.0e7 {
        return Err(GeometryError::Height(h));
    }
    Ok([lon, lat, h])
}

/// Positions of a line, consecutive duplicates dropped, longitudes unwrapped. At least two
/// distinct positions.
pub fn line(coords: &[Vec<f64>]) -> Result<Vec<Position>, GeometryError> {
    let mut out: Vec<Position> = Vec::with_capacity(coords.len());
    for c in coords {
        let mut p = position(c)?;
        if let Some(prev) = out.last() {
            p[0] = unwrap_near(p[0], prev[0]);
            if same(&p, prev) {
                continue;
            }
        }
        out.push(p);
    }
    if out.len() < 2 {
        return Err(GeometryError::ShortLine);
    }
    Ok(out)
}

/// A closed ring: checked (closed, three distinct positions, an area), the closing position
/// dropped, longitudes unwrapped, and closed over the pole it winds around.
pub fn ring(coords: &[Vec<f64>]) -> Result<Vec<Position>, GeometryError> {
    if coords.len() < 4 {
        return Err(GeometryError::ShortRing(coords.len()));
    }
    let first = position(&coords[0])?;
    let last = position(&coords[coords.len() - 1])?;
    if first[0] != last[0] || first[1] != last[1] {
        return Err(GeometryError::Unclosed {
            first: [first[0], first[1]],
            last: [last[0], last[1]],
        });
    }
    let mut pts = line(coords)?;
    let end = pts[pts.len() - 1];
    let turn = end[0] - pts[0][0];
    if turn.abs() < 1e-9 {
        pts.pop(); // the closing position
    } else if (turn.abs() - 360.0).abs() < 1e-6 {
        // Winds once around a pole: go along the pole's parallel back to the start.
        let mean_lat = pts.iter().map(|p| p[1]).sum::<f64>() / pts.len() as f64;
        let pole = 90f64.copysign(mean_lat);
        pts.push([end[0], pole, end[2]]);
        pts.push([pts[0][0], pole, pts[0][2]]);
    } else {
        return Err(GeometryError::Winding(turn));
    }
    if pts.len() < 3 {
        return Err(GeometryError::FewDistinct);
    }
    if signed_area(&pts).abs() < 1e-18 {
        return Err(GeometryError::NoArea);
    }
    Ok(pts)
}

fn same(a: &Position, b: &Position) -> bool {
    a[0] == b[0] && a[1] == b[1]
}

/// `lon` shifted by whole turns to within 180 degrees of `near`.
pub fn unwrap_near(lon: f64, near: f64) -> f64 {
    lon - ((lon - near) / 360.0).round() * 360.0
}

/// Shoelace area in degrees squared (positive counter-clockwise).
pub fn signed_area(ring: &[Position]) -> f64 {
    let n = ring.len();
    (0..n)
        .map(|i| {
            let (a, b) = (ring[i], ring[(i + 1) % n]);
            a[0] * b[1] - b[0] * a[1]
        })
        .sum::<f64>()
        / 2.0
}

/// Whether two edges of the ring cross (not merely touch at a shared vertex). Sorted sweep
/// over the edges' longitude spans; rings of more than 100,000 edges are not checked.
pub fn self_intersects(ring: &[Position]) -> bool {
    let n = ring.len();
    if !(4..=100_000).contains(&n) {
        return false;
    }
    let edge = |i: usize| (ring[i], ring[(i + 1) % n]);
    let mut order: Vec<usize> = (0..n).collect();
    let min_x = |i: usize| edge(i).0[0].min(edge(i).1[0]);
    order.sort_by(|&a, &b| min_x(a).total_cmp(&min_x(b)));
    for (k, &i) in order.iter().enumerate() {
        let (a, b) = edge(i);
        let max_x = a[0].max(b[0]);
        for &j in &order[k + 1..] {
            if min_x(j) > max_x {
                break;
            }
            if j == (i + 1) % n || i == (j + 1) % n {
                continue;
            }
            let (c, d) = edge(j);
            if segments_cross(a, b, c, d) {
                return true;
            }
        }
    }
    false
}

fn segments_cross(a: Position, b: Position, c: Position, d: Position) -> bool {
    let orient = |p: Position, q: Position, r: Position| {
        (q[0] - p[0]) * (r[1] - p[1]) - (q[1] - p[1]) * (r[0] - p[0])
    };
    let (d1, d2) = (orient(c, d, a), orient(c, d, b));
    let (d3, d4) = (orient(a, b, c), orient(a, b, d));
    d1 * d2 < 0.0 && d3 * d4 < 0.0
}

/// Densifies a line (or a ring, with `closed`) so that drawing it `straight` between its
/// vertices stays within `tolerance_m` of the true `path`. Heights are interpolated along
/// the way; longitudes stay unwrapped.
pub fn densify(
    ellipsoid: &Ellipsoid,
    pts: &[Position],
    closed: bool,
    path: PathKind,
    straight: Straight,
    tolerance_m: f64,
) -> Vec<Position> {
    let radii = ellipsoid.radii();
    let geodesic = Geodesic::new(radii.x, 1.0 - radii.z / radii.x);
    let curve = Curve {
        ellipsoid,
        geodesic: &geodesic,
        path,
        straight,
        tolerance_m: tolerance_m.max(1e-3),
    };
    let mut out = Vec::with_capacity(pts.len());
    let n = pts.len();
    let segments = if closed { n } else { n.saturating_sub(1) };
    for i in 0..segments {
        let (a, b) = (pts[i], pts[(i + 1) % n]);
        out.push(a);
        if path == PathKind::Geodesic && straight == Straight::Chord {
            curve.sample_geodesic(a, b, &mut out);
        } else {
            curve.split(a, b, 0, &mut out);
        }
    }
    if !closed && let Some(&last) = pts.last() {
        out.push(last);
    }
    out
}

struct Curve<'a> {
    ellipsoid: &'a Ellipsoid,
    geodesic: &'a Geodesic,
    path: PathKind,
    straight: Straight,
    tolerance_m: f64,
}

impl Curve<'_> {
    /// Pushes the interior points of a..b (not a, not b) for 3D chords along a geodesic:
    /// evenly spaced, as far apart as a chord may be whose sagitta under the tightest
    /// curvature of the body (1 / its smallest radius of curvature, b^2 / a) is within the
    /// tolerance. One inverse and one direct problem per point, where halving needs two
    /// per split.
    fn sample_geodesic(&self, a: Position, b: Position, out: &mut Vec<Position>) {
        let (s12, azi1, _azi2, _a12): (f64, f64, f64, f64) =
            self.geodesic.inverse(a[1], a[0], b[1], b[0]);
        if !s12.is_finite() || s12 <= 0.0 {
            return;
        }
        let r = self.ellipsoid.radii();
        let min_radius = r.z * r.z / r.x + a[2].min(b[2]).max(0.0);
        let step = 0.95 * (8.0 * min_radius * self.tolerance_m).sqrt();
        let pieces = (s12 / step).ceil().min(f64::from(1u32 << MAX_SPLIT_DEPTH)) as u32;
        let mut lon_prev = a[0];
        for k in 1..pieces {
            let t = f64::from(k) / f64::from(pieces);
            let (lat, lon): (f64, f64) = self.geodesic.direct(a[1], a[0], azi1, s12 * t);
            let lon = unwrap_near(lon, lon_prev);
            lon_prev = lon;
            out.push([lon, lat, a[2] + (b[2] - a[2]) * t]);
        }
    }

    /// Pushes the interior points of a..b (not a, not b).
    fn split(&self, a: Position, b: Position, depth: u32, out: &mut Vec<Position>) {
        if depth >= MAX_SPLIT_DEPTH {
            return;
        }
        if self.surely_within_tolerance(a, b) {
            return;
        }
        let Some(mid) = self.midpoint(a, b) else {
            return;
        };
        if 90.0 - mid[1].abs() < 1e-7 {
            // Through a pole: up a's meridian and down b's, which are straight in any
            // drawing; the pole is two vertices, one per longitude.
            let pole = 90f64.copysign(mid[1]);
            let (pa, pb) = ([a[0], pole, mid[2]], [b[0], pole, mid[2]]);
            self.split(a, pa, depth + 1, out);
            out.push(pa);
            out.push(pb);
            self.split(pb, b, depth + 1, out);
            return;
        }
        let drawn = self.drawn_midpoint(a, b);
        let truth = self.ecef(mid);
        if (drawn - truth).length() <= self.tolerance_m {
            return;
        }
        self.split(a, mid, depth + 1, out);
        out.push(mid);
        self.split(mid, b, depth + 1, out);
    }

    /// Whether a piece is so short that its drawing cannot stray from its path by the
    /// tolerance, whatever the path and the drawing (densely sampled lines, a million
    /// vertices a few metres apart, skip the geodesic problems). Drawings and paths both
    /// leave the piece's ends in directions that differ by at most the angle a parallel
    /// turns over its length (`L tan(lat) / R`) or the body's curvature (`L / R`), so they
    /// part by at most `L^2 (1 + tan(lat)) / (8 R)` with `R` the smallest radius of
    /// curvature, counted twice over here.
    fn surely_within_tolerance(&self, a: Position, b: Position) -> bool {
        let lat = a[1].abs().max(b[1].abs());
        if lat > 89.0 {
            return false;
        }
        let r = self.ellipsoid.radii();
        let (min_radius, max_radius) = (r.z * r.z / r.x, r.x * r.x / r.z);
        let h = a[2].abs().max(b[2].abs());
        // A bound on the piece's length: its latitude and longitude spans together.
        let len = (max_radius + h) * ((a[1] - b[1]).abs() + (a[0] - b[0]).abs()).to_radians();
        let apart = len * len * (1.0 + lat.to_radians().tan()) / (8.0 * min_radius);
        2.0 * apart <= self.tolerance_m
    }

    fn ecef(&self, p: Position) -> DVec3 {
        self.ellipsoid.cartographic_to_ecef(Cartographic::new(
            p[0].to_radians(),
            p[1].to_radians(),
            p[2],
        ))
    }

    /// Where the drawn straight line between a and b is at its middle.
    fn drawn_midpoint(&self, a: Position, b: Position) -> DVec3 {
        match self.straight {
            Straight::LonLat => self.ecef([
                (a[0] + b[0]) / 2.0,
                (a[1] + b[1]) / 2.0,
                (a[2] + b[2]) / 2.0,
            ]),
            Straight::Chord => (self.ecef(a) + self.ecef(b)) / 2.0,
        }
    }

    /// The true path's midpoint (longitude unwrapped near a's).
    fn midpoint(&self, a: Position, b: Position) -> Option<Position> {
        let h = (a[2] + b[2]) / 2.0;
        match self.path {
            PathKind::Geodesic => {
                let (s12, azi1, _azi2, _a12): (f64, f64, f64, f64) =
                    self.geodesic.inverse(a[1], a[0], b[1], b[0]);
                if !s12.is_finite() || s12 <= 0.0 {
                    return None;
                }
                let (lat, lon): (f64, f64) = self.geodesic.direct(a[1], a[0], azi1, s12 / 2.0);
                let lon = unwrap_near(lon, (a[0] + b[0]) / 2.0);
                Some([lon, lat, h])
            }
            PathKind::Rhumb => {
                let e = self.eccentricity();
                let (pa, pb) = (isometric(a[1], e), isometric(b[1], e));
                let lat = geodetic_from_isometric((pa + pb) / 2.0, e);
                Some([(a[0] + b[0]) / 2.0, lat, h])
            }
        }
    }

    fn eccentricity(&self) -> f64 {
        let r = self.ellipsoid.radii();
        (1.0 - (r.z / r.x).powi(2)).max(0.0).sqrt()
    }
}

/// Latitudes closer to a pole than this are moved to it (isometric latitude is infinite at
/// the pole itself).
const POLAR_LIMIT_DEG: f64 = 89.999_999;

/// Isometric latitude (the Mercator northing on the unit sphere) of a geodetic latitude in
/// degrees, on an ellipsoid of eccentricity `e`.
pub fn isometric(lat_deg: f64, e: f64) -> f64 {
    let phi = lat_deg
        .clamp(-POLAR_LIMIT_DEG, POLAR_LIMIT_DEG)
        .to_radians();
    phi.tan().asinh() - e * (e * phi.sin()).atanh()
}

/// Inverse of [`isometric`] (fixed-point iteration; converges to 1e-12 degrees in a few
/// steps for the Earth's eccentricity).
pub fn geodetic_from_isometric(psi: f64, e: f64) -> f64 {
    let mut phi = psi.sinh().atan();
    for _ in 0..20 {
        let next = (psi + e * (e * phi.sin()).atanh()).sinh().atan();
        if (next - phi).abs() < 1e-15 {
            phi = next;
            break;
        }
        phi = next;
    }
    phi.to_degrees()
}

/// Triangles of a polygon (rings: exterior first, then holes, as from [`ring`]) in unwrapped
/// longitude/latitude: the vertices and counter-clockwise index triples.
pub fn triangulate(rings: &[Vec<Position>]) -> (Vec<[f64; 2]>, Vec<u32>) {
    let Some(exterior) = rings.first() else {
        return (Vec::new(), Vec::new());
    };
    let centre = |r: &[Position]| r.iter().map(|p| p[0]).sum::<f64>() / r.len() as f64;
    let c0 = centre(exterior);
    let mut vertices = Vec::new();
    let mut holes = Vec::new();
    for (k, r) in rings.iter().enumerate() {
        if k > 0 {
            holes.push(vertices.len() as u32);
        }
        // Holes move by whole turns next to their exterior.
        let shift = if k == 0 {
            0.0
        } else {
            ((centre(r) - c0) / 360.0).round() * 360.0
        };
        vertices.extend(r.iter().map(|p| [p[0] - shift, p[1]]));
    }
    let mut indices: Vec<u32> = Vec::new();
    earcut::Earcut::new().earcut(vertices.iter().copied(), &holes, &mut indices);
    for t in indices.chunks_exact_mut(3) {
        let [a, b, c] = [t[0], t[1], t[2]].map(|i| vertices[i as usize]);
        if (b[0] - a[0]) * (c[1] - a[1]) - (b[1] - a[1]) * (c[0] - a[0]) < 0.0 {
            t.swap(1, 2);
        }
    }
    (vertices, indices)
}

/// Triangles of a polygon (as [`triangulate`] takes it) cut into cells of `step_deg` on a
/// side, so no triangle is larger than a cell: earcut alone makes slivers as long as the
/// polygon, which sag under the body's curvature at altitude and cross hundreds of terrain
/// triangles when draped. Each latitude band is clipped from the polygon first, then each
/// cell from its band (Sutherland-Hodgman per ring; the degenerate seams it leaves along a
/// cell edge are zero-area and earcut drops them), so the work grows with the ring length
/// times the bands plus the cells, not their product.
pub fn tessellate(rings: &[Vec<Position>], step_deg: f64) -> Vec<[[f64; 2]; 3]> {
    tessellate_flat(&flatten_rings(rings), step_deg)
}

/// A polygon's rings in longitude/latitude, holes moved by whole turns next to their
/// exterior.
pub fn flatten_rings(rings: &[Vec<Position>]) -> Vec<Vec<[f64; 2]>> {
    let Some(exterior) = rings.first() else {
        return Vec::new();
    };
    let c0 = exterior.iter().map(|p| p[0]).sum::<f64>() / exterior.len() as f64;
    rings
        .iter()
        .enumerate()
        .map(|(k, r)| {
            let c = r.iter().map(|p| p[0]).sum::<f64>() / r.len() as f64;
            let shift = if k == 0 {
                0.0
            } else {
                ((c - c0) / 360.0).round() * 360.0
            };
            r.iter().map(|p| [p[0] - shift, p[1]]).collect()
        })
        .collect()
}

/// The part of a polygon (flattened rings, exterior first) inside `rect` (west, south,
/// east, north): each ring clipped (Sutherland-Hodgman), rings left with fewer than three
/// vertices dropped; nothing if the exterior is.
pub fn clip_rings(flat: &[Vec<[f64; 2]>], rect: [f64; 4]) -> Vec<Vec<[f64; 2]>> {
    let [w, s, e, n] = rect;
    let mut out = Vec::with_capacity(flat.len());
    for (k, r) in flat.iter().enumerate() {
        let c = clip_ring(&clip_ring(r, 0, w, true), 0, e, false);
        let c = clip_ring(&clip_ring(&c, 1, s, true), 1, n, false);
        if c.len() < 3 {
            if k == 0 {
                return Vec::new();
            }
            continue;
        }
        out.push(c);
    }
    out
}

/// [`tessellate`] of rings already flattened ([`flatten_rings`]).
pub fn tessellate_flat(flat: &[Vec<[f64; 2]>], step_deg: f64) -> Vec<[[f64; 2]; 3]> {
    if flat.is_empty() {
        return Vec::new();
    }
    let step = step_deg.max(1e-3);
    let (mut lo, mut hi) = ([f64::INFINITY; 2], [f64::NEG_INFINITY; 2]);
    for p in &flat[0] {
        for d in 0..2 {
            lo[d] = lo[d].min(p[d]);
            hi[d] = hi[d].max(p[d]);
        }
    }
    let mut out = Vec::new();
    let mut earcut = earcut::Earcut::new();
    let mut indices: Vec<u32> = Vec::new();
    let rows = ((hi[1] - lo[1]) / step).ceil().max(1.0) as usize;
    let cols = ((hi[0] - lo[0]) / step).ceil().max(1.0) as usize;
    for row in 0..rows {
        let (s, n) = (lo[1] + row as f64 * step, lo[1] + (row + 1) as f64 * step);
        let band: Vec<Vec<[f64; 2]>> = flat
            .iter()
            .map(|r| clip_ring(&clip_ring(r, 1, s, true), 1, n, false))
            .collect();
        if band[0].len() < 3 {
            continue;
        }
        for col in 0..cols {
            let (w, e) = (lo[0] + col as f64 * step, lo[0] + (col + 1) as f64 * step);
            let mut vertices: Vec<[f64; 2]> = Vec::new();
            let mut holes: Vec<u32> = Vec::new();
            for (k, r) in band.iter().enumerate() {
                let cell = clip_ring(&clip_ring(r, 0, w, true), 0, e, false);
                if cell.len() < 3 {
                    if k == 0 {
                        break;
                    }
                    continue;
                }
                if k > 0 {
                    holes.push(vertices.len() as u32);
                }
                vertices.extend(cell);
            }
            if vertices.len() < 3 {
                continue;
            }
            earcut.earcut(vertices.iter().copied(), &holes, &mut indices);
            for t in indices.chunks_exact(3) {
                let [a, b, c] = [t[0], t[1], t[2]].map(|i| vertices[i as usize]);
                let area = (b[0] - a[0]) * (c[1] - a[1]) - (b[1] - a[1]) * (c[0] - a[0]);
                if area > 0.0 {
                    out.push([a, b, c]);
                } else if area < 0.0 {
                    out.push([a, c, b]);
                }
            }
        }
    }
    out
}

/// The part of a ring on one side of the line `axis = at` (`above`: the side of greater
/// values), Sutherland-Hodgman.
fn clip_ring(ring: &[[f64; 2]], axis: usize, at: f64, above: bool) -> Vec<[f64; 2]> {
    let n = ring.len();
    let mut out = Vec::with_capacity(n + 4);
    let inside = |p: [f64; 2]| if above { p[axis] >= at } else { p[axis] <= at };
    for i in 0..n {
        let (p, q) = (ring[i], ring[(i + 1) % n]);
        let (ip, iq) = (inside(p), inside(q));
        if ip {
            out.push(p);
        }
        if ip != iq {
            let t = (at - p[axis]) / (q[axis] - p[axis]);
            out.push([p[0] + (q[0] - p[0]) * t, p[1] + (q[1] - p[1]) * t]);
        }
    }
    out
}

#[cfg(test)]
mod tests {
    use super::*;

    /// Summed signed area of indexed triangles.
    fn indexed_area(v: &[[f64; 2]], i: &[u32]) -> f64 {
        let tris: Vec<[[f64; 2]; 3]> = i
            .chunks_exact(3)
            .map(|t| [t[0], t[1], t[2]].map(|k| v[k as usize]))
            .collect();
        area(&tris)
    }

    fn ring_of(pts: &[[f64; 2]]) -> Vec<Vec<f64>> {
        pts.iter().map(|p| p.to_vec()).collect()
    }

    #[test]
    fn bad_positions_are_refused_with_what_is_wrong() {
        assert!(position(&[1.0]).is_err());
        assert!(position(&[f64::NAN, 1.0]).is_err());
        assert!(position(&[181.0, 1.0]).is_err());
        assert!(position(&[1.0, -90.5]).is_err());
        assert_eq!(position(&[1.0, 2.0]), Ok([1.0, 2.0, 0.0]));
        assert_eq!(position(&[1.0, 2.0, 3.0, 4.0]), Ok([1.0, 2.0, 3.0]));
    }

    #[test]
    fn rings_must_be_closed_and_have_area() {
        let unclosed = ring_of(&[[0.0, 0.0], [1.0, 0.0], [1.0, 1.0], [0.0, 1.0]]);
        assert!(matches!(
            ring(&unclosed),
            Err(GeometryError::Unclosed { .. })
        ));
        let flat = ring_of(&[[0.0, 0.0], [1.0, 1.0], [2.0, 2.0], [0.0, 0.0]]);
        assert_eq!(ring(&flat), Err(GeometryError::NoArea));
        let short = ring_of(&[[0.0, 0.0], [1.0, 1.0], [0.0, 0.0]]);
        assert!(ring(&short).is_err());
        let square = ring_of(&[[0.0, 0.0], [1.0, 0.0], [1.0, 1.0], [0.0, 1.0], [0.0, 0.0]]);
        assert_eq!(ring(&square).map(|r| r.len()), Ok(4));
        let bowtie = ring_of(&[[0.0, 0.0], [2.0, 2.0], [2.0, 0.0], [0.0, 1.0], [0.0, 0.0]]);
        assert!(self_intersects(&ring(&bowtie).unwrap()));
        assert!(!self_intersects(&ring(&square).unwrap()));
    }

    #[test]
    fn a_ring_over_the_antimeridian_is_one_polygon() {
        let r = ring(&ring_of(&[
            [179.0, 0.0],
            [-179.0, 0.0],
            [-179.0, 1.0],
            [179.0, 1.0],
            [179.0, 0.0],
        ]))
        .unwrap();
        assert_eq!(
            r.iter().map(|p| p[0]).collect::<Vec<_>>(),
            [179.0, 181.0, 181.0, 179.0]
        );
        assert!((signed_area(&r) - 2.0).abs() < 1e-9);
    }

    #[test]
    fn a_ring_around_the_pole_covers_the_cap() {
        let coords: Vec<Vec<f64>> = (0..=8)
            .map(|k| vec![-180.0 + 45.0 * f64::from(k % 8), 80.0])
            .collect();
        let r = ring(&coords).unwrap();
        // Nine points along 80 N (the last a turn from the first), then the pole twice.
        assert_eq!(r.len(), 11);
        assert_eq!(r[8][0], 180.0);
        assert!(r[9][1] == 90.0 && r[10][1] == 90.0);
        let (v, i) = triangulate(&[r]);
        let area = indexed_area(&v, &i);
        assert!((area - 360.0 * 10.0).abs() < 1e-6, "{area}");
    }

    #[test]
    fn holes_are_cut_out() {
        let outer = ring(&ring_of(&[
            [0.0, 0.0],
            [4.0, 0.0],
            [4.0, 4.0],
            [0.0, 4.0],
            [0.0, 0.0],
        ]))
        .unwrap();
        let hole = ring(&ring_of(&[
            [1.0, 1.0],
            [1.0, 3.0],
            [3.0, 3.0],
            [3.0, 1.0],
            [1.0, 1.0],
        ]))
        .unwrap();
        let (v, i) = triangulate(&[outer, hole]);
        let area = indexed_area(&v, &i);
        assert!((area - 12.0).abs() < 1e-9, "{area}");
    }

    fn area(tris: &[[[f64; 2]; 3]]) -> f64 {
        tris.iter()
            .map(|[a, b, c]| ((b[0] - a[0]) * (c[1] - a[1]) - (b[1] - a[1]) * (c[0] - a[0])) / 2.0)
            .sum()
    }

    #[test]
    fn tessellated_polygons_keep_their_area_in_small_triangles() {
        // A concave L with a hole, 10 x 10 degrees.
        let outer = ring(&ring_of(&[
            [0.0, 0.0],
            [10.0, 0.0],
            [10.0, 4.0],
            [4.0, 4.0],
            [4.0, 10.0],
            [0.0, 10.0],
            [0.0, 0.0],
        ]))
        .unwrap();
        let hole = ring(&ring_of(&[
            [1.0, 1.0],
            [1.0, 2.0],
            [2.0, 2.0],
            [2.0, 1.0],
            [1.0, 1.0],
        ]))
        .unwrap();
        let tris = tessellate(&[outer, hole], 1.0);
        assert!(
            (area(&tris) - (40.0 + 24.0 - 1.0)).abs() < 1e-9,
            "{}",
            area(&tris)
        );
        for t in &tris {
            for d in 0..2 {
                let (lo, hi) = t
                    .iter()
                    .fold((f64::MAX, f64::MIN), |m, p| (m.0.min(p[d]), m.1.max(p[d])));
                assert!(hi - lo <= 1.0 + 1e-9);
            }
        }
        // Over the antimeridian and round the pole, as triangulate.
        let coords: Vec<Vec<f64>> = (0..=8)
            .map(|k| vec![-180.0 + 45.0 * f64::from(k % 8), 80.0])
            .collect();
        assert!((area(&tessellate(&[ring(&coords).unwrap()], 2.0)) - 3600.0).abs() < 1e-6);
    }

    #[test]
    fn rhumb_latitude_round_trips() {
        let e = 0.081_819_190_842_622;
        for lat in [-89.0, -45.0, 0.0, 12.5, 60.0, 89.9] {
            assert!((geodetic_from_isometric(isometric(lat, e), e) - lat).abs() < 1e-10);
        }
    }

    #[test]
    fn densified_lines_keep_their_ends_and_split_long_pieces() {
        let e = Ellipsoid::WGS84;
        let pts = [[0.0, 50.0, 0.0], [30.0, 50.0, 0.0]];
        let d = densify(&e, &pts, false, PathKind::Geodesic, Straight::LonLat, 1.0);
        assert!(d.len() > 30, "{}", d.len());
        assert_eq!(d.first(), Some(&pts[0]));
        assert_eq!(d.last(), Some(&pts[1]));
        // A rhumb line along a parallel is straight in lon/lat: nothing to add.
        let r = densify(&e, &pts, false, PathKind::Rhumb, Straight::LonLat, 1.0);
        assert_eq!(r.len(), 2);
        // Over the antimeridian, longitudes stay continuous.
        let pts = [[179.0, 10.0, 0.0], [181.0, 10.0, 0.0]];
        let d = densify(&e, &pts, false, PathKind::Geodesic, Straight::LonLat, 1.0);
        assert!(
            d.windows(2)
                .all(|w| w[1][0] > w[0][0] && w[1][0] - w[0][0] < 2.0),
            "{d:?}"
        );
    }

    #[test]
    fn pieces_skipped_as_short_are_within_the_tolerance() {
        // Pieces just short enough to be skipped, at every latitude up to 89 degrees, in
        // every direction, for each path and drawing: the midpoint test they skip would
        // have passed, with room to spare.
        let e = Ellipsoid::WGS84;
        let radii = e.radii();
        let geodesic = Geodesic::new(radii.x, 1.0 - radii.z / radii.x);
        let mut skipped = 0;
        for path in [PathKind::Geodesic, PathKind::Rhumb] {
            for straight in [Straight::LonLat, Straight::Chord] {
                let curve = Curve {
                    ellipsoid: &e,
                    geodesic: &geodesic,
                    path,
                    straight,
                    tolerance_m: 1.0,
                };
                for lat10 in 0..=889 {
                    let lat = f64::from(lat10) / 10.0;
                    for k in 0..8 {
                        let azi = f64::from(k) * 0.785 + 0.1;
                        // Lengths from 100 m to 40 km.
                        for step in [1e-3, 1e-2, 0.05, 0.1, 0.2, 0.4] {
                            let a = [10.0, lat, 0.0];
                            let b = [10.0 + step * azi.sin(), lat + step * azi.cos() * 0.5, 0.0];
                            if b[1].abs() > 89.0 || !curve.surely_within_tolerance(a, b) {
                                continue;
                            }
                            skipped += 1;
                            let mid = curve.midpoint(a, b).expect("a midpoint");
                            let off = (curve.drawn_midpoint(a, b) - curve.ecef(mid)).length();
                            assert!(off <= 0.6, "{path:?} {straight:?} {a:?}-{b:?}: {off} m");
                        }
                    }
                }
            }
        }
        assert!(skipped > 20_000, "{skipped}");
    }
}
