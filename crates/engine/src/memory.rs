//! One memory budget for everything Globus holds (`memory_mb` in the config file,
//! `--memory-mb`): the process as it stands before any tile (code, GPU driver, targets,
//! vector features already read: measured when the globe is made, plus what a software
//! rasteriser's first draw adds, an eighth of the total for the triangles it bins (the
//! error bound rises when a frame draws more) and what overlays reserved for their GPU
//! buffers),
//! headroom for loads in flight and allocator slack, the decoded source tiles and
//! refinement bases of the data sources, the GPU tile pools (counted
//! in full: on a software rasteriser they are host memory, on a GPU they are video memory an
//! application should not overrun either) and the cache of loaded tiles, which gets the rest.
//!
//! When the parts fill up, the engine lowers detail (raises the error bound) instead of
//! growing: the tile cache and the pools never grow past their share.

use crate::EngineError;

/// Default total budget of `globus view|render|bench`, MiB, when the config sizes no cache.
pub const DEFAULT_MEMORY_MB: u64 = 1024;

/// Share of the total for the data sources' own caches: decoded source tiles (shared by all
/// layers) and refinement bases.
const SOURCE_TILES_SHARE: f64 = 0.06;
const REFINE_BASES_SHARE: f64 = 0.03;
/// Share of what is left for the GPU pools (the rest is the tile cache), and their size limits.
const GPU_SHARE: f64 = 0.3;
const MIN_GPU_SLOTS: u32 = 256;
const MAX_GPU_SLOTS: u32 = 2048;
/// The least tile cache worth having (a 1080p view draws a few hundred tiles).
const MIN_TILE_CACHE: u64 = 48 << 20;
/// Headroom: fixed, per loader thread (a response body, its decoded image and the tile built
/// from it), and a share of the total for allocator slack. Measured: a 30-minute soak with
/// 32 loader threads on lavapipe peaked 140 MiB above the accounted parts (loads in flight
/// after a jump, the driver's staging and shader memory) against 128 MiB of headroom at
/// 2 MiB per thread; 3 MiB per thread leaves room.
const HEADROOM_FIXED: u64 = 32 << 20;
const HEADROOM_PER_WORKER: u64 = 3 << 20;
const HEADROOM_SHARE: f64 = 1.0 / 16.0;
/// Used for the process's own footprint where it cannot be measured (not Linux).
const BASELINE_ESTIMATE: u64 = 160 << 20;

/// The data sources' share of a total budget.
#[derive(Clone, Copy, Debug, PartialEq, Eq)]
pub struct SourceBudgets {
    /// Decoded source tiles, for each of `layers` layers.
    pub per_layer: usize,
    /// Refinement bases.
    pub refine_bases: usize,
}

impl SourceBudgets {
    /// The shares of `total` bytes for sources with `layers` raster layers.
    pub fn of(total: u64, layers: usize) -> Self {
        let tiles = total as f64 * SOURCE_TILES_SHARE;
        Self {
            per_layer: (tiles / layers.max(1) as f64) as usize,
            refine_bases: (total as f64 * REFINE_BASES_SHARE) as usize,
        }
    }

    /// Both together (what the plan sets aside for them, whatever the number of layers).
    fn all(total: u64) -> u64 {
        (total as f64 * (SOURCE_TILES_SHARE + REFINE_BASES_SHARE)) as u64
    }
}

/// How a total budget is shared.
#[derive(Clone, Copy, Debug, PartialEq, Eq)]
pub struct MemoryPlan {
    /// The whole budget, bytes.
    pub total: u64,
    /// The process before any tile (with what a software rasteriser's first draw adds and
    /// what the application reserved for its overlays).
    pub baseline: u64,
    /// Loads in flight and allocator slack.
    pub headroom: u64,
    /// Caches of the data sources (decoded source tiles, refinement bases).
    pub sources: u64,
    /// Tile slots of the GPU pools.
    pub gpu_slots: u32,
    /// Bytes of those pools.
    pub gpu_pool: u64,
    /// The loaded-tile cache.
    pub tile_cache: u64,
}

