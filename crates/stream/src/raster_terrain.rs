//! [`RasterTerrainSource`]: engine terrain tiles built from elevation pyramids (Terrarium,
//! Terrain-RGB, centimetre; geographic or Web Mercator; corner or cell grids) and draped
//! with imagery pyramids.
//!
//! * **Elevation** layers stack bottom to top: each mesh sample takes its height from the
//!   topmost layer whose bounds hold it and which has a tile there (so an SRTM square over a
//!   coarse world DEM shows its detail where it exists). Each layer is read at the level whose
//!   samples are at least four times finer than the mesh (or its deepest), so the tile's
//!   geometric error is measured against real data: the mesh against the data on a 4x finer
//!   grid, times 1.5, plus the body's curvature between vertices.
//! * A tile is "no data" (refinement takes over, see [`crate::RefinedSource`]) once no layer
//!   holds data finer than its mesh; shallower tiles always load.
//! * **Imagery** layers are composited bottom to top with alpha into the tile's colour image,
//!   each read at the level matching the tile's texel size (Web Mercator reprojected per
//!   texel; beyond its 85 degree limit the edge row). Without imagery, heights are tinted.
//!   Below the roots the colour is a load of its own ([`TerrainSource::load_colour`]), so a
//!   tile's geometry does not wait for its imagery: the renderer shows the nearest ancestor's
//!   colour meanwhile, and the roots (which carry theirs) guarantee there is one.
//! * The one-sample ring round the grid (for normals) is extrapolated linearly from inside:
//!   neighbours' tiles are not fetched for it.

use std::ops::Add;
use std::sync::Arc;

use globus_geo::Ellipsoid;
use globus_terrain::grid::{
    COLOUR_SIZE, HEIGHT_GRID_SIDE, MESH_SEGMENTS, mesh_bulge_m, mesh_height_at,
};
use globus_terrain::{ColourImage, MeshOptions, TerrainTile};
use globus_tiling::{GLOBE_SCHEME, GeoRect, TileKey, TilingScheme};
use rustc_hash::FxHashMap;

use crate::decode::{HeightImage, Rgba};
use crate::fetch::{Cancel, FetchError};
use crate::pyramid::{RasterPyramid, Samples, bilinear};
use crate::{SourceError, TerrainData, TerrainSource, TileSource};

/// Mesh samples are checked against data this many times finer.
const OVERSAMPLE: u32 = 4;
/// A layer still has detail for a tile whose mesh spacing (or texel) is this close to the
/// layer's finest sample spacing (rounding of tile sizes like 255 vs 256 samples).
const DETAIL_TOLERANCE: f64 = 1.01;
/// Sample positions are pulled this far (a fraction of the tile) inside the tile, so
/// points on an edge read the tile being built, not its neighbour.
const EDGE_NUDGE: f64 = 1e-9;

/// Terrain from elevation pyramids (none: the bare ellipsoid), draped with imagery pyramids.
pub struct RasterTerrainSource {
    name: String,
    elevation: Vec<Arc<RasterPyramid<HeightImage>>>,
    imagery: Vec<Arc<RasterPyramid<Rgba>>>,
    ellipsoid: Ellipsoid,
    occluder: Ellipsoid,
    height_range_m: (f64, f64),
    mesh_options: MeshOptions,
    max_level: u8,
}

fn intersects(a: &GeoRect, b: &GeoRect) -> bool {
    a.west < b.east && b.west < a.east && a.south < b.north && b.south < a.north
}

fn inside(r: &GeoRect, lon: f64, lat: f64) -> bool {
    let eps = 1e-12;
    lon >= r.west - eps && lon <= r.east + eps && lat >= r.south - eps && lat <= r.north + eps
}

/// Part of a layer's extent over which it fades out towards its bounds.
const FEATHER_FRACTION: f64 = 0.03;

/// A layer's weight at a point: 0 outside its bounds, rising linearly to 1 over
/// [`FEATHER_FRACTION`] of its extent inside each edge that is not an edge of the world.
fn feather(r: &GeoRect, lon: f64, lat: f64) -> f64 {
    if !inside(r, lon, lat) {
        return 0.0;
    }
    let eps = 1e-9;
    let width = FEATHER_FRACTION * r.width().min(r.height());
    let mut w: f64 = 1.0;
    let mut edge = |d: f64, open: bool| {
        if open {
            w = w.min((d / width).clamp(0.0, 1.0));
        }
    };
    let world = GeoRect::WORLD;
    edge(lon - r.west, r.west > world.west + eps);
    edge(r.east - lon, r.east < world.east - eps);
    edge(lat - r.south, r.south > world.south + eps);
    edge(r.north - lat, r.north < world.north - eps);
    w
}

