//! The per-level error passes of [`super::Rtin::new`]: [`errors`].
//!
//! At level `s` every s-square is cut into the two A(s) triangles of its diagonal and into the
//! four B(s) triangles around its centre (one per side, the side as hypotenuse). A pass
//! computes, per square, the largest distance of a grid sample to the plane of the triangle
//! holding it: for both A halves together, and for each B triangle ([`Scratch`]); [`combine`]
//! then stores the values at the midpoints, with their children's.
//!
//! A sample on a triangle's legs need not be measured against that triangle: its legs are the
//! hypotenuses of its children, whose stored values already hold those samples against the
//! same line. So an A(s) square is measured at its interior samples (its diagonal included,
//! its sides left out) and a B(s) triangle at its interior and its hypotenuse (the square's
//! diagonals left out).
//!
//! Three ways to run a pass, by level:
//! * [`level_two`]: a B(2) triangle holds one sample besides its corners, an A(2) square one
//!   more; computed directly on the grid rows.
//! * [`across_squares`] for small squares, whose rows are too short to vectorise along: the
//!   loop runs over one set of squares of a square row at once (every `2 * 16 / s`-th square),
//!   sample `(i, j)` of each read from one contiguous array (the rows regrouped by `x mod 32`,
//!   [`Phased`]).
//! * [`along_rows`] for large squares: each triangle's rows scanned in SIMD lanes.

use rayon::prelude::*;

use crate::adaptive::rows::{larger, row_deviation};

/// Levels up to this square size are computed across squares, larger ones, whose triangles
/// have long rows, along rows.
pub(super) const ACROSS_SQUARES_UP_TO: usize = 16;

/// The refinement error stored at every sample of the `side` x `side` grid `h` (0 at the
/// tile's corners): level by level from the smallest squares up.
pub(super) fn errors(h: &[f32], side: usize, scratch: &mut Scratch, errors: &mut Vec<f32>) {
    let n = side - 1;
    errors.clear();
    errors.resize(side * side, 0.0);
    level_two(h, side, errors);
    scratch.transposed = false;
    scratch.phased_filled = false;
    let mut s = 4;
    while s <= n {
        if s == n || s > ACROSS_SQUARES_UP_TO {
            along_rows(h, side, s, scratch);
        } else {
            across_squares(h, side, s, scratch);
        }
        combine(errors, &scratch.a, &scratch.b, side, s);
        s *= 2;
    }
}

/// Per-square errors of one level and the buffers reused from level to level (fresh ones
/// would cost page faults every level).
#[derive(Default)]
pub(super) struct Scratch {
    /// Per level, coarsest first: the per-square errors of a bound's build
    /// ([`super::bound::errors_for_bound`]).
    pub(super) per_level: Vec<LevelErrors>,
    /// The grid regrouped for [`across_squares`], once `phased_filled`.
    phased: Phased,
    pub(super) phased_filled: bool,
    /// The grid transposed, for [`along_rows`], once `transposed`.
    columns: Vec<f32>,
    pub(super) transposed: bool,
    /// Per square, row-major: both A(s) halves.
    pub(super) a: Vec<f32>,
    /// Per square: the B(s) triangles north, south, west and east of its centre.
    pub(super) b: Vec<[f32; 4]>,
}

/// One level's per-square errors, as [`Scratch::a`] and [`Scratch::b`] hold them.
#[derive(Default)]
pub(super) struct LevelErrors {
    pub(super) a: Vec<f32>,
    pub(super) b: Vec<[f32; 4]>,
}

impl Scratch {
    fn prepare(&mut self, squares: usize) {
        self.a.clear();
        self.a.resize(squares * squares, 0.0);
        self.b.clear();
        self.b.resize(squares * squares, [0.0; 4]);
    }
}

pub(super) const NORTH: usize = 0;
pub(super) const SOUTH: usize = 1;
pub(super) const WEST: usize = 2;
pub(super) const EAST: usize = 3;

