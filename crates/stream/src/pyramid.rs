//! A raster pyramid read through a [`Fetch`]: its layout, a small cache of decoded tiles, and
//! sampling at any longitude and latitude, so engine tiles (geographic) can be built from
//! pyramids of either scheme and of any tile size (Web Mercator is reprojected here).

use std::f64::consts::PI;
use std::sync::{Arc, Condvar, Mutex};
use std::time::{Duration, Instant};

use globus_tiling::{GeoRect, TileKey, TilingScheme, lat_to_mercator_y};
use rustc_hash::FxHashMap;

use crate::decode::DecodeError;
use crate::fetch::{Cancel, Fetch, FetchError};

/// Where a tile's samples lie.
#[derive(Clone, Copy, Debug, PartialEq, Eq)]
pub enum SampleGrid {
    /// Sample `i` of `n` at `i / (n - 1)` of the tile: edges shared with the neighbours
    /// (`globus tile` elevation).
    Corners,
    /// Pixel `i` of `n` covers `[i, i + 1] / n` (ordinary images, most elevation services).
    Cells,
}

/// What a pyramid holds and where.
#[derive(Clone, Copy, Debug, PartialEq)]
pub struct PyramidSpec {
    /// The tiling scheme of its keys.
    pub scheme: TilingScheme,
    /// Shallowest level.
    pub min_level: u8,
    /// Deepest level.
    pub max_level: u8,
    /// Samples per tile side.
    pub tile_size: u32,
    /// Sample registration.
    pub grid: SampleGrid,
    /// Where it has data.
    pub bounds: GeoRect,
}

impl PyramidSpec {
    /// The level whose sample spacing is closest to (not coarser than) `spacing_rad` of
    /// latitude at the equator, clamped to the pyramid's levels.
    pub fn level_for_spacing(&self, spacing_rad: f64) -> u8 {
        let level = self.ideal_level(spacing_rad).clamp(0, 30) as u8;
        level.clamp(self.min_level, self.max_level)
    }

    /// The same level before clamping to the pyramid's (may be negative or beyond them).
    pub fn ideal_level(&self, spacing_rad: f64) -> i32 {
        let span0 = match self.scheme {
            TilingScheme::Geographic | TilingScheme::GeographicReduced => PI,
            TilingScheme::WebMercator => 2.0 * PI,
        };
        let per_tile =
            f64::from(self.tile_size.max(2) - u32::from(self.grid == SampleGrid::Corners));
        (span0 / per_tile / spacing_rad)
            .log2()
            .ceil()
            .clamp(-64.0, 64.0) as i32
    }

    /// The tile and its fractional sample coordinates (x east, y south, in samples) holding
    /// a longitude and latitude at `level`. Web Mercator clamps latitude to its square.
    pub fn locate(&self, lon_rad: f64, lat_rad: f64, level: u8) -> Option<(TileKey, f64, f64)> {
        let nx = self.scheme.tiles_x(level) as f64;
        let ny = self.scheme.tiles_y(level) as f64;
        let fx = ((lon_rad + PI) / (2.0 * PI)).clamp(0.0, 1.0) * nx;
        let fy = match self.scheme {
            TilingScheme::Geographic | TilingScheme::GeographicReduced => (PI / 2.0 - lat_rad) / PI,
            TilingScheme::WebMercator => lat_to_mercator_y(lat_rad.clamp(-1.5, 1.5)),
        }
        .clamp(0.0, 1.0)
            * ny;
        let tx = (fx.floor()).min(nx - 1.0).max(0.0);
        let ty = (fy.floor()).min(ny - 1.0).max(0.0);
        let key = self.scheme.key(level, tx as u32, ty as u32)?;
        let n = f64::from(self.tile_size);
        let (u, v) = (fx - tx, fy - ty);
        let (px, py) = match self.grid {
            SampleGrid::Corners => (u * (n - 1.0), v * (n - 1.0)),
            SampleGrid::Cells => (
                (u * n - 0.5).clamp(0.0, n - 1.0),
                (v * n - 0.5).clamp(0.0, n - 1.0),
            ),
        };
        Some((key, px, py))
    }
}

