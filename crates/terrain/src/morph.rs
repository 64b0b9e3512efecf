//! [`MorphVertex`]: where each vertex of a tile's mesh lies on its parent's surface, so the
//! renderer can draw the tile growing out of its parent over the last part of its
//! level-of-detail range (geomorphing; Strugar's CDLOD, 2010) instead of replacing it in one
//! frame. How far it has grown is selection's ([`globus_tiling::morph_fraction`]).
//!
//! The parent's surface is the one it draws: its own mesh's triangles (an adaptive cut of
//! its grid), with heights and normals interpolated across them as the GPU interpolates them.
//! Each triangle is rasterised over the lattice of the tile's grid samples (in the parent's
//! grid coordinates a lattice of half cells, or whole cells across a reduced polar row), so
//! finding every vertex's place costs one pass over the parent's triangles. At a fresh split
//! a tile then shows exactly its parent's surface at its vertices; between them its own
//! triangles may cut a parent's crease (a blend of surfaces where CDLOD's regular grids
//! morph exactly).

use bytemuck::{Pod, Zeroable};
use globus_geo::{DVec3, Ellipsoid};

use crate::grid::{MESH_SEGMENTS, MESH_SIDE};
use crate::{TerrainTile, TileMesh, decode_oct_normal, encode_oct_normal};

/// A vertex's morph target, as the GPU reads it (8 bytes, one per mesh vertex).
#[repr(C)]
#[derive(Clone, Copy, Debug, Default, PartialEq, Pod, Zeroable)]
pub struct MorphVertex {
    /// Drawn metres from the vertex to its parent's surface along the ellipsoid's normal
    /// (skirt vertices move with their edge vertex).
    pub dh_m: f32,
    /// The parent surface's unit normal there, oct-encoded as
    /// [`crate::TerrainVertex::normal_oct`].
    pub normal_oct: u32,
}

impl MorphVertex {
    /// No morph: every vertex is its own target (for roots, or a tile whose parent's data
    /// is gone).
    pub fn none(mesh: &TileMesh) -> Vec<Self> {
        mesh.vertices
            .iter()
            .map(|v| Self {
                dh_m: 0.0,
                normal_oct: v.normal_oct,
            })
            .collect()
    }

