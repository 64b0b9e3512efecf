//! Building a pyramid: a depth-first walk of the quadtree over the data's footprint. Tiles
//! at the finest level are resampled from the source; every coarser tile is made from its
//! four children while they are still in memory, then written, so the source is read once
//! and memory holds only the tiles on the active paths (about four per level per thread).
//! Siblings are built in parallel (rayon work stealing).

use std::sync::atomic::{AtomicU64, Ordering};
use std::time::{Duration, Instant};

use globus_tiling::{GeoRect, TileKey, TilingScheme};
use rayon::prelude::*;

use crate::error::Result;
use crate::layer::{Layer, TileCodec};
use crate::raster::intersect;
use crate::sink::TileSink;

/// The range of tile columns and rows at a level that intersect a footprint.
#[derive(Clone, Copy, Debug, PartialEq, Eq)]
pub struct TileRange {
    /// The level.
    pub level: u8,
    /// First and last column.
    pub x: (u32, u32),
    /// First and last row (from the north).
    pub y: (u32, u32),
}

impl TileRange {
    /// The number of tiles in the range.
    pub fn count(&self) -> u64 {
        u64::from(self.x.1 - self.x.0 + 1) * u64::from(self.y.1 - self.y.0 + 1)
    }
}

/// First index in `0..n` where `pred` turns false (`pred` is true then false).
fn partition_point(n: u64, pred: impl Fn(u64) -> bool) -> u64 {
    let (mut lo, mut hi) = (0u64, n);
    while lo < hi {
        let mid = lo + (hi - lo) / 2;
        if pred(mid) {
            lo = mid + 1;
        } else {
            hi = mid;
        }
    }
    lo
}

/// The tiles of `level` whose rectangles intersect `footprint` (with positive area, or also
/// by touching when `closed`), exactly as [`covers`] decides per tile.
pub fn tile_range(
    scheme: TilingScheme,
    level: u8,
    footprint: &GeoRect,
    closed: bool,
) -> Option<TileRange> {
    let (nx, ny) = (scheme.tiles_x(level), scheme.tiles_y(level));
    let col = |i: u64| scheme.rect(TileKey::new(level, i as u32, 0));
    let row = |j: u64| scheme.rect(TileKey::new(level, 0, j as u32));
    let before = |a: f64, b: f64| if closed { a < b } else { a <= b };
    // Each predicate is true for the tiles before the range (or not yet past it).
    let x0 = partition_point(nx, |i| before(col(i).east, footprint.west));
    let x_end = partition_point(nx, |i| !before(footprint.east, col(i).west));
    let y0 = partition_point(ny, |j| before(footprint.north, row(j).south));
    let y_end = partition_point(ny, |j| !before(row(j).north, footprint.south));
    (x0 < x_end && y0 < y_end).then(|| TileRange {
        level,
        x: (x0 as u32, (x_end - 1) as u32),
        y: (y0 as u32, (y_end - 1) as u32),
    })
}

/// Whether a tile is part of the pyramid over `footprint`.
pub fn covers(scheme: TilingScheme, key: TileKey, footprint: &GeoRect, closed: bool) -> bool {
    intersect(&scheme.rect(key), footprint, closed).is_some()
}

/// Tiles done and bytes written, shared by the workers and the progress display.
#[derive(Debug, Default)]
pub struct Progress {
    /// Tiles written or found already written.
    pub tiles: AtomicU64,
    /// Tiles written by this run.
    pub written: AtomicU64,
    /// Bytes written by this run.
    pub bytes: AtomicU64,
    /// Tiles the job will make in all.
    pub total: AtomicU64,
}

/// Tiles at a hand-over level, kept raw (exact samples) for building the levels above them
/// elsewhere: see [`crate::shard`].
pub type Handover = std::sync::Mutex<Vec<(TileKey, Vec<u8>)>>;

