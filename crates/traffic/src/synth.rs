//! Synthetic traffic: a deterministic record of N flights between real airports, all airborne
//! at once around the middle of the record, written in the state-vector layout
//! [`crate::record`] reads (plus a `typecode` column).
//!
//! Each flight picks a kind (light aircraft 15 %, helicopter 5 %, narrow-body 65 %, wide-body
//! 15 %; light aircraft and helicopters use any airfield, airliners only airports with an IATA
//! code), an origin, and a destination at a distance typical of the kind, and flies the
//! geodesic between them (geographiclib): a climb at constant vertical rate while speeding up
//! from take-off to cruise speed, a cruise at a flight level obeying the semicircular rule
//! (odd thousands of feet eastbound, even westbound; VFR levels plus 500 ft for light
//! aircraft), and a descent slowing to approach speed that ends on the destination's runway.
//! Short flights cruise lower, so climb and descent always fit. Reports come every
//! `period_s` (OpenSky's historical vectors: 10 s) on a common time grid; the first is on the
//! ground at the origin at take-off, the last on the ground at the destination at landing.
//!
//! Every flight is shorter than the record, and its take-off is drawn so that it is in the air
//! at the record's middle. Randomness is a SplitMix64 stream per flight seeded from the seed
//! and the flight's number, so a seed gives the same bytes on every machine (a generator
//! crate's streams may change between versions, which would break that).

use std::io::Write;
use std::path::{Path, PathBuf};

use geographiclib_rs::{DirectGeodesic, Geodesic, InverseGeodesic};

use crate::kind::AircraftKind;

/// The most flights one record may have.
pub const MAX_FLIGHTS: usize = 1_000_000;
/// The longest record, hours.
pub const MAX_HOURS: f64 = 48.0;
/// Unix time of the default record start: 2026-01-01T00:00:00Z.
pub const DEFAULT_START_UNIX_S: f64 = 1_767_225_600.0;

/// Making a synthetic record failed.
#[derive(Debug, thiserror::Error)]
pub enum SynthError {
    /// The airports file could not be read.
    #[error("{path}: cannot read airports: {source}")]
    Airports {
        /// The file.
        path: PathBuf,
        /// Why.
        source: csv::Error,
    },
    /// The airports file lacks a needed column.
    #[error("{path}: not an airports CSV: no {column} column")]
    AirportColumns {
        /// The file.
        path: PathBuf,
        /// The missing column.
        column: &'static str,
    },
    /// An option is out of range.
    #[error("{0}")]
    Options(String),
    /// No pair of airports makes a flight of any kind that fits the record.
    #[error(
        "no pair of airports {where_} makes a flight shorter than the record ({hours} h); widen the bounds or lengthen --hours"
    )]
    NoRoute {
        /// Which airports were tried.
        where_: String,
        /// The record's length.
        hours: f64,
    },
    /// Writing the record failed (the message quotes the cause, which is not also its
    /// `source()`).
    #[error("cannot write the record: {0}")]
    Write(std::io::Error),
}

impl From<std::io::Error> for SynthError {
    fn from(e: std::io::Error) -> Self {
        Self::Write(e)
    }
}

/// One airport from `airports.csv`.
#[derive(Clone, Debug, PartialEq)]
pub struct Airport {
    /// ICAO location indicator (e.g. `LSZH`).
    pub icao: String,
    /// Whether it has an IATA code (scheduled airline service).
    pub scheduled: bool,
    /// Latitude, degrees.
    pub lat_deg: f64,
    /// Longitude, degrees.
    pub lon_deg: f64,
    /// Elevation above the ellipsoid (the file's feet above sea level, taken as is), metres.
    pub elevation_m: f64,
}

