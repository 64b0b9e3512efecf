//! Vertex removal with an exact error check on every re-triangulated hole (after Kaiser 2018,
//! Algorithm 1: remove a vertex, fill its hole by ear clipping, keep the change only if the new
//! triangles hold the bound).
//!
//! The mesh is held as **rings**: per vertex, its neighbours in the triangles' winding order
//! (closed around an interior vertex, open along the tile border), all in one pool, and each
//! vertex's height beside it. Removing a vertex reads its ring and rewrites only its
//! neighbours' rings, in place; nothing is allocated per removal and no triangle list is
//! searched (a triangle list with per-vertex fans, as before, spent more time finding and
//! updating fans than scanning samples).
//!
//! Two choices differ from the thesis, both measured on the SRTM and mountain tiles of
//! `tools/compare-meshers.py` at 1, 5 and 30 m:
//! - **Order.** Kaiser takes the vertex of least plane deviance from a priority queue and
//!   re-queues its neighbours after each removal. Here vertices are taken in passes in the
//!   order of their numbers (the RTIN mesh numbers them along its hierarchy, so neighbours
//!   are near in memory), and a vertex whose ring changed is taken again in the next pass,
//!   until a pass changes nothing. The meshes come out within 0.1 % of the deviance order's
//!   triangles or with fewer (it left up to 8 % more), and the queue's pops and deviances
//!   had been a third of the pass.
//! - **Ears.** The thesis clips the ear of least error first, which scans every ear of the
//!   polygon; here the first ear (in ring order) that holds the bound is clipped. That scans
//!   35-45 % fewer triangles and, because it does not leave the hardest part of the hole for
//!   last, more removals succeed: 0.4-8 % fewer triangles.

use std::hint::select_unpredictable;

use super::scan::Scanner;
use super::{DecimateOptions, orient};

/// Removes interior vertices of the triangulation `triangles` (a triangulation of the whole
/// grid square, wound as the meshes are) while the bound holds; returns the surviving
/// triangles.
pub(super) fn remove_vertices(
    scanner: &Scanner<'_>,
    points: &[[u16; 2]],
    triangles: &[[u32; 3]],
    options: &DecimateOptions,
) -> Vec<[u32; 3]> {
    remove_vertices_with(scanner, points, triangles, options, true)
}

/// [`remove_vertices`], with or without [`Soup::some_triangle_holds`] before the ears are
/// scanned (the same result either way, only slower without).
fn remove_vertices_with(
    scanner: &Scanner<'_>,
    points: &[[u16; 2]],
    triangles: &[[u32; 3]],
    options: &DecimateOptions,
    prefilter: bool,
) -> Vec<[u32; 3]> {
    let grid = scanner.grid();
    let n = (grid.side() - 1) as u16;
    let interior = |v: u32| {
        let [x, y] = points[v as usize];
        x != 0 && y != 0 && x != n && y != n
    };
    let Some(rings) = Rings::new(points.len(), triangles, interior) else {
        // Not a triangulation of the square (never the case for the meshes this module
        // builds): nothing is removed.
        debug_assert!(false, "remove_vertices was given a mesh that is not a disc");
        return triangles.to_vec();
    };
    let mut m = Soup {
        points,
        heights: points
            .iter()
            .map(|&[x, y]| f64::from(grid.at(usize::from(x), usize::from(y))))
            .collect(),
        rings,
        limit: options.max_error,
        scanner,
        scratch: Scratch::default(),
        prefilter,
    };
    let mut dirty = vec![false; points.len()];
    let mut pass: Vec<u32> = (0..points.len() as u32)
        .filter(|&v| interior(v) && !m.rings.get(v).is_empty())
        .collect();
    while !pass.is_empty() {
        for &v in &pass {
            dirty[v as usize] = false;
            if m.try_remove(v, options) {
                for &r in &m.scratch.ring {
                    dirty[r as usize] = interior(r);
                }
            }
        }
        pass.clear();
        pass.extend((0..points.len() as u32).filter(|&v| dirty[v as usize]));
    }
    m.rings.triangles(interior)
}

