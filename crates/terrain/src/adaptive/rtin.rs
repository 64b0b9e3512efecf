//! Right-triangulated irregular networks with exact per-triangle errors.
//!
//! The hierarchy is the one of `@mapbox/martini` (Evans et al. 2001): the tile square is cut
//! along its north-west to south-east diagonal, and every triangle splits at the midpoint of
//! its hypotenuse. Two kinds of triangle alternate, for square sizes `s = n, n/2, ..., 2`:
//!
//! ```text
//!   A(s): half of an s-square,           B(s): a side of an s-square as hypotenuse,
//!         hypotenuse = its diagonal            apex = the square's centre
//!   +-------+                               +-------+
//!   | \   1 |   split at the centre ->      |\  1  /|   split at the side's midpoint ->
//!   |   \   |   four B(s) (one per side)    |  \ /  |   two A(s/2)
//!   | 2   \ |                               |4  X  2|
//!   +-------+                               +-------+
//! ```
//!
//! An A(s) square at `(X, Y)` has its diagonal from north-west to south-east when
//! `X/s + Y/s` is even and from north-east to south-west when odd; that is what splitting
//! B(2s) produces.
//!
//! **Errors.** For each triangle the build scans every grid sample it covers and takes the
//! largest distance to the triangle's plane. The value stored at a midpoint vertex is the
//! largest of the errors of the (one or two) triangles whose hypotenuse it splits and of the
//! values stored at their children's midpoints. Refining every triangle whose midpoint value
//! exceeds `max_error` then gives a conforming mesh (both triangles sharing a hypotenuse split
//! together, and a triangle only splits when its parent did) whose error is at most
//! `max_error`, up to f32 rounding of about 1e-4 m. The scan costs each level one pass over
//! the grid: `2 log2(n)` passes, about 4.7 million samples for 513 x 513.

use rayon::prelude::*;

use super::{AdaptiveMesh, HeightGrid};

/// A tile's RTIN hierarchy with exact errors; build once, then [`Rtin::mesh`] per bound.
#[derive(Clone, Debug)]
pub struct Rtin {
    side: usize,
    /// Per sample: the refinement error stored at it as a hypotenuse midpoint (0 at corners).
    errors: Vec<f32>,
}

impl Rtin {
    /// Computes the error hierarchy of `grid`.
    pub fn new(grid: &HeightGrid) -> Self {
        let side = grid.side();
        let n = side - 1;
        let scan = Scan::new(grid.heights(), side);
        let mut errors = vec![0.0f32; side * side];
        let mut s = 2;
        while s <= n {
            // Small levels have many tiny triangles: constant sizes let the compiler unroll
            // their rows and drop the divisions.
            match s {
                2 => level::<2>(&scan, s, &mut errors),
                4 => level::<4>(&scan, s, &mut errors),
                8 => level::<8>(&scan, s, &mut errors),
                16 => level::<16>(&scan, s, &mut errors),
                _ => level::<0>(&scan, s, &mut errors),
            }
            s *= 2;
        }
        Self { side, errors }
    }

    /// Samples per side of the grid.
    pub fn side(&self) -> usize {
        self.side
    }

    /// The refinement error stored at each sample (row-major).
    pub fn errors(&self) -> &[f32] {
        &self.errors
    }

    /// The coarsest mesh of the hierarchy whose vertical error is at most `max_error` metres.
    pub fn mesh(&self, max_error: f64) -> AdaptiveMesh {
        self.mesh_with(max_error, u16::MAX)
    }

    /// Like [`Rtin::mesh`], but also splitting every triangle whose legs are longer than
    /// `max_leg` grid cells (a leg's length counted as `|dx| + |dy|`, so diagonal legs count
    /// double). Tiles on a curved body use this to bound how far a flat triangle strays from
    /// the ellipsoid between its corners. The limit depends only on a triangle's level, so
    /// the mesh stays conforming. A negative `max_error` keeps every grid vertex.
    pub fn mesh_with(&self, max_error: f64, max_leg: u16) -> AdaptiveMesh {
        let side = self.side;
        let n = (side - 1) as u16;
        let mut builder = MeshBuilder {
            side,
            errors: &self.errors,
            max_error: max_error as f32,
            max_leg: max_leg.max(1),
            index_of: vec![u32::MAX; side * side],
            mesh: AdaptiveMesh {
                side,
                ..AdaptiveMesh::default()
            },
        };
        builder.split([0, 0], [n, n], [n, 0]);
        builder.split([n, n], [0, 0], [0, n]);
        builder.mesh
    }
}