/// Samples of one decoded tile that can be interpolated.
pub trait Samples: Send + Sync + 'static {
    /// Width and height, samples.
    fn size(&self) -> (u32, u32);
    /// Bytes held.
    fn byte_size(&self) -> usize;
}

impl Samples for crate::decode::HeightImage {
    fn size(&self) -> (u32, u32) {
        (self.width, self.height)
    }
    fn byte_size(&self) -> usize {
        self.heights_m.len() * 4
    }
}

impl Samples for crate::decode::Rgba {
    fn size(&self) -> (u32, u32) {
        (self.width, self.height)
    }
    fn byte_size(&self) -> usize {
        self.pixels.len()
    }
}

/// A decoded tile, "no tile", or why the tile is broken for good
/// ([`FetchError::Permanent`]: transient failures are not kept).
type TileEntry<T> = Result<Option<Arc<T>>, FetchError>;

/// Decoded tiles with their last-use stamps.
struct TileCache<T> {
    tiles: FxHashMap<TileKey, (TileEntry<T>, u64)>,
    /// The stamp clock.
    now: u64,
    /// Bytes held.
    bytes: usize,
}

/// Bytes an entry of a [`TileCache`] is counted at: its samples, or a small record.
fn entry_bytes<T: Samples>(e: &TileEntry<T>) -> usize {
    const RECORD: usize = 64;
    match e {
        Ok(Some(t)) => t.byte_size() + RECORD,
        Ok(None) => RECORD,
        Err(_) => 4 * RECORD,
    }
}

pub(crate) type Decoder<T> = dyn Fn(&[u8]) -> Result<T, DecodeError> + Send + Sync;

/// A pyramid of decoded tiles of type `T`.
pub struct RasterPyramid<T: Samples> {
    fetch: Arc<dyn Fetch>,
    spec: PyramidSpec,
    decode: Box<Decoder<T>>,
    cache: Mutex<TileCache<T>>,
    cache_bytes: usize,
    /// Tiles whose last fetch failed transiently, and until when reads on another tile's
    /// behalf ([`RasterPyramid::tile_for_neighbour`]) leave them alone.
    failing: Mutex<FxHashMap<TileKey, Instant>>,
    /// Fetches under way: a second caller for the same tile (a neighbour's ring read racing
    /// the tile's own load) waits for the first instead of asking the server again.
    in_flight: Mutex<FxHashMap<TileKey, Arc<Flight<T>>>>,
    /// Tiles that failed for good, for the user to be told.
    failures: Mutex<LayerFailures>,
}

/// How many of the first failures a layer keeps the message of.
const FIRST_FAILURES_KEPT: usize = 3;

/// The tiles of one layer that failed for good (HTTP 403s, undecodable bytes, HTML where a
/// WMS image should be): how many, by kind, and the first few messages (each naming its URL
/// or file). Retried transient failures do not count.
#[derive(Clone, Debug, Default, PartialEq, Eq)]
pub struct LayerFailures {
    /// The layer (its URL template, archive or directory).
    pub layer: String,
    /// Tiles that failed.
    pub tiles: u64,
    /// Counts by kind: `HTTP 403`, `undecodable`, `other`.
    pub by_kind: std::collections::BTreeMap<String, u64>,
    /// The first few failures' messages.
    pub first: Vec<String>,
}

impl LayerFailures {
    fn record(&mut self, kind: String, message: &str) {
        self.tiles += 1;
        *self.by_kind.entry(kind).or_insert(0) += 1;
        if self.first.len() < FIRST_FAILURES_KEPT {
            self.first.push(message.to_string());
        }
    }
}

/// The kind of a fetch failure's message: its HTTP status where it has one.
fn failure_kind(message: &str) -> String {
    message
        .match_indices("HTTP ")
        .find_map(|(i, _)| {
            let code = message.get(i + 5..i + 8)?;
            code.bytes()
                .all(|b| b.is_ascii_digit())
                .then(|| format!("HTTP {code}"))
        })
        .unwrap_or_else(|| "other".into())
}

/// A fetch under way, and its result once it lands.
struct Flight<T> {
    result: Mutex<Option<Result<Option<Arc<T>>, FetchError>>>,
    landed: Condvar,
}

