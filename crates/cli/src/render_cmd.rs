//! `globus render`: one complete frame offscreen, written as PNG (and its statistics as
//! JSON).

use std::time::Duration;

use std::io::IsTerminal;

use anyhow::Context;
use globus_engine::{FrameReport, Headless, Overlay, save_png};
use serde_json::json;

use crate::args::{self, RenderArgs};

pub fn run(a: RenderArgs) -> anyhow::Result<()> {
    let (width, height) = args::parse_size(&a.size)?;
    let camera = args::parse_camera(&a.camera, a.above_ground)?;
    let mut builder = args::globe_builder(&a.globe)?;
    if !(a.timeout_s > 0.0 && a.timeout_s <= 86_400.0) {
        anyhow::bail!(
            "--timeout-s {} must be a number of seconds above 0 and at most a day (86400)",
            a.timeout_s
        );
    }
    args::check_writable(&a.out)?;
    if let Some(s) = &a.stats {
        if globus_tiling::files::same_file(s, &a.out) {
            anyhow::bail!(
                "--stats {} and --out {} are the same file: the statistics would replace the picture",
                s.display(),
                a.out.display()
            );
        }
        args::check_writable(s)?;
    }
    let mut vectors = args::vector_layer(&a.globe, &mut builder)?;
    let mut traffic = match &a.traffic.traffic {
        Some(path) => {
            let mut scene = crate::traffic_cmd::scene(path, a.traffic.time.as_deref(), None)?;
            crate::traffic_cmd::apply_models(&mut scene.layer, &a.traffic.models)?;
            Some(scene)
        }
        None => None,
    };
    // The Sun of the moment drawn: --time, or the replay's moment.
    let sun_time = match (&traffic, &a.traffic.time) {
        (Some(scene), _) => Some(scene.time_s),
        (None, Some(t)) => Some(crate::traffic_cmd::parse_time(t, "--time")?),
        (None, None) => None,
    };
    let mut off = Headless::new(&builder, width, height)?;
    if let Some(t) = sun_time {
        off.globe_mut()
            .set_lighting(Some(globus_engine::Lighting::at_time(t)));
    }
    let timeout = Duration::from_secs_f64(a.timeout_s);
    let mut view = args::camera_view(&camera, off.globe(), &a.globe, width, height);
    let progress = LoadProgress::new();
    let mut show = |r: &FrameReport| progress.show(r);
    let mut frame = {
        let mut overlays = overlays(&mut vectors, &mut traffic);
        off.render_complete_reporting(&view, timeout, &mut overlays, &mut show)?
    };
    // Above the ground of streamed data: the ground is known once the tiles under the
    // camera have loaded, so place the camera again and finish the picture from there.
    for _ in 0..3 {
        let placed = args::camera_view(&camera, off.globe(), &a.globe, width, height);
        if !camera.above_ground || (placed.position - view.position).length() < 0.1 {
            break;
        }
        view = placed;
        let mut overlays = overlays(&mut vectors, &mut traffic);
        frame = off.render_complete_reporting(&view, timeout, &mut overlays, &mut show)?;
    }
    progress.finish();
    // Tiles that failed for good are drawn over with coarser data: say so, per layer.
    let failures: Vec<_> = off
        .globe()
        .layer_failures()
        .into_iter()
        .filter(|f| f.tiles > 0)
        .collect();
    for f in &failures {
        let kinds: Vec<String> = f.by_kind.iter().map(|(k, n)| format!("{n} {k}")).collect();
        tracing::warn!(
            "{}: {} tiles failed ({}); first: {}",
            f.layer,
            f.tiles,
            kinds.join(", "),
            f.first.join("; ")
        );
    }
    if !frame.complete {
        tracing::warn!(
            "gave up waiting for tiles after {:.1} s; the picture is coarser than the SSE bound asks",
            frame.load_ms / 1e3
        );
    }
    save_png(&frame.image, &a.out)?;
    if let Some(path) = &a.stats {
        let r = &frame.report;
        let s = &r.selection;
        let per_slot = r.pool.gpu_bytes / u64::from(r.pool.capacity.max(1));
        let altitude = off
            .globe()
            .ellipsoid()
            .ecef_to_cartographic(view.position)
            .map_or(f64::NAN, |c| c.height_m);
        let stats = json!({
            "tiles_rendered": r.draw.tiles,
            "nodes_visited": s.nodes_visited,
            "culled_frustum": s.culled_frustum,
            "culled_horizon": s.culled_horizon,
            "max_level": s.max_level,
            "max_sse_px": s.max_sse_px,
            "sse_bound_px": r.sse_bound_px,
            "triangles": r.draw.triangles,
            "draw_calls": r.draw.draw_calls,
            "select_us": r.select_us,
            "select_cpu_us": r.select_cpu_us,
            "load_ms": frame.load_ms,
            // Everything wanted drawn from its own data: no tile gave up, none failed.
            "complete": frame.complete && failures.is_empty(),
            "failures": failures.iter().map(|f| json!({
                "layer": f.layer,
                "tiles": f.tiles,
                "by_kind": f.by_kind,
                "first": f.first,
            })).collect::<Vec<_>>(),
            "tiles_loaded": off.globe().layer().scheduler_stats().loaded,
            "gpu_tile_bytes": per_slot * u64::from(r.pool.resident),
            "gpu_pool_bytes": r.pool.gpu_bytes,
            "adapter": off.gpu().adapter_description(),
            "camera": {"lon": camera.lon_deg, "lat": camera.lat_deg, "alt_m": altitude,
                        "heading": camera.heading_deg,
                        "pitch": if view.ortho_height_m().is_some() { -90.0 } else { camera.pitch_deg },
                        "ortho_km": view.ortho_height_m().map(|m| m / 1e3)},
            "size": [width, height],
            "vector": vectors.as_ref().map(|v| {
                let s = v.stats();
                json!({
                    "features": s.features,
                    "line_instances": s.line_instances,
                    "pieces_left_out": s.left_out,
                    "fill_vertices": s.fill_vertices,
                    "labels": s.labels,
                    "labels_drawn": s.labels_drawn,
                    "draw_calls": s.draw_calls,
                    "gpu_bytes": s.gpu_bytes,
                })
            }),
            "traffic": traffic.as_ref().map(|t| {
                let mut v = crate::traffic_cmd::stats_json(&t.layer.stats());
                if let Some(m) = v.as_object_mut() {
                    m.insert("time".into(), json!(crate::traffic_cmd::format_time(t.time_s)));
                }
                v
            }),
        });
        let text = serde_json::to_string_pretty(&stats)? + "\n";
        globus_tiling::files::write_atomic(path, text.as_bytes())
            .with_context(|| format!("cannot write {}", path.display()))?;
    }
    Ok(())
}

