//! Procedural refinement below the data (Plooy's "procedural detail below the finest real
//! level"): tiles deeper than a source's data, invented from the deepest real tile above them.
//!
//! A refined tile at level `L` below a base tile at level `N` is a function of position only:
//!
//! ```text
//!   height(p) = cubic(base heights)(p) + amp(p) * sum_{k < L - N} w_k * noise_k(p)
//!   amp(p)    = min(gain * roughness(p), 0.5 * max(cubic(p), 0))
//!   colour(p) = bilinear(base colour)(p) * (1 + contrast(p) * sum_k c * noise'_k(p))
//! ```
//!
//! * `cubic` is Catmull-Rom over the base grid (smooth, exact at base samples); `roughness` is a
//!   hidden layer derived from the base: the largest second difference of the base heights at
//!   each base sample, interpolated bilinearly. Flat plains (roughness 0) stay flat, mountains
//!   get crags, and the `0.5 * height` cap keeps the sea and the land near it flat (detail can
//!   never push land below sea level).
//! * Octave `k` has wavelength `2 s / 2^k` (`s` the base sample spacing), so it appears at level
//!   `N + 1 + k` with four samples per wavelength; weights `w_k = (1 - q) q^k`, `q = 2^-H`
//!   (fractal, Hurst exponent `H`) sum to at most 1.
//! * Noise is evaluated at the point of the ellipsoid under each sample (seeded gradient noise
//!   in ECEF, [`crate::noise`]), and base coordinates are snapped to exact samples on base tile
//!   borders, so neighbours compute the same heights on shared edges (and their border rings
//!   agree with each other's interiors to the precision of the cubic's one-sided end), and the
//!   same key always gives the same tile.
//! * From level `L` to `L + 1` the surface changes by one octave, at most `amp * w * 1.1`, which
//!   is inside the parent's geometric error (the bound of everything it leaves out plus its
//!   measured interpolation error): LOD transitions do not jump.

use globus_geo::{Cartographic, Ellipsoid};
use globus_tiling::{GLOBE_SCHEME, GeoRect, TileKey};

use crate::generate::{catmull_rom, lerp_exact};
use crate::grid::{COLOUR_SIZE, HEIGHT_GRID_SIDE, MESH_SEGMENTS, mesh_height_at};
use crate::noise::{NOISE_BOUND, Octaves};
use crate::planet::smoothstep;
use crate::tile::{ColourImage, TerrainTile, height_range};

/// Parameters of the invented detail.
#[derive(Clone, Copy, Debug, PartialEq)]
pub struct RefineOptions {
    /// Seed of the detail noise.
    pub seed: u64,
    /// Total detail amplitude per metre of base roughness (largest second difference).
    pub roughness_gain: f64,
    /// Hurst exponent: how fast amplitude falls with wavelength (0.5 rough .. 1 smooth).
    pub hurst: f64,
    /// Colour modulation per octave on rough land (halved on smooth land, a fifth on water).
    pub colour_contrast: f64,
}

impl Default for RefineOptions {
    fn default() -> Self {
        Self {
            seed: 0x5eed_0fde_7a11,
            roughness_gain: 1.5,
            hurst: 0.8,
            colour_contrast: 0.07,
        }
    }
}

/// Why a tile cannot be refined.
#[derive(Debug, Clone, PartialEq, thiserror::Error)]
pub enum RefineError {
    /// The base tile is not an ancestor of the requested tile (or is the tile itself).
    #[error("tile {key} cannot be refined from {base}: not a descendant")]
    NotADescendant {
        /// The requested tile.
        key: TileKey,
        /// The base tile.
        base: TileKey,
    },
    /// The base tile's grid does not have the expected size.
    #[error("base tile {0} has a malformed height grid or colour image")]
    MalformedBase(TileKey),
}

/// Octaves in the detail family (enough for 40 levels below the data).
const OCTAVES: usize = 40;
const SIDE: usize = HEIGHT_GRID_SIDE;

