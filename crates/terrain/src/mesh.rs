//! [`TileMesh`]: a terrain tile's vertices in its own f32 frame, ready for the GPU.
//!
//! Positions are computed in f64 ECEF and stored as f32 offsets from the tile's centre, so
//! nothing large ever reaches an f32: a level-20 tile spans about 20 m, where f32 resolves
//! about 2 micrometres. Normals come from the height grid including its border ring, so they
//! are continuous across tile edges, and are stored oct-encoded in 2 x 16 bits.
//!
//! Skirts hang below each edge by [`TileMesh::skirt_depth_m`], sized from the tile's geometric
//! error so they close the largest crack that a neighbour up to two levels coarser can leave
//! (Ulrich 2002; Zeitler 2015, section 4.10).

use bytemuck::{Pod, Zeroable};
use globus_geo::{Cartographic, DVec2, DVec3, Ellipsoid};
use globus_tiling::{TileBounds, TileKey};

use crate::TerrainTile;
use crate::grid::{MESH_SEGMENTS, MESH_SIDE, VERTICES_PER_TILE, vertex_grid_position};

/// One vertex as the GPU reads it (16 bytes).
#[repr(C)]
#[derive(Clone, Copy, Debug, Default, PartialEq, Pod, Zeroable)]
pub struct TerrainVertex {
    /// Position relative to the tile centre, metres.
    pub position: [f32; 3],
    /// Unit normal, oct-encoded: x in the low 16 bits, y in the high 16 bits, both snorm.
    pub normal_oct: u32,
}

/// A tile's mesh data on the CPU.
#[derive(Clone, Debug)]
pub struct TileMesh {
    /// The tile.
    pub key: TileKey,
    /// The tile's origin in ECEF: every vertex is relative to it.
    pub centre: DVec3,
    /// [`VERTICES_PER_TILE`] vertices in [`crate::grid`] order.
    pub vertices: Vec<TerrainVertex>,
    /// Exact bounds of all vertices, skirts included.
    pub bounds: TileBounds,
    /// How far skirts hang below the edges, metres.
    pub skirt_depth_m: f64,
}

/// Skirts reach this many times the tile's geometric error below its edges: a neighbour two
/// levels coarser has about four times the error, and the crack is at most the sum.
const SKIRT_ERROR_FACTOR: f64 = 6.0;

impl TileMesh {
    /// Builds the mesh of `tile` on `ellipsoid`; `occluder` is the horizon-culling body.
    pub fn build(tile: &TerrainTile, ellipsoid: &Ellipsoid, occluder: &Ellipsoid) -> Self {
        let rect = tile.rect;
        let lon_at = |i: i32| {
            let t = f64::from(i) / f64::from(MESH_SEGMENTS);
            rect.west * (1.0 - t) + rect.east * t
        };
        let lat_at = |j: i32| {
            let t = f64::from(j) / f64::from(MESH_SEGMENTS);
            rect.north * (1.0 - t) + rect.south * t
        };
        let position = |i: i32, j: i32, dh: f64| {
            let h = f64::from(tile.height_at(i, j)) + dh;
            ellipsoid.cartographic_to_ecef(Cartographic::new(lon_at(i), lat_at(j), h))
        };
        let mesh_spacing_m = rect.height() / f64::from(MESH_SEGMENTS) * ellipsoid.mean_radius();
        let skirt_depth_m = SKIRT_ERROR_FACTOR * tile.geometric_error_m + 0.02 * mesh_spacing_m;
        let mut points = Vec::with_capacity(VERTICES_PER_TILE as usize);
        let mut normals = Vec::with_capacity(VERTICES_PER_TILE as usize);
        for v in 0..VERTICES_PER_TILE {
            let (i, j, skirt) = vertex_grid_position(v);
            let (i, j) = (i as i32, j as i32);
            points.push(position(i, j, if skirt { -skirt_depth_m } else { 0.0 }));
            let east = position(i + 1, j, 0.0) - position(i - 1, j, 0.0);
            let south = position(i, j + 1, 0.0) - position(i, j - 1, 0.0);
            let up = ellipsoid.geodetic_normal_from_lon_lat(lon_at(i), lat_at(j));
            let n = south
                .cross(east)
                .try_normalize()
                .filter(|n| n.dot(up) > 0.0)
                .unwrap_or(up);
            normals.push(n);
        }
        let bounds = TileBounds::from_points(ellipsoid, occluder, &rect, &points)
            .unwrap_or_else(|| TileBounds::from_rect(ellipsoid, occluder, &rect, 0.0, 0.0));
        let centre = bounds.obb.centre;
        let vertices = points
            .iter()
            .zip(&normals)
            .map(|(p, n)| {
                let local = *p - centre;
                TerrainVertex {
                    position: [local.x as f32, local.y as f32, local.z as f32],
                    normal_oct: encode_oct_normal(*n),
                }
            })
            .collect();
        debug_assert_eq!(MESH_SIDE * MESH_SIDE + 4 * MESH_SIDE, VERTICES_PER_TILE);
        Self {
            key: tile.key,
            centre,
            vertices,
            bounds,
            skirt_depth_m,
        }
    }

