//! `globus bench --popping CAMERA`: how much the picture jumps when tiles split, with nothing
//! else moving (issue 20's measurement). The camera stands still while the error bound is
//! lowered from 8 px to 1 px over 120 frames (geometrically: splits come about evenly per
//! frame, as levels halve the error); every frame is loaded completely before it is drawn, so
//! what changes between two frames is only what the new bound split. Per frame: the mean
//! absolute change of a colour channel against the frame before and the share of pixels
//! changing by more than 8/255.

use std::time::Duration;

use anyhow::Context;
use globus_engine::{GlobeBuilder, Headless};

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
    let view = spec.view(off.globe(), a.globe.fov_deg, width, height);
    let frames: Vec<serde_json::Value> = off
        .sweep_error_bound(
            &view,
            (COARSEST_PX, FINEST_PX),
            STEPS,
            VISIBLE,
            Duration::from_secs(300),
        )?
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
    let report = serde_json::json!({
        "camera": camera,
        "size": [width, height],
        "bounds_px": [COARSEST_PX, FINEST_PX],
        "frames": frames.len(),
        "mean_abs_change": quantiles(mean),
        "changed_share": quantiles(share),
        "frames_changing": changing,
        "per_frame": frames,
    });
    println!("{}", serde_json::to_string_pretty(&report)?);
    Ok(())
}
