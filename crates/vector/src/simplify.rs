//! Lines at every level of detail from one ranking of their vertices, so a tile draws a line
//! with as many segments as its size on screen can show, whatever the line's length.
//!
//! Why this technique. A draped line is cut into every drawn tile it crosses. Drawn whole, a
//! line of a million vertices costs a million instances in a tile that covers it on a few
//! hundred pixels, and is scanned whole by every tile under its bounds. Vector-tile
//! pipelines (geojson-vt, tippecanoe) simplify each feature once per zoom level with
//! Douglas-Peucker; here the levels are the terrain's tiles, which come and go every frame,
//! so the line is ranked once instead: each vertex gets the tolerance below which
//! Douglas-Peucker keeps it (its distance from the chord of the interval it splits, capped
//! by the interval's own rank, so the vertices kept at any tolerance are exactly those
//! Douglas-Peucker keeps: every dropped vertex lies within the tolerance of the segment
//! drawn over it). A tile then reads only the blocks of vertices near it ([`LineIndex`]
//! keeps their bounds and largest rank) and keeps the vertices ranked above its tolerance.
//! The `geo` crate's `Simplify` gives one tolerance per call over the whole line; the
//! ranking and the block index are what a tile needs, hence this module.
//!
//! Distances are measured in degrees of latitude with longitude scaled by the largest cosine
//! of latitude over the dropped vertex and the chord that replaces it (a straight piece of
//! the tile's longitude/latitude plane stays straight under that scaling). The scale at the
//! vertex alone is not enough near a pole: there it vanishes, and a ring's corner at the pole
//! (Antarctica's runs along 90 S from 180 E to 180 W) measured nothing from a chord that
//! swept hundreds of kilometres across the ice, which left a spiral hole in the fill.
//!
//! Cost: ranking splits an interval at its farthest vertex, or at its middle where the
//! farthest is in the interval's outer eighths (the kept sets stay exact, only a little less
//! sparse), so no input takes more than `O(n log n)`.

use std::ops::Range;

/// Vertices per block of the index.
const BLOCK: usize = 64;

/// A polyline's vertices ranked for simplification, and the bounds of its blocks.
#[derive(Clone, Debug, Default)]
pub struct LineIndex {
    /// Per vertex, the largest tolerance (degrees of latitude) at which it is kept; the ends
    /// are kept at any.
    rank: Vec<f32>,
    blocks: Vec<Block>,
}

/// Vertices `k * BLOCK ..= (k + 1) * BLOCK` (the next block's first too, so every segment
/// lies in a block).
#[derive(Clone, Copy, Debug)]
struct Block {
    /// West, south, east, north, degrees.
    rect: [f64; 4],
    /// Largest rank of its own vertices (`k * BLOCK .. (k + 1) * BLOCK`).
    top: f32,
}

/// What a tile draws of a line: runs of vertex indices into the line.
#[derive(Clone, Debug, Default)]
pub struct Selection {
    /// Indices of the vertices kept, run after run.
    pub vertices: Vec<u32>,
    /// Runs, as ranges of `vertices`: each is a piece of the simplified line (at least two
    /// vertices) that comes near the rectangle.
    pub runs: Vec<Range<usize>>,
    /// The tolerance the vertices were kept at, degrees of latitude.
    pub tolerance: f64,
}

