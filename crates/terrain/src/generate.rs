//! Generating one tile of the procedural planet.
//!
//! A tile is evaluated on three grids over its rectangle:
//!
//! ```text
//!  coarse grid: the 33 x 33 mesh vertices plus rings (38 x 38, indices -2..=35)
//!  mid grid:    2x denser, 65 x 65 plus rings (69 x 69, indices -2..=66)
//!  fine grid:   4x denser, 129 x 129 plus one ring (131 x 131, indices -1..=129)
//! ```
//!
//! The continent-scale fields and every relief octave whose wavelength is at least half the
//! tile (16 mesh cells) are evaluated on the coarse grid and carried to the mid grid by
//! Catmull-Rom interpolation (for a wavelength of 16 cells its error is below 2e-4 of the
//! octave's amplitude). Octaves of 2 to 16 mesh cells (4 to 32 mid samples a wavelength) are
//! added at every mid sample, and the sum is carried on to the fine grid likewise. The
//! remaining octaves, down to twice the fine spacing, are evaluated at every fine sample.
//! Octaves finer than that are left out and their largest possible contribution is added to
//! the tile's geometric error. Mesh vertices are samples of all three grids, where
//! interpolation is exact: their heights are the direct sum. Between them a mid octave's
//! gully crest is rounded over about one mid cell (half a mesh cell), below what the mesh
//! draws; the colour's slope shading sees it a little softer. The outer ring of the height
//! grid is evaluated directly.
//!
//! Why the mid grid: in the mountains the gully octaves (slope-following stripes, several
//! times a noise octave's cost) take most of a tile's time, and the three coarsest of those at
//! fine samples cost as much at a quarter of the samples. `cargo bench -p globus-terrain
//! --bench terrain -- "generate_tile alps"` on a 2-core machine, medians: level 10 14.65 ms on
//! two grids, 12.32 with octaves of 4-16 cells on the mid grid, 10.45 with 2-16 cells; level
//! 14 16.36, 13.45 and 11.52 ms. Mesh heights and geometric errors are unchanged (mesh
//! vertices are exact either way); colour images differ from the two grids' by 0.21-0.57 of
//! 255 on average (1.5 % of texels by more than 8 at level 10; side by side I could not tell
//! them apart).
//!
//! Which octaves are used depends only on the tile's level, and positions on a shared edge
//! are computed from the shared edge coordinates, so neighbours at the same level produce
//! bit-identical edge heights. Interpolation along an edge uses only edge samples, which
//! keeps that true for the interpolated part as well.

use globus_geo::{Cartographic, DVec3};
use globus_tiling::{GLOBE_SCHEME, GeoRect, TileKey};

use crate::biome::{self, Surface};
use crate::grid::{COLOUR_SIZE, HEIGHT_GRID_SIDE, MESH_SEGMENTS, interpolate_in_cell};
use crate::planet::{Drainage, Fields, ProceduralPlanet, Relief};
use crate::tile::{ColourImage, TerrainTile, height_range};

/// Fine samples per mesh cell.
const OVERSAMPLE: i32 = 4;
/// Fine cells per tile side (equal to the colour size: one texel per fine cell).
const FINE: i32 = MESH_SEGMENTS as i32 * OVERSAMPLE;
/// Fine grid: fine indices -1..=129.
const FINE_LO: i32 = -1;
const FINE_SIDE: usize = FINE as usize + 3;

/// A square grid of samples over the tile: `cells` cells across it, indices `lo..lo + side`
/// (0 on the west/north edge, `cells` on the east/south edge).
#[derive(Clone, Copy, Debug, PartialEq)]
struct Grid {
    lo: i32,
    side: usize,
    cells: i32,
}

impl Grid {
    fn index(&self, i: i32, j: i32) -> usize {
        (j - self.lo) as usize * self.side + (i - self.lo) as usize
    }
}

/// Mesh vertices with the rings the mid grid's Catmull-Rom taps reach (-2..=35).
const COARSE: Grid = Grid {
    lo: -2,
    side: MESH_SEGMENTS as usize + 6,
    cells: MESH_SEGMENTS as i32,
};
/// Twice as dense, with the rings the fine grid's taps reach (-2..=66).
const MID: Grid = Grid {
    lo: -2,
    side: 2 * MESH_SEGMENTS as usize + 5,
    cells: 2 * MESH_SEGMENTS as i32,
};
/// The fine samples: mesh vertices every 4th, one colour texel per cell.
const FINE_GRID: Grid = Grid {
    lo: FINE_LO,
    side: FINE_SIDE,
    cells: FINE,
};

