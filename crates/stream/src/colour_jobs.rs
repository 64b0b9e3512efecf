//! Colour loads of their own: the imagery of terrain tiles loaded with
//! [`TerrainData::colour_separate`], fetched by a scheduler of its own so that a tile's
//! geometry is drawn as soon as its heights arrive and its imagery sharpens independently
//! (Zeitler 2015, future work: imagery tiled independently of terrain).
//!
//! A colour load needs the tile it colours (heights tint the ground where no imagery layer
//! covers it), so the layer hands the jobs the loaded tiles whose colour it wants now; a job
//! whose tile is no longer wanted finds nothing and ends as cancelled.

use std::sync::{Arc, Mutex};
use std::time::{Duration, Instant};

use globus_terrain::ColourImage;
use globus_tiling::{GLOBE_SCHEME, TileKey, TilingScheme};
use rustc_hash::{FxHashMap, FxHashSet};

use crate::fetch::Cancel;
use crate::{Scheduler, SourceError, TerrainData, TerrainSource, TileSource};

/// A tile that failed for good is asked for again after this long, doubling with each
/// failure up to [`FAILED_RETRY_MAX`].
pub(crate) const FAILED_RETRY_AFTER: Duration = Duration::from_secs(30);
/// Longest wait before asking for a failed tile again.
pub(crate) const FAILED_RETRY_MAX: Duration = Duration::from_secs(600);
/// Most "no data" answers or failures remembered (16 bytes each).
pub(crate) const MAX_REMEMBERED_KEYS: usize = 1 << 20;

/// Failed tiles: when each may be asked for again, and how often it failed.
#[derive(Default)]
pub(crate) struct Failures(FxHashMap<TileKey, (Instant, u32)>);

impl Failures {
    /// Records a failure of `key`: it waits [`FAILED_RETRY_AFTER`], twice that after a second
    /// failure, and so on up to [`FAILED_RETRY_MAX`].
    pub(crate) fn record(&mut self, key: TileKey) {
        let failures = self.0.get(&key).map_or(0, |f| f.1) + 1;
        let wait = FAILED_RETRY_AFTER
            .saturating_mul(1 << (failures - 1).min(5))
            .min(FAILED_RETRY_MAX);
        if self.0.len() >= MAX_REMEMBERED_KEYS {
            let now = Instant::now();
            self.0.retain(|_, f| f.0 > now);
        }
        self.0.insert(key, (Instant::now() + wait, failures));
    }

    /// Whether `key` failed and its cool-down has not passed.
    pub(crate) fn cooling(&self, key: TileKey) -> bool {
        self.0.get(&key).is_some_and(|f| Instant::now() < f.0)
    }

    /// Whether `key` failed and may be asked for again now.
    pub(crate) fn ready_again(&self, key: TileKey) -> bool {
        self.0.get(&key).is_some_and(|f| Instant::now() >= f.0)
    }

    /// Forgets `key` (it loaded).
    pub(crate) fn clear(&mut self, key: TileKey) {
        self.0.remove(&key);
    }

    #[cfg(test)]
    pub(crate) fn get(&self, key: TileKey) -> Option<(Instant, u32)> {
        self.0.get(&key).copied()
    }

    #[cfg(test)]
    pub(crate) fn set(&mut self, key: TileKey, retry_at: Instant, count: u32) {
        self.0.insert(key, (retry_at, count));
    }
}

/// The colour loads of a terrain source, as a [`TileSource`] of colour images.
pub(crate) struct ColourJobs {
    source: Arc<dyn TerrainSource>,
    name: String,
    /// The loaded tiles whose colour is wanted now, by key.
    tiles: Mutex<FxHashMap<TileKey, Arc<TerrainData>>>,
}

impl TileSource for ColourJobs {
    type Tile = ColourImage;

    fn name(&self) -> &str {
        &self.name
    }

    fn scheme(&self) -> TilingScheme {
        GLOBE_SCHEME
    }

    fn load(&self, key: TileKey, cancel: &Cancel) -> Result<Option<ColourImage>, SourceError> {
        let data = self
            .tiles
            .lock()
            .unwrap_or_else(|p| p.into_inner())
            .get(&key)
            .cloned();
        match data {
            Some(data) => self.source.load_colour(&data, cancel),
            None => Err(SourceError::Cancelled { key }),
        }
    }

    fn byte_size(&self, colour: &ColourImage) -> usize {
        colour.byte_size()
    }
}

/// The colour side of a terrain layer: its scheduler and what it learnt.
pub(crate) struct ColourChannel {
    jobs: Arc<ColourJobs>,
    pub(crate) scheduler: Scheduler<ColourJobs>,
    /// Tiles the source has no colour of its own for: their ancestors' stays.
    pub(crate) none: FxHashSet<TileKey>,
    pub(crate) failures: Failures,
}

impl ColourChannel {
    /// Starts `workers` threads loading colour from `source`.
    pub(crate) fn new(source: Arc<dyn TerrainSource>, workers: usize) -> Self {
        let jobs = Arc::new(ColourJobs {
            name: format!("imagery of {}", source.name()),
            source,
            tiles: Mutex::new(FxHashMap::default()),
        });
        Self {
            scheduler: Scheduler::new(Arc::clone(&jobs), workers),
            jobs,
            none: FxHashSet::default(),
            failures: Failures::default(),
        }
    }

    /// Whether the colour of `key` should be asked for: not known to be absent, not cooling
    /// down after a failure.
    pub(crate) fn may_ask(&self, key: TileKey) -> bool {
        !self.none.contains(&key) && !self.failures.cooling(key)
    }

    /// Replaces the wanted colour loads with `requests`, for the tiles in `tiles`.
    pub(crate) fn submit(
        &self,
        tiles: FxHashMap<TileKey, Arc<TerrainData>>,
        requests: &[globus_tiling::TileRequest],
    ) {
        *self.jobs.tiles.lock().unwrap_or_else(|p| p.into_inner()) = tiles;
        self.scheduler.submit(requests);
    }

    /// Loads queued or in flight.
    pub(crate) fn loading(&self) -> usize {
        self.scheduler.queued() + self.scheduler.in_flight()
    }

    /// Remembers that the source has no colour of its own for `key`.
    pub(crate) fn no_colour(&mut self, key: TileKey) {
        if self.none.len() >= MAX_REMEMBERED_KEYS {
            self.none.clear();
        }
        self.none.insert(key);
    }
}