impl LineIndex {
    /// Ranks the vertices of `pts` (longitude, latitude in degrees; longitudes may be
    /// unwrapped) and indexes their blocks.
    pub fn new(pts: &[[f64; 2]]) -> Self {
        let n = pts.len();
        let mut rank = vec![0.0f32; n];
        if n == 0 {
            return Self::default();
        }
        rank[0] = f32::INFINITY;
        rank[n - 1] = f32::INFINITY;
        let cos: Vec<f64> = pts.iter().map(|p| p[1].to_radians().cos()).collect();
        let mut stack = vec![(0usize, n - 1, f32::INFINITY)];
        while let Some((a, b, cap)) = stack.pop() {
            if b < a + 2 {
                continue;
            }
            let (mut far, mut dmax2) = (a + 1, -1.0f64);
            for i in a + 1..b {
                let d2 = distance2(
                    pts[i],
                    pts[a],
                    pts[b],
                    scale(&pts[i], &pts[a], &pts[b], [cos[i], cos[a], cos[b]]),
                );
                if d2 > dmax2 {
                    (far, dmax2) = (i, d2);
                }
            }
            let dmax = dmax2.sqrt();
            let len = b - a;
            if len > 16 && (far < a + len / 8 || far > b - len / 8) {
                far = a + len / 2;
            }
            // Rounded up, so a vertex is never dropped at a tolerance it exceeds.
            let r = round_up(dmax).min(cap);
            rank[far] = r;
            stack.push((a, far, r));
            stack.push((far, b, r));
        }
        let blocks = (0..n.div_ceil(BLOCK))
            .map(|k| {
                let own = k * BLOCK..((k + 1) * BLOCK).min(n);
                let reach = k * BLOCK..((k + 1) * BLOCK + 1).min(n);
                let mut rect = [
                    f64::INFINITY,
                    f64::INFINITY,
                    f64::NEG_INFINITY,
                    f64::NEG_INFINITY,
                ];
                for p in &pts[reach] {
                    rect = [
                        rect[0].min(p[0]),
                        rect[1].min(p[1]),
                        rect[2].max(p[0]),
                        rect[3].max(p[1]),
                    ];
                }
                let top = rank[own].iter().copied().fold(0.0f32, f32::max);
                Block { rect, top }
            })
            .collect();
        Self { rank, blocks }
    }

    /// Vertices ranked.
    pub fn len(&self) -> usize {
        self.rank.len()
    }

    /// Whether it ranks no vertex.
    pub fn is_empty(&self) -> bool {
        self.rank.is_empty()
    }

    /// The largest tolerance (degrees of latitude) at which vertex `i` is kept.
    pub fn rank(&self, i: usize) -> f32 {
        self.rank[i]
    }

    /// The line simplified to at least `tolerance` (degrees of latitude), and further where
    /// more than about `max_vertices` would be kept near the rectangle `rect` (west, south,
    /// east, north, degrees, in the line's own longitudes): every segment of the simplified
    /// line that may cross `rect` is in one of the runs, with the vertices before and after.
    pub fn select(&self, rect: [f64; 4], tolerance: f64, max_vertices: usize, out: &mut Selection) {
        out.vertices.clear();
        out.runs.clear();
        out.tolerance = tolerance;
        let n = self.rank.len();
        if n < 2 {
            return;
        }
        // Blocks that come within the tolerance of the rectangle, as ranges of vertices;
        // the margin grows as the tolerance is raised, so it is set for the largest one the
        // budget can ask for (twice the tolerance of the coarsest vertex kept).
        let mut ranges: Vec<(usize, usize)> = Vec::new();
        let pass = |tol: f64, ranges: &mut Vec<(usize, usize)>| {
            ranges.clear();
            let [w, s, e, nn] = rect;
            let margin_lat = 2.0 * tol;
            let coslat = (s.abs().max(nn.abs()) + margin_lat)
                .min(90.0)
                .to_radians()
                .cos()
                .max(1e-3);
            let margin_lon = (margin_lat / coslat).min(360.0);
            for (k, b) in self.blocks.iter().enumerate() {
                let near = b.rect[0] <= e + margin_lon
                    && b.rect[2] >= w - margin_lon
                    && b.rect[1] <= nn + margin_lat
                    && b.rect[3] >= s - margin_lat;
                if !near {
                    continue;
                }
                let (v0, v1) = (k * BLOCK, ((k + 1) * BLOCK).min(n - 1));
                match ranges.last_mut() {
                    Some(last) if last.1 >= v0 => last.1 = v1,
                    _ => ranges.push((v0, v1)),
                }
            }
        };
        pass(tolerance, &mut ranges);
        let count = |tol: f32, ranges: &[(usize, usize)]| -> usize {
            ranges
                .iter()
                .map(|&(v0, v1)| self.rank[v0..=v1].iter().filter(|&&r| r > tol).count())
                .sum()
        };
        let mut tol = round_down(tolerance);
        if count(tol, &ranges) > max_vertices {
            // The budget's tolerance: the rank of the first vertex past it, best first.
            let mut ranks: Vec<f32> = ranges
                .iter()
                .flat_map(|&(v0, v1)| self.rank[v0..=v1].iter().copied())
                .filter(|&r| r > tol)
                .collect();
            let k = max_vertices.min(ranks.len() - 1);
            ranks.select_nth_unstable_by(k, |a, b| b.total_cmp(a));
            tol = ranks[k];
            out.tolerance = f64::from(tol);
            pass(out.tolerance, &mut ranges);
        }
        let mut end_of_last: Option<usize> = None;
        for &(v0, v1) in &ranges {
            let (start, end) = (
                self.kept_at_or_before(v0, tol),
                self.kept_at_or_after(v1, tol),
            );
            let from = match end_of_last {
                // The run before reaches into this one: carry it on.
                Some(last) if start <= last => last + 1,
                _ => {
                    if let Some(r) = out.runs.last_mut() {
                        r.end = out.vertices.len();
                    }
                    out.runs.push(out.vertices.len()..out.vertices.len());
                    start
                }
            };
            for i in from..=end {
                if self.rank[i] > tol {
                    out.vertices.push(i as u32);
                }
            }
            end_of_last = Some(end_of_last.map_or(end, |l| l.max(end)));
        }
        if let Some(r) = out.runs.last_mut() {
            r.end = out.vertices.len();
        }
        out.runs.retain(|r| r.len() >= 2);
    }