/// Reads airports (columns `icao`, `iata`, `lat`, `lon`, `elevation` in feet, found by name);
/// rows with unusable values are skipped with one warning naming the first.
pub fn read_airports(path: &Path) -> Result<Vec<Airport>, SynthError> {
    let csv_err = |source| SynthError::Airports {
        path: path.to_owned(),
        source,
    };
    let mut reader = csv::ReaderBuilder::new()
        .flexible(true)
        .from_path(path)
        .map_err(csv_err)?;
    let header = reader.headers().map_err(csv_err)?.clone();
    let column = |name: &'static str| {
        header
            .iter()
            .position(|h| h.trim() == name)
            .ok_or(SynthError::AirportColumns {
                path: path.to_owned(),
                column: name,
            })
    };
    let (icao, iata, lat, lon, elev) = (
        column("icao")?,
        column("iata")?,
        column("lat")?,
        column("lon")?,
        column("elevation")?,
    );
    let mut airports = Vec::new();
    // Rows skipped, and the line of the first.
    let mut skipped: (u64, Option<usize>) = (0, None);
    for (i, row) in reader.records().enumerate() {
        let row = row.map_err(csv_err)?;
        let num = |k: usize| row.get(k).and_then(|c| c.trim().parse::<f64>().ok());
        let position = num(lat).zip(num(lon));
        let Some((la, lo)) = position.filter(|(la, lo)| la.abs() <= 90.0 && lo.abs() <= 180.0)
        else {
            skipped = (skipped.0 + 1, skipped.1.or(Some(i + 2)));
            continue;
        };
        airports.push(Airport {
            icao: row.get(icao).unwrap_or("").trim().to_owned(),
            scheduled: row.get(iata).is_some_and(|c| !c.trim().is_empty()),
            lat_deg: la,
            lon_deg: lo,
            elevation_m: num(elev).filter(|e| e.abs() < 30_000.0).unwrap_or(0.0) * 0.3048,
        });
    }
    if let (count, Some(line)) = skipped {
        tracing::warn!(
            "{}: line {line}: no usable position; {count} airport row(s) like it skipped",
            path.display(),
        );
    }
    Ok(airports)
}

/// What to make.
#[derive(Clone, Debug, PartialEq)]
pub struct SynthOptions {
    /// Number of flights (all airborne at the record's middle).
    pub flights: usize,
    /// Seed of the random choices.
    pub seed: u64,
    /// Length of the record, hours.
    pub hours: f64,
    /// Time between two reports of a flight, seconds.
    pub period_s: f64,
    /// Only airports inside `[west, south, east, north]` degrees (west > east crosses the
    /// antimeridian).
    pub bounds: Option<[f64; 4]>,
    /// Unix time of the record's start.
    pub start_unix_s: f64,
}

impl Default for SynthOptions {
    fn default() -> Self {
        SynthOptions {
            flights: 1_000,
            seed: 1,
            hours: 2.0,
            period_s: 10.0,
            bounds: None,
            start_unix_s: DEFAULT_START_UNIX_S,
        }
    }
}

impl SynthOptions {
    fn check(&self) -> Result<(), SynthError> {
        let bad = |s: String| Err(SynthError::Options(s));
        if self.flights == 0 || self.flights > MAX_FLIGHTS {
            return bad(format!(
                "--flights {} must be between 1 and {MAX_FLIGHTS}",
                self.flights
            ));
        }
        if !(self.hours >= 0.25 && self.hours <= MAX_HOURS) {
            return bad(format!(
                "--hours {} must be between 0.25 and {MAX_HOURS}",
                self.hours
            ));
        }
        if !(self.period_s >= 1.0 && self.period_s <= 60.0 && self.period_s.fract() == 0.0) {
            return bad(format!(
                "--period {} must be a whole number of seconds from 1 to 60",
                self.period_s
            ));
        }
        if !(self.start_unix_s >= 0.0
            && self.start_unix_s < 7.0e9
            && self.start_unix_s.fract() == 0.0)
        {
            return bad(format!(
                "start time {} is not a plausible Unix time",
                self.start_unix_s
            ));
        }
        if let Some(b) = self.bounds {
            let ok = b.iter().all(|v| v.is_finite())
                && b[0].abs() <= 180.0
                && b[2].abs() <= 180.0
                && -90.0 <= b[1]
                && b[1] < b[3]
                && b[3] <= 90.0;
            if !ok {
                return bad(format!("--bounds {b:?} must be W,S,E,N degrees with S < N"));
            }
        }
        Ok(())
    }

    fn contains(&self, a: &Airport) -> bool {
        let Some([w, s, e, n]) = self.bounds else {
            return true;
        };
        let lon_in = if w <= e {
            (w..=e).contains(&a.lon_deg)
        } else {
            a.lon_deg >= w || a.lon_deg <= e
        };
        lon_in && (s..=n).contains(&a.lat_deg)
    }
}

