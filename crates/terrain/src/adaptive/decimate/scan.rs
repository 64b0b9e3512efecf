//! Whether a triangle holds the bound: every grid sample inside or on it within the bound of
//! its plane. The inner loop of the decimator.
//!
//! The exact scan ([`scan_exact`], f64) is slow per sample; [`Scanner::holds`] does the same in
//! f32 lanes ([`row_deviation`]) over row spans walked incrementally (no division per row),
//! gives up at the first row beyond the bound, and only falls back on the exact scan when the
//! f32 value lies so close to the bound that its rounding could put it on the wrong side. So
//! every answer is the exact one.

use std::hint::select_unpredictable;

use super::orient;
use crate::adaptive::HeightGrid;
use crate::adaptive::rows::row_deviation;

/// Scans triangles of one grid against one bound.
pub(super) struct Scanner<'a> {
    grid: &'a HeightGrid,
    limit: f32,
    /// How far an f32 distance may be from the exact one.
    slack: f32,
}

impl<'a> Scanner<'a> {
    pub(super) fn new(grid: &'a HeightGrid, limit: f32) -> Self {
        let highest = grid.heights().iter().fold(1.0f32, |m, h| m.max(h.abs()));
        Self {
            grid,
            limit,
            // A plane value is a convex combination of corner heights (at most `highest`),
            // formed from a rounded start and step times at most the side; a few ulps of twice
            // the largest height bound the difference, 32 with room to spare.
            slack: 32.0 * f32::EPSILON * highest,
        }
    }

    /// The grid scanned.
    pub(super) fn grid(&self) -> &'a HeightGrid {
        self.grid
    }

    /// Whether every sample of triangle `p` is within the bound of its plane (a degenerate
    /// triangle holds). `known[i]`: the samples on the edge opposite corner `i` are known to
    /// hold (the edge belongs to a triangle that held; along an edge every triangle's plane
    /// is the same line), so they may be skipped.
    pub(super) fn holds(&self, p: [[u16; 2]; 3], known: [bool; 3]) -> bool {
        let xs = p.map(|[x, _]| i64::from(x));
        let ys = p.map(|[_, y]| i64::from(y));
        let (left, right) = (xs[0].min(xs[1]).min(xs[2]), xs[0].max(xs[1]).max(xs[2]));
        let (top, bottom) = (ys[0].min(ys[1]).min(ys[2]), ys[0].max(ys[1]).max(ys[2]));
        if (right - left + 1) * (bottom - top + 1) <= TINY {
            return self.holds_tiny(p, [left, right, top, bottom], known);
        }
        let worst = scan_fast(self.grid, p, self.limit + self.slack);
        if worst > self.limit + self.slack {
            return false;
        }
        worst <= self.limit - self.slack || scan_exact(self.grid, p) <= self.limit
    }

    /// [`Scanner::holds`] sample by sample over the bounding box `[left, right, top, bottom]`,
    /// exactly (f64): for triangles so small that setting up row spans costs more than the
    /// samples (most ears at fine bounds have three to six samples, corners included). The
    /// loop has no data-dependent branch: whether a sample is inside varies from sample to
    /// sample, and mispredicting it had cost more than evaluating every sample of the box.
    fn holds_tiny(&self, p: [[u16; 2]; 3], bbox: [i64; 4], known: [bool; 3]) -> bool {
        let Some((w, area)) = edges(p) else {
            return true;
        };
        let [left, right, top, bottom] = bbox;
        let z = p.map(|[x, y]| f64::from(self.grid.at(usize::from(x), usize::from(y))));
        let (side, h) = (self.grid.side(), self.grid.heights());
        let inv = 1.0 / area as f64;
        let plane_at =
            |e: [i64; 3]| (e[0] as f64 * z[0] + e[1] as f64 * z[1] + e[2] as f64 * z[2]) * inv;
        // Along a row the edge functions step by their x coefficients and the plane by its
        // east slope.
        let step = w.map(|(a, _, _)| a);
        let dz_dx = plane_at(step);
        // A known edge's samples count as outside: its function must be above zero there.
        let floor = known.map(i64::from);
        let mut beyond = false;
        for y in top..=bottom {
            let row = &h[y as usize * side..][..side];
            let mut e = w.map(|(a, b, c)| a * left + b * y + c);
            let mut plane = plane_at(e);
            for &height in &row[left as usize..=right as usize] {
                let inside = (e[0] - floor[0]) | (e[1] - floor[1]) | (e[2] - floor[2]) >= 0;
                let d = (f64::from(height) - plane).abs() as f32;
                beyond |= inside & (d > self.limit);
                for k in 0..3 {
                    e[k] += step[k];
                }
                plane += dz_dx;
            }
        }
        !beyond
    }
}