    /// The last vertex kept at `tol` at or before `i` (the first vertex is kept at any).
    fn kept_at_or_before(&self, mut i: usize, tol: f32) -> usize {
        loop {
            if self.rank[i] > tol {
                return i;
            }
            if i.is_multiple_of(BLOCK) {
                // Whole blocks before with nothing kept are stepped over.
                let mut k = i / BLOCK - 1;
                while self.blocks[k].top <= tol {
                    k -= 1;
                }
                i = (k + 1) * BLOCK;
            }
            i -= 1;
        }
    }

    /// The first vertex kept at `tol` at or after `i` (the last vertex is kept at any).
    fn kept_at_or_after(&self, mut i: usize, tol: f32) -> usize {
        loop {
            if self.rank[i] > tol {
                return i;
            }
            i += 1;
            if i.is_multiple_of(BLOCK) {
                let mut k = i / BLOCK;
                while self.blocks[k].top <= tol {
                    k += 1;
                }
                i = k * BLOCK;
            }
        }
    }
}

/// `x` as the nearest `f32` at least as large.
fn round_up(x: f64) -> f32 {
    let r = x as f32;
    if f64::from(r) < x { r.next_up() } else { r }
}

/// `x` as the nearest `f32` at most as large.
fn round_down(x: f64) -> f32 {
    let r = x as f32;
    if f64::from(r) > x { r.next_down() } else { r }
}

/// Distance of `p` from the segment `a`-`b` in degrees of latitude, longitudes scaled by the
/// largest cosine of latitude over `p` and the segment.
pub fn distance(p: [f64; 2], a: [f64; 2], b: [f64; 2]) -> f64 {
    let cos = [p, a, b].map(|q| q[1].to_radians().cos());
    distance2(p, a, b, scale(&p, &a, &b, cos)).sqrt()
}

/// The largest cosine of latitude over `p` and the segment `a`-`b` (given their cosines): 1
/// where they lie on both sides of the equator.
fn scale(p: &[f64; 2], a: &[f64; 2], b: &[f64; 2], cos: [f64; 3]) -> f64 {
    let lo = p[1].min(a[1]).min(b[1]);
    let hi = p[1].max(a[1]).max(b[1]);
    if lo <= 0.0 && hi >= 0.0 {
        1.0
    } else {
        cos[0].max(cos[1]).max(cos[2])
    }
}

/// The square of [`distance`], given the longitude scale `c`.
fn distance2(p: [f64; 2], a: [f64; 2], b: [f64; 2], c: f64) -> f64 {
    let a = [(a[0] - p[0]) * c, a[1] - p[1]];
    let b = [(b[0] - p[0]) * c, b[1] - p[1]];
    let d = [b[0] - a[0], b[1] - a[1]];
    let len2 = d[0] * d[0] + d[1] * d[1];
    let t = if len2 > 0.0 {
        (-(a[0] * d[0] + a[1] * d[1]) / len2).clamp(0.0, 1.0)
    } else {
        0.0
    };
    let (x, y) = (a[0] + d[0] * t, a[1] + d[1] * t);
    x * x + y * y
}

#[cfg(test)]
mod tests {
    use super::*;