/// One pyramid build.
pub struct Pyramid<'a, L: Layer> {
    /// What the tiles are made of.
    pub layer: &'a L,
    /// Where they go.
    pub sink: &'a dyn TileSink,
    /// The tiling scheme.
    pub scheme: TilingScheme,
    /// The data's extent; tiles outside it are not made.
    pub footprint: GeoRect,
    /// Whether tiles merely touching the footprint are made (corner grids, whose edge
    /// samples must exist on both sides of every edge).
    pub closed: bool,
    /// The tiles the walk starts from: the scheme's roots, or one shard's share of a level.
    pub starts: Vec<TileKey>,
    /// The levels written, coarsest and finest.
    pub write_levels: (u8, u8),
    /// The finest level, made by [`Layer::leaf`].
    pub max_level: u8,
    /// Reuse tiles the sink already holds instead of rebuilding their subtrees.
    pub resume: bool,
    /// Keep the raw tiles of this level (the shard hand-over level) here.
    pub handover: Option<(u8, &'a Handover)>,
    /// Counters.
    pub progress: &'a Progress,
}

/// The number of tiles of `levels` over `footprint` below `within` (itself included).
pub fn count_tiles(
    scheme: TilingScheme,
    footprint: &GeoRect,
    closed: bool,
    levels: (u8, u8),
    within: TileKey,
) -> u64 {
    let Some(fp) = intersect(&scheme.rect(within), footprint, closed) else {
        return 0;
    };
    (levels.0.max(within.level())..=levels.1)
        .map(|level| {
            let Some(r) = tile_range(scheme, level, &fp, closed) else {
                return 0;
            };
            // The intersection may touch neighbours of `within`; keep its descendants.
            let shift = level - within.level();
            let (kx0, kx1) = (within.x() << shift, ((within.x() + 1) << shift) - 1);
            let (ky0, ky1) = (within.y() << shift, ((within.y() + 1) << shift) - 1);
            let x = (r.x.0.max(kx0), r.x.1.min(kx1));
            let y = (r.y.0.max(ky0), r.y.1.min(ky1));
            if x.0 > x.1 || y.0 > y.1 {
                0
            } else {
                u64::from(x.1 - x.0 + 1) * u64::from(y.1 - y.0 + 1)
            }
        })
        .sum()
}

type TileOf<L> = <<L as Layer>::Codec as TileCodec>::Tile;

impl<L: Layer> Pyramid<'_, L> {
    /// The number of tiles this build writes (or finds written).
    pub fn count(&self) -> u64 {
        self.starts.iter().map(|&k| self.count_below(k)).sum()
    }

    fn count_below(&self, key: TileKey) -> u64 {
        count_tiles(
            self.scheme,
            &self.footprint,
            self.closed,
            self.write_levels,
            key,
        )
    }

    /// Builds and writes every tile.
    pub fn run(&self) -> Result<()> {
        self.starts
            .par_iter()
            .map(|&start| self.build(start).map(|_| ()))
            .collect()
    }

    fn writes(&self, level: u8) -> bool {
        (self.write_levels.0..=self.write_levels.1).contains(&level)
    }

    fn build(&self, key: TileKey) -> Result<Option<TileOf<L>>> {
        if !covers(self.scheme, key, &self.footprint, self.closed) {
            return Ok(None);
        }
        let level = key.level();
        let codec = self.layer.codec();
        let handover_here = matches!(self.handover, Some((l, _)) if l == level);
        if self.resume
            && self.writes(level)
            && !handover_here
            && let Some(bytes) = self.sink.existing(key)?
            // A tile cut short by the interruption does not decode: build it again.
            && let Ok(tile) = codec.decode(key, &bytes)
        {
            // A parent is written after all its children, so its subtree is complete.
            self.progress
                .tiles
                .fetch_add(self.count_below(key), Ordering::Relaxed);
            return Ok(Some(tile));
        }
        let tile = match key.children() {
            Some(children) if level < self.max_level => {
                let built: Vec<Result<Option<TileOf<L>>>> =
                    children.par_iter().map(|&c| self.build(c)).collect();
                let mut kids: [Option<TileOf<L>>; 4] = [None, None, None, None];
                for (slot, b) in kids.iter_mut().zip(built) {
                    *slot = b?;
                }
                if level < self.write_levels.0 && !handover_here {
                    return Ok(None);
                }
                codec.downsample(&kids)
            }
            _ => self.layer.leaf(self.scheme, key)?,
        };
        if let Some((_, store)) = self.handover.filter(|_| handover_here) {
            let raw = codec.tile_to_raw(&tile);
            store
                .lock()
                .map_err(|_| crate::error::TilerError::BadOptions("a worker panicked".into()))?
                .push((key, raw));
        }
        if self.writes(level) {
            let bytes = codec.encode(key, &tile)?;
            self.sink.put(key, &bytes)?;
            self.progress.tiles.fetch_add(1, Ordering::Relaxed);
            self.progress.written.fetch_add(1, Ordering::Relaxed);
            self.progress
                .bytes
                .fetch_add(bytes.len() as u64, Ordering::Relaxed);
        }
        Ok(Some(tile))
    }
}

