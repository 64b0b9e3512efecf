//! Draping: lines and fills placed exactly on the triangles of the terrain mesh a tile is
//! drawn with.
//!
//! Why this technique. The choices were (a) rasterising vector data into a texture per tile
//! (MapLibre, iTowns): exact in position, but a line's width is then in texels, which at a
//! low pitch are several pixels tall near the camera and a fraction far away, so pixel-wide
//! lines cannot hold their width within 1 px; (b) shadow volumes (CesiumJS ground
//! primitives): exact on any terrain, but two extra passes with a stencil per batch, and
//! volumes of neighbouring features that overlap on screen colour each other's ground unless
//! drawn one feature at a time (hundreds of draw calls for the countries file); (c) this:
//! cut each line and fill along the edges of the drawn tile's own triangles. Inside one
//! terrain triangle the surface is a plane and the map from the tile's (u, v) to the 3D
//! point is affine, so a piece of line straight in (u, v) is a straight 3D segment *on* that
//! plane, and a fill's piece is a flat polygon on it: the draped geometry lies on the drawn
//! surface to f32 rounding, at whatever level the tile is, and screen-space line widths stay
//! exact because lines are drawn as screen-space ribbons over it. The price is CPU work per
//! tile when it first becomes drawn (cached with the tile; nothing is recomputed while the
//! drawn tiles stay the same) and GPU triangles for covered tiles about equal to the
//! terrain's own.
//!
//! Longitudes may be unwrapped (beyond +-180, see [`crate::shape`]): geometry is tried at
//! every whole-turn shift that brings it over the tile.
//!
//! Geomorphing: a tile that is growing out of its parent draws each vertex lifted along the
//! body's normal towards the parent's surface by a fraction of its morph height. A surface
//! given its vertices' morph heights ([`DrapeSurface::with_lifts`]) interpolates them with
//! the positions, so every draped point carries the lift of the terrain under it
//! ([`SurfacePoint::lift_m`]) and the renderer lifts it with the terrain.
//!
//! Quadrants: every draped piece lies on one mesh triangle, and carries the quadrant of the
//! tile that triangle is in ([`globus_tiling::Quadrants::index_of`] of its centre). Terrain
//! meshes keep each quadrant's triangles apart, so a renderer drawing a tile over only some
//! of its quadrants (beside finer children) draws just those quadrants' pieces.

use globus_geo::DVec3;
use globus_tiling::Quadrants;

/// Buckets per side of the triangle index over a tile.
const CELLS: usize = 16;

/// One tile's drawn surface, ready for draping.
#[derive(Clone, Debug)]
pub struct DrapeSurface {
    /// West, south, east, north edges, degrees.
    rect_deg: [f64; 4],
    uv: Vec<[f64; 2]>,
    positions: Vec<DVec3>,
    triangles: Vec<[u32; 3]>,
    /// The quadrant of each triangle (of its centre), 0 to 3.
    quadrants: Vec<u8>,
    cells: Vec<Vec<u32>>,
    /// Skirt walls under the tile's edges: top vertices (on the edge) and the skirt vertices
    /// under them.
    skirts: Vec<[u32; 4]>,
    /// Per vertex, metres it moves along the body's normal to reach the parent's surface
    /// (empty: none).
    lifts: Vec<f64>,
}

/// A point on a draped surface, relative to the tile's origin, with the morph height of the
/// terrain there (metres along the body's normal to the parent's surface; 0 without one).
#[derive(Clone, Copy, Debug, PartialEq)]
pub struct SurfacePoint {
    /// The point.
    pub at: DVec3,
    /// Its morph height.
    pub lift_m: f64,
}

impl SurfacePoint {
    fn lerp(self, other: Self, t: f64) -> Self {
        Self {
            at: self.at.lerp(other.at, t),
            lift_m: self.lift_m + (other.lift_m - self.lift_m) * t,
        }
    }
}