    /// A random walk (deterministic), steps of about `step` degrees.
    fn walk(n: usize, step: f64, seed: u64) -> Vec<[f64; 2]> {
        let mut s = seed;
        let mut next = || {
            s = s
                .wrapping_mul(6364136223846793005)
                .wrapping_add(1442695040888963407);
            (s >> 11) as f64 / (1u64 << 53) as f64
        };
        let (mut lon, mut lat) = (7.0, 46.0);
        (0..n)
            .map(|_| {
                let a = next() * std::f64::consts::TAU;
                lon += step * a.cos();
                lat += step * a.sin();
                [lon, lat]
            })
            .collect()
    }

    /// Douglas-Peucker by the book, recursively: the vertices kept at `tol`.
    fn reference(pts: &[[f64; 2]], tol: f64) -> Vec<usize> {
        fn go(pts: &[[f64; 2]], a: usize, b: usize, tol: f64, out: &mut Vec<usize>) {
            let far = (a + 1..b)
                .map(|i| (i, distance(pts[i], pts[a], pts[b])))
                .max_by(|x, y| x.1.total_cmp(&y.1));
            if let Some((i, d)) = far
                && d > tol
            {
                go(pts, a, i, tol, out);
                out.push(i);
                go(pts, i, b, tol, out);
            }
        }
        let mut out = vec![0];
        go(pts, 0, pts.len() - 1, tol, &mut out);
        out.push(pts.len() - 1);
        out
    }

    fn kept(index: &LineIndex, tol: f64) -> Vec<usize> {
        (0..index.len())
            .filter(|&i| f64::from(index.rank(i)) > tol)
            .collect()
    }

    /// The largest distance of a dropped vertex from the kept segment over it.
    fn worst_dropped(pts: &[[f64; 2]], kept: &[usize]) -> f64 {
        kept.windows(2)
            .flat_map(|w| (w[0] + 1..w[1]).map(move |i| distance(pts[i], pts[w[0]], pts[w[1]])))
            .fold(0.0, f64::max)
    }

    /// A ring's corner at the pole is kept: the chord that would replace it sweeps across the
    /// polar cap, far from it everywhere but at the pole itself (Antarctica's ring runs along
    /// 90 S from 180 E to 180 W; dropping its corners left a spiral hole in the fill).
    #[test]
    fn a_corner_at_the_pole_is_kept() {
        let pts = [
            [150.0, -70.0],
            [170.0, -78.0],
            [180.0, -84.7],
            [180.0, -90.0],
            [-180.0, -90.0],
            [-180.0, -84.7],
            [-170.0, -78.0],
            [-150.0, -70.0],
        ];
        let index = LineIndex::new(&pts);
        for k in [3, 4] {
            assert!(index.rank(k) > 1.0, "corner {k}: rank {}", index.rank(k));
        }
        // The chord from the last coast vertex to the far pole corner passes 5 degrees of
        // latitude (at the coast's scale) from the near corner.
        assert!(distance(pts[3], pts[2], pts[4]) > 4.0);
        // Near the equator the scale is the plain one.
        assert!((distance([0.0, 1.0], [-1.0, 0.0], [1.0, 0.0]) - 1.0).abs() < 1e-12);
    }

    #[test]
    fn the_ranking_keeps_what_douglas_peucker_keeps() {
        // Short walks: the farthest vertex is always taken (no interval over 16 splits at
        // its middle unless the farthest is near an end, which the reference would not do,
        // so compare on walks of at most 17 vertices and on the bound for longer ones).
        for seed in 0..50 {
            let pts = walk(17, 0.01, seed);
            let index = LineIndex::new(&pts);
            for tol in [0.0, 0.002, 0.005, 0.01, 0.02, 0.05] {
                assert_eq!(
                    kept(&index, tol),
                    reference(&pts, tol),
                    "seed {seed} tol {tol}"
                );
            }
        }
    }

    #[test]
    fn every_dropped_vertex_lies_within_the_tolerance_of_its_segment() {
        let pts = walk(20_000, 0.002, 7);
        let index = LineIndex::new(&pts);
        let mut previous = usize::MAX;
        for tol in [0.0005, 0.001, 0.004, 0.016, 0.064, 0.25] {
            let k = kept(&index, tol);
            let worst = worst_dropped(&pts, &k);
            assert!(
                worst <= tol * (1.0 + 1e-6),
                "tol {tol}: a vertex {worst} off"
            );
            assert!(k.len() < previous, "tol {tol}: {} kept", k.len());
            previous = k.len();
            // Not much more than the book's own count.
            let book = reference(&pts, tol).len();
            assert!(
                k.len() as f64 <= book as f64 * 1.3 + 2.0,
                "tol {tol}: {} kept, Douglas-Peucker keeps {book}",
                k.len()
            );
        }
        // Collinear vertices go at any tolerance above rounding; the ends stay.
        let line: Vec<[f64; 2]> = (0..100).map(|i| [f64::from(i) * 0.01, 0.0]).collect();
        assert_eq!(kept(&LineIndex::new(&line), 1e-12), vec![0, 99]);
    }