/// Triangles whose bounding box holds at most this many samples go through
/// [`Scanner::holds_tiny`] (32: the fewest instructions on the tiles of
/// `tools/compare-meshers.py`, counted by valgrind; 24-64 are within 1 %).
const TINY: i64 = 32;

/// One edge's bound on a row's samples, `a x + (b y + c) >= 0`, stepped row by row:
/// `floor((b y + c) / |a|)` kept as quotient and remainder.
///
/// Without branches: which kind of bound an edge is varies from edge to edge and a carry
/// from row to row, and mispredicting them had been a tenth of the decimator's branch
/// misses (cachegrind, srtm 5 m), so both are selects the compiler must not turn into
/// branches ([`select_unpredictable`]).
#[derive(Clone, Copy)]
struct EdgeWalk {
    /// `|a|`.
    den: i64,
    /// The edge bounds x from below (`a > 0`), else from above.
    lower: bool,
    quotient: i64,
    remainder: i64,
    step_quotient: i64,
    step_remainder: i64,
}

impl EdgeWalk {
    /// An edge that bounds nothing: a horizontal one (every row from the triangle's top to
    /// its bottom is on its inner side), or any for triangles whose spans come from
    /// [`EdgeFunctions`] directly. A lower bound of `-i64::MAX`.
    const IDLE: Self = Self {
        den: 1,
        lower: true,
        quotient: i64::MAX,
        remainder: 0,
        step_quotient: 0,
        step_remainder: 0,
    };

    fn new(a: i64, b: i64, c: i64, y: i64) -> Self {
        if a == 0 {
            return Self::IDLE;
        }
        let den = a.abs();
        let (quotient, remainder) = floor_div(b * y + c, den);
        let (step_quotient, step_remainder) = floor_div(b, den);
        Self {
            den,
            lower: a > 0,
            quotient,
            remainder,
            step_quotient,
            step_remainder,
        }
    }

    /// Narrows `[lo, hi]` to the samples of this row on the inner side (`hi` below `lo`
    /// if none).
    #[inline(always)]
    fn clip(&self, lo: &mut i64, hi: &mut i64) {
        let q = self.quotient;
        // Lower: a x >= -rest  <=>  x >= ceil(-rest / a) = -floor(rest / a).
        let least = select_unpredictable(self.lower, -q, i64::MIN);
        // Upper: |a| x <= rest  <=>  x <= floor(rest / |a|).
        let most = select_unpredictable(self.lower, i64::MAX, q);
        *lo = (*lo).max(least);
        *hi = (*hi).min(most);
    }

    #[inline(always)]
    fn next_row(&mut self) {
        self.quotient += self.step_quotient;
        self.remainder += self.step_remainder;
        let carry = self.remainder >= self.den;
        self.remainder -= select_unpredictable(carry, self.den, 0);
        self.quotient += select_unpredictable(carry, 1, 0);
    }
}