/// Square rows per parallel task: enough for about 64k samples, below which scheduling
/// costs more than the work.
fn min_rows(squares: usize, s: usize) -> usize {
    (65536 / (squares * s * s).max(1)).max(1)
}

/// The grid's rows regrouped by a period `P` (twice the largest square computed across
/// squares): sample `x = P q + i` of row `y` is stored at phase `i` (`0 <= i < P`), position
/// `q`. The squares of size `s` at `x = P q + first` (`first` a multiple of `s` below `P`)
/// are one set, and sample `(i, j)` of every square of a set is one contiguous run.
#[derive(Default)]
struct Phased {
    /// Positions per phase carrying squares, `n / P`.
    runs: usize,
    /// Floats per phase: `runs + 1` (phase 0 holds the row's last sample too).
    len: usize,
    /// `P`.
    period: usize,
    data: Vec<f32>,
}

impl Phased {
    fn fill(&mut self, h: &[f32], side: usize, period: usize) {
        self.period = period;
        self.runs = (side - 1) / period;
        self.len = self.runs + 1;
        let row_len = period * self.len;
        self.data.resize(side * row_len, 0.0);
        for (row, out) in h
            .chunks_exact(side)
            .zip(self.data.chunks_exact_mut(row_len))
        {
            // Period by period: each read a run of `period`, written one to a phase (each
            // phase's writes contiguous from period to period).
            for (q, chunk) in row.chunks_exact(period).take(self.runs).enumerate() {
                for (i, &v) in chunk.iter().enumerate() {
                    out[i * self.len + q] = v;
                }
            }
            out[self.runs] = row[self.runs * period];
        }
    }

    /// `h[y][P q + i]` for `q < runs`, `0 <= i <= P`.
    #[inline(always)]
    fn column(&self, y: usize, i: usize) -> &[f32] {
        let row_len = self.period * self.len;
        let row = &self.data[y * row_len..(y + 1) * row_len];
        if i == self.period {
            &row[1..self.len]
        } else {
            &row[i * self.len..i * self.len + self.runs]
        }
    }
}

/// Heights of one set of squares of a square row, relative to their north-west corners.
struct Corners {
    nw: Vec<f32>,
    ne: Vec<f32>,
    sw: Vec<f32>,
    se: Vec<f32>,
    centre: Vec<f32>,
}

impl Corners {
    fn new(runs: usize) -> Self {
        let zeros = || vec![0.0f32; runs];
        Self {
            nw: zeros(),
            ne: zeros(),
            sw: zeros(),
            se: zeros(),
            centre: zeros(),
        }
    }

    /// The set of s-squares at `x = P q + first` and `y`.
    fn load(&mut self, grid: &Phased, y: usize, first: usize, s: usize) {
        let half = s / 2;
        self.nw.copy_from_slice(grid.column(y, first));
        let nw = &self.nw;
        let relative = |out: &mut Vec<f32>, from: &[f32]| {
            for ((o, &v), &base) in out.iter_mut().zip(from).zip(nw) {
                *o = v - base;
            }
        };
        relative(&mut self.ne, grid.column(y, first + s));
        relative(&mut self.sw, grid.column(y + s, first));
        relative(&mut self.se, grid.column(y + s, first + s));
        relative(&mut self.centre, grid.column(y + half, first + half));
    }
}

/// `acc[p] = max(acc[p], |h[p] - nw[p] - (wa a[p] + wb b[p] + wc c[p])|)`: the distance of
/// one sample of every square to a plane through the square's corners, in SIMD lanes
/// (compare-and-select, not `f32::max`, whose NaN rules keep it scalar; heights are finite).
#[inline(always)]
fn accumulate(acc: &mut [f32], h: &[f32], nw: &[f32], terms: [(f32, &[f32]); 3]) {
    let n = acc.len();
    let [(wa, a), (wb, b), (wc, c)] = terms;
    let (h, nw, a, b, c) = (&h[..n], &nw[..n], &a[..n], &b[..n], &c[..n]);
    for p in 0..n {
        let d = ((h[p] - nw[p]) - (wa * a[p] + wb * b[p] + wc * c[p])).abs();
        acc[p] = larger(acc[p], d);
    }
}

