//! [`TerrainLayer`]: a terrain source, its scheduler and its cache, seen by LOD selection as a
//! [`TileOracle`].

use std::sync::Arc;
use std::time::{Duration, Instant};

use globus_geo::Ellipsoid;
use globus_tiling::{
    DrawTile, TileBounds, TileInfo, TileKey, TileOracle, TileRequest, TileState, TilingScheme,
};
use rustc_hash::FxHashMap;

use crate::scheduler::Outcome;
use crate::{LruCache, Scheduler, SchedulerStats, TerrainData, TerrainSource};

/// Knobs of a terrain layer.
#[derive(Clone, Copy, Debug)]
pub struct TerrainLayerOptions {
    /// Bytes of decoded tiles kept in RAM.
    pub cache_bytes: usize,
    /// Worker threads.
    pub workers: usize,
}

impl Default for TerrainLayerOptions {
    fn default() -> Self {
        Self {
            cache_bytes: 512 << 20,
            workers: std::thread::available_parallelism().map_or(2, |n| n.get()),
        }
    }
}

/// What one update did.
#[derive(Clone, Copy, Debug, Default, PartialEq)]
pub struct LayerStats {
    /// Tiles that arrived this update.
    pub arrived: u32,
    /// Tiles evicted this update.
    pub evicted: u32,
    /// Tiles queued or in flight after the update.
    pub loading: u32,
    /// Tiles in the cache.
    pub cached: u32,
    /// Bytes in the cache.
    pub cached_bytes: usize,
    /// Whether the cache is over its budget with everything in use (lower the detail).
    pub over_budget: bool,
}

/// A terrain layer: scheduler, cache and oracle over any [`TerrainSource`].
pub struct TerrainLayer {
    scheduler: Scheduler<dyn TerrainSource>,
    cache: LruCache<Arc<TerrainData>>,
    missing: FxHashMap<TileKey, TileState>,
    root_bounds: FxHashMap<TileKey, TileBounds>,
    ellipsoid: Ellipsoid,
    occluder: Ellipsoid,
    height_range_m: (f64, f64),
    max_level: u8,
    frame: u64,
}

impl TerrainLayer {
    /// A layer over `source`.
    pub fn new(source: Arc<dyn TerrainSource>, options: TerrainLayerOptions) -> Self {
        let ellipsoid = *source.ellipsoid();
        let occluder = *source.occluder();
        let height_range_m = source.height_range_m();
        let max_level = source.max_level();
        let root_bounds = TilingScheme::Geographic
            .roots()
            .iter()
            .map(|&k| {
                let rect = TilingScheme::Geographic.rect(k);
                (
                    k,
                    TileBounds::from_rect(
                        &ellipsoid,
                        &occluder,
                        &rect,
                        height_range_m.0,
                        height_range_m.1,
                    ),
                )
            })
            .collect();
        Self {
            scheduler: Scheduler::new(source, options.workers),
            cache: LruCache::new(options.cache_bytes),
            missing: FxHashMap::default(),
            root_bounds,
            ellipsoid,
            occluder,
            height_range_m,
            max_level,
            frame: 0,
        }
    }

    /// The body tiles are on.
    pub fn ellipsoid(&self) -> &Ellipsoid {
        &self.ellipsoid
    }

    /// The horizon-culling body.
    pub fn occluder(&self) -> &Ellipsoid {
        &self.occluder
    }

    /// The deepest level of the source.
    pub fn max_level(&self) -> u8 {
        self.max_level
    }

    /// The source.
    pub fn source(&self) -> &Arc<dyn TerrainSource> {
        self.scheduler.source()
    }

    /// A loaded tile.
    pub fn get(&self, key: TileKey) -> Option<&Arc<TerrainData>> {
        self.cache.get(key)
    }

    /// Scheduler counters.
    pub fn scheduler_stats(&self) -> SchedulerStats {
        self.scheduler.stats()
    }

    /// Tiles queued or in flight.
    pub fn loading(&self) -> usize {
        self.scheduler.queued() + self.scheduler.in_flight()
    }