/// Per vertex, its neighbours in winding order, in one pool.
struct Rings {
    pool: Vec<u32>,
    slots: Vec<Slot>,
}

/// Where one vertex's ring lies in [`Rings::pool`].
#[derive(Clone, Copy, Default)]
struct Slot {
    start: u32,
    len: u32,
    cap: u32,
}

impl Rings {
    /// The rings of `triangles`; `None` if some vertex's triangles do not chain into one fan
    /// (closed for `interior` vertices, open for the others).
    fn new(count: usize, triangles: &[[u32; 3]], interior: impl Fn(u32) -> bool) -> Option<Self> {
        // Per vertex, the far edge of each of its triangles, grouped by vertex.
        let mut offsets = vec![0usize; count + 1];
        for t in triangles {
            for &v in t {
                offsets[v as usize + 1] += 1;
            }
        }
        for v in 0..count {
            offsets[v + 1] += offsets[v];
        }
        let mut fill = offsets.clone();
        let mut edges = vec![(0u32, 0u32); offsets[count]];
        for t in triangles {
            for k in 0..3 {
                let v = t[k] as usize;
                edges[fill[v]] = (t[(k + 1) % 3], t[(k + 2) % 3]);
                fill[v] += 1;
            }
        }
        let mut rings = Self {
            pool: Vec::with_capacity(2 * edges.len()),
            slots: vec![Slot::default(); count],
        };
        for v in 0..count {
            let fan = &edges[offsets[v]..offsets[v + 1]];
            if fan.is_empty() {
                continue;
            }
            let closed = interior(v as u32);
            let len = fan.len() + usize::from(!closed);
            let start = rings.pool.len();
            let cap = len + len / 2 + 2;
            rings.slots[v] = Slot {
                start: start as u32,
                len: len as u32,
                cap: cap as u32,
            };
            // An open fan starts at the edge whose start no other edge ends at.
            let first = if closed {
                fan[0].0
            } else {
                fan.iter().find(|e| fan.iter().all(|f| f.1 != e.0))?.0
            };
            let mut at = first;
            for _ in 0..fan.len() {
                rings.pool.push(at);
                at = fan.iter().find(|e| e.0 == at)?.1;
            }
            if closed {
                if at != first {
                    return None;
                }
            } else {
                rings.pool.push(at);
            }
            rings.pool.resize(start + cap, u32::MAX);
        }
        Some(rings)
    }

    fn get(&self, v: u32) -> &[u32] {
        let s = self.slots[v as usize];
        &self.pool[s.start as usize..(s.start + s.len) as usize]
    }

    /// In `r`'s ring, replaces `v` by `with`.
    fn splice(&mut self, r: u32, v: u32, with: &[u32]) {
        let s = self.slots[r as usize];
        let (start, len) = (s.start as usize, s.len as usize);
        let Some(at) = self.pool[start..start + len].iter().position(|&x| x == v) else {
            debug_assert!(false, "{v} is not in the ring of {r}");
            return;
        };
        let new_len = len - 1 + with.len();
        let start = if new_len > s.cap as usize {
            // Moved to the end of the pool with room to grow.
            let cap = 2 * new_len;
            let moved = self.pool.len();
            self.pool.extend_from_within(start..start + len);
            self.pool.resize(moved + cap, u32::MAX);
            self.slots[r as usize].start = moved as u32;
            self.slots[r as usize].cap = cap as u32;
            moved
        } else {
            start
        };
        self.pool
            .copy_within(start + at + 1..start + len, start + at + with.len());
        self.pool[start + at..start + at + with.len()].copy_from_slice(with);
        self.slots[r as usize].len = new_len as u32;
    }

    /// Every triangle once, from its lowest-numbered vertex.
    fn triangles(&self, interior: impl Fn(u32) -> bool) -> Vec<[u32; 3]> {
        let mut out = Vec::new();
        for a in 0..self.slots.len() as u32 {
            let ring = self.get(a);
            let m = ring.len();
            let pairs = if interior(a) { m } else { m.saturating_sub(1) };
            for i in 0..pairs {
                let (b, c) = (ring[i], ring[(i + 1) % m]);
                if a < b && a < c {
                    out.push([a, b, c]);
                }
            }
        }
        out
    }
}