/// The base tile prepared for evaluation: its rectangle, grids and hidden roughness layer.
struct Base<'a> {
    tile: &'a TerrainTile,
    rect: GeoRect,
    /// Largest second difference at base samples 0..=32, row-major 33 x 33.
    roughness: Vec<f64>,
    /// Base sample spacing, metres (north-south).
    spacing_m: f64,
}

impl<'a> Base<'a> {
    fn new(tile: &'a TerrainTile, radius_m: f64) -> Self {
        let n = MESH_SEGMENTS as i32;
        let h = |i: i32, j: i32| f64::from(tile.height_at(i, j));
        let mut roughness = Vec::with_capacity(((n + 1) * (n + 1)) as usize);
        for j in 0..=n {
            for i in 0..=n {
                let dxx = h(i - 1, j) + h(i + 1, j) - 2.0 * h(i, j);
                let dyy = h(i, j - 1) + h(i, j + 1) - 2.0 * h(i, j);
                roughness.push(dxx.abs().max(dyy.abs()));
            }
        }
        Self {
            tile,
            rect: tile.rect,
            roughness,
            spacing_m: tile.rect.height() / f64::from(MESH_SEGMENTS) * radius_m,
        }
    }

    /// Base grid coordinates of a position, snapped to exact samples within 1e-9 of one.
    fn grid_xy(&self, lon: f64, lat: f64) -> (f64, f64) {
        let (u, v) = self.rect.uv(lon, lat);
        let snap = |t: f64| {
            let x = t * f64::from(MESH_SEGMENTS);
            if (x - x.round()).abs() < 1e-9 {
                x.round()
            } else {
                x
            }
        };
        (snap(u), snap(v))
    }

    /// Catmull-Rom of the base heights at grid coordinates (samples -1..=33 available).
    fn cubic(&self, x: f64, y: f64) -> f64 {
        let lo = -1i32;
        let hi = MESH_SEGMENTS as i32 + 1;
        let cell = |c: f64| (c.floor() as i32).clamp(lo, hi - 1);
        let (cx, cy) = (cell(x), cell(y));
        let (wx, wy) = (
            catmull_rom(x - f64::from(cx)),
            catmull_rom(y - f64::from(cy)),
        );
        // One sample beyond the ring (a cell past it) is extrapolated linearly from the ring
        // and the sample inside it, so a refined tile's own ring, half a base cell outside the
        // base, follows the slope instead of flattening.
        let sample = |i: i32, j: i32| {
            let h = |i: i32, j: i32| f64::from(self.tile.height_at(i, j));
            // Per axis: the nearest ring sample, and the one inside it where outside.
            let near = |k: i32| k.clamp(lo, hi);
            let inward = |k: i32| {
                if k > hi {
                    hi - 1
                } else if k < lo {
                    lo + 1
                } else {
                    k
                }
            };
            if (near(i), near(j)) == (i, j) {
                h(i, j)
            } else {
                2.0 * h(near(i), near(j)) - h(inward(i), inward(j))
            }
        };
        let mut sum = 0.0;
        for (b, wyb) in wy.iter().enumerate() {
            let j = (cy - 1 + b as i32).clamp(lo - 1, hi + 1);
            let mut row = 0.0;
            for (a, wxa) in wx.iter().enumerate() {
                let i = (cx - 1 + a as i32).clamp(lo - 1, hi + 1);
                row += wxa * sample(i, j);
            }
            sum += wyb * row;
        }
        sum
    }

    /// Bilinear roughness at grid coordinates (clamped to the tile).
    fn roughness(&self, x: f64, y: f64) -> f64 {
        let n = MESH_SEGMENTS as usize;
        let (x, y) = (x.clamp(0.0, n as f64), y.clamp(0.0, n as f64));
        let (i, j) = (
            (x.floor() as usize).min(n - 1),
            (y.floor() as usize).min(n - 1),
        );
        let (fx, fy) = (x - i as f64, y - j as f64);
        let r = |a: usize, b: usize| self.roughness[b * (n + 1) + a];
        let top = r(i, j) * (1.0 - fx) + r(i + 1, j) * fx;
        let bottom = r(i, j + 1) * (1.0 - fx) + r(i + 1, j + 1) * fx;
        top * (1.0 - fy) + bottom * fy
    }