/// Wavelength of the vegetation patch field, metres (see [`ProceduralPlanet::patches`]).
const PATCH_WAVELENGTH_M: f64 = 8_000.0;

/// Octaves at least this many mesh cells long are evaluated on the coarse grid.
const COARSE_OCTAVE_CELLS: f64 = 16.0;
/// Octaves at least this many mesh cells long (4 mid samples) are evaluated on the mid grid.
const MID_OCTAVE_CELLS: f64 = 2.0;

/// Quantities carried from the coarse to the fine grid.
#[derive(Clone, Copy, Default)]
struct Coarse {
    fields: Fields,
    patches: f64,
    /// Sum of the coarse relief octaves, metres.
    relief_m: f64,
    /// Their drainage (see [`ProceduralPlanet::relief_term`]).
    drainage: Drainage,
    /// Colour texture from the coarse detail octaves (see [`texture_weight`]).
    texture: f64,
}

impl Coarse {
    fn weighted_sum(items: [(&Coarse, f64); 4]) -> Coarse {
        let mut out = Coarse::default();
        for (c, w) in items {
            out.fields.base_m += w * c.fields.base_m;
            out.fields.mountains += w * c.fields.mountains;
            out.fields.roughness += w * c.fields.roughness;
            out.fields.moisture += w * c.fields.moisture;
            out.patches += w * c.patches;
            out.relief_m += w * c.relief_m;
            out.drainage.gradient += w * c.drainage.gradient;
            out.drainage.bend += w * c.drainage.bend;
            out.texture += w * c.texture;
        }
        // Cubic interpolation can overshoot slightly; weights stay non-negative.
        out.fields.mountains = out.fields.mountains.max(0.0);
        out.fields.roughness = out.fields.roughness.max(0.0);
        out.drainage.bend = out.drainage.bend.max(0.0);
        out
    }
}

/// A point of a grid: the surface point, its up vector and latitude.
#[derive(Clone, Copy, Default)]
struct GridPoint {
    surface: DVec3,
    up: DVec3,
    lat_rad: f64,
}

/// How the octaves of one level are split between the grids.
struct OctavePlan {
    /// Octaves on the coarse grid, with their amplitudes (metres at weight 1) and texture
    /// weights.
    coarse: Vec<(Relief, f64, f64)>,
    /// Octaves on the mid grid, likewise.
    mid: Vec<(Relief, f64, f64)>,
    /// Octaves at every fine sample, likewise.
    fine: Vec<(Relief, f64, f64)>,
    /// Octaves shorter than this are left out, metres.
    finest_m: f64,
    /// Weight of the vegetation patch field: faded out where the coarse grid is too sparse
    /// to sample its 8 km wavelength (it would alias into blotches).
    patch_weight: f64,
}

/// How much an octave's shape varies the ground colour. Detail octaves up to 20 km each add
/// a fixed variation (stronger below 50 m and in the texture octaves, as grain, stones and
/// grass are contrasty), whatever the level: a coarse tile shows the average of what its
/// children show (the finer octaves average out), so colours match across LOD changes while
/// every zoom level adds texture at its own scale.
fn texture_weight(planet: &ProceduralPlanet, r: Relief) -> f64 {
    match r {
        Relief::Detail(_) if planet.wavelength_m(r) <= 50.0 => 0.5,
        Relief::Detail(_) if planet.wavelength_m(r) <= 20_000.0 => 0.25,
        Relief::Texture(_) => 0.8,
        _ => 0.0,
    }
}