/// A piece of a draped line: its ends on the surface (relative to the tile's origin) and
/// where they are along the input line, as fractional vertex indices (vertex `i` plus the
/// fraction of segment `i` to `i + 1`).
#[derive(Clone, Copy, Debug, PartialEq)]
pub struct DrapedSegment {
    /// Start on the surface.
    pub a: DVec3,
    /// End on the surface.
    pub b: DVec3,
    /// Start and end along the line.
    pub along: [f64; 2],
    /// The morph heights at the start and end ([`SurfacePoint::lift_m`]).
    pub lift_m: [f64; 2],
    /// The tile's quadrant it lies in, 0 to 3 ([`Quadrants::index_of`]).
    pub quadrant: u8,
    /// Whether the start and the end lie on the tile's border (where the line leaves the
    /// tile and the neighbour's piece goes on).
    pub on_border: [bool; 2],
}

/// A piece of a draped triangle: a triangle on one of the surface's triangles or skirt walls.
#[derive(Clone, Copy, Debug, PartialEq)]
pub struct DrapedTriangle {
    /// The corners, relative to the tile's origin.
    pub at: [SurfacePoint; 3],
    /// The tile's quadrant it lies in, 0 to 3 ([`Quadrants::index_of`]).
    pub quadrant: u8,
}

impl DrapeSurface {
    /// A surface over `rect_deg` (west, south, east, north) from its vertices' texture
    /// coordinates (u east from the west edge, v south from the north edge, 0..1), positions
    /// (relative to the tile's origin) and surface triangles. Triangles with an index out of
    /// range are dropped.
    pub fn new(
        rect_deg: [f64; 4],
        uv: Vec<[f64; 2]>,
        positions: Vec<DVec3>,
        triangles: Vec<[u32; 3]>,
    ) -> Self {
        let n = uv.len().min(positions.len()) as u32;
        let triangles: Vec<[u32; 3]> = triangles
            .into_iter()
            .filter(|t| t.iter().all(|&i| i < n))
            .collect();
        let mut cells = vec![Vec::new(); CELLS * CELLS];
        for (k, t) in triangles.iter().enumerate() {
            let [lo, hi] = bbox(t.map(|i| uv[i as usize]));
            let (i0, j0, i1, j1) = cell_span(lo, hi);
            for j in j0..=j1 {
                for i in i0..=i1 {
                    cells[j * CELLS + i].push(k as u32);
                }
            }
        }
        let quadrants = triangles
            .iter()
            .map(|t| {
                let [a, b, c] = t.map(|i| uv[i as usize]);
                quadrant_at([(a[0] + b[0] + c[0]) / 3.0, (a[1] + b[1] + c[1]) / 3.0])
            })
            .collect();
        Self {
            rect_deg,
            uv,
            positions,
            triangles,
            quadrants,
            cells,
            skirts: Vec::new(),
            lifts: Vec::new(),
        }
    }

    /// Gives the vertices morph heights (one per vertex, metres along the body's normal to
    /// the parent's surface), which draped points then carry. A list of another length is
    /// ignored (no lifts).
    pub fn with_lifts(mut self, lifts: Vec<f64>) -> Self {
        if lifts.len() == self.positions.len() {
            self.lifts = lifts;
        }
        self
    }

    /// Vertex `v` with its lift.
    fn vertex(&self, v: u32) -> SurfacePoint {
        SurfacePoint {
            at: self.positions[v as usize],
            lift_m: self.lifts.get(v as usize).copied().unwrap_or(0.0),
        }
    }

    /// Adds the tile's skirt walls (`[top0, top1, bottom0, bottom1]`: two vertices on an
    /// edge and the skirt vertices hanging under them), so draped fills cover them too and
    /// leave no seam where a coarser neighbour's edge lies lower. Walls with an index out of
    /// range are dropped.
    pub fn with_skirts(mut self, skirts: Vec<[u32; 4]>) -> Self {
        let n = self.uv.len().min(self.positions.len()) as u32;
        self.skirts = skirts
            .into_iter()
            .filter(|q| q.iter().all(|&i| i < n))
            .collect();
        self
    }

    /// Surface triangles.
    pub fn triangle_count(&self) -> usize {
        self.triangles.len()
    }

    /// West, south, east, north, degrees.
    pub fn rect_deg(&self) -> [f64; 4] {
        self.rect_deg
    }

