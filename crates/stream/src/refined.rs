//! [`RefinedSource`]: any terrain source, continued below its data by procedural refinement.

use std::sync::{Arc, Mutex};

use globus_geo::Ellipsoid;
use globus_terrain::refine::{BaseNeighbours, RefineOptions, Refiner};
use globus_terrain::{MeshOptions, TerrainTile};
use globus_tiling::{GLOBE_SCHEME, TileKey, TilingScheme};

use crate::cache::LruCache;
use crate::fetch::Cancel;
use crate::{SourceError, TerrainData, TerrainSource, TileSource};

/// Bytes of base tiles kept for refinement by default (a view needs a handful of bases at a
/// time).
pub const DEFAULT_BASE_CACHE_BYTES: usize = 32 << 20;

/// Wraps a geographic terrain source whose data ends at its `max_level`: deeper tiles are
/// invented from the deepest tile the source has above them ([`Refiner`]), down to
/// `max_level` of the wrapper. Where the source has no data at a level (`Ok(None)`), the
/// nearest ancestor it has is refined instead.
pub struct RefinedSource {
    inner: Arc<dyn TerrainSource>,
    refiner: Refiner,
    data_level: u8,
    max_level: u8,
    mesh_options: MeshOptions,
    /// Base tiles by key; `None` remembers "no data there".
    bases: Mutex<(LruCache<Option<Arc<TerrainTile>>>, u64)>,
    name: String,
}

impl RefinedSource {
    /// `inner` refined from its deepest level down to `max_level`.
    pub fn new(
        inner: Arc<dyn TerrainSource>,
        options: RefineOptions,
        max_level: u8,
        mesh_options: MeshOptions,
    ) -> Self {
        let data_level = inner.max_level();
        let name = format!(
            "{} refined below level {data_level} to {max_level}",
            inner.name()
        );
        Self {
            refiner: Refiner::new(options, *inner.ellipsoid()),
            inner,
            data_level,
            max_level: max_level.max(data_level),
            mesh_options,
            bases: Mutex::new((LruCache::new(DEFAULT_BASE_CACHE_BYTES), 0)),
            name,
        }
    }

    /// The same, keeping up to `bytes` of base tiles.
    pub fn with_base_cache_bytes(self, bytes: usize) -> Self {
        Self {
            bases: Mutex::new((LruCache::new(bytes), 0)),
            ..self
        }
    }

    /// The deepest level of real data.
    pub fn data_level(&self) -> u8 {
        self.data_level
    }

    /// The deepest tile of the inner source at or above `key`, loading bases as needed.
    fn base_for(
        &self,
        key: TileKey,
        cancel: &Cancel,
    ) -> Result<Option<Arc<TerrainTile>>, SourceError> {
        let mut level = self.data_level.min(key.level());
        loop {
            let Some(candidate) = GLOBE_SCHEME.ancestor_at(key, level) else {
                return Ok(None);
            };
            if let Some(found) = self.base_at(candidate, cancel)? {
                return Ok(Some(found));
            }
            if level == 0 {
                return Ok(None);
            }
            level -= 1;
        }
    }

    /// The inner source's tile `key` as a base (with its colour), from the cache or loaded;
    /// `None` where the source has no data there.
    fn base_at(
        &self,
        key: TileKey,
        cancel: &Cancel,
    ) -> Result<Option<Arc<TerrainTile>>, SourceError> {
        if let Some(found) = self.cached_base(key) {
            return Ok(found);
        }
        let loaded = match self.inner.load(key, cancel)? {
            Some(mut d) => {
                // Refinement textures the base's real colour, so a base whose imagery loads
                // separately gets it now.
                if d.colour_separate {
                    d.tile.colour =
                        self.inner
                            .load_colour(&d, cancel)?
                            .ok_or_else(|| SourceError::Failed {
                                key,
                                source_name: self.name.clone(),
                                message: "no colour for a base tile".into(),
                            })?;
                }
                Some(Arc::new(d.tile))
            }
            None => None,
        };
        self.remember(key, loaded.clone());
        Ok(loaded)
    }