struct MeshBuilder<'a> {
    side: usize,
    errors: &'a [f32],
    max_error: f32,
    max_leg: u16,
    index_of: Vec<u32>,
    mesh: AdaptiveMesh,
}

impl MeshBuilder<'_> {
    /// Emits triangle (a, b, c) (hypotenuse a-b, apex c) or its refinement.
    fn split(&mut self, a: [u16; 2], b: [u16; 2], c: [u16; 2]) {
        let m = [(a[0] + b[0]) / 2, (a[1] + b[1]) / 2];
        let leg = a[0].abs_diff(c[0]) + a[1].abs_diff(c[1]);
        let at = usize::from(m[1]) * self.side + usize::from(m[0]);
        if leg > 1 && (leg > self.max_leg || self.errors[at] > self.max_error) {
            self.split(c, a, m);
            self.split(b, c, m);
        } else {
            let t = [self.vertex(a), self.vertex(b), self.vertex(c)];
            self.mesh.triangles.push(t);
        }
    }

    fn vertex(&mut self, p: [u16; 2]) -> u32 {
        let at = usize::from(p[1]) * self.side + usize::from(p[0]);
        if self.index_of[at] == u32::MAX {
            self.index_of[at] = self.mesh.vertices.len() as u32;
            self.mesh.vertices.push(p);
        }
        self.index_of[at]
    }
}

/// The grid and its transpose: a triangle on a vertical side is scanned as the same triangle
/// on a horizontal side of the transpose, so every scan runs along long rows.
struct Scan<'a> {
    side: usize,
    rows: &'a [f32],
    columns: Vec<f32>,
}

impl<'a> Scan<'a> {
    fn new(h: &'a [f32], side: usize) -> Self {
        let mut columns = vec![0.0; side * side];
        for (y, row) in h.chunks_exact(side).enumerate() {
            for (x, &v) in row.iter().enumerate() {
                columns[x * side + y] = v;
            }
        }
        Self {
            side,
            rows: h,
            columns,
        }
    }

    /// Error of the B triangle with hypotenuse from (x, y) to (x + s, y) of `grid` and its
    /// apex s/2 rows below (`down`) or above, leaving out the hypotenuse row itself (see
    /// [`Scan::hypotenuse`]).
    #[inline(always)]
    fn side_triangle(&self, grid: &[f32], x: usize, y: usize, s: usize, down: bool) -> f32 {
        let side = self.side;
        let half = s / 2;
        let ha = grid[y * side + x];
        let hb = grid[y * side + x + s];
        let apex_y = if down { y + half } else { y - half };
        let hc = grid[apex_y * side + x + half];
        let dx = (hb - ha) / s as f32;
        // Height gained per row towards the apex, beyond the hypotenuse's own slope.
        let per_row = (hc - (ha + hb) * 0.5) / half as f32;
        let mut worst = 0.0f32;
        for k in 1..half {
            let row = if down { y + k } else { y - k };
            let start = ha + dx * k as f32 + per_row * k as f32;
            let at = row * side + x + k;
            worst = worst.max(row_deviation(&grid[at..=at + s - 2 * k], start, dx));
        }
        worst
    }

    /// Error of the samples on the hypotenuse from (x, y) to (x + s, y) against the straight
    /// line between its ends: part of both triangles that share it.
    #[inline(always)]
    fn hypotenuse(&self, grid: &[f32], x: usize, y: usize, s: usize) -> f32 {
        let at = y * self.side + x;
        let (ha, hb) = (grid[at], grid[at + s]);
        row_deviation(&grid[at..=at + s], ha, (hb - ha) / s as f32)
    }

