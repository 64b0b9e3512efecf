use super::*;
use crate::record::{Track, read_record_from};
use std::collections::HashMap;
use std::sync::OnceLock;

fn airports() -> &'static [Airport] {
    static AIRPORTS: OnceLock<Vec<Airport>> = OnceLock::new();
    AIRPORTS.get_or_init(|| {
        read_airports(&globus_test_support::shared_data("airports.csv")).expect("airports.csv")
    })
}

fn make(options: &SynthOptions) -> (Vec<FlightPlan>, Vec<u8>) {
    let plans = plan_flights(airports(), options).expect("plans");
    let mut bytes = Vec::new();
    write_record(airports(), &plans, options, &mut bytes).expect("write in memory");
    (plans, bytes)
}

fn geodesic_m(a: (f64, f64), b: (f64, f64)) -> f64 {
    let (s12, _, _, _): (f64, f64, f64, f64) = Geodesic::wgs84().inverse(a.0, a.1, b.0, b.1);
    s12
}

#[test]
fn airports_are_read_with_their_elevation_in_metres() {
    let all = airports();
    assert_eq!(all.len(), 28_298);
    assert_eq!(all.iter().filter(|a| a.scheduled).count(), 7_884);
    let zurich = all.iter().find(|a| a.icao == "LSZH").expect("LSZH");
    assert_eq!((zurich.lat_deg, zurich.lon_deg), (47.4647, 8.54917));
    assert!((zurich.elevation_m - 1_416.0 * 0.3048).abs() < 1e-9);
    assert!(zurich.scheduled);
}

#[test]
fn a_seed_gives_the_same_record_and_another_seed_another() {
    let options = SynthOptions {
        flights: 300,
        seed: 7,
        ..SynthOptions::default()
    };
    let (_, a) = make(&options);
    let (_, b) = make(&options);
    assert!(a == b, "same seed, different bytes");
    let (_, c) = make(&SynthOptions { seed: 8, ..options });
    assert!(a != c);
}

#[test]
fn every_flight_flies_from_its_origin_to_its_destination_and_all_are_airborne_at_the_middle() {
    let options = SynthOptions {
        flights: 800,
        seed: 3,
        ..SynthOptions::default()
    };
    let (plans, bytes) = make(&options);
    let record = read_record_from(bytes.as_slice(), Path::new("synth.csv")).expect("read back");
    assert!(record.skipped.is_empty(), "{:?}", record.skipped);
    assert_eq!(record.tracks.len(), plans.len());
    let tracks: HashMap<u32, &Track> = record.tracks.iter().map(|t| (t.icao24, t)).collect();
    let middle = options.start_unix_s + options.hours * 1_800.0;
    let end = options.start_unix_s + options.hours * 3_600.0;
    let mut kinds: HashMap<AircraftKind, usize> = HashMap::new();
    let mut levels_checked = 0;
    for plan in &plans {
        *kinds.entry(plan.kind).or_default() += 1;
        let track = tracks[&plan.icao24];
        assert_eq!(track.callsign, plan.callsign);
        assert_eq!(AircraftKind::from_typecode(&track.typecode), plan.kind);
        let (o, d) = (&airports()[plan.origin], &airports()[plan.destination]);
        let (first, last) = (track.reports[0], track.reports[track.reports.len() - 1]);
        // On the ground at both airports (positions written to 1e-6 degrees: 0.11 m).
        assert!(first.on_ground && last.on_ground, "{}", plan.callsign);
        assert!(geodesic_m((first.lat_deg, first.lon_deg), (o.lat_deg, o.lon_deg)) < 0.2);
        assert!(geodesic_m((last.lat_deg, last.lon_deg), (d.lat_deg, d.lon_deg)) < 0.2);
        assert!((first.altitude_m - o.elevation_m).abs() < 0.01);
        assert!((last.altitude_m - d.elevation_m).abs() < 0.01);
        assert!(first.time_s >= options.start_unix_s && last.time_s <= end);
        assert!(first.time_s < middle - 30.0 && last.time_s > middle + 30.0);
        levels_checked += usize::from(check_flight(plan, track, options.period_s));
    }
    assert!(
        levels_checked > 200,
        "{levels_checked} cruise levels checked"
    );
    let share = |k| kinds.get(&k).copied().unwrap_or(0) as f64 / plans.len() as f64;
    // Wide-bodies whose routes do not fit the record fly as narrow-bodies: 65 % + 15 %.
    let airliners = share(AircraftKind::NarrowBody) + share(AircraftKind::WideBody);
    assert!((airliners - 0.80).abs() < 0.05, "{kinds:?}");
    assert!(share(AircraftKind::Light) > 0.08 && share(AircraftKind::Helicopter) > 0.02);
    // A two-hour record only fits wide-bodies' shortest routes: some, but fewer than drawn.
    assert!(share(AircraftKind::WideBody) < 0.16, "{kinds:?}");
}

