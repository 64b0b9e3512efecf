//! `globus traffic`: a record replayed in the viewer, synthetic records, a record's
//! summary; and the traffic scene `render` and `bench` draw.

use std::fs::File;
use std::path::{Path, PathBuf};

use anyhow::{Context, bail};
use clap::{Args, Subcommand};
use globus_engine::traffic::{Replay, ReplayOptions};
use globus_engine::{CameraSpec, TrafficLayer, TrafficStats};
use globus_traffic::synth::{self, SynthOptions};
use globus_traffic::{AircraftKind, read_record};
use serde_json::json;

use crate::args;
use crate::viewer;

/// `globus traffic`: a subcommand, or the replay viewer's options.
#[derive(Args)]
#[command(args_conflicts_with_subcommands = true, subcommand_negates_reqs = true)]
pub struct TrafficArgs {
    #[command(subcommand)]
    pub command: Option<TrafficCommand>,
    #[command(flatten)]
    pub view: TrafficViewArgs,
}

/// The replay viewer: `globus traffic --record FILE`.
#[derive(Args)]
pub struct TrafficViewArgs {
    /// The record to replay: OpenSky state-vector CSV, plain or gzip (e.g.
    /// ../shared/data/traffic-switzerland-2018-08-01.csv.gz). Space pauses, + and - double
    /// and halve the speed, a click selects an aircraft (printed as JSON), C follows it.
    #[arg(long, required = true)]
    pub record: Option<PathBuf>,
    /// Seconds of record per second shown (up to 10000).
    #[arg(long, default_value_t = 1.0, allow_negative_numbers = true)]
    pub speed: f64,
    /// Where the replay starts: RFC 3339 or Unix seconds (default: the record's first
    /// moment).
    #[arg(long)]
    pub start: Option<String>,
    #[command(flatten)]
    pub view: crate::args::ViewArgs,
    /// Draw one kind with a glTF 2.0 binary model: KIND=FILE.glb, KIND one of light,
    /// narrowbody, widebody, helicopter. Repeatable.
    #[arg(long = "model")]
    pub models: Vec<String>,
}

/// The fastest replay, seconds of record per second.
pub const MAX_SPEED: f64 = 10_000.0;

/// A record ready to draw: its replay at a moment, and the layer drawing it.
pub struct Scene {
    /// The replay.
    pub replay: Replay,
    /// The layer, holding the aircraft at `time_s`.
    pub layer: TrafficLayer,
    /// The moment drawn, Unix seconds.
    pub time_s: f64,
}

/// Reads a record and replays it to `time` (RFC 3339 or Unix seconds; default `default`, or
/// the record's first moment).
pub fn scene(path: &Path, time: Option<&str>, default: Option<f64>) -> anyhow::Result<Scene> {
    let record = read_record(path)?;
    let Some((first, last)) = record.time_span_s() else {
        bail!("{}: the record holds no positions", path.display());
    };
    let time_s = match time {
        Some(t) => parse_time(t, "--time")?,
        None => default.unwrap_or(first),
    };
    if time_s < first - 3_600.0 || time_s > last + 3_600.0 {
        tracing::warn!(
            "{}: {} is outside the record ({} to {}): no aircraft to draw",
            path.display(),
            format_time(time_s),
            format_time(first),
            format_time(last)
        );
    }
    let mut replay = Replay::new(record, ReplayOptions::default());
    let mut layer = TrafficLayer::new();
    layer
        .play(&mut replay, time_s)
        .with_context(|| format!("{}: replaying", path.display()))?;
    Ok(Scene {
        replay,
        layer,
        time_s,
    })
}

