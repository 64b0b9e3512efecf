use super::*;
use crate::fleet::{Fleet, FleetOptions};

fn report(t: f64, lon: f64, lat: f64, alt: f64) -> Report {
    Report {
        time_s: t,
        lat_deg: lat,
        lon_deg: lon,
        altitude_m: alt,
        velocity_mps: 200.0,
        heading_deg: 90.0,
        vertical_rate_mps: 0.0,
        on_ground: false,
    }
}

fn track(icao24: u32, callsign: &str, reports: Vec<Report>) -> Track {
    Track {
        icao24,
        callsign: callsign.into(),
        typecode: String::new(),
        reports,
    }
}

/// Where the record itself puts a track at `t`: straight-line interpolation between the two
/// reports around it (the independent expectation the fleet must meet).
fn expected(track: &Track, t: f64) -> Option<[f64; 3]> {
    let r = &track.reports;
    if t < r.first()?.time_s || t > r.last()?.time_s {
        return None;
    }
    let k = r.partition_point(|x| x.time_s <= t);
    if k == r.len() {
        let l = r.last()?;
        return Some([l.lon_deg, l.lat_deg, l.altitude_m]);
    }
    let (a, b) = (&r[k - 1], &r[k]);
    let f = (t - a.time_s) / (b.time_s - a.time_s);
    let dlon = (b.lon_deg - a.lon_deg + 540.0).rem_euclid(360.0) - 180.0;
    let lon = (a.lon_deg + dlon * f + 540.0).rem_euclid(360.0) - 180.0;
    Some([
        lon,
        a.lat_deg + (b.lat_deg - a.lat_deg) * f,
        a.altitude_m + (b.altitude_m - a.altitude_m) * f,
    ])
}

fn play(replay: &mut Replay, fleet: &mut Fleet, t: f64, batch: &mut Batch) -> Step {
    let step = replay.advance_to(t, batch);
    if step == Step::Reset {
        fleet.clear();
    }
    fleet.apply(batch).expect("apply");
    step
}

fn small_record() -> Record {
    Record {
        tracks: vec![
            track(
                0xabc123,
                "SWR1",
                (0..30)
                    .map(|k| {
                        let t = 1000.0 + f64::from(k) * 7.0 + f64::from(k % 3);
                        report(
                            t,
                            8.0 + f64::from(k) * 0.01,
                            47.0,
                            3000.0 + f64::from(k) * 50.0,
                        )
                    })
                    .collect(),
            ),
            // The same aircraft again under another call sign, right after.
            track(
                0xabc123,
                "SWR2",
                (0..10)
                    .map(|k| {
                        report(
                            1215.0 + f64::from(k) * 5.0,
                            9.0,
                            47.0 + f64::from(k) * 0.01,
                            1000.0,
                        )
                    })
                    .collect(),
            ),
            // Across the antimeridian.
            track(
                0x000001,
                "",
                (0..10)
                    .map(|k| {
                        report(
                            1100.0 + f64::from(k) * 10.0,
                            179.97 + f64::from(k) * 0.01,
                            -10.0,
                            9000.0,
                        )
                    })
                    .map(|mut r| {
                        r.lon_deg = (r.lon_deg + 540.0).rem_euclid(360.0) - 180.0;
                        r
                    })
                    .collect(),
            ),
        ],
        skipped: Vec::new(),
        rows: 0,
    }
}

fn check_everyone(replay: &Replay, fleet: &Fleet, t: f64) -> usize {
    let mut seen = 0;
    for (i, tr) in replay.record().tracks.iter().enumerate() {
        let id = Replay::id_of(i, tr.icao24);
        match expected(tr, t) {
            Some(want) => {
                let (got, _) = fleet
                    .state_of(id, t)
                    .unwrap_or_else(|| panic!("track {i} missing at {t}"));
                for c in 0..3 {
                    let tol = if c == 2 { 1e-6 } else { 1e-9 };
                    assert!(
                        (got[c] - want[c]).abs() < tol,
                        "track {i} at {t}: {got:?} vs {want:?}"
                    );
                }
                seen += 1;
            }
            None => {
                let last = tr.reports.last().map_or(0.0, |r| r.time_s);
                let first = tr.reports[0].time_s;
                if t < first || t > last + replay.options().linger_s {
                    assert!(!fleet.contains(id), "track {i} still there at {t}");
                }
            }
        }
    }
    seen
}

#[test]
fn every_aircraft_is_where_the_record_interpolates_it_at_any_step() {
    for step_s in [0.4, 1.0 / 30.0 * 720.0, 37.0] {
        let mut replay = Replay::new(small_record(), ReplayOptions::default());
        let mut fleet = Fleet::new(FleetOptions::default());
        let mut batch = Batch::default();
        let mut t = 990.0;
        let mut resets = 0;
        let mut seen = 0;
        while t < 1300.0 {
            if play(&mut replay, &mut fleet, t, &mut batch) == Step::Reset {
                resets += 1;
            }
            seen += check_everyone(&replay, &fleet, t);
            t += step_s;
        }
        assert_eq!(resets, 1, "only the first step seeks");
        assert!(seen > 5, "{seen}");
        // Every flight ended and was removed.
        play(&mut replay, &mut fleet, 1400.0, &mut batch);
        assert!(fleet.is_empty());
        assert_eq!(replay.live_flights(), 0);
    }
}