/// `(floor(n / d), n - d floor(n / d))` for `d > 0`, with one division.
#[inline(always)]
fn floor_div(n: i64, d: i64) -> (i64, i64) {
    let (q, r) = (n / d, n % d);
    let negative = r < 0;
    (
        q - select_unpredictable(negative, 1, 0),
        r + select_unpredictable(negative, d, 0),
    )
}

/// The rows of a triangle and the span of samples inside or on it in each, `(y, lo, hi)`
/// (inclusive), top to bottom, skipping empty rows.
struct Spans {
    walks: [EdgeWalk; 3],
    /// The edge functions themselves, for narrow triangles (`walks` unused).
    direct: Option<EdgeFunctions>,
    y: i64,
    bottom: i64,
    left: i64,
    right: i64,
}

/// Triangles at most this many columns wide find their spans by testing every column (three
/// additions each) rather than walking edges (divisions to set up).
const DIRECT_WIDTH: i64 = 6;

impl Spans {
    fn new(p: [[u16; 2]; 3], w: &EdgeFunctions) -> Self {
        let ys = p.map(|[_, y]| i64::from(y));
        let xs = p.map(|[x, _]| i64::from(x));
        let top = ys[0].min(ys[1]).min(ys[2]);
        let (left, right) = (xs[0].min(xs[1]).min(xs[2]), xs[0].max(xs[1]).max(xs[2]));
        let direct = right - left <= DIRECT_WIDTH;
        Self {
            walks: if direct {
                [EdgeWalk::IDLE; 3]
            } else {
                w.map(|(a, b, c)| EdgeWalk::new(a, b, c, top))
            },
            direct: direct.then_some(*w),
            y: top,
            bottom: ys[0].max(ys[1]).max(ys[2]),
            left,
            right,
        }
    }
}

impl Iterator for Spans {
    type Item = (i64, i64, i64);

    #[inline(always)]
    fn next(&mut self) -> Option<Self::Item> {
        while self.y <= self.bottom {
            let y = self.y;
            self.y += 1;
            let (mut lo, mut hi) = (self.left, self.right);
            if let Some(w) = &self.direct {
                let inside = |x: i64| w.iter().all(|&(a, b, c)| a * x + b * y + c >= 0);
                while lo <= hi && !inside(lo) {
                    lo += 1;
                }
                while hi >= lo && !inside(hi) {
                    hi -= 1;
                }
            } else {
                for walk in &mut self.walks {
                    walk.clip(&mut lo, &mut hi);
                    walk.next_row();
                }
            }
            if lo <= hi {
                return Some((y, lo, hi));
            }
        }
        None
    }
}

/// `(a, b, c)` per edge: `a x + b y + c >= 0` on the inner side.
type EdgeFunctions = [(i64, i64, i64); 3];

/// The inner-side test of the three edges of `p`: `(a, b, c)` with `a x + b y + c >= 0` inside
/// or on the edge opposite each vertex, twice the area, and its sign.
fn edges(p: [[u16; 2]; 3]) -> Option<(EdgeFunctions, i64)> {
    let area = orient(p[0], p[1], p[2]);
    if area == 0 {
        return None;
    }
    let s = area.signum();
    let q = p.map(|[x, y]| [i64::from(x), i64::from(y)]);
    let coeff = |i: usize, j: usize| {
        let (a, b) = (q[i], q[j]);
        let (ca, cb) = (-s * (b[1] - a[1]), s * (b[0] - a[0]));
        (ca, cb, -(ca * a[0] + cb * a[1]))
    };
    Some(([coeff(1, 2), coeff(2, 0), coeff(0, 1)], area * s))
}

/// A proper triangle's edge functions, corner heights, `1 / (2 area)` and east slope.
struct Plane {
    w: EdgeFunctions,
    z: [f64; 3],
    inv: f64,
    dz_dx: f64,
}