/// Where a job stands, as reported to a progress callback ([`crate::run_with_progress`]).
#[derive(Clone, Copy, Debug, PartialEq)]
pub struct ProgressReport {
    /// Tiles written or found already written.
    pub tiles_done: u64,
    /// Tiles the job will make in all.
    pub tiles_total: u64,
    /// Bytes written so far.
    pub bytes: u64,
    /// Time since the job started.
    pub elapsed: Duration,
}

/// What a job calls with its progress: a few times a second while it runs (from a thread of
/// its own), and once at the end.
pub type ProgressFn<'a> = dyn Fn(&ProgressReport) + Sync + 'a;

impl Progress {
    fn report(&self, start: Instant) -> ProgressReport {
        ProgressReport {
            tiles_done: self.tiles.load(Ordering::Relaxed),
            tiles_total: self.total.load(Ordering::Relaxed),
            bytes: self.bytes.load(Ordering::Relaxed),
            elapsed: start.elapsed(),
        }
    }
}

/// Calls `on_progress` every quarter second until `done` is set, then once more.
pub fn report_progress(
    progress: &Progress,
    done: &std::sync::atomic::AtomicBool,
    start: Instant,
    on_progress: &ProgressFn<'_>,
) {
    let period = Duration::from_millis(250);
    while !done.load(Ordering::Relaxed) {
        std::thread::sleep(period);
        on_progress(&progress.report(start));
    }
    on_progress(&progress.report(start));
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn ranges_match_the_per_tile_test() {
        let fp = GeoRect::from_degrees(11.0, 57.0, 12.0, 58.0);
        for scheme in [TilingScheme::Geographic, TilingScheme::WebMercator] {
            for closed in [false, true] {
                for level in 0..9u8 {
                    let r = tile_range(scheme, level, &fp, closed).unwrap();
                    let mut n = 0;
                    for y in 0..scheme.tiles_y(level) as u32 {
                        for x in 0..scheme.tiles_x(level) as u32 {
                            let k = TileKey::new(level, x, y);
                            let inside = covers(scheme, k, &fp, closed);
                            let in_range =
                                (r.x.0..=r.x.1).contains(&x) && (r.y.0..=r.y.1).contains(&y);
                            assert_eq!(inside, in_range, "{scheme:?} closed {closed} {k:?}");
                            n += u64::from(inside);
                        }
                    }
                    assert_eq!(n, r.count());
                }
            }
        }
        // Level 8 geographic tiles are 0.703125 degrees: 11..12 E spans columns 271..273,
        // 57..58 N rows 45..46.
        let r = tile_range(TilingScheme::Geographic, 8, &fp, false).unwrap();
        assert_eq!((r.x, r.y), ((271, 273), (45, 46)));
    }
}