/// A camera looking straight down on a record's aircraft: over the median of every report,
/// high enough to see nine in ten of them.
pub fn default_camera(replay: &Replay) -> CameraSpec {
    let mut lons = Vec::new();
    let mut lats = Vec::new();
    for t in &replay.record().tracks {
        for r in t.reports.iter().step_by(8) {
            lons.push(r.lon_deg);
            lats.push(r.lat_deg);
        }
    }
    let median = |v: &mut Vec<f64>| {
        v.sort_by(f64::total_cmp);
        v.get(v.len() / 2).copied().unwrap_or(0.0)
    };
    let (lon, lat) = (median(&mut lons), median(&mut lats));
    let mut spread: Vec<f64> = lons
        .iter()
        .zip(&lats)
        .map(|(&x, &y)| {
            let dx = (x - lon) * lat.to_radians().cos();
            (dx * dx + (y - lat) * (y - lat)).sqrt() * 111_000.0
        })
        .collect();
    spread.sort_by(f64::total_cmp);
    let reach_m = spread
        .get(spread.len() * 9 / 10)
        .copied()
        .unwrap_or(100_000.0);
    CameraSpec {
        lon_deg: lon,
        lat_deg: lat,
        alt_m: (reach_m * 1.9).clamp(30_000.0, 8.0e6),
        heading_deg: 0.0,
        pitch_deg: -90.0,
        above_ground: false,
    }
}

/// The traffic layer's figures as JSON.
pub fn stats_json(s: &TrafficStats) -> serde_json::Value {
    json!({
        "aircraft": s.aircraft,
        "models": s.models,
        "models_coarse": s.models_coarse,
        "labels": s.labels,
        "labels_wanted": s.labels_wanted,
        "label_placement_us": s.label_placement_s * 1e6,
        "trail_segments": s.trail_segments,
        "draw_calls": s.draw_calls,
        "gpu_bytes": s.gpu_bytes,
        "prepare_us": s.prepare_s * 1e6,
        "apply_us": s.apply_s * 1e6,
    })
}

/// The name of a kind on the command line.
fn kind_name(kind: AircraftKind) -> &'static str {
    match kind {
        AircraftKind::Light => "light",
        AircraftKind::NarrowBody => "narrowbody",
        AircraftKind::WideBody => "widebody",
        AircraftKind::Helicopter => "helicopter",
    }
}

/// Gives `layer` the models of `--model KIND=FILE.glb` arguments.
pub fn apply_models(layer: &mut TrafficLayer, specs: &[String]) -> anyhow::Result<()> {
    for spec in specs {
        let Some((kind, file)) = spec.split_once('=') else {
            bail!("--model {spec:?} must be KIND=FILE.glb");
        };
        let kind = AircraftKind::ALL
            .into_iter()
            .find(|&k| kind_name(k) == kind.trim().to_ascii_lowercase().replace('-', ""))
            .with_context(|| {
                format!(
                    "--model {spec:?}: the kind must be one of light, narrowbody, widebody, helicopter"
                )
            })?;
        let mesh = globus_engine::traffic::read_glb(Path::new(file))?;
        tracing::info!(
            "{file}: {} triangles for {}",
            mesh.triangles(),
            kind_name(kind)
        );
        layer.set_model(kind, mesh);
    }
    Ok(())
}

fn write_models(out: &Path) -> anyhow::Result<String> {
    std::fs::create_dir_all(out).with_context(|| format!("cannot make {}", out.display()))?;
    let mut written = Vec::new();
    for kind in AircraftKind::ALL {
        let path = out.join(format!("{}.glb", kind_name(kind)));
        let bytes = globus_engine::traffic::write_glb(&globus_engine::traffic::aircraft_mesh(kind));
        globus_tiling::files::write_atomic(&path, &bytes)
            .with_context(|| format!("cannot write {}", path.display()))?;
        written.push(path.display().to_string());
    }
    Ok(json!({ "models": written }).to_string())
}