/// Sample spacing (radians of latitude at the equator) of a pyramid's deepest level.
fn finest_spacing(p: &RasterPyramid<impl Samples>) -> f64 {
    let s = p.spec();
    let span0 = match s.scheme {
        TilingScheme::Geographic | TilingScheme::GeographicReduced => std::f64::consts::PI,
        TilingScheme::WebMercator => 2.0 * std::f64::consts::PI,
    };
    let per_tile = s.tile_size.max(2) - u32::from(s.grid == crate::pyramid::SampleGrid::Corners);
    span0 / f64::from(per_tile) / f64::from(1u32 << s.max_level.min(30))
}

/// Decoded tiles one load touches, fetched once each.
struct Touched<'a, T: Samples> {
    pyramid: &'a RasterPyramid<T>,
    tiles: FxHashMap<TileKey, Option<Arc<T>>>,
}

impl<'a, T: Samples> Touched<'a, T> {
    fn new(pyramid: &'a RasterPyramid<T>) -> Self {
        Self {
            pyramid,
            tiles: FxHashMap::default(),
        }
    }

    fn get(&mut self, key: TileKey, cancel: &Cancel) -> Result<Option<Arc<T>>, FetchError> {
        self.read(key, cancel, false)
    }

    /// A tile read on a neighbour's behalf ([`RasterPyramid::tile_for_neighbour`]) or for
    /// this tile itself.
    fn read(
        &mut self,
        key: TileKey,
        cancel: &Cancel,
        for_neighbour: bool,
    ) -> Result<Option<Arc<T>>, FetchError> {
        if let Some(t) = self.tiles.get(&key) {
            return Ok(t.clone());
        }
        let t = if for_neighbour {
            self.pyramid.tile_for_neighbour(key, cancel)?
        } else {
            self.pyramid.tile(key, cancel)?
        };
        self.tiles.insert(key, t.clone());
        Ok(t)
    }

    /// Like [`Touched::get`], but a broken tile counts as missing (and is not asked again).
    fn get_or_missing(
        &mut self,
        key: TileKey,
        cancel: &Cancel,
    ) -> Result<Option<Arc<T>>, FetchError> {
        match self.get(key, cancel) {
            Err(FetchError::Permanent(_)) => {
                self.tiles.insert(key, None);
                Ok(None)
            }
            other => other,
        }
    }
}

impl RasterTerrainSource {
    /// Terrain on `ellipsoid` from `elevation` layers (bottom first), draped with `imagery`
    /// layers (bottom first). `height_range_m` bounds the true heights of tiles not loaded
    /// yet (the drawn ones are raised by `mesh_options.exaggeration`).
    pub fn new(
        elevation: Vec<Arc<RasterPyramid<HeightImage>>>,
        imagery: Vec<Arc<RasterPyramid<Rgba>>>,
        ellipsoid: Ellipsoid,
        height_range_m: (f64, f64),
        mesh_options: MeshOptions,
    ) -> Result<Self, crate::fetch::OpenError> {
        if elevation.is_empty() && imagery.is_empty() {
            return Err(crate::fetch::OpenError::Spec(
                "no elevation or imagery layer given".into(),
            ));
        }
        // The deepest engine level whose mesh (or colour image) is still coarser than some
        // layer's data.
        let mesh0 = std::f64::consts::PI / f64::from(MESH_SEGMENTS);
        let texel0 = std::f64::consts::PI / f64::from(COLOUR_SIZE);
        let deepest = |spacing: f64, unit: f64| (unit / spacing).log2().add(0.015).floor().max(0.0);
        let max_level = if elevation.is_empty() {
            imagery
                .iter()
                .map(|p| deepest(finest_spacing(p), texel0))
                .fold(0.0, f64::max)
        } else {
            elevation
                .iter()
                .map(|p| deepest(finest_spacing(p), mesh0))
                .fold(0.0, f64::max)
        }
        .min(f64::from(TileKey::MAX_LEVEL)) as u8;
        let names: Vec<&str> = elevation
            .iter()
            .map(|p| p.name())
            .chain(imagery.iter().map(|p| p.name()))
            .collect();
        Ok(Self {
            name: names.join(" + "),
            elevation,
            imagery,
            // The drawn surface: heights raised by the exaggeration.
            occluder: ellipsoid.grown(height_range_m.0.min(0.0) * mesh_options.exaggeration),
            ellipsoid,
            height_range_m: (
                height_range_m.0 * mesh_options.exaggeration,
                height_range_m.1 * mesh_options.exaggeration,
            ),
            mesh_options,
            max_level,
        })
    }

