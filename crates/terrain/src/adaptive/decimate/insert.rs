//! Greedy Delaunay refinement on a half-edge mesh (the structure of `delaunator`: triangle
//! `t` owns half-edges `3t`, `3t + 1`, `3t + 2`; half-edge `e` runs from `tris[e]` to
//! `tris[next(e)]`; `twin[e]` is the opposite half-edge or [`NONE`] on the tile border).

use std::cmp::Ordering;
use std::collections::BinaryHeap;
use std::ops::{Add, Mul, Sub};

use super::orient;
use super::scan::{Scanner, Verdict};

const NONE: u32 = u32::MAX;

/// Inserts samples until the mesh is within the scanner's bound of its grid; returns the vertices and
/// the triangles (counter-clockwise from above).
pub(super) fn refine(scanner: &Scanner<'_>) -> (Vec<[u16; 2]>, Vec<[u32; 3]>) {
    let n = (scanner.grid().side() - 1) as u16;
    let mut r = Refiner {
        scanner,
        points: vec![[0, 0], [n, 0], [n, n], [0, n]],
        tris: Vec::new(),
        twin: Vec::new(),
        candidate: Vec::new(),
        version: Vec::new(),
        queue: BinaryHeap::new(),
        pending: Vec::new(),
        flips: Vec::new(),
        narrow: n < 4096,
    };
    // North-west to south-east diagonal, as RTIN; edge 0 -> 2 is half-edge 0 and 3.
    r.push_triangle([0, 2, 1]);
    r.push_triangle([2, 0, 3]);
    r.link(0, 3);
    r.rescan_pending();
    // Only triangles beyond the bound are queued.
    while let Some(Entry { tri, version, .. }) = r.queue.pop() {
        if r.version[tri as usize] != version {
            continue;
        }
        let p = r.candidate[tri as usize];
        r.insert(tri, p);
        r.rescan_pending();
    }
    let triangles = r.tris.chunks_exact(3).map(|t| [t[0], t[1], t[2]]).collect();
    (r.points, triangles)
}

#[derive(PartialEq)]
struct Entry {
    error: f32,
    tri: u32,
    version: u32,
}

impl Eq for Entry {}

impl PartialOrd for Entry {
    fn partial_cmp(&self, other: &Self) -> Option<Ordering> {
        Some(self.cmp(other))
    }
}

impl Ord for Entry {
    fn cmp(&self, other: &Self) -> Ordering {
        self.error
            .total_cmp(&other.error)
            .then_with(|| other.tri.cmp(&self.tri))
    }
}

struct Refiner<'a> {
    scanner: &'a Scanner<'a>,
    points: Vec<[u16; 2]>,
    tris: Vec<u32>,
    twin: Vec<u32>,
    candidate: Vec<[u16; 2]>,
    version: Vec<u32>,
    queue: BinaryHeap<Entry>,
    /// Triangles created or changed since the last rescan (a triangle flipped twice is
    /// here twice).
    pending: Vec<u32>,
    /// [`Refiner::legalize`]'s stack of edges to check, kept from insertion to insertion.
    flips: Vec<u32>,
    /// Coordinates below 4096: the in-circle test fits i64.
    narrow: bool,
}

fn next(e: u32) -> u32 {
    if e % 3 == 2 { e - 2 } else { e + 1 }
}