impl OctavePlan {
    fn for_tile(planet: &ProceduralPlanet, tile_ns_m: f64) -> Self {
        let mesh_spacing = tile_ns_m / f64::from(MESH_SEGMENTS);
        let fine_spacing = mesh_spacing / f64::from(OVERSAMPLE);
        let finest_m = 2.0 * fine_spacing;
        let split = COARSE_OCTAVE_CELLS * mesh_spacing;
        let mid_split = MID_OCTAVE_CELLS * mesh_spacing;
        let mut coarse = Vec::new();
        let mut mid = Vec::new();
        let mut fine = Vec::new();
        for r in planet.relief_octaves() {
            let wl = planet.wavelength_m(r);
            let entry = (r, planet.amplitude_m(r), texture_weight(planet, r));
            if wl >= split {
                coarse.push(entry);
            } else if wl >= mid_split {
                mid.push(entry);
            } else if wl >= finest_m {
                fine.push(entry);
            }
        }
        let patch_weight = crate::planet::smoothstep(2.0, 6.0, PATCH_WAVELENGTH_M / mesh_spacing);
        Self {
            coarse,
            mid,
            fine,
            finest_m,
            patch_weight,
        }
    }
}

/// Catmull-Rom weights for fraction `t` of the interval between samples 0 and 1
/// (samples -1, 0, 1, 2).
pub(crate) fn catmull_rom(t: f64) -> [f64; 4] {
    let t2 = t * t;
    let t3 = t2 * t;
    [
        0.5 * (-t3 + 2.0 * t2 - t),
        0.5 * (3.0 * t3 - 5.0 * t2 + 2.0),
        0.5 * (-3.0 * t3 + 4.0 * t2 + t),
        0.5 * (t3 - t2),
    ]
}

/// `a` at t = 0 and `b` at t = 1 exactly (so shared edges are bit-identical).
pub(crate) fn lerp_exact(a: f64, b: f64, t: f64) -> f64 {
    a * (1.0 - t) + b * t
}

impl ProceduralPlanet {
    /// Generates the engine's terrain tile `key` ([`GLOBE_SCHEME`]).
    pub fn generate_tile(&self, key: TileKey) -> TerrainTile {
        let rect = GLOBE_SCHEME.rect(key);
        let tile_ns_m = rect.height() * self.ellipsoid().mean_radius();
        let plan = OctavePlan::for_tile(self, tile_ns_m);
        let coarse_pts = self.grid_points(&rect, COARSE);
        let fine_pts = self.grid_points(&rect, FINE_GRID);
        let coarse = self.evaluate_coarse(&coarse_pts, &plan);
        let fine_coarse = if plan.mid.is_empty() {
            upsample(&coarse, COARSE, FINE_GRID)
        } else {
            let mut mid = upsample(&coarse, COARSE, MID);
            for (c, pt) in mid.iter_mut().zip(self.grid_points(&rect, MID)) {
                let (relief_m, texture) =
                    self.relief_sum(&plan.mid, &c.fields, pt.surface, &mut c.drainage);
                c.relief_m += relief_m;
                c.texture += texture;
            }
            upsample(&mid, MID, FINE_GRID)
        };
        // Fine heights (raw, negative under water) and the colour texture.
        let mut raw = vec![0.0; FINE_SIDE * FINE_SIDE];
        let mut micro = vec![0.0; FINE_SIDE * FINE_SIDE];
        for (idx, pt) in fine_pts.iter().enumerate() {
            let c = &fine_coarse[idx];
            let mut drainage = c.drainage;
            let (fine_m, texture) =
                self.relief_sum(&plan.fine, &c.fields, pt.surface, &mut drainage);
            raw[idx] = c.fields.base_m + c.relief_m + fine_m;
            micro[idx] = (c.texture + texture).clamp(-1.0, 1.0);
        }
        let heights_m = self.mesh_heights(&coarse, &coarse_pts, &raw, &plan);
        let rendered: Vec<f64> = raw.iter().map(|h| h.max(0.0)).collect();
        let max_weights = coarse.iter().fold(Fields::default(), |m, c| Fields {
            mountains: m.mountains.max(c.fields.mountains),
            roughness: m.roughness.max(c.fields.roughness),
            ..m
        });
        let mesh_error = mesh_deviation(&heights_m, &rendered);
        let bulge = crate::grid::mesh_bulge_m(self.ellipsoid(), &rect);
        let omitted = self.omitted_amplitude_m(plan.finest_m, &max_weights);
        let colour = self.colour_image(&fine_pts, &fine_coarse, &raw, &rendered, &micro);
        let (min_h, max_h) = height_range(&heights_m);
        TerrainTile {
            key,
            rect,
            heights_m,
            colour,
            geometric_error_m: mesh_error + bulge + omitted,
            texel_size_m: tile_ns_m / f64::from(COLOUR_SIZE),
            min_height_m: min_h,
            max_height_m: max_h,
        }
    }

