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
    // at its first draw and for its triangles, an eighth of the total (counted in the plan's
    // baseline on lavapipe).
    let now = resident_bytes().unwrap_or(160 * MIB);
    let total = (now + (320 + 128) * MIB) * 8 / 7;
    let mut builder = GlobeBuilder::new();
    builder
        .refine_below(Some(7))
        .max_level(18)
        .memory_budget(Some(total))
        .workers(2);
    let (w, h) = (480, 270);
    let mut off = Headless::new(&builder, w, h).expect("a GPU or lavapipe");
    let software = off.gpu().adapter.get_info().device_type == wgpu::DeviceType::Cpu;
    let mut most_triangles = 0;
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
        most_triangles = most_triangles.max(frame.report.draw.triangles);
    }
    // A software rasteriser's triangles stay within their share (170 bytes each): the error
    // bound rises instead.
    if software {
        assert!(
            most_triangles <= total / 8 / 170,
            "{most_triangles} triangles under a budget of {} MiB",
            total / MIB
        );
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

#[test]
fn on_a_software_rasteriser_the_triangles_stay_within_their_share() {
    // The README's Alps view from 3 km at 1280x720 draws about 666,000 triangles at 2 px;
    // lavapipe takes about 170 bytes for each. Under a budget whose eighth holds about
    // 530,000 (and room enough in the caches that they alone keep 2 px: checked by hand with
    // the cap off, 666,000 triangles at 2 px), the error bound rises until the frame fits.
    // Without fog, which would thin out the hazy distance below the cap by itself.
    let now = resident_bytes().unwrap_or(160 * MIB);
    let total = now + 680 * MIB;
    let mut builder = GlobeBuilder::new();
    builder.memory_budget(Some(total)).workers(2).fog(false);
    let (w, h) = (1280, 720);
    let mut off = Headless::new(&builder, w, h).expect("a GPU or lavapipe");
    if off.gpu().adapter.get_info().device_type != wgpu::DeviceType::Cpu {
        return; // a GPU's triangles are not host memory
    }
    let cap = total / 8 / 170;
    let cam = CameraSpec {
        lon_deg: 7.6,
        lat_deg: 46.0,
        alt_m: 3_000.0,
        heading_deg: 200.0,
        pitch_deg: -10.0,
        above_ground: true,
    };
    let mut view = cam.view(off.globe(), 60.0, w, h);
    off.render_complete(&view, Duration::from_secs(120), &mut [])
        .expect("render");
    view = cam.view(off.globe(), 60.0, w, h);
    let frame = off
        .render_complete(&view, Duration::from_secs(120), &mut [])
        .expect("render");
    let (triangles, bound) = (frame.report.draw.triangles, frame.report.sse_bound_px);
    eprintln!("{triangles} triangles (at most {cap}), bound {bound} px");
    assert!(triangles <= cap, "{triangles} triangles, at most {cap}");
    assert!(
        bound > 2.0,
        "the bound stayed at {bound} px: the cap never bound"
    );
    assert_eq!(frame.report.draw.missing, 0);
}
