//! Adaptive terrain meshes: triangulations of a tile's height grid that keep the vertical error
//! under a bound with as few triangles as the method can manage.
//!
//! * [`Rtin`]: right-triangulated irregular networks (Evans, Kirkpatrick, Townsend 2001), the
//!   hierarchy `@mapbox/martini` uses, but with the **exact** error of every triangle against
//!   every grid sample it covers, so a mesh built for `max_error` never exceeds it (martini
//!   measures one sample per triangle and can exceed its bound several times over).
//! * [`decimate`]: the RTIN mesh, then vertex removal after Kaiser's thesis (Algorithm 1) with
//!   the exact check on every re-triangulated hole, for when fewer triangles matter more than
//!   build time.
//!
//! Both work on a [`HeightGrid`] of `(2^k + 1)^2` samples and produce an [`AdaptiveMesh`] in
//! grid coordinates:
//!
//! ```text
//!   (0,0) ----- x (east) ----> (n,0)      n = side - 1
//!     |                          |        vertex = [column, row]
//!     y (south)                  |        triangles counter-clockwise seen from above
//!     v                          |        (east right, north up), as quantized-mesh wants
//!   (0,n) --------------------- (n,n)
//! ```
//!
//! Tile borders: neither method keeps every border vertex, so two neighbouring meshes need
//! not share border vertices. Cracks are closed by skirts (Ulrich 2002; Cesium's
//! quantized-mesh terrain does the same), which also cover neighbours at other levels; see
//! [`AdaptiveMesh::edge_vertices`] for the skirt input.

mod rows;
mod rtin;

pub use rtin::{Rtin, RtinScratch};

pub mod decimate;

/// Why a height grid cannot be meshed.
#[derive(Debug, thiserror::Error, PartialEq)]
pub enum MeshError {
    /// The side is not `2^k + 1` with `1 <= k <= 15`.
    #[error("a height grid must have 2^k + 1 samples per side (3 .. 32769), not {0}")]
    BadSide(usize),
    /// The sample count is not side^2.
    #[error("a {side} x {side} height grid needs {} samples, got {got}", side * side)]
    WrongLength {
        /// Samples per side.
        side: usize,
        /// Samples given.
        got: usize,
    },
    /// A sample is NaN or infinite.
    #[error("height sample at column {x}, row {y} is not a finite number")]
    NotFinite {
        /// Column.
        x: usize,
        /// Row.
        y: usize,
    },
}

/// A square grid of heights in metres, `side = 2^k + 1` samples per side, row-major from the
/// north-west corner (row 0 is north, column 0 is west).
#[derive(Clone, Debug, PartialEq)]
pub struct HeightGrid {
    side: usize,
    heights: Vec<f32>,
}

impl HeightGrid {
    /// Checks and wraps `heights`.
    pub fn new(side: usize, heights: Vec<f32>) -> Result<Self, MeshError> {
        let cells = side.wrapping_sub(1);
        if !(2..=32768).contains(&cells) || !cells.is_power_of_two() {
            return Err(MeshError::BadSide(side));
        }
        if heights.len() != side * side {
            return Err(MeshError::WrongLength {
                side,
                got: heights.len(),
            });
        }
        if let Some(i) = heights.iter().position(|h| !h.is_finite()) {
            return Err(MeshError::NotFinite {
                x: i % side,
                y: i / side,
            });
        }
        Ok(Self { side, heights })
    }

    /// Samples per side.
    pub fn side(&self) -> usize {
        self.side
    }

    /// All samples, row-major.
    pub fn heights(&self) -> &[f32] {
        &self.heights
    }

    /// The sample at column `x`, row `y`.
    pub fn at(&self, x: usize, y: usize) -> f32 {
        self.heights[y * self.side + x]
    }

    /// Lowest and highest sample (in eight lanes with compare-and-select: the samples are
    /// finite, and `f32::min`'s NaN rules would keep the loop scalar).
    pub fn min_max(&self) -> (f32, f32) {
        let (mut lo, mut hi) = ([f32::INFINITY; 8], [f32::NEG_INFINITY; 8]);
        let chunks = self.heights.chunks_exact(8);
        let tail = chunks.remainder();
        for chunk in chunks {
            for k in 0..8 {
                lo[k] = if chunk[k] < lo[k] { chunk[k] } else { lo[k] };
                hi[k] = if chunk[k] > hi[k] { chunk[k] } else { hi[k] };
            }
        }
        tail.iter()
            .chain(&lo)
            .chain(&hi)
            .fold((f32::INFINITY, f32::NEG_INFINITY), |(lo, hi), &h| {
                (lo.min(h), hi.max(h))
            })
    }
}

/// A triangle mesh over a [`HeightGrid`], vertices at grid samples.
#[derive(Clone, Debug, Default, PartialEq)]
pub struct AdaptiveMesh {
    /// Samples per side of the grid the mesh was built from.
    pub side: usize,
    /// Vertex positions as `[column, row]`.
    pub vertices: Vec<[u16; 2]>,
    /// Triangles, counter-clockwise seen from above.
    pub triangles: Vec<[u32; 3]>,
}

impl AdaptiveMesh {
    /// The largest vertical distance, metres, between the mesh and the grid, over every grid
    /// sample (each sample is checked against the triangle that covers it, in f64). This is
    /// the independent check of the builders' bounds.
    pub fn max_error(&self, grid: &HeightGrid) -> f64 {
        let mut worst = 0.0f64;
        for t in &self.triangles {
            let p = t.map(|i| self.vertices[i as usize]);
            let h = p.map(|[x, y]| f64::from(grid.at(usize::from(x), usize::from(y))));
            for_each_sample_in(p, |x, y, w| {
                let mesh = w[0] * h[0] + w[1] * h[1] + w[2] * h[2];
                let d = (f64::from(grid.at(x, y)) - mesh).abs();
                worst = worst.max(d);
            });
        }
        worst
    }

