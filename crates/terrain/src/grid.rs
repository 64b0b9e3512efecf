//! The grid every terrain tile is sampled on, and how the full-resolution mesh cuts its cells.
//!
//! ```text
//!   i = 0 ............ 32      (west -> east)        sample (i, j), 33 x 33 per tile
//! j=0  +----+----+----+
//!      | \  |  / | \  |        cell (i, j) is cut along its north-west to south-east
//!      |  \ | /  |  \ |        diagonal when i + j is even and along the north-east to
//!      +----+----+----+        south-west one when odd: the finest level of the
//!  :                           right-triangle hierarchy (see [`crate::adaptive::Rtin`])
//! j=32 +----+----+----+        that tile meshes are cut from
//!  (north -> south)
//! ```
//!
//! Tile meshes keep a subset of these samples (an adaptive mesh with an error bound, see
//! [`crate::TileMesh`]); the full grid is the mesh with every sample kept.
//!
//! Height grids carry one extra sample on every side (35 x 35, see [`HEIGHT_GRID_SIDE`]) so
//! that normals at tile edges use the neighbour's heights and are continuous across tiles.
//! Colour images have [`COLOUR_SIZE`] texels per side over the same rectangle, texel centres
//! at `(k + 0.5) / COLOUR_SIZE` (cell registration); heights are on grid points (point
//! registration, `k / MESH_SEGMENTS`).

/// Cells per tile side.
pub const MESH_SEGMENTS: u32 = 32;
/// Samples per tile side.
pub const MESH_SIDE: u32 = MESH_SEGMENTS + 1;
/// Samples per side of a tile's height grid: the mesh samples plus one border sample each side.
pub const HEIGHT_GRID_SIDE: usize = MESH_SIDE as usize + 2;
/// Colour texels per tile side.
pub const COLOUR_SIZE: u32 = 128;
/// Vertices of the largest tile mesh: every sample and one skirt vertex per sample on an
/// edge or on one of the two midlines.
pub const MAX_MESH_VERTICES: u32 = MESH_SIDE * MESH_SIDE + 6 * MESH_SIDE;
/// Indices of the largest tile mesh: two triangles per cell and per skirt segment (one skirt
/// under each edge, two under each midline: one facing either way).
pub const MAX_MESH_INDICES: u32 =
    (2 * MESH_SEGMENTS * MESH_SEGMENTS + 4 * 2 * MESH_SEGMENTS + 2 * 2 * 2 * MESH_SEGMENTS) * 3;

/// Whether the full-resolution mesh cuts cell (`i`, `j`) from its north-west to its
/// south-east corner (else from north-east to south-west).
pub const fn cell_diagonal_is_nw_se(i: i32, j: i32) -> bool {
    (i + j).rem_euclid(2) == 0
}

/// Height of the full-resolution mesh inside cell (`i`, `j`) at fractions (`s` east, `t`
/// south) of the cell, given its corner heights. This is what the GPU draws where every
/// sample is kept, so geometric error is measured against it.
#[allow(clippy::too_many_arguments)]
pub fn interpolate_in_cell(
    i: i32,
    j: i32,
    nw: f64,
    ne: f64,
    sw: f64,
    se: f64,
    s: f64,
    t: f64,
) -> f64 {
    if cell_diagonal_is_nw_se(i, j) {
        if t >= s {
            nw + t * (sw - nw) + s * (se - sw)
        } else {
            nw + s * (ne - nw) + t * (se - ne)
        }
    } else if s + t <= 1.0 {
        nw + s * (ne - nw) + t * (sw - nw)
    } else {
        se + (1.0 - s) * (sw - se) + (1.0 - t) * (ne - se)
    }
}

