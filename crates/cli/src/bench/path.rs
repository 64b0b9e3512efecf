//! `globus bench --path`: a camera path replayed offscreen, frame by frame (or in real
//! time), reporting per-frame costs and what became of the loads.

use std::path::Path;
use std::time::{Duration, Instant};

use anyhow::Context;
use globus_engine::{CameraSpec, FrameReport, GlobeBuilder, Headless};
use serde_json::json;

use super::quantiles;
use crate::args::{self, BenchArgs};
use crate::path::CameraPath;

/// The most frames a path is replayed for.
const MAX_FRAMES: usize = 1_000_000;

/// What one frame of the path cost and showed.
#[derive(Clone, Copy, Debug)]
struct FrameSample {
    select_us: f64,
    select_cpu_us: f64,
    update_cpu_us: f64,
    frame_ms: f64,
    tiles_rendered: u32,
    nodes_visited: u32,
    nodes_culled: u32,
    draw_calls: u32,
    triangles: u64,
    tiles_wanted_not_drawable: u32,
    tiles_showing_ancestor_imagery: u32,
    sse_bound_px: f64,
    drawn_in_part: u32,
    arrived: u32,
    loading: u32,
    evicted: u32,
    requests_deferred: u32,
}

impl FrameSample {
    fn new(r: &FrameReport, frame_ms: f64) -> Self {
        Self {
            select_us: r.select_us,
            select_cpu_us: r.select_cpu_us,
            update_cpu_us: r.update_cpu_us,
            frame_ms,
            tiles_rendered: r.draw.tiles,
            nodes_visited: r.selection.nodes_visited,
            nodes_culled: r.selection.culled_frustum + r.selection.culled_horizon,
            draw_calls: r.draw.draw_calls,
            triangles: r.draw.triangles,
            tiles_wanted_not_drawable: r.wanted,
            tiles_showing_ancestor_imagery: r.colours_pending,
            sse_bound_px: r.sse_bound_px,
            drawn_in_part: r.selection.drawn_in_part,
            arrived: r.layer.arrived,
            loading: r.layer.loading,
            evicted: r.layer.evicted,
            requests_deferred: r.requests_deferred,
        }
    }

    const CSV_HEADER: &str = "t_s,frame_ms,select_us,select_cpu_us,update_cpu_us,tiles_rendered,drawn_in_part,\
        nodes_visited,nodes_culled,draw_calls,triangles,wanted_not_drawable,\
        showing_ancestor_imagery,sse_bound_px,arrived,loading,evicted,requests_deferred";

    fn csv_row(&self, t: f64) -> String {
        format!(
            "{t:.3},{:.3},{:.1},{:.1},{:.1},{},{},{},{},{},{},{},{},{:.4},{},{},{},{}",
            self.frame_ms,
            self.select_us,
            self.select_cpu_us,
            self.update_cpu_us,
            self.tiles_rendered,
            self.drawn_in_part,
            self.nodes_visited,
            self.nodes_culled,
            self.draw_calls,
            self.triangles,
            self.tiles_wanted_not_drawable,
            self.tiles_showing_ancestor_imagery,
            self.sse_bound_px,
            self.arrived,
            self.loading,
            self.evicted,
            self.requests_deferred,
        )
    }

    fn complete(&self) -> bool {
        self.tiles_wanted_not_drawable == 0 && self.tiles_showing_ancestor_imagery == 0
    }
}

