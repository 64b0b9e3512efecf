//! Kaiser's plane-deviance vertex removal (Kaiser 2018, Algorithm 1) with an exact error
//! check on every re-triangulated hole.

use std::cmp::Ordering;
use std::collections::BinaryHeap;

use super::scan::{Scanner, Verdict};
use super::{DecimateOptions, orient};
use crate::adaptive::HeightGrid;

/// Removes interior vertices while the bound holds; returns the surviving triangles.
pub(super) fn remove_vertices(
    scanner: &Scanner<'_>,
    points: &[[u16; 2]],
    triangles: Vec<[u32; 3]>,
    options: &DecimateOptions,
) -> Vec<[u32; 3]> {
    remove_vertices_with(scanner, points, triangles, options, true)
}

/// [`remove_vertices`], with or without [`Soup::some_triangle_holds`] before the ears are
/// scanned (the same result either way, only slower without).
fn remove_vertices_with(
    scanner: &Scanner<'_>,
    points: &[[u16; 2]],
    triangles: Vec<[u32; 3]>,
    options: &DecimateOptions,
    prefilter: bool,
) -> Vec<[u32; 3]> {
    let grid = scanner.grid();
    let mut m = Soup {
        grid,
        points,
        tris: triangles,
        alive: Vec::new(),
        fans: vec![Vec::new(); points.len()],
        limit: options.max_error,
        scanner,
        scratch: Scratch::default(),
        prefilter,
    };
    m.alive = vec![true; m.tris.len()];
    for (t, tri) in m.tris.iter().enumerate() {
        for &v in tri {
            m.fans[v as usize].push(t as u32);
        }
    }
    let n = (grid.side() - 1) as u16;
    let interior = |v: u32| {
        let [x, y] = points[v as usize];
        x != 0 && y != 0 && x != n && y != n
    };
    let mut version = vec![0u32; points.len()];
    let mut queue = BinaryHeap::new();
    for v in 0..points.len() as u32 {
        if interior(v) && !m.fans[v as usize].is_empty() {
            queue.push(Candidate {
                deviance: m.plane_deviance(v),
                vertex: v,
                version: 0,
            });
        }
    }
    while let Some(c) = queue.pop() {
        if version[c.vertex as usize] != c.version || m.fans[c.vertex as usize].is_empty() {
            continue;
        }
        let Some(ring) = m.ring(c.vertex) else {
            continue;
        };
        if ring.len() > options.max_neighbours {
            continue;
        }
        if let Some(max_area) = options.max_triangle_area
            && m.fans[c.vertex as usize].iter().any(|&t| {
                let [a, b, d] = m.tris[t as usize].map(|v| points[v as usize]);
                orient(a, b, d).abs() as f64 / 2.0 > max_area
            })
        {
            continue;
        }
        if !m.try_remove(c.vertex, &ring) {
            continue;
        }
        for &r in &ring {
            if interior(r) {
                version[r as usize] += 1;
                queue.push(Candidate {
                    deviance: m.plane_deviance(r),
                    vertex: r,
                    version: version[r as usize],
                });
            }
        }
    }
    m.tris
        .iter()
        .zip(&m.alive)
        .filter(|(_, alive)| **alive)
        .map(|(t, _)| *t)
        .collect()
}

/// Smallest deviance first.
#[derive(PartialEq)]
struct Candidate {
    deviance: f64,
    vertex: u32,
    version: u32,
}

impl Eq for Candidate {}

impl PartialOrd for Candidate {
    fn partial_cmp(&self, other: &Self) -> Option<Ordering> {
        Some(self.cmp(other))
    }
}

impl Ord for Candidate {
    fn cmp(&self, other: &Self) -> Ordering {
        other
            .deviance
            .total_cmp(&self.deviance)
            .then_with(|| other.vertex.cmp(&self.vertex))
    }
}

struct Soup<'a> {
    grid: &'a HeightGrid,
    points: &'a [[u16; 2]],
    tris: Vec<[u32; 3]>,
    alive: Vec<bool>,
    /// Per vertex, its live triangles.
    fans: Vec<Vec<u32>>,
    limit: f64,
    scanner: &'a Scanner<'a>,
    scratch: Scratch,
    /// Whether [`Soup::some_triangle_holds`] is asked first.
    prefilter: bool,
}