struct Soup<'a> {
    points: &'a [[u16; 2]],
    /// Per vertex, its height.
    heights: Vec<f64>,
    rings: Rings,
    limit: f64,
    scanner: &'a Scanner<'a>,
    scratch: Scratch,
    /// Whether [`Soup::some_triangle_holds`] is asked first.
    prefilter: bool,
}

/// Buffers of one removal, kept from vertex to vertex.
#[derive(Default)]
struct Scratch {
    /// The ring of the vertex tried last.
    ring: Vec<u32>,
    /// The hole's polygon still to fill, as positions in `ring`.
    poly: Vec<usize>,
    /// Per ring position: whether its ear held the bound when last scanned, with the
    /// neighbours it was scanned with.
    ears: Vec<Option<(usize, usize, bool)>>,
    /// New edges across the hole, as positions in `ring`, both ways round.
    diagonals: Vec<(usize, usize)>,
    replacement: Vec<u32>,
}

impl Soup<'_> {
    fn height(&self, v: u32) -> f64 {
        self.heights[v as usize]
    }

    /// Removes interior vertex `v` and fills the hole by ear clipping if every new triangle
    /// is within the bound and the options allow; leaves `v`'s ring in `scratch.ring` either
    /// way.
    fn try_remove(&mut self, v: u32, options: &DecimateOptions) -> bool {
        let mut scratch = std::mem::take(&mut self.scratch);
        scratch.ring.clear();
        scratch.ring.extend_from_slice(self.rings.get(v));
        let done = self.allowed(v, &scratch.ring, options)
            && self.clip_ears(self.points[v as usize], &mut scratch);
        if done {
            self.rewire(v, &mut scratch);
        }
        self.scratch = scratch;
        done
    }

    /// The checks before any ear is scanned: the options' limits, the ring's height range and
    /// [`Soup::some_triangle_holds`].
    fn allowed(&self, v: u32, ring: &[u32], options: &DecimateOptions) -> bool {
        let k = ring.len();
        if k < 3 || k > options.max_neighbours {
            return false;
        }
        if let Some(max_area) = options.max_triangle_area {
            let p = self.points[v as usize];
            let too_large = (0..k).any(|i| {
                let (b, c) = (
                    self.points[ring[i] as usize],
                    self.points[ring[(i + 1) % k] as usize],
                );
                orient(p, b, c).abs() as f64 / 2.0 > max_area
            });
            if too_large {
                return false;
            }
        }
        // The new triangles' planes at v are convex combinations of the ring's heights, so a
        // vertex further than the bound outside their range cannot go.
        let (low, high) = ring
            .iter()
            .fold((f64::INFINITY, f64::NEG_INFINITY), |(l, h), &r| {
                (l.min(self.height(r)), h.max(self.height(r)))
            });
        let z = self.height(v);
        if z > high + self.limit || z < low - self.limit {
            return false;
        }
        !self.prefilter || self.some_triangle_holds(v, ring, z)
    }

    /// Whether some triangle of three ring vertices holds `v`'s sample within the bound: any
    /// filling of the hole has one triangle over `v`, made of ring vertices, so without one
    /// the removal cannot succeed and no ear need be scanned. Most failed removals fail at
    /// the removed sample itself.
    fn some_triangle_holds(&self, v: u32, ring: &[u32], z: f64) -> bool {
        let p = self.points[v as usize];
        // Generous by far more than f64 rounding: this only spares scans.
        let limit = self.limit + 1e-6 * (1.0 + z.abs() + self.limit);
        let k = ring.len();
        for i in 0..k {
            let a = self.points[ring[i] as usize];
            for j in i + 1..k {
                let b = self.points[ring[j] as usize];
                let ab = orient(a, b, p);
                for l in j + 1..k {
                    let c = self.points[ring[l] as usize];
                    let (bc, ca) = (orient(b, c, p), orient(c, a, p));
                    let area = ab + bc + ca;
                    // Inside or on an edge: every sub-area of one sign (the mesh's winding
                    // either way round, as the triple is not ordered).
                    let inside = (ab <= 0 && bc <= 0 && ca <= 0) || (ab >= 0 && bc >= 0 && ca >= 0);
                    if area == 0 || !inside {
                        continue;
                    }
                    let h = |x: u32| self.height(x);
                    let at =
                        (bc as f64 * h(ring[i]) + ca as f64 * h(ring[j]) + ab as f64 * h(ring[l]))
                            / area as f64;
                    if (at - z).abs() <= limit {
                        return true;
                    }
                }
            }
        }
        false
    }

    /// Triangulates the hole `scratch.ring` by clipping, each time, the first ear in ring
    /// order that holds the bound, recording the new edges in `scratch.diagonals`; false if
    /// some step has no such ear. An ear's scan is kept until one of its neighbours changes.
    /// `centre`: where the removed vertex was.
    fn clip_ears(&self, centre: [u16; 2], scratch: &mut Scratch) -> bool {
        let Scratch {
            ring,
            poly,
            ears,
            diagonals,
            ..
        } = scratch;
        let corner = |i: usize| self.points[ring[i] as usize];
        poly.clear();
        poly.extend(0..ring.len());
        ears.clear();
        ears.resize(poly.len(), None);
        diagonals.clear();
        // Whether the polygon left is star-shaped from `centre`: the hole is at first (the
        // ring round it), and stays so while the ears clipped leave `centre` outside.
        let mut star = true;
        while poly.len() > 3 {
            let k = poly.len();
            let clip = (0..k).find(|&i| {
                let (prev, next) = around(i, k);
                let [a, b, c] = [poly[prev], poly[i], poly[next]];
                if !is_ear(poly, i, corner, star.then_some(centre)) {
                    return false;
                }
                match ears[b] {
                    Some((ea, ec, holds)) if ea == a && ec == c => holds,
                    _ => {
                        // Edges a-b and b-c are the hole's: edges of triangles that held.
                        let holds = self
                            .scanner
                            .holds([a, b, c].map(corner), [true, false, true]);
                        ears[b] = Some((a, c, holds));
                        holds
                    }
                }
            });
            let Some(i) = clip else {
                return false;
            };
            let (prev, next) = around(i, k);
            let (a, c) = (poly[prev], poly[next]);
            star &= orient(centre, corner(a), corner(c)) < 0;
            diagonals.extend([(a, c), (c, a)]);
            // By hand: `Vec::remove` calls memmove, whose size classes mispredict on these
            // few elements.
            for j in i..k - 1 {
                poly[j] = poly[j + 1];
            }
            poly.pop();
        }
        let last = [poly[0], poly[1], poly[2]].map(corner);
        orient(last[0], last[1], last[2]) < 0 && self.scanner.holds(last, [true; 3])
    }

    /// Takes `v` out: each neighbour's ring gets, in `v`'s place, its new diagonals in
    /// winding order.
    fn rewire(&mut self, v: u32, scratch: &mut Scratch) {
        let Scratch {
            ring,
            diagonals,
            replacement,
            ..
        } = scratch;
        let k = ring.len();
        // Around ring vertex i the hole runs from i + 1 to i - 1, so its diagonals go in
        // order of (j - i) mod k.
        // (Both below k: one conditional subtraction instead of a division per key.)
        diagonals.sort_unstable_by_key(|&(i, j)| {
            let d = j + k - i;
            (i, select_unpredictable(d >= k, d.wrapping_sub(k), d))
        });
        let mut d = 0;
        for i in 0..k {
            replacement.clear();
            while d < diagonals.len() && diagonals[d].0 == i {
                replacement.push(ring[diagonals[d].1]);
                d += 1;
            }
            self.rings.splice(ring[i], v, replacement);
        }
        self.rings.slots[v as usize].len = 0;
    }
}