/// `globus traffic --record FILE`: the viewer on a replay.
pub fn view(a: TrafficViewArgs) -> anyhow::Result<()> {
    let Some(record) = &a.record else {
        bail!("traffic needs --record FILE, or a subcommand (see globus traffic --help)");
    };
    if !(a.speed > 0.0 && a.speed <= MAX_SPEED) {
        bail!(
            "--speed {} must be above 0 and at most {MAX_SPEED}",
            a.speed
        );
    }
    let v = &a.view;
    let exit_after = v.exit_after()?;
    let (width, height) = args::parse_size(&v.size)?;
    if v.time.is_some() {
        bail!(
            "globus traffic replays from --start (the Sun follows the replay's clock): --time is for view and render"
        );
    }
    let mut globe = args::globe_builder(&v.globe)?;
    let vectors = args::vector_layer(&v.globe, &mut globe)?;
    let mut scene = scene(record, a.start.as_deref(), None)?;
    apply_models(&mut scene.layer, &a.models)?;
    let camera = match &v.camera {
        Some(c) => args::parse_camera(c, v.above_ground)?,
        None => default_camera(&scene.replay),
    };
    viewer::run(viewer::ViewerOptions {
        globe,
        camera,
        fov_deg: v.globe.fov_deg,
        ortho_m: v.globe.ortho_km.map(|km| km * 1e3),
        width,
        height,
        exit_after,
        vectors,
        traffic: Some(viewer::ViewerTraffic::new(scene, a.speed)),
        sun_time: None,
    })
}

#[derive(Subcommand)]
pub enum TrafficCommand {
    /// Write a deterministic synthetic record (OpenSky state-vector CSV, gzip when the name
    /// ends in .gz): N flights between real airports, all airborne at the record's middle.
    Synth(SynthArgs),
    /// Read a record and print what it holds as JSON (flights, reports, time span, most
    /// aircraft at once, rows skipped by kind).
    Info {
        /// The record: OpenSky state-vector CSV, plain or gzip.
        record: PathBuf,
    },
    /// Write the built-in aircraft shapes as glTF 2.0 binary files (light.glb,
    /// narrowbody.glb, widebody.glb, helicopter.glb), to change and give back with --model.
    Models {
        /// The folder to write them in (made if missing).
        #[arg(long)]
        out: PathBuf,
    },
}

#[derive(Args)]
pub struct SynthArgs {
    /// Airports CSV (columns icao, iata, lat, lon, elevation in feet), e.g.
    /// ../shared/data/airports.csv.
    #[arg(long)]
    pub airports: PathBuf,
    /// Number of flights, all in the air at once around the record's middle.
    #[arg(long)]
    pub flights: usize,
    /// The record to write (.csv or .csv.gz); an existing file is replaced.
    #[arg(long)]
    pub out: PathBuf,
    /// Seed of the random choices: the same seed writes the same bytes.
    #[arg(long, default_value_t = 1)]
    pub seed: u64,
    /// Length of the record, hours (every flight is shorter).
    #[arg(long, default_value_t = 2.0)]
    pub hours: f64,
    /// Seconds between two reports of a flight (OpenSky's historical vectors: 10).
    #[arg(long = "period-s", default_value_t = 10.0)]
    pub period_s: f64,
    /// Only airports inside W,S,E,N degrees (e.g. -12,35,35,62 for Europe).
    #[arg(long, allow_negative_numbers = true)]
    pub bounds: Option<String>,
    /// The record's start: RFC 3339 (2026-01-01T00:00:00Z) or Unix seconds.
    #[arg(long, default_value = "2026-01-01T00:00:00Z")]
    pub start: String,
}

/// Runs a `traffic` subcommand and returns its JSON line.
pub fn run(command: TrafficCommand) -> anyhow::Result<String> {
    match command {
        TrafficCommand::Synth(a) => synth_cmd(&a),
        TrafficCommand::Info { record } => info(&record),
        TrafficCommand::Models { out } => write_models(&out),
    }
}