    fn fail(&self, key: TileKey, e: FetchError) -> SourceError {
        match e {
            FetchError::Transient {
                message,
                retry_after,
            } => SourceError::Transient {
                key,
                source_name: self.name.clone(),
                message,
                retry_after,
            },
            FetchError::Permanent(message) => SourceError::Failed {
                key,
                source_name: self.name.clone(),
                message,
            },
            FetchError::Cancelled => SourceError::Cancelled { key },
        }
    }

    /// Whether some imagery layer has detail at the texel size of a tile over `rect`.
    fn imagery_detailed(&self, rect: &GeoRect) -> bool {
        let texel = rect.height() / f64::from(COLOUR_SIZE);
        self.imagery.iter().any(|p| {
            intersects(rect, &p.spec().bounds) && finest_spacing(p) <= texel * DETAIL_TOLERANCE
        })
    }

    /// Heights of the 4x oversampled grid (and the mesh grid inside it), and of the ring of
    /// mesh samples one mesh cell outside the tile (in [`ring_index`] order; `None` where no
    /// layer has data there, beyond a pole or past the layers' bounds), or `None` if no layer
    /// holds data finer than this tile's mesh. The ring is read from the same layers at the
    /// same levels as the neighbouring tiles read their own samples, so normals at shared
    /// edges agree.
    fn heights(
        &self,
        key: TileKey,
        rect: &GeoRect,
        cancel: &Cancel,
    ) -> Result<Option<SampledHeights>, FetchError> {
        let mesh_spacing = rect.height() / f64::from(MESH_SEGMENTS);
        // Layers that reach this tile, with the level each is read at.
        let mut layers = Vec::new();
        let mut detailed = false;
        for p in &self.elevation {
            let s = p.spec();
            if !intersects(rect, &s.bounds) {
                continue;
            }
            let level = s.level_for_spacing(mesh_spacing / f64::from(OVERSAMPLE));
            // A layer whose shallowest tiles are far finer than this tile needs would take
            // dozens of requests per tile: leave it to deeper tiles.
            if s.ideal_level(mesh_spacing / f64::from(OVERSAMPLE)) + 1 < i32::from(s.min_level) {
                continue;
            }
            detailed |= finest_spacing(p) <= mesh_spacing * DETAIL_TOLERANCE;
            layers.push((Touched::new(p), level));
        }
        // Without elevation layers (imagery on the bare ellipsoid) imagery decides how deep
        // tiles go; with them, elevation does, and deeper imagery reaches refined tiles
        // through `has_imagery_for` and `load_colour`.
        if self.elevation.is_empty() {
            detailed = self.imagery_detailed(rect);
        }
        if !detailed && key.level() > 0 {
            return Ok(None);
        }
        let side = (MESH_SEGMENTS * OVERSAMPLE + 1) as usize;
        let n = f64::from(MESH_SEGMENTS * OVERSAMPLE);
        let mut out = Vec::with_capacity(side * side);
        let mut any_data = false;
        for j in 0..side {
            for i in 0..side {
                let inward = |f: f64| f.clamp(EDGE_NUDGE, 1.0 - EDGE_NUDGE);
                let (lon, lat) = rect.lon_lat_at(inward(i as f64 / n), inward(j as f64 / n));
                let h = height_from(&mut layers, lon, lat, false, cancel)?;
                any_data |= h.is_some();
                out.push(h.unwrap_or(0.0));
            }
            if cancel.is_cancelled() {
                return Err(FetchError::Cancelled);
            }
        }
        // Every layer answered "no tile here" (404, or a hole in an archive): no data, so
        // the ancestor stays (or refinement takes over); the roots always exist.
        if !any_data && !self.elevation.is_empty() && key.level() > 0 {
            return Ok(None);
        }
        let m = f64::from(MESH_SEGMENTS);
        let mut ring = Vec::with_capacity(RING_LEN);
        for (i, j) in ring_positions() {
            let (lon, lat) = rect.lon_lat_at(f64::from(i) / m, f64::from(j) / m);
            ring.push(if lat.abs() > std::f64::consts::FRAC_PI_2 {
                None
            } else {
                let lon = (lon + std::f64::consts::PI).rem_euclid(std::f64::consts::TAU)
                    - std::f64::consts::PI;
                // A neighbour's source tile that fails leaves the slope extrapolated: the
                // tile itself is whole.
                match height_from(&mut layers, lon, lat, true, cancel) {
                    Ok(h) => h,
                    Err(FetchError::Cancelled) => return Err(FetchError::Cancelled),
                    Err(_) => None,
                }
            });
        }
        Ok(Some((out, ring)))
    }