    /// The morph targets of `mesh` (built from `tile`) on the surface `parent_mesh` draws,
    /// one per vertex in the mesh's order; both meshes stand on `ellipsoid`. A vertex's
    /// target is where the ellipsoid's normal through it meets the parent's triangle over it
    /// (so the GPU, moving it along that normal, lands exactly on the parent's surface); skirt
    /// vertices move as their edge vertex. A vertex no parent triangle covers (not with
    /// meshes of this crate) keeps its own place.
    pub fn towards_parent(
        tile: &TerrainTile,
        mesh: &TileMesh,
        parent: &TerrainTile,
        parent_mesh: &TileMesh,
        ellipsoid: &Ellipsoid,
    ) -> Vec<Self> {
        let n = f64::from(MESH_SEGMENTS);
        let side = MESH_SIDE as usize;
        let rect = tile.rect;
        // Where the tile's grid columns and rows fall in the parent's grid (ascending).
        let columns: Vec<f64> = (0..MESH_SIDE)
            .map(|i| {
                let lon = rect.west + rect.width() * f64::from(i) / n;
                parent.rect.uv(lon, parent.rect.north).0 * n
            })
            .collect();
        let rows: Vec<f64> = (0..MESH_SIDE)
            .map(|j| {
                let lat = rect.north - rect.height() * f64::from(j) / n;
                parent.rect.uv(parent.rect.west, lat).1 * n
            })
            .collect();
        // Per grid sample of the tile: the parent triangle over it and the sample's
        // barycentric weights in it (in grid coordinates).
        let mut over: Vec<Option<([u32; 3], [f64; 3])>> = vec![None; side * side];
        let surface = (parent_mesh.surface_triangles as usize * 3).min(parent_mesh.indices.len());
        for tri in parent_mesh.indices[..surface].chunks_exact(3) {
            let corner = |k: usize| {
                let [i, j] = grid_index(parent_mesh.vertices[tri[k] as usize].uv);
                (f64::from(i), f64::from(j))
            };
            let (a, b, c) = (corner(0), corner(1), corner(2));
            let det = (b.0 - a.0) * (c.1 - a.1) - (c.0 - a.0) * (b.1 - a.1);
            if det.abs() < 1e-12 {
                continue;
            }
            let within = |lattice: &[f64], lo: f64, hi: f64| {
                lattice.partition_point(|&x| x < lo - 1e-9)
                    ..lattice.partition_point(|&x| x <= hi + 1e-9)
            };
            let xs = within(&columns, a.0.min(b.0).min(c.0), a.0.max(b.0).max(c.0));
            let ys = within(&rows, a.1.min(b.1).min(c.1), a.1.max(b.1).max(c.1));
            for j in ys {
                for i in xs.clone() {
                    let cell = &mut over[j * side + i];
                    if cell.is_some() {
                        continue;
                    }
                    let (x, y) = (columns[i], rows[j]);
                    let wb = ((x - a.0) * (c.1 - a.1) - (c.0 - a.0) * (y - a.1)) / det;
                    let wc = ((b.0 - a.0) * (y - a.1) - (x - a.0) * (b.1 - a.1)) / det;
                    let wa = 1.0 - wb - wc;
                    if wa >= -1e-9 && wb >= -1e-9 && wc >= -1e-9 {
                        *cell = Some(([tri[0], tri[1], tri[2]], [wa, wb, wc]));
                    }
                }
            }
        }
        let position = |m: &TileMesh, k: u32| {
            let p = m.vertices[k as usize].position;
            m.centre + DVec3::new(f64::from(p[0]), f64::from(p[1]), f64::from(p[2]))
        };
        // Surface vertices come first and hold each grid sample once: the first vertex of a
        // sample sets its height change, its skirt vertex reuses it.
        let mut dh_of: Vec<Option<f32>> = vec![None; side * side];
        mesh.vertices
            .iter()
            .enumerate()
            .map(|(k, v)| {
                let [i, j] = grid_index(v.uv);
                let at = j as usize * side + i as usize;
                let Some((tri, w)) = over[at] else {
                    return Self {
                        dh_m: 0.0,
                        normal_oct: v.normal_oct,
                    };
                };
                let dh_m = *dh_of[at].get_or_insert_with(|| {
                    let [a, b, c] = tri.map(|t| position(parent_mesh, t));
                    let p = position(mesh, k as u32);
                    let Some(up) = ellipsoid.geodetic_normal(p) else {
                        return 0.0;
                    };
                    let plane = (b - a).cross(c - a);
                    let along = up.dot(plane);
                    // A triangle with two corners on a pole has no plane (nor a lattice
                    // point off the pole, where the vertex stays).
                    if along.is_nan() || along.abs() <= 1e-12 * plane.length() {
                        0.0
                    } else {
                        ((a - p).dot(plane) / along) as f32
                    }
                });
                let normal = tri
                    .iter()
                    .zip(w)
                    .map(|(&t, w)| {
                        decode_oct_normal(parent_mesh.vertices[t as usize].normal_oct) * w
                    })
                    .sum::<DVec3>();
                Self {
                    dh_m,
                    normal_oct: encode_oct_normal(
                        normal.normalize_or(decode_oct_normal(v.normal_oct)),
                    ),
                }
            })
            .collect()
    }
}

/// The grid sample a vertex stands on, from its unorm16 texture coordinates.
fn grid_index(uv: u32) -> [u32; 2] {
    let k = |q: u32| {
        ((f64::from(q) / 65535.0 * f64::from(MESH_SEGMENTS)).round() as u32).min(MESH_SEGMENTS)
    };
    [k(uv & 0xffff), k(uv >> 16)]
}

#[cfg(test)]
mod tests {
    use globus_tiling::{GLOBE_SCHEME, TileKey};

    use super::*;
    use crate::grid::HEIGHT_GRID_SIDE;
    use crate::{MeshOptions, ProceduralPlanet};