    /// Bilinear base colour (RGBA) at a position (texel centres at (k + 0.5) / size).
    fn colour(&self, lon: f64, lat: f64) -> [f64; 4] {
        let size = self.tile.colour.size as usize;
        let px = &self.tile.colour.mips[0];
        let (u, v) = self.rect.uv(lon, lat);
        let x = (u * size as f64 - 0.5).clamp(0.0, (size - 1) as f64);
        let y = (v * size as f64 - 0.5).clamp(0.0, (size - 1) as f64);
        let (i, j) = (
            (x.floor() as usize).min(size - 2),
            (y.floor() as usize).min(size - 2),
        );
        let (fx, fy) = (x - i as f64, y - j as f64);
        let at = |a: usize, b: usize, c: usize| f64::from(px[(b * size + a) * 4 + c]);
        std::array::from_fn(|c| {
            let top = at(i, j, c) * (1.0 - fx) + at(i + 1, j, c) * fx;
            let bottom = at(i, j + 1, c) * (1.0 - fx) + at(i + 1, j + 1, c) * fx;
            top * (1.0 - fy) + bottom * fy
        })
    }
}

/// Generates refined tiles below base tiles; holds the noise families.
#[derive(Clone, Debug)]
pub struct Refiner {
    options: RefineOptions,
    ellipsoid: Ellipsoid,
}

impl Refiner {
    /// A refiner on `ellipsoid`.
    pub fn new(options: RefineOptions, ellipsoid: Ellipsoid) -> Self {
        Self { options, ellipsoid }
    }

    /// The options.
    pub fn options(&self) -> &RefineOptions {
        &self.options
    }

    /// The tile `key` ([`GLOBE_SCHEME`]) invented below `base`, one of its ancestors.
    pub fn refine(&self, base: &TerrainTile, key: TileKey) -> Result<TerrainTile, RefineError> {
        let depth = key.level().saturating_sub(base.key.level());
        if depth == 0 || GLOBE_SCHEME.ancestor_at(key, base.key.level()) != Some(base.key) {
            return Err(RefineError::NotADescendant {
                key,
                base: base.key,
            });
        }
        let colour_size = base.colour.size as usize;
        if base.heights_m.len() != SIDE * SIDE
            || colour_size < 2
            || base.colour.mips.first().map(Vec::len) != Some(colour_size * colour_size * 4)
        {
            return Err(RefineError::MalformedBase(base.key));
        }
        let e = &self.ellipsoid;
        let radius = e.mean_radius();
        let b = Base::new(base, radius);
        let octaves = self.height_octaves(&b);
        // Octave k is introduced at depth k + 1.
        let included = usize::from(depth).min(OCTAVES);
        let q = 2f64.powf(-self.options.hurst);
        let rect = GLOBE_SCHEME.rect(key);
        let n = f64::from(MESH_SEGMENTS);
        let lon_at = |i: f64| lerp_exact(rect.west, rect.east, i / n);
        let lat_at = |j: f64| lerp_exact(rect.north, rect.south, j / n);
        let surface =
            |lon: f64, lat: f64, count: usize| self.surface(&b, &octaves, lon, lat, count);

        let mut heights_m = Vec::with_capacity(SIDE * SIDE);
        let mut max_amp = 0.0f64;
        for j in -1..=MESH_SEGMENTS as i32 + 1 {
            for i in -1..=MESH_SEGMENTS as i32 + 1 {
                let (h, amp) = surface(lon_at(f64::from(i)), lat_at(f64::from(j)), included);
                max_amp = max_amp.max(amp);
                heights_m.push(h as f32);
            }
        }
        // Interpolation error: the mesh against the surface at every cell's centre and edge
        // midpoints (where linear interpolation of the finest octave errs most).
        let mut interpolation = 0.0f64;
        for cj in 0..MESH_SEGMENTS as i32 {
            for ci in 0..MESH_SEGMENTS as i32 {
                for (s, t) in [(0.5, 0.5), (0.5, 0.0), (0.0, 0.5)] {
                    let (lon, lat) = (lon_at(f64::from(ci) + s), lat_at(f64::from(cj) + t));
                    let mesh = mesh_height_at(&heights_m, f64::from(ci) + s, f64::from(cj) + t);
                    interpolation = interpolation.max((surface(lon, lat, included).0 - mesh).abs());
                }
            }
        }
        // Everything left out: the octaves of deeper levels, at the largest amplitude here.
        let omitted = max_amp * NOISE_BOUND * q.powi(included as i32);
        let bulge = crate::grid::mesh_bulge_m(&self.ellipsoid, &rect);
        // The measured interpolation error with a margin: midpoints see most, not all, of it.
        let geometric_error_m = 1.5 * interpolation + omitted + bulge;

        let colour = self.colour(&b, &rect, depth, max_amp);
        let (min_h, max_h) = height_range(&heights_m);
        Ok(TerrainTile {
            key,
            rect,
            heights_m,
            colour,
            geometric_error_m,
            texel_size_m: rect.height() * radius / f64::from(COLOUR_SIZE),
            min_height_m: min_h,
            max_height_m: max_h,
        })
    }

