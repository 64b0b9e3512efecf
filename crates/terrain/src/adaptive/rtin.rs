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
//! **Errors.** For each triangle the build takes the largest distance of any grid sample it
//! covers to the triangle's plane. The value stored at a midpoint vertex is the largest of the
//! errors of the (one or two) triangles whose hypotenuse it splits and of the values stored at
//! their children's midpoints. Refining every triangle whose midpoint value exceeds
//! `max_error` then gives a conforming mesh (both triangles sharing a hypotenuse split
//! together, and a triangle only splits when its parent did) whose error is at most
//! `max_error`: the errors are computed in f32, so the mesh is cut at `max_error` less the
//! rounding those computations can make for the grid's largest height (8 ulps of it: 5e-4 m
//! for Earth's relief, 0.8 m for the 1.6e6 m a wrong encoding decodes), and the bound holds
//! whatever the heights. Each level costs about one pass over the
//! grid (samples on a triangle's legs are left to its children, which hold them against the
//! same line); how the passes are vectorised is in [`levels`]. Figures against martini:
//! `tools/compare-meshers.py`, summarised in the README.

use super::{AdaptiveMesh, HeightGrid};

mod levels;

/// A tile's RTIN hierarchy with exact errors; build once, then [`Rtin::mesh`] per bound.
/// The default is an empty hierarchy to [`Rtin::rebuild`] into (its meshes are empty).
#[derive(Clone, Debug, Default)]
pub struct Rtin {
    side: usize,
    /// Per sample: the refinement error stored at it as a hypotenuse midpoint (0 at corners).
    errors: Vec<f32>,
    /// How far the stored errors may be below the true ones from f32 rounding, metres.
    rounding_m: f32,
}

impl Rtin {
    /// Computes the error hierarchy of `grid`.
    pub fn new(grid: &HeightGrid) -> Self {
        Self::build(grid, &mut RtinScratch::default())
    }

    /// Like [`Rtin::new`], with buffers kept in `scratch` for the next grid.
    pub fn build(grid: &HeightGrid, scratch: &mut RtinScratch) -> Self {
        let mut rtin = Self {
            side: grid.side(),
            errors: Vec::new(),
            rounding_m: 0.0,
        };
        rtin.rebuild(grid, scratch);
        rtin
    }

    /// Replaces this hierarchy by the one of `grid`, reusing its memory and `scratch`'s.
    pub fn rebuild(&mut self, grid: &HeightGrid, scratch: &mut RtinScratch) {
        self.side = grid.side();
        levels::errors(
            grid.heights(),
            self.side,
            &mut scratch.levels,
            &mut self.errors,
        );
        let highest = grid.heights().iter().fold(0.0f32, |m, h| m.max(h.abs()));
        self.rounding_m = 8.0 * f32::EPSILON * highest;
    }

    /// Makes every mesh keep the samples `keep(x, y)` names (grid columns and rows), and
    /// with them whatever keeps the mesh conforming: their stored errors become infinite and
    /// every midpoint above them in the hierarchy takes the largest of its children again.
    /// A tile keeps its north and south edges' samples this way where a chord across a
    /// polar parallel would stray sideways from a neighbour's.
    pub fn require(&mut self, keep: impl Fn(u16, u16) -> bool) {
        let side = self.side;
        if side < 3 {
            return;
        }
        let n = (side - 1) as u16;
        let mut changed = false;
        for (k, e) in self.errors.iter_mut().enumerate() {
            if keep((k % side) as u16, (k / side) as u16) {
                *e = f32::INFINITY;
                changed = true;
            }
        }
        if !changed {
            return;
        }
        let at = |x: u16, y: u16| u32::from(y) * side as u32 + u32::from(x);
        let (nw, ne, sw, se) = (at(0, 0), at(n, 0), at(0, n), at(n, n));
        // A midpoint is shared by the two triangles of its diamond, and depth first visits
        // one of them before the other's subtree is done: repeat until nothing rises.
        loop {
            let mut rose = false;
            self.lift(nw, se, ne, n, true, &mut rose);
            self.lift(se, nw, sw, n, true, &mut rose);
            if !rose {
                break;
            }
        }
    }