    #[test]
    fn a_spiral_is_ranked_in_n_log_n() {
        // The farthest vertex from the chord of an outward spiral is always its last turn:
        // by the book every split peels off a few vertices, n^2 in all.
        let n = 200_000;
        let pts: Vec<[f64; 2]> = (0..n)
            .map(|i| {
                let t = i as f64 * 0.01;
                [t.cos() * t * 1e-3, t.sin() * t * 1e-3]
            })
            .collect();
        let index = LineIndex::new(&pts);
        let k = kept(&index, 1e-4);
        assert!(worst_dropped(&pts, &k) <= 1e-4 * (1.0 + 1e-6));
    }

    /// Segments of the simplified line that cross `rect` (by their bounding boxes).
    fn crossing(pts: &[[f64; 2]], kept: &[usize], rect: [f64; 4]) -> Vec<(usize, usize)> {
        kept.windows(2)
            .filter(|w| {
                let (a, b) = (pts[w[0]], pts[w[1]]);
                a[0].max(b[0]) >= rect[0]
                    && a[0].min(b[0]) <= rect[2]
                    && a[1].max(b[1]) >= rect[1]
                    && a[1].min(b[1]) <= rect[3]
            })
            .map(|w| (w[0], w[1]))
            .collect()
    }

    #[test]
    fn a_tile_gets_every_segment_that_crosses_it_and_little_else() {
        let pts = walk(100_000, 0.002, 3);
        let index = LineIndex::new(&pts);
        let mut sel = Selection::default();
        for (rect, tol) in [
            ([7.0, 46.0, 7.1, 46.1], 1e-4),
            ([6.5, 45.5, 7.5, 46.5], 1e-3),
            ([6.0, 45.0, 8.0, 47.0], 4e-3),
            ([0.0, 0.0, 1.0, 1.0], 1e-4),
        ] {
            index.select(rect, tol, usize::MAX, &mut sel);
            assert_eq!(sel.tolerance, tol);
            let all = kept(&index, tol);
            let mut segments = Vec::new();
            for r in &sel.runs {
                let v = &sel.vertices[r.clone()];
                assert!(v.len() >= 2);
                for w in v.windows(2) {
                    // Consecutive kept vertices of the whole line.
                    let at = all.binary_search(&(w[0] as usize)).expect("a kept vertex");
                    assert_eq!(all[at + 1], w[1] as usize);
                    segments.push((w[0] as usize, w[1] as usize));
                }
            }
            let want = crossing(&pts, &all, rect);
            for s in &want {
                assert!(segments.contains(s), "{rect:?}: segment {s:?} missing");
            }
            assert!(
                segments.len() <= want.len() * 3 + 64 * 4,
                "{rect:?}: {} segments for {} crossing",
                segments.len(),
                want.len()
            );
        }
    }

    #[test]
    fn a_budget_raises_the_tolerance_just_enough() {
        let pts = walk(100_000, 0.002, 5);
        let index = LineIndex::new(&pts);
        let mut sel = Selection::default();
        let rect = [6.0, 45.0, 8.0, 47.0];
        index.select(rect, 0.0, 4096, &mut sel);
        assert!(sel.tolerance > 0.0);
        assert!(
            sel.vertices.len() <= 4096 + 2 * sel.runs.len(),
            "{} vertices",
            sel.vertices.len()
        );
        assert!(sel.vertices.len() > 3000, "{} vertices", sel.vertices.len());
        // Still exact at its tolerance: what crosses is there.
        let all = kept(&index, sel.tolerance);
        let got: Vec<(usize, usize)> = sel
            .runs
            .iter()
            .flat_map(|r| {
                sel.vertices[r.clone()]
                    .windows(2)
                    .map(|w| (w[0] as usize, w[1] as usize))
                    .collect::<Vec<_>>()
            })
            .collect();
        for s in crossing(&pts, &all, rect) {
            assert!(got.contains(&s), "segment {s:?} missing");
        }
    }
}
