//! [`TerrainLayer`]: a terrain source, its scheduler and its cache, seen by LOD selection as a
//! [`TileOracle`].
//!
//! Selection asks about every tile it visits, every frame, so the answers live in one compact
//! table ([`Node`] records stored by family, see [`crate::nodes`]): one lookup and a few
//! adjacent cache lines for all the children of a tile selection refines, instead of chasing
//! pointers into the large tile data. Loaded tiles have
//! exact records; their children get estimated records (bounds from the parent's heights) as
//! soon as the parent arrives, so they can be culled before they are loaded.
//!
//! A loaded tile is reported as [`TileState::Loaded`] as soon as it is in the cache; an
//! engine that draws from GPU copies answers selection through an oracle of its own that
//! also asks whether the tile is resident there (so everything selection draws can be drawn
//! now), and keeps that record itself.
//!
//! Tiles whose imagery loads on its own ([`TerrainData::colour_separate`]) get their colour
//! from a second scheduler ([`crate::colour_jobs`]), asked for the drawn tiles (and the loaded
//! ones about to be drawn) that lack it; the colour joins the tile's cache entry and budget.

use std::sync::Arc;
use std::time::{Duration, Instant};

use globus_terrain::ColourImage;

use globus_geo::Ellipsoid;
use globus_tiling::{
    DrawTile, GLOBE_SCHEME, TileBounds, TileInfo, TileKey, TileOracle, TileRequest, TileState,
    TilingScheme,
};
use rustc_hash::{FxHashMap, FxHashSet};

use crate::colour_jobs::{ColourChannel, Failures, MAX_REMEMBERED_KEYS};
use crate::nodes::{NOWHERE, NodeTable};
use crate::scheduler::Outcome;
use crate::terrain_jobs::TerrainJobs;
use crate::{LruCache, Scheduler, SchedulerStats, TerrainData, TerrainSource};

/// While waiting for terrain tiles, colour arrivals are looked for this often.
const COLOUR_POLL: Duration = Duration::from_millis(5);

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
    /// Bytes of the cached tiles this frame uses (drawn, their ancestors, and arrivals):
    /// what the view needs at least, against the budget.
    pub in_use_bytes: usize,
    /// The cache's budget, bytes.
    pub budget_bytes: usize,
    /// Whether the cache is over its budget with everything in use: nothing more is loaded
    /// until the engine lowers the detail.
    pub over_budget: bool,
    /// Colours (separate imagery loads) that arrived this update.
    pub colours_arrived: u32,
    /// Colour loads queued or in flight after the update.
    pub colours_loading: u32,
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
    /// Colours that arrived in loads of their own (separate imagery).
    pub colours_loaded: u64,
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
}

/// A cached tile: its data, and its colour once that arrived in a load of its own.
struct Cached {
    data: Arc<TerrainData>,
    colour: Option<Arc<ColourImage>>,
}

/// A loaded tile's colour, as the renderer should take it.
#[derive(Clone, Copy, Debug)]
pub enum TileColour<'a> {
    /// The tile's own colour.
    Ready(&'a ColourImage),
    /// Loading on its own: show the nearest ancestor's meanwhile.
    Loading,
    /// The source has none of its own for this tile, or it failed: the nearest ancestor's
    /// stays.
    Borrowed,
}