/// How a kind flies.
#[derive(Clone, Copy, Debug)]
struct Performance {
    /// Distance range, metres.
    range_m: (f64, f64),
    /// Cruise levels, feet: lowest, highest, step between same-direction levels.
    levels_ft: (f64, f64, f64),
    /// Added to a VFR level (500 ft) or 0.
    level_offset_ft: f64,
    /// Cruise altitude is above the origin (helicopters) rather than above sea level.
    above_ground: bool,
    /// Take-off, cruise and approach speeds over ground, m/s.
    speeds_mps: (f64, f64, f64),
    /// Climb and descent rates, m/s.
    rates_mps: (f64, f64),
    /// Share of flights, percent.
    share: u32,
}

fn performance(kind: AircraftKind) -> Performance {
    match kind {
        AircraftKind::Light => Performance {
            range_m: (40e3, 400e3),
            levels_ft: (3_000.0, 9_000.0, 2_000.0),
            level_offset_ft: 500.0,
            above_ground: false,
            speeds_mps: (33.0, 60.0, 36.0),
            rates_mps: (3.5, 3.0),
            share: 15,
        },
        AircraftKind::Helicopter => Performance {
            range_m: (15e3, 150e3),
            levels_ft: (1_000.0, 2_000.0, 1_000.0),
            level_offset_ft: 0.0,
            above_ground: true,
            speeds_mps: (20.0, 65.0, 25.0),
            rates_mps: (4.0, 3.5),
            share: 5,
        },
        AircraftKind::NarrowBody => Performance {
            range_m: (250e3, 4_500e3),
            levels_ft: (29_000.0, 39_000.0, 2_000.0),
            level_offset_ft: 0.0,
            above_ground: false,
            speeds_mps: (80.0, 230.0, 72.0),
            rates_mps: (11.0, 8.0),
            share: 65,
        },
        AircraftKind::WideBody => Performance {
            range_m: (2_500e3, 13_000e3),
            levels_ft: (31_000.0, 41_000.0, 2_000.0),
            level_offset_ft: 0.0,
            above_ground: false,
            speeds_mps: (85.0, 250.0, 75.0),
            rates_mps: (9.0, 7.5),
            share: 15,
        },
    }
}

/// A flight's vertical and speed profile along its geodesic, in time from take-off.
#[derive(Clone, Copy, Debug, PartialEq)]
pub struct Profile {
    /// Ground distance, metres.
    pub distance_m: f64,
    /// Runway elevations at origin and destination, metres.
    pub elevations_m: (f64, f64),
    /// Cruise altitude, metres.
    pub cruise_m: f64,
    /// Take-off, cruise and approach speeds, m/s.
    pub speeds_mps: (f64, f64, f64),
    /// Durations of climb, cruise and descent, seconds.
    pub phases_s: (f64, f64, f64),
}

/// Where a flight is at one moment of its profile.
#[derive(Clone, Copy, Debug, PartialEq)]
pub struct ProfilePoint {
    /// Distance flown, metres.
    pub along_m: f64,
    /// Altitude, metres.
    pub altitude_m: f64,
    /// Speed over ground, m/s.
    pub speed_mps: f64,
    /// Vertical rate, m/s.
    pub vertical_rate_mps: f64,
}

impl Profile {
    fn new(p: &Performance, distance_m: f64, elevations_m: (f64, f64), level_m: f64) -> Profile {
        let (v0, vc, va) = p.speeds_mps;
        let (rc, rd) = p.rates_mps;
        let (ea, eb) = elevations_m;
        // Distance covered climbing to h and descending from it is linear in h; keep both
        // within 90 % of the route.
        let per_m = (v0 + vc) / 2.0 / rc + (vc + va) / 2.0 / rd;
        let fixed = (v0 + vc) / 2.0 / rc * ea + (vc + va) / 2.0 / rd * eb;
        let highest = (0.9 * distance_m + fixed) / per_m;
        let floor = ea.max(eb) + 150.0;
        let cruise_m = level_m.min(highest).max(floor);
        let climb = (cruise_m - ea) / rc;
        let descent = (cruise_m - eb) / rd;
        let (d_climb, d_descent) = ((v0 + vc) / 2.0 * climb, (vc + va) / 2.0 * descent);
        let cruise = ((distance_m - d_climb - d_descent) / vc).max(0.0);
        // Flown a hair slower, so take-off to landing is a whole number of seconds (records
        // time reports in whole seconds) and the distances stay the same.
        let total = climb + cruise + descent;
        let k = if total > 0.0 {
            total.ceil() / total
        } else {
            1.0
        };
        Profile {
            distance_m,
            elevations_m,
            cruise_m,
            speeds_mps: (v0 / k, vc / k, va / k),
            phases_s: (climb * k, cruise * k, descent * k),
        }
    }

