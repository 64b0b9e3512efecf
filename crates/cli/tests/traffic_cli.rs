//! `globus render --traffic`, `globus bench --traffic` and `globus traffic`: the Swiss record
//! drawn at a moment with as many aircraft as the record has in the air then (counted here
//! from the raw CSV), synthetic records made and summarised, and every bad input one line.

mod common;

use std::collections::HashMap;
use std::io::Read;

use common::{fails_with_one_line, globus, json, s, scratch};

const SWISS: &str = "traffic-switzerland-2018-08-01.csv.gz";

/// Flights in the air at `t` in the raw record: rows grouped by address and call sign, split
/// after 30 minutes of silence, each in the air from its first report to 10 s after its last
/// (the replay's linger). An independent count: plain CSV reading, no Globus code.
fn airborne_in_raw_csv(t: f64) -> usize {
    let path = globus_test_support::shared_data(SWISS);
    let mut text = String::new();
    flate2::read::MultiGzDecoder::new(std::fs::File::open(path).expect("record"))
        .read_to_string(&mut text)
        .expect("gzip");
    let mut lines = text.lines();
    let header: Vec<&str> = lines.next().expect("header").split(',').collect();
    let col = |name: &str| header.iter().position(|h| *h == name).expect(name);
    let (ti, ic, cs, pu, lat) = (
        col("time"),
        col("icao24"),
        col("callsign"),
        col("lastposupdate"),
        col("lat"),
    );
    // Per aircraft: its report times with the call sign they came under.
    let mut reports: HashMap<String, Vec<(f64, String)>> = HashMap::new();
    for line in lines {
        let cells: Vec<&str> = line.split(',').collect();
        if cells.len() < header.len() || cells[lat].is_empty() {
            continue;
        }
        let time = cells[pu]
            .parse::<f64>()
            .or_else(|_| cells[ti].parse::<f64>());
        if let Ok(time) = time {
            reports
                .entry(cells[ic].to_string())
                .or_default()
                .push((time, cells[cs].trim().to_string()));
        }
    }
    let mut airborne = 0;
    for (_, mut r) in reports {
        r.sort_by(|a, b| a.0.total_cmp(&b.0));
        let mut start = 0;
        for k in 1..=r.len() {
            let split = k == r.len()
                || r[k].0 - r[k - 1].0 > 1_800.0
                || (!r[k].1.is_empty() && !r[start].1.is_empty() && r[k].1 != r[start].1);
            if split {
                if r[start].0 <= t && t <= r[k - 1].0 + 10.0 {
                    airborne += 1;
                }
                start = k;
            }
        }
    }
    airborne
}

#[test]
fn render_draws_the_swiss_record_at_a_moment_with_every_aircraft_then_in_the_air() {
    let dir = scratch("traffic-cli", "render");
    let (png, stats) = (dir.join("swiss.png"), dir.join("swiss.json"));
    let record = globus_test_support::shared_data(SWISS);
    let out = globus(&[
        "render",
        "--camera",
        "8.2,46.8,450000,0,-90",
        "--size",
        "480x360",
        "--traffic",
        s(&record),
        "--time",
        "2018-08-01T14:00:00Z",
        "--out",
        s(&png),
        "--stats",
        s(&stats),
    ]);
    assert!(
        out.status.success(),
        "{}",
        String::from_utf8_lossy(&out.stderr)
    );
    assert!(
        out.stderr.is_empty(),
        "{}",
        String::from_utf8_lossy(&out.stderr)
    );
    let st: serde_json::Value =
        serde_json::from_slice(&std::fs::read(&stats).expect("stats")).expect("JSON");
    let t = st["traffic"].clone();
    let drawn = t["aircraft"].as_u64().expect("aircraft") as i64;
    // 2018-08-01T14:00:00Z is 1533132000.
    let expected = airborne_in_raw_csv(1_533_132_000.0) as i64;
    assert!(expected > 10, "{expected}");
    assert!(
        (drawn - expected).abs() <= 1,
        "drew {drawn}, the record has {expected}"
    );
    assert!(t["labels"].as_u64().expect("labels") > 5, "{t}");
    assert!(t["draw_calls"].as_u64().expect("draw calls") <= 10, "{t}");
    assert_eq!(t["time"], "2018-08-01T14:00:00Z");
    let img = image::open(&png).expect("a PNG").to_rgba8();
    assert_eq!(img.dimensions(), (480, 360));

    // The orthographic top-down camera over the same moment: 400 km of Switzerland from
    // top to bottom, looking straight down from its eye height whatever --camera says.
    let out = globus(&[
        "render",
        "--camera",
        "8.2,46.8,450000,0,-30",
        "--ortho-km",
        "400",
        "--size",
        "480x360",
        "--traffic",
        s(&record),
        "--time",
        "2018-08-01T14:00:00Z",
        "--out",
        s(&png),
        "--stats",
        s(&stats),
    ]);
    assert!(
        out.status.success(),
        "{}",
        String::from_utf8_lossy(&out.stderr)
    );
    let st: serde_json::Value =
        serde_json::from_slice(&std::fs::read(&stats).expect("stats")).expect("JSON");
    assert_eq!(st["camera"]["ortho_km"], 400.0);
    assert_eq!(st["camera"]["pitch"], -90.0);
    let ortho_drawn = st["traffic"]["aircraft"].as_u64().expect("aircraft") as i64;
    assert!(
        (ortho_drawn - expected).abs() <= 1,
        "drew {ortho_drawn} of {expected}"
    );
    assert!(st["traffic"]["labels"].as_u64().expect("labels") > 5);
}