impl Plane {
    fn new(grid: &HeightGrid, p: [[u16; 2]; 3]) -> Option<Self> {
        let (w, area) = edges(p)?;
        let z = p.map(|[x, y]| f64::from(grid.at(usize::from(x), usize::from(y))));
        let inv = 1.0 / area as f64;
        let dz_dx = (w[0].0 as f64 * z[0] + w[1].0 as f64 * z[1] + w[2].0 as f64 * z[2]) * inv;
        Some(Self { w, z, inv, dz_dx })
    }
}

/// Approximate (f32) largest distance of triangle `p`'s samples from its plane; stops at the
/// first row whose largest distance exceeds `stop`.
fn scan_fast(grid: &HeightGrid, p: [[u16; 2]; 3], stop: f32) -> f32 {
    let Some(plane) = Plane::new(grid, p) else {
        return 0.0;
    };
    let Plane { w, z, dz_dx, .. } = plane;
    let (side, h) = (grid.side(), grid.heights());
    let dz_dy = (w[0].1 as f64 * z[0] + w[1].1 as f64 * z[1] + w[2].1 as f64 * z[2]) * plane.inv;
    let [x0, y0] = p[0].map(i64::from);
    let step = dz_dx as f32;
    let mut worst = 0.0f32;
    for (y, lo, hi) in Spans::new(p, &w) {
        let start = (z[0] + dz_dx * (lo - x0) as f64 + dz_dy * (y - y0) as f64) as f32;
        let base = y as usize * side;
        let row = &h[base + lo as usize..=base + hi as usize];
        worst = worst.max(row_deviation(row, start, step));
        if worst > stop {
            break;
        }
    }
    worst
}

/// The exact largest |height - plane| over the samples in triangle `p` (f64).
fn scan_exact(grid: &HeightGrid, p: [[u16; 2]; 3]) -> f32 {
    let Some(Plane { w, z, inv, dz_dx }) = Plane::new(grid, p) else {
        return 0.0;
    };
    let (side, h) = (grid.side(), grid.heights());
    let mut worst = 0.0f32;
    for (y, lo, hi) in Spans::new(p, &w) {
        let wl: f64 = w
            .iter()
            .zip(&z)
            .map(|(&(a, b, c), &zk)| (a * lo + b * y + c) as f64 * zk)
            .sum();
        let start = wl * inv;
        let row = &h[y as usize * side + lo as usize..=y as usize * side + hi as usize];
        for (k, &v) in row.iter().enumerate() {
            worst = worst.max((f64::from(v) - (start + dz_dx * k as f64)).abs() as f32);
        }
    }
    worst
}

#[cfg(test)]
mod tests {
    use super::*;
    use crate::adaptive::test_grids::rough;
    use proptest::prelude::*;

    /// Every sample inside or on triangle `p`, by the edge functions at each sample.
    fn brute(grid: &HeightGrid, p: [[u16; 2]; 3]) -> (f32, usize) {
        let Some((w, area)) = edges(p) else {
            return (0.0, 0);
        };
        let z = p.map(|[x, y]| f64::from(grid.at(usize::from(x), usize::from(y))));
        let (mut worst, mut count) = (0.0f32, 0);
        for y in 0..grid.side() as i64 {
            for x in 0..grid.side() as i64 {
                let e = w.map(|(a, b, c)| a * x + b * y + c);
                if e.iter().all(|&e| e >= 0) {
                    count += 1;
                    let plane = (0..3).map(|k| e[k] as f64 * z[k]).sum::<f64>() / area as f64;
                    let d = (f64::from(grid.at(x as usize, y as usize)) - plane).abs() as f32;
                    worst = worst.max(d);
                }
            }
        }
        (worst, count)
    }