    /// The tiles around `base` at its level that refining `key` reads (see
    /// [`Refiner::neighbours_needed`]): loaded when `load`, else only those cached.
    fn neighbours_of(
        &self,
        base: TileKey,
        key: TileKey,
        load: Option<&Cancel>,
    ) -> Result<[[Option<Arc<TerrainTile>>; 3]; 3], SourceError> {
        use globus_tiling::Direction;
        let needed = Refiner::neighbours_needed(base, key);
        let mut around: [[Option<Arc<TerrainTile>>; 3]; 3] = Default::default();
        for (r, row) in needed.iter().enumerate() {
            for (c, &wanted) in row.iter().enumerate() {
                if !wanted {
                    continue;
                }
                let across = |k: Option<TileKey>, d: usize, less: Direction, more: Direction| {
                    k.and_then(|k| match d {
                        0 => k.neighbor(GLOBE_SCHEME, less),
                        2 => k.neighbor(GLOBE_SCHEME, more),
                        _ => Some(k),
                    })
                };
                let beside = across(Some(base), c, Direction::West, Direction::East);
                let Some(neighbour) = across(beside, r, Direction::North, Direction::South) else {
                    continue;
                };
                around[r][c] = match load {
                    // A neighbour that fails to load is left out (the base's own ring stands
                    // in) rather than failing this tile for good; a cancel still stops it.
                    Some(cancel) => match self.base_at(neighbour, cancel) {
                        Ok(found) => found,
                        Err(e @ SourceError::Cancelled { .. }) => return Err(e),
                        Err(e) => {
                            tracing::debug!("refining {key} without neighbour {neighbour}: {e}");
                            None
                        }
                    },
                    None => self.cached_base(neighbour).flatten(),
                };
            }
        }
        Ok(around)
    }

    /// Caches a base tile, or that the inner source has none at `key`.
    fn remember(&self, key: TileKey, base: Option<Arc<TerrainTile>>) {
        let bytes = base.as_ref().map_or(64, |t| t.byte_size());
        if let Ok(mut guard) = self.bases.lock() {
            let (cache, clock) = &mut *guard;
            *clock += 1;
            cache.insert(key, base, bytes, *clock);
            cache.evict_to_budget(|_, _| false);
        }
    }

    fn cached_base(&self, key: TileKey) -> Option<Option<Arc<TerrainTile>>> {
        let mut guard = self.bases.lock().ok()?;
        let (cache, clock) = &mut *guard;
        *clock += 1;
        cache.touch(key, *clock);
        cache.get(key).cloned()
    }
}

impl TileSource for RefinedSource {
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
        if key.level() <= self.data_level {
            if let Some(data) = self.inner.load(key, cancel)? {
                return Ok(Some(data));
            }
            // No data here: refine from the nearest ancestor that has some.
            self.remember(key, None);
        }
        let Some(base) = self.base_for(key, cancel)? else {
            return Ok(None);
        };
        let around = self.neighbours_of(base.key, key, Some(cancel))?;
        let mut tile = self
            .refiner
            .refine_among(&base, &borrowed(&around), key)
            .map_err(|e| SourceError::Failed {
                key,
                source_name: self.name.clone(),
                message: e.to_string(),
            })?;
        // Real imagery deeper than the terrain's data replaces the refined colour: a load of
        // its own (`load_colour`), so the refined geometry is drawn before it arrives. Its
        // mean colour stands in (never drawn: the nearest ancestor's colour is shown).
        let colour_separate = self.inner.has_imagery_for(key);
        if colour_separate {
            let mean = tile
                .colour
                .mips
                .last()
                .cloned()
                .unwrap_or_else(|| vec![0; 4]);
            tile.colour = globus_terrain::ColourImage::with_mips(1, mean);
        }
        Ok(Some(TerrainData {
            generated: true,
            colour_separate,
            ..TerrainData::build(
                tile,
                self.inner.ellipsoid(),
                self.inner.occluder(),
                &self.mesh_options,
            )
        }))
    }

    fn byte_size(&self, tile: &TerrainData) -> usize {
        tile.byte_size()
    }
}

impl TerrainSource for RefinedSource {
    fn load_colour(
        &self,
        data: &TerrainData,
        cancel: &Cancel,
    ) -> Result<Option<globus_terrain::ColourImage>, SourceError> {
        // The inner source's imagery, over the tile's heights (refined or its own).
        self.inner.load_colour(data, cancel)
    }

    fn has_imagery_for(&self, key: TileKey) -> bool {
        self.inner.has_imagery_for(key)
    }

    fn ellipsoid(&self) -> &Ellipsoid {
        self.inner.ellipsoid()
    }

    fn occluder(&self) -> &Ellipsoid {
        // Refined heights never go below the base's lowest point nor below sea level.
        self.inner.occluder()
    }

    fn height_range_m(&self) -> (f64, f64) {
        let (lo, hi) = self.inner.height_range_m();
        // Detail adds at most half a height above the sea (see the refine module).
        (lo, hi * 1.5)
    }

    fn max_level(&self) -> u8 {
        self.max_level
    }

    fn cached_bytes(&self) -> usize {
        let bases = self.bases.lock().map_or(0, |g| g.0.bytes());
        bases + self.inner.cached_bytes()
    }