#[test]
fn bench_replays_a_record_and_reports_tick_and_frame_costs() {
    let record = globus_test_support::shared_data(SWISS);
    let out = globus(&[
        "bench",
        "--traffic",
        s(&record),
        "--speed",
        "720",
        "--frames",
        "20",
        "--size",
        "320x240",
    ]);
    let v = json(&out);
    for key in [
        "tick_us",
        "traffic_prepare_us",
        "label_placement_us",
        "frame_ms",
        "frame_ms_without_traffic",
        "aircraft",
    ] {
        assert!(v[key]["median"].is_number(), "{key}: {v}");
    }
    assert!(
        v["aircraft"]["max"].as_f64().expect("aircraft") >= 20.0,
        "{v}"
    );
    assert!(v["traffic_draw_calls"].as_u64().expect("draw calls") <= 20);
}

#[test]
fn synthetic_records_are_made_and_summarised_through_the_traffic_subcommands() {
    let dir = scratch("traffic-cli", "synth");
    let file = dir.join("few.csv.gz");
    let made = json(&globus(&[
        "traffic",
        "synth",
        "--airports",
        s(&globus_test_support::shared_data("airports.csv")),
        "--flights",
        "12",
        "--hours",
        "1",
        "--out",
        s(&file),
    ]));
    assert_eq!(made["flights"], 12);
    let info = json(&globus(&["traffic", "info", s(&file)]));
    assert_eq!(info["flights"], 12);
    assert_eq!(info["most_at_once"], 12);
}

#[test]
fn bad_traffic_input_is_one_line() {
    let record = globus_test_support::shared_data(SWISS);
    let readme = globus_test_support::workspace_root().join("README.md");
    let dir = scratch("traffic-cli", "bad");
    let out = dir.join("x.png");
    let render = |extra: &[&str]| {
        let mut a = vec![
            "render",
            "--camera",
            "8,46,400000,0,-90",
            "--size",
            "64x48",
            "--out",
            s(&out),
        ];
        a.extend_from_slice(extra);
        a.into_iter().map(str::to_string).collect::<Vec<_>>()
    };
    let args = render(&["--traffic", s(&readme)]);
    let args: Vec<&str> = args.iter().map(String::as_str).collect();
    fails_with_one_line(&args, &["README.md", "not an OpenSky state-vector CSV"]);
    let args = render(&["--traffic", s(&record), "--time", "yesterday"]);
    let args: Vec<&str> = args.iter().map(String::as_str).collect();
    fails_with_one_line(&args, &["--time", "yesterday"]);
    let args = render(&["--time", "1e300"]);
    let args: Vec<&str> = args.iter().map(String::as_str).collect();
    fails_with_one_line(&args, &["--time", "1e300"]);
    fails_with_one_line(&["traffic"], &["--record"]);
    for km in ["0", "-5", "1e9", "NaN"] {
        let args = render(&["--ortho-km", km]);
        let args: Vec<&str> = args.iter().map(String::as_str).collect();
        fails_with_one_line(&args, &["--ortho-km"]);
    }
    fails_with_one_line(
        &["bench", "--soak", "1", "--ortho-km", "10"],
        &["--ortho-km", "--traffic"],
    );
    fails_with_one_line(
        &["traffic", "--record", s(&record), "--speed", "0"],
        &["--speed"],
    );
    fails_with_one_line(
        &["bench", "--traffic", s(&record), "--frames", "0"],
        &["--frames"],
    );
    fails_with_one_line(
        &["bench", "--traffic", s(&record), "--speed", "-3"],
        &["--speed"],
    );
}

#[test]
fn built_in_models_are_written_as_glb_and_read_back_with_model() {
    let dir = scratch("traffic-cli", "models");
    let made = json(&globus(&["traffic", "models", "--out", s(&dir)]));
    assert_eq!(made["models"].as_array().map(Vec::len), Some(4));
    let glb = dir.join("widebody.glb");
    let bytes = std::fs::read(&glb).expect("written");
    assert_eq!(&bytes[..4], b"glTF");
    let record = globus_test_support::shared_data(SWISS);
    let png = dir.join("x.png");
    let spec = format!("narrowbody={}", s(&glb));
    let out = globus(&[
        "render",
        "--camera",
        "8.2,46.8,450000,0,-90",
        "--size",
        "64x48",
        "--traffic",
        s(&record),
        "--time",
        "2018-08-01T14:00:00Z",
        "--model",
        &spec,
        "--out",
        s(&png),
    ]);
    assert!(
        out.status.success(),
        "{}",
        String::from_utf8_lossy(&out.stderr)
    );
    let readme = globus_test_support::workspace_root().join("README.md");
    for (model, needles) in [
        (
            format!("jumbo={}", s(&glb)),
            vec!["jumbo", "light, narrowbody, widebody, helicopter"],
        ),
        (format!("light={}", s(&readme)), vec!["README.md", "glTF"]),
        (s(&glb).to_string(), vec!["KIND=FILE.glb"]),
    ] {
        fails_with_one_line(
            &[
                "render",
                "--camera",
                "8,46,400000,0,-90",
                "--size",
                "64x48",
                "--traffic",
                s(&record),
                "--model",
                &model,
                "--out",
                s(&png),
            ],
            &needles,
        );
    }
}