    /// `key`'s procedural tile with its heights replaced by `f(lon, lat)` (radians), border
    /// ring included.
    fn tile_of(key: TileKey, f: &dyn Fn(f64, f64) -> f64) -> TerrainTile {
        let mut tile = ProceduralPlanet::new(3).generate_tile(key);
        let n = f64::from(MESH_SEGMENTS);
        let side = HEIGHT_GRID_SIDE as i32;
        for j in -1..side - 1 {
            for i in -1..side - 1 {
                let lon = tile.rect.west + tile.rect.width() * f64::from(i) / n;
                let lat = tile.rect.north - tile.rect.height() * f64::from(j) / n;
                tile.heights_m[((j + 1) * side + i + 1) as usize] = f(lon, lat) as f32;
            }
        }
        tile
    }

    fn mesh_of(tile: &TerrainTile, options: &MeshOptions) -> TileMesh {
        TileMesh::build(tile, &Ellipsoid::WGS84, &Ellipsoid::WGS84, options)
    }

    #[test]
    fn a_child_on_its_parents_samples_has_nothing_to_grow_there_and_the_detail_between() {
        let parent_key = TileKey::new(9, 530, 150);
        let child = GLOBE_SCHEME.children(parent_key)[3];
        // Smooth relief both sample, plus detail only the child has: zero on the parent's
        // samples (every other child sample), 40 m between.
        let relief = |lon: f64, lat: f64| 800.0 + 300.0 * (lon * 900.0).sin() * (lat * 700.0).cos();
        let parent = tile_of(parent_key, &relief);
        let half_cell = GLOBE_SCHEME.rect(child).width() / f64::from(MESH_SEGMENTS);
        let rect = GLOBE_SCHEME.rect(child);
        let detail = move |lon: f64, lat: f64| {
            let i = ((lon - rect.west) / half_cell).round() as i64;
            let j = ((rect.north - lat) / half_cell * rect.width() / rect.height()).round() as i64;
            if i % 2 != 0 || j % 2 != 0 { 40.0 } else { 0.0 }
        };
        let tile = tile_of(child, &|lon, lat| relief(lon, lat) + detail(lon, lat));
        let mesh = mesh_of(&tile, &MeshOptions::FULL_GRID);
        let parent_mesh = mesh_of(&parent, &MeshOptions::FULL_GRID);
        let morph =
            MorphVertex::towards_parent(&tile, &mesh, &parent, &parent_mesh, &Ellipsoid::WGS84);
        assert_eq!(morph.len(), mesh.vertices.len());
        let (mut on, mut between) = (0, 0);
        for (v, m) in mesh.vertices.iter().zip(&morph) {
            let [i, j] = grid_index(v.uv);
            let rect = tile.rect;
            let (u, w) = parent.rect.uv(
                rect.west + rect.width() * f64::from(i) / 32.0,
                rect.north - rect.height() * f64::from(j) / 32.0,
            );
            let (pi, pj) = ((u * 32.0).round(), (w * 32.0).round());
            if i % 2 == 0 && j % 2 == 0 {
                // The parent's own sample: the same height (to centimetres: f32 positions,
                // and a reduced tile's equatorward row pushed out by its own chords).
                let want = f64::from(parent.height_at(pi as i32, pj as i32))
                    - f64::from(tile.height_at(i as i32, j as i32));
                assert!(
                    (f64::from(m.dh_m) - want).abs() < 0.1,
                    "({i}, {j}): {} vs {want}",
                    m.dh_m
                );
                assert!(want.abs() < 1e-3);
                on += 1;
            } else {
                // Between: the parent's flat triangle, so the detail goes, and the smooth
                // relief's curvature over a parent cell stays (a few metres at most).
                assert!(
                    (f64::from(m.dh_m) + 40.0).abs() < 6.0,
                    "({i}, {j}): dh {}",
                    m.dh_m
                );
                between += 1;
            }
        }
        assert!(
            on >= 17 * 17 && between >= 33 * 33 - 17 * 17,
            "{on} {between}"
        );
    }

