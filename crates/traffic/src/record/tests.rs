use super::*;
use std::io::Write;

const HEADER: &str = "time,icao24,lat,lon,velocity,heading,vertrate,callsign,onground,alert,spi,squawk,baroaltitude,geoaltitude,lastposupdate,lastcontact";

fn row(t: u32, id: &str, lat: f64, lon: f64, alt: &str) -> String {
    format!("{t},{id},{lat},{lon},230.5,90.0,0.0,SWR12,,,,,{alt},,{t},{t}")
}

fn read_text(text: &str) -> Result<Record, RecordError> {
    read_record_from(text.as_bytes(), Path::new("test.csv"))
}

fn gzip(bytes: &[u8]) -> Vec<u8> {
    let mut enc = flate2::write::GzEncoder::new(Vec::new(), flate2::Compression::fast());
    enc.write_all(bytes).expect("gzip in memory");
    enc.finish().expect("gzip in memory")
}

#[test]
fn the_swiss_record_reads_whole_into_its_flights() {
    let path = globus_test_support::shared_data("traffic-switzerland-2018-08-01.csv.gz");
    let record = read_record(&path).expect("the Swiss record");
    assert_eq!(record.rows, 139_098);
    assert_eq!(record.reports(), 139_098, "skipped: {:?}", record.skipped);
    assert!(record.skipped.is_empty());
    // 1,243 (icao24, callsign) pairs; one of them is silent for over 30 minutes and becomes
    // two flights (counted independently with Python's csv module).
    assert_eq!(record.tracks.len(), 1_244);
    let aircraft: std::collections::HashSet<u32> = record.tracks.iter().map(|t| t.icao24).collect();
    assert_eq!(aircraft.len(), 842);
    assert_eq!(
        record.time_span_s(),
        Some((1_533_099_600.0, 1_533_160_790.0))
    );
    // The first row of the file.
    let first = record.tracks[0].clone();
    assert_eq!(first.icao24_hex(), "4067f2");
    assert_eq!(first.callsign, "TOM2XE");
    let r = first.reports[0];
    assert_eq!(
        (r.time_s, r.lat_deg, r.lon_deg),
        (1_533_099_600.0, 46.679232, 10.202179)
    );
    assert_eq!(r.altitude_m, 11_582.4);
    assert_eq!((r.velocity_mps, r.heading_deg), (225.37, 292.41));
    // The same aircraft flies again later as TOM32T.
    let names: Vec<&str> = record
        .flights_of(0x4067f2)
        .map(|t| t.callsign.as_str())
        .collect();
    assert_eq!(names, ["TOM2XE", "TOM32T"]);
    for t in &record.tracks {
        assert!(t.reports.windows(2).all(|w| w[0].time_s < w[1].time_s));
    }
}

#[test]
fn every_kind_of_bad_row_is_counted_and_skipped_and_the_rest_plays() {
    let lines = [
        HEADER.to_string(),
        row(100, "4b1805", 46.0, 7.0, "10000"),     // 2: good
        "110,4b1805".to_string(),                   // 3: short row
        row(120, "4b1805", 46.1, 7.1, "abc"),       // 4: unparsable altitude
        row(130, "4b1805", f64::NAN, 7.1, "10000"), // 5: NaN latitude
        row(140, "4b1805", 46.2, 181.0, "10000"),   // 6: longitude out of range
        row(150, "4b1805", 46.3, 7.3, "10000"),     // 7: good
        row(145, "4b1805", 46.25, 7.25, "10000"),   // 8: backwards
        row(150, "4b1805", 46.3, 7.3, "10000"),     // 9: duplicate
        row(160, "zzzzzz", 46.0, 7.0, "10000"),     // 10: bad address
        row(160, "4b1805", 46.4, 7.4, ""),          // 11: no altitude in the air
        row(170, "4b1805", 46.5, 7.5, "1e9"),       // 12: absurd altitude
        row(170, "abc123", -33.9, 151.2, "inf"),    // 13: infinite altitude
        row(180, "4b1805", 46.6, 7.6, "10100"),     // 14: good
        row(181, "4b1805", 46.6, 7.6, "10100").replace("230.5", "-5"), // 15: negative speed
        "190,4b1805,46.7,7.7,,,,SWR12,true,,,,,,,".to_string(), // 16: good, on the ground
    ];
    let record = read_text(&lines.join("\n")).expect("a record with bad rows");
    assert_eq!(record.rows, 15);
    let track = &record.tracks[0];
    let times: Vec<f64> = track.reports.iter().map(|r| r.time_s).collect();
    assert_eq!(times, [100.0, 150.0, 180.0, 190.0]);
    assert!(track.reports[3].on_ground && track.reports[3].altitude_m.is_nan());
    assert!(track.reports[3].velocity_mps.is_nan());
    let got: Vec<(SkipKind, u64, u64)> = record
        .skipped
        .iter()
        .map(|s| (s.kind, s.count, s.first_line))
        .collect();
    assert_eq!(
        got,
        [
            (SkipKind::MissingColumn, 2, 3),
            (SkipKind::Unparsable, 2, 4),
            (SkipKind::OutOfRange, 5, 5),
            (SkipKind::TimeBackwards, 1, 8),
            (SkipKind::Duplicate, 1, 9),
        ]
    );
    let details: Vec<&str> = record.skipped.iter().map(|s| s.detail.as_str()).collect();
    assert_eq!(details[1], "baroaltitude \"abc\"");
    assert_eq!(details[2], "lat NaN outside -90..90");
    assert!(
        details[3].contains("4b1805 at 145 after 150"),
        "{}",
        details[3]
    );
}