/// Altitudes, speeds, rates, spacing and headings of one flight are those of its kind;
/// returns whether its cruise level was checked against the semicircular rule.
fn check_flight(plan: &FlightPlan, track: &Track, period_s: f64) -> bool {
    let (ceiling_m, speed_mps) = match plan.kind {
        AircraftKind::Light => (10_600.0 * 0.3048, 15.0..=70.0),
        AircraftKind::Helicopter => (5_000.0, 15.0..=70.0),
        AircraftKind::NarrowBody => (12_000.0, 60.0..=240.0),
        AircraftKind::WideBody => (12_600.0, 60.0..=260.0),
    };
    let highest = track
        .reports
        .iter()
        .map(|r| r.altitude_m)
        .fold(f64::MIN, f64::max);
    assert!(highest <= ceiling_m, "{} at {highest} m", plan.callsign);
    let cruise_ft = plan.profile.cruise_m / 0.3048;
    let thousands = (cruise_ft / 1_000.0).round() as i64;
    let is_level = (cruise_ft - thousands as f64 * 1_000.0).abs() < 0.01;
    if plan.kind == AircraftKind::NarrowBody && is_level {
        // A cruise level (not one lowered for a short route) obeys the semicircular rule.
        let eastbound = plan.course_deg.rem_euclid(360.0) < 180.0;
        assert_eq!(
            thousands % 2 == 1,
            eastbound,
            "{} at FL{}",
            plan.callsign,
            thousands * 10
        );
    }
    for w in track.reports.windows(2) {
        let (a, b) = (w[0], w[1]);
        assert!(
            speed_mps.contains(&f64::from(a.velocity_mps)),
            "{} {a:?}",
            plan.callsign
        );
        assert!(a.vertical_rate_mps.abs() <= 12.0);
        let dt = b.time_s - a.time_s;
        assert!(dt > 0.0 && dt <= period_s);
        // Distance flown agrees with the mean of the two speeds (within 2 %, and 1 m for
        // rounding of the written positions).
        let flown = geodesic_m((a.lat_deg, a.lon_deg), (b.lat_deg, b.lon_deg));
        let expected = f64::from(a.velocity_mps + b.velocity_mps) / 2.0 * dt;
        assert!(
            (flown - expected).abs() <= 0.02 * expected + 1.0,
            "{} flew {flown} m, expected {expected}",
            plan.callsign
        );
        let climbed = b.altitude_m - a.altitude_m;
        assert!(climbed.abs() <= 12.0 * dt + 0.02);
        // The heading is the track between reports.
        let (_, azi, _, _): (f64, f64, f64, f64) =
            Geodesic::wgs84().inverse(a.lat_deg, a.lon_deg, b.lat_deg, b.lon_deg);
        if flown > 100.0 {
            let off = (azi - f64::from(a.heading_deg) + 540.0).rem_euclid(360.0) - 180.0;
            assert!(
                off.abs() < 1.0,
                "{}: heading {} vs track {azi}",
                plan.callsign,
                a.heading_deg
            );
        }
    }
    is_level && plan.kind == AircraftKind::NarrowBody
}

#[test]
fn bounds_keep_every_airport_inside_them() {
    let europe = [-12.0, 35.0, 35.0, 62.0];
    let options = SynthOptions {
        flights: 200,
        bounds: Some(europe),
        ..SynthOptions::default()
    };
    let plans = plan_flights(airports(), &options).expect("European flights");
    for p in &plans {
        for a in [&airports()[p.origin], &airports()[p.destination]] {
            assert!(options.contains(a), "{} outside", a.icao);
        }
    }
}

#[test]
fn bad_options_are_refused_with_what_is_wrong() {
    let base = SynthOptions::default();
    let cases = [
        (
            SynthOptions {
                flights: 0,
                ..base.clone()
            },
            "--flights 0",
        ),
        (
            SynthOptions {
                flights: 4_000_000_000,
                ..base.clone()
            },
            "--flights 4000000000",
        ),
        (
            SynthOptions {
                hours: f64::NAN,
                ..base.clone()
            },
            "--hours NaN",
        ),
        (
            SynthOptions {
                hours: 1e300,
                ..base.clone()
            },
            "--hours",
        ),
        (
            SynthOptions {
                period_s: 0.5,
                ..base.clone()
            },
            "--period 0.5",
        ),
        (
            SynthOptions {
                bounds: Some([10.0, 50.0, 11.0, 40.0]),
                ..base.clone()
            },
            "--bounds",
        ),
    ];
    for (options, needle) in cases {
        let err = plan_flights(airports(), &options)
            .expect_err(needle)
            .to_string();
        assert!(err.contains(needle), "{err}");
    }
    // A patch of sea: no airports, one clear error.
    let sea = SynthOptions {
        bounds: Some([-30.0, 30.0, -29.5, 30.5]),
        ..base
    };
    let err = plan_flights(airports(), &sea).expect_err("sea").to_string();
    assert!(err.starts_with("no pair of airports inside"), "{err}");
}