    fn colour(
        &self,
        rect: &GeoRect,
        heights: &[f32],
        cancel: &Cancel,
    ) -> Result<ColourImage, FetchError> {
        let size = COLOUR_SIZE as usize;
        let texel = rect.height() / f64::from(COLOUR_SIZE);
        let mut px = vec![0u8; size * size * 4];
        // Heights tinted underneath: what shows where no imagery layer covers.
        let mut acc = vec![[0f64; 3]; size * size];
        for ty in 0..size {
            for tx in 0..size {
                let x = (tx as f64 + 0.5) / size as f64 * f64::from(MESH_SEGMENTS);
                let y = (ty as f64 + 0.5) / size as f64 * f64::from(MESH_SEGMENTS);
                let c = tint(mesh_height_at(heights, x, y));
                acc[ty * size + tx] = [f64::from(c[0]), f64::from(c[1]), f64::from(c[2])];
            }
        }
        for p in &self.imagery {
            let spec = *p.spec();
            if !intersects(rect, &spec.bounds) {
                continue;
            }
            let level = spec.level_for_spacing(texel);
            let mut touched = Touched::new(p);
            let cap = polar_caps(p, &mut touched, cancel)?;
            for ty in 0..size {
                for tx in 0..size {
                    let (lon, lat) = rect.lon_lat_at(
                        (tx as f64 + 0.5) / size as f64,
                        (ty as f64 + 0.5) / size as f64,
                    );
                    if !inside(&spec.bounds, lon, lat) {
                        continue;
                    }
                    let Some(c) = sample_imagery(&mut touched, level, lon, lat, cap, cancel)?
                    else {
                        continue;
                    };
                    let alpha = c[3] / 255.0;
                    let a = &mut acc[ty * size + tx];
                    for (k, v) in a.iter_mut().enumerate() {
                        // Premultiplied "over".
                        *v = c[k] + *v * (1.0 - alpha);
                    }
                }
            }
        }
        for (i, a) in acc.iter().enumerate() {
            px[i * 4] = a[0].round().clamp(0.0, 255.0) as u8;
            px[i * 4 + 1] = a[1].round().clamp(0.0, 255.0) as u8;
            px[i * 4 + 2] = a[2].round().clamp(0.0, 255.0) as u8;
            px[i * 4 + 3] = 255;
        }
        Ok(ColourImage::with_mips(COLOUR_SIZE, px))
    }

    /// Whether a tile's imagery loads on its own: with imagery layers, below the roots.
    fn colour_separate(&self, key: TileKey) -> bool {
        !self.imagery.is_empty() && key.level() > 0
    }

