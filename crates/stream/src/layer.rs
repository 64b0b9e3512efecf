//! [`TerrainLayer`]: a terrain source, its scheduler and its cache, seen by LOD selection as a
//! [`TileOracle`].
//!
//! Selection asks about every tile it visits, every frame, so the answers live in one compact
//! table ([`Node`] records, stored inline in a hash map): one lookup and a few adjacent cache
//! lines per visit, instead of chasing pointers into the large tile data. Loaded tiles have
//! exact records; their children get estimated records (bounds from the parent's heights) as
//! soon as the parent arrives, so they can be culled before they are loaded.
//!
//! A loaded tile is reported as [`TileState::Loaded`] only once the renderer has marked it
//! drawable ([`TerrainLayer::set_drawable`]): everything selection draws can be drawn now.

use std::sync::Arc;
use std::time::{Duration, Instant};

use globus_geo::Ellipsoid;
use globus_tiling::{
    DrawTile, TileBounds, TileInfo, TileKey, TileOracle, TileRequest, TileState, TilingScheme,
};
use rustc_hash::{FxHashMap, FxHashSet};

use crate::scheduler::Outcome;
use crate::{LruCache, Scheduler, SchedulerStats, TerrainData, TerrainSource};

/// A tile that failed for good is asked for again after this long, doubling with each
/// failure up to [`FAILED_RETRY_MAX`].
const FAILED_RETRY_AFTER: Duration = Duration::from_secs(30);
/// Longest wait before asking for a failed tile again.
const FAILED_RETRY_MAX: Duration = Duration::from_secs(600);

/// Most "no data here" answers remembered (16 bytes each).
const MAX_NO_DATA_KEYS: usize = 1 << 20;

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
    /// Whether the cache is over its budget with everything in use: nothing more is loaded
    /// until the engine lowers the detail.
    pub over_budget: bool,
}

/// What became of loads over a session, for benchmarks.
#[derive(Clone, Copy, Debug, Default, PartialEq, Eq)]
pub struct UsageStats {
    /// Tiles that arrived loaded.
    pub loaded: u64,
    /// Distinct loaded tiles that were never in a draw list.
    pub loaded_never_drawn: u64,
    /// Tiles that arrived loaded from fetched data (not generated here).
    pub fetched: u64,
    /// Distinct tiles loaded from fetched data that were never in a draw list: requests
    /// that bought nothing visible.
    pub fetched_never_drawn: u64,
    /// Loads of a tile that was in the cache at the time (should be none).
    pub loaded_again_while_cached: u64,
    /// Loads of a tile loaded before and evicted since.
    pub loaded_again_after_eviction: u64,
}

#[derive(Default)]
struct Usage {
    drawn: FxHashSet<TileKey>,
    loaded: FxHashSet<TileKey>,
    fetched: FxHashSet<TileKey>,
    stats: UsageStats,
}

/// What selection needs to know about one tile, stored inline.
#[derive(Clone, Copy, Debug)]
struct Node {
    bounds: TileBounds,
    error_m: f64,
    /// Unloaded (estimate), Loaded, NoData or Failed.
    state: TileState,
    /// Loaded and ready to draw (set by the renderer).
    drawable: bool,
}