    /// Bytes of vertex data.
    pub fn byte_size(&self) -> usize {
        self.vertices.len() * std::mem::size_of::<TerrainVertex>()
    }
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
    use crate::grid::triangle_indices;

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

    fn mesh(key: TileKey) -> (TerrainTile, TileMesh) {
        let planet = ProceduralPlanet::new(1);
        let tile = planet.generate_tile(key);
        let m = TileMesh::build(&tile, &Ellipsoid::WGS84, &Ellipsoid::WGS84);
        (tile, m)
    }

    #[test]
    fn triangles_face_outwards() {
        for key in [
            TileKey::new(5, 33, 10),
            TileKey::new(2, 3, 0),
            TileKey::new(16, 70_000, 16_000),
        ] {
            let (_, m) = mesh(key);
            let p = |i: u32| {
                let v = m.vertices[i as usize].position;
                m.centre + DVec3::new(f64::from(v[0]), f64::from(v[1]), f64::from(v[2]))
            };
            let tile_up = m.centre.normalize();
            let mut grid_up = 0;
            let mut walls_out = 0;
            for tri in triangle_indices().chunks_exact(3) {
                let (a, b, c) = (p(tri[0]), p(tri[1]), p(tri[2]));
                let n = (b - a).cross(c - a);
                if n.length() < 1e-9 {
                    continue; // degenerate (pole)
                }
                let is_skirt = tri.iter().any(|&i| i >= crate::grid::GRID_VERTICES);
                if is_skirt {
                    // Walls face away from the tile centre.
                    let mid = (a + b + c) / 3.0;
                    let out = (mid - m.centre) - tile_up * (mid - m.centre).dot(tile_up);
                    assert!(n.dot(out) > 0.0, "{key:?}: skirt faces inwards");
                    walls_out += 1;
                } else {
                    assert!(
                        n.dot(a.normalize()) > 0.0,
                        "{key:?}: grid triangle faces down"
                    );
                    grid_up += 1;
                }
            }
            assert!(grid_up > 1900 && walls_out >= 192, "{grid_up} {walls_out}");
        }
    }

    #[test]
    fn bounds_contain_every_vertex_and_offsets_are_small() {
        let (tile, m) = mesh(TileKey::new(18, 140_000, 70_000));
        for v in &m.vertices {
            let p = m.centre
                + DVec3::new(
                    f64::from(v.position[0]),
                    f64::from(v.position[1]),
                    f64::from(v.position[2]),
                );
            assert!(m.bounds.obb.contains(p, 1e-3));
            assert!(DVec3::from_array(v.position.map(f64::from)).length() < 200.0);
        }
        assert!(m.skirt_depth_m > 6.0 * tile.geometric_error_m);
    }

    #[test]
    fn normals_are_continuous_across_tiles() {
        let (_, a) = mesh(TileKey::new(10, 1060, 250));
        let (_, b) = mesh(TileKey::new(10, 1061, 250));
        for k in 0..MESH_SIDE {
            let na =
                decode_oct_normal(a.vertices[(k * MESH_SIDE + MESH_SEGMENTS) as usize].normal_oct);
            let nb = decode_oct_normal(b.vertices[(k * MESH_SIDE) as usize].normal_oct);
            assert!(na.dot(nb) > 0.9999, "edge normal {k}: {na} vs {nb}");
        }
    }
}