/// The leader's side of a [`Flight`]: lands its result and takes it off the map however the
/// fetch ends (a panicking fetch lands as cancelled, so the followers fetch for themselves).
struct Landing<'a, T: Samples> {
    pyramid: &'a RasterPyramid<T>,
    key: TileKey,
    flight: Arc<Flight<T>>,
}

impl<T: Samples> Drop for Landing<'_, T> {
    fn drop(&mut self) {
        {
            let mut r = self.flight.result.lock().unwrap_or_else(|p| p.into_inner());
            if r.is_none() {
                *r = Some(Err(FetchError::Cancelled));
            }
        }
        self.flight.landed.notify_all();
        self.pyramid.end_flight(self.key, &self.flight);
    }
}

/// How often a caller waiting on another's fetch looks at its own cancel flag.
const FOLLOWER_POLL: Duration = Duration::from_millis(20);

/// How long reads on a neighbour's behalf leave a transiently failing tile alone (longer if
/// the server asked for longer with Retry-After).
const NEIGHBOUR_QUIET: Duration = Duration::from_secs(10);

impl<T: Samples> RasterPyramid<T> {
    /// A pyramid read through `fetch`, decoded by `decode`, keeping decoded tiles up to
    /// `cache_bytes` (neighbouring engine tiles share source tiles when schemes or levels
    /// differ).
    pub fn new(
        fetch: Arc<dyn Fetch>,
        spec: PyramidSpec,
        decode: Box<Decoder<T>>,
        cache_bytes: usize,
    ) -> Self {
        Self {
            fetch,
            spec,
            decode,
            cache: Mutex::new(TileCache {
                tiles: FxHashMap::default(),
                now: 0,
                bytes: 0,
            }),
            cache_bytes,
            failing: Mutex::new(FxHashMap::default()),
            in_flight: Mutex::new(FxHashMap::default()),
            failures: Mutex::new(LayerFailures::default()),
        }
    }

    /// Bytes of decoded tiles held.
    pub fn cached_bytes(&self) -> usize {
        self.cache.lock().unwrap_or_else(|p| p.into_inner()).bytes
    }

    /// The layout.
    pub fn spec(&self) -> &PyramidSpec {
        &self.spec
    }

    /// The fetcher's name.
    pub fn name(&self) -> &str {
        self.fetch.name()
    }

    /// A decoded tile, `None` where the pyramid has none. A tile whose bytes do not decode is
    /// a permanent error, remembered (while it stays in the cache) so it is not fetched again
    /// for every engine tile that needs it.
    ///
    /// Concurrent calls for one tile make one request: the others wait for it (each still
    /// stops when its own `cancel` fires), and take over if the one fetching is cancelled.
    pub fn tile(&self, key: TileKey, cancel: &Cancel) -> Result<Option<Arc<T>>, FetchError> {
        loop {
            {
                let mut c = self.cache.lock().unwrap_or_else(|p| p.into_inner());
                c.now += 1;
                let now = c.now;
                if let Some(e) = c.tiles.get_mut(&key) {
                    e.1 = now;
                    return e.0.clone();
                }
            }
            let (flight, leads) = {
                let mut f = self.in_flight.lock().unwrap_or_else(|p| p.into_inner());
                match f.get(&key) {
                    Some(flight) => (Arc::clone(flight), false),
                    None => {
                        let flight = Arc::new(Flight {
                            result: Mutex::new(None),
                            landed: Condvar::new(),
                        });
                        f.insert(key, Arc::clone(&flight));
                        (flight, true)
                    }
                }
            };
            if leads {
                let landing = Landing {
                    pyramid: self,
                    key,
                    flight,
                };
                let result = self.fetch_and_keep(key, cancel);
                *landing
                    .flight
                    .result
                    .lock()
                    .unwrap_or_else(|p| p.into_inner()) = Some(result.clone());
                return result;
            }
            let mut r = flight.result.lock().unwrap_or_else(|p| p.into_inner());
            loop {
                match r.as_ref() {
                    // The one fetching was cancelled: fetch it ourselves (or find it cached).
                    Some(Err(FetchError::Cancelled)) => {
                        self.end_flight(key, &flight);
                        break;
                    }
                    Some(done) => return done.clone(),
                    None if cancel.is_cancelled() => return Err(FetchError::Cancelled),
                    None => {
                        r = flight
                            .landed
                            .wait_timeout(r, FOLLOWER_POLL)
                            .unwrap_or_else(|p| p.into_inner())
                            .0;
                    }
                }
            }
        }
    }