#[test]
fn seeking_anywhere_gives_the_state_stepping_there_gives() {
    let options = ReplayOptions {
        jump_s: 60.0,
        ..ReplayOptions::default()
    };
    let mut replay = Replay::new(small_record(), options);
    let mut fleet = Fleet::new(FleetOptions::default());
    let mut batch = Batch::default();
    for t in [1150.0, 1010.5, 1230.0, 1005.0, 1500.0, 1199.0, 1213.0] {
        assert_eq!(play(&mut replay, &mut fleet, t, &mut batch), Step::Reset);
        check_everyone(&replay, &fleet, t);
        // And onwards from there by small steps.
        for k in 1..20 {
            let t = t + f64::from(k) * 1.3;
            assert_eq!(play(&mut replay, &mut fleet, t, &mut batch), Step::Advance);
            check_everyone(&replay, &fleet, t);
        }
    }
    // After a seek, the trail holds the history before the moment.
    play(&mut replay, &mut fleet, 1150.0, &mut batch);
    let id = Replay::id_of(0, 0xabc123);
    let mut sampled = crate::Sampled::default();
    fleet.sample(1150.0, &mut sampled);
    let row = sampled.find(id).expect("live");
    let mut trail = Vec::new();
    fleet.trail(
        sampled.slots[row],
        1150.0,
        sampled.positions[row],
        &mut trail,
    );
    assert!(trail.len() >= 10, "{}", trail.len());
    assert!(trail[0].time_s <= 1010.0);
}

#[test]
fn the_same_aircraft_twice_is_two_objects_and_ids_give_the_address_back() {
    let mut replay = Replay::new(small_record(), ReplayOptions::default());
    let mut fleet = Fleet::new(FleetOptions::default());
    let mut batch = Batch::default();
    // The first flight's last report is at 1000 + 29 * 7 + 2 = 1205, so it lingers until
    // 1215, when the second flight's first report comes.
    let (a, b) = (Replay::id_of(0, 0xabc123), Replay::id_of(1, 0xabc123));
    assert_ne!(a, b);
    play(&mut replay, &mut fleet, 1200.0, &mut batch);
    play(&mut replay, &mut fleet, 1214.0, &mut batch);
    assert!(fleet.contains(a) && !fleet.contains(b));
    play(&mut replay, &mut fleet, 1215.0, &mut batch);
    // The first one's removal does not end the second.
    assert!(!fleet.contains(a) && fleet.contains(b));
    assert_eq!(Replay::icao24_of(b), 0xabc123);
    assert_eq!(
        replay.track_of(b).map(|t| t.callsign.as_str()),
        Some("SWR2")
    );
    assert!(replay.track_of(Replay::id_of(1, 0x123456)).is_none());
}

#[test]
fn a_step_hands_over_only_what_became_due() {
    let mut replay = Replay::new(small_record(), ReplayOptions::default());
    let mut batch = Batch::default();
    replay.advance_to(1120.0, &mut batch);
    // Small steps between reports hand over nothing.
    replay.advance_to(1120.1, &mut batch);
    assert!(batch.is_empty());
    // Reaching the next report of flight 0 (at 1121) hands over the one after it alone.
    replay.advance_to(1121.0, &mut batch);
    assert_eq!(batch.len(), 1);
    assert_eq!(batch.times_s[0], 1126.0);
}

#[test]
fn altitude_colours_ramp_from_orange_to_violet() {
    assert_eq!(altitude_colour(-50.0), [255, 140, 0, 255]);
    assert_eq!(altitude_colour(f64::NAN), [255, 140, 0, 255]);
    assert_eq!(altitude_colour(20_000.0), [190, 90, 255, 255]);
    let mid = altitude_colour(5_500.0);
    assert!(mid[1] > 200 && mid[2] > 150, "{mid:?}");
}

/// The real Swiss day at 720x (24 s of record per frame at 30 fps): every live aircraft at
/// every frame is where the record interpolates it.
#[test]
fn the_swiss_record_replays_at_720x_with_every_aircraft_in_place() {
    let path = globus_test_support::shared_data("traffic-switzerland-2018-08-01.csv.gz");
    let record = crate::read_record(&path).expect("record");
    let (start, end) = record.time_span_s().expect("span");
    let mut replay = Replay::new(record, ReplayOptions::default());
    let mut fleet = Fleet::new(FleetOptions::default());
    let mut batch = Batch::default();
    let (mut t, mut checked, mut most) = (start, 0usize, 0usize);
    while t <= end + 60.0 {
        play(&mut replay, &mut fleet, t, &mut batch);
        checked += check_everyone(&replay, &fleet, t);
        most = most.max(fleet.len());
        t += 24.0;
    }
    assert!(fleet.is_empty());
    assert!(checked > 50_000, "{checked}");
    assert!((40..=60).contains(&most), "{most}");
}
