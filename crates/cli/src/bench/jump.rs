//! `globus bench --from A --to B`: everything loaded at one view, then a jump to another;
//! reports when the first frame of the new view is out (and whether it has holes), when
//! every tile its selection wants is loaded and resident (`geometry_loaded_ms`), and when
//! every drawn tile shows its own imagery too (`all_loaded_ms`).

use std::time::{Duration, Instant};

use anyhow::{Context, bail};
use globus_engine::{CameraSpec, GlobeBuilder, Headless, holes_inside};
use serde_json::json;

use crate::args::{self, BenchArgs};

/// How the new view filled in.
#[derive(Debug, Default)]
struct JumpTimes {
    first_frame_ms: f64,
    first_frame_pixels_on_planet: u32,
    first_frame_holes: u32,
    geometry_loaded_ms: Option<f64>,
    all_loaded_ms: Option<f64>,
    frames: u32,
}

pub fn run(
    a: &BenchArgs,
    builder: &GlobeBuilder,
    from: &str,
    to: &str,
    (width, height): (u32, u32),
) -> anyhow::Result<()> {
    let from = args::parse_camera(from, false).context("--from")?;
    let to = args::parse_camera(to, false).context("--to")?;
    let fov = a.globe.fov_deg;
    let mut off = Headless::new(builder, width, height)?;
    super::light(a, &mut off)?;
    off.globe_mut().layer_mut().track_usage();
    let view_a = from.view(off.globe(), fov, width, height);
    let settled = off.render_complete(&view_a, Duration::from_secs(300), &mut [])?;
    if !settled.complete {
        bail!("the first view did not finish loading in 300 s");
    }
    let before = off.globe().layer().scheduler_stats();
    let colours_before = off.globe().layer().colour_scheduler_stats();
    let view_b = to.view(off.globe(), fov, width, height);
    off.globe_mut().set_relax_detail(false);
    let started = Instant::now();
    let ms = || started.elapsed().as_secs_f64() * 1e3;
    let mut times = JumpTimes::default();
    let mut last = None;
    while started.elapsed() < Duration::from_secs(120) {
        let report = off.update(&view_b);
        times.frames += 1;
        if times.frames == 1 {
            let image = off.draw_and_read(&mut [])?;
            times.first_frame_ms = ms();
            let below_sea = off.globe().ellipsoid().grown(-16_000.0);
            (times.first_frame_pixels_on_planet, times.first_frame_holes) =
                holes_inside(&image, &view_b, &below_sea);
        } else if !a.no_draw {
            off.draw(&mut []);
        } else {
            // Uploads still reach the GPU.
            off.submit_uploads();
        }
        if report.wanted == 0 && times.geometry_loaded_ms.is_none() {
            times.geometry_loaded_ms = Some(ms());
        }
        let done = report.is_complete();
        last = Some(report);
        if done {
            times.all_loaded_ms = Some(ms());
            break;
        }
    }
    let globe = off.globe();
    let after = globe.layer().scheduler_stats();
    let colours_after = globe.layer().colour_scheduler_stats();
    let e = globe.ellipsoid();
    let c = |cam: &CameraSpec| {
        globus_engine::Cartographic::new(cam.lon_deg.to_radians(), cam.lat_deg.to_radians(), 0.0)
    };
    let last = last.context("no frame ran")?;
    let out = json!({
        "jump_km": e.great_circle_distance(c(&from), c(&to)) / 1e3,
        "size": [width, height],
        "first_frame_ms": times.first_frame_ms,
        "first_frame_pixels_on_planet": times.first_frame_pixels_on_planet,
        "first_frame_holes": times.first_frame_holes,
        "all_loaded_ms": times.all_loaded_ms,
        "geometry_loaded_ms": times.geometry_loaded_ms,
        "frames": times.frames,
        "tiles_drawn": last.draw.tiles,
        "max_level": last.selection.max_level,
        "tiles_requested": after.requested - before.requested,
        "tiles_loaded": after.loaded - before.loaded,
        "imagery_loaded": colours_after.loaded - colours_before.loaded,
        "retries": after.retries - before.retries,
        "tiles_failed": after.failed - before.failed,
        "per_host": builder.http_options().per_host,
        "frames_drawn": !a.no_draw,
        "adapter": off.gpu().adapter_description(),
    });
    println!("{out}");
    Ok(())
}