    /// The whole-turn longitude shifts that bring `[lon_min, lon_max]` over the tile.
    pub fn shifts(&self, lon_min: f64, lon_max: f64) -> impl Iterator<Item = f64> + use<> {
        let [w, _, e, _] = self.rect_deg;
        (-2..=2)
            .map(|k| f64::from(k) * 360.0)
            .filter(move |s| lon_max + s >= w && lon_min + s <= e)
    }

    fn to_uv(&self, lon: f64, lat: f64) -> [f64; 2] {
        let [w, s, e, n] = self.rect_deg;
        [(lon - w) / (e - w), (n - lat) / (n - s)]
    }

    /// Drapes a line (longitude, latitude in degrees, shifted by `shift`): appends the 3D
    /// segments on the surface, relative to the tile's origin, in order along the line.
    pub fn drape_line(&self, pts: &[[f64; 2]], shift: f64, out: &mut Vec<DrapedSegment>) {
        let mut seen = vec![u32::MAX; self.triangles.len()];
        let mut pieces: Vec<(f64, f64, u32)> = Vec::new();
        for (s, w) in pts.windows(2).enumerate() {
            let a = self.to_uv(w[0][0] + shift, w[0][1]);
            let b = self.to_uv(w[1][0] + shift, w[1][1]);
            let Some((t0, t1)) = clip_to_unit(a, b) else {
                continue;
            };
            let at = |t: f64| [a[0] + (b[0] - a[0]) * t, a[1] + (b[1] - a[1]) * t];
            let [lo, hi] = bbox([at(t0), at(t1), at(t1)]);
            let (i0, j0, i1, j1) = cell_span(lo, hi);
            pieces.clear();
            for j in j0..=j1 {
                for i in i0..=i1 {
                    for &k in &self.cells[j * CELLS + i] {
                        if seen[k as usize] == s as u32 {
                            continue;
                        }
                        seen[k as usize] = s as u32;
                        let tri = self.triangles[k as usize].map(|v| self.uv[v as usize]);
                        if let Some((lo, hi)) = segment_in_triangle(a, b, tri, t0, t1) {
                            pieces.push((lo, hi, k));
                        }
                    }
                }
            }
            pieces.sort_by(|x, y| x.0.total_cmp(&y.0));
            let mut reached = t0;
            for &(lo, hi, k) in &pieces {
                // Along a shared edge both triangles report the piece: keep it once.
                if hi <= reached + 1e-12 {
                    continue;
                }
                let lo = lo.max(reached);
                reached = hi;
                let p = |t: f64| self.point_in(k, at(t));
                let along = [s as f64 + lo, s as f64 + hi];
                // Pieces meeting on a triangle edge share one end point exactly.
                let a = match out.last() {
                    Some(prev) if prev.along[1] == along[0] => SurfacePoint {
                        at: prev.b,
                        lift_m: prev.lift_m[1],
                    },
                    _ => p(lo),
                };
                let b = p(hi);
                out.push(DrapedSegment {
                    a: a.at,
                    b: b.at,
                    along,
                    lift_m: [a.lift_m, b.lift_m],
                    quadrant: self.quadrants[k as usize],
                    on_border: [on_unit_border(at(lo)), on_unit_border(at(hi))],
                });
            }
        }
    }