    proptest! {
        #![proptest_config(ProptestConfig::with_cases(256))]
        #[test]
        fn scans_see_exactly_the_samples_inside_and_agree_on_the_bound(
            seed in any::<u32>(),
            c in prop::array::uniform6(0u16..=32),
            limit in 0.0f32..40.0,
        ) {
            let grid = rough(33, seed, 300.0);
            let p = [[c[0], c[1]], [c[2], c[3]], [c[4], c[5]]];
            let (truth, inside) = brute(&grid, p);
            let spanned: i64 = edges(p)
                .map_or(0, |(w, _)| Spans::new(p, &w).map(|(_, lo, hi)| hi - lo + 1).sum());
            prop_assert_eq!(spanned as usize, inside);
            let exact = scan_exact(&grid, p);
            prop_assert!((exact - truth).abs() <= 1e-4, "{exact} vs {truth}");
            let fast = scan_fast(&grid, p, f32::INFINITY);
            let scanner = Scanner::new(&grid, limit);
            prop_assert!((fast - exact).abs() <= scanner.slack, "{fast} vs {exact}");
            let holds = |limit: f32| Scanner::new(&grid, limit).holds(p, [false; 3]);
            let span = |i: usize| c[i].max(c[i + 2]).max(c[i + 4]) - c[i].min(c[i + 2]).min(c[i + 4]);
            if i64::from(span(0) + 1) * i64::from(span(1) + 1) > TINY {
                // Bounds at the triangle's own error and a hair either side take the exact
                // path, which is `exact` itself.
                for limit in [limit, exact, exact.next_down().max(0.0), exact.next_up()] {
                    prop_assert_eq!(holds(limit), exact <= limit, "bound {}, error {}", limit, exact);
                }
            } else {
                // Sample by sample: the same f64 values, up to their rounding.
                prop_assert!(holds(exact + 1e-3), "error {}", exact);
                if exact > 1e-3 {
                    prop_assert!(!holds(exact - 1e-3), "error {}", exact);
                }
            }
        }

        /// Small triangles, sample by sample, with some edges known to hold: exactly the
        /// samples off those edges decide.
        #[test]
        fn small_triangles_skip_only_the_known_edges(
            seed in any::<u32>(),
            origin in prop::array::uniform2(0u16..=26),
            c in prop::array::uniform6(0u16..=6),
            known in prop::array::uniform3(any::<bool>()),
        ) {
            let grid = rough(33, seed, 300.0);
            let p = [[c[0], c[1]], [c[2], c[3]], [c[4], c[5]]]
                .map(|[x, y]| [origin[0] + x, origin[1] + y]);
            let xs = p.map(|[x, _]| i64::from(x));
            let ys = p.map(|[_, y]| i64::from(y));
            let bbox = [
                xs.iter().copied().min().unwrap_or(0),
                xs.iter().copied().max().unwrap_or(0),
                ys.iter().copied().min().unwrap_or(0),
                ys.iter().copied().max().unwrap_or(0),
            ];
            let Some((w, area)) = edges(p) else {
                prop_assert!(Scanner::new(&grid, 0.0).holds_tiny(p, bbox, known));
                return Ok(());
            };
            let z = p.map(|[x, y]| f64::from(grid.at(usize::from(x), usize::from(y))));
            let mut worst = 0.0f32;
            for y in 0..33i64 {
                for x in 0..33i64 {
                    let e = w.map(|(a, b, c)| a * x + b * y + c);
                    let on_known = (0..3).any(|i| known[i] && e[i] == 0);
                    if e.iter().all(|&e| e >= 0) && !on_known {
                        let plane = (0..3).map(|k| e[k] as f64 * z[k]).sum::<f64>() / area as f64;
                        let d = (f64::from(grid.at(x as usize, y as usize)) - plane).abs();
                        worst = worst.max(d as f32);
                    }
                }
            }
            let holds = |limit: f32| Scanner::new(&grid, limit).holds_tiny(p, bbox, known);
            prop_assert!(holds(worst + 1e-3), "error {}", worst);
            if worst > 1e-3 {
                prop_assert!(!holds(worst - 1e-3), "error {}", worst);
            }
        }
    }
}