    fn layer_failures(&self) -> Vec<crate::pyramid::LayerFailures> {
        self.inner.layer_failures()
    }

    fn height_at(&self, lon_rad: f64, lat_rad: f64) -> Option<f64> {
        // Only bases already loaded: this runs on the render thread, and the inner source may
        // be a network service.
        let key = GLOBE_SCHEME.tile_at(lon_rad, lat_rad, self.data_level)?;
        let base = (0..=self.data_level)
            .rev()
            .filter_map(|level| {
                self.cached_base(GLOBE_SCHEME.ancestor_at(key, level)?)
                    .flatten()
            })
            .next();
        let Some(base) = base else {
            return self.inner.height_at(lon_rad, lat_rad);
        };
        let depth = self.max_level - base.key.level();
        let deepest = GLOBE_SCHEME.tile_at(lon_rad, lat_rad, self.max_level)?;
        let around = self.neighbours_of(base.key, deepest, None).ok()?;
        Some(
            self.refiner
                .height_at(&base, &borrowed(&around), lon_rad, lat_rad, depth),
        )
    }
}

/// The neighbours as the refiner takes them.
fn borrowed(around: &[[Option<Arc<TerrainTile>>; 3]; 3]) -> BaseNeighbours<'_> {
    around
        .each_ref()
        .map(|row| row.each_ref().map(Option::as_deref))
}

#[cfg(test)]
mod tests {
    use super::*;
    use crate::ProceduralSource;
    use globus_terrain::grid::MESH_SEGMENTS;

    #[test]
    fn data_levels_pass_through_and_deeper_levels_are_refined() {
        let inner: Arc<dyn TerrainSource> = Arc::new(ProceduralSource::new(1, 10));
        let source = RefinedSource::new(
            inner.clone(),
            RefineOptions::default(),
            22,
            MeshOptions::default(),
        );
        assert_eq!((source.data_level(), source.max_level()), (10, 22));
        let data_key = TileKey::new(10, 703, 522);
        let direct = inner
            .load(data_key, &Cancel::new())
            .expect("load")
            .expect("tile");
        let through = source
            .load(data_key, &Cancel::new())
            .expect("load")
            .expect("tile");
        assert_eq!(direct.tile.heights_m, through.tile.heights_m);
        // A deep tile: refined from the level-10 base, deterministic, with its own mesh.
        let deep = TileKey::new(18, 703 * 256 + 17, 522 * 256 + 200);
        let a = source
            .load(deep, &Cancel::new())
            .expect("load")
            .expect("refined");
        let b = source
            .load(deep, &Cancel::new())
            .expect("load")
            .expect("refined");
        assert_eq!(a.tile.heights_m, b.tile.heights_m);
        assert_eq!(a.mesh.indices, b.mesh.indices);
        assert!(a.tile.geometric_error_m < direct.tile.geometric_error_m);
        // Height queries agree with the deep tile's samples within its error.
        let rect = a.tile.rect;
        let h = source
            .height_at(rect.west, rect.north)
            .expect("height under the data");
        let corner = f64::from(a.tile.height_at(0, 0));
        assert!(
            (h - corner).abs() <= a.tile.geometric_error_m + 1e-3,
            "{h} vs {corner}"
        );
        // Beyond the wrapper's depth: no data.
        assert!(
            source
                .load(TileKey::new(23, 703 << 13, 522 << 13), &Cancel::new())
                .expect("load")
                .is_none()
        );
    }

    /// Refined tiles on either side of a border between base tiles are refined with each
    /// other's base as a neighbour: their shared edge and their border rings agree (the
    /// rings are 20-40 m apart where each side extrapolates its own base).
    #[test]
    fn refined_tiles_agree_across_base_borders() {
        let inner: Arc<dyn TerrainSource> = Arc::new(ProceduralSource::new(1, 10));
        let source =
            RefinedSource::new(inner, RefineOptions::default(), 22, MeshOptions::default());
        for depth in [1u8, 3, 6] {
            let scale = 1u32 << depth;
            let y = 522 * scale + scale / 2;
            let west = TileKey::new(10 + depth, 704 * scale - 1, y);
            let east = TileKey::new(10 + depth, 704 * scale, y);
            let load = |k| {
                source
                    .load(k, &Cancel::new())
                    .expect("load")
                    .expect("refined")
                    .tile
            };
            let (w, e) = (load(west), load(east));
            let n = MESH_SEGMENTS as i32;
            for j in -1..=n + 1 {
                let edge = (w.height_at(n, j) - e.height_at(0, j)).abs();
                let ring = (w.height_at(n + 1, j) - e.height_at(1, j)).abs();
                let ring_e = (e.height_at(-1, j) - w.height_at(n - 1, j)).abs();
                assert!(
                    edge.max(ring).max(ring_e) <= 1e-3,
                    "{west} | {east} row {j}: edge {edge}, rings {ring} / {ring_e} m"
                );
            }
        }
    }