    /// Drapes a triangle (longitude, latitude in degrees, shifted by `shift`): appends the
    /// 3D triangles covering its part of the surface, relative to the tile's origin.
    pub fn drape_triangle(&self, tri: [[f64; 2]; 3], shift: f64, out: &mut Vec<DrapedTriangle>) {
        let t = tri.map(|p| self.to_uv(p[0] + shift, p[1]));
        let [lo, hi] = bbox(t);
        if hi[0] < 0.0 || hi[1] < 0.0 || lo[0] > 1.0 || lo[1] > 1.0 {
            return;
        }
        // The fill triangle's edges as inward half-planes.
        let orient = cross(t[0], t[1], t[2]);
        if orient == 0.0 || !orient.is_finite() {
            return;
        }
        let planes: [([f64; 2], [f64; 2]); 3] = if orient > 0.0 {
            [(t[0], t[1]), (t[1], t[2]), (t[2], t[0])]
        } else {
            [(t[0], t[2]), (t[2], t[1]), (t[1], t[0])]
        };
        let inside = |p: [f64; 2]| planes.iter().all(|&(a, b)| cross(a, b, p) >= 0.0);
        self.drape_skirts(t, lo, hi, out);
        let (i0, j0, i1, j1) = cell_span(lo, hi);
        let mut seen = vec![false; self.triangles.len()];
        let mut poly = Vec::with_capacity(9);
        let mut next = Vec::with_capacity(9);
        for j in j0..=j1 {
            for i in i0..=i1 {
                for &k in &self.cells[j * CELLS + i] {
                    if std::mem::replace(&mut seen[k as usize], true) {
                        continue;
                    }
                    let idx = self.triangles[k as usize];
                    let mesh = idx.map(|v| self.uv[v as usize]);
                    let [mlo, mhi] = bbox(mesh);
                    if mhi[0] < lo[0] || mhi[1] < lo[1] || mlo[0] > hi[0] || mlo[1] > hi[1] {
                        continue;
                    }
                    let quadrant = self.quadrants[k as usize];
                    if mesh.iter().all(|&p| inside(p)) {
                        out.push(DrapedTriangle {
                            at: idx.map(|v| self.vertex(v)),
                            quadrant,
                        });
                        continue;
                    }
                    poly.clear();
                    poly.extend_from_slice(&mesh);
                    for &(a, b) in &planes {
                        clip_polygon(&poly, a, b, &mut next);
                        std::mem::swap(&mut poly, &mut next);
                        if poly.len() < 3 {
                            break;
                        }
                    }
                    if poly.len() < 3 {
                        continue;
                    }
                    let p: Vec<SurfacePoint> = poly.iter().map(|&q| self.point_in(k, q)).collect();
                    for m in 1..p.len() - 1 {
                        out.push(DrapedTriangle {
                            at: [p[0], p[m], p[m + 1]],
                            quadrant,
                        });
                    }
                }
            }
        }
    }

    /// Appends the parts of the skirt walls under the fill triangle `t` (in u, v).
    fn drape_skirts(
        &self,
        t: [[f64; 2]; 3],
        lo: [f64; 2],
        hi: [f64; 2],
        out: &mut Vec<DrapedTriangle>,
    ) {
        for &[a, b, sa, sb] in &self.skirts {
            let (ua, ub) = (self.uv[a as usize], self.uv[b as usize]);
            let [slo, shi] = bbox([ua, ub, ub]);
            if shi[0] < lo[0] || shi[1] < lo[1] || slo[0] > hi[0] || slo[1] > hi[1] {
                continue;
            }
            let Some((t0, t1)) = segment_in_triangle(ua, ub, t, 0.0, 1.0) else {
                continue;
            };
            let p = |i: u32| self.vertex(i);
            let (top0, top1) = (p(a).lerp(p(b), t0), p(a).lerp(p(b), t1));
            let (bot0, bot1) = (p(sa).lerp(p(sb), t0), p(sa).lerp(p(sb), t1));
            let mid = (t0 + t1) / 2.0;
            let quadrant =
                quadrant_at([ua[0] + (ub[0] - ua[0]) * mid, ua[1] + (ub[1] - ua[1]) * mid]);
            out.push(DrapedTriangle {
                at: [top0, top1, bot0],
                quadrant,
            });
            out.push(DrapedTriangle {
                at: [top1, bot1, bot0],
                quadrant,
            });
        }
    }

    /// The point of the surface over (longitude, latitude) in degrees shifted by `shift`,
    /// relative to the tile's origin, if the tile covers it.
    pub fn point(&self, lon: f64, lat: f64, shift: f64) -> Option<SurfacePoint> {
        let q = self.to_uv(lon + shift, lat);
        if !(0.0..=1.0).contains(&q[0]) || !(0.0..=1.0).contains(&q[1]) {
            return None;
        }
        let (i, j, _, _) = cell_span(q, q);
        self.cells[j * CELLS + i].iter().copied().find_map(|k| {
            let tri = self.triangles[k as usize].map(|v| self.uv[v as usize]);
            let o = cross(tri[0], tri[1], tri[2]).signum();
            (0..3)
                .all(|e| cross(tri[e], tri[(e + 1) % 3], q) * o >= -1e-12)
                .then(|| self.point_in(k, q))
        })
    }

