//! Recorded flights in OpenSky's historical state-vector CSV layout, plain or gzip.
//!
//! The layout (documented in `../shared/data/README.md` and by OpenSky for its historical
//! database dumps) has one row per aircraft and report: `time` (Unix s), `icao24` (24-bit
//! address, hex), `lat`, `lon` (degrees), `velocity` (m/s over ground), `heading` (degrees
//! clockwise from north), `vertrate` (m/s), `callsign`, `onground`, `alert`, `spi`, `squawk`,
//! `baroaltitude`, `geoaltitude` (m), `lastposupdate`, `lastcontact`; empty cells are unknown.
//! Columns are found by name, so their order and any extra columns do not matter; `time`,
//! `icao24`, `lat`, `lon` and one of the two altitudes must be there.
//!
//! A record is read into one [`Track`] per flight, reports sorted by time. Bad rows never end
//! the read: each is counted under a [`SkipKind`] (with the first line it happened on) and
//! skipped, one warning per kind is logged at the end, and the rest plays. A gzip stream that
//! stops early keeps every complete row before the break. Only a file that is not such a CSV at
//! all (no header with those columns) is an error.
//!
//! When `lastposupdate` is given, a report is timed by it: OpenSky repeats the last known
//! position every 10 s while no new one arrives, and timing those repeats by `time` would make
//! a replayed aircraft stop and jump. A repeat therefore counts as a duplicate.

use std::collections::HashMap;
use std::fmt;
use std::fs::File;
use std::io::{BufReader, Read};
use std::path::{Path, PathBuf};

use flate2::read::MultiGzDecoder;

/// Reading a record failed as a whole.
#[derive(Debug, thiserror::Error)]
pub enum RecordError {
    /// The file could not be opened or its first bytes read.
    #[error("{path}: cannot read the traffic record: {source}")]
    Open {
        /// The file.
        path: PathBuf,
        /// Why.
        source: std::io::Error,
    },
    /// The file is not a state-vector CSV (no header naming the needed columns).
    #[error(
        "{path}: not an OpenSky state-vector CSV ({reason}); expected a header with time, icao24, lat, lon and baroaltitude or geoaltitude"
    )]
    NotStateVectors {
        /// The file.
        path: PathBuf,
        /// What was found instead.
        reason: String,
    },
}

/// Why a row was skipped.
#[derive(Clone, Copy, Debug, PartialEq, Eq, Hash, PartialOrd, Ord)]
pub enum SkipKind {
    /// A needed cell is empty or the row is short.
    MissingColumn,
    /// A cell is not a number (or not a 24-bit hex address, or not UTF-8).
    Unparsable,
    /// A coordinate, altitude or time is NaN, infinite or outside its range.
    OutOfRange,
    /// The report is older than the aircraft's previous one.
    TimeBackwards,
    /// The aircraft already has a report at that time.
    Duplicate,
    /// The gzip stream (or the file) ended inside the data; everything before it was kept.
    TruncatedGzip,
}

impl SkipKind {
    /// Every kind, in the order warnings are logged.
    pub const ALL: [SkipKind; 6] = [
        SkipKind::MissingColumn,
        SkipKind::Unparsable,
        SkipKind::OutOfRange,
        SkipKind::TimeBackwards,
        SkipKind::Duplicate,
        SkipKind::TruncatedGzip,
    ];

    fn describe(self) -> &'static str {
        match self {
            SkipKind::MissingColumn => "missing column",
            SkipKind::Unparsable => "unparsable value",
            SkipKind::OutOfRange => "value out of range",
            SkipKind::TimeBackwards => "time going backwards for its aircraft",
            SkipKind::Duplicate => "duplicate report",
            SkipKind::TruncatedGzip => "stream ends early (truncated gzip)",
        }
    }
}

impl fmt::Display for SkipKind {
    fn fmt(&self, f: &mut fmt::Formatter<'_>) -> fmt::Result {
        f.write_str(self.describe())
    }
}

/// The rows of one kind that were skipped.
#[derive(Clone, Debug, PartialEq)]
pub struct Skip {
    /// Why.
    pub kind: SkipKind,
    /// How many rows (for [`SkipKind::TruncatedGzip`]: 1, the break).
    pub count: u64,
    /// The 1-based line of the first such row (the header is line 1).
    pub first_line: u64,
    /// What was wrong with that first row.
    pub detail: String,
}

