//! [`TileMesh`]: a terrain tile's adaptive mesh in its own f32 frame, ready for the GPU.
//!
//! The mesh keeps only the samples of the tile's 33 x 33 grid that its error bound needs: a
//! right-triangle hierarchy ([`Rtin`]) cut at a vertical error of
//! [`MeshOptions::error_fraction`] times the tile's geometric error, half of it for the
//! heights and half for the curvature of the body between a triangle's corners (long
//! triangles are split until their sagitta fits). The error the cut adds is measured and
//! folded into [`TileMesh::geometric_error_m`], so LOD selection sees the mesh it draws.
//!
//! Positions are computed in f64 ECEF and stored as f32 offsets from the tile's centre, so
//! nothing large ever reaches an f32: a level-20 tile spans about 20 m, where f32 resolves
//! about 2 micrometres. Normals come from the height grid including its border ring, so they
//! are continuous across tile edges, and are stored oct-encoded in 2 x 16 bits.
//!
//! Borders: neighbouring meshes need not share edge vertices (their own cuts, or other
//! levels), so every edge carries a skirt hanging by [`TileMesh::skirt_depth_m`], sized from
//! the geometric error so it closes the largest crack that a neighbour up to two levels
//! coarser can leave (Ulrich 2002; Zeitler 2015, section 4.10; Cesium does the same).

use std::ops::Range;

use bytemuck::{Pod, Zeroable};
use globus_geo::{Cartographic, DVec2, DVec3, Ellipsoid};
use globus_tiling::{GLOBE_SCHEME, Quadrants, TileBounds, TileKey};

use crate::TerrainTile;
use crate::adaptive::{AdaptiveMesh, HeightGrid, Rtin, RtinScratch};
use crate::grid::{MESH_SEGMENTS, MESH_SIDE};

/// One vertex as the GPU reads it (20 bytes).
#[repr(C)]
#[derive(Clone, Copy, Debug, Default, PartialEq, Pod, Zeroable)]
pub struct TerrainVertex {
    /// Position relative to the tile centre, metres.
    pub position: [f32; 3],
    /// Unit normal, oct-encoded: x in the low 16 bits, y in the high 16 bits, both snorm.
    pub normal_oct: u32,
    /// Texture coordinates over the tile (0,0 north-west, 1,1 south-east), unorm16 x 2
    /// (u in the low half).
    pub uv: u32,
}

/// How tile meshes are cut and raised.
#[derive(Clone, Copy, Debug, PartialEq)]
pub struct MeshOptions {
    /// Vertical error the mesh may add to the full grid, as a fraction of the tile's
    /// geometric error; 0 keeps every grid sample.
    pub error_fraction: f64,
    /// Elevation exaggeration (Kaiser 2018, 3.4): every height is drawn this many times its
    /// value above the ellipsoid, and skirts, bounds and errors scale with it, so culling and
    /// LOD selection see the surface that is drawn. 1 draws true heights.
    pub exaggeration: f64,
}

impl Default for MeshOptions {
    fn default() -> Self {
        Self {
            error_fraction: 0.25,
            exaggeration: 1.0,
        }
    }
}

impl MeshOptions {
    /// Every grid sample kept (the regular grid), true heights.
    pub const FULL_GRID: Self = Self {
        error_fraction: 0.0,
        exaggeration: 1.0,
    };
}

/// A tile's mesh data on the CPU.
#[derive(Clone, Debug)]
pub struct TileMesh {
    /// The tile.
    pub key: TileKey,
    /// The tile's origin in ECEF: every vertex is relative to it.
    pub centre: DVec3,
    /// The surface vertices, then one skirt vertex per edge vertex (north, east, south and
    /// west edges), then one per vertex on the tile's north-south and west-east midlines.
    pub vertices: Vec<TerrainVertex>,
    /// Triangle list, counter-clockwise seen from outside: the surface triangles, then the
    /// skirt walls under the edges, then the inner skirts, each by quadrant (see
    /// [`MeshQuadrants`]).
    pub indices: Vec<u32>,
    /// Where each quadrant's triangles are in `indices`.
    pub quadrants: MeshQuadrants,
    /// Triangles of the surface (the rest are skirt walls).
    pub surface_triangles: u32,
    /// Exact bounds of all vertices, skirts included.
    pub bounds: TileBounds,
    /// How far skirts hang below the edges, metres.
    pub skirt_depth_m: f64,
    /// Largest vertical distance, metres, this mesh adds to the full grid (measured).
    pub cut_error_m: f64,
    /// The tile's geometric error with the cut's added, in true (unexaggerated) metres.
    pub geometric_error_m: f64,
    /// The elevation exaggeration the vertices were raised with
    /// ([`MeshOptions::exaggeration`]): drawn vertical distances are this many times true ones.
    pub exaggeration: f64,
}