    /// Take-off to landing, seconds (a whole number).
    pub fn duration_s(&self) -> f64 {
        self.phases_s.0 + self.phases_s.1 + self.phases_s.2
    }

    /// The state `t_s` seconds after take-off (clamped to the flight).
    pub fn at(&self, t_s: f64) -> ProfilePoint {
        let (v0, vc, va) = self.speeds_mps;
        let (tc, tcr, td) = self.phases_s;
        let (ea, eb) = self.elevations_m;
        let t = t_s.clamp(0.0, self.duration_s());
        let d_climb = (v0 + vc) / 2.0 * tc;
        let point = if t < tc {
            let f = t / tc;
            ProfilePoint {
                along_m: v0 * t + (vc - v0) * t * f / 2.0,
                altitude_m: ea + (self.cruise_m - ea) * f,
                speed_mps: v0 + (vc - v0) * f,
                vertical_rate_mps: (self.cruise_m - ea) / tc,
            }
        } else if t < tc + tcr {
            ProfilePoint {
                along_m: d_climb + vc * (t - tc),
                altitude_m: self.cruise_m,
                speed_mps: vc,
                vertical_rate_mps: 0.0,
            }
        } else {
            let tau = t - tc - tcr;
            let f = if td > 0.0 { tau / td } else { 1.0 };
            ProfilePoint {
                along_m: d_climb + vc * tcr + vc * tau - (vc - va) * tau * f / 2.0,
                altitude_m: self.cruise_m + (eb - self.cruise_m) * f,
                speed_mps: vc + (va - vc) * f,
                vertical_rate_mps: -(self.cruise_m - eb) / td.max(1e-9),
            }
        };
        ProfilePoint {
            along_m: point.along_m.min(self.distance_m),
            ..point
        }
    }
}

/// One planned flight.
#[derive(Clone, Debug, PartialEq)]
pub struct FlightPlan {
    /// Its own 24-bit address.
    pub icao24: u32,
    /// Call sign.
    pub callsign: String,
    /// Kind, and the type designator written for it.
    pub kind: AircraftKind,
    /// Index of the origin in the airports given to [`plan_flights`].
    pub origin: usize,
    /// Index of the destination.
    pub destination: usize,
    /// Take-off, seconds after the record's start (on the report grid).
    pub takeoff_s: f64,
    /// Initial course, degrees clockwise from north.
    pub course_deg: f64,
    /// The profile.
    pub profile: Profile,
}

impl FlightPlan {
    /// Landing, seconds after the record's start (a whole second).
    pub fn landing_s(&self) -> f64 {
        self.takeoff_s + self.profile.duration_s().round()
    }
}

/// SplitMix64 (Steele, Lea and Flood 2014): tiny, fast and fixed.
struct SplitMix(u64);

impl SplitMix {
    fn next(&mut self) -> u64 {
        self.0 = self.0.wrapping_add(0x9e37_79b9_7f4a_7c15);
        let mut z = self.0;
        z = (z ^ (z >> 30)).wrapping_mul(0xbf58_476d_1ce4_e5b9);
        z = (z ^ (z >> 27)).wrapping_mul(0x94d0_49bb_1331_11eb);
        z ^ (z >> 31)
    }

    /// Uniform in [0, 1).
    fn unit(&mut self) -> f64 {
        (self.next() >> 11) as f64 / (1u64 << 53) as f64
    }

    fn below(&mut self, n: usize) -> usize {
        (self.unit() * n as f64) as usize % n.max(1)
    }
}