    /// Takes `flight` off the map (unless a newer one for `key` has replaced it).
    fn end_flight(&self, key: TileKey, flight: &Arc<Flight<T>>) {
        let mut f = self.in_flight.lock().unwrap_or_else(|p| p.into_inner());
        if f.get(&key).is_some_and(|g| Arc::ptr_eq(g, flight)) {
            f.remove(&key);
        }
    }

    /// Fetches and decodes a tile, keeping the outcome in the cache unless it was transient.
    fn fetch_and_keep(&self, key: TileKey, cancel: &Cancel) -> Result<Option<Arc<T>>, FetchError> {
        let entry = match self.fetch.fetch(key, cancel) {
            Ok(None) => Ok(None),
            Ok(Some(f)) => match self.decode_checked(key, &f.bytes) {
                Ok(t) => Ok(Some(Arc::new(t))),
                Err(e) => {
                    self.record_failure("undecodable".into(), &e);
                    Err(e)
                }
            },
            Err(e @ FetchError::Permanent(_)) => {
                if let FetchError::Permanent(m) = &e {
                    self.record_failure(failure_kind(m), &e);
                }
                Err(e)
            }
            Err(e) => {
                if let FetchError::Transient { retry_after, .. } = &e {
                    let quiet = retry_after.map_or(NEIGHBOUR_QUIET, |r| r.max(NEIGHBOUR_QUIET));
                    self.failing
                        .lock()
                        .unwrap_or_else(|p| p.into_inner())
                        .insert(key, Instant::now() + quiet);
                }
                return Err(e);
            }
        };
        self.failing
            .lock()
            .unwrap_or_else(|p| p.into_inner())
            .remove(&key);
        let bytes = entry_bytes(&entry);
        let mut c = self.cache.lock().unwrap_or_else(|p| p.into_inner());
        c.now += 1;
        let now = c.now;
        if c.bytes + bytes > self.cache_bytes {
            // Drop the least recently used until the new tile fits (all of them if it alone
            // is over the budget: it is still returned, and kept until the next one comes).
            let mut stamps: Vec<(u64, TileKey)> = c.tiles.iter().map(|(k, e)| (e.1, *k)).collect();
            stamps.sort_unstable();
            for (_, k) in stamps {
                if c.bytes + bytes <= self.cache_bytes {
                    break;
                }
                if let Some(e) = c.tiles.remove(&k) {
                    c.bytes -= entry_bytes(&e.0);
                }
            }
        }
        if let Some(old) = c.tiles.insert(key, (entry.clone(), now)) {
            c.bytes -= entry_bytes(&old.0);
        }
        c.bytes += bytes;
        entry
    }

    fn record_failure(&self, kind: String, e: &FetchError) {
        self.failures
            .lock()
            .unwrap_or_else(|p| p.into_inner())
            .record(kind, &e.to_string());
    }

    /// The tiles that failed for good so far.
    pub fn failures(&self) -> LayerFailures {
        let mut f = self
            .failures
            .lock()
            .unwrap_or_else(|p| p.into_inner())
            .clone();
        f.layer = self.fetch.name().to_string();
        f
    }

    /// Like [`RasterPyramid::tile`], for samples a tile reads beyond its own edges: a tile
    /// whose fetch failed transiently a moment ago is not asked again on a neighbour's
    /// behalf (its own load retries it on the scheduler's terms, Retry-After included).
    pub fn tile_for_neighbour(
        &self,
        key: TileKey,
        cancel: &Cancel,
    ) -> Result<Option<Arc<T>>, FetchError> {
        let until = self
            .failing
            .lock()
            .unwrap_or_else(|p| p.into_inner())
            .get(&key)
            .copied();
        if until.is_some_and(|u| Instant::now() < u) {
            return Err(FetchError::transient(format!(
                "{}: failing, left alone for now",
                self.fetch.locate(key)
            )));
        }
        self.tile(key, cancel)
    }