/// Skirts reach this many times the tile's geometric error below its edges: a neighbour two
/// levels coarser has about four times the error, and the crack is at most the sum.
const SKIRT_ERROR_FACTOR: f64 = 6.0;

impl TileMesh {
    /// Builds the mesh of `tile` on `ellipsoid`; `occluder` is the horizon-culling body.
    pub fn build(
        tile: &TerrainTile,
        ellipsoid: &Ellipsoid,
        occluder: &Ellipsoid,
        options: &MeshOptions,
    ) -> Self {
        let rect = tile.rect;
        let n = f64::from(MESH_SEGMENTS);
        let lon_at = |i: i32| {
            let t = f64::from(i) / n;
            rect.west * (1.0 - t) + rect.east * t
        };
        let lat_at = |j: i32| {
            let t = f64::from(j) / n;
            rect.north * (1.0 - t) + rect.south * t
        };
        let exaggeration = options.exaggeration;
        let position = |i: i32, j: i32, dh: f64| {
            let h = f64::from(tile.height_at(i, j)) * exaggeration + dh;
            ellipsoid.cartographic_to_ecef(Cartographic::new(lon_at(i), lat_at(j), h))
        };
        let spacing_m = rect.height() / n * ellipsoid.mean_radius();
        let (adaptive, cut_error_m) = cut(tile, spacing_m, ellipsoid.mean_radius(), options);
        let reduced = GLOBE_SCHEME.columns(tile.key.level(), tile.key.y()) > 1;
        let geometric_error_m = tile.geometric_error_m + cut_error_m;
        // Drawn metres: cracks between neighbours are differences of exaggerated heights.
        let skirt_depth_m =
            SKIRT_ERROR_FACTOR * geometric_error_m * exaggeration + 0.02 * spacing_m;

        let edges = adaptive.edge_vertices();
        let midlines = midline_vertices(&adaptive);
        let surface = adaptive.vertices.len();
        let skirt_count: usize = edges.iter().chain(&midlines).map(Vec::len).sum();
        let mut grid_of = Vec::with_capacity(surface + skirt_count);
        grid_of.extend(adaptive.vertices.iter().map(|&[i, j]| (i, j, false)));
        for line in edges.iter().chain(&midlines) {
            grid_of.extend(line.iter().map(|&v| {
                let [i, j] = adaptive.vertices[v as usize];
                (i, j, true)
            }));
        }
        let (equatorward_row, push) = equatorward_push(tile, &adaptive, &edges, reduced);
        let mut points = Vec::with_capacity(grid_of.len());
        let mut normals = Vec::with_capacity(grid_of.len());
        for &(i, j, skirt) in &grid_of {
            let mut p = position(
                i32::from(i),
                i32::from(j),
                if skirt { -skirt_depth_m } else { 0.0 },
            );
            if j == equatorward_row {
                let f = push[usize::from(i)];
                p.x *= f;
                p.y *= f;
            }
            let (i, j) = (i32::from(i), i32::from(j));
            points.push(p);
            let east = position(i + 1, j, 0.0) - position(i - 1, j, 0.0);
            let south = position(i, j + 1, 0.0) - position(i, j - 1, 0.0);
            let up = ellipsoid.geodetic_normal_from_lon_lat(lon_at(i), lat_at(j));
            let normal = south
                .cross(east)
                .try_normalize()
                .filter(|v| v.dot(up) > 0.0)
                .unwrap_or(up);
            normals.push(normal);
        }
        let bounds = TileBounds::from_points(ellipsoid, occluder, &rect, &points)
            .unwrap_or_else(|| TileBounds::from_rect(ellipsoid, occluder, &rect, 0.0, 0.0));
        let centre = bounds.obb.centre;
        let vertices = points
            .iter()
            .zip(&normals)
            .zip(&grid_of)
            .map(|((p, normal), &(i, j, _))| {
                let local = *p - centre;
                TerrainVertex {
                    position: [local.x as f32, local.y as f32, local.z as f32],
                    normal_oct: encode_oct_normal(*normal),
                    uv: encode_uv(i, j),
                }
            })
            .collect();
        let (indices, quadrants) = triangles_by_quadrant(&adaptive, &edges, &midlines);
        Self {
            key: tile.key,
            centre,
            vertices,
            indices,
            quadrants,
            surface_triangles: adaptive.triangles.len() as u32,
            bounds,
            skirt_depth_m,
            cut_error_m,
            geometric_error_m,
            exaggeration,
        }
    }