/// A moment given as RFC 3339, as Unix seconds or as `now`, in Unix seconds.
pub fn parse_time(text: &str, what: &str) -> anyhow::Result<f64> {
    if text.trim() == "now" {
        return Ok(jiff::Timestamp::now().as_millisecond() as f64 / 1000.0);
    }
    if let Ok(s) = text.trim().parse::<f64>() {
        if s.is_finite() && (0.0..7.0e9).contains(&s) {
            return Ok(s);
        }
        bail!("{what} {text:?} is not a Unix time from 1970 to 2191");
    }
    let t: jiff::Timestamp = text.trim().parse().with_context(|| {
        format!(
            "{what} {text:?} is neither RFC 3339 (2018-08-01T12:00:00Z), Unix seconds nor `now`"
        )
    })?;
    let s = t.as_millisecond() as f64 / 1000.0;
    if !(0.0..7.0e9).contains(&s) {
        bail!("{what} {text:?} is before 1970 or after 2191");
    }
    Ok(s)
}

/// Unix seconds as RFC 3339 (UTC, whole seconds).
pub fn format_time(unix_s: f64) -> String {
    jiff::Timestamp::from_second(unix_s.floor() as i64)
        .map(|t| t.to_string())
        .unwrap_or_else(|_| format!("{unix_s} s"))
}

fn synth_cmd(a: &SynthArgs) -> anyhow::Result<String> {
    let options = SynthOptions {
        flights: a.flights,
        seed: a.seed,
        hours: a.hours,
        period_s: a.period_s,
        bounds: a
            .bounds
            .as_deref()
            .map(crate::tile_cmd::parse_bounds_deg)
            .transpose()?,
        start_unix_s: parse_time(&a.start, "--start")?.floor(),
    };
    let airports = synth::read_airports(&a.airports)?;
    let plans = synth::plan_flights(&airports, &options)?;
    let file =
        File::create(&a.out).with_context(|| format!("{}: cannot create", a.out.display()))?;
    let gzip = a
        .out
        .extension()
        .is_some_and(|e| e.eq_ignore_ascii_case("gz"));
    let write_err = || format!("{}: cannot write the record", a.out.display());
    let rows = if gzip {
        let mut enc = flate2::write::GzEncoder::new(file, flate2::Compression::fast());
        let rows =
            synth::write_record(&airports, &plans, &options, &mut enc).with_context(write_err)?;
        enc.finish().with_context(write_err)?;
        rows
    } else {
        synth::write_record(&airports, &plans, &options, file).with_context(write_err)?
    };
    let mut kinds = serde_json::Map::new();
    for kind in AircraftKind::ALL {
        let n = plans.iter().filter(|p| p.kind == kind).count();
        kinds.insert(format!("{kind:?}").to_lowercase(), json!(n));
    }
    Ok(json!({
        "out": a.out.display().to_string(),
        "flights": plans.len(),
        "rows": rows,
        "kinds": kinds,
        "start": format_time(options.start_unix_s),
        "end": format_time(options.start_unix_s + options.hours * 3_600.0),
    })
    .to_string())
}

fn info(path: &std::path::Path) -> anyhow::Result<String> {
    let record = read_record(path)?;
    let (most, at) = record.most_at_once();
    let span = record.time_span_s();
    let skipped: Vec<_> = record
        .skipped
        .iter()
        .map(|s| json!({"kind": s.kind.to_string(), "rows": s.count, "first_line": s.first_line, "detail": s.detail}))
        .collect();
    let aircraft: std::collections::HashSet<u32> = record.tracks.iter().map(|t| t.icao24).collect();
    Ok(json!({
        "record": path.display().to_string(),
        "rows": record.rows,
        "reports": record.reports(),
        "flights": record.tracks.len(),
        "aircraft": aircraft.len(),
        "start": span.map(|s| format_time(s.0)),
        "end": span.map(|s| format_time(s.1)),
        "most_at_once": most,
        "most_at": (most > 0).then(|| format_time(at)),
        "skipped": skipped,
    })
    .to_string())
}
