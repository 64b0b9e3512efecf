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
//! `max_error`. The errors are computed in f32. On heights on a fine enough binary lattice
//! (whole metres over up to 2,048 m of relief in a 513-sample tile; see [`on_exact_lattice`])
//! they are exact, measured from the lowest sample. Otherwise f32 can round them by up to 8
//! ulps of the grid's largest height (5e-4 m for Earth's relief, 0.8 m for the 1.6e6 m a wrong
//! encoding decodes): a stored value that far or further below the bound keeps its triangles,
//! one that far above splits them, and one in between is settled exactly, in f64 over the
//! samples of the triangles it stands for (see [`MeshBuilder::exactly_beyond`]). Whole-metre
//! heights such as SRTM's put many errors exactly on a whole-metre bound: cut at the bound
//! less the rounding, as before, the srtm window of `tools/compare-meshers.py` took 251,607
//! triangles at 1 m where 213,983 hold it exactly; settling all 18,865 of its values on the
//! bound in f64 took 40 % longer than the lattice's exact f32. Each level costs about one
//! pass over the grid (samples on a triangle's legs are left to its children, which hold them
//! against the same line); how the passes are vectorised is in [`levels`].
//!
//! **One bound.** A mesh at one bound needs less: [`Rtin::rebuild_for`] runs the levels from
//! the coarsest down, stops each scan at its first sample beyond the bound, and never scans
//! below a triangle whose samples all lie within half the bound of its plane (no descendant
//! can then exceed the bound); see [`bound`]. Its meshes at that bound are the full build's
//! (tested on spikes, bumps and random grids, on and off the lattice), at about half the cost
//! on the srtm window at 5 and 30 m. `globus mesh` and the engine's tiles build this way.
//! Figures against martini: `tools/compare-meshers.py`, summarised in the README.

use super::{AdaptiveMesh, HeightGrid};

mod bound;
mod levels;