    /// Bytes of vertex and index data.
    pub fn byte_size(&self) -> usize {
        self.vertices.len() * std::mem::size_of::<TerrainVertex>() + self.indices.len() * 4
    }

    /// Triangles, skirts included.
    pub fn triangle_count(&self) -> u32 {
        (self.indices.len() / 3) as u32
    }
}

/// A tile's north and south edges as a parallel's circle curves sideways under them: the
/// radius of that circle at the tile's equatorward edge (where it is widest), the width of
/// one grid cell there, and the stride (grid cells, a power of two) at which the edges keep
/// their samples so that a chord strays at most half `budget` from the circle.
fn parallel_edges(tile: &TerrainTile, radius_m: f64, budget: f64) -> (f64, f64, u16) {
    let rect = &tile.rect;
    let equatorward = if rect.north > 0.0 && rect.south < 0.0 {
        0.0
    } else {
        rect.north.abs().min(rect.south.abs())
    };
    let parallel_m = radius_m * equatorward.cos();
    let cell_width_m = rect.width() / f64::from(MESH_SEGMENTS) * parallel_m;
    // A chord across L cells strays (L w)^2 / (8 r) inside the circle.
    let leg = (4.0 * parallel_m * budget.max(0.0)).sqrt() / cell_width_m.max(f64::MIN_POSITIVE);
    let stride = 1u16 << (leg.max(1.0).log2().floor() as u32).min(5);
    (parallel_m, cell_width_m, stride)
}

/// The row of a reduced tile's edge nearer the equator, and per grid column the factor its
/// vertices there move away from the polar axis by: `1 / cos(d / 2)` for the longer of the
/// chords `d` (radians of longitude) beside them, so that every chord of that edge reaches
/// the parallel instead of cutting inside it. The neighbour across that edge, narrower or
/// finer, has shorter chords: without this a lens between the two chords (12 m across and
/// 1.9 km long for the level-9 polar row against level-10 tiles) let rays grazing along
/// the edge slip under both surfaces; now the two overlap by at most the chord's sagitta,
/// which the edge's sample stride keeps within half the mesh's error budget. Tiles that
/// are not reduced meet neighbours of their own width: factors 1.
fn equatorward_push(
    tile: &TerrainTile,
    mesh: &AdaptiveMesh,
    edges: &[Vec<u32>; 4],
    reduced: bool,
) -> (u16, Vec<f64>) {
    let last = MESH_SEGMENTS as u16;
    let north_hemisphere = tile.rect.south >= 0.0;
    let (row, edge) = if north_hemisphere {
        (last, &edges[2])
    } else {
        (0, &edges[0])
    };
    let mut push = vec![1.0; MESH_SIDE as usize];
    if !reduced || (tile.rect.north > 0.0 && tile.rect.south < 0.0) {
        return (row, push);
    }
    let xs: Vec<u16> = edge.iter().map(|&v| mesh.vertices[v as usize][0]).collect();
    let cell = tile.rect.width() / f64::from(MESH_SEGMENTS);
    for (k, &x) in xs.iter().enumerate() {
        let before = k.checked_sub(1).map_or(0, |p| x - xs[p]);
        let after = xs.get(k + 1).map_or(0, |&n| n - x);
        let d = f64::from(before.max(after)) * cell;
        push[usize::from(x)] = 1.0 / (d * 0.5).cos();
    }
    (row, push)
}