    /// The tile's quadrant (0 to 3, [`Quadrants::index_of`]) over (longitude, latitude) in
    /// degrees shifted by `shift`.
    pub fn quadrant(&self, lon: f64, lat: f64, shift: f64) -> u8 {
        quadrant_at(self.to_uv(lon + shift, lat))
    }

    /// The 3D point at `q` (u, v) in triangle `k`'s plane, and its lift.
    fn point_in(&self, k: u32, q: [f64; 2]) -> SurfacePoint {
        let idx = self.triangles[k as usize];
        let [a, b, c] = idx.map(|v| self.uv[v as usize]);
        let [pa, pb, pc] = idx.map(|v| self.vertex(v));
        let area = cross(a, b, c);
        if area == 0.0 {
            return pa;
        }
        let wb = cross(a, q, c) / area;
        let wc = cross(a, b, q) / area;
        let wa = 1.0 - wb - wc;
        SurfacePoint {
            at: pa.at * wa + pb.at * wb + pc.at * wc,
            lift_m: pa.lift_m * wa + pb.lift_m * wb + pc.lift_m * wc,
        }
    }
}

/// The quadrant holding (u, v).
fn quadrant_at([u, v]: [f64; 2]) -> u8 {
    Quadrants::index_of(u, v) as u8
}

fn cross(a: [f64; 2], b: [f64; 2], c: [f64; 2]) -> f64 {
    (b[0] - a[0]) * (c[1] - a[1]) - (b[1] - a[1]) * (c[0] - a[0])
}

fn bbox<const N: usize>(p: [[f64; 2]; N]) -> [[f64; 2]; 2] {
    let mut lo = [f64::INFINITY; 2];
    let mut hi = [f64::NEG_INFINITY; 2];
    for q in p {
        for d in 0..2 {
            lo[d] = lo[d].min(q[d]);
            hi[d] = hi[d].max(q[d]);
        }
    }
    [lo, hi]
}

fn cell_span(lo: [f64; 2], hi: [f64; 2]) -> (usize, usize, usize, usize) {
    let c = |x: f64| ((x * CELLS as f64).floor().max(0.0) as usize).min(CELLS - 1);
    (c(lo[0]), c(lo[1]), c(hi[0]), c(hi[1]))
}

/// The parameter interval of a..b inside the unit square (Liang-Barsky).
/// Whether `p` (texture coordinates) lies on the unit square's border, up to rounding.
fn on_unit_border(p: [f64; 2]) -> bool {
    const EPS: f64 = 1e-9;
    p.iter().any(|&c| c <= EPS || c >= 1.0 - EPS)
}

fn clip_to_unit(a: [f64; 2], b: [f64; 2]) -> Option<(f64, f64)> {
    let (mut t0, mut t1) = (0.0f64, 1.0f64);
    for d in 0..2 {
        let delta = b[d] - a[d];
        for (p, q) in [(-delta, a[d]), (delta, 1.0 - a[d])] {
            if p == 0.0 {
                if q < 0.0 {
                    return None;
                }
            } else {
                let r = q / p;
                if p < 0.0 {
                    t0 = t0.max(r);
                } else {
                    t1 = t1.min(r);
                }
            }
        }
    }
    (t1 > t0).then_some((t0, t1))
}

/// The part of a..b (parameters t0..t1) inside triangle `tri`, as a parameter interval.
fn segment_in_triangle(
    a: [f64; 2],
    b: [f64; 2],
    tri: [[f64; 2]; 3],
    t0: f64,
    t1: f64,
) -> Option<(f64, f64)> {
    let orient = cross(tri[0], tri[1], tri[2]);
    if orient == 0.0 {
        return None;
    }
    let (mut lo, mut hi) = (t0, t1);
    for e in 0..3 {
        let (p, q) = (tri[e], tri[(e + 1) % 3]);
        let fa = cross(p, q, a) * orient.signum();
        let fb = cross(p, q, b) * orient.signum();
        // f(t) = fa + t (fb - fa) >= 0, with a little slack so shared edges leave no gap.
        let slack = 1e-12;
        let d = fb - fa;
        if d.abs() < 1e-300 {
            if fa < -slack {
                return None;
            }
            continue;
        }
        let t = -fa / d;
        if d > 0.0 {
            lo = lo.max(t);
        } else {
            hi = hi.min(t);
        }
        if hi - lo <= 1e-12 {
            return None;
        }
    }
    Some((lo, hi))
}