pub fn run(
    a: &BenchArgs,
    builder: &GlobeBuilder,
    path_file: &Path,
    (width, height): (u32, u32),
) -> anyhow::Result<()> {
    let text =
        globus_tiling::files::read_text_capped(path_file, globus_tiling::files::MAX_TEXT_BYTES)
            .with_context(|| format!("cannot read {}", path_file.display()))?;
    let mut builder = builder.clone();
    let mut vectors = args::vector_layer(&a.globe, &mut builder)?;
    let builder = &builder;
    let mut vector_samples: Vec<(f64, bool, u32)> = Vec::new();
    let mut off = Headless::new(builder, width, height)?;
    super::light(a, &mut off)?;
    let fov = a.globe.fov_deg;
    let origin = path_file.display().to_string();
    if builder.uses_real_data() {
        // Streamed data knows its ground only once tiles are loaded: load the ground under
        // every keyframe given above the ground (from 15 km up, looking down) first.
        let points = std::cell::RefCell::new(Vec::new());
        CameraPath::parse(&text, &origin, |lon, lat| {
            points.borrow_mut().push((lon, lat));
            0.0
        })?;
        for (lon, lat) in points.into_inner() {
            let look_down = args::parse_camera(&format!("{lon},{lat},15000,0,-90"), false)?;
            let view = look_down.view(off.globe(), fov, width, height);
            off.render_complete(&view, Duration::from_secs(120), &mut [])?;
        }
    }
    let path = {
        let globe = off.globe();
        CameraPath::parse(&text, &origin, |lon, lat| {
            globe.drawn_ground_m(lon.to_radians(), lat.to_radians())
        })?
    };
    if a.realtime {
        // A viewer opens on its start view and shows it complete before the flight starts:
        // load it first, so the flight is not timed from a cold start (pipeline compilation
        // and the first tiles take the first second).
        let view = camera_at(&path, 0.0).view(off.globe(), fov, width, height);
        off.render_complete(&view, Duration::from_secs(120), &mut [])?;
    }
    // Counting starts with the path.
    off.globe_mut().layer_mut().track_usage();
    // A path of a day at 30 fps is 2.6 million frames: refuse what no benchmark means
    // before allocating a sample per frame.
    let frames_f = (path.duration() * a.fps).floor() + 1.0;
    if frames_f.is_nan() || frames_f > MAX_FRAMES as f64 {
        anyhow::bail!(
            "{}: {:.0} s at {} fps is {frames_f:.0} frames; at most {MAX_FRAMES} are replayed",
            path_file.display(),
            path.duration(),
            a.fps
        );
    }
    let frames = frames_f as usize;
    let mut samples: Vec<FrameSample> = Vec::with_capacity(frames);
    let mut deferred = 0u64;
    let clock = Instant::now();
    for i in 0..frames {
        let t = i as f64 / a.fps;
        if a.realtime {
            let ahead = t - clock.elapsed().as_secs_f64();
            if ahead > 0.0 {
                std::thread::sleep(Duration::from_secs_f64(ahead));
            }
        }
        let view = camera_at(&path, t).view(off.globe(), fov, width, height);
        let started = Instant::now();
        let r = off.update(&view);
        match vectors.as_mut() {
            Some(v) => {
                off.draw(&mut [v]);
                let s = v.stats();
                vector_samples.push((s.prepare_s * 1e6, s.rebuilt, s.draw_calls));
            }
            None => off.draw(&mut []),
        }
        let frame_s = started.elapsed().as_secs_f64();
        // With --target-fps the next frames' error bound follows this one's cost.
        off.globe_mut().frame_time(frame_s);
        samples.push(FrameSample::new(&r, frame_s * 1e3));
        deferred += u64::from(r.requests_deferred);
    }
    if let Some(csv) = &a.frames_csv {
        let mut text = String::from(FrameSample::CSV_HEADER);
        text.push('\n');
        for (i, s) in samples.iter().enumerate() {
            text.push_str(&s.csv_row(i as f64 / a.fps));
            text.push('\n');
        }
        globus_tiling::files::write_atomic(csv, text.as_bytes())
            .with_context(|| format!("cannot write {}", csv.display()))?;
    }
    let column = |f: fn(&FrameSample) -> f64| quantiles(samples.iter().map(f).collect());
    let complete = samples.iter().filter(|s| s.complete()).count();
    let per_tile = |count: fn(&FrameSample) -> u32| {
        quantiles(
            samples
                .iter()
                .filter(|s| s.tiles_rendered > 0)
                .map(|s| f64::from(count(s)) / f64::from(s.tiles_rendered))
                .collect(),
        )
    };
    // How the error bound moved from frame to frame (budgets and the quality loop): the
    // factor of each step, and how often it turned from rising to falling or back.
    let bounds: Vec<f64> = samples.iter().map(|s| s.sse_bound_px).collect();
    let steps: Vec<f64> = bounds
        .windows(2)
        .map(|w| (w[1] / w[0]).max(w[0] / w[1]))
        .collect();
    let mut reversals = 0u32;
    let mut last_rise: Option<bool> = None;
    for w in bounds.windows(2).filter(|w| w[1] != w[0]) {
        let rise = w[1] > w[0];
        if last_rise.is_some_and(|r| r != rise) {
            reversals += 1;
        }
        last_rise = Some(rise);
    }
    // Frames that fell back to coarse tiles: fewer than half the tiles of the frame before
    // (a turning camera whose new children are still loading, an evicted ancestor).
    let collapses = samples
        .windows(2)
        .filter(|w| 2 * w[1].tiles_rendered < w[0].tiles_rendered)
        .count();
    let globe = off.globe();
    let st = globe.layer().scheduler_stats();
    let cs = globe.layer().colour_scheduler_stats();
    let mut summary = json!({
        "complete_frames_fraction": complete as f64 / frames.max(1) as f64,
        "requests_deferred_while_moving": deferred,
        "frames": frames,
        "size": [width, height],
        "sse_px": builder.error_bound_px(),
        "target_fps": builder.target_frame_rate(),
        "sse_bound_px": column(|s| s.sse_bound_px),
        "sse_bound_step": quantiles(steps),
        "sse_bound_reversals": reversals,
        "realtime": a.realtime,
        "wall_s": clock.elapsed().as_secs_f64(),
        "mesh_error": a.globe.mesh_error,
        "select_us": column(|s| s.select_us),
        "frame_ms": column(|s| s.frame_ms),
        "tiles_rendered": column(|s| f64::from(s.tiles_rendered)),
        "tiles_rendered_collapses": collapses,
        "nodes_visited": column(|s| f64::from(s.nodes_visited)),
        "draw_calls": column(|s| f64::from(s.draw_calls)),
        "triangles": column(|s| s.triangles as f64),
        "select_cpu_us": column(|s| s.select_cpu_us),
        "update_cpu_us": column(|s| s.update_cpu_us),
        "tiles_wanted_not_drawable": column(|s| f64::from(s.tiles_wanted_not_drawable)),
        "tiles_showing_ancestor_imagery": column(|s| f64::from(s.tiles_showing_ancestor_imagery)),
        "nodes_visited_per_tile": per_tile(|s| s.nodes_visited),
        "nodes_culled": column(|s| f64::from(s.nodes_culled)),
        "visible_nodes_per_tile": per_tile(|s| s.nodes_visited - s.nodes_culled),
        "tiles_requested": st.requested,
        "tiles_loaded": st.loaded,
        "requests_cancelled": st.cancelled,
        "loads_stopped_in_flight": st.cancelled_in_flight,
        "retries": st.retries,
        "tiles_failed": st.failed,
        "imagery_requested": cs.requested,
        "imagery_loaded": cs.loaded,
        "imagery_stopped_in_flight": cs.cancelled_in_flight,
        "adapter": off.gpu().adapter_description(),
    });
    if let Some(u) = globe.layer().usage()
        && let Some(map) = summary.as_object_mut()
    {
        let fraction = |n: u64, of: u64| n as f64 / of.max(1) as f64;
        for (k, v) in [
            ("loaded_never_drawn", json!(u.loaded_never_drawn)),
            (
                "loaded_never_drawn_fraction",
                json!(fraction(u.loaded_never_drawn, u.loaded)),
            ),
            ("fetched", json!(u.fetched)),
            ("fetched_never_drawn", json!(u.fetched_never_drawn)),
            (
                "fetched_never_drawn_fraction",
                json!(fraction(u.fetched_never_drawn, u.fetched)),
            ),
            (
                "loaded_again_while_cached",
                json!(u.loaded_again_while_cached),
            ),
            (
                "loaded_again_after_eviction",
                json!(u.loaded_again_after_eviction),
            ),
        ] {
            map.insert(k.into(), v);
        }
    }
    if let Some(v) = vectors.as_mut() {
        let report = vector_report(
            &mut off,
            v,
            &vector_samples,
            &camera_at(&path, path.duration()),
            fov,
        );
        if let Some(map) = summary.as_object_mut() {
            map.insert("vector".into(), report);
        }
    }
    println!("{summary}");
    Ok(())
}