    fn build(&self, key: TileKey, cancel: &Cancel) -> Result<Option<TerrainTile>, FetchError> {
        let rect = GLOBE_SCHEME.rect(key);
        let Some((fine, ring)) = self.heights(key, &rect, cancel)? else {
            return Ok(None);
        };
        let side = (MESH_SEGMENTS * OVERSAMPLE + 1) as usize;
        let o = OVERSAMPLE as usize;
        let fine_at = |i: usize, j: usize| fine[j * side + i];
        // Mesh samples are every OVERSAMPLE-th fine sample; the ring outside the tile is
        // read from the layers (as the neighbours read them), and where they have nothing
        // continues the slope of the outermost cell.
        let last = MESH_SEGMENTS as i32;
        let m = |i: i32, j: i32| fine_at(i as usize * o, j as usize * o);
        let side_of = |v: i32| match v {
            v if v < 0 => (0, 1),
            v if v > last => (last, -1),
            v => (v, 0),
        };
        let g = HEIGHT_GRID_SIDE;
        let mut heights = Vec::with_capacity(g * g);
        for j in -1..=last + 1 {
            for i in -1..=last + 1 {
                let ((ci, di), (cj, dj)) = (side_of(i), side_of(j));
                let read = ring_index(i, j).and_then(|r| ring[r]);
                let h = read.unwrap_or_else(|| {
                    let base = m(ci, cj);
                    let mut h = base;
                    if di != 0 {
                        h += base - m(ci + di, cj);
                    }
                    if dj != 0 {
                        h += base - m(ci, cj + dj);
                    }
                    h
                });
                heights.push(h as f32);
            }
        }
        let mut deviation: f64 = 0.0;
        for j in 0..side {
            for i in 0..side {
                let mesh = mesh_height_at(&heights, i as f64 / o as f64, j as f64 / o as f64);
                deviation = deviation.max((fine_at(i, j) - mesh).abs());
            }
        }
        let colour = if self.colour_separate(key) {
            // A stand-in (never drawn): the real colour is a load of its own.
            let mean = heights.iter().map(|&h| f64::from(h)).sum::<f64>() / heights.len() as f64;
            ColourImage::with_mips(1, tint(mean).to_vec())
        } else {
            self.colour(&rect, &heights, cancel)?
        };
        let (lo, hi) = heights
            .iter()
            .fold((f64::INFINITY, f64::NEG_INFINITY), |(a, b), &h| {
                (a.min(f64::from(h)), b.max(f64::from(h)))
            });
        let radius = self.ellipsoid.mean_radius();
        Ok(Some(TerrainTile {
            key,
            rect,
            heights_m: heights,
            colour,
            geometric_error_m: 1.5 * deviation + mesh_bulge_m(&self.ellipsoid, &rect),
            texel_size_m: rect.height() * radius / f64::from(COLOUR_SIZE),
            min_height_m: lo,
            max_height_m: hi,
        }))
    }
}

/// A tile's oversampled heights and its ring ([`RasterTerrainSource::heights`]).
type SampledHeights = (Vec<f64>, Vec<Option<f64>>);

/// Samples in the ring one mesh cell outside a tile.
const RING_LEN: usize = 4 * (MESH_SEGMENTS as usize + 2);

/// Mesh coordinates (`-1..=MESH_SEGMENTS + 1`) of the ring's samples, in [`ring_index`] order.
fn ring_positions() -> impl Iterator<Item = (i32, i32)> {
    let last = MESH_SEGMENTS as i32 + 1;
    (-1..=last)
        .map(move |i| (i, -1))
        .chain((-1..=last).map(move |i| (i, last)))
        .chain((0..last).map(|j| (-1, j)))
        .chain((0..last).map(move |j| (last, j)))
}

/// Where mesh coordinates (`i`, `j`) lie in the ring, `None` inside the tile.
fn ring_index(i: i32, j: i32) -> Option<usize> {
    let last = MESH_SEGMENTS as i32 + 1;
    let row = (last + 2) as usize;
    let at = |v: i32| (v + 1) as usize;
    match (i, j) {
        (_, -1) => Some(at(i)),
        (_, j) if j == last => Some(row + at(i)),
        (-1, _) => Some(2 * row + j as usize),
        (i, _) if i == last => Some(2 * row + last as usize + j as usize),
        _ => None,
    }
}