/// A terrain layer: scheduler, cache and oracle over any [`TerrainSource`].
pub struct TerrainLayer {
    /// The loads, with the parents their morph targets need ([`TerrainJobs`]).
    jobs: Arc<TerrainJobs>,
    scheduler: Scheduler<TerrainJobs>,
    cache: LruCache<Cached>,
    /// Separate colour loads, started with the first tile that needs one.
    colours: Option<ColourChannel>,
    workers: usize,
    nodes: NodeTable<Node>,
    /// Tiles the source said it has no data for: never asked again, even after their
    /// records were dropped with an evicted parent.
    no_data: FxHashSet<TileKey>,
    /// Load and draw bookkeeping, when a benchmark asked for it.
    usage: Option<Usage>,
    /// Tiles that failed: when they may be asked for again, and how often they failed.
    failures: Failures,
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
        let jobs = Arc::new(TerrainJobs::new(source));
        let mut layer = Self {
            scheduler: Scheduler::new(Arc::clone(&jobs), options.workers),
            jobs,
            cache: LruCache::new(options.cache_bytes),
            colours: None,
            workers: options.workers,
            nodes: NodeTable::default(),
            no_data: FxHashSet::default(),
            usage: None,
            failures: Failures::default(),
            ellipsoid,
            occluder,
            height_range_m,
            max_level,
            frame: 0,
        };
        for &root in GLOBE_SCHEME.roots() {
            let node = layer.estimate(root);
            layer.nodes.insert(root, node);
        }
        layer
    }

    /// Bytes of loaded tiles (and their colours) in the cache, and its budget.
    pub fn cache_bytes(&self) -> (usize, usize) {
        (self.cache.bytes(), self.cache.budget())
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
        self.jobs.source()
    }

    /// A loaded tile.
    pub fn get(&self, key: TileKey) -> Option<&Arc<TerrainData>> {
        self.cache.get(key).map(|c| &c.data)
    }

    /// The colour of a loaded tile (`None` if it is not loaded).
    pub fn colour(&self, key: TileKey) -> Option<TileColour<'_>> {
        let c = self.cache.get(key)?;
        Some(if !c.data.colour_separate {
            TileColour::Ready(&c.data.tile.colour)
        } else if let Some(colour) = &c.colour {
            TileColour::Ready(colour)
        } else if self.colours.as_ref().is_some_and(|ch| !ch.may_ask(key)) {
            TileColour::Borrowed
        } else {
            TileColour::Loading
        })
    }

    /// Colour loads queued or in flight.
    pub fn colours_loading(&self) -> usize {
        self.colours.as_ref().map_or(0, ColourChannel::loading)
    }

    /// Counters of the colour scheduler (zero until a tile needed a separate colour).
    pub fn colour_scheduler_stats(&self) -> SchedulerStats {
        self.colours
            .as_ref()
            .map_or_else(SchedulerStats::default, |c| c.scheduler.stats())
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

    /// One frame's bookkeeping after selection: marks the tiles `in_use` (what is drawn
    /// and every ancestor of it, which selection walks through) as used this frame, submits
    /// the tiles to load (replacing the previous list), takes in arrived tiles and evicts to
    /// the budget (never a tile in use, nor a root). `drawn` is the draw list: its tiles'
    /// separate colours are asked for first.
    pub fn update(
        &mut self,
        drawn: &[DrawTile],
        in_use: &[TileKey],
        wanted: &[TileRequest],
    ) -> LayerStats {
        self.frame += 1;
        let now = self.frame;
        for &k in in_use {
            self.cache.touch(k, now);
        }
        if let Some(u) = &mut self.usage {
            u.drawn.extend(drawn.iter().map(|d| d.key));
        }
        let mut stats = LayerStats::default();
        for (key, outcome) in self.scheduler.drain() {
            stats.arrived += 1;
            self.accept(key, outcome);
        }
        stats.colours_arrived = self.take_colours() as u32;
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
            // Nor hold on to parents the cache may have given up.
            self.jobs.set_parents([]);
            self.scheduler.submit(&[]);
            self.request_colours(&[], &[]);
        } else {
            self.request_colours(drawn, wanted);
            // The caller split its list before this update took in what arrived: tiles that
            // just arrived must not be asked for again.
            let missing: Vec<TileRequest> = wanted
                .iter()
                .filter(|r| !self.cache.contains(r.key) && !self.no_data.contains(&r.key))
                .copied()
                .collect();
            // Their loaded parents, for the morph targets the loads compute.
            self.jobs.set_parents(missing.iter().filter_map(|r| {
                let parent = GLOBE_SCHEME.parent(r.key)?;
                Some((parent, Arc::clone(&self.cache.get(parent)?.data)))
            }));
            self.scheduler.submit(&missing);
        }
        stats.loading = self.loading() as u32;
        stats.colours_loading = self.colours_loading() as u32;
        stats.cached = self.cache.len() as u32;
        stats.cached_bytes = self.cache.bytes();
        stats.in_use_bytes = self.cache.bytes_used_at(now);
        stats.budget_bytes = self.cache.budget();
        stats.over_budget = self.cache.is_over_budget();
        stats
    }

    /// Asks for the colour of the drawn tiles, then of the wanted ones already loaded, that
    /// lack their own (replacing the previous list: colours nobody shows any more are
    /// cancelled).
    fn request_colours(&mut self, drawn: &[DrawTile], wanted: &[TileRequest]) {
        let mut tiles = FxHashMap::default();
        let mut requests = Vec::new();
        let candidates = drawn
            .iter()
            .map(|d| (d.key, d.sse_px))
            .chain(wanted.iter().map(|r| (r.key, r.priority)));
        for (key, priority) in candidates {
            let Some(c) = self.cache.get(key) else {
                continue;
            };
            if !c.data.colour_separate
                || c.colour.is_some()
                || self.colours.as_ref().is_some_and(|ch| !ch.may_ask(key))
            {
                continue;
            }
            if tiles.insert(key, Arc::clone(&c.data)).is_none() {
                requests.push(TileRequest { key, priority });
            }
        }
        if requests.is_empty() && self.colours.is_none() {
            return;
        }
        let source = Arc::clone(self.jobs.source());
        let workers = self.workers;
        self.colours
            .get_or_insert_with(|| ColourChannel::new(source, workers))
            .submit(tiles, &requests);
    }

    /// Takes in the colours that arrived; returns how many.
    fn take_colours(&mut self) -> usize {
        let Some(ch) = &mut self.colours else {
            return 0;
        };
        let arrived = ch.scheduler.drain();
        let n = arrived.len();
        for (key, outcome) in arrived {
            match outcome {
                Outcome::Loaded(colour) => {
                    ch.failures.clear(key);
                    let Some(c) = self.cache.get_mut(key) else {
                        continue;
                    };
                    let bytes = c.data.byte_size() + colour.byte_size();
                    c.colour = Some(colour);
                    self.cache.resize(key, bytes);
                    if let Some(u) = &mut self.usage {
                        u.stats.colours_loaded += 1;
                    }
                }
                Outcome::NoData => ch.no_colour(key),
                Outcome::Failed(e) => {
                    tracing::warn!("imagery: {e}");
                    ch.failures.record(key);
                }
            }
        }
        n
    }

    fn accept(&mut self, key: TileKey, outcome: Outcome<TerrainData>) {
        let state = match outcome {
            Outcome::Loaded(data) => {
                self.failures.clear(key);
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
                    error_m: data.lod_error_m(),
                    state: TileState::Loaded,
                };
                let n = GLOBE_SCHEME.children(key).len();
                if n > 0 {
                    let child_error = node.error_m * 0.5;
                    let child_bounds = &data.child_bounds[..n];
                    self.nodes.update_children(key, |i, member| {
                        // Loaded, failed and empty children keep their records.
                        if member.is_none_or(|n| n.state == TileState::Unloaded)
                            && let Some(&bounds) = child_bounds.get(i)
                        {
                            *member = Some(Node {
                                bounds,
                                error_m: child_error,
                                state: TileState::Unloaded,
                            });
                        }
                    });
                }
                self.nodes.insert(key, node);
                let cached = Cached { data, colour: None };
                self.cache.insert(key, cached, bytes, self.frame);
                return;
            }
            Outcome::NoData => {
                if self.no_data.len() >= MAX_REMEMBERED_KEYS {
                    self.no_data.clear();
                }
                self.no_data.insert(key);
                TileState::NoData
            }
            Outcome::Failed(e) => {
                tracing::warn!("{e}");
                self.failures.record(key);
                TileState::Failed
            }
        };
        let mut node = self
            .nodes
            .get(key)
            .copied()
            .unwrap_or_else(|| self.estimate(key));
        node.state = state;
        self.nodes.insert(key, node);
    }

    /// Drops an evicted tile's record, keeping an estimate if its parent is still loaded,
    /// and the estimates of its children (nobody can reach them any more).
    fn forget(&mut self, key: TileKey) {
        // Estimates, failures and "no data" (remembered in `no_data`).
        self.nodes.update_children(key, |_, member| {
            if member.is_some_and(|n| n.state != TileState::Loaded) {
                *member = None;
            }
        });
        let parent_loaded = GLOBE_SCHEME
            .parent(key)
            .is_some_and(|p| self.cache.contains(p));
        if key.level() == 0 || parent_loaded {
            let estimate = self.estimate(key);
            self.nodes.insert(key, estimate);
        } else {
            self.nodes.remove(key);
        }
    }

    /// An estimated record for an unloaded tile: bounds from the parent's heights if it is
    /// loaded, else from the rectangle and the source's height range.
    fn estimate(&self, key: TileKey) -> Node {
        let parent = GLOBE_SCHEME
            .parent(key)
            .and_then(|p| Some((p, self.get(p)?)));
        let index = parent.and_then(|(p, _)| GLOBE_SCHEME.children(p).position(key));
        let parent = parent.map(|(_, data)| data);
        let bounds = match (parent, index) {
            (Some(p), Some(i)) => p.child_bounds[i],
            _ => {
                let rect = GLOBE_SCHEME.rect(key);
                let (lo, hi) = self.height_range_m;
                TileBounds::from_rect(&self.ellipsoid, &self.occluder, &rect, lo, hi)
            }
        };
        let error_m = match parent {
            Some(p) => p.lod_error_m() * 0.5,
            None => GLOBE_SCHEME.rect(key).height() * self.ellipsoid.mean_radius(),
        };
        Node {
            bounds,
            error_m,
            state: TileState::Unloaded,
        }
    }

    /// Waits up to `timeout` for at least one tile to arrive and takes in everything that
    /// has; returns how many arrived. For offline rendering, which waits on purpose.
    pub fn wait_for_tiles(&mut self, timeout: Duration) -> usize {
        let deadline = Instant::now() + timeout;
        loop {
            let mut n = self.take_colours();
            for (key, outcome) in self.scheduler.drain() {
                self.accept(key, outcome);
                n += 1;
            }
            let now = Instant::now();
            if n > 0 || now >= deadline {
                return n;
            }
            // Block on terrain, looking at colours every few milliseconds.
            let mut slice = deadline - now;
            if self.colours.is_some() {
                slice = slice.min(COLOUR_POLL);
            }
            if let Some((key, outcome)) = self.scheduler.wait_one(slice) {
                self.accept(key, outcome);
                return 1 + self.wait_for_tiles(Duration::ZERO);
            }
        }
    }
}

