//! `globus traffic`: synthetic records and a record's summary.

use std::fs::File;
use std::path::PathBuf;

use anyhow::{Context, bail};
use clap::{Args, Subcommand};
use globus_traffic::synth::{self, SynthOptions};
use globus_traffic::{AircraftKind, read_record};
use serde_json::json;

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
    }
}

/// A moment given as RFC 3339 or as Unix seconds, in Unix seconds.
pub fn parse_time(text: &str, what: &str) -> anyhow::Result<f64> {
    if let Ok(s) = text.trim().parse::<f64>() {
        if s.is_finite() && (0.0..7.0e9).contains(&s) {
            return Ok(s);
        }
        bail!("{what} {text:?} is not a Unix time from 1970 to 2191");
    }
    let t: jiff::Timestamp = text.trim().parse().with_context(|| {
        format!("{what} {text:?} is neither RFC 3339 (2018-08-01T12:00:00Z) nor Unix seconds")
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