/// How far the flat triangles between full-grid mesh vertices of a tile over `rect` sag below
/// the curved body: `d^2 / (8 r)` for the cell diagonal `d` and the largest radius of
/// curvature `r`. Part of every tile's geometric error.
pub fn mesh_bulge_m(ellipsoid: &globus_geo::Ellipsoid, rect: &globus_tiling::GeoRect) -> f64 {
    let r_max =
        ellipsoid.maximum_radius() * ellipsoid.maximum_radius() / ellipsoid.minimum_radius();
    let cos_lat = rect.north.abs().min(rect.south.abs()).cos();
    let ns = rect.height() / f64::from(MESH_SEGMENTS) * r_max;
    let ew = rect.width() / f64::from(MESH_SEGMENTS) * r_max * cos_lat;
    (ns * ns + ew * ew) / (8.0 * r_max)
}

/// Height of the full-resolution mesh through a tile's height grid (see
/// [`crate::TerrainTile::heights_m`]) at fractional vertex coordinates `x` (east) and `y`
/// (south), both in `0..=MESH_SEGMENTS`.
pub fn mesh_height_at(heights_m: &[f32], x: f64, y: f64) -> f64 {
    let n = MESH_SEGMENTS as i32;
    let i = (x.floor() as i32).clamp(0, n - 1);
    let j = (y.floor() as i32).clamp(0, n - 1);
    let h = |a: i32, b: i32| {
        f64::from(heights_m[((b + 1) as usize) * HEIGHT_GRID_SIDE + (a + 1) as usize])
    };
    interpolate_in_cell(
        i,
        j,
        h(i, j),
        h(i + 1, j),
        h(i, j + 1),
        h(i + 1, j + 1),
        x - f64::from(i),
        y - f64::from(j),
    )
}

#[cfg(test)]
mod tests {
    use super::*;
    use crate::adaptive::{HeightGrid, Rtin};

    #[test]
    fn interpolation_matches_corners_and_diagonals() {
        for (i, j) in [(0, 0), (1, 0), (3, 5), (4, 4)] {
            let h = |s, t| interpolate_in_cell(i, j, 1.0, 2.0, 3.0, 4.0, s, t);
            assert_eq!(h(0.0, 0.0), 1.0);
            assert_eq!(h(1.0, 0.0), 2.0);
            assert_eq!(h(0.0, 1.0), 3.0);
            assert_eq!(h(1.0, 1.0), 4.0);
        }
        // On the cut diagonal the two triangles agree; across it the surface kinks.
        let h = |i, s, t| interpolate_in_cell(i, 0, 0.0, 0.0, 0.0, 1.0, s, t);
        assert!((h(0, 0.5, 0.5) - 0.5).abs() < 1e-12, "NW-SE cut");
        assert!(h(1, 0.5, 0.5).abs() < 1e-12, "NE-SW cut: SE raised alone");
    }

    /// The diagonals here are the ones the right-triangle hierarchy produces: a mesh that keeps
    /// every sample interpolates exactly as [`interpolate_in_cell`] says.
    #[test]
    fn diagonals_match_the_full_rtin_mesh() {
        let side = MESH_SIDE as usize;
        let grid = HeightGrid::new(side, vec![0.0; side * side]).expect("grid");
        let mesh = Rtin::new(&grid).mesh_with(-1.0, 1);
        assert_eq!(mesh.triangles.len(), 2 * 32 * 32);
        for t in &mesh.triangles {
            let p = t.map(|k| mesh.vertices[k as usize]);
            // The hypotenuse of a unit right triangle is the cell's cut diagonal.
            let (a, b) = (0..3)
                .map(|k| (p[k], p[(k + 1) % 3]))
                .find(|(a, b)| a[0] != b[0] && a[1] != b[1])
                .expect("a diagonal edge");
            let (i, j) = (a[0].min(b[0]), a[1].min(b[1]));
            let nw_se = (a[0] < b[0]) == (a[1] < b[1]);
            assert_eq!(nw_se, cell_diagonal_is_nw_se(i32::from(i), i32::from(j)));
        }
    }
}