/// Buffers of one removal, kept from vertex to vertex.
#[derive(Default)]
struct Scratch {
    poly: Vec<u32>,
    /// Per polygon vertex: the error of its ear as last scanned (`None`: beyond the bound),
    /// with the neighbours it was scanned with.
    ears: Vec<Option<(u32, u32, Option<f32>)>>,
    new_tris: Vec<[u32; 3]>,
}

impl Soup<'_> {
    fn position(&self, v: u32) -> [f64; 3] {
        let [x, y] = self.points[v as usize];
        [
            f64::from(x),
            f64::from(y),
            f64::from(self.grid.at(usize::from(x), usize::from(y))),
        ]
    }

    /// Distance of `v` from the area-weighted average plane of its fan (Kaiser's eq. for P
    /// and n: area-weighted triangle centres and normals).
    fn plane_deviance(&self, v: u32) -> f64 {
        let mut centre = [0.0; 3];
        let mut normal = [0.0; 3];
        let mut total = 0.0;
        for &t in &self.fans[v as usize] {
            let [a, b, c] = self.tris[t as usize].map(|i| self.position(i));
            let n = cross(sub(b, a), sub(c, a));
            let area = len(n) / 2.0;
            if area == 0.0 {
                continue;
            }
            for k in 0..3 {
                centre[k] += area * (a[k] + b[k] + c[k]) / 3.0;
                // n / |n| * area = n / 2.
                normal[k] += n[k] / 2.0;
            }
            total += area;
        }
        if total == 0.0 || len(normal) == 0.0 {
            return 0.0;
        }
        let centre = centre.map(|c| c / total);
        let l = len(normal);
        let normal = normal.map(|c| c / l);
        dot(normal, sub(self.position(v), centre)).abs()
    }

    /// The ring of neighbours around interior vertex `v`, in the triangles' winding order;
    /// `None` if the fan is not a closed disc.
    fn ring(&self, v: u32) -> Option<Vec<u32>> {
        let fan = &self.fans[v as usize];
        let mut edges: Vec<(u32, u32)> = Vec::with_capacity(fan.len());
        for &t in fan {
            let tri = self.tris[t as usize];
            let k = tri.iter().position(|&x| x == v)?;
            edges.push((tri[(k + 1) % 3], tri[(k + 2) % 3]));
        }
        let mut ring = Vec::with_capacity(edges.len());
        let mut at = edges[0].0;
        for _ in 0..edges.len() {
            ring.push(at);
            at = edges.iter().find(|e| e.0 == at)?.1;
        }
        (at == edges[0].0).then_some(ring)
    }

    /// Removes `v` and fills the hole by ear clipping (the ear with the smallest error first);
    /// keeps the change only if every new triangle is within the bound.
    fn try_remove(&mut self, v: u32, ring: &[u32]) -> bool {
        // The new triangles' planes at v are convex combinations of the ring's heights, so a
        // vertex further than the bound outside their range cannot go.
        let height = |x: u32| self.position(x)[2];
        let (low, high) = ring
            .iter()
            .fold((f64::INFINITY, f64::NEG_INFINITY), |(l, h), &r| {
                (l.min(height(r)), h.max(height(r)))
            });
        let z = height(v);
        if z > high + self.limit || z < low - self.limit {
            return false;
        }
        if self.prefilter && !self.some_triangle_holds(v, ring, z) {
            return false;
        }
        let mut scratch = std::mem::take(&mut self.scratch);
        let done = self.clip_ears(ring, &mut scratch);
        if done {
            for t in std::mem::take(&mut self.fans[v as usize]) {
                self.alive[t as usize] = false;
                for &r in &self.tris[t as usize] {
                    if r != v {
                        self.fans[r as usize].retain(|&x| x != t);
                    }
                }
            }
            for &tri in &scratch.new_tris {
                let t = self.tris.len() as u32;
                self.tris.push(tri);
                self.alive.push(true);
                for r in tri {
                    self.fans[r as usize].push(t);
                }
            }
        }
        self.scratch = scratch;
        done
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
                    let h = |x: u32| self.position(x)[2];
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

    /// Triangulates the polygon `ring` into `scratch.new_tris`, cheapest ear first; false if
    /// some step has no ear within the bound. An ear's scan is kept until one of its
    /// neighbours changes.
    fn clip_ears(&self, ring: &[u32], scratch: &mut Scratch) -> bool {
        let Scratch {
            poly,
            ears,
            new_tris,
        } = scratch;
        poly.clear();
        poly.extend_from_slice(ring);
        ears.clear();
        ears.resize(poly.len(), None);
        new_tris.clear();
        while poly.len() > 3 {
            let k = poly.len();
            let mut best: Option<(f32, usize)> = None;
            for i in 0..k {
                let (a, b, c) = (poly[(i + k - 1) % k], poly[i], poly[(i + 1) % k]);
                if !self.is_ear(poly, a, b, c) {
                    continue;
                }
                let err = match ears[i] {
                    Some((ea, ec, err)) if ea == a && ec == c => err,
                    _ => {
                        let err = match self.scanner.check(self.corners([a, b, c]), true) {
                            Verdict::Within(e) => Some(e),
                            Verdict::Beyond(_) => None,
                        };
                        ears[i] = Some((a, c, err));
                        err
                    }
                };
                if let Some(err) = err
                    && best.is_none_or(|(e, _)| err < e)
                {
                    best = Some((err, i));
                }
            }
            let Some((_, i)) = best else {
                return false;
            };
            new_tris.push([poly[(i + k - 1) % k], poly[i], poly[(i + 1) % k]]);
            poly.remove(i);
            ears.remove(i);
        }
        let last = [poly[0], poly[1], poly[2]];
        let p = self.corners(last);
        if orient(p[0], p[1], p[2]) >= 0
            || matches!(self.scanner.check(p, true), Verdict::Beyond(_))
        {
            return false;
        }
        new_tris.push(last);
        true
    }

    fn corners(&self, t: [u32; 3]) -> [[u16; 2]; 3] {
        t.map(|x| self.points[x as usize])
    }

    /// Whether (a, b, c) is a proper ear of `poly`: wound like the mesh and with no other
    /// polygon vertex inside or on it.
    fn is_ear(&self, poly: &[u32], a: u32, b: u32, c: u32) -> bool {
        let p = |x: u32| self.points[x as usize];
        if orient(p(a), p(b), p(c)) >= 0 {
            return false;
        }
        poly.iter()
            .filter(|&&x| x != a && x != b && x != c)
            .all(|&x| {
                let q = p(x);
                // Outside if strictly on the outer side of any edge (mesh winding is negative).
                orient(p(a), p(b), q) > 0 || orient(p(b), p(c), q) > 0 || orient(p(c), p(a), q) > 0
            })
    }
}

fn sub(a: [f64; 3], b: [f64; 3]) -> [f64; 3] {
    [a[0] - b[0], a[1] - b[1], a[2] - b[2]]
}

fn cross(a: [f64; 3], b: [f64; 3]) -> [f64; 3] {
    [
        a[1] * b[2] - a[2] * b[1],
        a[2] * b[0] - a[0] * b[2],
        a[0] * b[1] - a[1] * b[0],
    ]
}

fn dot(a: [f64; 3], b: [f64; 3]) -> f64 {
    a[0] * b[0] + a[1] * b[1] + a[2] * b[2]
}

fn len(a: [f64; 3]) -> f64 {
    dot(a, a).sqrt()
}

#[cfg(test)]
mod tests {
    use super::*;
    use crate::adaptive::decimate::insert;
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
            let (points, triangles) = insert::refine(&scanner);
            let quick = remove_vertices_with(&scanner, &points, triangles.clone(), &options, true);
            let slow = remove_vertices_with(&scanner, &points, triangles, &options, false);
            prop_assert_eq!(quick, slow);
        }
    }
}