/// Sutherland-Hodgman: the part of convex polygon `poly` left of a->b.
fn clip_polygon(poly: &[[f64; 2]], a: [f64; 2], b: [f64; 2], out: &mut Vec<[f64; 2]>) {
    out.clear();
    let n = poly.len();
    for i in 0..n {
        let (p, q) = (poly[i], poly[(i + 1) % n]);
        let (fp, fq) = (cross(a, b, p), cross(a, b, q));
        if fp >= 0.0 {
            out.push(p);
        }
        if (fp >= 0.0) != (fq >= 0.0) {
            let t = fp / (fp - fq);
            out.push([p[0] + (q[0] - p[0]) * t, p[1] + (q[1] - p[1]) * t]);
        }
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    /// A 4 x 4 grid over 10..11 E, 50..51 N with a height field that is not planar, as two
    /// triangles per cell; positions are (lon, lat, h) scaled to metres-ish for the test.
    fn surface() -> (DrapeSurface, impl Fn(f64, f64) -> f64) {
        let h = |u: f64, v: f64| 100.0 * (u * 3.0).sin() + 50.0 * (v * 5.0).cos();
        let n = 4;
        let mut uv = Vec::new();
        let mut pos = Vec::new();
        for j in 0..=n {
            for i in 0..=n {
                let (u, v) = (f64::from(i) / f64::from(n), f64::from(j) / f64::from(n));
                uv.push([u, v]);
                pos.push(DVec3::new(u * 1000.0, v * 1000.0, h(u, v)));
            }
        }
        let mut tris = Vec::new();
        let w = n + 1;
        for j in 0..n {
            for i in 0..n {
                let k = (j * w + i) as u32;
                tris.push([k, k + 1, k + w as u32]);
                tris.push([k + 1, k + w as u32 + 1, k + w as u32]);
            }
        }
        (
            DrapeSurface::new([10.0, 50.0, 11.0, 51.0], uv, pos, tris),
            h,
        )
    }

    /// The mesh's own height at (u, v): the plane of the triangle holding it.
    fn mesh_height(s: &DrapeSurface, u: f64, v: f64) -> f64 {
        for (k, t) in s.triangles.iter().enumerate() {
            let tri = t.map(|i| s.uv[i as usize]);
            let o = cross(tri[0], tri[1], tri[2]).signum();
            if (0..3).all(|e| cross(tri[e], tri[(e + 1) % 3], [u, v]) * o >= -1e-12) {
                return s.point_in(k as u32, [u, v]).at.z;
            }
        }
        f64::NAN
    }

    #[test]
    fn a_draped_line_lies_on_the_mesh_along_its_whole_length() {
        let (s, _) = surface();
        let mut out = Vec::new();
        // Diagonal across the tile, beyond its edges on both sides.
        s.drape_line(&[[9.8, 50.1], [11.3, 50.9]], 0.0, &mut out);
        assert!(out.len() >= 8, "{}", out.len());
        for seg in &out {
            for k in 0..=10 {
                let p = seg.a.lerp(seg.b, f64::from(k) / 10.0);
                let (u, v) = (p.x / 1000.0, p.y / 1000.0);
                let z = mesh_height(&s, u, v);
                assert!((p.z - z).abs() < 1e-9, "{p:?} vs {z}");
            }
        }
        // Continuous, from the west edge to the east edge.
        for w in out.windows(2) {
            assert_eq!(w[0].b, w[1].a);
            assert_eq!(w[0].along[1], w[1].along[0]);
            assert!(w[1].along[1] > w[1].along[0]);
        }
        // Along the input line: the tile's edges at lon 10 and 11 of 9.8..11.3.
        let first = out[0].along[0];
        let last = out[out.len() - 1].along[1];
        assert!((first - 0.2 / 1.5).abs() < 1e-9 && (last - 1.2 / 1.5).abs() < 1e-9);
        assert!(out[0].a.x.abs() < 1e-9 && (out[out.len() - 1].b.x - 1000.0).abs() < 1e-9);
        // Only where it crosses the tile's border are its ends on the border (where the
        // neighbour's piece goes on), not where pieces meet on the mesh's inner edges.
        let ends: Vec<bool> = out.iter().flat_map(|p| p.on_border).collect();
        let mut want = vec![false; ends.len()];
        want[0] = true;
        want[ends.len() - 1] = true;
        assert_eq!(ends, want);
        // A line that starts and ends inside the tile touches the border nowhere.
        out.clear();
        s.drape_line(&[[10.2, 50.3], [10.7, 50.6]], 0.0, &mut out);
        assert!(out.iter().all(|p| p.on_border == [false, false]));
    }

    #[test]
    fn a_line_along_a_mesh_edge_is_drawn_once() {
        let (s, _) = surface();
        let mut out = Vec::new();
        s.drape_line(&[[10.0, 50.5], [11.0, 50.5]], 0.0, &mut out);
        let length: f64 = out.iter().map(|p| (p.b - p.a).truncate().length()).sum();
        assert!((length - 1000.0).abs() < 1e-6, "{length}");
    }

    #[test]
    fn a_draped_triangle_covers_its_area_on_the_mesh() {
        let (s, _) = surface();
        let mut out = Vec::new();
        let tri = [[10.1, 50.1], [10.9, 50.2], [10.4, 50.8]];
        s.drape_triangle(tri, 0.0, &mut out);
        let area: f64 = out
            .iter()
            .map(|t| {
                let [a, b, c] = t.at.map(|p| [p.at.x, p.at.y]);
                cross(a, b, c).abs() / 2.0
            })
            .sum();
        let uv = tri.map(|p| [(p[0] - 10.0) * 1000.0, (51.0 - p[1]) * 1000.0]);
        let expected = cross(uv[0], uv[1], uv[2]).abs() / 2.0;
        assert!(
            (area - expected).abs() < 1e-6 * expected,
            "{area} vs {expected}"
        );
        for t in &out {
            let c = (t.at[0].at + t.at[1].at + t.at[2].at) / 3.0;
            assert!((c.z - mesh_height(&s, c.x / 1000.0, c.y / 1000.0)).abs() < 1e-9);
        }
        // A triangle covering the tile gives back the whole mesh.
        out.clear();
        s.drape_triangle([[0.0, 40.0], [40.0, 40.0], [0.0, 80.0]], 0.0, &mut out);
        assert_eq!(out.len(), s.triangle_count());
    }

    #[test]
    fn fills_cover_the_skirt_walls_under_them() {
        let (s, _) = surface();
        // A skirt under the north edge (v = 0) between its first two vertices, 100 m deep.
        let n = s.uv.len() as u32;
        let mut s = s;
        s.uv.push(s.uv[0]);
        s.uv.push(s.uv[1]);
        s.positions.push(s.positions[0] - DVec3::Z * 100.0);
        s.positions.push(s.positions[1] - DVec3::Z * 100.0);
        let plain = s.clone();
        let s = s.with_skirts(vec![[0, 1, n, n + 1]]);
        // A fill over the west half of that edge piece (u 0 .. 0.125) and beyond the tile.
        let fill = [[9.0, 52.0], [10.125, 52.0], [10.125, 50.5]];
        let (mut out, mut without) = (Vec::new(), Vec::new());
        s.drape_triangle(fill, 0.0, &mut out);
        plain.drape_triangle(fill, 0.0, &mut without);
        let walls: Vec<[SurfacePoint; 3]> = out
            .iter()
            .filter(|t| !without.contains(t))
            .map(|t| t.at)
            .collect();
        assert_eq!(walls.len(), 2, "{walls:?}");
        let area: f64 = walls
            .iter()
            .map(|t| ((t[1].at - t[0].at).cross(t[2].at - t[0].at)).length() / 2.0)
            .sum();
        // 125 m of edge (of 250) by 100 m.
        assert!((area - 125.0 * 100.0).abs() < 1.0, "{area}");
    }

    /// Pieces say which quarter of the tile they lie in (the grid's triangles keep to their
    /// quarters, as terrain meshes do), so a tile drawn over some quarters draws just theirs.
    #[test]
    fn draped_pieces_know_their_quadrant() {
        let (s, _) = surface();
        // (u, v) of a point of the test surface is its x, y over 1000.
        let of = |p: DVec3| Quadrants::index_of(p.x / 1000.0, p.y / 1000.0) as u8;
        let mut segs = Vec::new();
        s.drape_line(
            &[[9.8, 50.1], [11.3, 50.9], [10.2, 50.3], [10.2, 50.9]],
            0.0,
            &mut segs,
        );
        let mut seen = [false; 4];
        for seg in &segs {
            assert_eq!(seg.quadrant, of((seg.a + seg.b) / 2.0), "{seg:?}");
            seen[usize::from(seg.quadrant)] = true;
        }
        assert_eq!(seen, [true; 4]);
        let mut tris = Vec::new();
        s.drape_triangle([[0.0, 40.0], [40.0, 40.0], [0.0, 80.0]], 0.0, &mut tris);
        let mut per_quadrant = [0; 4];
        for t in &tris {
            let centre = (t.at[0].at + t.at[1].at + t.at[2].at) / 3.0;
            assert_eq!(t.quadrant, of(centre), "{t:?}");
            per_quadrant[usize::from(t.quadrant)] += 1;
        }
        assert_eq!(per_quadrant, [8; 4]);
        assert_eq!(s.quadrant(10.2, 50.9, 0.0), 0);
        assert_eq!(s.quadrant(10.7, 50.9, 0.0), 1);
        assert_eq!(s.quadrant(370.2, 50.1, -360.0), 2);
        assert_eq!(s.quadrant(10.7, 50.1, 0.0), 3);
    }

    #[test]
    fn a_draped_point_is_on_the_mesh() {
        let (s, _) = surface();
        let p = s.point(10.3, 50.6, 0.0).unwrap();
        assert!((p.at.z - mesh_height(&s, 0.3, 0.4)).abs() < 1e-9);
        assert_eq!(p.lift_m, 0.0);
        assert!(s.point(12.0, 50.6, 0.0).is_none());
    }

    #[test]
    fn shifted_geometry_lands_on_the_tile() {
        let (s, _) = surface();
        assert_eq!(s.shifts(369.0, 372.0).collect::<Vec<_>>(), [-360.0]);
        assert_eq!(s.shifts(20.0, 30.0).count(), 0);
        let mut out = Vec::new();
        s.drape_line(&[[370.2, 50.5], [370.8, 50.5]], -360.0, &mut out);
        assert!(!out.is_empty());
    }

    #[test]
    fn draped_points_carry_the_lift_of_the_terrain_under_them() {
        // Lifts that are a linear function of (u, v): every draped point's lift is that
        // function where it lies, as the GPU interpolates the terrain's.
        let (s, _) = surface();
        let lift = |u: f64, v: f64| 10.0 + 30.0 * u - 20.0 * v;
        let lifts = s.uv.iter().map(|&[u, v]| lift(u, v)).collect();
        let s = s.with_lifts(lifts);
        let check = |p: SurfacePoint| {
            let want = lift(p.at.x / 1000.0, p.at.y / 1000.0);
            assert!((p.lift_m - want).abs() < 1e-9, "{p:?}: {want}");
        };
        check(s.point(10.3, 50.6, 0.0).unwrap());
        let mut tris = Vec::new();
        s.drape_triangle([[10.1, 50.1], [10.9, 50.2], [10.4, 50.8]], 0.0, &mut tris);
        assert!(!tris.is_empty());
        tris.iter().flat_map(|t| t.at).for_each(check);
        let mut segs = Vec::new();
        s.drape_line(&[[9.8, 50.1], [11.3, 50.9]], 0.0, &mut segs);
        for seg in &segs {
            for (at, lift_m) in [(seg.a, seg.lift_m[0]), (seg.b, seg.lift_m[1])] {
                check(SurfacePoint { at, lift_m });
            }
        }
        // A list of the wrong length is ignored.
        let (s, _) = surface();
        assert_eq!(
            s.with_lifts(vec![1.0])
                .point(10.3, 50.6, 0.0)
                .unwrap()
                .lift_m,
            0.0
        );
    }
}