    /// One frame's bookkeeping after selection: marks what is drawn (and its ancestors) as
    /// used, submits the tiles to load (replacing the previous list), takes in arrived tiles
    /// and evicts to the budget.
    pub fn update(&mut self, drawn: &[DrawTile], wanted: &[TileRequest]) -> LayerStats {
        self.frame += 1;
        let now = self.frame;
        for d in drawn {
            let mut key = Some(d.key);
            while let Some(k) = key {
                if !self.cache.touch(k, now) {
                    break;
                }
                key = k.parent();
            }
        }
        self.scheduler.submit(wanted);
        let mut stats = LayerStats::default();
        for (key, outcome) in self.scheduler.drain() {
            stats.arrived += 1;
            self.accept(key, outcome);
        }
        let evicted = self
            .cache
            .evict_to_budget(|k, last_used| last_used == now || k.level() == 0);
        stats.evicted = evicted.len() as u32;
        stats.loading = self.loading() as u32;
        stats.cached = self.cache.len() as u32;
        stats.cached_bytes = self.cache.bytes();
        stats.over_budget = self.cache.is_over_budget();
        stats
    }

    fn accept(&mut self, key: TileKey, outcome: Outcome<TerrainData>) {
        match outcome {
            Outcome::Loaded(data) => {
                let bytes = data.byte_size();
                self.missing.remove(&key);
                self.cache.insert(key, data, bytes, self.frame);
            }
            Outcome::NoData => {
                self.missing.insert(key, TileState::NoData);
            }
            Outcome::Failed(e) => {
                eprintln!("globus: {e}");
                self.missing.insert(key, TileState::Failed);
            }
        }
    }

    /// Waits up to `timeout` for at least one tile to arrive and takes in everything that
    /// has; returns how many arrived. For offline rendering, which waits on purpose.
    pub fn wait_for_tiles(&mut self, timeout: Duration) -> usize {
        let deadline = Instant::now() + timeout;
        let mut n = 0;
        if let Some((key, outcome)) = self.scheduler.wait_one(timeout) {
            self.accept(key, outcome);
            n += 1;
        }
        while Instant::now() < deadline {
            let more = self.scheduler.drain();
            if more.is_empty() {
                break;
            }
            for (key, outcome) in more {
                self.accept(key, outcome);
                n += 1;
            }
        }
        n
    }

    fn estimated_bounds(&self, key: TileKey) -> TileBounds {
        if let Some(b) = self.root_bounds.get(&key) {
            return *b;
        }
        if let Some(parent) = key.parent().and_then(|p| self.cache.get(p)) {
            return parent.child_bounds[key.child_index()];
        }
        let rect = TilingScheme::Geographic.rect(key);
        TileBounds::from_rect(
            &self.ellipsoid,
            &self.occluder,
            &rect,
            self.height_range_m.0,
            self.height_range_m.1,
        )
    }

    fn estimated_error(&self, key: TileKey) -> f64 {
        match key.parent().and_then(|p| self.cache.get(p)) {
            Some(parent) => parent.tile.lod_error_m() * 0.5,
            None => TilingScheme::Geographic.rect(key).height() * self.ellipsoid.mean_radius(),
        }
    }
}

impl TileOracle for TerrainLayer {
    fn scheme(&self) -> TilingScheme {
        TilingScheme::Geographic
    }

    fn tile(&self, key: TileKey) -> TileInfo {
        let has_children = key.level() < self.max_level;
        if let Some(data) = self.cache.get(key) {
            return TileInfo {
                bounds: data.mesh.bounds,
                geometric_error_m: data.tile.lod_error_m(),
                state: TileState::Loaded,
                has_children,
            };
        }
        TileInfo {
            bounds: self.estimated_bounds(key),
            geometric_error_m: self.estimated_error(key),
            state: self
                .missing
                .get(&key)
                .copied()
                .unwrap_or(TileState::Unloaded),
            has_children,
        }
    }
}