/// One position report of one aircraft.
#[derive(Clone, Copy, Debug, PartialEq)]
pub struct Report {
    /// When the position was measured (Unix seconds).
    pub time_s: f64,
    /// Geodetic latitude, degrees.
    pub lat_deg: f64,
    /// Longitude, degrees.
    pub lon_deg: f64,
    /// Height above the ellipsoid (geometric altitude, else barometric), metres; NaN when
    /// unknown, which only an aircraft on the ground may have.
    pub altitude_m: f64,
    /// Speed over ground, m/s (NaN when unknown).
    pub velocity_mps: f32,
    /// Track over ground, degrees clockwise from north (NaN when unknown).
    pub heading_deg: f32,
    /// Vertical rate, m/s, positive up (NaN when unknown).
    pub vertical_rate_mps: f32,
    /// On the ground (from `onground`).
    pub on_ground: bool,
}

/// One flight: the reports of one aircraft under one call sign, sorted by time, none at the
/// same time. An aircraft's reports become a new flight when its call sign changes or after
/// [`FLIGHT_GAP_S`] without a report (as the `traffic` library splits flights).
#[derive(Clone, Debug, PartialEq)]
pub struct Track {
    /// The 24-bit ICAO address.
    pub icao24: u32,
    /// The call sign (trimmed; empty when the record gives none).
    pub callsign: String,
    /// The ICAO aircraft type designator (e.g. `A320`) from an optional `typecode` column
    /// (OpenSky's aircraft database names it so; `globus traffic synth` writes it); empty when
    /// unknown.
    pub typecode: String,
    /// The reports.
    pub reports: Vec<Report>,
}

/// A silence after which an aircraft's next report starts a new flight, seconds.
pub const FLIGHT_GAP_S: f64 = 1_800.0;

impl Track {
    fn new(icao24: u32) -> Track {
        Track {
            icao24,
            callsign: String::new(),
            typecode: String::new(),
            reports: Vec::new(),
        }
    }

    fn starts_new_flight(&self, callsign: Option<&str>, time_s: f64) -> bool {
        let Some(last) = self.reports.last() else {
            return false;
        };
        let renamed = callsign.is_some_and(|c| !self.callsign.is_empty() && c != self.callsign);
        renamed || time_s - last.time_s > FLIGHT_GAP_S
    }

    /// The address as OpenSky writes it: six lowercase hex digits.
    pub fn icao24_hex(&self) -> String {
        format!("{:06x}", self.icao24)
    }
}

/// A whole record: one track per aircraft.
#[derive(Clone, Debug, Default, PartialEq)]
pub struct Record {
    /// Flights in order of their first report.
    pub tracks: Vec<Track>,
    /// Rows skipped, one entry per kind that happened, in [`SkipKind::ALL`] order.
    pub skipped: Vec<Skip>,
    /// Data rows read (kept and skipped).
    pub rows: u64,
}

impl Record {
    /// Reports kept, over all tracks.
    pub fn reports(&self) -> usize {
        self.tracks.iter().map(|t| t.reports.len()).sum()
    }

    /// The first and last report time, or `None` for an empty record.
    pub fn time_span_s(&self) -> Option<(f64, f64)> {
        let mut span: Option<(f64, f64)> = None;
        for r in self
            .tracks
            .iter()
            .flat_map(|t| [t.reports.first(), t.reports.last()])
        {
            let Some(r) = r else { continue };
            span = Some(match span {
                None => (r.time_s, r.time_s),
                Some((a, b)) => (a.min(r.time_s), b.max(r.time_s)),
            });
        }
        span
    }

    /// The most flights in the air (between their first and last report) at one moment,
    /// and the first moment it happens; `(0, NaN)` for an empty record.
    pub fn most_at_once(&self) -> (usize, f64) {
        let mut events: Vec<(f64, i32)> = Vec::with_capacity(self.tracks.len() * 2);
        for t in &self.tracks {
            if let (Some(a), Some(b)) = (t.reports.first(), t.reports.last()) {
                events.push((a.time_s, 1));
                events.push((b.time_s, -1));
            }
        }
        // Starts before ends at the same moment: a flight seen at t counts at t.
        events.sort_by(|a, b| a.0.total_cmp(&b.0).then(b.1.cmp(&a.1)));
        let (mut now, mut best) = (0i64, (0usize, f64::NAN));
        for (time, step) in events {
            now += i64::from(step);
            if now as usize > best.0 {
                best = (now as usize, time);
            }
        }
        best
    }

    /// How many rows of `kind` were skipped.
    pub fn skipped_of(&self, kind: SkipKind) -> u64 {
        self.skipped
            .iter()
            .filter(|s| s.kind == kind)
            .map(|s| s.count)
            .sum()
    }