    #[test]
    fn on_a_plane_parent_and_child_agree_and_the_normals_tilt_with_the_slope() {
        let parent_key = TileKey::new(11, 2100, 600);
        let child = GLOBE_SCHEME.children(parent_key)[0];
        // A plane rising 0.3 m per metre east (in degrees of longitude at this latitude).
        let rect = GLOBE_SCHEME.rect(parent_key);
        let metres_per_rad = Ellipsoid::WGS84.mean_radius() * rect.north.cos();
        let plane = move |lon: f64, _lat: f64| 0.3 * (lon - rect.west) * metres_per_rad;
        let parent = tile_of(parent_key, &plane);
        let tile = tile_of(child, &plane);
        for options in [MeshOptions::FULL_GRID, MeshOptions::default()] {
            let mesh = mesh_of(&tile, &options);
            let parent_mesh = mesh_of(&parent, &options);
            let morph =
                MorphVertex::towards_parent(&tile, &mesh, &parent, &parent_mesh, &Ellipsoid::WGS84);
            // The parent's flat triangles sag below the curved plane by about its cut error
            // (the cut's estimate of the sag is for level ground; this plane climbs 4 km
            // across the parent).
            let sag = 1.5 * parent_mesh.cut_error_m + 0.05;
            for (v, m) in mesh.vertices.iter().zip(&morph) {
                assert!(f64::from(m.dh_m).abs() < sag, "dh {} against {sag}", m.dh_m);
                let (own, theirs) = (
                    decode_oct_normal(v.normal_oct),
                    decode_oct_normal(m.normal_oct),
                );
                // Within 0.2 degrees (both from ECEF chords, the parent's twice as long, and
                // interpolated; oct encoding adds 0.003 degrees).
                assert!(
                    own.dot(theirs) > 0.2f64.to_radians().cos(),
                    "{own} vs {theirs}"
                );
                // And tilted 16.7 degrees (atan 0.3) off the vertical, westwards.
                let [i, j] = grid_index(v.uv);
                let rect = tile.rect;
                let lon = rect.west + rect.width() * f64::from(i) / 32.0;
                let lat = rect.north - rect.height() * f64::from(j) / 32.0;
                let up = Ellipsoid::WGS84.geodetic_normal_from_lon_lat(lon, lat);
                let tilt = theirs.dot(up).acos().to_degrees();
                assert!(
                    (tilt - 0.3f64.atan().to_degrees()).abs() < 0.2,
                    "tilt {tilt}"
                );
            }
        }
        // No morph keeps the vertices' own normals.
        let mesh = mesh_of(&tile, &MeshOptions::default());
        let none = MorphVertex::none(&mesh);
        assert!(
            none.iter()
                .zip(&mesh.vertices)
                .all(|(m, v)| m.dh_m == 0.0 && m.normal_oct == v.normal_oct)
        );
    }

    #[test]
    fn exaggerated_meshes_morph_by_exaggerated_heights() {
        let parent_key = TileKey::new(8, 270, 70);
        let child = GLOBE_SCHEME.children(parent_key)[1];
        let parent = tile_of(parent_key, &|_, _| 100.0);
        let tile = tile_of(child, &|_, _| 130.0);
        let options = MeshOptions {
            exaggeration: 3.0,
            ..MeshOptions::FULL_GRID
        };
        let mesh = mesh_of(&tile, &options);
        let parent_mesh = mesh_of(&parent, &options);
        let morph =
            MorphVertex::towards_parent(&tile, &mesh, &parent, &parent_mesh, &Ellipsoid::WGS84);
        // 30 m times 3, less the sag of the parent's cells (4 km across: under a metre).
        assert!(
            morph.iter().all(|m| (m.dh_m + 90.0).abs() < 1.0),
            "{:?}",
            morph[0]
        );
    }

    /// The first point along `origin + s * dir` (s >= 0) on a triangle of `mesh`'s surface.
    fn hit(mesh: &TileMesh, origin: DVec3, dir: DVec3) -> Option<f64> {
        let p = |k: u32| {
            let v = mesh.vertices[k as usize].position;
            mesh.centre + DVec3::new(f64::from(v[0]), f64::from(v[1]), f64::from(v[2]))
        };
        let surface = mesh.surface_triangles as usize * 3;
        mesh.indices[..surface]
            .chunks_exact(3)
            .filter_map(|t| {
                // Moller-Trumbore.
                let (a, b, c) = (p(t[0]), p(t[1]), p(t[2]));
                let (e1, e2) = (b - a, c - a);
                let q = dir.cross(e2);
                let det = e1.dot(q);
                if det.abs() < 1e-12 {
                    return None;
                }
                let s = origin - a;
                let u = s.dot(q) / det;
                let r = s.cross(e1);
                let v = dir.dot(r) / det;
                let eps = 1e-6;
                (u >= -eps && v >= -eps && u + v <= 1.0 + eps).then(|| e2.dot(r) / det)
            })
            .filter(|&d| d >= 0.0)
            .min_by(f64::total_cmp)
    }