    /// Surface points of `grid` over the rectangle.
    fn grid_points(&self, rect: &GeoRect, grid: Grid) -> Vec<GridPoint> {
        let Grid { lo, side, cells } = grid;
        let e = self.ellipsoid();
        let lons: Vec<f64> = (0..side)
            .map(|i| {
                lerp_exact(
                    rect.west,
                    rect.east,
                    f64::from(lo + i as i32) / f64::from(cells),
                )
            })
            .collect();
        let mut out = Vec::with_capacity(side * side);
        for j in 0..side {
            let lat = lerp_exact(
                rect.north,
                rect.south,
                f64::from(lo + j as i32) / f64::from(cells),
            );
            for &lon in &lons {
                let c = Cartographic::new(lon, lat, 0.0);
                out.push(GridPoint {
                    surface: e.cartographic_to_ecef(c),
                    up: e.geodetic_normal_from_lon_lat(lon, lat),
                    lat_rad: lat,
                });
            }
        }
        out
    }

    fn evaluate_coarse(&self, pts: &[GridPoint], plan: &OctavePlan) -> Vec<Coarse> {
        pts.iter()
            .map(|pt| {
                let fields = self.fields(pt.surface);
                let mut drainage = Drainage::default();
                let (relief_m, texture) =
                    self.relief_sum(&plan.coarse, &fields, pt.surface, &mut drainage);
                Coarse {
                    fields,
                    patches: self.patches(pt.surface) * plan.patch_weight,
                    relief_m,
                    drainage,
                    texture,
                }
            })
            .collect()
    }

    /// Relief of the mid and fine octaves at `p` (metres), continuing the coarse octaves'
    /// drainage.
    fn finer_relief(&self, plan: &OctavePlan, coarse: &Coarse, p: DVec3) -> f64 {
        let mut drainage = coarse.drainage;
        let (mid, _) = self.relief_sum(&plan.mid, &coarse.fields, p, &mut drainage);
        let (fine, _) = self.relief_sum(&plan.fine, &coarse.fields, p, &mut drainage);
        mid + fine
    }

    /// Sum of the given octaves' relief (metres) and colour texture at `p`.
    #[inline]
    fn relief_sum(
        &self,
        octaves: &[(Relief, f64, f64)],
        fields: &Fields,
        p: DVec3,
        drainage: &mut Drainage,
    ) -> (f64, f64) {
        let mut height = 0.0;
        let mut texture = 0.0;
        for &(r, a, t) in octaves {
            let w = Self::relief_weight(r, fields);
            let shape = self.relief_term(r, p, a, w, drainage);
            height += a * w * shape;
            texture += t * shape;
        }
        (height, texture)
    }

    /// The height grid with its border ring: interior vertices are fine samples, the ring is
    /// evaluated directly at its coarse-grid points.
    fn mesh_heights(
        &self,
        coarse: &[Coarse],
        coarse_pts: &[GridPoint],
        raw: &[f64],
        plan: &OctavePlan,
    ) -> Vec<f32> {
        let side = HEIGHT_GRID_SIDE as i32;
        let mut out = Vec::with_capacity(HEIGHT_GRID_SIDE * HEIGHT_GRID_SIDE);
        for j in -1..side - 1 {
            for i in -1..side - 1 {
                let interior = (0..=MESH_SEGMENTS as i32).contains(&i)
                    && (0..=MESH_SEGMENTS as i32).contains(&j);
                let h = if interior {
                    raw[fine_index(i * OVERSAMPLE, j * OVERSAMPLE)]
                } else {
                    let ci = COARSE.index(i, j);
                    let c = &coarse[ci];
                    c.fields.base_m
                        + c.relief_m
                        + self.finer_relief(plan, c, coarse_pts[ci].surface)
                };
                out.push(h.max(0.0) as f32);
            }
        }
        out
    }