    /// The refined surface height at a longitude and latitude (radians) inside `base`, with
    /// the detail of every level down to `depth` levels below it.
    pub fn height_at(&self, base: &TerrainTile, lon_rad: f64, lat_rad: f64, depth: u8) -> f64 {
        let b = Base::new(base, self.ellipsoid.mean_radius());
        let octaves = self.height_octaves(&b);
        self.surface(
            &b,
            &octaves,
            lon_rad,
            lat_rad,
            usize::from(depth).min(OCTAVES),
        )
        .0
    }

    fn height_octaves(&self, b: &Base<'_>) -> Octaves {
        Octaves::new(self.options.seed, 2.0 * b.spacing_m, OCTAVES)
    }

    /// The surface with `count` detail octaves at a position, and the detail amplitude there.
    fn surface(
        &self,
        b: &Base<'_>,
        octaves: &Octaves,
        lon: f64,
        lat: f64,
        count: usize,
    ) -> (f64, f64) {
        let (x, y) = b.grid_xy(lon, lat);
        let smooth = b.cubic(x, y);
        let amp = (self.options.roughness_gain * b.roughness(x, y)).min(0.5 * smooth.max(0.0));
        if amp <= 0.0 || count == 0 {
            return (smooth, amp.max(0.0));
        }
        let q = 2f64.powf(-self.options.hurst);
        let p = self
            .ellipsoid
            .cartographic_to_ecef(Cartographic::new(lon, lat, 0.0));
        let detail: f64 = (0..count)
            .map(|k| (1.0 - q) * q.powi(k as i32) * octaves.octave(k, p))
            .sum();
        (smooth + amp * detail, amp)
    }

    /// The base colour resampled and modulated by noise octaves from the base texel size down
    /// to this tile's (so the ground is textured at every zoom, and a tile's colour is about
    /// the average of its children's).
    fn colour(&self, b: &Base<'_>, rect: &GeoRect, depth: u8, max_amp: f64) -> ColourImage {
        let e = &self.ellipsoid;
        let radius = e.mean_radius();
        let base_texel_m = b.rect.height() * radius / f64::from(b.tile.colour.size);
        let octaves = Octaves::new(self.options.seed ^ 0xc010_u64, 2.0 * base_texel_m, OCTAVES);
        let count = (usize::from(depth) + 1).min(OCTAVES);
        let size = COLOUR_SIZE as usize;
        let mut px = vec![0u8; size * size * 4];
        // Rough ground gets the full contrast, smooth land half, water a fifth.
        let rock = smoothstep(0.0, 5.0, max_amp);
        for ty in 0..size {
            let lat = lerp_exact(rect.north, rect.south, (ty as f64 + 0.5) / size as f64);
            for tx in 0..size {
                let lon = lerp_exact(rect.west, rect.east, (tx as f64 + 0.5) / size as f64);
                let c = b.colour(lon, lat);
                let land = c[3] >= 128.0;
                let contrast =
                    self.options.colour_contrast * if land { 0.5 + 0.5 * rock } else { 0.2 };
                let p = e.cartographic_to_ecef(Cartographic::new(lon, lat, 0.0));
                let noise: f64 = (0..count).map(|k| octaves.octave(k, p)).sum();
                let m = 1.0 + contrast * noise;
                let o = (ty * size + tx) * 4;
                for ch in 0..3 {
                    px[o + ch] = (c[ch] * m).round().clamp(0.0, 255.0) as u8;
                }
                px[o + 3] = if land { 255 } else { 0 };
            }
        }
        ColourImage::with_mips(COLOUR_SIZE, px)
    }
}