impl Refiner<'_> {
    fn push_triangle(&mut self, v: [u32; 3]) -> u32 {
        let t = (self.tris.len() / 3) as u32;
        self.tris.extend_from_slice(&v);
        self.twin.extend_from_slice(&[NONE; 3]);
        self.candidate.push([0, 0]);
        self.version.push(0);
        self.pending.push(t);
        t
    }

    /// Overwrites triangle `t` with vertices `v` and outer twins `o` (linked both ways).
    fn set_triangle(&mut self, t: u32, v: [u32; 3], o: [u32; 3]) {
        for k in 0..3 {
            let e = 3 * t + k as u32;
            self.tris[e as usize] = v[k];
            self.link(e, o[k]);
        }
        self.version[t as usize] += 1;
        self.pending.push(t);
    }

    fn new_triangle(&mut self, v: [u32; 3], o: [u32; 3]) -> u32 {
        let t = self.push_triangle(v);
        self.set_triangle(t, v, o);
        t
    }

    fn link(&mut self, a: u32, b: u32) {
        if a != NONE {
            self.twin[a as usize] = b;
        }
        if b != NONE {
            self.twin[b as usize] = a;
        }
    }

    fn point(&self, v: u32) -> [u16; 2] {
        self.points[v as usize]
    }

    fn rescan_pending(&mut self) {
        // An insertion's flips change some triangles twice or more: scan each once.
        self.pending.sort_unstable();
        self.pending.dedup();
        while let Some(t) = self.pending.pop() {
            let i = 3 * t as usize;
            let p = [
                self.point(self.tris[i]),
                self.point(self.tris[i + 1]),
                self.point(self.tris[i + 2]),
            ];
            if let Verdict::Beyond((error, at)) = self.scanner.check(p, false) {
                self.candidate[t as usize] = at;
                let version = self.version[t as usize];
                self.queue.push(Entry {
                    error,
                    tri: t,
                    version,
                });
            }
        }
    }

    /// Inserts sample `p` (inside or on the border of triangle `t`).
    fn insert(&mut self, t: u32, p: [u16; 2]) {
        let pi = self.points.len() as u32;
        self.points.push(p);
        let e0 = 3 * t;
        let [a, b, c] = [
            self.tris[e0 as usize],
            self.tris[e0 as usize + 1],
            self.tris[e0 as usize + 2],
        ];
        // On an edge: split the edge (and the triangle across it).
        for (k, (u, v)) in [(a, b), (b, c), (c, a)].into_iter().enumerate() {
            if orient(self.point(u), self.point(v), p) == 0 {
                self.split_edge(e0 + k as u32, pi);
                return;
            }
        }
        let [hab, hbc, hca] = [
            self.twin[e0 as usize],
            self.twin[e0 as usize + 1],
            self.twin[e0 as usize + 2],
        ];
        // Triangle t becomes [a, b, p]; new [b, c, p] and [c, a, p]. Edges opposite p first.
        self.set_triangle(t, [a, b, pi], [hab, NONE, NONE]);
        let t1 = self.new_triangle([b, c, pi], [hbc, NONE, 3 * t + 1]);
        let t2 = self.new_triangle([c, a, pi], [hca, 3 * t + 2, 3 * t1 + 1]);
        for tri in [t, t1, t2] {
            self.legalize(3 * tri);
        }
    }

    /// Splits half-edge `e` (from u to v, apex w) at new vertex `pi`.
    fn split_edge(&mut self, e: u32, pi: u32) {
        let t = e / 3;
        let (u, v, w) = (
            self.tris[e as usize],
            self.tris[next(e) as usize],
            self.tris[next(next(e)) as usize],
        );
        let (h_vw, h_wu) = (
            self.twin[next(e) as usize],
            self.twin[next(next(e)) as usize],
        );
        let o = self.twin[e as usize];
        // [w, u, p] and [v, w, p]: the edges opposite p come first.
        self.set_triangle(t, [w, u, pi], [h_wu, NONE, NONE]);
        let t1 = self.new_triangle([v, w, pi], [h_vw, 3 * t + 2, NONE]);
        let mut created = vec![t, t1];
        if o == NONE {
            self.twin[3 * t as usize + 1] = NONE;
            self.twin[3 * t1 as usize + 2] = NONE;
        } else {
            // The other side: half-edge o runs v -> u with apex x.
            let s = o / 3;
            let x = self.tris[next(next(o)) as usize];
            let (h_ux, h_xv) = (
                self.twin[next(o) as usize],
                self.twin[next(next(o)) as usize],
            );
            // [u, x, p] and [x, v, p].
            self.set_triangle(s, [u, x, pi], [h_ux, NONE, 3 * t + 1]);
            let s1 = self.new_triangle([x, v, pi], [h_xv, NONE, 3 * s + 1]);
            self.link(3 * s1 + 1, 3 * t1 + 2);
            created.extend([s, s1]);
        }
        for tri in created {
            self.legalize(3 * tri);
        }
    }

    /// Restores the Delaunay property across half-edge `e` = (a -> b) of triangle
    /// [a, b, p] whose apex p is the newly inserted point, flipping recursively.
    fn legalize(&mut self, e: u32) {
        let mut stack = std::mem::take(&mut self.flips);
        stack.push(e);
        while let Some(e) = stack.pop() {
            let o = self.twin[e as usize];
            if o == NONE {
                continue;
            }
            let t = e / 3;
            let s = o / 3;
            let (a, b, p) = (
                self.tris[e as usize],
                self.tris[next(e) as usize],
                self.tris[next(next(e)) as usize],
            );
            let q = self.tris[next(next(o)) as usize];
            let corners = [a, b, p, q].map(|v| self.point(v));
            let flip = if self.narrow {
                in_circle::<i64>(corners)
            } else {
                in_circle::<i128>(corners)
            };
            if !flip {
                continue;
            }
            let (h_bp, h_pa) = (
                self.twin[next(e) as usize],
                self.twin[next(next(e)) as usize],
            );
            let (h_aq, h_qb) = (
                self.twin[next(o) as usize],
                self.twin[next(next(o)) as usize],
            );
            // [a, q, p] and [q, b, p]: the edges opposite p come first.
            self.set_triangle(t, [a, q, p], [h_aq, NONE, h_pa]);
            self.set_triangle(s, [q, b, p], [h_qb, h_bp, NONE]);
            self.link(3 * t + 1, 3 * s + 2);
            stack.push(3 * t);
            stack.push(3 * s);
        }
        self.flips = stack;
    }
}

/// Whether `d` is strictly inside the circumcircle of triangle (a, b, c), either orientation,
/// computed exactly in `T`: i128 always suffices; i64 does for coordinates below 2^12 (the
/// determinant's three products are each below 2^12 * 2^38, their sum below 2^52).
fn in_circle<T>([a, b, c, d]: [[u16; 2]; 4]) -> bool
where
    T: Copy
        + Default
        + PartialOrd
        + From<u16>
        + Add<Output = T>
        + Sub<Output = T>
        + Mul<Output = T>,
{
    let rel = |p: [u16; 2]| (T::from(p[0]) - T::from(d[0]), T::from(p[1]) - T::from(d[1]));
    let (a, b, c) = (rel(a), rel(b), rel(c));
    let lift = |p: (T, T)| p.0 * p.0 + p.1 * p.1;
    let det = a.0 * (b.1 * lift(c) - lift(b) * c.1) - a.1 * (b.0 * lift(c) - lift(b) * c.0)
        + lift(a) * (b.0 * c.1 - b.1 * c.0);
    let o = (b.0 - a.0) * (c.1 - a.1) - (b.1 - a.1) * (c.0 - a.0);
    let zero = T::default();
    (det > zero && o > zero) || (det < zero && o < zero)
}