/// The tile's grid cut to `options`, and the vertical error the cut adds (heights plus the
/// sagitta of the body under its longest triangle legs).
fn cut(
    tile: &TerrainTile,
    spacing_m: f64,
    radius_m: f64,
    options: &MeshOptions,
) -> (AdaptiveMesh, f64) {
    let side = MESH_SIDE as usize;
    let heights = (0..side * side)
        .map(|k| tile.height_at((k % side) as i32, (k / side) as i32))
        .collect();
    let grid = match HeightGrid::new(side, heights) {
        Ok(grid) => grid,
        Err(e) => unreachable!("the tile grid is 2^5 + 1 samples: {e}"),
    };
    let budget = options.error_fraction * tile.geometric_error_m;
    if budget.is_nan() || budget <= 0.0 {
        return (Rtin::new(&grid).mesh_with(-1.0, 1), 0.0);
    }
    // Built for the one bound the tile is cut at (the same mesh as a full build's).
    let mut rtin = Rtin::default();
    rtin.rebuild_for(&grid, &mut RtinScratch::default(), budget * 0.5);
    // Sagitta of a right triangle with legs of L cells (hypotenuse L sqrt 2): the body bulges
    // (L s)^2 / (4 R) under its circumcircle. Allow half the budget for that.
    // Legs of at most half the tile: every triangle lies in one quadrant (see
    // [`MeshQuadrants`]).
    let max_leg = ((2.0 * radius_m * budget).sqrt() / spacing_m)
        .floor()
        .clamp(1.0, f64::from(MESH_SEGMENTS / 2)) as u16;
    // Along a parallel the surface also curves sideways, round a circle of radius R cos(lat):
    // near a pole far tighter than R, and a reduced polar tile is wide. A north or south
    // edge's chord strays inside that circle where a narrower neighbour's chords do not: a
    // gap a vertical skirt closes only from the side. Keep those edges' samples at a stride
    // whose chords stray at most half the budget (the skirts cover what is left).
    let (_, _, stride) = parallel_edges(tile, radius_m, budget);
    if stride < max_leg {
        let last = MESH_SEGMENTS as u16;
        rtin.require(|x, y| (y == 0 || y == last) && x % stride == 0);
    }
    let mesh = rtin.mesh_with(budget * 0.5, max_leg);
    // Longest edge (a right triangle's hypotenuse), grid cells.
    let longest = mesh
        .triangles
        .iter()
        .flat_map(|t| {
            let p = t.map(|k| mesh.vertices[k as usize]);
            (0..3).map(move |k| {
                let (a, b) = (p[k], p[(k + 1) % 3]);
                f64::from(a[0].abs_diff(b[0])).hypot(f64::from(a[1].abs_diff(b[1])))
            })
        })
        .fold(0.0, f64::max);
    // Sagitta under the circumcircle (radius: half the hypotenuse). The full grid's own
    // (one-cell triangles) is already part of the tile's error.
    let sagitta = if longest > 1.5 {
        (longest * spacing_m).powi(2) / (8.0 * radius_m)
    } else {
        0.0
    };
    let error = mesh.max_error(&grid) + sagitta;
    (mesh, error)
}

/// Where the quadrants of a tile's mesh lie in its index list, so a renderer can draw part
/// of a tile: selection draws a tile over the quadrants of its children that are still
/// loading while the loaded ones are drawn over the rest ([`globus_tiling::DrawTile::parts`]).
///
/// Meshes are cut to triangles with legs of at most half the tile, so no triangle crosses
/// a midline and each lies in one quadrant (a flat tile has 8 triangles, not 2). The index
/// list holds the surface triangles quadrant by quadrant (north-west, north-east,
/// south-west, south-east, as [`globus_tiling::Quadrants`] numbers them), then the skirt
/// walls under the tile's edges the same way, then the inner skirts: walls under each
/// quadrant's two edges on the midlines, facing the neighbouring quadrant. A child drawn
/// beside a part has skirts of its own, facing the part; the inner skirts close the crack
/// seen from the child's side, where the part's edge is the higher. A whole tile is drawn
/// without them ([`MeshQuadrants::whole`]): under a continuous surface they would never show.
#[derive(Clone, Copy, Debug, Default, PartialEq, Eq)]
pub struct MeshQuadrants {
    /// Index offsets: section `s` (0 surface, 1 edge skirts, 2 inner skirts) of quadrant `q`
    /// is `ends[4 s + q] .. ends[4 s + q + 1]`.
    ends: [u32; 13],
}

impl MeshQuadrants {
    /// The indices of the whole tile: its surface and edge skirts.
    pub fn whole(&self) -> Range<u32> {
        0..self.ends[8]
    }

    /// The indices of the surface triangles.
    pub fn surface(&self) -> Range<u32> {
        0..self.ends[4]
    }

    /// The indices of the skirt walls under the tile's edges.
    pub fn edge_skirts(&self) -> Range<u32> {
        self.ends[4]..self.ends[8]
    }

    /// Section `section` (0 surface, 1 edge skirts, 2 inner skirts) of quadrant `q`.
    pub fn section(&self, section: usize, q: usize) -> Range<u32> {
        self.ends[4 * section + q]..self.ends[4 * section + q + 1]
    }