    /// Decodes a tile's bytes; a tile that does not decode, or decodes to another size than
    /// the pyramid's, is broken for good.
    fn decode_checked(&self, key: TileKey, bytes: &[u8]) -> Result<T, FetchError> {
        let t = (self.decode)(bytes)
            .map_err(|e| FetchError::Permanent(format!("{}: {e}", self.fetch.locate(key))))?;
        let (w, h) = t.size();
        if w != self.spec.tile_size || h != self.spec.tile_size {
            return Err(FetchError::Permanent(format!(
                "{}: {w} x {h} samples, the pyramid's tiles have {1} x {1}",
                self.fetch.locate(key),
                self.spec.tile_size
            )));
        }
        Ok(t)
    }
}

/// Bilinear interpolation of `get(x, y)` at fractional sample coordinates.
pub fn bilinear(px: f64, py: f64, w: u32, h: u32, get: impl Fn(u32, u32) -> f64) -> f64 {
    let x0 = (px.floor().max(0.0) as u32).min(w - 1);
    let y0 = (py.floor().max(0.0) as u32).min(h - 1);
    let x1 = (x0 + 1).min(w - 1);
    let y1 = (y0 + 1).min(h - 1);
    let (fx, fy) = (px - f64::from(x0), py - f64::from(y0));
    let top = get(x0, y0) * (1.0 - fx) + get(x1, y0) * fx;
    let bottom = get(x0, y1) * (1.0 - fx) + get(x1, y1) * fx;
    top * (1.0 - fy) + bottom * fy
}

#[cfg(test)]
mod tests {
    use super::*;
    use globus_test_support::eventually;

    fn spec(scheme: TilingScheme, grid: SampleGrid) -> PyramidSpec {
        PyramidSpec {
            scheme,
            min_level: 0,
            max_level: 12,
            tile_size: 256,
            grid,
            bounds: GeoRect::WORLD,
        }
    }

    #[test]
    fn locates_samples_in_both_schemes() {
        let g = spec(TilingScheme::Geographic, SampleGrid::Corners);
        // Geographic level 1: tile (2, 0) spans 0..90 E, 0..90 N; its centre is sample 127.5.
        let (k, x, y) = g.locate(45f64.to_radians(), 45f64.to_radians(), 1).unwrap();
        assert_eq!(k, TileKey::new(1, 2, 0));
        assert!((x - 127.5).abs() < 1e-9 && (y - 127.5).abs() < 1e-9);
        let m = spec(TilingScheme::WebMercator, SampleGrid::Cells);
        // Web Mercator level 1: 45 N lies at mercator fraction 0.3597 of the square, so at
        // 0.7194 of tile (1, 0), pixel 0.7194 * 256 - 0.5.
        let (k, x, y) = m.locate(45f64.to_radians(), 45f64.to_radians(), 1).unwrap();
        assert_eq!(k, TileKey::new(1, 1, 0));
        let want = (lat_to_mercator_y(45f64.to_radians()) * 2.0) * 256.0 - 0.5;
        assert!((y - want).abs() < 1e-9 && (x - (0.25 * 256.0 - 0.5)).abs() < 1e-9);
        // Beyond the Mercator square: the edge row, not a wrap.
        let (_, _, y) = m.locate(0.0, 89f64.to_radians(), 3).unwrap();
        assert_eq!(y, 0.0);
        // Spacing to level: geographic 256-sample corner tiles at level 3 are 22.5/255 deg apart.
        let spacing = (22.5f64 / 255.0).to_radians();
        assert_eq!(g.level_for_spacing(spacing), 3);
        assert_eq!(g.level_for_spacing(spacing * 0.99), 4);
        assert_eq!(g.level_for_spacing(1e-12), 12);
    }

    /// A Web Mercator pyramid read through `fetch` whose every tile decodes to 256 x 256 blank
    /// pixels, keeping `cache_bytes` of them.
    fn blank_pyramid(
        fetch: Arc<dyn Fetch>,
        cache_bytes: usize,
    ) -> RasterPyramid<crate::decode::Rgba> {
        let decode: Box<Decoder<crate::decode::Rgba>> = Box::new(|_| {
            Ok(crate::decode::Rgba {
                width: 256,
                height: 256,
                pixels: vec![0; 256 * 256 * 4],
            })
        });
        RasterPyramid::new(
            fetch,
            spec(TilingScheme::WebMercator, SampleGrid::Cells),
            decode,
            cache_bytes,
        )
    }