/// Whether the corner at position `i` of `poly` and its two neighbours make a proper ear:
/// wound like the mesh and with no other polygon vertex inside or on it.
///
/// `star`: a point the polygon is star-shaped from, its vertices in angular order round it
/// (the removed vertex, while no clipped ear has reached it). Then an ear that turns less
/// than half a turn round that point (wound like the mesh as seen from it) lies in the convex
/// wedge from it through the ear's two ends, and every other vertex lies outside that wedge
/// (the vertices' directions from the point are distinct and in order): no vertex need be
/// tested. About half the convex ears are of this kind (49-51 % on the tiles of
/// `tools/compare-meshers.py` at 1, 5 and 30 m).
fn is_ear(
    poly: &[usize],
    i: usize,
    corner: impl Fn(usize) -> [u16; 2],
    star: Option<[u16; 2]>,
) -> bool {
    let k = poly.len();
    let (prev, next) = around(i, k);
    let [a, b, c] = [poly[prev], poly[i], poly[next]].map(&corner);
    if orient(a, b, c) >= 0 {
        return false;
    }
    // The other vertices, from the one after `next` round to the one before `prev`.
    let none_inside = || {
        (2..k - 1).all(|m| {
            let j = if i + m >= k { i + m - k } else { i + m };
            let q = corner(poly[j]);
            // Outside if strictly on the outer side of any edge (mesh winding is negative).
            (orient(a, b, q) > 0) | (orient(b, c, q) > 0) | (orient(c, a, q) > 0)
        })
    };
    if let Some(o) = star
        && orient(o, a, c) < 0
    {
        debug_assert!(
            none_inside(),
            "a vertex inside the wedge of {a:?} {b:?} {c:?}"
        );
        return true;
    }
    none_inside()
}