    #[test]
    fn the_targets_lie_on_the_triangles_the_parent_draws() {
        // Rough procedural mountains, the parent cut adaptively (big triangles where the
        // ground allows), the child on its full grid or cut too.
        let planet = ProceduralPlanet::new(7);
        let parent_key = TileKey::new(10, 1066, 301);
        let parent = planet.generate_tile(parent_key);
        let coarse = MeshOptions {
            error_fraction: 1.0,
            ..MeshOptions::default()
        };
        let parent_mesh = mesh_of(&parent, &coarse);
        assert!(
            parent_mesh.surface_triangles < 32 * 32,
            "a cut mesh: {}",
            parent_mesh.surface_triangles
        );
        for (c, options) in [MeshOptions::FULL_GRID, MeshOptions::default()]
            .into_iter()
            .enumerate()
        {
            let child = GLOBE_SCHEME.children(parent_key)[c + 1];
            let tile = planet.generate_tile(child);
            let mesh = mesh_of(&tile, &options);
            let morph =
                MorphVertex::towards_parent(&tile, &mesh, &parent, &parent_mesh, &Ellipsoid::WGS84);
            let (mut worst, mut moved) = (0.0f64, 0.0f64);
            let surface = &mesh.indices[..mesh.surface_triangles as usize * 3];
            for (k, (v, m)) in mesh.vertices.iter().zip(&morph).enumerate() {
                if !surface.contains(&(k as u32)) {
                    continue; // a skirt
                }
                let p = v.position;
                let p = mesh.centre + DVec3::new(f64::from(p[0]), f64::from(p[1]), f64::from(p[2]));
                let up = Ellipsoid::WGS84.geodetic_normal(p).expect("off the centre");
                let target = p + up * f64::from(m.dh_m);
                let Some(d) = hit(&parent_mesh, target + up * 500.0, -up) else {
                    // Only where it grazes the parent's outer edge.
                    let [i, j] = grid_index(v.uv);
                    let rect = tile.rect;
                    let (u, w) = parent.rect.uv(
                        rect.west + rect.width() * f64::from(i) / 32.0,
                        rect.north - rect.height() * f64::from(j) / 32.0,
                    );
                    let edge = |f: f64| f.abs() < 1e-9 || (f - 1.0).abs() < 1e-9;
                    assert!(edge(u) || edge(w), "({i}, {j}) not over the parent");
                    continue;
                };
                worst = worst.max((d - 500.0).abs());
                moved = moved.max(f64::from(m.dh_m).abs());
            }
            // On the parent's triangles: to f32 vertex positions, and to a centimetre or two
            // where a vertex sits on a parent's crease and the normal's line crosses it.
            assert!(
                worst < 0.05,
                "{child:?}: {worst} m off the parent's surface"
            );
            assert!(moved > 5.0, "{child:?}: the detail moved at most {moved} m");
        }
    }

    #[test]
    fn polar_tiles_morph_by_finite_small_amounts() {
        // Their rows on the pole are one point: triangles there have no plane.
        let planet = ProceduralPlanet::new(1);
        for level in [6u8, 9, 12] {
            for parent_key in [
                TileKey::new(level, 0, 0),
                TileKey::new(level, 0, (1 << level) - 1),
            ] {
                let parent = planet.generate_tile(parent_key);
                let parent_mesh = mesh_of(&parent, &MeshOptions::default());
                for &child in GLOBE_SCHEME.children(parent_key).iter() {
                    let tile = planet.generate_tile(child);
                    let mesh = mesh_of(&tile, &MeshOptions::default());
                    let morph = MorphVertex::towards_parent(
                        &tile,
                        &mesh,
                        &parent,
                        &parent_mesh,
                        &Ellipsoid::WGS84,
                    );
                    let bound = 4.0 * parent_mesh.geometric_error_m;
                    for m in &morph {
                        assert!(
                            m.dh_m.is_finite() && f64::from(m.dh_m).abs() <= bound,
                            "{child:?}: dh {} against {bound}",
                            m.dh_m
                        );
                    }
                }
            }
        }
    }
}