    /// Error of both halves of the s-square at (x, y), split along its NW-SE diagonal
    /// (`nw_se`) or its NE-SW one.
    #[inline(always)]
    fn square(&self, x: usize, y: usize, s: usize, nw_se: bool) -> f32 {
        let (side, h) = (self.side, self.rows);
        let at = |dx: usize, dy: usize| h[(y + dy) * side + x + dx];
        let (nw, ne, sw, se) = (at(0, 0), at(s, 0), at(0, s), at(s, s));
        let inv = 1.0 / s as f32;
        let mut worst = 0.0f32;
        for k in 0..=s {
            let row = (y + k) * side + x;
            let t = k as f32;
            if nw_se {
                // Upper right (NW, NE, SE): x from k to s; lower left (NW, SW, SE): 0 to k.
                let (upper_dx, upper_dy) = ((ne - nw) * inv, (se - ne) * inv);
                let (lower_dx, lower_dy) = ((se - sw) * inv, (sw - nw) * inv);
                let upper = nw + upper_dx * t + upper_dy * t;
                worst = worst.max(row_deviation(&h[row + k..=row + s], upper, upper_dx));
                worst = worst.max(row_deviation(
                    &h[row..=row + k],
                    nw + lower_dy * t,
                    lower_dx,
                ));
            } else {
                // Upper left (NW, NE, SW): x from 0 to s - k; lower right (NE, SW, SE): s - k to s.
                let (upper_dx, upper_dy) = ((ne - nw) * inv, (sw - nw) * inv);
                let (lower_dx, lower_dy) = ((se - sw) * inv, (se - ne) * inv);
                let upper = nw + upper_dy * t;
                worst = worst.max(row_deviation(&h[row..=row + s - k], upper, upper_dx));
                let lower = ne + lower_dy * t - lower_dx * t;
                worst = worst.max(row_deviation(&h[row + s - k..=row + s], lower, lower_dx));
            }
        }
        worst
    }
}

/// Both passes of level `s`: B(s), then A(s). `S` is `s` as a compile-time constant for
/// the small levels (0 otherwise), so the closures the rows run see a constant size.
fn level<const S: usize>(scan: &Scan<'_>, s: usize, errors: &mut [f32]) {
    let s = if S == 0 { s } else { S };
    sides_pass::<S>(scan, s, errors);
    squares_pass::<S>(scan, s, errors);
}

/// Computes `value(errors, x, y)` for `x = x0 + i * step` (`i < cols`) on every row
/// `y = y0 + j * step` (`j < rows`), rows in parallel (they only read `errors`) into one flat
/// buffer, then stores each at `errors[index(x, y)]`.
#[allow(clippy::too_many_arguments)] // one call per pass; a struct would only rename them
#[inline(always)]
fn each_row(
    errors: &mut [f32],
    (y0, rows): (usize, usize),
    (x0, cols): (usize, usize),
    step: usize,
    value: impl Fn(&[f32], usize, usize) -> f32 + Sync,
    index: impl Fn(usize, usize) -> usize,
) {
    let mut out = vec![0.0f32; rows * cols];
    let read: &[f32] = errors;
    // Tasks of at least ~64k grid samples (a value scans about step^2 of them): below that,
    // scheduling costs more than the work.
    let min_rows = (65536 / (cols * step * step).max(1)).max(1);
    out.par_chunks_mut(cols)
        .with_min_len(min_rows)
        .enumerate()
        .for_each(|(j, row)| {
            let y = y0 + j * step;
            for (i, e) in row.iter_mut().enumerate() {
                *e = value(read, x0 + i * step, y);
            }
        });
    for (j, row) in out.chunks_exact(cols).enumerate() {
        for (i, &e) in row.iter().enumerate() {
            errors[index(x0 + i * step, y0 + j * step)] = e;
        }
    }
}