    /// A procedural source with one tile (and what lies under it) missing: no data, or a
    /// failed load when `fails`.
    struct Gap {
        inner: ProceduralSource,
        missing: TileKey,
        fails: bool,
    }

    impl TileSource for Gap {
        type Tile = TerrainData;
        fn name(&self) -> &str {
            "gap"
        }
        fn scheme(&self) -> TilingScheme {
            GLOBE_SCHEME
        }
        fn load(&self, key: TileKey, cancel: &Cancel) -> Result<Option<TerrainData>, SourceError> {
            if !GLOBE_SCHEME.contains(self.missing, key) {
                return self.inner.load(key, cancel);
            }
            if self.fails {
                return Err(SourceError::Failed {
                    key,
                    source_name: "gap".into(),
                    message: "corrupt".into(),
                });
            }
            Ok(None)
        }
        fn byte_size(&self, tile: &TerrainData) -> usize {
            tile.byte_size()
        }
    }

    impl TerrainSource for Gap {
        fn ellipsoid(&self) -> &Ellipsoid {
            self.inner.ellipsoid()
        }
        fn occluder(&self) -> &Ellipsoid {
            self.inner.occluder()
        }
        fn height_range_m(&self) -> (f64, f64) {
            self.inner.height_range_m()
        }
        fn max_level(&self) -> u8 {
            self.inner.max_level()
        }
    }

    /// A neighbouring base that fails to load is left out: the tile near the border is
    /// refined from its own base alone instead of failing; the failing base's own tiles fail.
    #[test]
    fn a_neighbour_that_fails_is_left_out() {
        let broken = TileKey::new(10, 704, 522);
        let inner = Arc::new(Gap {
            inner: ProceduralSource::new(1, 10),
            missing: broken,
            fails: true,
        });
        let source = RefinedSource::new(
            inner.clone(),
            RefineOptions::default(),
            16,
            MeshOptions::default(),
        );
        let key = TileKey::new(12, 704 * 4 - 1, 522 * 4 + 1);
        let tile = source
            .load(key, &Cancel::new())
            .expect("refined without the neighbour")
            .expect("tile");
        let base = inner
            .load(TileKey::new(10, 703, 522), &Cancel::new())
            .expect("load")
            .expect("base");
        let alone = Refiner::new(RefineOptions::default(), Ellipsoid::WGS84)
            .refine(&base.tile, key)
            .expect("refine");
        assert_eq!(tile.tile.heights_m, alone.heights_m);
        assert!(
            source
                .load(TileKey::new(12, 704 * 4, 522 * 4 + 1), &Cancel::new())
                .is_err()
        );
    }

    #[test]
    fn holes_in_the_data_are_refined_from_the_nearest_ancestor_with_data() {
        let hole = TileKey::new(10, 703, 522);
        let inner = Arc::new(Gap {
            inner: ProceduralSource::new(1, 10),
            missing: hole,
            fails: false,
        });
        let source =
            RefinedSource::new(inner, RefineOptions::default(), 16, MeshOptions::default());
        let parent = source
            .load(hole.parent().expect("parent"), &Cancel::new())
            .expect("load")
            .expect("real data above the hole");
        let filled = source
            .load(hole, &Cancel::new())
            .expect("load")
            .expect("refined");
        assert_eq!(filled.tile.key, hole);
        // Refined from the level-9 parent: at the parent's own samples it stays within the
        // parent's error.
        let (qx, qy) = ((hole.x() & 1) as i32 * 16, (hole.y() & 1) as i32 * 16);
        for b in 0..=16 {
            for a in 0..=16 {
                let d = filled.tile.height_at(2 * a, 2 * b) - parent.tile.height_at(qx + a, qy + b);
                assert!(
                    f64::from(d.abs()) <= parent.tile.geometric_error_m,
                    "{a},{b}: {d}"
                );
            }
        }
        // Deeper tiles in the hole come from the same level-9 base: the filled tile's children
        // agree with it along its west edge at the shared samples.
        let child = hole.children().expect("children")[0];
        let c = source
            .load(child, &Cancel::new())
            .expect("load")
            .expect("refined child");
        for j in 0..=16 {
            let (a, b) = (filled.tile.height_at(0, j), c.tile.height_at(0, 2 * j));
            assert!(
                f64::from((a - b).abs()) <= filled.tile.geometric_error_m,
                "row {j}: {a} vs {b}"
            );
        }
    }
}
