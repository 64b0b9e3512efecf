//! Decimated meshes: fewer triangles than [`super::Rtin`] for the same error, at a higher
//! build cost.
//!
//! Two passes, both with the exact error bound (every grid sample checked against the
//! triangle over it):
//!
//! 1. **Greedy Delaunay refinement** (Garland and Heckbert 1995, the algorithm of
//!    `mapbox/delatin`): start from the two corner triangles and keep inserting the sample
//!    of largest error, restoring the Delaunay property by edge flips, until no sample is
//!    further than `max_error` from the mesh.
//! 2. **Plane-deviance vertex removal** (Kaiser 2018, Algorithm 1): the interior vertices go
//!    into a queue ordered by their distance from the area-weighted average plane of their
//!    triangle fan; each in turn is removed and its hole re-triangulated by ear clipping
//!    (cheapest ear first), and the removal is kept only if the new triangles still hold the
//!    bound. Neighbours of a removed vertex are re-queued with their new deviance. Tile
//!    border vertices are never removed, and like the thesis a vertex whose fan holds a
//!    triangle larger than `max_triangle_area` is kept, so large flat triangles (sea) do not
//!    grow into land.
//!
//! Insertion overshoots: samples inserted early to fix a large error often become redundant
//! once their neighbours are in; the removal pass takes those out again.

mod insert;
mod remove;

use super::{AdaptiveMesh, HeightGrid};

/// Knobs of [`decimate_with`].
#[derive(Clone, Copy, Debug, PartialEq)]
pub struct DecimateOptions {
    /// Largest vertical error, metres.
    pub max_error: f64,
    /// Run the plane-deviance removal pass (on by default).
    pub remove_pass: bool,
    /// Keep vertices whose fan holds a triangle larger than this (grid cells squared).
    pub max_triangle_area: Option<f64>,
    /// Keep vertices with more neighbours than this (bounds the cost of one removal).
    pub max_neighbours: usize,
}

impl DecimateOptions {
    /// Defaults for `max_error`.
    pub fn new(max_error: f64) -> Self {
        Self {
            max_error,
            remove_pass: true,
            max_triangle_area: None,
            max_neighbours: 16,
        }
    }
}

/// The decimated mesh of `grid` with vertical error at most `max_error` metres.
pub fn decimate(grid: &HeightGrid, max_error: f64) -> AdaptiveMesh {
    decimate_with(grid, &DecimateOptions::new(max_error))
}

/// [`decimate`] with all options.
pub fn decimate_with(grid: &HeightGrid, options: &DecimateOptions) -> AdaptiveMesh {
    let (vertices, triangles) = insert::refine(grid, options.max_error);
    let triangles = if options.remove_pass {
        remove::remove_vertices(grid, &vertices, triangles, options)
    } else {
        triangles
    };
    compact(grid.side(), &vertices, &triangles)
}

/// Keeps only used vertices, numbered in order of first use (what quantized-mesh's
/// high-water-mark index coding wants).
fn compact(side: usize, vertices: &[[u16; 2]], triangles: &[[u32; 3]]) -> AdaptiveMesh {
    let mut index_of = vec![u32::MAX; vertices.len()];
    let mut mesh = AdaptiveMesh {
        side,
        ..AdaptiveMesh::default()
    };
    for t in triangles {
        let t = t.map(|v| {
            let slot = &mut index_of[v as usize];
            if *slot == u32::MAX {
                *slot = mesh.vertices.len() as u32;
                mesh.vertices.push(vertices[v as usize]);
            }
            *slot
        });
        mesh.triangles.push(t);
    }
    mesh
}

/// Twice the signed area of (a, b, c) in grid coordinates; negative for the mesh's
/// counter-clockwise-from-above triangles (rows run south).
pub(super) fn orient(a: [u16; 2], b: [u16; 2], c: [u16; 2]) -> i64 {
    let [ax, ay] = a.map(i64::from);
    let [bx, by] = b.map(i64::from);
    let [cx, cy] = c.map(i64::from);
    (bx - ax) * (cy - ay) - (by - ay) * (cx - ax)
}