    /// Tiles whose bytes are their key's level, counting fetches.
    struct Counting(std::sync::atomic::AtomicUsize);

    impl Fetch for Counting {
        fn name(&self) -> &str {
            "counting"
        }
        fn fetch(
            &self,
            key: TileKey,
            _: &Cancel,
        ) -> Result<Option<crate::fetch::Fetched>, FetchError> {
            self.0.fetch_add(1, std::sync::atomic::Ordering::Relaxed);
            Ok(Some(crate::fetch::Fetched::local(vec![key.level()])))
        }
    }

    #[test]
    fn decoded_tiles_stay_within_their_byte_budget() {
        let fetch = Arc::new(Counting(Default::default()));
        let tile_bytes = 256 * 256 * 4;
        // Room for five tiles and their records, not six.
        let budget = 5 * tile_bytes + 5 * 64 + 100;
        let p = blank_pyramid(fetch.clone(), budget);
        let cancel = Cancel::new();
        let keys: Vec<TileKey> = (0..40).map(|x| TileKey::new(6, x, 7)).collect();
        for k in &keys {
            p.tile(*k, &cancel).expect("tile");
            assert!(
                p.cached_bytes() <= budget,
                "{} > {budget}",
                p.cached_bytes()
            );
        }
        assert_eq!(p.cached_bytes(), 5 * (tile_bytes + 64));
        // The five most recent are kept (no fetch), the first one was dropped (fetched again).
        let before = fetch.0.load(std::sync::atomic::Ordering::Relaxed);
        for k in &keys[35..] {
            p.tile(*k, &cancel).expect("tile");
        }
        assert_eq!(fetch.0.load(std::sync::atomic::Ordering::Relaxed), before);
        p.tile(keys[0], &cancel).expect("tile");
        assert_eq!(
            fetch.0.load(std::sync::atomic::Ordering::Relaxed),
            before + 1
        );
    }

    /// Fails transiently (with a Retry-After of 30 s) while `failing` is set.
    struct Flaky {
        calls: std::sync::atomic::AtomicUsize,
        failing: std::sync::atomic::AtomicBool,
    }

    impl Fetch for Flaky {
        fn name(&self) -> &str {
            "flaky"
        }
        fn fetch(
            &self,
            _: TileKey,
            _: &Cancel,
        ) -> Result<Option<crate::fetch::Fetched>, FetchError> {
            use std::sync::atomic::Ordering::Relaxed;
            self.calls.fetch_add(1, Relaxed);
            if self.failing.load(Relaxed) {
                Err(FetchError::Transient {
                    message: "503".into(),
                    retry_after: Some(Duration::from_secs(30)),
                })
            } else {
                Ok(Some(crate::fetch::Fetched::local(vec![1])))
            }
        }
    }

    #[test]
    fn reads_for_a_neighbour_leave_a_failing_tile_alone() {
        use std::sync::atomic::Ordering::Relaxed;
        let fetch = Arc::new(Flaky {
            calls: Default::default(),
            failing: std::sync::atomic::AtomicBool::new(true),
        });
        let p = blank_pyramid(fetch.clone(), 1 << 20);
        let (key, cancel) = (TileKey::new(3, 1, 1), Cancel::new());
        assert!(p.tile(key, &cancel).is_err());
        assert_eq!(fetch.calls.load(Relaxed), 1);
        // A neighbour's read: no request (the server asked for 30 s).
        assert!(matches!(
            p.tile_for_neighbour(key, &cancel),
            Err(FetchError::Transient { .. })
        ));
        assert_eq!(fetch.calls.load(Relaxed), 1);
        // The tile's own load asks again (the scheduler decides when), and once it
        // succeeds neighbours read it too.
        fetch.failing.store(false, Relaxed);
        assert!(p.tile(key, &cancel).expect("own load").is_some());
        assert!(
            p.tile_for_neighbour(key, &cancel)
                .expect("cached")
                .is_some()
        );
        assert_eq!(fetch.calls.load(Relaxed), 2);
    }