    /// The flights of an aircraft, in time order.
    pub fn flights_of(&self, icao24: u32) -> impl Iterator<Item = &Track> {
        self.tracks.iter().filter(move |t| t.icao24 == icao24)
    }
}

/// Reads a record from a file, gzip-compressed or not (told by its first bytes, not its name).
pub fn read_record(path: &Path) -> Result<Record, RecordError> {
    let open_err = |source| RecordError::Open {
        path: path.to_owned(),
        source,
    };
    let file = File::open(path).map_err(open_err)?;
    read_record_from(file, path)
}

/// Reads a record from any byte stream; `name` is what errors and warnings call it.
pub fn read_record_from(source: impl Read, name: &Path) -> Result<Record, RecordError> {
    let mut input = BufReader::with_capacity(1 << 16, source);
    let mut magic = [0u8; 2];
    let got = read_up_to(&mut input, &mut magic).map_err(|source| RecordError::Open {
        path: name.to_owned(),
        source,
    })?;
    let prefix = std::io::Cursor::new(magic[..got].to_vec());
    let chained = prefix.chain(input);
    if got == 2 && magic == [0x1f, 0x8b] {
        read_csv(MultiGzDecoder::new(chained), name)
    } else {
        read_csv(chained, name)
    }
}

fn read_up_to(input: &mut impl Read, buf: &mut [u8]) -> std::io::Result<usize> {
    let mut got = 0;
    while got < buf.len() {
        match input.read(&mut buf[got..]) {
            Ok(0) => break,
            Ok(n) => got += n,
            Err(e) if e.kind() == std::io::ErrorKind::Interrupted => {}
            Err(e) => return Err(e),
        }
    }
    Ok(got)
}