/// A terrain layer: scheduler, cache and oracle over any [`TerrainSource`].
pub struct TerrainLayer {
    scheduler: Scheduler<dyn TerrainSource>,
    cache: LruCache<Arc<TerrainData>>,
    nodes: FxHashMap<TileKey, Node>,
    /// Tiles the source said it has no data for: never asked again, even after their
    /// records were dropped with an evicted parent.
    no_data: FxHashSet<TileKey>,
    /// Load and draw bookkeeping, when a benchmark asked for it.
    usage: Option<Usage>,
    /// Tiles that failed: when they may be asked for again, and how often they failed.
    failures: FxHashMap<TileKey, (Instant, u32)>,
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
        let mut layer = Self {
            scheduler: Scheduler::new(source, options.workers),
            cache: LruCache::new(options.cache_bytes),
            nodes: FxHashMap::default(),
            no_data: FxHashSet::default(),
            usage: None,
            failures: FxHashMap::default(),
            ellipsoid,
            occluder,
            height_range_m,
            max_level,
            frame: 0,
        };
        for &root in TilingScheme::Geographic.roots() {
            let node = layer.estimate(root);
            layer.nodes.insert(root, node);
        }
        layer
    }

    /// Marks a loaded tile as ready (or no longer ready) to draw: the renderer calls this when
    /// it uploads or evicts the tile.
    pub fn set_drawable(&mut self, key: TileKey, drawable: bool) {
        if let Some(n) = self.nodes.get_mut(&key) {
            n.drawable = drawable && n.state == TileState::Loaded;
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

    /// Starts remembering every tile loaded and drawn (for benchmarks: it grows with the
    /// session).
    pub fn track_usage(&mut self) {
        self.usage = Some(Usage::default());
    }

    /// Load and draw bookkeeping since [`TerrainLayer::track_usage`].
    pub fn usage(&self) -> Option<UsageStats> {
        self.usage.as_ref().map(|u| UsageStats {
            loaded_never_drawn: u.loaded.difference(&u.drawn).count() as u64,
            fetched_never_drawn: u.fetched.difference(&u.drawn).count() as u64,
            ..u.stats
        })
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
        if let Some(u) = &mut self.usage {
            u.drawn.extend(drawn.iter().map(|d| d.key));
        }
        let mut stats = LayerStats::default();
        for (key, outcome) in self.scheduler.drain() {
            stats.arrived += 1;
            self.accept(key, outcome);
        }
        let evicted = self
            .cache
            .evict_to_budget(|k, last_used| last_used == now || k.level() == 0);
        stats.evicted = evicted.len() as u32;
        for key in evicted {
            self.forget(key);
        }
        // A hard budget: while what is in use does not fit, load nothing more (the engine
        // lowers detail until it does); otherwise replace the wanted list.
        if self.cache.is_over_budget() {
            self.scheduler.submit(&[]);
        } else {
            // The caller split its list before this update took in what arrived: tiles that
            // just arrived must not be asked for again.
            let missing: Vec<TileRequest> = wanted
                .iter()
                .filter(|r| !self.cache.contains(r.key) && !self.no_data.contains(&r.key))
                .copied()
                .collect();
            self.scheduler.submit(&missing);
        }
        stats.loading = self.loading() as u32;
        stats.cached = self.cache.len() as u32;
        stats.cached_bytes = self.cache.bytes();
        stats.over_budget = self.cache.is_over_budget();
        stats
    }

    fn accept(&mut self, key: TileKey, outcome: Outcome<TerrainData>) {
        let state = match outcome {
            Outcome::Loaded(data) => {
                self.failures.remove(&key);
                if let Some(u) = &mut self.usage {
                    u.stats.loaded += 1;
                    if !data.generated {
                        u.stats.fetched += 1;
                        u.fetched.insert(key);
                    }
                    if self.cache.contains(key) {
                        u.stats.loaded_again_while_cached += 1;
                    } else if !u.loaded.insert(key) {
                        u.stats.loaded_again_after_eviction += 1;
                    }
                }
                let bytes = data.byte_size();
                let node = Node {
                    bounds: data.mesh.bounds,
                    error_m: data.tile.lod_error_m(),
                    state: TileState::Loaded,
                    drawable: false,
                };
                if let Some(children) = key.children() {
                    let child_error = node.error_m * 0.5;
                    for (i, child) in children.into_iter().enumerate() {
                        let estimate = Node {
                            bounds: data.child_bounds[i],
                            error_m: child_error,
                            state: TileState::Unloaded,
                            drawable: false,
                        };
                        self.nodes
                            .entry(child)
                            .and_modify(|n| {
                                if n.state == TileState::Unloaded {
                                    *n = estimate;
                                }
                            })
                            .or_insert(estimate);
                    }
                }
                self.nodes.insert(key, node);
                self.cache.insert(key, data, bytes, self.frame);
                return;
            }
            Outcome::NoData => {
                if self.no_data.len() >= MAX_NO_DATA_KEYS {
                    self.no_data.clear();
                }
                self.no_data.insert(key);
                TileState::NoData
            }
            Outcome::Failed(e) => {
                eprintln!("globus: {e}");
                let failures = self.failures.get(&key).map_or(0, |f| f.1) + 1;
                let wait = FAILED_RETRY_AFTER
                    .saturating_mul(1 << (failures - 1).min(5))
                    .min(FAILED_RETRY_MAX);
                if self.failures.len() >= MAX_NO_DATA_KEYS {
                    let now = Instant::now();
                    self.failures.retain(|_, f| f.0 > now);
                }
                self.failures.insert(key, (Instant::now() + wait, failures));
                TileState::Failed
            }
        };
        let mut node = self
            .nodes
            .get(&key)
            .copied()
            .unwrap_or_else(|| self.estimate(key));
        node.state = state;
        node.drawable = false;
        self.nodes.insert(key, node);
    }

    /// Drops an evicted tile's record, keeping an estimate if its parent is still loaded,
    /// and the estimates of its children (nobody can reach them any more).
    fn forget(&mut self, key: TileKey) {
        if let Some(children) = key.children() {
            for child in children {
                if self
                    .nodes
                    .get(&child)
                    .is_some_and(|n| n.state != TileState::Loaded)
                {
                    // Estimates, failures and "no data" (remembered in `no_data`).
                    self.nodes.remove(&child);
                }
            }
        }
        let parent_loaded = key.parent().is_some_and(|p| self.cache.contains(p));
        if key.level() == 0 || parent_loaded {
            let estimate = self.estimate(key);
            self.nodes.insert(key, estimate);
        } else {
            self.nodes.remove(&key);
        }
    }

    /// An estimated record for an unloaded tile: bounds from the parent's heights if it is
    /// loaded, else from the rectangle and the source's height range.
    fn estimate(&self, key: TileKey) -> Node {
        let parent = key.parent().and_then(|p| self.cache.get(p));
        let bounds = match parent {
            Some(p) => p.child_bounds[key.child_index()],
            None => {
                let rect = TilingScheme::Geographic.rect(key);
                let (lo, hi) = self.height_range_m;
                TileBounds::from_rect(&self.ellipsoid, &self.occluder, &rect, lo, hi)
            }
        };
        let error_m = match parent {
            Some(p) => p.tile.lod_error_m() * 0.5,
            None => TilingScheme::Geographic.rect(key).height() * self.ellipsoid.mean_radius(),
        };
        Node {
            bounds,
            error_m,
            state: TileState::Unloaded,
            drawable: false,
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
}

impl TileOracle for TerrainLayer {
    fn scheme(&self) -> TilingScheme {
        TilingScheme::Geographic
    }

    fn tile(&self, key: TileKey) -> TileInfo {
        let has_children = key.level() < self.max_level;
        let node = match self.nodes.get(&key) {
            Some(n) => *n,
            // Only reachable through a tile selection did not descend into; stay correct.
            None => self.estimate(key),
        };
        let state = match node.state {
            TileState::Loaded if !node.drawable => TileState::Unloaded,
            TileState::Unloaded if self.no_data.contains(&key) => TileState::NoData,
            // A failed tile is asked for again after its cool-down (a server may recover).
            TileState::Failed
                if self
                    .failures
                    .get(&key)
                    .is_some_and(|f| Instant::now() >= f.0) =>
            {
                TileState::Unloaded
            }
            s => s,
        };
        TileInfo {
            bounds: node.bounds,
            geometric_error_m: node.error_m,
            state,
            has_children,
        }
    }
}

#[cfg(test)]
mod tests {
    use super::*;
    use crate::ProceduralSource;

    /// A layer over the default procedural planet down to `max_level`.
    fn procedural_layer(max_level: u8, cache_bytes: usize, workers: usize) -> TerrainLayer {
        TerrainLayer::new(
            Arc::new(ProceduralSource::new(24, max_level)),
            TerrainLayerOptions {
                cache_bytes,
                workers,
            },
        )
    }

    #[test]
    fn no_data_is_remembered_after_its_record_is_dropped() {
        let mut layer = procedural_layer(3, 1 << 30, 1);
        let parent = TileKey::new(3, 5, 2);
        let child = TileKey::new(4, 10, 4);
        layer.accept(child, Outcome::NoData);
        assert_eq!(layer.tile(child).state, TileState::NoData);
        // The parent is evicted: its children's records go, the answer stays.
        layer.forget(parent);
        assert!(!layer.nodes.contains_key(&child));
        assert_eq!(layer.tile(child).state, TileState::NoData);
        assert_eq!(
            layer.tile(TileKey::new(4, 11, 4)).state,
            TileState::Unloaded
        );
    }

    #[test]
    fn failed_tiles_are_asked_for_again_after_a_cool_down() {
        let mut layer = procedural_layer(3, 1 << 30, 1);
        let key = TileKey::new(2, 1, 1);
        let failure = crate::SourceError::Failed {
            key,
            source_name: "test".into(),
            message: "HTTP 403".into(),
        };
        layer.accept(key, Outcome::Failed(failure.clone()));
        assert_eq!(layer.tile(key).state, TileState::Failed);
        let (retry_at, count) = layer.failures[&key];
        assert_eq!(count, 1);
        assert!(retry_at >= Instant::now() + FAILED_RETRY_AFTER - Duration::from_secs(1));
        // Once the cool-down has passed, selection sees it as not loaded (and asks again).
        layer
            .failures
            .insert(key, (Instant::now() - Duration::from_millis(1), 1));
        assert_eq!(layer.tile(key).state, TileState::Unloaded);
        // A second failure waits twice as long.
        layer.accept(key, Outcome::Failed(failure));
        let (retry_at, count) = layer.failures[&key];
        assert_eq!(count, 2);
        assert!(retry_at >= Instant::now() + 2 * FAILED_RETRY_AFTER - Duration::from_secs(1));
    }

    #[test]
    fn the_cache_budget_holds_under_a_stream_of_requests() {
        let budget = 2 << 20;
        let mut layer = procedural_layer(12, budget, 2);
        let mut state = 7u64;
        let mut next = || {
            state ^= state << 13;
            state ^= state >> 7;
            state ^= state << 17;
            state
        };
        let mut peak = 0;
        let mut arrived = 0;
        for _ in 0..100 {
            // Sixteen random tiles at levels 5-8 wanted each frame, nothing drawn.
            let wanted: Vec<TileRequest> = (0..16)
                .map(|_| {
                    let level = 5 + (next() % 4) as u8;
                    let key = TileKey::new(
                        level,
                        (next() % (2 << level)) as u32,
                        (next() % (1 << level)) as u32,
                    );
                    TileRequest { key, priority: 1.0 }
                })
                .collect();
            let stats = layer.update(&[], &wanted);
            arrived += stats.arrived;
            peak = peak.max(stats.cached_bytes);
            arrived += layer.wait_for_tiles(Duration::from_millis(50)) as u32;
        }
        let stats = layer.update(&[], &[]);
        peak = peak.max(stats.cached_bytes);
        // Far more arrived than fits, and the cache never held more than its budget after an
        // update (the two roots, always kept, fit in it).
        assert!(
            arrived as usize * 150_000 > 2 * budget,
            "{arrived} tiles arrived"
        );
        assert!(peak <= budget, "peak {peak} bytes, budget {budget}");
    }
}