impl TileOracle for TerrainLayer {
    fn scheme(&self) -> TilingScheme {
        GLOBE_SCHEME
    }

    fn tile(&self, key: TileKey) -> TileInfo {
        let (node, children_at) = self.nodes.get_with_children_at(key);
        let estimated;
        let node = match node {
            Some(n) => n,
            // Only reachable through a tile selection did not descend into; stay correct.
            None => {
                estimated = self.estimate(key);
                &estimated
            }
        };
        self.info(key, node, children_at)
    }

    fn child_tiles(
        &self,
        parent: TileKey,
        info: &TileInfo,
        children: &[TileKey],
        out: &mut [Option<TileInfo>; 4],
    ) {
        let family = self.nodes.family_at(parent, info.children_at);
        for (i, slot) in out.iter_mut().enumerate() {
            let Some(&child) = children.get(i) else {
                *slot = None;
                continue;
            };
            // By reference: a record is a few hundred bytes, and copying it on its way into
            // the slot had been a quarter of selection's time (warm).
            let estimated;
            let node = match family.and_then(|f| f.members()[i].as_ref()) {
                Some(n) => n,
                None => {
                    estimated = self.estimate(child);
                    &estimated
                }
            };
            let at = family.map_or(NOWHERE, |f| f.kids()[i]);
            *slot = Some(self.info(child, node, at));
        }
    }
}