    /// The largest stored error in the subtree of triangle (a, b, c) (as in
    /// [`MeshBuilder::split`]), raising its midpoint's to it.
    fn lift(&mut self, a: u32, b: u32, c: u32, leg: u16, diagonal: bool, rose: &mut bool) -> f32 {
        if leg <= 1 {
            return 0.0;
        }
        let m = (a + b) / 2;
        let child = if diagonal { leg } else { leg / 2 };
        let below = self
            .lift(c, a, m, child, !diagonal, rose)
            .max(self.lift(b, c, m, child, !diagonal, rose));
        let e = &mut self.errors[m as usize];
        if below > *e {
            *e = below;
            *rose = true;
        }
        *e
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
        let mut mesh = AdaptiveMesh::default();
        self.mesh_into(max_error, max_leg, &mut RtinScratch::default(), &mut mesh);
        mesh
    }

    /// Like [`Rtin::mesh_with`], into `mesh` (its buffers reused), with the vertex map kept in
    /// `scratch`: a tiler meshing tile after tile with one scratch and one output per thread
    /// allocates nothing once they have grown.
    pub fn mesh_into(
        &self,
        max_error: f64,
        max_leg: u16,
        scratch: &mut RtinScratch,
        mesh: &mut AdaptiveMesh,
    ) {
        let side = self.side;
        mesh.side = side;
        mesh.vertices.clear();
        mesh.triangles.clear();
        if side < 2 {
            return;
        }
        let n = (side - 1) as u16;
        // Every entry is u32::MAX between calls: only the entries of used vertices are
        // written, and they are put back below.
        let index_of = &mut scratch.index_of;
        if index_of.len() != side * side {
            index_of.clear();
            index_of.resize(side * side, u32::MAX);
        }
        let mut builder = MeshBuilder {
            side,
            errors: &self.errors,
            max_error: if max_error < 0.0 {
                max_error as f32
            } else {
                (max_error as f32 - self.rounding_m).max(0.0)
            },
            max_leg: max_leg.max(1),
            index_of,
            mesh,
        };
        // Corners as row-major sample indices (a hypotenuse's midpoint is their mean).
        let at = |x: u16, y: u16| u32::from(y) * side as u32 + u32::from(x);
        let (nw, ne, sw, se) = (at(0, 0), at(n, 0), at(0, n), at(n, n));
        builder.split(nw, se, ne, n, true);
        builder.split(se, nw, sw, n, true);
        for &[x, y] in &mesh.vertices {
            index_of[usize::from(y) * side + usize::from(x)] = u32::MAX;
        }
    }
}

/// Buffers [`Rtin::build`] and [`Rtin::mesh_into`] keep from one grid to the next (a few
/// times the grid's size): meshing many tiles with one scratch per thread spares the
/// allocations and their page faults.
#[derive(Default)]
pub struct RtinScratch {
    levels: levels::Scratch,
    /// Per grid sample: its vertex index in the mesh being built, or u32::MAX.
    index_of: Vec<u32>,
}

struct MeshBuilder<'a> {
    side: usize,
    errors: &'a [f32],
    max_error: f32,
    max_leg: u16,
    index_of: &'a mut [u32],
    mesh: &'a mut AdaptiveMesh,
}

impl MeshBuilder<'_> {
    /// Emits triangle (a, b, c) (hypotenuse a-b, apex c; row-major sample indices) or its
    /// refinement. `leg` is its legs' length as `|dx| + |dy|` and `diagonal` whether its
    /// hypotenuse is a square's diagonal (an A triangle, whose children keep its leg length;
    /// a B triangle's children have half).
    fn split(&mut self, a: u32, b: u32, c: u32, leg: u16, diagonal: bool) {
        let m = (a + b) / 2;
        if leg > 1 && (leg > self.max_leg || self.errors[m as usize] > self.max_error) {
            let leg = if diagonal { leg } else { leg / 2 };
            self.split(c, a, m, leg, !diagonal);
            self.split(b, c, m, leg, !diagonal);
        } else {
            let t = [self.vertex(a), self.vertex(b), self.vertex(c)];
            self.mesh.triangles.push(t);
        }
    }

    fn vertex(&mut self, p: u32) -> u32 {
        let at = p as usize;
        if self.index_of[at] == u32::MAX {
            self.index_of[at] = self.mesh.vertices.len() as u32;
            let side = self.side as u32;
            self.mesh
                .vertices
                .push([(p % side) as u16, (p / side) as u16]);
        }
        self.index_of[at]
    }
}