/// Vector costs: CPU of frames where nothing changed and of those that rebuilt, draw calls,
/// GPU bytes, and the CPU of the frame after 1,000 features are replaced (at the path's last
/// camera).
fn vector_report(
    off: &mut Headless,
    layer: &mut globus_engine::VectorLayer,
    samples: &[(f64, bool, u32)],
    last: &CameraSpec,
    fov: f64,
) -> serde_json::Value {
    let (w, h) = (off.size().0, off.size().1);
    let view = last.view(off.globe(), fov, w, h);
    // Two frames on the same view: the second changes nothing.
    for _ in 0..2 {
        off.update(&view);
        off.draw(&mut [layer]);
    }
    let idle = layer.stats();
    let n = layer.len();
    let ids: Vec<_> = (0..n as u32)
        .map(globus_engine::FeatureId)
        .filter(|&id| layer.feature(id).is_some())
        .cycle()
        .take(1000)
        .collect();
    let started = Instant::now();
    let mut updated = 0;
    for &id in &ids {
        if let Some(f) = layer.feature(id).cloned() {
            updated += usize::from(layer.update(id, f));
        }
    }
    let update_calls_us = started.elapsed().as_secs_f64() * 1e6;
    off.update(&view);
    off.draw(&mut [layer]);
    let after = layer.stats();
    let quiet: Vec<f64> = samples.iter().filter(|s| !s.1).map(|s| s.0).collect();
    let rebuilt: Vec<f64> = samples.iter().filter(|s| s.1).map(|s| s.0).collect();
    json!({
        "features": idle.features,
        "prepare_us_unchanged_frames": quantiles(quiet),
        "prepare_us_rebuilding_frames": quantiles(rebuilt),
        "prepare_us_idle_frame": idle.prepare_s * 1e6,
        "draw_calls": samples.iter().map(|s| s.2).max().unwrap_or(idle.draw_calls),
        "gpu_bytes": idle.gpu_bytes,
        "line_instances": idle.line_instances,
        "fill_vertices": idle.fill_vertices,
        "pieces_left_out": idle.left_out,
        "updated_features": updated,
        "update_calls_us": update_calls_us,
        "prepare_us_after_update": after.prepare_s * 1e6,
        "features_rebuilt_after_update": after.features_built,
    })
}

/// The path's camera at time `t` (altitude above the ellipsoid).
fn camera_at(path: &CameraPath, t: f64) -> CameraSpec {
    let p = path.pose(t);
    CameraSpec {
        lon_deg: p.lon,
        lat_deg: p.lat,
        alt_m: p.alt,
        heading_deg: p.heading,
        pitch_deg: p.pitch,
        above_ground: false,
    }
}