/// Airports sorted by latitude, for range queries.
struct Index<'a> {
    airports: &'a [Airport],
    /// Indices of usable airports, by latitude.
    by_lat: Vec<usize>,
}

impl<'a> Index<'a> {
    fn new(airports: &'a [Airport], keep: impl Fn(&Airport) -> bool) -> Index<'a> {
        let mut by_lat: Vec<usize> = (0..airports.len())
            .filter(|&i| keep(&airports[i]))
            .collect();
        by_lat.sort_by(|&a, &b| airports[a].lat_deg.total_cmp(&airports[b].lat_deg));
        Index { airports, by_lat }
    }

    /// A random airport between `range_m` from `origin` (great-circle estimate), among up to
    /// 16 found scanning the latitude band from a random place.
    fn destination(&self, origin: usize, range_m: (f64, f64), rng: &mut SplitMix) -> Option<usize> {
        let o = &self.airports[origin];
        let band_deg = range_m.1 / 111_000.0 + 0.1;
        let lo = self
            .by_lat
            .partition_point(|&i| self.airports[i].lat_deg < o.lat_deg - band_deg);
        let hi = self
            .by_lat
            .partition_point(|&i| self.airports[i].lat_deg <= o.lat_deg + band_deg);
        let band = &self.by_lat[lo..hi];
        if band.is_empty() {
            return None;
        }
        let start = rng.below(band.len());
        let mut found = [0usize; 16];
        let mut n = 0;
        for k in 0..band.len() {
            let i = band[(start + k) % band.len()];
            let d = haversine_m(o, &self.airports[i]);
            if (range_m.0..=range_m.1).contains(&d) {
                found[n] = i;
                n += 1;
                if n == found.len() {
                    break;
                }
            }
        }
        (n > 0).then(|| found[rng.below(n)])
    }
}

fn haversine_m(a: &Airport, b: &Airport) -> f64 {
    let (la, lb) = (a.lat_deg.to_radians(), b.lat_deg.to_radians());
    let dlat = lb - la;
    let dlon = (b.lon_deg - a.lon_deg).to_radians();
    let h = (dlat / 2.0).sin().powi(2) + la.cos() * lb.cos() * (dlon / 2.0).sin().powi(2);
    2.0 * 6_371_008.8 * h.sqrt().min(1.0).asin()
}

/// The airline-like prefixes of synthetic call signs (not real operators' designators).
const PREFIXES: [&str; 8] = ["GLB", "SYN", "XQA", "XQB", "XQC", "XQD", "XQE", "XQF"];

/// Plans `options.flights` flights between `airports`.
pub fn plan_flights(
    airports: &[Airport],
    options: &SynthOptions,
) -> Result<Vec<FlightPlan>, SynthError> {
    options.check()?;
    let scheduled = Index::new(airports, |a| a.scheduled && options.contains(a));
    let any = Index::new(airports, |a| options.contains(a));
    let geodesic = Geodesic::wgs84();
    let length_s = options.hours * 3_600.0;
    let mut plans = Vec::with_capacity(options.flights);
    for n in 0..options.flights {
        let mut rng = SplitMix(options.seed ^ (n as u64).wrapping_mul(0xd134_2543_de82_ef95));
        let plan = plan_one(
            n,
            &mut rng,
            (&scheduled, &any),
            &geodesic,
            length_s,
            options,
        );
        plans.push(plan.ok_or_else(|| SynthError::NoRoute {
            where_: match options.bounds {
                Some(b) => format!("inside {b:?}"),
                None => format!("among {}", airports.len()),
            },
            hours: options.hours,
        })?);
    }
    Ok(plans)
}

fn pick_kind(rng: &mut SplitMix) -> AircraftKind {
    let mut roll = rng.below(100) as u32;
    for kind in AircraftKind::ALL {
        let share = performance(kind).share;
        if roll < share {
            return kind;
        }
        roll -= share;
    }
    AircraftKind::NarrowBody
}

fn plan_one(
    n: usize,
    rng: &mut SplitMix,
    (scheduled, any): (&Index, &Index),
    geodesic: &Geodesic,
    length_s: f64,
    options: &SynthOptions,
) -> Option<FlightPlan> {
    let first = pick_kind(rng);
    // The drawn kind first; where it cannot fit (a short record, small bounds), the others,
    // commonest first.
    const FALLBACK: [AircraftKind; 4] = [
        AircraftKind::NarrowBody,
        AircraftKind::Light,
        AircraftKind::Helicopter,
        AircraftKind::WideBody,
    ];
    let kinds = std::iter::once(first).chain(FALLBACK.into_iter().filter(|&k| k != first));
    for kind in kinds {
        let index = match kind {
            AircraftKind::Light | AircraftKind::Helicopter => any,
            _ => scheduled,
        };
        if index.by_lat.is_empty() {
            continue;
        }
        let perf = performance(kind);
        for _ in 0..24 {
            let origin = index.by_lat[rng.below(index.by_lat.len())];
            let Some(destination) = index.destination(origin, perf.range_m, rng) else {
                continue;
            };
            let (a, b) = (&index.airports[origin], &index.airports[destination]);
            let (distance_m, course_deg, _, _): (f64, f64, f64, f64) =
                geodesic.inverse(a.lat_deg, a.lon_deg, b.lat_deg, b.lon_deg);
            let level_m = cruise_level_m(&perf, course_deg, a.elevation_m, rng);
            let profile = Profile::new(&perf, distance_m, (a.elevation_m, b.elevation_m), level_m);
            let duration = profile.duration_s().ceil();
            if !(duration > 120.0 && duration < length_s * 0.9) {
                continue;
            }
            return Some(FlightPlan {
                icao24: address(n),
                callsign: callsign(n, kind),
                kind,
                origin,
                destination,
                takeoff_s: takeoff_s(duration, length_s, options.period_s, rng),
                course_deg,
                profile,
            });
        }
    }
    None
}

/// A take-off on the report grid such that the flight is airborne at the record's middle
/// (at least a minute after take-off and before landing) and inside the record.
fn takeoff_s(duration_s: f64, length_s: f64, period_s: f64, rng: &mut SplitMix) -> f64 {
    let middle = length_s / 2.0;
    let margin = 60.0_f64.min(duration_s / 4.0);
    let earliest = (middle - duration_s + margin).max(0.0);
    let latest = (middle - margin).min(length_s - duration_s - period_s);
    let t = earliest + (latest - earliest).max(0.0) * rng.unit();
    let on_grid = (t / period_s).ceil() * period_s;
    if on_grid > latest {
        (t / period_s).floor() * period_s
    } else {
        on_grid
    }
}

fn cruise_level_m(perf: &Performance, course_deg: f64, ground_m: f64, rng: &mut SplitMix) -> f64 {
    let (lowest, highest, step) = perf.levels_ft;
    // Eastbound flies the odd thousands, westbound the even ones (lowest is odd), never above
    // the kind's highest level.
    let eastbound = course_deg.rem_euclid(360.0) < 180.0;
    let first = if eastbound {
        lowest
    } else {
        lowest + step / 2.0
    };
    let count = ((highest - first) / step).floor() as usize + 1;
    let feet = first + step * rng.below(count) as f64 + perf.level_offset_ft;
    let metres = feet * 0.3048;
    if perf.above_ground {
        ground_m + metres
    } else {
        metres
    }
}

/// Distinct 24-bit addresses: an odd multiplier is a bijection modulo 2^24.
fn address(n: usize) -> u32 {
    ((n as u64).wrapping_mul(0x5b_d1e9).wrapping_add(0x30_0000) & 0xff_ffff) as u32
}

fn callsign(n: usize, kind: AircraftKind) -> String {
    match kind {
        AircraftKind::Light | AircraftKind::Helicopter => {
            // Registration-like: a made-up nationality mark and four letters.
            let mut s = String::from("XZ");
            let mut v = n;
            for _ in 0..4 {
                s.push(char::from(b'A' + (v % 26) as u8));
                v /= 26;
            }
            s
        }
        _ => format!("{}{}", PREFIXES[n % PREFIXES.len()], n / PREFIXES.len() + 1),
    }
}

/// The header [`write_record`] writes.
pub const HEADER: &str = "time,icao24,lat,lon,velocity,heading,vertrate,callsign,onground,alert,spi,squawk,baroaltitude,geoaltitude,lastposupdate,lastcontact,typecode";

/// Writes the record of `plans` (rows in time order) and returns how many rows it wrote.
pub fn write_record(
    airports: &[Airport],
    plans: &[FlightPlan],
    options: &SynthOptions,
    out: impl Write,
) -> Result<u64, SynthError> {
    let geodesic = Geodesic::wgs84();
    let mut out = std::io::BufWriter::with_capacity(1 << 20, out);
    writeln!(out, "{HEADER}")?;
    let mut order: Vec<usize> = (0..plans.len()).collect();
    order.sort_by(|&a, &b| plans[a].takeoff_s.total_cmp(&plans[b].takeoff_s));
    let mut next = 0;
    let mut active: Vec<usize> = Vec::new();
    let mut landed: Vec<usize> = Vec::new();
    let mut rows = 0u64;
    let steps = (options.hours * 3_600.0 / options.period_s).ceil() as u64;
    for step in 0..=steps {
        let t = step as f64 * options.period_s;
        while next < order.len() && plans[order[next]].takeoff_s <= t {
            active.push(order[next]);
            next += 1;
        }
        // Landings since the last step first (their times lie before this step's).
        landed.clear();
        active.retain(|&i| {
            let flying = plans[i].landing_s() > t;
            if !flying {
                landed.push(i);
            }
            flying
        });
        for (&i, at) in landed
            .iter()
            .map(|i| (i, plans[*i].landing_s()))
            .chain(active.iter().map(|i| (i, t)))
        {
            Row::of(&plans[i], at, &geodesic, airports).write(&mut out, options.start_unix_s)?;
            rows += 1;
        }
    }
    out.flush()?;
    Ok(rows)
}

/// One report of one planned flight.
struct Row<'p> {
    plan: &'p FlightPlan,
    time_s: f64,
    lat_deg: f64,
    lon_deg: f64,
    heading_deg: f64,
    state: ProfilePoint,
    on_ground: bool,
}