    /// Calls `f` with the index ranges that draw the quadrants in `parts` (with their inner
    /// skirts unless all are drawn), in index order, adjacent ones merged: at most 6.
    pub fn ranges(&self, parts: Quadrants, mut f: impl FnMut(Range<u32>)) {
        if parts.is_all() {
            f(self.whole());
            return;
        }
        let sections = (0..3).flat_map(|section| {
            (0..4)
                .filter(move |&q| parts.contains(q))
                .map(move |q| self.section(section, q))
        });
        globus_tiling::merge_touching(sections, f);
    }
}

/// The surface vertices on the tile's midlines, sorted along them: the north-south one (x
/// half the grid, north to south) and the west-east one (y half the grid, west to east).
fn midline_vertices(mesh: &AdaptiveMesh) -> [Vec<u32>; 2] {
    let half = ((mesh.side - 1) / 2) as u16;
    let mut lines: [Vec<(u16, u32)>; 2] = Default::default();
    for (i, &[x, y]) in mesh.vertices.iter().enumerate() {
        if x == half {
            lines[0].push((y, i as u32));
        }
        if y == half {
            lines[1].push((x, i as u32));
        }
    }
    lines.map(|mut l| {
        l.sort_unstable();
        l.into_iter().map(|(_, i)| i).collect()
    })
}

/// The index list and its quadrants (see [`MeshQuadrants`]): surface triangles, skirt walls
/// under each edge facing outwards, inner walls under each quadrant's midline edges facing
/// the next quadrant. `edges` and `midlines` hold surface vertices; their skirt vertices
/// follow the surface ones in the same order.
fn triangles_by_quadrant(
    mesh: &AdaptiveMesh,
    edges: &[Vec<u32>; 4],
    midlines: &[Vec<u32>; 2],
) -> (Vec<u32>, MeshQuadrants) {
    let twice_half = (mesh.side - 1) as u32; // twice the midline coordinate
    let grid = |v: u32| mesh.vertices[v as usize].map(u32::from);
    // The quadrant of a segment or triangle from the sum of its corners' coordinates.
    let quadrant = |sx: u32, sy: u32, corners: u32| {
        usize::from(sy * 2 >= twice_half * corners) * 2
            + usize::from(sx * 2 >= twice_half * corners)
    };
    let skirt_count: usize = edges.iter().chain(midlines).map(Vec::len).sum();
    let mut sections: [Vec<u32>; 12] = Default::default();
    for t in &mesh.triangles {
        let c = t.map(grid);
        let q = quadrant(c[0][0] + c[1][0] + c[2][0], c[0][1] + c[1][1] + c[2][1], 3);
        debug_assert!(
            c.iter().all(|p| quadrant(p[0] * 2, p[1] * 2, 2) == q
                || p[0] == twice_half / 2
                || p[1] == twice_half / 2),
            "a triangle crosses a midline"
        );
        sections[q].extend_from_slice(t);
    }
    // A wall under the segment g0-g1 (sorted west to east or north to south) with skirt
    // vertices s0, s1, facing north or east (else south or west).
    let wall = |out: &mut Vec<u32>, g0, g1, s0, s1, north_or_east: bool| {
        if north_or_east {
            out.extend_from_slice(&[g0, g1, s0, g1, s1, s0]);
        } else {
            out.extend_from_slice(&[g0, s0, g1, g1, s0, s1]);
        }
    };
    let mut skirt = mesh.vertices.len() as u32;
    // Edges are sorted north (west to east), east (north to south), south, west.
    for (e, edge) in edges.iter().enumerate() {
        for k in 1..edge.len() {
            let (g0, g1) = (edge[k - 1], edge[k]);
            let (a, b) = (grid(g0), grid(g1));
            let q = quadrant(a[0] + b[0], a[1] + b[1], 2);
            let s0 = skirt + k as u32 - 1;
            wall(&mut sections[4 + q], g0, g1, s0, s0 + 1, e < 2);
        }
        skirt += edge.len() as u32;
    }
    // The north-south midline: west quadrants' walls face east, east quadrants' west.
    // The west-east one: north quadrants' walls face south, south quadrants' north.
    for (m, line) in midlines.iter().enumerate() {
        for k in 1..line.len() {
            let (g0, g1) = (line[k - 1], line[k]);
            let (a, b) = (grid(g0), grid(g1));
            let s0 = skirt + k as u32 - 1;
            let (first, second) = if m == 0 {
                // North or south half of the line: quadrants 0 | 1 or 2 | 3.
                let row = quadrant(0, a[1] + b[1], 2);
                (row, row + 1)
            } else {
                let column = quadrant(a[0] + b[0], 0, 2);
                (column, column + 2)
            };
            // The first (west or north) quadrant's wall faces east or south, the second's
            // west or north.
            wall(&mut sections[8 + first], g0, g1, s0, s0 + 1, m == 0);
            wall(&mut sections[8 + second], g0, g1, s0, s0 + 1, m == 1);
        }
        skirt += line.len() as u32;
    }
    let mut idx = Vec::with_capacity(mesh.triangles.len() * 3 + skirt_count * 12);
    let mut ends = [0u32; 13];
    for (k, section) in sections.iter().enumerate() {
        idx.extend_from_slice(section);
        ends[k + 1] = idx.len() as u32;
    }
    (idx, MeshQuadrants { ends })
}