#[test]
fn columns_are_found_by_name_in_any_order() {
    let text = "lon,geoaltitude,lat,extra,icao24,time\n7.5,3000,46.5,x,ABC123,1000\n";
    let record = read_text(text).expect("reordered columns");
    let r = record.tracks[0].reports[0];
    assert_eq!(record.tracks[0].icao24, 0xabc123);
    assert_eq!((r.lat_deg, r.lon_deg, r.altitude_m), (46.5, 7.5, 3000.0));
    assert!(r.velocity_mps.is_nan() && r.heading_deg.is_nan());
    // Geometric altitude is preferred to barometric when both are given.
    let text = format!("{HEADER}\n1,a,1,1,,,,,,,,,900,950,,\n2,a,1,1,,,,,,,,,900,,,\n");
    let record = read_text(&text).expect("two altitudes");
    let alts: Vec<f64> = record.tracks[0]
        .reports
        .iter()
        .map(|r| r.altitude_m)
        .collect();
    assert_eq!(alts, [950.0, 900.0]);
}

#[test]
fn stale_positions_are_timed_by_their_update_and_repeats_are_duplicates() {
    let text = format!(
        "{HEADER}\n100,a,46,7,200,90,0,X,,,,,9000,,100,100\n110,a,46,7,200,90,0,X,,,,,9000,,100,110\n120,a,46.1,7.1,200,90,0,X,,,,,9000,,118,120\n"
    );
    let record = read_text(&text).expect("stale rows");
    let times: Vec<f64> = record.tracks[0].reports.iter().map(|r| r.time_s).collect();
    assert_eq!(times, [100.0, 118.0]);
    assert_eq!(record.skipped_of(SkipKind::Duplicate), 1);
}

#[test]
fn a_truncated_gzip_keeps_every_complete_row_before_the_break() {
    let mut text = HEADER.to_string();
    for i in 0..5_000u32 {
        let lat = 45.0 + f64::from(i) * 1e-4;
        text.push('\n');
        text.push_str(&row(1_000 + i, "4b1805", lat, 7.0, "10000"));
    }
    let whole = gzip(text.as_bytes());
    let full = read_record_from(whole.as_slice(), Path::new("w.csv.gz")).expect("whole gzip");
    assert_eq!(full.reports(), 5_000);
    assert!(full.skipped.is_empty());

    let cut = &whole[..whole.len() / 2];
    let record = read_record_from(cut, Path::new("cut.csv.gz")).expect("a truncated gzip plays");
    let kept = record.reports();
    assert!(kept > 1_000 && kept < 5_000, "kept {kept}");
    assert_eq!(record.skipped_of(SkipKind::TruncatedGzip), 1);
    assert_eq!(record.skipped[0].first_line, kept as u64 + 2);
    // Every kept report is exactly the original one.
    assert_eq!(record.tracks[0].reports[..], full.tracks[0].reports[..kept]);
    // The same cut through a file on disk.
    let dir = globus_test_support::output_dir("traffic_truncated_gzip");
    let path = dir.join("cut.csv.gz");
    std::fs::write(&path, cut).expect("write the cut file");
    assert_eq!(read_record(&path).expect("from disk").reports(), kept);
}

#[test]
fn a_file_that_is_not_a_state_vector_csv_is_one_clear_error() {
    let cases: [(&str, &[u8], &str); 5] = [
        ("empty", b"", "the file is empty"),
        (
            "geojson",
            b"{\"type\": \"FeatureCollection\", \"features\": []}",
            "no time column",
        ),
        (
            "binary",
            &[0u8, 159, 146, 150, 255, 1, 2, 3],
            "no time column",
        ),
        (
            "no altitude",
            b"time,icao24,lat,lon\n1,a,1,1\n",
            "no baroaltitude or geoaltitude",
        ),
        (
            "corrupt gzip",
            &[0x1f, 0x8b, 8, 0, 0, 0, 0, 0, 0, 3, 0xff, 0xff, 0xff],
            "header",
        ),
    ];
    for (what, bytes, needle) in cases {
        let err = read_record_from(bytes, Path::new("bad.csv")).expect_err(what);
        let text = err.to_string();
        assert!(
            matches!(err, RecordError::NotStateVectors { .. }),
            "{what}: {text}"
        );
        assert!(
            text.starts_with("bad.csv: not an OpenSky state-vector CSV"),
            "{what}: {text}"
        );
        assert!(text.contains(needle), "{what}: {text}");
    }
    let missing = read_record(Path::new("/nonexistent/traffic.csv")).expect_err("missing file");
    assert!(missing.to_string().contains("/nonexistent/traffic.csv"));
}

#[test]
fn arbitrary_bytes_never_panic() {
    let report = globus_test_support::fuzz::run("traffic-record", |bytes| {
        read_record_from(bytes, Path::new("fuzz.csv")).is_ok()
    });
    assert!(report.cases >= 100, "{report:?}");
}