/// The height at a point from elevation layers read at their levels, top layer first (a
/// layer fades out towards its bounds, where they are not the world's edges, so its data
/// meets the layer below without a step); `None` if no layer has data there.
/// `for_neighbour`: the point is outside the tile being built (its normal ring).
fn height_from(
    layers: &mut [(Touched<'_, HeightImage>, u8)],
    lon: f64,
    lat: f64,
    for_neighbour: bool,
    cancel: &Cancel,
) -> Result<Option<f64>, FetchError> {
    let (mut h, mut remaining, mut any) = (0.0, 1.0, false);
    for (touched, level) in layers.iter_mut().rev() {
        let spec = *touched.pyramid.spec();
        let w = feather(&spec.bounds, lon, lat);
        if w <= 0.0 {
            continue;
        }
        let Some((k, px, py)) = spec.locate(lon, lat, *level) else {
            continue;
        };
        if let Some(t) = touched.read(k, cancel, for_neighbour)? {
            let v = bilinear(px, py, t.width, t.height, |x, y| {
                f64::from(t.heights_m[(y * t.width + x) as usize])
            });
            any = true;
            h += remaining * w * v;
            remaining *= 1.0 - w;
            if remaining <= 0.0 {
                break;
            }
        }
    }
    Ok(any.then_some(h))
}

/// Latitude (radians) beyond which Web Mercator imagery has nothing.
fn mercator_limit_rad() -> f64 {
    globus_tiling::WEB_MERCATOR_MAX_LAT_DEG.to_radians()
}

/// Over this many degrees of latitude past the Web Mercator limit, the last row of imagery
/// fades into the polar cap colour.
const CAP_BLEND_DEG: f64 = 1.0;

/// The colour (premultiplied RGBA, 0..255) of the north and south polar caps of a Web Mercator
/// layer: the mean of its shallowest tiles' top and bottom rows, so the poles the projection
/// cannot reach are filled with the colour the imagery has at its edge (ice where it shows
/// ice), without streaks. `None` for geographic layers, which reach the poles.
fn polar_caps(
    p: &RasterPyramid<Rgba>,
    touched: &mut Touched<'_, Rgba>,
    cancel: &Cancel,
) -> Result<Option<[[f64; 4]; 2]>, FetchError> {
    let spec = *p.spec();
    if spec.scheme != TilingScheme::WebMercator {
        return Ok(None);
    }
    let level = spec.min_level;
    let n = spec.scheme.tiles_x(level) as u32;
    let rows = spec.scheme.tiles_y(level) as u32;
    let mut caps = [[0.0; 4]; 2];
    for (cap, (ty, row_of)) in caps.iter_mut().zip([(0u32, 0u32), (rows - 1, u32::MAX)]) {
        let mut count = 0.0;
        for tx in 0..n {
            let Some(key) = spec.scheme.key(level, tx, ty) else {
                continue;
            };
            let t = match touched.get_or_missing(key, cancel) {
                Ok(Some(t)) => t,
                Ok(None) | Err(FetchError::Permanent(_)) => continue,
                Err(e) => return Err(e),
            };
            let y = if row_of == 0 { 0 } else { t.height - 1 };
            for x in 0..t.width {
                let px = t.at(x, y);
                let a = f64::from(px[3]);
                for k in 0..3 {
                    cap[k] += f64::from(px[k]) * a / 255.0;
                }
                cap[3] += a;
                count += 1.0;
            }
        }
        if count > 0.0 {
            cap.iter_mut().for_each(|v| *v /= count);
        }
    }
    Ok(Some(caps))
}

/// Premultiplied RGBA (0..255) of an imagery layer at a point: from its tile at `level`, or
/// where that tile is missing or broken, from the nearest ancestor that has one (cropped and
/// scaled: the same point sampled at a coarser level); past the Web Mercator limit, the
/// polar cap. `None` where the layer has nothing at all.
fn sample_imagery(
    touched: &mut Touched<'_, Rgba>,
    level: u8,
    lon: f64,
    lat: f64,
    caps: Option<[[f64; 4]; 2]>,
    cancel: &Cancel,
) -> Result<Option<[f64; 4]>, FetchError> {
    let spec = *touched.pyramid.spec();
    let mut found = None;
    let mut l = level;
    loop {
        if let Some((k, x, y)) = spec.locate(lon, lat, l) {
            match touched.get_or_missing(k, cancel) {
                Ok(Some(t)) => {
                    let alpha = bilinear(x, y, t.width, t.height, |a, b| f64::from(t.at(a, b)[3]));
                    let ch = |c: usize| {
                        bilinear(x, y, t.width, t.height, |a, b| {
                            let p = t.at(a, b);
                            f64::from(p[c]) * f64::from(p[3]) / 255.0
                        })
                    };
                    found = Some([ch(0), ch(1), ch(2), alpha]);
                    break;
                }
                Ok(None) | Err(FetchError::Permanent(_)) => {}
                Err(e) => return Err(e),
            }
        }
        if l <= spec.min_level {
            break;
        }
        l -= 1;
    }
    let (Some(caps), true) = (caps, lat.abs() > mercator_limit_rad()) else {
        return Ok(found);
    };
    let cap = if lat > 0.0 { caps[0] } else { caps[1] };
    let t = ((lat.abs() - mercator_limit_rad()) / CAP_BLEND_DEG.to_radians()).clamp(0.0, 1.0);
    Ok(Some(match found {
        Some(f) => [0, 1, 2, 3].map(|k| f[k] + (cap[k] - f[k]) * t),
        None => cap,
    }))
}

/// A hypsometric tint for terrain without imagery: sea blue, lowland green, brown, rock grey,
/// snow above 4500 m.
fn tint(h: f64) -> [u8; 4] {
    const STOPS: [(f64, [f64; 3]); 6] = [
        (-500.0, [30.0, 60.0, 120.0]),
        (0.5, [60.0, 110.0, 160.0]),
        (1.0, [80.0, 130.0, 70.0]),
        (800.0, [150.0, 140.0, 90.0]),
        (2500.0, [130.0, 115.0, 100.0]),
        (4500.0, [240.0, 240.0, 245.0]),
    ];
    let mut c = STOPS[STOPS.len() - 1].1;
    for w in STOPS.windows(2) {
        let ((h0, c0), (h1, c1)) = (w[0], w[1]);
        if h < h1 {
            let t = ((h - h0) / (h1 - h0)).clamp(0.0, 1.0);
            c = [0, 1, 2].map(|k| c0[k] + (c1[k] - c0[k]) * t);
            break;
        }
    }
    [c[0] as u8, c[1] as u8, c[2] as u8, 255]
}

impl TileSource for RasterTerrainSource {
    type Tile = TerrainData;

    fn name(&self) -> &str {
        &self.name
    }

    fn scheme(&self) -> TilingScheme {
        GLOBE_SCHEME
    }

    fn load(&self, key: TileKey, cancel: &Cancel) -> Result<Option<TerrainData>, SourceError> {
        if key.level() > self.max_level || !GLOBE_SCHEME.is_valid(key) {
            return Ok(None);
        }
        let tile = self.build(key, cancel).map_err(|e| self.fail(key, e))?;
        Ok(tile.map(|t| TerrainData {
            colour_separate: self.colour_separate(key),
            ..TerrainData::build(t, &self.ellipsoid, &self.occluder, &self.mesh_options)
        }))
    }

    fn byte_size(&self, tile: &TerrainData) -> usize {
        tile.byte_size()
    }
}

impl TerrainSource for RasterTerrainSource {
    fn has_imagery_for(&self, key: TileKey) -> bool {
        !self.imagery.is_empty() && self.imagery_detailed(&GLOBE_SCHEME.rect(key))
    }

    fn load_colour(
        &self,
        data: &TerrainData,
        cancel: &Cancel,
    ) -> Result<Option<ColourImage>, SourceError> {
        let t = &data.tile;
        self.colour(&t.rect, &t.heights_m, cancel)
            .map(Some)
            .map_err(|e| self.fail(t.key, e))
    }

    fn ellipsoid(&self) -> &Ellipsoid {
        &self.ellipsoid
    }

    fn layer_failures(&self) -> Vec<crate::pyramid::LayerFailures> {
        let elevation = self.elevation.iter().map(|p| p.failures());
        let imagery = self.imagery.iter().map(|p| p.failures());
        elevation.chain(imagery).collect()
    }

    fn occluder(&self) -> &Ellipsoid {
        &self.occluder
    }

    fn height_range_m(&self) -> (f64, f64) {
        self.height_range_m
    }

    fn max_level(&self) -> u8 {
        self.max_level
    }

    fn cached_bytes(&self) -> usize {
        let elevation: usize = self.elevation.iter().map(|p| p.cached_bytes()).sum();
        let imagery: usize = self.imagery.iter().map(|p| p.cached_bytes()).sum();
        elevation + imagery
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn the_ring_is_every_sample_around_the_mesh_once() {
        let positions: Vec<(i32, i32)> = ring_positions().collect();
        assert_eq!(positions.len(), RING_LEN);
        let last = MESH_SEGMENTS as i32 + 1;
        let mut seen = [false; RING_LEN];
        for j in -1..=last {
            for i in -1..=last {
                let outside = i == -1 || j == -1 || i == last || j == last;
                match ring_index(i, j) {
                    Some(r) => {
                        assert!(outside, "({i}, {j}) is inside");
                        assert_eq!(positions[r], (i, j));
                        assert!(!seen[r]);
                        seen[r] = true;
                    }
                    None => assert!(!outside, "({i}, {j}) is on the ring"),
                }
            }
        }
        assert!(seen.iter().all(|&s| s));
    }
}