/// B(s): every side of every s-square; the midpoint gets the errors of the triangles on both
/// sides of it and of their children (the A(s/2) centres beside it).
#[inline(always)]
fn sides_pass<const S: usize>(scan: &Scan<'_>, s: usize, errors: &mut [f32]) {
    let s = if S == 0 { s } else { S };
    let side = scan.side;
    let n = side - 1;
    let (half, quarter) = (s / 2, s / 4);
    let at = move |x: usize, y: usize| y * side + x;
    if s == 2 {
        // The only sample off the corners is the midpoint itself.
        let h = scan.rows;
        let horizontal = |_: &[f32], x: usize, y: usize| {
            (h[at(x + 1, y)] - (h[at(x, y)] + h[at(x + 2, y)]) * 0.5).abs()
        };
        let (edges, cells) = (n / 2 + 1, n / 2);
        each_row(errors, (0, edges), (0, cells), 2, horizontal, |x, y| {
            at(x + 1, y)
        });
        let vertical = |_: &[f32], x: usize, y: usize| {
            (h[at(x, y + 1)] - (h[at(x, y)] + h[at(x, y + 2)]) * 0.5).abs()
        };
        each_row(errors, (0, cells), (0, edges), 2, vertical, |x, y| {
            at(x, y + 1)
        });
        return;
    }
    // Horizontal sides on the grid, vertical sides as horizontal sides of the transpose.
    for (grid, transposed) in [(scan.rows, false), (&scan.columns[..], true)] {
        let value = |errors: &[f32], x: usize, y: usize| {
            let mut e = scan.hypotenuse(grid, x, y, s);
            if y > 0 {
                e = e.max(scan.side_triangle(grid, x, y, s, false));
            }
            if y < n {
                e = e.max(scan.side_triangle(grid, x, y, s, true));
            }
            for cy in [y.wrapping_sub(quarter), y + quarter] {
                if cy < side {
                    for cx in [x + quarter, x + half + quarter] {
                        let child = if transposed { at(cy, cx) } else { at(cx, cy) };
                        e = e.max(errors[child]);
                    }
                }
            }
            e
        };
        let index = |x: usize, y: usize| {
            if transposed {
                at(y, x + half)
            } else {
                at(x + half, y)
            }
        };
        each_row(errors, (0, n / s + 1), (0, n / s), s, value, index);
    }
}

/// A(s): both halves of every s-square; the centre gets their errors and those of the four
/// side midpoints (their children).
#[inline(always)]
fn squares_pass<const S: usize>(scan: &Scan<'_>, s: usize, errors: &mut [f32]) {
    let s = if S == 0 { s } else { S };
    let side = scan.side;
    let n = side - 1;
    let half = s / 2;
    let at = move |x: usize, y: usize| y * side + x;
    let h = scan.rows;
    let value = |errors: &[f32], x: usize, y: usize| {
        let nw_se = (x / s + y / s).is_multiple_of(2);
        let mut e = if s == 2 {
            // Off the corners: the centre (on the diagonal) and the side midpoints, whose
            // errors the B(2) pass already holds.
            let (a, b) = if nw_se {
                (h[at(x, y)], h[at(x + 2, y + 2)])
            } else {
                (h[at(x + 2, y)], h[at(x, y + 2)])
            };
            (h[at(x + 1, y + 1)] - (a + b) * 0.5).abs()
        } else {
            scan.square(x, y, s, nw_se)
        };
        for (cx, cy) in [
            (x + half, y),
            (x + half, y + s),
            (x, y + half),
            (x + s, y + half),
        ] {
            e = e.max(errors[at(cx, cy)]);
        }
        e
    };
    each_row(errors, (0, n / s), (0, n / s), s, value, |x, y| {
        at(x + half, y + half)
    });
}

/// max |row[k] - (start + step * k)|, in lanes the compiler vectorises (compare-and-select
/// instead of `f32::max`, whose NaN rules keep it scalar; heights are finite).
#[inline(always)]
fn row_deviation(row: &[f32], start: f32, step: f32) -> f32 {
    const LANES: usize = 8;
    const OFFSETS: [f32; LANES] = [0.0, 1.0, 2.0, 3.0, 4.0, 5.0, 6.0, 7.0];
    let mut acc = [0.0f32; LANES];
    let chunks = row.chunks_exact(LANES);
    let tail = chunks.remainder();
    let mut base = start;
    let mut done = 0usize;
    for chunk in chunks {
        for k in 0..LANES {
            let d = (chunk[k] - (base + step * OFFSETS[k])).abs();
            acc[k] = if d > acc[k] { d } else { acc[k] };
        }
        done += LANES;
        base = start + step * done as f32;
    }
    let mut worst = 0.0f32;
    for (k, &v) in tail.iter().enumerate() {
        let d = (v - (base + step * k as f32)).abs();
        worst = if d > worst { d } else { worst };
    }
    for a in acc {
        worst = if a > worst { a } else { worst };
    }
    worst
}

#[cfg(test)]
mod tests {
    use super::*;
    use crate::adaptive::test_grids::{assert_covers, random, rough};
    use proptest::prelude::*;