/// Errors of one set of squares of a square row: both A(s) halves together and the four B(s)
/// triangles.
struct RowErrors {
    a: Vec<f32>,
    b: [Vec<f32>; 4],
}

/// Computes the A(s) and B(s) errors of the set of squares at `x = P q + first` of square row
/// `y`; `nw_se` is their diagonal.
fn square_row(
    grid: &Phased,
    corners: &mut Corners,
    out: &mut RowErrors,
    (y, first, nw_se): (usize, usize, bool),
    s: usize,
) {
    corners.load(grid, y, first, s);
    let Corners {
        nw,
        ne,
        sw,
        se,
        centre,
    } = &*corners;
    let (ne, sw, se, c) = (&ne[..], &sw[..], &se[..], &centre[..]);
    out.a.fill(0.0);
    for b in &mut out.b {
        b.fill(0.0);
    }
    let inv = 1.0 / s as f32;
    for j in 0..=s {
        let v = j as f32 * inv;
        for i in 0..=s {
            let u = i as f32 * inv;
            let on_side = i == 0 || i == s || j == 0 || j == s;
            let on_diagonal = i == j || i + j == s;
            if on_side && on_diagonal {
                continue; // a corner: on every plane
            }
            let h = grid.column(y + j, first + i);
            if !on_side {
                // A(s): plane - nw = alpha (ne - nw) + beta (sw - nw) + gamma (se - nw).
                let a_terms = if nw_se {
                    if i >= j {
                        [(u - v, ne), (0.0, sw), (v, se)]
                    } else {
                        [(0.0, ne), (v - u, sw), (u, se)]
                    }
                } else if i + j <= s {
                    [(u, ne), (v, sw), (0.0, se)]
                } else {
                    [(1.0 - v, ne), (1.0 - u, sw), (u + v - 1.0, se)]
                };
                accumulate(&mut out.a, h, nw, a_terms);
            }
            if on_diagonal {
                continue;
            }
            // B(s): the one triangle around the centre that holds (i, j).
            let (which, terms) = if j < i && j < s - i {
                (NORTH, [(u - v, ne), (2.0 * v, c), (0.0, se)])
            } else if j > i && j > s - i {
                (SOUTH, [(v - u, sw), (u + v - 1.0, se), (2.0 - 2.0 * v, c)])
            } else if i < j {
                (WEST, [(v - u, sw), (2.0 * u, c), (0.0, se)])
            } else {
                (EAST, [(u - v, ne), (u + v - 1.0, se), (2.0 - 2.0 * u, c)])
            };
            accumulate(&mut out.b[which], h, nw, terms);
        }
    }
}