impl MemoryPlan {
    /// Shares `total` bytes: `baseline` is the process's footprint now (`None`: unknown,
    /// estimated), `workers` the loader threads, `sources_cached` whether the data sources
    /// keep caches of their own, `gpu_bytes(slots)` the bytes of pools of that many slots.
    /// Refuses a total too small for a usable tile cache and pool, naming the least that
    /// would do.
    pub fn new(
        total: u64,
        baseline: Option<u64>,
        workers: usize,
        sources_cached: bool,
        gpu_bytes: impl Fn(u32) -> u64,
    ) -> Result<Self, EngineError> {
        let baseline = baseline.unwrap_or(BASELINE_ESTIMATE);
        let headroom = HEADROOM_FIXED
            + HEADROOM_PER_WORKER * workers as u64
            + (total as f64 * HEADROOM_SHARE) as u64;
        let sources = if sources_cached {
            SourceBudgets::all(total)
        } else {
            0
        };
        let fixed = baseline + headroom + sources;
        let least = gpu_bytes(MIN_GPU_SLOTS) + MIN_TILE_CACHE;
        let left = total.saturating_sub(fixed);
        if left < least {
            // Headroom and sources grow with the total: solve for the total that leaves `least`.
            let share = HEADROOM_SHARE
                + if sources_cached {
                    SOURCE_TILES_SHARE + REFINE_BASES_SHARE
                } else {
                    0.0
                };
            let fixed_part = baseline + HEADROOM_FIXED + HEADROOM_PER_WORKER * workers as u64;
            let need = ((fixed_part + least) as f64 / (1.0 - share)).ceil() as u64;
            return Err(EngineError::MemoryBudget {
                total_mib: total >> 20,
                baseline_mib: baseline >> 20,
                workers,
                least_mib: need.div_ceil(1 << 20),
            });
        }
        let per_slot = gpu_bytes(MAX_GPU_SLOTS) as f64 / f64::from(MAX_GPU_SLOTS);
        let gpu_slots = ((left as f64 * GPU_SHARE) / per_slot.max(1.0)) as u32;
        let mut gpu_slots = gpu_slots.clamp(MIN_GPU_SLOTS, MAX_GPU_SLOTS);
        while gpu_slots > MIN_GPU_SLOTS && gpu_bytes(gpu_slots) + MIN_TILE_CACHE > left {
            gpu_slots -= 1;
        }
        // The pool gives a multiple of 6 one layer more (`globus_render::array_layers`, for
        // the GL backend): plan one less, so the pool is the size and the bytes planned.
        // (The bounds are no multiples of 6, so this stays within them.)
        if gpu_slots.is_multiple_of(6) {
            gpu_slots -= 1;
        }
        let gpu_pool = gpu_bytes(gpu_slots);
        Ok(Self {
            total,
            baseline,
            headroom,
            sources,
            gpu_slots,
            gpu_pool,
            tile_cache: left - gpu_pool,
        })
    }
}

/// A `kB` figure from a `/proc` file, bytes.
fn proc_kb(file: &str, key: &str) -> Option<u64> {
    let text = std::fs::read_to_string(file).ok()?;
    let kb = text
        .lines()
        .find(|l| l.starts_with(key))?
        .split_whitespace()
        .nth(1)?
        .parse::<u64>()
        .ok()?;
    Some(kb << 10)
}

/// Resident memory of this process, bytes (Linux; `None` elsewhere).
pub fn resident_bytes() -> Option<u64> {
    proc_kb("/proc/self/status", "VmRSS:")
}

/// The machine's memory, bytes (Linux; `None` elsewhere): the largest budget that makes sense.
pub fn physical_bytes() -> Option<u64> {
    proc_kb("/proc/meminfo", "MemTotal:")
}

/// The most GPU tile slots a globe may ask for (about 8 GiB of pools at the default tile size;
/// a billion slots took 4.9 GB of bookkeeping before any GPU memory).
pub const MAX_GPU_TILES: u32 = 65_536;

/// The most terrain and imagery layers a globe composites (5,000 layers took 7.8 GB).
pub const MAX_LAYERS: usize = 64;