    /// Holds every fetch until opened (or until the caller is cancelled), counting them.
    #[derive(Default)]
    struct Gated {
        calls: std::sync::atomic::AtomicUsize,
        open: std::sync::atomic::AtomicBool,
    }

    impl Fetch for Gated {
        fn name(&self) -> &str {
            "gated"
        }
        fn fetch(
            &self,
            _: TileKey,
            cancel: &Cancel,
        ) -> Result<Option<crate::fetch::Fetched>, FetchError> {
            use std::sync::atomic::Ordering::SeqCst;
            self.calls.fetch_add(1, SeqCst);
            while !self.open.load(SeqCst) {
                if cancel.is_cancelled() {
                    return Err(FetchError::Cancelled);
                }
                std::thread::sleep(Duration::from_millis(1));
            }
            Ok(Some(crate::fetch::Fetched::local(vec![1])))
        }
    }

    fn gated_pyramid() -> (Arc<Gated>, Arc<RasterPyramid<crate::decode::Rgba>>) {
        let fetch = Arc::new(Gated::default());
        let p = blank_pyramid(fetch.clone(), 1 << 20);
        (fetch, Arc::new(p))
    }

    #[test]
    fn concurrent_reads_of_one_tile_make_one_request() {
        use std::sync::atomic::Ordering::SeqCst;
        let (fetch, p) = gated_pyramid();
        let key = TileKey::new(4, 3, 2);
        let readers: Vec<_> = (0..4)
            .map(|i| {
                let p = Arc::clone(&p);
                std::thread::spawn(move || {
                    let cancel = Cancel::new();
                    if i % 2 == 0 {
                        p.tile(key, &cancel)
                    } else {
                        p.tile_for_neighbour(key, &cancel)
                    }
                })
            })
            .collect();
        eventually("the first request", || fetch.calls.load(SeqCst) == 1);
        std::thread::sleep(Duration::from_millis(50));
        fetch.open.store(true, SeqCst);
        for r in readers {
            let got = r.join().expect("reader").expect("tile");
            assert!(got.is_some());
        }
        assert_eq!(fetch.calls.load(SeqCst), 1);
        assert!(p.in_flight.lock().unwrap().is_empty());
    }

    #[test]
    fn a_waiting_reader_takes_over_when_the_fetching_one_is_cancelled() {
        use std::sync::atomic::Ordering::SeqCst;
        let (fetch, p) = gated_pyramid();
        let key = TileKey::new(4, 3, 2);
        let (first, second, third) = (Cancel::new(), Cancel::new(), Cancel::new());
        let read = |cancel: &Cancel| {
            let (p, cancel) = (Arc::clone(&p), cancel.clone());
            std::thread::spawn(move || p.tile(key, &cancel))
        };
        let a = read(&first);
        eventually("the first request", || fetch.calls.load(SeqCst) == 1);
        let b = read(&second);
        let c = read(&third);
        std::thread::sleep(Duration::from_millis(50));
        // A waiting reader that is no longer wanted stops waiting; the fetch goes on.
        third.cancel();
        assert_eq!(c.join().expect("third"), Err(FetchError::Cancelled));
        assert_eq!(fetch.calls.load(SeqCst), 1);
        // The fetching reader is cancelled: the other waiting one fetches for itself.
        first.cancel();
        assert_eq!(a.join().expect("first"), Err(FetchError::Cancelled));
        eventually("the second request", || fetch.calls.load(SeqCst) == 2);
        fetch.open.store(true, SeqCst);
        assert!(b.join().expect("second").expect("tile").is_some());
        assert_eq!(fetch.calls.load(SeqCst), 2);
        // Kept: a later read makes no request.
        assert!(p.tile(key, &Cancel::new()).expect("cached").is_some());
        assert_eq!(fetch.calls.load(SeqCst), 2);
    }

    #[test]
    fn bilinear_interpolates_and_clamps() {
        let get = |x: u32, y: u32| f64::from(x * 10 + y);
        assert!((bilinear(0.5, 0.5, 4, 4, get) - 5.5).abs() < 1e-12);
        assert!((bilinear(3.0, 3.0, 4, 4, get) - 33.0).abs() < 1e-12);
    }
}