/// Level 2, directly on the grid: a B(2) triangle holds one sample off its corners, the
/// midpoint of its hypotenuse, and an A(2) square one more, its centre.
pub(super) fn level_two(h: &[f32], side: usize, errors: &mut [f32]) {
    let n = side - 1;
    let mut line = vec![0.0f32; side];
    for y in 0..side {
        let row = &h[y * side..(y + 1) * side];
        let out = &mut errors[y * side..(y + 1) * side];
        if y % 2 == 0 {
            // Midpoints of horizontal sides (odd x) against their side.
            for (l, w) in line[1..n].iter_mut().zip(row.windows(3)) {
                *l = (w[1] - (w[0] + w[2]) * 0.5).abs();
            }
            for x in (1..n).step_by(2) {
                out[x] = line[x];
            }
        } else {
            // Midpoints of vertical sides (even x) against their side; odd x are A(2)
            // centres, set below.
            let (above, below) = (
                &h[(y - 1) * side..y * side],
                &h[(y + 1) * side..(y + 2) * side],
            );
            for (((e, &c), &a), &b) in out.iter_mut().zip(row).zip(above).zip(below) {
                *e = (c - (a + b) * 0.5).abs();
            }
        }
    }
    for y in (1..n).step_by(2) {
        for x in (1..n).step_by(2) {
            let at = y * side + x;
            let nw_se = ((x / 2) + (y / 2)).is_multiple_of(2);
            let (a, b) = if nw_se {
                (h[at - side - 1], h[at + side + 1])
            } else {
                (h[at - side + 1], h[at + side - 1])
            };
            let mut e = (h[at] - (a + b) * 0.5).abs();
            for child in [at - 1, at + 1, at - side, at + side] {
                e = larger(e, errors[child]);
            }
            errors[at] = e;
        }
    }
}

/// Per-square errors of level `s` (`4 <= s < n`) across squares.
pub(super) fn across_squares(h: &[f32], side: usize, s: usize, scratch: &mut Scratch) {
    let squares = (side - 1) / s;
    if !scratch.phased_filled {
        let period = (2 * ACROSS_SQUARES_UP_TO).min(side - 1);
        scratch.phased.fill(h, side, period);
        scratch.phased_filled = true;
    }
    scratch.prepare(squares);
    let grid = &scratch.phased;
    let (runs, sets) = (grid.runs, grid.period / s);
    scratch
        .a
        .par_chunks_mut(squares)
        .zip(scratch.b.par_chunks_mut(squares))
        .enumerate()
        .with_min_len(min_rows(squares, s))
        .for_each_init(
            || {
                let zeros = || vec![0.0f32; runs];
                (
                    Corners::new(runs),
                    RowErrors {
                        a: zeros(),
                        b: [zeros(), zeros(), zeros(), zeros()],
                    },
                )
            },
            |(corners, row), (row_index, (a_out, b_out))| {
                for set in 0..sets {
                    // Sets alternate diagonals, as squares do (`sets` is even).
                    let nw_se = (row_index + set).is_multiple_of(2);
                    square_row(grid, corners, row, (row_index * s, set * s, nw_se), s);
                    for q in 0..runs {
                        let k = sets * q + set;
                        a_out[k] = row.a[q];
                        b_out[k] = [
                            row.b[NORTH][q],
                            row.b[SOUTH][q],
                            row.b[WEST][q],
                            row.b[EAST][q],
                        ];
                    }
                }
            },
        );
}

/// Per-square errors of level `s` along rows: A halves and the north and south B triangles
/// on the grid, the west and east ones as north and south of the transposed grid, so every
/// triangle is scanned along its long rows.
pub(super) fn along_rows(h: &[f32], side: usize, s: usize, scratch: &mut Scratch) {
    let squares = (side - 1) / s;
    if !scratch.transposed {
        transpose(h, side, &mut scratch.columns);
        scratch.transposed = true;
    }
    scratch.prepare(squares);
    let columns = &scratch.columns[..];
    scratch
        .a
        .par_chunks_mut(squares)
        .zip(scratch.b.par_chunks_mut(squares))
        .enumerate()
        .with_min_len(min_rows(squares, s))
        .for_each(|(row_index, (a_out, b_out))| {
            let y = row_index * s;
            for (col, (a, b)) in a_out.iter_mut().zip(b_out.iter_mut()).enumerate() {
                let x = col * s;
                let nw_se = (row_index + col).is_multiple_of(2);
                *a = halves(h, side, (x, y), s, nw_se);
                let [north, south] = north_south(h, side, (x, y), s);
                let [west, east] = north_south(columns, side, (y, x), s);
                *b = [north, south, west, east];
            }
        });
}

