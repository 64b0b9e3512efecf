//! `globus bench`: a camera path replayed offscreen (`path`), a jump between two views
//! (`jump`), a soak of random flights (`soak`), a traffic record replayed (`traffic`), or
//! the picture's jumps as the error bound falls (`popping`), each printing JSON.

mod jump;
mod path;
mod popping;
mod soak;
mod traffic;

use anyhow::bail;
use globus_engine::Headless;

use crate::args::{self, BenchArgs};

/// Lights the frames by the Sun of `--time`, if given (the traffic benchmark lights them by
/// the replay's moment itself).
fn light(a: &BenchArgs, off: &mut Headless) -> anyhow::Result<()> {
    if let Some(t) = &a.time {
        let t = crate::traffic_cmd::parse_time(t, "--time")?;
        off.globe_mut()
            .set_lighting(Some(globus_engine::Lighting::at_time(t)));
    }
    Ok(())
}

pub fn run(a: BenchArgs) -> anyhow::Result<()> {
    let (width, height) = args::parse_size(&a.size)?;
    let builder = args::globe_builder(&a.globe)?;
    if let Some(t) = &a.time {
        crate::traffic_cmd::parse_time(t, "--time")?;
    }
    if !(a.fps > 0.0 && a.fps <= 1000.0) {
        bail!("--fps {} must be above 0 and at most 1000", a.fps);
    }
    if a.globe.ortho_km.is_some() && a.traffic.is_none() {
        bail!(
            "--ortho-km applies to bench --traffic only (paths, jumps and soaks fly perspective cameras)"
        );
    }
    if let (Some(from), Some(to)) = (&a.from, &a.to) {
        return jump::run(&a, &builder, from, to, (width, height));
    }
    if let Some(seconds) = a.soak {
        if !(seconds > 0.0 && seconds.is_finite()) {
            bail!("--soak {seconds} must be a positive number of seconds");
        }
        return soak::run(&a, &builder, seconds, (width, height));
    }
    if let Some(record) = &a.traffic {
        return traffic::run(&a, &builder, record, (width, height));
    }
    if let Some(camera) = &a.popping {
        return popping::run(&a, &builder, camera, (width, height));
    }
    let Some(path_file) = &a.path else {
        bail!(
            "bench needs --path FILE.json, --from CAMERA --to CAMERA, --soak S, --traffic RECORD \
             or --popping CAMERA"
        );
    };
    path::run(&a, &builder, path_file, (width, height))
}

/// Median, 95th percentile and maximum of a sample, as JSON.
fn quantiles(mut v: Vec<f64>) -> serde_json::Value {
    if v.is_empty() {
        return serde_json::Value::Null;
    }
    v.sort_by(f64::total_cmp);
    let q = |p: f64| v[((v.len() - 1) as f64 * p).round() as usize];
    serde_json::json!({"median": q(0.5), "p95": q(0.95), "max": q(1.0)})
}

/// Bytes as MiB for reports (NaN when unknown).
fn mib(bytes: Option<u64>) -> f64 {
    bytes.map_or(f64::NAN, |b| b as f64 / 1048576.0)
}