/// Grid sample (`i`, `j`) as unorm16 texture coordinates.
fn encode_uv(i: u16, j: u16) -> u32 {
    let q = |k: u16| (f64::from(k) / f64::from(MESH_SEGMENTS) * 65535.0).round() as u32;
    q(i) | (q(j) << 16)
}

/// Oct-encodes a unit vector (Cigolle et al., "A Survey of Efficient Representations for
/// Independent Unit Vectors", JCGT 2014) into two snorm16 values packed in a `u32`.
pub fn encode_oct_normal(n: DVec3) -> u32 {
    let p = oct_project(n);
    let q = |v: f64| ((v.clamp(-1.0, 1.0) * 32767.0).round() as i16) as u16;
    u32::from(q(p.x)) | (u32::from(q(p.y)) << 16)
}

/// Inverse of [`encode_oct_normal`] (the shader does the same).
pub fn decode_oct_normal(packed: u32) -> DVec3 {
    let f = |bits: u16| (f64::from(bits as i16) / 32767.0).max(-1.0);
    oct_unproject(DVec2::new(f(packed as u16), f((packed >> 16) as u16)))
}

/// A unit vector projected onto the octahedron and unfolded into the square [-1, 1]^2
/// (the part every oct encoding shares; only the quantisation differs).
pub(crate) fn oct_project(n: DVec3) -> DVec2 {
    let l1 = n.x.abs() + n.y.abs() + n.z.abs();
    if l1 == 0.0 {
        return DVec2::ZERO;
    }
    let p = DVec2::new(n.x, n.y) / l1;
    if n.z < 0.0 {
        (DVec2::ONE - DVec2::new(p.y.abs(), p.x.abs())) * DVec2::new(sign(p.x), sign(p.y))
    } else {
        p
    }
}

/// Inverse of [`oct_project`].
pub(crate) fn oct_unproject(p: DVec2) -> DVec3 {
    let z = 1.0 - p.x.abs() - p.y.abs();
    let t = (-z).max(0.0);
    let x = p.x + if p.x >= 0.0 { -t } else { t };
    let y = p.y + if p.y >= 0.0 { -t } else { t };
    DVec3::new(x, y, z).normalize_or_zero()
}

fn sign(v: f64) -> f64 {
    if v >= 0.0 { 1.0 } else { -1.0 }
}

#[cfg(test)]
mod tests {
    use super::*;
    use crate::ProceduralPlanet;
    use crate::adaptive::for_each_sample_in;

    #[test]
    fn oct_normals_round_trip() {
        for n in [
            DVec3::X,
            DVec3::NEG_Z,
            DVec3::new(0.3, -0.5, -0.8).normalize(),
            DVec3::new(-1.0, 2.0, 3.0).normalize(),
        ] {
            let back = decode_oct_normal(encode_oct_normal(n));
            assert!(back.dot(n) > 0.999_99, "{n} -> {back}");
        }
    }

    fn mesh_with(key: TileKey, options: &MeshOptions) -> (TerrainTile, TileMesh) {
        let planet = ProceduralPlanet::new(1);
        let tile = planet.generate_tile(key);
        let m = TileMesh::build(&tile, &Ellipsoid::WGS84, &Ellipsoid::WGS84, options);
        (tile, m)
    }

    fn mesh(key: TileKey) -> (TerrainTile, TileMesh) {
        mesh_with(key, &MeshOptions::default())
    }

    fn point(m: &TileMesh, i: u32) -> DVec3 {
        let v = m.vertices[i as usize].position;
        m.centre + DVec3::new(f64::from(v[0]), f64::from(v[1]), f64::from(v[2]))
    }