/// Writes `h` transposed into `columns`, in 8 x 8 blocks held in registers, so reads and
/// writes are both runs of eight.
fn transpose(h: &[f32], side: usize, columns: &mut Vec<f32>) {
    const BLOCK: usize = 8;
    columns.resize(side * side, 0.0);
    let full = side / BLOCK * BLOCK;
    for y0 in (0..full).step_by(BLOCK) {
        for x0 in (0..full).step_by(BLOCK) {
            let mut block = [[0.0f32; BLOCK]; BLOCK];
            for (r, row) in block.iter_mut().enumerate() {
                row.copy_from_slice(&h[(y0 + r) * side + x0..][..BLOCK]);
            }
            for c in 0..BLOCK {
                let out = &mut columns[(x0 + c) * side + y0..][..BLOCK];
                for (o, row) in out.iter_mut().zip(&block) {
                    *o = row[c];
                }
            }
        }
    }
    // The rows and columns past the last whole block.
    for y in 0..side {
        for x in full..side {
            columns[x * side + y] = h[y * side + x];
            columns[y * side + x] = h[x * side + y];
        }
    }
}

/// A plane over a square as its value at `(0, k)` and its slopes: `p0 + gx i + gy k`.
#[derive(Clone, Copy)]
pub(super) struct Plane {
    pub(super) p0: f32,
    pub(super) gx: f32,
    pub(super) gy: f32,
}

impl Plane {
    /// `max |h - plane|` over columns `i0..=i1` of the square's row `k`.
    #[inline(always)]
    pub(super) fn deviation(self, row: &[f32], k: usize, (i0, i1): (usize, usize)) -> f32 {
        let start = self.p0 + self.gy * k as f32 + self.gx * i0 as f32;
        row_deviation(&row[i0..=i1], start, self.gx)
    }
}

/// Corner heights of the s-square at `(x, y)`: NW, NE, SW, SE, centre.
#[inline(always)]
pub(super) fn corners(h: &[f32], side: usize, (x, y): (usize, usize), s: usize) -> [f32; 5] {
    let at = |i: usize, k: usize| h[(y + k) * side + x + i];
    [at(0, 0), at(s, 0), at(0, s), at(s, s), at(s / 2, s / 2)]
}

/// The planes of the s-square's two A(s) halves from its corners: with the NW-SE diagonal
/// (`nw_se`), lower left (NW, SW, SE) then upper right (NW, NE, SE); with the NE-SW one,
/// upper left (NW, NE, SW) then lower right (NE, SW, SE).
#[inline(always)]
pub(super) fn half_planes([nw, ne, sw, se, _]: [f32; 5], s: usize, nw_se: bool) -> [Plane; 2] {
    let inv = 1.0 / s as f32;
    let plane = |p0, gx, gy| Plane { p0, gx, gy };
    if nw_se {
        [
            plane(nw, (se - sw) * inv, (sw - nw) * inv),
            plane(nw, (ne - nw) * inv, (se - ne) * inv),
        ]
    } else {
        [
            plane(nw, (ne - nw) * inv, (sw - nw) * inv),
            plane(sw + ne - se, (se - sw) * inv, (se - ne) * inv),
        ]
    }
}

/// The planes of the s-square's B(s) triangles north and south of its centre, from its
/// corners (the west and east ones are these on the transposed grid).
#[inline(always)]
pub(super) fn north_south_planes([nw, ne, sw, se, c]: [f32; 5], s: usize) -> [Plane; 2] {
    let inv = 1.0 / s as f32;
    [
        Plane {
            p0: nw,
            gx: (ne - nw) * inv,
            gy: (2.0 * c - nw - ne) * inv,
        },
        Plane {
            p0: 2.0 * c - se,
            gx: (se - sw) * inv,
            gy: (sw + se - 2.0 * c) * inv,
        },
    ]
}