    fn colour_image(
        &self,
        pts: &[GridPoint],
        coarse: &[Coarse],
        raw: &[f64],
        rendered: &[f64],
        micro: &[f64],
    ) -> ColourImage {
        // Normals of the rendered surface at fine samples 0..=FINE (central differences).
        let n = FINE as usize + 1;
        let mut slope_cos = vec![1.0; n * n];
        let pos = |i: i32, j: i32| {
            let k = fine_index(i, j);
            pts[k].surface + pts[k].up * rendered[k]
        };
        for j in 0..=FINE {
            for i in 0..=FINE {
                let east = pos(i + 1, j) - pos(i - 1, j);
                let south = pos(i, j + 1) - pos(i, j - 1);
                let up = pts[fine_index(i, j)].up;
                slope_cos[j as usize * n + i as usize] = south
                    .cross(east)
                    .try_normalize()
                    .map_or(1.0, |nrm| nrm.dot(up));
            }
        }
        let size = COLOUR_SIZE as usize;
        let mut px = vec![0u8; size * size * 4];
        for ty in 0..size {
            for tx in 0..size {
                let mut s = Surface::default();
                for (dx, dy) in [(0, 0), (1, 0), (0, 1), (1, 1)] {
                    let (i, j) = ((tx + dx) as i32, (ty + dy) as i32);
                    let k = fine_index(i, j);
                    s.height_m += raw[k] * 0.25;
                    s.slope_cos += slope_cos[(ty + dy) * n + tx + dx] * 0.25;
                    s.abs_lat_rad += pts[k].lat_rad.abs() * 0.25;
                    s.moisture += coarse[k].fields.moisture * 0.25;
                    s.patches += coarse[k].patches * 0.25;
                    s.micro += micro[k] * 0.25;
                }
                let c = biome::colour(&s);
                px[(ty * size + tx) * 4..][..4].copy_from_slice(&c);
            }
        }
        ColourImage::with_mips(COLOUR_SIZE, px)
    }
}

fn fine_index(i: i32, j: i32) -> usize {
    FINE_GRID.index(i, j)
}

/// Catmull-Rom upsampling of quantities on grid `from` onto the denser grid `to` (rows,
/// then columns); `to.cells` is a multiple of `from.cells`, and `from`'s rings hold every
/// tap `to` needs.
fn upsample(src: &[Coarse], from: Grid, to: Grid) -> Vec<Coarse> {
    let factor = to.cells / from.cells;
    // For each index of `to`: the first of the four indices of `from` and the weights.
    let taps: Vec<(usize, [f64; 4])> = (0..to.side as i32)
        .map(|f| {
            let fi = f + to.lo;
            let base = fi.div_euclid(factor);
            let t = f64::from(fi.rem_euclid(factor)) / f64::from(factor);
            ((base - 1 - from.lo) as usize, catmull_rom(t))
        })
        .collect();
    let mut rows = vec![Coarse::default(); from.side * to.side];
    for cj in 0..from.side {
        for (fi, &(first, w)) in taps.iter().enumerate() {
            let at = |k: usize| &src[cj * from.side + first + k];
            rows[cj * to.side + fi] =
                Coarse::weighted_sum([(at(0), w[0]), (at(1), w[1]), (at(2), w[2]), (at(3), w[3])]);
        }
    }
    let mut out = vec![Coarse::default(); to.side * to.side];
    for (fj, &(first, w)) in taps.iter().enumerate() {
        for fi in 0..to.side {
            let at = |k: usize| &rows[(first + k) * to.side + fi];
            out[fj * to.side + fi] =
                Coarse::weighted_sum([(at(0), w[0]), (at(1), w[1]), (at(2), w[2]), (at(3), w[3])]);
        }
    }
    out
}

/// Largest difference between the fine samples and the mesh drawn through the vertices.
fn mesh_deviation(heights_m: &[f32], fine: &[f64]) -> f64 {
    let h = |i: i32, j: i32| {
        f64::from(heights_m[((j + 1) as usize) * HEIGHT_GRID_SIDE + (i + 1) as usize])
    };
    let mut worst: f64 = 0.0;
    for cj in 0..MESH_SEGMENTS as i32 {
        for ci in 0..MESH_SEGMENTS as i32 {
            let (nw, ne, sw, se) = (h(ci, cj), h(ci + 1, cj), h(ci, cj + 1), h(ci + 1, cj + 1));
            for dj in 0..=OVERSAMPLE {
                for di in 0..=OVERSAMPLE {
                    let s = f64::from(di) / f64::from(OVERSAMPLE);
                    let t = f64::from(dj) / f64::from(OVERSAMPLE);
                    let mesh = interpolate_in_cell(ci, cj, nw, ne, sw, se, s, t);
                    let f = fine[fine_index(ci * OVERSAMPLE + di, cj * OVERSAMPLE + dj)];
                    worst = worst.max((f - mesh).abs());
                }
            }
        }
    }
    worst
}