    fn grid_position(m: &TileMesh, i: u32) -> [u16; 2] {
        let uv = m.vertices[i as usize].uv;
        let k = |q: u32| (f64::from(q) / 65535.0 * f64::from(MESH_SEGMENTS)).round() as u16;
        [k(uv & 0xffff), k(uv >> 16)]
    }

    #[test]
    fn triangles_face_outwards() {
        for key in [
            TileKey::new(5, 33, 10),
            TileKey::new(2, 2, 0),
            TileKey::new(16, 70_000, 16_000),
        ] {
            for options in [MeshOptions::default(), MeshOptions::FULL_GRID] {
                let (_, m) = mesh_with(key, &options);
                let tile_up = m.centre.normalize();
                let (mut walls, mut inner) = (0, 0);
                for (t, tri) in m.indices.chunks_exact(3).enumerate() {
                    let (a, b, c) = (point(&m, tri[0]), point(&m, tri[1]), point(&m, tri[2]));
                    let n = (b - a).cross(c - a);
                    if n.length() < 1e-9 {
                        continue; // degenerate (pole)
                    }
                    let at = t as u32 * 3;
                    if at >= m.quadrants.whole().end {
                        // Inner walls face away from their quadrant.
                        let q = (0..4)
                            .find(|&q| m.quadrants.section(2, q).contains(&at))
                            .expect("an inner wall is in a quadrant");
                        let corners: Vec<DVec3> = m.indices
                            [m.quadrants.section(0, q).start as usize..]
                            [..m.quadrants.section(0, q).len()]
                            .iter()
                            .map(|&v| point(&m, v))
                            .collect();
                        let middle = corners.iter().sum::<DVec3>() / corners.len() as f64;
                        let mid = (a + b + c) / 3.0;
                        let out = (mid - middle) - tile_up * (mid - middle).dot(tile_up);
                        assert!(
                            n.dot(out) > 0.0,
                            "{key:?}: inner skirt of {q} faces inwards"
                        );
                        inner += 1;
                    } else if t as u32 >= m.surface_triangles {
                        // Walls face away from the tile centre.
                        let mid = (a + b + c) / 3.0;
                        let out = (mid - m.centre) - tile_up * (mid - m.centre).dot(tile_up);
                        assert!(n.dot(out) > 0.0, "{key:?}: skirt faces inwards");
                        walls += 1;
                    } else {
                        assert!(n.dot(a.normalize()) > 0.0, "{key:?}: triangle faces down");
                    }
                }
                assert!(walls >= 8, "{key:?}: {walls} skirt walls");
                // Each quadrant has two inner edges of at least one segment, two triangles.
                assert!(inner >= 16, "{key:?}: {inner} inner walls");
                // Every triangle is in one quadrant's section, and the sections tile the list.
                let mut covered = 0;
                for section in 0..3 {
                    for q in 0..4 {
                        let r = m.quadrants.section(section, q);
                        assert_eq!(r.start, covered);
                        covered = r.end;
                    }
                }
                assert_eq!(covered as usize, m.indices.len());
                assert_eq!(m.quadrants.surface().end, m.surface_triangles * 3);
            }
            let (_, full) = mesh_with(key, &MeshOptions::FULL_GRID);
            assert_eq!(full.surface_triangles, 2 * 32 * 32);
            // The largest mesh is what the GPU pools are sized by.
            assert_eq!(full.vertices.len() as u32, crate::grid::MAX_MESH_VERTICES);
            assert_eq!(full.indices.len() as u32, crate::grid::MAX_MESH_INDICES);
            assert_eq!(full.cut_error_m, 0.0);
        }
    }

    #[test]
    fn quadrant_ranges_draw_exactly_the_parts_asked_for() {
        let (_, m) = mesh(TileKey::new(7, 140, 40));
        for mask in 1..=15u8 {
            let parts = Quadrants(mask);
            let mut got = Vec::new();
            m.quadrants.ranges(parts, |r| got.extend(r));
            let mut want = Vec::new();
            if parts.is_all() {
                want.extend(m.quadrants.whole());
            } else {
                for section in 0..3 {
                    for q in (0..4).filter(|&q| parts.contains(q)) {
                        want.extend(m.quadrants.section(section, q));
                    }
                }
            }
            assert_eq!(got, want, "{parts:?}");
            let mut runs = 0;
            m.quadrants.ranges(parts, |_| runs += 1);
            assert!(runs <= 6, "{parts:?}: {runs} ranges");
        }
        // Opposite corners: the north-west surface, the south-east surface and the north-west
        // edge skirts after it, the south-east edge skirts and the north-west inner ones, the
        // south-east inner ones.
        let mut runs = 0;
        m.quadrants.ranges(Quadrants(0b1001), |_| runs += 1);
        assert_eq!(runs, 4);
    }

