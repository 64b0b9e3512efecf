//! The regular grid every terrain tile uses: vertex order, skirts and triangulation.
//!
//! ```text
//!   i = 0 ............ 32      (west -> east)        vertex index = j * 33 + i
//! j=0  +----+----+----+                              (1089 grid vertices)
//!      | \  | \  |    |        each cell is split along its north-east to
//!      |  \ |  \ |    |        south-west diagonal: (a, c, b) and (b, c, d)
//!      +----+----+----+        with a = NW, b = NE, c = SW, d = SE
//!  :
//! j=32 +----+----+----+        then 4 x 33 skirt vertices, one below each edge vertex:
//!  (north -> south)            north edge (i = 0..32), south edge, west edge (j = 0..32), east edge
//! ```
//!
//! Height grids carry one extra sample on every side (35 x 35, see [`HEIGHT_GRID_SIDE`]) so
//! that normals at tile edges use the neighbour's heights and are continuous across tiles.
//! Colour images have [`COLOUR_SIZE`] texels per side over the same rectangle, texel centres
//! at `(k + 0.5) / COLOUR_SIZE` (cell registration); heights are on grid points (point
//! registration, `k / MESH_SEGMENTS`).

/// Cells per tile side.
pub const MESH_SEGMENTS: u32 = 32;
/// Vertices per tile side.
pub const MESH_SIDE: u32 = MESH_SEGMENTS + 1;
/// Grid vertices (without skirts).
pub const GRID_VERTICES: u32 = MESH_SIDE * MESH_SIDE;
/// Skirt vertices, one per edge vertex on each of the four edges.
pub const SKIRT_VERTICES: u32 = 4 * MESH_SIDE;
/// All vertices of a tile.
pub const VERTICES_PER_TILE: u32 = GRID_VERTICES + SKIRT_VERTICES;
/// Samples per side of a tile's height grid: the vertices plus one border sample each side.
pub const HEIGHT_GRID_SIDE: usize = MESH_SIDE as usize + 2;
/// Colour texels per tile side.
pub const COLOUR_SIZE: u32 = 128;

/// Which edge a skirt vertex hangs from.
#[derive(Clone, Copy, Debug, PartialEq, Eq)]
pub enum Edge {
    /// j = 0.
    North,
    /// j = 32.
    South,
    /// i = 0.
    West,
    /// i = 32.
    East,
}

/// Where a vertex of the tile layout sits: its grid column and row, and whether it is the
/// skirt vertex below that grid vertex.
pub fn vertex_grid_position(index: u32) -> (u32, u32, bool) {
    if index < GRID_VERTICES {
        return (index % MESH_SIDE, index / MESH_SIDE, false);
    }
    let s = index - GRID_VERTICES;
    let (edge, k) = (s / MESH_SIDE, s % MESH_SIDE);
    let (i, j) = match edge {
        0 => (k, 0),
        1 => (k, MESH_SEGMENTS),
        2 => (0, k),
        _ => (MESH_SEGMENTS, k),
    };
    (i, j, true)
}

/// The index of the skirt vertex at position `k` along `edge`.
pub fn skirt_index(edge: Edge, k: u32) -> u32 {
    let e = match edge {
        Edge::North => 0,
        Edge::South => 1,
        Edge::West => 2,
        Edge::East => 3,
    };
    GRID_VERTICES + e * MESH_SIDE + k
}

/// Triangle list indices of the grid and skirts, counter-clockwise seen from outside.
pub fn triangle_indices() -> Vec<u32> {
    let g = |i: u32, j: u32| j * MESH_SIDE + i;
    let mut idx = Vec::with_capacity(index_count() as usize);
    for j in 0..MESH_SEGMENTS {
        for i in 0..MESH_SEGMENTS {
            let (a, b, c, d) = (g(i, j), g(i + 1, j), g(i, j + 1), g(i + 1, j + 1));
            idx.extend_from_slice(&[a, c, b, b, c, d]);
        }
    }
    for k in 0..MESH_SEGMENTS {
        // Walls facing north and east: (g0, g1, s0), (g1, s1, s0).
        for (edge, g0, g1) in [
            (Edge::North, g(k, 0), g(k + 1, 0)),
            (Edge::East, g(MESH_SEGMENTS, k), g(MESH_SEGMENTS, k + 1)),
        ] {
            let (s0, s1) = (skirt_index(edge, k), skirt_index(edge, k + 1));
            idx.extend_from_slice(&[g0, g1, s0, g1, s1, s0]);
        }
        // Walls facing south and west: (g0, s0, g1), (g1, s0, s1).
        for (edge, g0, g1) in [
            (Edge::South, g(k, MESH_SEGMENTS), g(k + 1, MESH_SEGMENTS)),
            (Edge::West, g(0, k), g(0, k + 1)),
        ] {
            let (s0, s1) = (skirt_index(edge, k), skirt_index(edge, k + 1));
            idx.extend_from_slice(&[g0, s0, g1, g1, s0, s1]);
        }
    }
    idx
}

/// Number of indices [`triangle_indices`] returns.
pub const fn index_count() -> u32 {
    MESH_SEGMENTS * MESH_SEGMENTS * 6 + 4 * MESH_SEGMENTS * 6
}

/// Height of the mesh surface inside cell (`i`, `j`) at fractions (`s` east, `t` south) of the
/// cell, given its corner heights, following the triangulation above. This is what the GPU
/// draws, so geometric error is measured against it.
pub fn interpolate_in_cell(nw: f64, ne: f64, sw: f64, se: f64, s: f64, t: f64) -> f64 {
    if s + t <= 1.0 {
        nw + s * (ne - nw) + t * (sw - nw)
    } else {
        se + (1.0 - s) * (sw - se) + (1.0 - t) * (ne - se)
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn every_vertex_is_used_and_indices_are_in_range() {
        let idx = triangle_indices();
        assert_eq!(idx.len() as u32, index_count());
        let mut used = vec![false; VERTICES_PER_TILE as usize];
        for i in idx {
            used[i as usize] = true;
        }
        assert!(used.iter().all(|u| *u));
    }

    #[test]
    fn skirt_positions_round_trip() {
        for (edge, k) in [
            (Edge::North, 3),
            (Edge::South, 32),
            (Edge::West, 0),
            (Edge::East, 17),
        ] {
            let (i, j, skirt) = vertex_grid_position(skirt_index(edge, k));
            assert!(skirt);
            let expected = match edge {
                Edge::North => (k, 0),
                Edge::South => (k, 32),
                Edge::West => (0, k),
                Edge::East => (32, k),
            };
            assert_eq!((i, j), expected);
        }
    }

    #[test]
    fn interpolation_matches_corners_and_diagonal() {
        let h = |s, t| interpolate_in_cell(1.0, 2.0, 3.0, 4.0, s, t);
        assert_eq!(h(0.0, 0.0), 1.0);
        assert_eq!(h(1.0, 0.0), 2.0);
        assert_eq!(h(0.0, 1.0), 3.0);
        assert_eq!(h(1.0, 1.0), 4.0);
        // On the NE-SW diagonal both triangles agree.
        assert!((h(0.5, 0.5) - 2.5).abs() < 1e-12);
    }
}