impl TerrainLayer {
    /// Selection's view of a record.
    fn info(&self, key: TileKey, node: &Node, children_at: u32) -> TileInfo {
        let has_children = key.level() < self.max_level;
        let state = match node.state {
            TileState::Unloaded if self.no_data.contains(&key) => TileState::NoData,
            // A failed tile is asked for again after its cool-down (a server may recover).
            TileState::Failed if self.failures.ready_again(key) => TileState::Unloaded,
            s => s,
        };
        TileInfo {
            bounds: node.bounds,
            geometric_error_m: node.error_m,
            state,
            has_children,
            children_at,
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

    /// Asks for `key` until it is loaded.
    fn load(layer: &mut TerrainLayer, key: TileKey) -> Arc<TerrainData> {
        let wanted = [TileRequest { key, priority: 1.0 }];
        for _ in 0..200 {
            if let Some(data) = layer.get(key) {
                return Arc::clone(data);
            }
            layer.update(&[], &[], &wanted);
            layer.wait_for_tiles(Duration::from_millis(50));
        }
        panic!("{key} did not load");
    }

    #[test]
    fn tiles_arrive_with_their_morph_targets_found_on_the_loader_thread() {
        let mut layer = procedural_layer(8, 1 << 30, 1);
        let root = TileKey::new(0, 1, 0);
        let root_data = load(&mut layer, root);
        // A root has no parent to grow out of.
        assert!(root_data.morph.is_empty());
        // A child asked for while its parent is loaded comes with its targets, the ones
        // the parent's mesh gives.
        let mut parent = (root, root_data);
        for level in 1..=4 {
            let child = GLOBE_SCHEME.tile_at(0.13, 0.8, level).expect("a tile");
            assert_eq!(GLOBE_SCHEME.parent(child), Some(parent.0));
            let data = load(&mut layer, child);
            let expected = globus_terrain::MorphVertex::towards_parent(
                &data.tile,
                &data.mesh,
                &parent.1.tile,
                &parent.1.mesh,
                layer.ellipsoid(),
            );
            assert_eq!(data.morph.len(), data.mesh.vertices.len(), "{child}");
            assert_eq!(data.morph, expected, "{child}");
            assert!(data.morph.iter().any(|m| m.dh_m != 0.0), "{child}");
            parent = (child, data);
        }
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
        assert!(!layer.nodes.contains_key(child));
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
        let (retry_at, count) = layer.failures.get(key).expect("recorded");
        assert_eq!(count, 1);
        assert!(
            retry_at
                >= Instant::now() + crate::colour_jobs::FAILED_RETRY_AFTER - Duration::from_secs(1)
        );
        // Once the cool-down has passed, selection sees it as not loaded (and asks again).
        layer
            .failures
            .set(key, Instant::now() - Duration::from_millis(1), 1);
        assert_eq!(layer.tile(key).state, TileState::Unloaded);
        // A second failure waits twice as long.
        layer.accept(key, Outcome::Failed(failure));
        let (retry_at, count) = layer.failures.get(key).expect("recorded");
        assert_eq!(count, 2);
        assert!(
            retry_at
                >= Instant::now() + 2 * crate::colour_jobs::FAILED_RETRY_AFTER
                    - Duration::from_secs(1)
        );
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
        let mut asked = Vec::new();
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
            asked.extend(wanted.iter().map(|r| r.key));
            let stats = layer.update(&[], &[], &wanted);
            arrived += stats.arrived;
            peak = peak.max(stats.cached_bytes);
            arrived += layer.wait_for_tiles(Duration::from_millis(50)) as u32;
        }
        let stats = layer.update(&[], &[], &[]);
        peak = peak.max(stats.cached_bytes);
        // Far more arrived than fits, and the cache never held more than its budget after an
        // update (the two roots, always kept, fit in it).
        assert!(
            arrived as usize * 150_000 > 2 * budget,
            "{arrived} tiles arrived"
        );
        assert!(peak <= budget, "peak {peak} bytes, budget {budget}");
        // Through all those loads and evictions, the records read by family agree with the
        // records read one by one, for loaded parents, evicted ones and never-loaded ones.
        let mut parents = 0;
        for key in asked {
            for parent in [Some(key), GLOBE_SCHEME.parent(key)].into_iter().flatten() {
                if !GLOBE_SCHEME.is_valid(parent) {
                    continue;
                }
                let children = GLOBE_SCHEME.children(parent);
                let mut together = [None; 4];
                layer.child_tiles(parent, &layer.tile(parent), &children, &mut together);
                for (i, &child) in children.iter().enumerate() {
                    assert_eq!(together[i], Some(layer.tile(child)), "{child}");
                }
                assert!(together[children.len()..].iter().all(Option::is_none));
                parents += usize::from(layer.get(parent).is_some());
            }
        }
        assert!(parents > 3, "{parents} loaded parents among those compared");
        layer.nodes.check_links();
    }
}