    /// Every grid sample's true position against the drawn surface above or below it: the
    /// vertical gap stays within the mesh's geometric error, curvature included (a flat ocean
    /// tile at level 4 is cut into few triangles, and would sag kilometres without the leg
    /// limit).
    #[test]
    fn drawn_surface_stays_within_the_geometric_error() {
        let e = Ellipsoid::WGS84;
        for key in [
            TileKey::new(4, 5, 6),
            TileKey::new(7, 140, 40),
            TileKey::new(12, 2_170, 560),
            TileKey::new(17, 70_000, 16_000),
        ] {
            let (tile, m) = mesh(key);
            assert!(m.cut_error_m <= 0.25 * tile.geometric_error_m * (1.0 + 1e-6) + 1e-4);
            let rect = tile.rect;
            let n = f64::from(MESH_SEGMENTS);
            let truth = |i: usize, j: usize| {
                let (lon, lat) = (
                    rect.west + (rect.east - rect.west) * i as f64 / n,
                    rect.north + (rect.south - rect.north) * j as f64 / n,
                );
                let h = f64::from(tile.height_at(i as i32, j as i32));
                (
                    e.cartographic_to_ecef(Cartographic::new(lon, lat, h)),
                    e.geodetic_normal_from_lon_lat(lon, lat),
                )
            };
            let mut worst = 0.0f64;
            for tri in m.indices[..m.surface_triangles as usize * 3].chunks_exact(3) {
                let g = [tri[0], tri[1], tri[2]].map(|v| grid_position(&m, v));
                let p = [tri[0], tri[1], tri[2]].map(|v| point(&m, v));
                for_each_sample_in(g, |i, j, w| {
                    let drawn = p[0] * w[0] + p[1] * w[1] + p[2] * w[2];
                    let (true_p, up) = truth(i, j);
                    worst = worst.max((true_p - drawn).dot(up).abs());
                });
            }
            assert!(
                worst <= m.geometric_error_m + 0.01,
                "{key:?}: drawn surface {worst:.3} m from the samples, error {:.3} m",
                m.geometric_error_m
            );
        }
    }

    #[test]
    fn adaptive_meshes_drop_samples_where_the_ground_is_smooth() {
        // Open ocean at level 9 and a mountain tile: the ocean keeps few samples.
        let (_, ocean) = mesh(TileKey::new(9, 300, 260));
        let (_, full) = mesh_with(TileKey::new(9, 300, 260), &MeshOptions::FULL_GRID);
        assert!(
            ocean.surface_triangles * 4 <= full.surface_triangles,
            "ocean: {} of {} triangles",
            ocean.surface_triangles,
            full.surface_triangles
        );
    }

    #[test]
    fn bounds_contain_every_vertex_and_offsets_are_small() {
        let (tile, m) = mesh(TileKey::new(18, 140_000, 70_000));
        for i in 0..m.vertices.len() as u32 {
            assert!(m.bounds.obb.contains(point(&m, i), 1e-3));
            let v = m.vertices[i as usize].position;
            assert!(DVec3::from_array(v.map(f64::from)).length() < 200.0);
        }
        assert!(m.skirt_depth_m > 6.0 * tile.geometric_error_m);
        assert!(m.indices.iter().all(|&i| (i as usize) < m.vertices.len()));
    }

    #[test]
    fn normals_are_continuous_across_tiles() {
        let (_, a) = mesh(TileKey::new(10, 1060, 250));
        let (_, b) = mesh(TileKey::new(10, 1061, 250));
        let edge = |m: &TileMesh, column: u16| -> Vec<(u16, DVec3)> {
            (0..m.vertices.len() as u32)
                .filter(|&v| grid_position(m, v)[0] == column)
                .map(|v| {
                    let n = decode_oct_normal(m.vertices[v as usize].normal_oct);
                    (grid_position(m, v)[1], n)
                })
                .collect()
        };
        let (east, west) = (edge(&a, 32), edge(&b, 0));
        let mut shared = 0;
        for (row, na) in &east {
            for (_, nb) in west.iter().filter(|(r, _)| r == row) {
                assert!(
                    na.dot(*nb) > 0.9999,
                    "edge normal at row {row}: {na} vs {nb}"
                );
                shared += 1;
            }
        }
        assert!(shared >= 4, "{shared} shared edge samples");
    }
}