/// A tile's RTIN hierarchy with exact errors; build once, then [`Rtin::mesh`] per bound.
/// The default is an empty hierarchy to [`Rtin::rebuild`] into (its meshes are empty).
#[derive(Clone, Debug, Default)]
pub struct Rtin {
    side: usize,
    /// Per sample: the refinement error stored at it as a hypotenuse midpoint (0 at corners).
    errors: Vec<f32>,
    /// How far the stored errors may be from the true ones from f32 rounding, metres.
    rounding_m: f32,
    /// The grid's heights, for errors within rounding of a bound.
    heights: Vec<f32>,
    /// The one bound the stored errors are built for ([`Rtin::rebuild_for`]), or `None`
    /// when they are exact.
    only_for: Option<f64>,
    /// The samples [`Rtin::require`] made every mesh keep (to apply again to exact errors).
    required: Vec<u32>,
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
            heights: Vec::new(),
            only_for: None,
            required: Vec::new(),
        };
        rtin.rebuild(grid, scratch);
        rtin
    }

    /// Replaces this hierarchy by the one of `grid`, reusing its memory and `scratch`'s.
    pub fn rebuild(&mut self, grid: &HeightGrid, scratch: &mut RtinScratch) {
        self.take_heights(grid);
        self.only_for = None;
        levels::errors(
            &self.heights,
            self.side,
            &mut scratch.levels,
            &mut self.errors,
        );
    }

    /// Like [`Rtin::rebuild`], for meshes at `max_error` only: the stored errors are exact
    /// only where a mesh at that bound reads them, so the build skips the samples that
    /// cannot change such a mesh (scans stop at their first sample beyond the bound, and
    /// the subtrees of triangles within half the bound are never scanned; see the `bound`
    /// module). Meshes at `max_error` are the same as [`Rtin::rebuild`]'s and cost a
    /// fraction of the time at coarse bounds; a mesh at any other bound first computes the
    /// exact errors (as a full build would). The stored [`Rtin::errors`] are then only on
    /// the right side of `max_error`.
    pub fn rebuild_for(&mut self, grid: &HeightGrid, scratch: &mut RtinScratch, max_error: f64) {
        if max_error.is_nan() || max_error < 0.0 {
            // Negative (every vertex kept) or NaN: nothing to skip.
            return self.rebuild(grid, scratch);
        }
        self.take_heights(grid);
        self.only_for = Some(max_error);
        let rounding = f64::from(self.rounding_m);
        let stop = outwards(max_error + rounding, true);
        let prune = 0.5 * max_error - rounding;
        let prune = if prune < 0.0 {
            -1.0
        } else {
            outwards(prune, false)
        };
        bound::errors_for_bound(
            &self.heights,
            self.side,
            bound::Cut { stop, prune },
            &mut scratch.levels,
            &mut self.errors,
        );
    }

    /// The grid's heights as the passes read them, and their rounding.
    fn take_heights(&mut self, grid: &HeightGrid) {
        self.side = grid.side();
        self.required.clear();
        let heights = grid.heights();
        let (lowest, highest) = grid.min_max();
        self.heights.clear();
        if on_exact_lattice(heights, lowest, highest, self.side) {
            // Measured from the lowest sample (exactly: both are on the lattice), every
            // value the passes compute is exact in f32.
            self.heights.extend(heights.iter().map(|h| h - lowest));
            self.rounding_m = 0.0;
        } else {
            self.heights.extend_from_slice(heights);
            let largest = lowest.abs().max(highest.abs());
            self.rounding_m = 8.0 * f32::EPSILON * largest;
        }
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
        let before = self.required.len();
        for k in 0..side * side {
            if keep((k % side) as u16, (k / side) as u16) {
                self.required.push(k as u32);
            }
        }
        if self.required.len() > before {
            self.apply_required(before);
        }
    }

    /// Makes the stored errors of `required[from..]` infinite and lifts every midpoint above
    /// them.
    fn apply_required(&mut self, from: usize) {
        for &k in &self.required[from..] {
            self.errors[k as usize] = f32::INFINITY;
        }
        let side = self.side;
        let n = (side - 1) as u16;
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
        let RtinScratch {
            index_of, settled, ..
        } = scratch;
        if index_of.len() != side * side {
            index_of.clear();
            index_of.resize(side * side, u32::MAX);
        }
        settled.reset(side * side);
        // Stored errors up to `keep` keep their triangles, those above `split` split them;
        // in between they are settled exactly.
        let (keep, split) = if max_error < 0.0 {
            (max_error as f32, max_error as f32)
        } else {
            if let Some(built) = self.only_for
                && built != max_error
            {
                // Built for another bound: mesh from the exact errors.
                let mut exact = self.clone();
                exact.only_for = None;
                levels::errors(
                    &exact.heights,
                    side,
                    &mut levels::Scratch::default(),
                    &mut exact.errors,
                );
                if !exact.required.is_empty() {
                    exact.apply_required(0);
                }
                return exact.mesh_into(max_error, max_leg, scratch, mesh);
            }
            let rounding = f64::from(self.rounding_m);
            // Rounded outwards, so that only stored values in the band are settled in f64.
            (
                outwards((max_error - rounding).max(0.0), false),
                outwards(max_error + rounding, true),
            )
        };
        let mut builder = MeshBuilder {
            side,
            errors: &self.errors,
            heights: &self.heights,
            max_error,
            keep,
            split,
            settled,
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

/// `v` as f32, rounded up (`up`) or down where f32 cannot hold it.
fn outwards(v: f64, up: bool) -> f32 {
    let f = v as f32;
    if up && f64::from(f) < v {
        f.next_up()
    } else if !up && f64::from(f) > v {
        f.next_down()
    } else {
        f
    }
}

/// Whether the error passes of [`levels`] compute exactly in f32 on these heights: all on one
/// binary lattice (multiples of `2^-q` m: whole metres, Terrarium's 1/256 m) fine enough
/// that, measured from the lowest sample, `relief * 2^q * (side - 1) <= 2^20`. The passes'
/// values are then multiples of `2^-q / (side - 1)` no larger than 16 times the relief
/// (slopes times offsets, partial sums of three weighted corners), which f32's 24-bit
/// significand holds exactly. Whole-metre heights qualify up to 2,048 m of relief in a
/// 513-sample tile; the errors then need no settling near the bound.
fn on_exact_lattice(heights: &[f32], lowest: f32, highest: f32, side: usize) -> bool {
    let relief = f64::from(highest) - f64::from(lowest);
    if !relief.is_finite() || side < 2 {
        return false;
    }
    if relief == 0.0 {
        return true;
    }
    // The finest lattice allowed: 2^q with relief * 2^q * n <= 2^20.
    let q = ((1u64 << 20) as f64 / (relief * (side - 1) as f64))
        .log2()
        .floor();
    if !(-60.0..=60.0).contains(&q) {
        return false;
    }
    let scale = 2f32.powi(q as i32);
    // A power-of-two scale is exact; any f32 from 2^23 up is a whole number, and below it
    // adding and taking away 2^23 rounds to a whole number. Pure f32 arithmetic in runs
    // without an early exit, so the loop is vectorised (`fract` is a call to libm's
    // `truncf` on x86-64, and a conversion to i32 saturates lane by lane).
    const WHOLE_FROM: f32 = 8_388_608.0;
    heights.chunks(64).all(|run| {
        run.iter().fold(true, |whole, &h| {
            let v = (h * scale).abs();
            whole & ((v >= WHOLE_FROM) | ((v + WHOLE_FROM) - WHOLE_FROM == v))
        })
    })
}

/// Buffers [`Rtin::build`] and [`Rtin::mesh_into`] keep from one grid to the next (a few
/// times the grid's size): meshing many tiles with one scratch per thread spares the
/// allocations and their page faults.
#[derive(Default)]
pub struct RtinScratch {
    levels: levels::Scratch,
    /// Per grid sample: its vertex index in the mesh being built, or u32::MAX.
    index_of: Vec<u32>,
    /// Midpoints settled exactly by the mesh being built.
    settled: Settled,
}

/// Per grid sample, whether its stored error, settled exactly, is beyond the bound (unknown
/// until asked); only the samples asked are cleared for the next mesh.
#[derive(Default)]
struct Settled {
    state: Vec<u8>,
    asked: Vec<u32>,
}

impl Settled {
    const UNKNOWN: u8 = 0;
    const WITHIN: u8 = 1;
    const BEYOND: u8 = 2;

    fn reset(&mut self, samples: usize) {
        if self.state.len() == samples {
            for &m in &self.asked {
                self.state[m as usize] = Self::UNKNOWN;
            }
        } else {
            self.state.clear();
            self.state.resize(samples, Self::UNKNOWN);
        }
        self.asked.clear();
    }

    fn get(&self, m: u32) -> Option<bool> {
        match self.state[m as usize] {
            Self::UNKNOWN => None,
            s => Some(s == Self::BEYOND),
        }
    }

    fn set(&mut self, m: u32, beyond: bool) {
        self.state[m as usize] = if beyond { Self::BEYOND } else { Self::WITHIN };
        self.asked.push(m);
    }
}

struct MeshBuilder<'a> {
    side: usize,
    errors: &'a [f32],
    heights: &'a [f32],
    max_error: f64,
    /// Stored errors at most this hold the bound.
    keep: f32,
    /// Stored errors above this break it.
    split: f32,
    /// Midpoints whose stored error lay between the two, settled exactly.
    settled: &'a mut Settled,
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
        if leg > 1 && (leg > self.max_leg || self.beyond(m)) {
            let leg = if diagonal { leg } else { leg / 2 };
            self.split(c, a, m, leg, !diagonal);
            self.split(b, c, m, leg, !diagonal);
        } else {
            let t = [self.vertex(a), self.vertex(b), self.vertex(c)];
            self.mesh.triangles.push(t);
        }
    }

    /// Whether the value stored at midpoint `m` is beyond the bound.
    #[inline(always)]
    fn beyond(&mut self, m: u32) -> bool {
        let e = self.errors[m as usize];
        if e <= self.keep {
            false
        } else if e > self.split {
            true
        } else {
            self.exactly_beyond(m)
        }
    }

    /// Whether the value stored at midpoint `m`, computed in f64, is beyond the bound: the
    /// errors of the triangles it stands for (as [`levels`] builds it: an A(s) square's
    /// centre the square's two halves, a side's midpoint the B(s) triangles on either side)
    /// and the values at their children's midpoints. The f64 values are exact for heights
    /// in whole metres or Terrarium's 1/256 m steps: every triangle's doubled area is a power
    /// of two. Samples on a triangle's legs are measured too: against the same line, they
    /// are part of a child's error, so they change nothing.
    #[inline(never)]
    fn exactly_beyond(&mut self, m: u32) -> bool {
        if let Some(beyond) = self.settled.get(m) {
            return beyond;
        }
        let side = self.side as u32;
        let n = side - 1;
        let (x, y) = (m % side, m / side);
        let zeros = |v: u32| {
            if v == 0 {
                u32::BITS
            } else {
                v.trailing_zeros()
            }
        };
        let (zx, zy) = (zeros(x), zeros(y));
        let half = 1u32 << zx.min(zy);
        let quarter = half / 2;
        let at = |x: u32, y: u32| y * side + x;
        let mut triangles: [Option<[u32; 3]>; 2] = [None; 2];
        let mut children: [Option<u32>; 4] = [None; 4];
        if zx == zy {
            // The centre of the A(2 half) square with corner (x0, y0).
            let (x0, y0, s) = (x - half, y - half, 2 * half);
            let (nw, ne, sw, se) = (
                at(x0, y0),
                at(x0 + s, y0),
                at(x0, y0 + s),
                at(x0 + s, y0 + s),
            );
            let nw_se = (x0 / s + y0 / s).is_multiple_of(2);
            triangles = if nw_se {
                [Some([nw, sw, se]), Some([nw, ne, se])]
            } else {
                [Some([nw, ne, sw]), Some([ne, sw, se])]
            };
            children = [
                Some(at(x, y0)),
                Some(at(x, y0 + s)),
                Some(at(x0, y)),
                Some(at(x0 + s, y)),
            ];
        } else {
            // The midpoint of a side, between the squares on either side of it; with
            // (u, v) along and across the side.
            let horizontal = zx < zy;
            let point = |along: u32, across: u32| {
                if horizontal {
                    at(along, across)
                } else {
                    at(across, along)
                }
            };
            let (u, v) = if horizontal { (x, y) } else { (y, x) };
            let (a, b) = (point(u - half, v), point(u + half, v));
            if v > 0 {
                triangles[0] = Some([a, b, point(u, v - half)]);
            }
            if v < n {
                triangles[1] = Some([a, b, point(u, v + half)]);
            }
            if quarter > 0 {
                for (k, (du, up)) in [(false, true), (true, true), (false, false), (true, false)]
                    .into_iter()
                    .enumerate()
                {
                    if (up && v == 0) || (!up && v == n) {
                        continue;
                    }
                    let cu = if du { u + quarter } else { u - quarter };
                    let cv = if up { v - quarter } else { v + quarter };
                    children[k] = Some(point(cu, cv));
                }
            }
        }
        let beyond = triangles
            .into_iter()
            .flatten()
            .any(|t| self.triangle_beyond(t))
            || children.into_iter().flatten().any(|c| self.beyond(c));
        self.settled.set(m, beyond);
        beyond
    }

    /// Whether some sample in or on triangle `t` (row-major sample indices) is further than
    /// the bound from its plane, in f64: row by row over the samples the triangle covers.
    /// Its doubled area is a power of two, so the plane's slopes are exact for heights on a
    /// binary lattice (whole metres, Terrarium's 1/256 m).
    fn triangle_beyond(&self, t: [u32; 3]) -> bool {
        let side = self.side as i64;
        let p = t.map(|v| (i64::from(v) % side, i64::from(v) / side));
        let h = t.map(|v| f64::from(self.heights[v as usize]));
        let [(ax, ay), (bx, by), (cx, cy)] = p;
        let area = (bx - ax) * (cy - ay) - (by - ay) * (cx - ax);
        if area == 0 {
            return false;
        }
        // h(x, y) = h_a + gx (x - ax) + gy (y - ay) through all three corners.
        let (db, dc) = (h[1] - h[0], h[2] - h[0]);
        let gx = (db * (cy - ay) as f64 - dc * (by - ay) as f64) / area as f64;
        let gy = (dc * (bx - ax) as f64 - db * (cx - ax) as f64) / area as f64;
        // The triangle's legs and hypotenuse run along the grid or at 45 degrees, so each
        // edge crosses row y at a whole column: `x0 + step * y`. The inside of a sloping edge
        // is to its right or left (`bounds_left`); a horizontal edge keeps the rows on its
        // inner side.
        let sign = area.signum();
        let mut sloping = [(0i64, 0i64, false); 3];
        let mut count = 0;
        let (mut y_min, mut y_max) = (ay.min(by).min(cy), ay.max(by).max(cy));
        for ((ux, uy), (vx, vy)) in [(p[0], p[1]), (p[1], p[2]), (p[2], p[0])] {
            if vy == uy {
                // Inside where sign * (vx - ux) * (y - uy) >= 0.
                if sign * (vx - ux) > 0 {
                    y_min = y_min.max(uy);
                } else {
                    y_max = y_max.min(uy);
                }
                continue;
            }
            debug_assert!(vx == ux || (vx - ux).abs() == (vy - uy).abs());
            let step = (vx - ux) / (vy - uy);
            // orient(u, v, (x, y)) grows with x when -(vy - uy) * sign > 0.
            sloping[count] = (ux - step * uy, step, -(vy - uy) * sign > 0);
            count += 1;
        }
        let (x_min, x_max) = (ax.min(bx).min(cx), ax.max(bx).max(cx));
        for y in y_min..=y_max {
            let (mut lo, mut hi) = (x_min, x_max);
            for &(x0, step, bounds_left) in &sloping[..count] {
                let x = x0 + step * y;
                if bounds_left {
                    lo = lo.max(x);
                } else {
                    hi = hi.min(x);
                }
            }
            if lo > hi {
                continue;
            }
            let start = h[0] + gy * (y - ay) as f64 + gx * (lo - ax) as f64;
            let row = &self.heights[(y * side + lo) as usize..=(y * side + hi) as usize];
            let mut worst = 0.0f64;
            for (k, &v) in row.iter().enumerate() {
                let d = (f64::from(v) - (start + gx * k as f64)).abs();
                worst = if d > worst { d } else { worst };
            }
            if worst > self.max_error {
                return true;
            }
        }
        false
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

    /// A spike or a broad bump anywhere (on a coarse triangle's leg, hypotenuse, or
    /// inside) stops the bound's build from skipping the triangles around it. A spike
    /// shows at the finest level, which the build always computes in full; a bump only at
    /// coarser ones.
    #[test]
    fn a_bounds_build_never_misses_a_spike_or_a_bump() {
        let side = 33;
        let bound = 1.0;
        for at in 0..side * side {
            let (x, y) = ((at % side) as f32, (at / side) as f32);
            let plane = |k: usize| (k % side) as f32 * 0.25 + (k / side) as f32 * 0.5;
            let spike: Vec<f32> = (0..side * side)
                .map(|k| plane(k) + if k == at { 10.0 } else { 0.0 })
                .collect();
            // A cosine bump 6 samples in radius: second differences of about 0.7 m, so no
            // finest-level error reaches the bound.
            let bump: Vec<f32> = (0..side * side)
                .map(|k| {
                    let d = ((k % side) as f32 - x).hypot((k / side) as f32 - y);
                    let b = if d < 6.0 {
                        5.0 * (1.0 + (d / 6.0 * std::f32::consts::PI).cos())
                    } else {
                        0.0
                    };
                    plane(k) + b
                })
                .collect();
            for h in [spike, bump] {
                let grid = HeightGrid::new(side, h).expect("grid");
                let mut cut = Rtin::default();
                cut.rebuild_for(&grid, &mut RtinScratch::default(), bound);
                let mesh = cut.mesh(bound);
                assert!(mesh.max_error(&grid) <= bound, "at ({x}, {y})");
                assert_eq!(mesh.triangles, Rtin::new(&grid).mesh(bound).triangles);
            }
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

    /// Whole-metre heights put many errors exactly on a whole-metre bound. Those hold it and
    /// keep their triangles: the mesh's vertices are the corners and exactly the midpoints
    /// whose value, by the definition in f64, is beyond the bound (cut at the bound less
    /// the f32 rounding, as before, the ones on it split too). Both ways to get there: errors
    /// exact in f32 (heights on a fine enough lattice), and errors settled in f64 near the
    /// bound (a spike of 100 km, whose relief leaves the f32 values rounded).
    #[test]
    fn errors_exactly_on_the_bound_keep_their_triangles() {
        for (k, seed) in [(5u32, 3u32), (6, 11), (7, 5)] {
            let side = (1usize << k) + 1;
            for spike in [None, Some(1e5f32)] {
                let mut heights: Vec<f32> = rough(side, seed, 40.0)
                    .heights()
                    .iter()
                    .map(|h| h.round())
                    .collect();
                if let Some(spike) = spike {
                    heights[side + 1] = spike;
                }
                let grid = HeightGrid::new(side, heights).expect("grid");
                let reference = reference_errors(&grid);
                let rtin = Rtin::new(&grid);
                assert_eq!(rtin.rounding_m == 0.0, spike.is_none(), "{side}, {spike:?}");
                let n = side - 1;
                let corners = [0, n, n * side, n * side + n];
                for bound in [1.0, 2.0, 3.0] {
                    let on_bound = reference.iter().filter(|&&e| e == bound).count();
                    assert!(on_bound > 0, "{side}: no error is exactly {bound}");
                    let mesh = rtin.mesh(bound);
                    let mut got: Vec<usize> = mesh
                        .vertices
                        .iter()
                        .map(|&[x, y]| usize::from(y) * side + usize::from(x))
                        .collect();
                    got.sort_unstable();
                    let want: Vec<usize> = (0..side * side)
                        .filter(|&i| corners.contains(&i) || reference[i] > bound)
                        .collect();
                    let case = format!("{side} at {bound} m, spike {spike:?}");
                    assert_eq!(got.len(), want.len(), "{case} ({on_bound} on it)");
                    assert_eq!(got, want, "{case}");
                    assert!(mesh.max_error(&grid) <= bound, "{case}");
                }
            }
        }
    }

    /// Heights on a binary lattice as fine as [`on_exact_lattice`] allows (relief x 2^q x n
    /// = 2^20: whole metres over 8,192 m, Terrarium's 1/256 m over 32 m, 4 m steps over
    /// 262 km, above a datum far from zero) store exactly the errors of the definition, so
    /// meshes need no rounding allowance; a lattice twice as fine does not qualify.
    #[test]
    fn errors_on_a_fine_enough_lattice_are_exact() {
        let n = 128usize;
        for (step, datum, seed) in [
            (1.0f64, 0.0f64, 1u64),
            (1.0, 2_000.0, 2),
            (1.0 / 256.0, -430.0, 3),
            (4.0, 1.0e5, 4),
        ] {
            let levels = (1u64 << 20) as f64 / n as f64;
            let rough_grid = rough(n + 1, seed as u32, 1.0);
            let noise = random(7, seed, 1.0);
            // Half ridges, half noise (the noise's steepest slopes), spanning the full relief.
            let mut heights: Vec<f64> = rough_grid
                .heights()
                .iter()
                .zip(noise.heights())
                .map(|(&r, &z)| (0.5 * f64::from(r) + 0.5 * (f64::from(z) + 0.5)) * levels)
                .collect();
            let (lo, hi) = heights
                .iter()
                .fold((f64::MAX, f64::MIN), |(l, h), &v| (l.min(v), h.max(v)));
            for v in &mut heights {
                *v = ((*v - lo) / (hi - lo) * levels).round() * step + datum;
            }
            let grid =
                HeightGrid::new(n + 1, heights.iter().map(|&v| v as f32).collect()).expect("grid");
            let rtin = Rtin::new(&grid);
            let case = format!("step {step} m over {datum} m");
            assert_eq!(rtin.rounding_m, 0.0, "{case} should qualify");
            let reference = reference_errors(&grid);
            for (i, (&got, &want)) in rtin.errors().iter().zip(&reference).enumerate() {
                assert_eq!(f64::from(got), want, "{case}: sample {i}");
            }
            // Half the step: the same relief on a lattice twice as fine.
            let finer: Vec<f32> = heights
                .iter()
                .enumerate()
                .map(|(i, &v)| (v + if i == 1 { step / 2.0 } else { 0.0 }) as f32)
                .collect();
            let finer = HeightGrid::new(n + 1, finer).expect("grid");
            assert!(Rtin::new(&finer).rounding_m > 0.0, "{case}, halved");
        }
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

    /// A bound's build and the full build give the same mesh, and the bound's build does
    /// skip samples (its stored errors differ from the exact ones somewhere).
    fn assert_bound_build_meshes_alike(grid: &HeightGrid, bound: f64, keep_edges: bool) -> bool {
        let mut full = Rtin::new(grid);
        let mut scratch = RtinScratch::default();
        let mut cut = Rtin::default();
        cut.rebuild_for(grid, &mut scratch, bound);
        if keep_edges {
            let last = (grid.side() - 1) as u16;
            let keep = move |x: u16, y: u16| (y == 0 || y == last) && x.is_multiple_of(4);
            full.require(keep);
            cut.require(keep);
        }
        for max_leg in [u16::MAX, 8] {
            let want = full.mesh_with(bound, max_leg);
            let got = cut.mesh_with(bound, max_leg);
            assert_eq!(
                got.vertices,
                want.vertices,
                "side {}, bound {bound}, max_leg {max_leg}",
                grid.side()
            );
            assert_eq!(got.triangles, want.triangles, "bound {bound}");
        }
        full.errors() != cut.errors()
    }

    #[test]
    fn a_bounds_build_meshes_as_the_full_build_and_skips_samples() {
        let mut skipped = 0;
        let mut cases = 0;
        for (side, seed, relief) in [(129, 3u32, 800.0f32), (257, 11, 2500.0), (65, 5, 40.0)] {
            let smooth = rough(side, seed, relief);
            // On a whole-metre lattice (exact f32 passes), and off it far from the datum
            // (settled in f64 near the bound).
            let metres = smooth.heights().iter().map(|h| h.round()).collect();
            let metres = HeightGrid::new(side, metres).expect("grid");
            let lifted = smooth.heights().iter().map(|h| h + 4321.123).collect();
            let lifted = HeightGrid::new(side, lifted).expect("grid");
            for grid in [&smooth, &metres, &lifted] {
                for fraction in [0.0, 0.001, 0.01, 0.05, 0.2, 1.5] {
                    let bound = f64::from(relief) * fraction;
                    for keep_edges in [false, true] {
                        cases += 1;
                        skipped +=
                            usize::from(assert_bound_build_meshes_alike(grid, bound, keep_edges));
                    }
                }
                // Exactly on a whole-metre error: many stored values sit on the bound.
                for bound in [1.0, 5.0, 30.0] {
                    cases += 1;
                    skipped += usize::from(assert_bound_build_meshes_alike(grid, bound, false));
                }
            }
        }
        // Coarse bounds on smooth ground leave subtrees unscanned.
        assert!(
            skipped * 2 > cases,
            "{skipped} of {cases} builds skipped samples"
        );
    }

    #[test]
    fn a_bounds_build_meshed_at_another_bound_is_exact() {
        let grid = rough(129, 9, 600.0);
        let mut scratch = RtinScratch::default();
        let mut cut = Rtin::default();
        cut.rebuild_for(&grid, &mut scratch, 30.0);
        let mut full = Rtin::new(&grid);
        let keep = |x: u16, y: u16| y == 0 && x.is_multiple_of(2);
        cut.require(keep);
        full.require(keep);
        for other in [1.0, 14.9, 29.0, 31.0, 200.0] {
            let want = full.mesh(other);
            let got = cut.mesh(other);
            assert_eq!(got.triangles, want.triangles, "bound {other}");
            assert_eq!(got.vertices, want.vertices, "bound {other}");
        }
        // The kept samples stay kept there too.
        let mesh = cut.mesh(200.0);
        for x in (0..=128u16).step_by(2) {
            assert!(mesh.vertices.contains(&[x, 0]), "({x}, 0) dropped");
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
            let mut cut = Rtin::default();
            cut.rebuild_for(&grid, &mut RtinScratch::default(), max_error);
            let same = cut.mesh(max_error);
            prop_assert_eq!(same.triangles, mesh.triangles);
            prop_assert_eq!(same.vertices, mesh.vertices);
        }

        #[test]
        fn a_bounds_build_meshes_as_the_full_build_on_smooth_grids(
            k in 2u32..=8,
            seed in 0u32..1000,
            relief in 1.0f32..3000.0,
            fraction in 0.0f64..0.6,
            whole_metres in any::<bool>(),
        ) {
            let side = (1usize << k) + 1;
            let mut grid = rough(side, seed, relief);
            if whole_metres {
                let h = grid.heights().iter().map(|h| h.round()).collect();
                grid = HeightGrid::new(side, h).expect("grid");
            }
            assert_bound_build_meshes_alike(&grid, f64::from(relief) * fraction, seed % 2 == 0);
        }
    }
}