/// The scene's overlays, in drawing order: vector data, then traffic.
fn overlays<'a>(
    vectors: &'a mut Option<globus_engine::VectorLayer>,
    traffic: &'a mut Option<crate::traffic_cmd::Scene>,
) -> Vec<&'a mut dyn Overlay> {
    let mut out: Vec<&mut dyn Overlay> = Vec::new();
    if let Some(v) = vectors.as_mut() {
        out.push(v);
    }
    if let Some(t) = traffic.as_mut() {
        out.push(&mut t.layer);
    }
    out
}

/// Tiles drawn and still loading, on one line of stderr while the picture completes, if
/// stderr is a terminal (nothing otherwise).
struct LoadProgress(Option<indicatif::ProgressBar>);

impl LoadProgress {
    fn new() -> Self {
        if !std::io::stderr().is_terminal() {
            return Self(None);
        }
        let bar = indicatif::ProgressBar::new_spinner();
        bar.enable_steady_tick(Duration::from_millis(200));
        Self(Some(bar))
    }

    fn show(&self, r: &FrameReport) {
        if let Some(bar) = &self.0 {
            bar.set_message(format!(
                "{} tiles drawn, {} still loading, {} showing their parent's imagery",
                r.draw.tiles, r.wanted, r.colours_pending
            ));
        }
    }

    fn finish(&self) {
        if let Some(bar) = &self.0 {
            bar.finish_and_clear();
        }
    }
}