/// The largest |height - plane| over the samples in triangle `p` other than its corners, and
/// where it is. Each row's extent comes from the three edge functions exactly (integers), so
/// only samples inside are visited.
pub(super) fn scan_triangle(grid: &HeightGrid, p: [[u16; 2]; 3]) -> (f32, [u16; 2]) {
    let side = grid.side();
    let h = grid.heights();
    let q = p.map(|[x, y]| [i64::from(x), i64::from(y)]);
    let z = p.map(|[x, y]| f64::from(grid.at(usize::from(x), usize::from(y))));
    let area = orient(p[0], p[1], p[2]);
    if area == 0 {
        return (0.0, p[0]);
    }
    let s = area.signum();
    // w_k(x, y) = a_k x + b_k y + c_k >= 0 inside, for the edge opposite vertex k.
    let coeff = |i: usize, j: usize| {
        let (a, b) = (q[i], q[j]);
        let (ca, cb) = (-s * (b[1] - a[1]), s * (b[0] - a[0]));
        (ca, cb, -(ca * a[0] + cb * a[1]))
    };
    let w = [coeff(1, 2), coeff(2, 0), coeff(0, 1)];
    let inv = 1.0 / (area * s) as f64;
    let dz_dx = (w[0].0 as f64 * z[0] + w[1].0 as f64 * z[1] + w[2].0 as f64 * z[2]) * inv;
    let y0 = q[0][1].min(q[1][1]).min(q[2][1]);
    let y1 = q[0][1].max(q[1][1]).max(q[2][1]);
    let x_min = q[0][0].min(q[1][0]).min(q[2][0]);
    let x_max = q[0][0].max(q[1][0]).max(q[2][0]);
    let mut best = (0.0f32, p[0]);
    for y in y0..=y1 {
        let (mut lo, mut hi) = (x_min, x_max);
        for &(a, b, c) in &w {
            let rest = b * y + c; // a x + rest >= 0
            if a > 0 {
                lo = lo.max((-rest).div_euclid(a) + i64::from((-rest).rem_euclid(a) != 0));
            } else if a < 0 {
                hi = hi.min(rest.div_euclid(-a));
            } else if rest < 0 {
                hi = lo - 1;
            }
        }
        if lo > hi {
            continue;
        }
        let wl: f64 = w
            .iter()
            .zip(&z)
            .map(|(&(a, b, c), &zk)| (a * lo + b * y + c) as f64 * zk)
            .sum();
        let start = wl * inv;
        let row = &h[y as usize * side + lo as usize..=y as usize * side + hi as usize];
        for (k, &v) in row.iter().enumerate() {
            let d = (f64::from(v) - (start + dz_dx * k as f64)).abs() as f32;
            if d > best.0 {
                best = (d, [(lo + k as i64) as u16, y as u16]);
            }
        }
    }
    best
}

#[cfg(test)]
mod tests {
    use super::*;
    use crate::adaptive::Rtin;
    use crate::adaptive::test_grids::{assert_covers, random, rough};
    use proptest::prelude::*;

    #[test]
    fn bound_holds_and_beats_rtin_on_triangles() {
        let grid = rough(129, 5, 1200.0);
        for max_error in [50.0, 10.0, 2.0] {
            let dec = decimate(&grid, max_error);
            assert!(
                dec.max_error(&grid) <= max_error + 1e-3,
                "bound {max_error}"
            );
            let rtin = Rtin::new(&grid).mesh(max_error);
            assert!(
                dec.triangles.len() < rtin.triangles.len(),
                "{max_error}: decimate {} vs rtin {}",
                dec.triangles.len(),
                rtin.triangles.len()
            );
        }
    }

    #[test]
    fn removal_pass_only_removes() {
        let grid = rough(65, 9, 600.0);
        let mut options = DecimateOptions::new(4.0);
        options.remove_pass = false;
        let greedy = decimate_with(&grid, &options);
        let both = decimate(&grid, 4.0);
        assert!(both.triangles.len() <= greedy.triangles.len());
        assert!(both.max_error(&grid) <= 4.0 + 1e-3);
    }

    #[test]
    fn flat_grid_is_two_triangles_and_a_spike_is_found() {
        let side = 33;
        let mut h = vec![5.0f32; side * side];
        assert_eq!(
            decimate(&HeightGrid::new(side, h.clone()).expect("grid"), 0.0)
                .triangles
                .len(),
            2
        );
        h[7 * side + 20] = 30.0;
        let grid = HeightGrid::new(side, h).expect("grid");
        let mesh = decimate(&grid, 1.0);
        assert!(mesh.vertices.contains(&[20, 7]));
        assert!(mesh.max_error(&grid) <= 1.0);
    }

    proptest! {
        #![proptest_config(ProptestConfig::with_cases(32))]
        #[test]
        fn bound_holds_and_mesh_covers_the_square(
            k in 1u32..=5,
            seed in any::<u64>(),
            max_error in 0.0f64..30.0,
            relief in 0.0f32..300.0,
        ) {
            let grid = random(k, seed, relief);
            let mesh = decimate(&grid, max_error);
            prop_assert!(mesh.max_error(&grid) <= max_error + 1e-3);
            assert_covers(&mesh);
        }
    }
}