/// A needed column the header lacks.
struct MissingColumn(&'static str);

/// Where the columns are.
struct Columns {
    time: usize,
    icao24: usize,
    lat: usize,
    lon: usize,
    geo_alt: Option<usize>,
    baro_alt: Option<usize>,
    velocity: Option<usize>,
    heading: Option<usize>,
    vertrate: Option<usize>,
    callsign: Option<usize>,
    onground: Option<usize>,
    lastposupdate: Option<usize>,
    typecode: Option<usize>,
}

impl Columns {
    fn find(header: &csv::ByteRecord) -> Result<Columns, MissingColumn> {
        let index = |name: &str| {
            header
                .iter()
                .position(|h| h.trim_ascii().eq_ignore_ascii_case(name.as_bytes()))
        };
        let need = |name: &'static str| index(name).ok_or(MissingColumn(name));
        let columns = Columns {
            time: need("time")?,
            icao24: need("icao24")?,
            lat: need("lat")?,
            lon: need("lon")?,
            geo_alt: index("geoaltitude"),
            baro_alt: index("baroaltitude"),
            velocity: index("velocity"),
            heading: index("heading"),
            vertrate: index("vertrate"),
            callsign: index("callsign"),
            onground: index("onground"),
            lastposupdate: index("lastposupdate"),
            typecode: index("typecode"),
        };
        if columns.geo_alt.is_none() && columns.baro_alt.is_none() {
            return Err(MissingColumn("baroaltitude or geoaltitude"));
        }
        Ok(columns)
    }
}

/// One bad row: its kind and what was wrong.
struct Bad(SkipKind, String);

/// Counts skipped rows per kind.
#[derive(Default)]
struct Skips(HashMap<SkipKind, Skip>);

impl Skips {
    fn add(&mut self, Bad(kind, detail): Bad, line: u64) {
        self.0
            .entry(kind)
            .and_modify(|s| s.count += 1)
            .or_insert(Skip {
                kind,
                count: 1,
                first_line: line,
                detail,
            });
    }

    fn finish(mut self, name: &Path) -> Vec<Skip> {
        let mut out = Vec::new();
        for kind in SkipKind::ALL {
            if let Some(s) = self.0.remove(&kind) {
                tracing::warn!(
                    "{}: line {}: {} ({}); {} such row(s) skipped, the rest plays",
                    name.display(),
                    s.first_line,
                    kind,
                    s.detail,
                    s.count
                );
                out.push(s);
            }
        }
        out
    }
}

fn read_csv(input: impl Read, name: &Path) -> Result<Record, RecordError> {
    let not_csv = |reason: String| RecordError::NotStateVectors {
        path: name.to_owned(),
        reason,
    };
    let mut reader = csv::ReaderBuilder::new()
        .has_headers(false)
        .flexible(true)
        .buffer_capacity(1 << 16)
        .from_reader(input);
    let mut row = csv::ByteRecord::new();
    let header_read = reader
        .read_byte_record(&mut row)
        .map_err(|e| not_csv(format!("header unreadable: {e}")))?;
    if !header_read {
        return Err(not_csv("the file is empty".into()));
    }
    let columns = Columns::find(&row).map_err(|why| {
        let shown = String::from_utf8_lossy(row.as_slice());
        let shown: String = shown.chars().take(60).collect();
        not_csv(format!(
            "no {} column; the first line reads {shown:?}",
            why.0
        ))
    })?;

    let mut tracks: Vec<Track> = Vec::new();
    let mut by_address: HashMap<u32, usize> = HashMap::new();
    let mut skips = Skips::default();
    let mut rows = 0u64;
    let mut line = 1u64;
    loop {
        match reader.read_byte_record(&mut row) {
            Ok(false) => break,
            Ok(true) => {}
            Err(e) => {
                // An I/O error mid-stream is a truncated or corrupt gzip (or a failing disk);
                // a CSV-level error (bad UTF-8 cannot happen with byte records) likewise ends
                // the data we can trust.
                let at = e.position().map_or(line + 1, |p| p.line().max(line + 1));
                skips.add(Bad(SkipKind::TruncatedGzip, e.to_string()), at);
                break;
            }
        }
        rows += 1;
        line = row.position().map_or(line + 1, |p| p.line());
        let (icao24, Names { callsign, typecode }, report) = match parse_row(&row, &columns) {
            Ok(parsed) => parsed,
            Err(bad) => {
                skips.add(bad, line);
                continue;
            }
        };
        let slot = *by_address.entry(icao24).or_insert_with(|| {
            tracks.push(Track::new(icao24));
            tracks.len() - 1
        });
        if let Some(last) = tracks[slot].reports.last() {
            if report.time_s < last.time_s {
                let why = format!("{:06x} at {} after {}", icao24, report.time_s, last.time_s);
                skips.add(Bad(SkipKind::TimeBackwards, why), line);
                continue;
            }
            if report.time_s == last.time_s {
                let why = format!("{:06x} twice at {}", icao24, report.time_s);
                skips.add(Bad(SkipKind::Duplicate, why), line);
                continue;
            }
        }
        let slot = if tracks[slot].starts_new_flight(callsign, report.time_s) {
            tracks.push(Track::new(icao24));
            by_address.insert(icao24, tracks.len() - 1);
            tracks.len() - 1
        } else {
            slot
        };
        let track = &mut tracks[slot];
        if let (Some(c), true) = (callsign, track.callsign.is_empty()) {
            track.callsign = c.to_owned();
        }
        if let (Some(c), true) = (typecode, track.typecode.is_empty()) {
            track.typecode = c.to_owned();
        }
        track.reports.push(report);
    }
    let skipped = skips.finish(name);
    tracing::debug!(
        "{}: {} rows, {} aircraft, {} skipped",
        name.display(),
        rows,
        tracks.len(),
        skipped.iter().map(|s| s.count).sum::<u64>()
    );
    Ok(Record {
        tracks,
        skipped,
        rows,
    })
}

/// A cell, trimmed; `None` when the row is short or the cell empty.
fn cell(row: &csv::ByteRecord, index: usize) -> Option<&[u8]> {
    row.get(index)
        .map(<[u8]>::trim_ascii)
        .filter(|c| !c.is_empty())
}

fn number(row: &csv::ByteRecord, index: usize, name: &str) -> Result<Option<f64>, Bad> {
    let Some(c) = cell(row, index) else {
        return Ok(None);
    };
    std::str::from_utf8(c)
        .ok()
        .and_then(|s| s.parse::<f64>().ok())
        .map(Some)
        .ok_or_else(|| {
            let shown = String::from_utf8_lossy(c);
            Bad(SkipKind::Unparsable, format!("{name} {shown:?}"))
        })
}

fn needed(row: &csv::ByteRecord, index: usize, name: &str) -> Result<f64, Bad> {
    number(row, index, name)?.ok_or_else(|| Bad(SkipKind::MissingColumn, format!("no {name}")))
}

fn optional(row: &csv::ByteRecord, index: Option<usize>, name: &str) -> Result<f64, Bad> {
    Ok(match index {
        Some(i) => number(row, i, name)?.unwrap_or(f64::NAN),
        None => f64::NAN,
    })
}

fn in_range(value: f64, lo: f64, hi: f64, name: &str) -> Result<f64, Bad> {
    if value.is_finite() && (lo..=hi).contains(&value) {
        Ok(value)
    } else {
        Err(Bad(
            SkipKind::OutOfRange,
            format!("{name} {value} outside {lo}..{hi}"),
        ))
    }
}

/// Optional values may be unknown (NaN) but not infinite or absurd.
fn finite_or_unknown(value: f64, lo: f64, hi: f64, name: &str) -> Result<f32, Bad> {
    if value.is_nan() {
        return Ok(f32::NAN);
    }
    in_range(value, lo, hi, name).map(|v| v as f32)
}

fn boolean(row: &csv::ByteRecord, index: Option<usize>) -> Result<bool, Bad> {
    let Some(c) = index.and_then(|i| cell(row, i)) else {
        return Ok(false);
    };
    match c.to_ascii_lowercase().as_slice() {
        b"true" | b"1" | b"t" => Ok(true),
        b"false" | b"0" | b"f" => Ok(false),
        other => Err(Bad(
            SkipKind::Unparsable,
            format!("onground {:?}", String::from_utf8_lossy(other)),
        )),
    }
}

fn address(row: &csv::ByteRecord, index: usize) -> Result<u32, Bad> {
    let c = cell(row, index).ok_or_else(|| Bad(SkipKind::MissingColumn, "no icao24".into()))?;
    let text = std::str::from_utf8(c).ok().filter(|s| s.len() <= 6);
    text.and_then(|s| u32::from_str_radix(s, 16).ok())
        .ok_or_else(|| {
            let shown = String::from_utf8_lossy(c);
            Bad(
                SkipKind::Unparsable,
                format!("icao24 {shown:?} is not a 24-bit hex address"),
            )
        })
}

/// Earliest and latest times accepted: 1970 to 2200.
const TIME_RANGE_S: (f64, f64) = (0.0, 7.3e9);

/// A row's text cells that name its flight.
struct Names<'r> {
    callsign: Option<&'r str>,
    typecode: Option<&'r str>,
}