/// The most tile loader threads.
pub const MAX_WORKERS: usize = 256;

#[cfg(test)]
mod tests {
    use super::*;

    const MIB: u64 = 1 << 20;

    #[test]
    fn parts_add_up_to_the_total() {
        // Pools with a little rounding, like the real ones.
        let slot = |n: u32| u64::from(n) * 131 * 1024 + u64::from(n % 7);
        for total_mb in [384, 512, 1024, 4096, 65536] {
            let p = MemoryPlan::new(total_mb * MIB, Some(120 * MIB), 16, true, slot).unwrap();
            let sum = p.baseline + p.headroom + p.sources + p.gpu_pool + p.tile_cache;
            assert_eq!(sum, p.total, "{p:?}");
            assert!(p.tile_cache >= MIN_TILE_CACHE, "{p:?}");
            assert!((MIN_GPU_SLOTS..=MAX_GPU_SLOTS).contains(&p.gpu_slots));
            assert_eq!(p.gpu_pool, slot(p.gpu_slots));
        }
        // Every total gets a slot count the pool allocates as it is: a multiple of 6 would
        // get a layer more than planned (the budget test once failed by one colour layer's
        // 87,380 bytes).
        for total_mb in 384..1600 {
            let p = MemoryPlan::new(total_mb * MIB, Some(120 * MIB), 16, true, slot).unwrap();
            assert_eq!(
                globus_render::array_layers(p.gpu_slots, 2048),
                p.gpu_slots,
                "{p:?}"
            );
            assert_eq!(p.gpu_pool, slot(p.gpu_slots));
        }
        // More memory: a bigger cache and pool, never smaller.
        let a = MemoryPlan::new(512 * MIB, Some(120 * MIB), 16, true, slot).unwrap();
        let b = MemoryPlan::new(1024 * MIB, Some(120 * MIB), 16, true, slot).unwrap();
        assert!(b.tile_cache > a.tile_cache && b.gpu_slots > a.gpu_slots);
        // The procedural planet keeps no source caches: their share goes to tiles.
        let c = MemoryPlan::new(1024 * MIB, Some(120 * MIB), 16, false, slot).unwrap();
        assert_eq!(c.sources, 0);
        assert!(c.tile_cache + c.gpu_pool > b.tile_cache + b.gpu_pool);
        // Unknown footprint: estimated.
        let d = MemoryPlan::new(1024 * MIB, None, 16, true, slot).unwrap();
        assert_eq!(d.baseline, BASELINE_ESTIMATE);
    }

    #[test]
    fn too_small_a_budget_names_the_least_that_works() {
        let slot = |n: u32| u64::from(n) * 131 * 1024;
        let e = MemoryPlan::new(200 * MIB, Some(120 * MIB), 16, true, slot)
            .unwrap_err()
            .to_string();
        assert!(
            e.contains("200 MiB is too small") && e.contains("120 MiB"),
            "{e}"
        );
        let least: u64 = e
            .rsplit("at least ")
            .next()
            .and_then(|t| t.split_whitespace().next())
            .and_then(|n| n.parse().ok())
            .expect("a number in the message");
        // The number it names works; one MiB less does not.
        assert!(MemoryPlan::new(least * MIB, Some(120 * MIB), 16, true, slot).is_ok());
        assert!(MemoryPlan::new((least - 1) * MIB, Some(120 * MIB), 16, true, slot).is_err());
    }

    #[test]
    fn source_shares_split_across_layers() {
        let one = SourceBudgets::of(1024 * MIB, 1);
        let three = SourceBudgets::of(1024 * MIB, 3);
        assert_eq!(one.refine_bases, three.refine_bases);
        assert!((three.per_layer * 3).abs_diff(one.per_layer) <= 3);
        assert!((one.per_layer + one.refine_bases) as u64 <= SourceBudgets::all(1024 * MIB) + 1);
    }

    #[test]
    fn reads_its_own_resident_memory_on_linux() {
        if cfg!(target_os = "linux") {
            let r = resident_bytes().expect("VmRSS");
            assert!(r > MIB && r < 1 << 40, "{r}");
        }
    }
}