#[cfg(test)]
mod tests {
    use super::*;
    use crate::ProceduralPlanet;

    fn refiner() -> Refiner {
        Refiner::new(RefineOptions::default(), Ellipsoid::WGS84)
    }

    /// A level-10 tile of the procedural planet with much relief (found by a scan of seed 1).
    fn mountain_base() -> TerrainTile {
        ProceduralPlanet::new(1).generate_tile(TileKey::new(10, 703, 522))
    }

    fn descendant(base: TileKey, depth: u8, pick: u32) -> TileKey {
        let mut k = base;
        for d in 0..depth {
            let children = k.children().expect("children");
            k = children[((pick >> (2 * d)) & 3) as usize];
        }
        k
    }

    #[test]
    fn same_key_same_tile() {
        let base = mountain_base();
        let key = descendant(base.key, 6, 0b10_01_11_00_01_10);
        let a = refiner().refine(&base, key).expect("refine");
        let b = refiner().refine(&base, key).expect("refine");
        assert_eq!(a.heights_m, b.heights_m);
        assert_eq!(a.colour, b.colour);
        assert_eq!(a.geometric_error_m, b.geometric_error_m);
    }

    #[test]
    fn bad_bases_are_refused() {
        let base = mountain_base();
        let r = refiner();
        assert!(matches!(
            r.refine(&base, base.key),
            Err(RefineError::NotADescendant { .. })
        ));
        assert!(r.refine(&base, TileKey::new(12, 0, 0)).is_err());
        let mut broken = base.clone();
        broken.heights_m.truncate(10);
        let child = base.key.children().expect("children")[0];
        assert_eq!(
            r.refine(&broken, child).err(),
            Some(RefineError::MalformedBase(base.key))
        );
    }

    /// Neighbours agree along their shared edge, both inside one base tile and across the
    /// border between two base tiles (whose own edges agree, as the planet guarantees).
    #[test]
    fn neighbours_agree_on_shared_edges() {
        let planet = ProceduralPlanet::new(1);
        let r = refiner();
        let west_base = mountain_base();
        let east_base = planet.generate_tile(TileKey::new(10, 704, 522));
        for depth in [1u8, 4, 9] {
            let scale = 1u32 << depth;
            // Inside one base: columns 3 and 4 of its descendants, row 2.
            // Across the base border: the last column under the west base, the first under the east.
            for (wx, ex) in [
                (703 * scale + scale / 2 - 1, 703 * scale + scale / 2),
                (704 * scale - 1, 704 * scale),
            ] {
                let y = 522 * scale + 2.min(scale - 1);
                let west_key = TileKey::new(10 + depth, wx, y);
                let east_key = TileKey::new(10 + depth, ex, y);
                let base_of = |k: TileKey| {
                    if k.ancestor_at(10) == Some(west_base.key) {
                        &west_base
                    } else {
                        &east_base
                    }
                };
                let w = r.refine(base_of(west_key), west_key).expect("west");
                let e = r.refine(base_of(east_key), east_key).expect("east");
                let n = MESH_SEGMENTS as i32;
                for j in 0..=n {
                    let (a, b) = (w.height_at(n, j), e.height_at(0, j));
                    assert!(
                        (a - b).abs() <= 1e-3,
                        "depth {depth}, {west_key} | {east_key}, row {j}: {a} vs {b}"
                    );
                    // The rings reach one sample into the neighbour: close to its interior.
                    let ring = (w.height_at(n + 1, j) - e.height_at(1, j)).abs();
                    let ring_e = (e.height_at(-1, j) - w.height_at(n - 1, j)).abs();
                    assert!(
                        f64::from(ring.max(ring_e)) <= 0.05 * (w.geometric_error_m + 0.01),
                        "depth {depth} row {j}: ring off by {ring} / {ring_e} m"
                    );
                }
            }
        }
    }