    /// The vertices on each edge of the tile, sorted along the edge: north (west to east),
    /// east (north to south), south (west to east), west (north to south). These are what
    /// skirts hang from, and what quantized-mesh's edge index lists hold.
    pub fn edge_vertices(&self) -> [Vec<u32>; 4] {
        let n = (self.side - 1) as u16;
        let mut edges: [Vec<(u16, u32)>; 4] = Default::default();
        for (i, &[x, y]) in self.vertices.iter().enumerate() {
            let i = i as u32;
            if y == 0 {
                edges[0].push((x, i));
            }
            if x == n {
                edges[1].push((y, i));
            }
            if y == n {
                edges[2].push((x, i));
            }
            if x == 0 {
                edges[3].push((y, i));
            }
        }
        edges.map(|mut e| {
            e.sort_unstable();
            e.into_iter().map(|(_, i)| i).collect()
        })
    }
}

/// Calls `f(x, y, barycentric weights)` for every grid sample inside or on the triangle `p`.
pub(crate) fn for_each_sample_in(p: [[u16; 2]; 3], mut f: impl FnMut(usize, usize, [f64; 3])) {
    let q = p.map(|[x, y]| (i64::from(x), i64::from(y)));
    let area = (q[1].0 - q[0].0) * (q[2].1 - q[0].1) - (q[1].1 - q[0].1) * (q[2].0 - q[0].0);
    if area == 0 {
        return;
    }
    let (x0, x1) = (q.iter().map(|v| v.0).min(), q.iter().map(|v| v.0).max());
    let (y0, y1) = (q.iter().map(|v| v.1).min(), q.iter().map(|v| v.1).max());
    let (Some(x0), Some(x1), Some(y0), Some(y1)) = (x0, x1, y0, y1) else {
        return;
    };
    let edge = |a: (i64, i64), b: (i64, i64), x: i64, y: i64| {
        (b.0 - a.0) * (y - a.1) - (b.1 - a.1) * (x - a.0)
    };
    for y in y0..=y1 {
        for x in x0..=x1 {
            let w0 = edge(q[1], q[2], x, y);
            let w1 = edge(q[2], q[0], x, y);
            let w2 = edge(q[0], q[1], x, y);
            let inside = if area > 0 {
                w0 >= 0 && w1 >= 0 && w2 >= 0
            } else {
                w0 <= 0 && w1 <= 0 && w2 <= 0
            };
            if inside {
                let a = area as f64;
                f(
                    x as usize,
                    y as usize,
                    [w0 as f64 / a, w1 as f64 / a, w2 as f64 / a],
                );
            }
        }
    }
}

#[cfg(test)]
pub(crate) mod test_grids {
    use super::{AdaptiveMesh, HeightGrid, for_each_sample_in};

    /// A grid of `2^k + 1` samples of uniform noise in `0..relief_m` (xorshift, from `seed`).
    pub fn random(k: u32, seed: u64, relief_m: f32) -> HeightGrid {
        let side = (1usize << k) + 1;
        let mut state = seed | 1;
        let h = (0..side * side)
            .map(|_| {
                state ^= state << 13;
                state ^= state >> 7;
                state ^= state << 17;
                (state >> 40) as f32 / (1u64 << 24) as f32 * relief_m
            })
            .collect();
        HeightGrid::new(side, h).expect("valid random grid")
    }

    /// Every triangle is counter-clockwise seen from above, their areas add up to the square,
    /// and every sample lies in some triangle.
    pub fn assert_covers(mesh: &AdaptiveMesh) {
        let n = (mesh.side - 1) as i64;
        let mut twice_area = 0i64;
        let mut seen = vec![false; mesh.side * mesh.side];
        for t in &mesh.triangles {
            let p = t.map(|i| mesh.vertices[i as usize].map(i64::from));
            let a = (p[1][0] - p[0][0]) * (p[2][1] - p[0][1])
                - (p[1][1] - p[0][1]) * (p[2][0] - p[0][0]);
            assert!(
                a < 0,
                "triangle {p:?} is not counter-clockwise seen from above"
            );
            twice_area -= a;
            for_each_sample_in(t.map(|i| mesh.vertices[i as usize]), |x, y, _| {
                seen[y * mesh.side + x] = true;
            });
        }
        assert_eq!(twice_area, 2 * n * n);
        assert!(seen.iter().all(|s| *s));
    }

    /// A rough synthetic grid: sums of ridged sines and a hash-based roughness, deterministic.
    pub fn rough(side: usize, seed: u32, relief_m: f32) -> HeightGrid {
        let mut h = Vec::with_capacity(side * side);
        for y in 0..side {
            for x in 0..side {
                let (fx, fy) = (x as f32 / side as f32, y as f32 / side as f32);
                let s = seed as f32;
                let ridge = 1.0 - ((fx * 7.3 + s).sin() * (fy * 5.1 - s).cos()).abs();
                let waves = (fx * 23.0 + fy * 17.0 + s).sin() * 0.2;
                let hash = (x as u32)
                    .wrapping_mul(0x9E37_79B1)
                    .wrapping_add((y as u32).wrapping_mul(0x85EB_CA77))
                    .wrapping_add(seed.wrapping_mul(0xC2B2_AE3D));
                let noise = ((hash >> 8) & 0xFFFF) as f32 / 65535.0 - 0.5;
                h.push(relief_m * (ridge + waves + 0.02 * noise));
            }
        }
        HeightGrid::new(side, h).expect("valid synthetic grid")
    }
}
