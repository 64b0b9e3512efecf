//! `globus bench --popping CAMERA`: how much the picture jumps when tiles split, with nothing
//! else moving (issue 20's measurement). The camera stands still while the error bound is
//! lowered from 8 px to 1 px over 120 frames (geometrically: splits come about evenly per
//! frame, as levels halve the error); every frame is loaded completely before it is drawn, so
//! what changes between two frames is only what the new bound split. Per frame: the mean
//! absolute change of a colour channel against the frame before and the share of pixels
//! changing by more than 8/255. Over the sweep: the changes added up, the change from the
//! first frame to the last (what the sum would be if no pixel went back and forth), and the
//! sum over the number of frames, the least the largest frame's change can be.
//!
//! With `--descent` the camera instead comes straight down from its height to a quarter of
//! it over the 120 frames (geometrically) at the configured bound: motion changes every
//! frame, and a split shows as a step in the series of changes (`largest_step`: the
//! largest difference between the changes of two frames in a row, of 255).

use std::time::Duration;

use anyhow::Context;
use globus_engine::{CameraSpec, GlobeBuilder, Headless, View, geometric_steps, save_png};

use super::quantiles;
use crate::args::{self, BenchArgs};

/// Frames after the first, from the coarsest bound to the finest.
const STEPS: u32 = 120;
const COARSEST_PX: f64 = 8.0;
const FINEST_PX: f64 = 1.0;
/// A channel change above this is a visible change (of 255).
const VISIBLE: u8 = 8;

pub fn run(
    a: &BenchArgs,
    builder: &GlobeBuilder,
    camera: &str,
    (width, height): (u32, u32),
) -> anyhow::Result<()> {
    let spec = args::parse_camera(camera, false).context("--popping")?;
    let mut off = Headless::new(builder, width, height)?;
    super::light(a, &mut off)?;
    let view_at =
        |off: &Headless, spec: &CameraSpec| spec.view(off.globe(), a.globe.fov_deg, width, height);
    let (schedule, bounds): (Vec<(View, f64)>, [f64; 2]) = if a.descent {
        let bound = a.globe.sse.unwrap_or(2.0);
        let schedule = geometric_steps(spec.alt_m, spec.alt_m / 4.0, STEPS)
            .into_iter()
            .map(|alt_m| (view_at(&off, &CameraSpec { alt_m, ..spec }), bound))
            .collect();
        (schedule, [bound, bound])
    } else {
        let view = view_at(&off, &spec);
        let schedule = geometric_steps(COARSEST_PX, FINEST_PX, STEPS)
            .into_iter()
            .map(|bound| (view, bound))
            .collect();
        (schedule, [COARSEST_PX, FINEST_PX])
    };
    if let Some(dir) = &a.frames_dir {
        std::fs::create_dir_all(dir)
            .with_context(|| format!("--frames-dir: cannot make {}", dir.display()))?;
    }
    // The first frame that could not be written stops the sweep's output, not the sweep.
    let mut unwritten: Option<std::io::Error> = None;
    let sweep = off.sweep_each(&schedule, VISIBLE, Duration::from_secs(300), |i, image| {
        if let (Some(dir), None) = (&a.frames_dir, &unwritten)
            && let Err(e) = save_png(image, &dir.join(format!("{i:03}.png")))
        {
            unwritten = Some(e);
        }
    })?;
    if let Some(e) = unwritten {
        return Err(e).context("--frames-dir");
    }
    // Every frame's change adds up to at least the sweep's net change; the largest frame
    // carries at least the sum over the number of frames (the floor an even spread meets).
    let total = sweep.total_mean_abs();
    let net = sweep.net.map(|c| c.mean_abs);
    let changes = sweep.frames.len().saturating_sub(1).max(1) as f64;
    let frames: Vec<serde_json::Value> = sweep
        .frames
        .into_iter()
        .map(|f| {
            serde_json::json!({
                "sse_bound_px": f.sse_bound_px,
                "tiles": f.tiles,
                "max_level": f.max_level,
                "mean_abs_change": f.change.map(|c| c.mean_abs),
                "changed_share": f.change.map(|c| c.changed_share),
            })
        })
        .collect();
    let series =
        |key: &str| -> Vec<f64> { frames.iter().filter_map(|f| f[key].as_f64()).collect() };
    let (mean, share) = (series("mean_abs_change"), series("changed_share"));
    let changing = share.iter().filter(|&&s| s > 0.0).count();
    // Along a descent motion changes every frame, more as detail comes in: a split shows as
    // a step in that series.
    let largest_step = mean
        .windows(2)
        .map(|w| (w[1] - w[0]).abs())
        .fold(0.0, f64::max);
    let report = serde_json::json!({
        "camera": camera,
        "size": [width, height],
        "descent": a.descent,
        "bounds_px": bounds,
        "frames": frames.len(),
        "mean_abs_change": quantiles(mean),
        "changed_share": quantiles(share),
        "frames_changing": changing,
        "total_mean_abs_change": total,
        "net_mean_abs_change": net,
        "even_spread_floor": total / changes,
        "largest_step": largest_step,
        "per_frame": frames,
    });
    println!("{}", serde_json::to_string_pretty(&report)?);
    Ok(())
}