    /// A child's samples stay within the parent's geometric error of the parent's mesh, so
    /// switching levels moves the surface by less than the error LOD selection accepts.
    #[test]
    fn children_stay_within_the_parent_error() {
        let base = mountain_base();
        let r = refiner();
        for pick in [0u32, 0b11_10_01, 0b01_01_01_01_01] {
            let mut parent = base.clone();
            for depth in 1..=6u8 {
                let key = descendant(base.key, depth, pick);
                let child = r.refine(&base, key).expect("child");
                let (qx, qy) = (key.x() & 1, key.y() & 1);
                let half = (MESH_SEGMENTS / 2) as i32;
                let mut worst = 0.0f64;
                for j in 0..=MESH_SEGMENTS as i32 {
                    for i in 0..=MESH_SEGMENTS as i32 {
                        // Position in parent grid units.
                        let (x, y) = (
                            f64::from(qx as i32 * half) + f64::from(i) / 2.0,
                            f64::from(qy as i32 * half) + f64::from(j) / 2.0,
                        );
                        let mesh = mesh_height_at(&parent.heights_m, x, y);
                        worst = worst.max((f64::from(child.height_at(i, j)) - mesh).abs());
                    }
                }
                assert!(
                    worst <= parent.geometric_error_m,
                    "{key}: child {worst:.3} m from the parent mesh, parent error {:.3} m",
                    parent.geometric_error_m
                );
                if depth > 1 {
                    assert!(child.geometric_error_m < parent.geometric_error_m);
                }
                parent = child;
            }
        }
    }

    #[test]
    fn plains_and_sea_stay_flat_mountains_get_crags() {
        let r = refiner();
        // A flat plateau and the sea: no detail at all.
        let mut flat = mountain_base();
        for h in flat.heights_m.iter_mut() {
            *h = 250.0;
        }
        let key = descendant(flat.key, 5, 0b1001);
        let t = r.refine(&flat, key).expect("flat");
        assert!(t.heights_m.iter().all(|&h| (h - 250.0).abs() < 1e-3));
        for h in flat.heights_m.iter_mut() {
            *h = 0.0;
        }
        let t = r.refine(&flat, key).expect("sea");
        assert!(t.heights_m.iter().all(|&h| h == 0.0));
        // Mountains: the refined surface departs from the smooth cubic by metres.
        let base = mountain_base();
        let b = Base::new(&base, Ellipsoid::WGS84.mean_radius());
        let t = r.refine(&base, key).expect("mountain");
        let rect = t.rect;
        let mut detail = 0.0f64;
        for j in 0..=32 {
            for i in 0..=32 {
                let lon = lerp_exact(rect.west, rect.east, f64::from(i) / 32.0);
                let lat = lerp_exact(rect.north, rect.south, f64::from(j) / 32.0);
                let (x, y) = b.grid_xy(lon, lat);
                detail = detail.max((f64::from(t.height_at(i, j)) - b.cubic(x, y)).abs());
            }
        }
        assert!(detail > 1.0, "mountain detail only {detail:.3} m");
    }

    /// Deep below the data the colour is textured, not a bilinear smear of one base texel.
    #[test]
    fn deep_imagery_is_textured() {
        let base = mountain_base();
        let key = descendant(base.key, 10, 0b01_10_11_00_01_10_11_00_01_10);
        let t = refiner().refine(&base, key).expect("deep");
        let px = &t.colour.mips[0];
        let size = t.colour.size as usize;
        let mut diff = 0u64;
        for y in 0..size {
            for x in 0..size - 1 {
                let a = (y * size + x) * 4;
                diff += u64::from(px[a].abs_diff(px[a + 4]));
            }
        }
        let mean = diff as f64 / (size * (size - 1)) as f64;
        // A bilinear smear across 1/8 of a base texel changes by well under 0.1 per texel.
        assert!(mean > 0.5, "mean neighbour difference {mean:.3}");
    }
}
