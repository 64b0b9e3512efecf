//! One memory budget sizes every cache (a test binary of its own: the budget's plan starts
//! from this process's resident memory, which other tests running beside it would change).

use std::time::Duration;

use globus_engine::memory::resident_bytes;
use globus_engine::{CameraSpec, GlobeBuilder, Headless};

const MIB: u64 = 1 << 20;

#[test]
fn a_memory_budget_sizes_every_cache_and_the_flight_stays_inside_it() {
    // A procedural planet whose data ends at level 7 (refinement bases are a source cache),
    // with 320 MiB beyond what the process holds now and what a software rasteriser takes
    // at its first draw (counted in the plan's baseline on lavapipe).
    let now = resident_bytes().unwrap_or(160 * MIB);
    let mut builder = GlobeBuilder::new();
    builder
        .refine_below(Some(7))
        .max_level(18)
        .memory_budget(Some(now + (320 + 128) * MIB))
        .workers(2);
    let (w, h) = (480, 270);
    let mut off = Headless::new(&builder, w, h).expect("a GPU or lavapipe");
    let plan = off.globe().memory_use().plan.expect("a plan");
    assert_eq!(
        plan.baseline + plan.headroom + plan.sources + plan.gpu_pool + plan.tile_cache,
        plan.total
    );
    assert_eq!(off.globe().layer().cache_bytes().1 as u64, plan.tile_cache);
    assert_eq!(off.globe().memory_use().gpu_pool, plan.gpu_pool);
    assert_eq!(
        u64::from(off.globe().pool_stats().capacity),
        u64::from(plan.gpu_slots)
    );

    // Low flights over many places, each view loaded completely: the cache fills to its
    // share and stays there, the sources' caches stay in theirs.
    let mut peak_cache = 0;
    let mut over_budget_frames = 0;
    for i in 0..24 {
        let cam = CameraSpec {
            lon_deg: -170.0 + 15.0 * f64::from(i),
            lat_deg: if i % 2 == 0 { 45.0 } else { -30.0 },
            alt_m: 3_000.0,
            heading_deg: 30.0 * f64::from(i),
            pitch_deg: -30.0,
            above_ground: true,
        };
        let view = cam.view(off.globe(), 60.0, w, h);
        let frame = off
            .render_complete(&view, Duration::from_secs(120), &mut [])
            .expect("render");
        let used = off.globe().memory_use();
        peak_cache = peak_cache.max(used.tile_cache);
        assert!(
            used.sources <= plan.sources,
            "view {i}: {used:?} vs {plan:?}"
        );
        if used.tile_cache > plan.tile_cache {
            // Only while the view itself needs more than the share: detail is lowered.
            assert!(frame.report.layer.over_budget, "view {i}: {used:?}");
            over_budget_frames += 1;
        }
        assert_eq!(frame.report.draw.missing, 0, "view {i}: a hole");
    }
    assert!(
        peak_cache as f64 > 0.8 * plan.tile_cache as f64,
        "the flight never filled the cache ({peak_cache} of {}): the test proves nothing",
        plan.tile_cache
    );
    assert!(
        over_budget_frames <= 2,
        "{over_budget_frames} views over budget"
    );
}

#[test]
fn a_budget_smaller_than_the_process_is_refused_with_the_least_that_works() {
    let mut builder = GlobeBuilder::new();
    builder.memory_budget(Some(64 * MIB));
    let e = match Headless::new(&builder, 64, 64) {
        Ok(_) => panic!("a 64 MiB budget was accepted"),
        Err(e) => e.to_string(),
    };
    assert!(
        e.contains("64 MiB is too small") && e.contains("at least"),
        "{e}"
    );
}