/// The A(s) error of the s-square at `(x, y)`, both halves, over its interior rows.
fn halves(h: &[f32], side: usize, (x, y): (usize, usize), s: usize, nw_se: bool) -> f32 {
    let [first, second] = half_planes(corners(h, side, (x, y), s), s, nw_se);
    let mut worst = 0.0f32;
    for k in 1..s {
        let row = &h[(y + k) * side + x..=(y + k) * side + x + s];
        // The diagonal sample belongs to both halves.
        let cut = if nw_se { k } else { s - k };
        worst = larger(worst, first.deviation(row, k, (1, cut)));
        worst = larger(worst, second.deviation(row, k, (cut, s - 1)));
    }
    worst
}

/// The errors of the B(s) triangles on the north and south sides of the s-square at
/// `(x, y)`, over their hypotenuse and interior.
fn north_south(h: &[f32], side: usize, (x, y): (usize, usize), s: usize) -> [f32; 2] {
    let [north, south] = north_south_planes(corners(h, side, (x, y), s), s);
    let half = s / 2;
    let row = |k: usize| &h[(y + k) * side + x..=(y + k) * side + x + s];
    let (mut n, mut so) = (0.0f32, 0.0f32);
    for k in 0..half {
        n = larger(n, north.deviation(row(k), k, (k + 1, s - k - 1)));
        let k = s - k;
        so = larger(so, south.deviation(row(k), k, (s - k + 1, k - 1)));
    }
    [n, so]
}

/// Stores level `s` from the per-square errors: B(s) values at the side midpoints, then A(s)
/// values at the square centres, each with its children's values.
pub(super) fn combine(errors: &mut [f32], a: &[f32], b: &[[f32; 4]], side: usize, s: usize) {
    let squares = (side - 1) / s;
    let (half, quarter) = (s / 2, s / 4);
    let at = |x: usize, y: usize| y * side + x;
    let square = |col: usize, row: usize| row * squares + col;
    // B(s): horizontal sides get the south triangle of the square above and the north one of
    // the square below; vertical sides the east one of the square left and the west one of
    // the square right; then their children, the A(s/2) centres beside the midpoint.
    for row in 0..=squares {
        let y = row * s;
        for col in 0..squares {
            let x = col * s;
            let mut e = 0.0f32;
            if row > 0 {
                e = larger(e, b[square(col, row - 1)][SOUTH]);
            }
            if row < squares {
                e = larger(e, b[square(col, row)][NORTH]);
            }
            if quarter > 0 {
                for cx in [x + quarter, x + half + quarter] {
                    if row > 0 {
                        e = larger(e, errors[at(cx, y - quarter)]);
                    }
                    if row < squares {
                        e = larger(e, errors[at(cx, y + quarter)]);
                    }
                }
            }
            errors[at(x + half, y)] = e;
        }
    }
    for row in 0..squares {
        let y = row * s;
        for col in 0..=squares {
            let x = col * s;
            let mut e = 0.0f32;
            if col > 0 {
                e = larger(e, b[square(col - 1, row)][EAST]);
            }
            if col < squares {
                e = larger(e, b[square(col, row)][WEST]);
            }
            if quarter > 0 {
                for cy in [y + quarter, y + half + quarter] {
                    if col > 0 {
                        e = larger(e, errors[at(x - quarter, cy)]);
                    }
                    if col < squares {
                        e = larger(e, errors[at(x + quarter, cy)]);
                    }
                }
            }
            errors[at(x, y + half)] = e;
        }
    }
    // A(s): the centre gets both halves and its four side midpoints (the B(s) just stored).
    for row in 0..squares {
        let y = row * s;
        for col in 0..squares {
            let x = col * s;
            let mut e = a[square(col, row)];
            for (cx, cy) in [
                (x + half, y),
                (x + half, y + s),
                (x, y + half),
                (x + s, y + half),
            ] {
                e = larger(e, errors[at(cx, cy)]);
            }
            errors[at(x + half, y + half)] = e;
        }
    }
}