impl<'p> Row<'p> {
    fn of(plan: &'p FlightPlan, time_s: f64, geodesic: &Geodesic, airports: &[Airport]) -> Row<'p> {
        let origin = &airports[plan.origin];
        let since = time_s - plan.takeoff_s;
        let landed = time_s >= plan.landing_s();
        let state = if landed {
            plan.profile.at(f64::INFINITY)
        } else {
            plan.profile.at(since)
        };
        let (lat_deg, lon_deg, heading_deg) = if landed {
            // Exactly on the destination's runway.
            let d = &airports[plan.destination];
            let (_, _, azi2, _): (f64, f64, f64, f64) =
                geodesic.inverse(origin.lat_deg, origin.lon_deg, d.lat_deg, d.lon_deg);
            (d.lat_deg, d.lon_deg, azi2)
        } else {
            let (lat, lon, azi): (f64, f64, f64) = geodesic.direct(
                origin.lat_deg,
                origin.lon_deg,
                plan.course_deg,
                state.along_m,
            );
            (lat, lon, azi)
        };
        Row {
            plan,
            time_s,
            lat_deg,
            lon_deg,
            heading_deg: heading_deg.rem_euclid(360.0),
            state,
            on_ground: since <= 0.0 || landed,
        }
    }

    fn write(&self, out: &mut impl Write, start_unix_s: f64) -> std::io::Result<()> {
        let t = start_unix_s + self.time_s;
        let p = self.plan;
        let speed = self.state.speed_mps;
        let rate = if self.on_ground {
            0.0
        } else {
            self.state.vertical_rate_mps
        };
        // Four octal digits, as transponder codes are.
        let squawk = format!("{:04o}", p.icao24 % 0o10000);
        writeln!(
            out,
            "{t:.0},{:06x},{:.6},{:.6},{speed:.2},{:.2},{rate:.2},{},{},false,false,{squawk},{alt:.2},{alt:.2},{t:.0},{t:.0},{}",
            p.icao24,
            self.lat_deg,
            self.lon_deg,
            self.heading_deg,
            p.callsign,
            self.on_ground,
            p.kind.typical_typecode(),
            alt = self.state.altitude_m,
        )
    }
}

#[cfg(test)]
mod tests;