fn parse_row<'r>(row: &'r csv::ByteRecord, c: &Columns) -> Result<(u32, Names<'r>, Report), Bad> {
    let icao24 = address(row, c.icao24)?;
    let time = needed(row, c.time, "time")?;
    let lat = needed(row, c.lat, "lat")?;
    let lon = needed(row, c.lon, "lon")?;
    let time = in_range(time, TIME_RANGE_S.0, TIME_RANGE_S.1, "time")?;
    let lat_deg = in_range(lat, -90.0, 90.0, "lat")?;
    let lon_deg = in_range(lon, -180.0, 180.0, "lon")?;
    let on_ground = boolean(row, c.onground)?;
    let geo = optional(row, c.geo_alt, "geoaltitude")?;
    let baro = optional(row, c.baro_alt, "baroaltitude")?;
    let altitude = if geo.is_nan() { baro } else { geo };
    let altitude_m = if altitude.is_nan() {
        if !on_ground {
            return Err(Bad(
                SkipKind::MissingColumn,
                "no altitude in the air".into(),
            ));
        }
        f64::NAN
    } else {
        in_range(altitude, -1_000.0, 100_000.0, "altitude")?
    };
    // A position is timed by its own update when that is given and plausible.
    let time_s = match c.lastposupdate.map(|i| number(row, i, "lastposupdate")) {
        Some(Ok(Some(p))) if p.is_finite() && p <= time && p > time - 3_600.0 => p,
        _ => time,
    };
    let report = Report {
        time_s,
        lat_deg,
        lon_deg,
        altitude_m,
        velocity_mps: finite_or_unknown(
            optional(row, c.velocity, "velocity")?,
            0.0,
            2_000.0,
            "velocity",
        )?,
        heading_deg: finite_or_unknown(
            optional(row, c.heading, "heading")?,
            -360.0,
            360.0,
            "heading",
        )?,
        vertical_rate_mps: finite_or_unknown(
            optional(row, c.vertrate, "vertrate")?,
            -500.0,
            500.0,
            "vertrate",
        )?,
        on_ground,
    };
    let text = |index: Option<usize>| {
        index
            .and_then(|i| cell(row, i))
            .and_then(|b| std::str::from_utf8(b).ok())
    };
    let names = Names {
        callsign: text(c.callsign),
        typecode: text(c.typecode),
    };
    Ok((icao24, names, report))
}

#[cfg(test)]
mod tests;