#[cfg(test)]
mod tests {
    use super::*;
    use crate::grid::MESH_SIDE;

    #[test]
    fn catmull_rom_weights_sum_to_one_and_interpolate() {
        for t in [0.0, 0.25, 0.5, 0.75] {
            let w = catmull_rom(t);
            assert!((w.iter().sum::<f64>() - 1.0).abs() < 1e-12);
        }
        assert_eq!(catmull_rom(0.0), [0.0, 1.0, 0.0, 0.0]);
    }

    #[test]
    fn neighbours_share_edge_heights_exactly() {
        let planet = ProceduralPlanet::new(11);
        for (a, b, horizontal) in [
            (TileKey::new(9, 533, 110), TileKey::new(9, 534, 110), true),
            (
                TileKey::new(14, 17_000, 4_000),
                TileKey::new(14, 17_000, 4_001),
                false,
            ),
            // Across the antimeridian.
            (TileKey::new(6, 127, 20), TileKey::new(6, 0, 20), true),
        ] {
            let ta = planet.generate_tile(a);
            let tb = planet.generate_tile(b);
            let last = MESH_SEGMENTS as i32;
            for k in 0..MESH_SIDE as i32 {
                let (ha, hb) = if horizontal {
                    (ta.height_at(last, k), tb.height_at(0, k))
                } else {
                    (ta.height_at(k, last), tb.height_at(k, 0))
                };
                if a.x() == 127 {
                    // 180 E and 180 W are the same meridian but computed from different
                    // longitudes: equal to rounding.
                    assert!((ha - hb).abs() < 1e-3, "{a:?}|{b:?} at {k}: {ha} vs {hb}");
                } else {
                    assert_eq!(ha, hb, "{a:?}|{b:?} at {k}");
                }
            }
            // The border ring holds the neighbour's next row of vertices.
            let (ra, rb) = if horizontal {
                (ta.height_at(last + 1, 5), tb.height_at(1, 5))
            } else {
                (ta.height_at(5, last + 1), tb.height_at(5, 1))
            };
            assert!(
                (ra - rb).abs() < 0.01 + 1e-3 * ra.abs(),
                "ring {ra} vs {rb}"
            );
        }
    }

    #[test]
    fn heights_match_direct_evaluation() {
        let planet = ProceduralPlanet::new(2);
        for key in [
            TileKey::new(3, 4, 2),
            TileKey::new(12, 2_170, 980),
            TileKey::new(20, 1_110_000, 480_000),
        ] {
            let t = planet.generate_tile(key);
            let rect = t.rect;
            let tile_ns_m = rect.height() * planet.ellipsoid().mean_radius();
            let finest = 2.0 * tile_ns_m / f64::from(FINE);
            for (i, j) in [(0, 0), (7, 19), (32, 32), (16, 3)] {
                let lon = lerp_exact(rect.west, rect.east, f64::from(i) / 32.0);
                let lat = lerp_exact(rect.north, rect.south, f64::from(j) / 32.0);
                let p = planet
                    .ellipsoid()
                    .cartographic_to_ecef(Cartographic::new(lon, lat, 0.0));
                let direct = planet.height_m(p, finest).max(0.0);
                let got = f64::from(t.height_at(i, j));
                // Coarse octaves are interpolated between vertices but exact on them, and the
                // fields are exact on vertices too: only f32 storage rounds.
                assert!(
                    (got - direct).abs() < 1e-3 + 1e-6 * direct.abs(),
                    "{key:?} ({i},{j}): {got} vs {direct}"
                );
            }
            assert!(t.geometric_error_m > 0.0);
        }
    }

    #[test]
    fn geometric_error_shrinks_with_level() {
        let planet = ProceduralPlanet::new(4);
        let mut key = TileKey::new(22, 4_350_000, 1_150_000);
        let mut errors = Vec::new();
        while let Some(p) = key.parent() {
            if key.level() % 4 == 2 {
                errors.push(planet.generate_tile(key).geometric_error_m);
            }
            key = p;
        }
        for w in errors.windows(2) {
            assert!(
                w[0] < w[1],
                "deeper tiles must be more accurate: {errors:?}"
            );
        }
    }
}
