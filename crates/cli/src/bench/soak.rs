//! `globus bench --soak SECONDS`: random flights between random views in real time at 10
//! frames per second, one JSON line of memory and load counters per second, then a summary.

use std::time::{Duration, Instant};

use globus_engine::{CameraSpec, GlobeBuilder, Headless};
use serde_json::json;

use super::mib;
use crate::args::BenchArgs;

/// Seconds a flight between two random views takes.
const LEG_S: f64 = 4.0;

/// A xorshift generator of uniform numbers in [0, 1): the same flights every run.
struct Uniform(u64);

impl Uniform {
    fn next(&mut self) -> f64 {
        let s = &mut self.0;
        *s ^= *s << 13;
        *s ^= *s >> 7;
        *s ^= *s << 17;
        (*s >> 11) as f64 / (1u64 << 53) as f64
    }

    /// A view from 300 m to 8,000 km above the ground, uniform over the sphere's area,
    /// looking down from high up and anywhere from down to near the horizon lower.
    fn pose(&mut self) -> CameraSpec {
        let alt = (300f64.ln() + self.next() * (8.0e6f64.ln() - 300f64.ln())).exp();
        CameraSpec {
            lon_deg: self.next() * 360.0 - 180.0,
            lat_deg: (self.next() * 2.0 - 1.0)
                .asin()
                .to_degrees()
                .clamp(-80.0, 80.0),
            alt_m: alt,
            heading_deg: self.next() * 360.0,
            pitch_deg: if alt > 500_000.0 {
                -90.0
            } else {
                -90.0 + self.next() * 80.0
            },
            above_ground: true,
        }
    }
}

/// Smooth (eased) interpolation between two poses, altitude in log space.
fn between(from: &CameraSpec, to: &CameraSpec, f: f64) -> CameraSpec {
    let s = f * f * (3.0 - 2.0 * f);
    let mix = |x: f64, y: f64| x + (y - x) * s;
    CameraSpec {
        lon_deg: mix(from.lon_deg, to.lon_deg),
        lat_deg: mix(from.lat_deg, to.lat_deg),
        alt_m: mix(from.alt_m.ln(), to.alt_m.ln()).exp(),
        heading_deg: mix(from.heading_deg, to.heading_deg),
        pitch_deg: mix(from.pitch_deg, to.pitch_deg),
        above_ground: true,
    }
}

pub fn run(
    a: &BenchArgs,
    builder: &GlobeBuilder,
    seconds: f64,
    (width, height): (u32, u32),
) -> anyhow::Result<()> {
    let mut off = Headless::new(builder, width, height)?;
    super::light(a, &mut off)?;
    let mut uniform = Uniform(0x2545_F491_4F6C_DD1D);
    let (mut from, mut to) = (uniform.pose(), uniform.pose());
    let started = Instant::now();
    let (mut leg_start, mut next_sample, mut frame) = (0.0, 0.0, 0u64);
    let mut max_rss: f64 = 0.0;
    loop {
        let t = started.elapsed().as_secs_f64();
        if t > seconds {
            break;
        }
        if t - leg_start >= LEG_S {
            from = to;
            to = uniform.pose();
            leg_start = t;
        }
        let pose = between(&from, &to, ((t - leg_start) / LEG_S).clamp(0.0, 1.0));
        let view = pose.view(off.globe(), a.globe.fov_deg, width, height);
        let r = off.update(&view);
        off.draw(&mut []);
        frame += 1;
        if t >= next_sample {
            next_sample += 1.0;
            let memory = off.globe().memory_use();
            let rss = mib(memory.resident);
            max_rss = max_rss.max(rss);
            let st = off.globe().layer().scheduler_stats();
            println!(
                "{}",
                json!({
                    "t_s": t,
                    "rss_mib": rss,
                    "cache_mib": mib(Some(memory.tile_cache)),
                    "cache_budget_mib": mib(Some(memory.tile_cache_budget)),
                    "source_caches_mib": mib(Some(memory.sources)),
                    "gpu_pool_mib": mib(Some(memory.gpu_pool)),
                    "memory_budget_mib": mib(memory.plan.map(|p| p.total)),
                    "baseline_mib": mib(memory.plan.map(|p| p.baseline)),
                    "gpu_tiles": r.pool.resident,
                    "gpu_capacity": r.pool.capacity,
                    "loading": r.layer.loading,
                    "loaded": st.loaded,
                    "failed": st.failed,
                    "retries": st.retries,
                    "sse_bound_px": r.sse_bound_px,
                    "frames": frame,
                })
            );
        }
        let ahead = frame as f64 / 10.0 - started.elapsed().as_secs_f64();
        if ahead > 0.0 {
            std::thread::sleep(Duration::from_secs_f64(ahead));
        }
    }
    let st = off.globe().layer().scheduler_stats();
    println!(
        "{}",
        json!({"summary": true, "seconds": seconds, "frames": frame, "max_rss_mib": max_rss,
               "memory_budget_mib": mib(off.globe().memory_use().plan.map(|p| p.total)),
               "loaded": st.loaded, "failed": st.failed, "retries": st.retries,
               "no_data": st.no_data, "stopped_in_flight": st.cancelled_in_flight})
    );
    Ok(())
}
