//! `globus bench --traffic`: a record replayed offscreen under a still camera, frame by frame,
//! reporting what a tick (handing the record's reports to the fleet) and the traffic layer's
//! frame cost on the CPU, and whole frames with and without the traffic (the same camera and
//! terrain, measured in the same run).

use std::path::Path;
use std::time::{Duration, Instant};

use anyhow::bail;
use globus_engine::{GlobeBuilder, Headless};
use serde_json::json;

use super::quantiles;
use crate::args::{self, BenchArgs};
use crate::traffic_cmd;

/// The most frames replayed.
const MAX_FRAMES: u32 = 100_000;

pub fn run(
    a: &BenchArgs,
    builder: &GlobeBuilder,
    record: &Path,
    (width, height): (u32, u32),
) -> anyhow::Result<()> {
    if !(a.speed > 0.0 && a.speed <= traffic_cmd::MAX_SPEED) {
        bail!(
            "--speed {} must be above 0 and at most {}",
            a.speed,
            traffic_cmd::MAX_SPEED
        );
    }
    if !(1..=MAX_FRAMES).contains(&a.frames) {
        bail!("--frames {} must be 1 to {MAX_FRAMES}", a.frames);
    }
    let read_started = Instant::now();
    let mut scene = traffic_cmd::scene(record, a.time.as_deref(), None)?;
    traffic_cmd::apply_models(&mut scene.layer, &a.models)?;
    let read_s = read_started.elapsed().as_secs_f64();
    if a.time.is_none() {
        // When the most aircraft are in the air.
        let (_, busiest) = scene.replay.record().most_at_once();
        scene.time_s = busiest;
        scene.layer.play(&mut scene.replay, busiest)?;
    }
    let camera = match &a.camera {
        Some(c) => args::parse_camera(c, false)?,
        None => traffic_cmd::default_camera(&scene.replay),
    };
    let mut off = Headless::new(builder, width, height)?;
    off.globe_mut()
        .set_lighting(Some(globus_engine::Lighting::at_time(scene.time_s)));
    let view = args::camera_view(&camera, off.globe(), &a.globe, width, height);
    // The terrain complete first, then one frame with the traffic (pipelines are made in the
    // first), so the figures time the replay alone.
    off.render_complete(&view, Duration::from_secs(120), &mut [])?;
    off.update(&view);
    off.draw(&mut [&mut scene.layer]);

    let start_s = scene.time_s;
    let dt = a.speed / a.fps;
    let mut tick_us = Vec::new();
    let mut prepare_us = Vec::new();
    let mut frame_ms = Vec::new();
    let mut aircraft = Vec::new();
    let mut uploaded = Vec::new();
    let mut placement_us = Vec::new();
    let mut labels = Vec::new();
    let (mut draw_calls, mut models, mut gpu_bytes) = (0u32, 0u32, 0u64);
    for i in 1..=a.frames {
        let t = start_s + f64::from(i) * dt;
        let started = Instant::now();
        scene.layer.play(&mut scene.replay, t)?;
        tick_us.push(started.elapsed().as_secs_f64() * 1e6);
        off.update(&view);
        off.draw(&mut [&mut scene.layer]);
        frame_ms.push(started.elapsed().as_secs_f64() * 1e3);
        let s = scene.layer.stats();
        prepare_us.push(s.prepare_s * 1e6);
        aircraft.push(s.aircraft as f64);
        uploaded.push(f64::from(s.trail_points_uploaded));
        placement_us.push(s.label_placement_s * 1e6);
        labels.push(f64::from(s.labels));
        draw_calls = draw_calls.max(s.draw_calls);
        models = models.max(s.models);
        gpu_bytes = gpu_bytes.max(s.gpu_bytes);
    }
    // The same frames without the traffic.
    let mut plain_ms = Vec::new();
    for _ in 0..a.frames.min(120) {
        let started = Instant::now();
        off.update(&view);
        off.draw(&mut []);
        plain_ms.push(started.elapsed().as_secs_f64() * 1e3);
    }
    let summary = json!({
        "record": record.display().to_string(),
        "record_read_s": read_s,
        "start": traffic_cmd::format_time(start_s),
        "speed": a.speed,
        "fps": a.fps,
        "frames": a.frames,
        "size": [width, height],
        "camera": [camera.lon_deg, camera.lat_deg, camera.alt_m, camera.heading_deg, camera.pitch_deg],
        "aircraft": quantiles(aircraft),
        "tick_us": quantiles(tick_us),
        "traffic_prepare_us": quantiles(prepare_us),
        "trail_points_uploaded": quantiles(uploaded),
        "label_placement_us": quantiles(placement_us),
        "labels": quantiles(labels),
        "frame_ms": quantiles(frame_ms),
        "frame_ms_without_traffic": quantiles(plain_ms),
        "traffic_draw_calls": draw_calls,
        "models_drawn_most": models,
        "traffic_gpu_bytes": gpu_bytes,
        "fleet_heap_bytes": scene.layer.fleet().heap_bytes(),
        "adapter": off.gpu().adapter_description(),
    });
    println!("{summary}");
    Ok(())
}