#[cfg(test)]
mod tests {
    use super::*;
    use crate::adaptive::test_grids::{assert_covers, random, rough};
    use proptest::prelude::*;

    /// A wrong encoding decoded noise to heights of 1.6e6 m, and the mesh's measured error
    /// (5.031 m) exceeded its own 5 m bound from f32 rounding: the bound holds at any height.
    #[test]
    fn the_bound_holds_for_heights_far_above_any_planet() {
        for (offset, relief) in [(0.0f32, 1.6e6f32), (1.6e6, 40.0), (-1e6, 3e5)] {
            let grid = rough(129, 7, relief);
            let h = grid.heights().iter().map(|h| h + offset).collect();
            let grid = HeightGrid::new(129, h).expect("grid");
            let rtin = Rtin::new(&grid);
            for bound in [0.5, 5.0, 50.0] {
                let got = rtin.mesh(bound).max_error(&grid);
                assert!(
                    got <= bound,
                    "offset {offset}, relief {relief}: {got} > {bound}"
                );
            }
        }
    }

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
    fn required_samples_are_kept_and_the_mesh_stays_conforming() {
        // A flat grid: without requirements two triangles.
        let side = 33;
        let grid = HeightGrid::new(side, vec![0.0; side * side]).expect("grid");
        let mut rtin = Rtin::new(&grid);
        assert_eq!(rtin.mesh(1.0).triangles.len(), 2);
        // Keep every sample of the north and south edges.
        rtin.require(|_, y| y == 0 || y == 32);
        let mesh = rtin.mesh(1.0);
        for x in 0..=32u16 {
            for y in [0u16, 32] {
                assert!(mesh.vertices.contains(&[x, y]), "({x}, {y}) dropped");
            }
        }
        // Far fewer triangles than the full grid's 2048: the interior stays coarse.
        assert!(mesh.triangles.len() < 700, "{}", mesh.triangles.len());
        // Conforming: every edge is shared by two triangles or lies on the border.
        let mut edges = std::collections::HashMap::new();
        for t in &mesh.triangles {
            for k in 0..3 {
                let (a, b) = (t[k], t[(k + 1) % 3]);
                *edges.entry((a.min(b), a.max(b))).or_insert(0) += 1;
            }
        }
        for (&(a, b), &count) in &edges {
            let (p, q) = (mesh.vertices[a as usize], mesh.vertices[b as usize]);
            let border = |c: usize| p[c] == q[c] && (p[c] == 0 || p[c] == 32);
            assert!(
                count == 2 || (count == 1 && (border(0) || border(1))),
                "edge {p:?}-{q:?} used {count} times"
            );
        }
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

    /// The stored errors by definition, in f64 and by brute force: every triangle of the
    /// hierarchy, smallest first, measured at every grid sample inside it or on its border
    /// against the plane through its corners; the value at a hypotenuse midpoint is the
    /// largest of its (one or two) triangles' errors and of their children's midpoints.
    fn reference_errors(grid: &HeightGrid) -> Vec<f64> {
        let side = grid.side();
        let n = (side - 1) as i64;
        let h = |x: i64, y: i64| f64::from(grid.heights()[(y * side as i64 + x) as usize]);
        let mut triangles = Vec::new();
        let mut stack = vec![([0, 0], [n, n], [n, 0]), ([n, n], [0, 0], [0, n])];
        while let Some((a, b, c)) = stack.pop() {
            if (a[0] - b[0]).abs().max((a[1] - b[1]).abs()) < 2 {
                continue;
            }
            let m = [(a[0] + b[0]) / 2, (a[1] + b[1]) / 2];
            triangles.push((a, b, c));
            stack.push((c, a, m));
            stack.push((b, c, m));
        }
        // Squared hypotenuse length: 4 for B(2), 8 for A(2), 16 for B(4), ...
        let size = |t: &([i64; 2], [i64; 2], [i64; 2])| {
            (t.0[0] - t.1[0]).pow(2) + (t.0[1] - t.1[1]).pow(2)
        };
        triangles.sort_by_key(size);
        let mut stored = vec![0.0f64; side * side];
        let index = |p: [i64; 2]| (p[1] * side as i64 + p[0]) as usize;
        for (a, b, c) in triangles {
            let det = ((b[0] - a[0]) * (c[1] - a[1]) - (c[0] - a[0]) * (b[1] - a[1])) as f64;
            let mut own = 0.0f64;
            for y in a[1].min(b[1]).min(c[1])..=a[1].max(b[1]).max(c[1]) {
                for x in a[0].min(b[0]).min(c[0])..=a[0].max(b[0]).max(c[0]) {
                    let wb = ((x - a[0]) * (c[1] - a[1]) - (c[0] - a[0]) * (y - a[1])) as f64 / det;
                    let wc = ((b[0] - a[0]) * (y - a[1]) - (x - a[0]) * (b[1] - a[1])) as f64 / det;
                    let wa = 1.0 - wb - wc;
                    if wa < -1e-9 || wb < -1e-9 || wc < -1e-9 {
                        continue;
                    }
                    let plane = wa * h(a[0], a[1]) + wb * h(b[0], b[1]) + wc * h(c[0], c[1]);
                    own = own.max((h(x, y) - plane).abs());
                }
            }
            let m = [(a[0] + b[0]) / 2, (a[1] + b[1]) / 2];
            let mut value = own;
            if size(&(a, b, c)) > 4 {
                for child in [
                    [(c[0] + a[0]) / 2, (c[1] + a[1]) / 2],
                    [(b[0] + c[0]) / 2, (b[1] + c[1]) / 2],
                ] {
                    value = value.max(stored[index(child)]);
                }
            }
            stored[index(m)] = stored[index(m)].max(value);
        }
        stored
    }

    /// The fast passes (directly, across squares, along rows) against the definition, on
    /// grids from 3 x 3 to 129 x 129: every stored value equal up to f32 rounding. Larger
    /// or smaller values would both be wrong: too large adds triangles, too small breaks
    /// the bound.
    #[test]
    fn stored_errors_match_the_definition() {
        let grids = [
            random(1, 3, 50.0),
            random(2, 5, 50.0),
            random(4, 7, 300.0),
            rough(33, 9, 1500.0),
            random(6, 11, 800.0),
            rough(129, 13, 2500.0),
        ];
        for grid in grids {
            let reference = reference_errors(&grid);
            let errors = Rtin::new(&grid).errors().to_vec();
            let side = grid.side();
            for (i, (&got, &want)) in errors.iter().zip(&reference).enumerate() {
                assert!(
                    (f64::from(got) - want).abs() <= 2e-3,
                    "side {side}: sample ({}, {}) stores {got}, the definition gives {want}",
                    i % side,
                    i / side
                );
            }
        }
    }

    /// A scratch carried from grid to grid (of other sizes too) changes nothing.
    #[test]
    fn reused_scratch_gives_the_same_errors() {
        let mut scratch = RtinScratch::default();
        for grid in [
            rough(129, 1, 900.0),
            rough(129, 2, 40.0),
            random(3, 4, 80.0),
            rough(129, 5, 2000.0),
        ] {
            let reused = Rtin::build(&grid, &mut scratch);
            assert_eq!(reused.errors(), Rtin::new(&grid).errors());
        }
    }

    /// One hierarchy rebuilt and one scratch and output reused across grids of two sizes and
    /// several bounds give exactly the meshes fresh ones do (the vertex map is left clean).
    #[test]
    fn reused_buffers_give_the_same_meshes() {
        let mut scratch = RtinScratch::default();
        let mut rtin = Rtin::default();
        let mut mesh = AdaptiveMesh::default();
        rtin.mesh_into(1.0, u16::MAX, &mut scratch, &mut mesh);
        assert!(mesh.triangles.is_empty() && mesh.vertices.is_empty());
        for (grid, max_error, max_leg) in [
            (rough(129, 1, 900.0), 5.0, u16::MAX),
            (rough(129, 2, 900.0), 0.5, 8),
            (random(3, 4, 80.0), 2.0, u16::MAX),
            (rough(129, 5, 2000.0), 20.0, u16::MAX),
            (rough(129, 5, 2000.0), -1.0, 1),
        ] {
            rtin.rebuild(&grid, &mut scratch);
            rtin.mesh_into(max_error, max_leg, &mut scratch, &mut mesh);
            let fresh = Rtin::new(&grid).mesh_with(max_error, max_leg);
            assert_eq!(mesh.side, grid.side());
            assert_eq!(mesh.vertices, fresh.vertices);
            assert_eq!(mesh.triangles, fresh.triangles);
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