/// The positions before and after `i` in a cycle of `k` (without a division).
fn around(i: usize, k: usize) -> (usize, usize) {
    (
        if i == 0 { k - 1 } else { i - 1 },
        if i + 1 == k { 0 } else { i + 1 },
    )
}

#[cfg(test)]
mod tests {
    use super::*;
    use crate::adaptive::Rtin;
    use crate::adaptive::test_grids::{random, rough};
    use proptest::prelude::*;

    proptest! {
        #![proptest_config(ProptestConfig::with_cases(24))]
        /// The test before the ears only spares work: every removal it refuses would have
        /// failed, so the meshes are the same.
        #[test]
        fn refusing_removals_early_changes_no_mesh(
            k in 2u32..=6,
            seed in any::<u32>(),
            smooth in any::<bool>(),
            max_error in 0.0f64..20.0,
            relief in 0.0f32..300.0,
        ) {
            // White noise (few removals succeed) or ridges (many do).
            let grid = if smooth {
                rough((1 << k) + 1, seed % 1000, 10.0 * relief)
            } else {
                random(k, u64::from(seed), relief)
            };
            let options = DecimateOptions::new(max_error);
            let scanner = Scanner::new(&grid, max_error as f32);
            let seed_mesh = Rtin::new(&grid).mesh(max_error);
            let with = |prefilter| {
                remove_vertices_with(
                    &scanner,
                    &seed_mesh.vertices,
                    &seed_mesh.triangles,
                    &options,
                    prefilter,
                )
            };
            prop_assert_eq!(with(true), with(false));
        }
    }

    #[test]
    fn rings_read_back_the_triangles() {
        let grid = rough(33, 4, 500.0);
        let mesh = Rtin::new(&grid).mesh(3.0);
        let n = 32;
        let interior = |v: u32| {
            let [x, y] = mesh.vertices[v as usize];
            x != 0 && y != 0 && x != n && y != n
        };
        let rings = Rings::new(mesh.vertices.len(), &mesh.triangles, interior).expect("a disc");
        let canonical = |t: &[u32; 3]| {
            // The same triangle, same winding, rotated to start at its lowest vertex.
            let k = (0..3).min_by_key(|&k| t[k]).unwrap_or(0);
            [t[k], t[(k + 1) % 3], t[(k + 2) % 3]]
        };
        let mut want: Vec<_> = mesh.triangles.iter().map(canonical).collect();
        let mut got = rings.triangles(interior);
        want.sort_unstable();
        got.sort_unstable();
        assert_eq!(got, want);
    }
}