    #[test]
    fn flat_grid_is_two_triangles() {
        let grid = HeightGrid::new(65, vec![12.5; 65 * 65]).expect("grid");
        let mesh = Rtin::new(&grid).mesh(0.0);
        assert_eq!(mesh.triangles.len(), 2);
        assert_eq!(mesh.vertices.len(), 4);
        assert_eq!(mesh.max_error(&grid), 0.0);
    }

    #[test]
    fn a_tilted_plane_is_exact_with_two_triangles() {
        let side = 33;
        let h = (0..side * side)
            .map(|i| 3.0 * (i % side) as f32 - 2.0 * (i / side) as f32)
            .collect();
        let grid = HeightGrid::new(side, h).expect("grid");
        let mesh = Rtin::new(&grid).mesh(1e-3);
        assert_eq!(mesh.triangles.len(), 2);
        assert!(mesh.max_error(&grid) < 1e-4);
    }

    #[test]
    fn leg_limit_splits_flat_ground_uniformly_and_stays_conforming() {
        let grid = HeightGrid::new(33, vec![0.0; 33 * 33]).expect("grid");
        let rtin = Rtin::new(&grid);
        for max_leg in [1u16, 2, 4, 8, 16, 32] {
            let mesh = rtin.mesh_with(1.0, max_leg);
            let longest = mesh
                .triangles
                .iter()
                .flat_map(|t| {
                    let p = t.map(|i| mesh.vertices[i as usize]);
                    (0..3).map(move |k| {
                        let (a, b) = (p[k], p[(k + 1) % 3]);
                        a[0].abs_diff(b[0]).max(a[1].abs_diff(b[1]))
                    })
                })
                .max()
                .unwrap_or(0);
            // Axis-aligned legs of at most max_leg cells (diagonal legs count double).
            assert!(
                longest <= max_leg,
                "max_leg {max_leg}: edge of {longest} cells"
            );
            assert_covers(&mesh);
        }
        assert_eq!(rtin.mesh_with(-1.0, 1).triangles.len(), 2 * 32 * 32);
    }

    #[test]
    fn zero_error_keeps_every_sample_of_a_rough_grid() {
        let grid = rough(17, 3, 100.0);
        let mesh = Rtin::new(&grid).mesh(0.0);
        assert_eq!(mesh.vertices.len(), 17 * 17);
        assert_eq!(mesh.triangles.len(), 2 * 16 * 16);
        assert_covers(&mesh);
    }

    /// A single spike is found wherever it sits, though martini-style sampling of one sample
    /// per triangle would miss it at coarse levels: the exactness this module is about.
    #[test]
    fn a_single_spike_is_never_missed() {
        let side = 65;
        for (x, y) in [(1, 1), (17, 5), (31, 33), (63, 2), (40, 63)] {
            let mut h = vec![0.0f32; side * side];
            h[y * side + x] = 10.0;
            let grid = HeightGrid::new(side, h).expect("grid");
            let mesh = Rtin::new(&grid).mesh(0.5);
            assert!(mesh.max_error(&grid) <= 0.5, "spike at {x},{y}");
            assert!(mesh.vertices.contains(&[x as u16, y as u16]));
        }
    }

    #[test]
    fn bound_holds_on_rough_grids_and_tighter_bounds_add_triangles() {
        let grid = rough(129, 7, 1500.0);
        let rtin = Rtin::new(&grid);
        let mut last = 0;
        for max_error in [200.0, 50.0, 10.0, 2.0, 0.5] {
            let mesh = rtin.mesh(max_error);
            let measured = mesh.max_error(&grid);
            assert!(
                measured <= max_error + 1e-3,
                "bound {max_error}: measured {measured}"
            );
            assert!(mesh.triangles.len() >= last);
            last = mesh.triangles.len();
            assert_covers(&mesh);
        }
    }

    proptest! {
        #![proptest_config(ProptestConfig::with_cases(48))]
        #[test]
        fn bound_holds_on_random_grids(
            k in 1u32..=5,
            seed in any::<u64>(),
            max_error in 0.0f64..40.0,
            relief in 0.0f32..500.0,
        ) {
            let grid = random(k, seed, relief);
            let mesh = Rtin::new(&grid).mesh(max_error);
            prop_assert!(mesh.max_error(&grid) <= max_error + 1e-3);
            assert_covers(&mesh);
        }
    }
}
