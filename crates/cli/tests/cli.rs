//! The `globus` binary as a user runs it: outputs, and one clear line for every bad input.

mod common;
use common::{fails_with_one_line, globus, json};

#[test]
fn geo_ecef_and_back() {
    let v = json(&globus(&["geo", "ecef", "-73.9857", "40.7484", "443"]));
    let (x, y, z) = (
        v["x"].as_f64().unwrap(),
        v["y"].as_f64().unwrap(),
        v["z"].as_f64().unwrap(),
    );
    // pyproj 3.7 / PROJ 9.5 (EPSG:4979 -> EPSG:4978) for the Empire State Building:
    // 1335028.2532, -4651415.0403, 4141585.1828.
    assert!(
        (x - 1_335_028.253_2).abs() < 1e-3
            && (y + 4_651_415.040_3).abs() < 1e-3
            && (z - 4_141_585.182_8).abs() < 1e-3,
        "{v}"
    );
    let back = json(&globus(&[
        "geo",
        "cartographic",
        &x.to_string(),
        &y.to_string(),
        &z.to_string(),
    ]));
    assert!((back["lon"].as_f64().unwrap() + 73.9857).abs() < 1e-9);
    assert!((back["height"].as_f64().unwrap() - 443.0).abs() < 1e-6);
}

#[test]
fn geo_tile_names_a_tile_like_bing_and_tms() {
    // Bing's example: level 3, x 3, y 5 is quadkey 213.
    let v = json(&globus(&[
        "geo",
        "tile",
        "--scheme",
        "webmercator",
        "--lon",
        "-20",
        "--lat",
        "-50",
        "--level",
        "3",
    ]));
    assert_eq!(
        (v["z"].as_u64(), v["x"].as_u64(), v["y"].as_u64()),
        (Some(3), Some(3), Some(5))
    );
    assert_eq!(v["quadkey"], "213");
    assert_eq!(v["tms_y"], 2);
    // mercantile: LngLatBbox(west=-45.0, south=-66.51326044311186, east=0.0, north=-40.97989806962013)
    let b = &v["bounds"];
    for (k, want) in [
        ("west", -45.0),
        ("south", -66.51326044311186),
        ("east", 0.0),
        ("north", -40.97989806962013),
    ] {
        assert!((b[k].as_f64().unwrap() - want).abs() < 1e-9, "{k}: {b}");
    }
    let g = json(&globus(&[
        "geo",
        "tile",
        "--scheme",
        "geographic",
        "--lon",
        "10",
        "--lat",
        "45",
        "--level",
        "0",
    ]));
    assert_eq!(
        (g["x"].as_u64(), g["quadkey"].as_str()),
        (Some(1), Some("1"))
    );
}

#[test]
fn geo_slopes_measures_the_procedural_mountains() {
    let v = json(&globus(&[
        "geo",
        "slopes",
        "--lon",
        "7.6",
        "--lat",
        "46",
        "--window-km",
        "3",
    ]));
    let share = |k: &str| v[k].as_f64().unwrap();
    let (s20, s30, s40) = (
        share("steeper_than_20_deg"),
        share("steeper_than_30_deg"),
        share("steeper_than_40_deg"),
    );
    // The default planet's range stands here: real relief, steeper shares nested.
    assert!(v["highest_m"].as_f64().unwrap() > 1_500.0, "{v}");
    assert!(s20 > 0.0 && s20 >= s30 && s30 >= s40 && s20 <= 1.0, "{v}");
    assert_eq!(v["samples"], 101 * 101, "{v}");
    fails_with_one_line(&["geo", "slopes", "--lon", "0", "--lat", "89"], &["85"]);
    fails_with_one_line(
        &[
            "geo",
            "slopes",
            "--lon",
            "0",
            "--lat",
            "0",
            "--spacing-m",
            "0",
        ],
        &["--spacing-m"],
    );
}

#[test]
fn bad_arguments_end_with_one_clear_line() {
    let png = std::env::temp_dir().join("globus-cli-test.png");
    let png = png.to_str().unwrap();
    // Arguments split on spaces (OUT stands for a writable PNG path); the text the one error
    // line must contain.
    let cases = [
        (
            "geo tile --scheme utm --lon 0 --lat 0 --level 1",
            "unknown tiling scheme",
        ),
        // The aliases are named where a scheme is refused.
        (
            "geo tile --scheme utm --lon 0 --lat 0 --level 1",
            "epsg:3857",
        ),
        // Beyond what the device can draw: refused before anything is allocated.
        (
            "render --camera 0,0,1000,0,0 --size 8193x8193 --out OUT",
            "8193x8193",
        ),
        (
            "render --camera 0,0,1000,0,0 --size 64x64 --out OUT --timeout-s 1e300",
            "--timeout-s",
        ),
        (
            "render --camera 0,0,1000,0,0 --size 64x64 --out OUT --timeout-s -1",
            "--timeout-s",
        ),
        (
            "render --camera 0,0,1000,0,0 --size 64x64 --out OUT --timeout-s NaN",
            "--timeout-s",
        ),
        // Budgets beyond the machine: refused naming the largest that makes sense.
        (
            "render --camera 0,0,1000,0,0 --size 64x64 --out OUT --memory-mb 1000000000000",
            "this machine has",
        ),
        (
            "render --camera 0,0,1000,0,0 --size 64x64 --out OUT --sse 1e-300",
            "error bound",
        ),
        // The frame's targets are counted: 8192 x 8192 needs more than the default 1 GiB.
        (
            "render --camera 0,0,1000,0,0 --size 8192x8192 --out OUT",
            "memory budget of 1024 MiB is too small",
        ),
        // The missing argument is named.
        ("geo ecef 7.6 46", "<HEIGHT>"),
        (
            "geo tile --scheme webmercator --lon 0 --lat 89 --level 1",
            "outside",
        ),
        ("geo ecef 200 0 0", "longitude 200"),
        ("geo cartographic 0 0 0", "centre of the Earth"),
        ("geo ecef 1 2", "globus"),
        (
            "render --camera 0,95,1000,0,0 --size 64x64 --out OUT",
            "latitude 95",
        ),
        (
            "render --camera 0,0,1000,0 --size 64x64 --out OUT",
            "5 numbers",
        ),
        (
            "render --camera 0,0,1000,0,-120 --size 64x64 --out OUT",
            "pitch",
        ),
        (
            "render --camera 0,0,abc,0,0 --size 64x64 --out OUT",
            "ALT_M",
        ),
        (
            "render --camera 0,0,1000,0,0 --size 64by64 --out OUT",
            "--size",
        ),
        (
            "render --camera 0,0,1000,0,0 --size 0x64 --out OUT",
            "--size",
        ),
        (
            "render --camera 0,0,1000,0,0 --size 64x64 --sse 0 --out OUT",
            "--sse",
        ),
        (
            "render --camera 0,0,1000,0,0 --size 64x64 --out /nonexistent-dir/x.png",
            "/nonexistent-dir/x.png",
        ),
        (
            "bench --path /nonexistent/path.json",
            "/nonexistent/path.json",
        ),
        ("frobnicate", "frobnicate"),
        (
            "render --camera 0,0,1000,0,0 --size 64x64 --out OUT --terrain /nonexistent/dem",
            "/nonexistent/dem",
        ),
        (
            "render --camera 0,0,1000,0,0 --size 64x64 --out OUT --terrain http://127.0.0.1:9/{z}/{x}.png",
            "names no tile",
        ),
        (
            "render --camera 0,0,1000,0,0 --size 64x64 --out OUT --imagery x.mbtiles#colour=red",
            "unknown option",
        ),
        (
            "render --camera 0,0,1000,0,0 --size 64x64 --out OUT --config /nonexistent/globus.toml",
            "/nonexistent/globus.toml",
        ),
        (
            "render --camera 0,0,1000,0,0 --size 64x64 --out OUT --terrain ./x --refine-below 5",
            "--refine-below",
        ),
        (
            "render --camera 0,0,1000,0,0 --size 64x64 --out OUT --exaggeration -2",
            "--exaggeration",
        ),
        (
            "render --camera 0,0,1000,0,0 --size 64x64 --out OUT --target-fps 0",
            "--target-fps",
        ),
        (
            "render --camera 0,0,1000,0,0 --size 64x64 --out OUT --sse 4 --sse-max 3",
            "--sse-max",
        ),
    ];
    for (args, needle) in cases {
        let args: Vec<&str> = args
            .split(' ')
            .map(|a| if a == "OUT" { png } else { a })
            .collect();
        fails_with_one_line(&args, &[needle]);
    }
    // Night lights: a missing file and an image that is not equirectangular, each named.
    let night = std::env::temp_dir().join("globus-cli-night-3x2.png");
    image::RgbImage::new(3, 2)
        .save(&night)
        .expect("write a PNG");
    let night = night.to_str().unwrap();
    for (file, needle) in [
        ("/nonexistent/night.jpg", "/nonexistent/night.jpg"),
        (night, "twice as wide as tall"),
        (night, "globus-cli-night-3x2.png"),
    ] {
        fails_with_one_line(
            &[
                "render",
                "--camera",
                "0,0,1000,0,0",
                "--size",
                "64x64",
                "--out",
                png,
                "--night-imagery",
                file,
            ],
            &[needle],
        );
    }
}

/// A camera path file of these keyframes (JSON objects, comma-separated) in a scratch file.
fn path_file(name: &str, keyframes: &str) -> std::path::PathBuf {
    let path = std::env::temp_dir().join(format!("globus-{name}-{}.json", std::process::id()));
    std::fs::write(&path, format!(r#"{{"keyframes": [{keyframes}]}}"#))
        .expect("a scratch path file");
    path
}

/// A keyframe a million years away is refused before a sample per frame is allocated.
#[test]
fn bench_refuses_a_path_of_more_frames_than_it_replays() {
    let path = path_file(
        "long-path",
        r#"{"t": 0, "lon": 7.6, "lat": 46, "alt": 10000, "heading": 0, "pitch": -90},
           {"t": 1e12, "lon": 7.6, "lat": 46, "alt": 20000, "heading": 0, "pitch": -90}"#,
    );
    fails_with_one_line(
        &["bench", "--path", path.to_str().unwrap(), "--size", "64x64"],
        &["frames", "at most 1000000"],
    );
    std::fs::remove_file(&path).ok();
}

/// A frame rate no renderer reaches here (1,000 fps): the bound rises from --sse towards
/// --sse-max and never past it, and the report says so frame by frame.
#[test]
fn bench_holds_a_target_frame_rate_by_raising_the_bound_within_its_range() {
    let path = path_file(
        "fps-path",
        r#"{"t": 0, "lon": 7.6, "lat": 46, "alt": 40000, "heading": 0, "pitch": -30},
           {"t": 6, "lon": 7.9, "lat": 46.2, "alt": 20000, "heading": 40, "pitch": -20}"#,
    );
    let csv = std::env::temp_dir().join(format!("globus-fps-frames-{}.csv", std::process::id()));
    let held = json(&globus(&[
        "bench",
        "--path",
        path.to_str().unwrap(),
        "--size",
        "160x90",
        "--target-fps",
        "1000",
        "--sse-max",
        "6",
        "--frames-csv",
        csv.to_str().unwrap(),
    ]));
    let bound = &held["sse_bound_px"];
    let (median, max) = (
        bound["median"].as_f64().unwrap(),
        bound["max"].as_f64().unwrap(),
    );
    assert!(median > 2.5 && max <= 6.0, "{held}");
    assert_eq!(held["target_fps"], 1000.0);
    // Visits: every drawn tile is visited, and culled ones are counted apart.
    let per_tile = |key: &str| held[key]["median"].as_f64().unwrap();
    let (all, visible) = (
        per_tile("nodes_visited_per_tile"),
        per_tile("visible_nodes_per_tile"),
    );
    assert!(visible >= 1.0 && visible <= all, "{held}");
    assert!(
        held["nodes_culled"]["max"].as_f64().unwrap() > 0.0,
        "{held}"
    );
    // --frames-csv: a row per frame (6 s at 30 fps), whose bounds are the summary's.
    let text = std::fs::read_to_string(&csv).expect("the frames CSV");
    let mut lines = text.lines();
    let header: Vec<&str> = lines.next().expect("a header").split(',').collect();
    let column = |name: &str| {
        header
            .iter()
            .position(|&c| c == name)
            .unwrap_or_else(|| panic!("a {name} column"))
    };
    let (bound, select, update) = (
        column("sse_bound_px"),
        column("select_cpu_us"),
        column("update_cpu_us"),
    );
    let bounds: Vec<f64> = lines
        .map(|l| {
            let cells: Vec<&str> = l.split(',').collect();
            assert_eq!(cells.len(), header.len(), "{l}");
            let number = |i: usize| -> f64 { cells[i].parse().expect("a number") };
            // The frame's whole update includes its selection.
            assert!(number(update) >= number(select), "{l}");
            number(bound)
        })
        .collect();
    assert_eq!(bounds.len(), 181);
    let most = bounds.iter().copied().fold(0.0, f64::max);
    assert!((most - max).abs() < 1e-3, "CSV {most}, summary {max}");
    std::fs::remove_file(&csv).ok();
    std::fs::remove_file(&path).ok();
}

/// `--descent`: the camera comes down to a quarter of its height at one bound; detail comes
/// in as it does, and every frame moves.
#[test]
fn bench_popping_descends_at_a_fixed_bound() {
    let v = json(&globus(&[
        "bench",
        "--popping",
        "7.6,46,40000,200,-20",
        "--descent",
        "--sse",
        "3",
        "--size",
        "96x54",
    ]));
    assert_eq!(v["frames"], 121, "{v}");
    assert_eq!(v["descent"], true, "{v}");
    assert_eq!(v["bounds_px"], serde_json::json!([3.0, 3.0]), "{v}");
    let frames = v["per_frame"].as_array().unwrap();
    let tiles = |f: &serde_json::Value| f["tiles"].as_u64().unwrap();
    assert!(tiles(&frames[120]) > tiles(&frames[0]), "{v}");
    assert_eq!(v["frames_changing"], 120, "{v}");
    assert!(v["largest_step"].as_f64().unwrap() >= 0.0, "{v}");
}

#[test]
fn bench_popping_reports_what_each_split_changes() {
    let dir = std::env::temp_dir().join(format!("globus-cli-popping-{}", std::process::id()));
    let v = json(&globus(&[
        "bench",
        "--popping",
        "7.6,46,8000,200,-10",
        "--size",
        "96x54",
        "--frames-dir",
        dir.to_str().unwrap(),
    ]));
    assert_eq!(v["frames"], 121, "{v}");
    let frames = v["per_frame"].as_array().unwrap();
    let tiles = |f: &serde_json::Value| f["tiles"].as_u64().unwrap();
    // The bound falls from 8 to 1 px: tiles split, and the picture changes where they do.
    assert!(tiles(&frames[120]) > tiles(&frames[0]), "{v}");
    assert!(
        (frames[120]["sse_bound_px"].as_f64().unwrap() - 1.0).abs() < 1e-9,
        "{v}"
    );
    assert!(frames[0]["mean_abs_change"].is_null());
    let changing = v["frames_changing"].as_u64().unwrap();
    assert!(changing > 0 && changing <= 120, "{v}");
    let share = v["changed_share"]["max"].as_f64().unwrap();
    assert!(share > 0.0 && share <= 1.0, "{v}");
    // Every frame is written; the sweep's totals add up from the frames and read back from
    // the first and last pictures.
    let frame = |i: usize| {
        globus_test_support::image::Rgba::read(&dir.join(format!("{i:03}.png"))).unwrap()
    };
    assert_eq!(std::fs::read_dir(&dir).unwrap().count(), 121);
    let (first, last) = (frame(0), frame(120));
    assert_eq!((first.width, first.height), (96, 54));
    let net = v["net_mean_abs_change"].as_f64().unwrap();
    assert!((net - first.mean_abs_diff(&last)).abs() < 1e-9, "{v}");
    let total = v["total_mean_abs_change"].as_f64().unwrap();
    let added: f64 = frames[1..]
        .iter()
        .map(|f| f["mean_abs_change"].as_f64().unwrap())
        .sum();
    assert!((total - added).abs() < 1e-9, "{v}");
    assert!(net > 0.0 && net <= total + 1e-9, "{v}");
    let floor = v["even_spread_floor"].as_f64().unwrap();
    assert!((floor - total / 120.0).abs() < 1e-9, "{v}");
    assert!(
        v["mean_abs_change"]["max"].as_f64().unwrap() >= floor,
        "{v}"
    );
    std::fs::remove_dir_all(&dir).ok();
}

#[test]
fn scheme_aliases_name_the_same_tiles() {
    let tile = |scheme: &str| {
        json(&globus(&[
            "geo", "tile", "--scheme", scheme, "--lon", "-20", "--lat", "-50", "--level", "3",
        ]))
    };
    for alias in ["mercator", "web-mercator", "EPSG:3857", "3857"] {
        assert_eq!(tile(alias), tile("webmercator"), "{alias}");
    }
    for alias in ["epsg:4326", "4326", "Geographic"] {
        assert_eq!(tile(alias), tile("geographic"), "{alias}");
    }
}

#[test]
fn view_without_a_display_fails_at_once_pointing_to_render() {
    fails_with_one_line(&["view"], &["globus render"]);
}

#[test]
fn render_writes_a_png_and_stats() {
    let dir = std::env::temp_dir().join(format!("globus-cli-render-{}", std::process::id()));
    std::fs::create_dir_all(&dir).unwrap();
    let png = dir.join("orbit.png");
    let stats = dir.join("orbit.json");
    let out = globus(&[
        "render",
        "--camera",
        "-120,10,20000000,0,-90",
        "--size",
        "160x120",
        "--out",
        png.to_str().unwrap(),
        "--stats",
        stats.to_str().unwrap(),
    ]);
    assert!(
        out.status.success(),
        "{}",
        String::from_utf8_lossy(&out.stderr)
    );
    let img = image::open(&png).expect("a PNG").to_rgba8();
    assert_eq!(img.dimensions(), (160, 120));
    let s: serde_json::Value = serde_json::from_slice(&std::fs::read(&stats).unwrap()).unwrap();
    for key in [
        "tiles_rendered",
        "nodes_visited",
        "culled_frustum",
        "culled_horizon",
        "max_level",
        "max_sse_px",
        "triangles",
        "draw_calls",
        "select_us",
        "load_ms",
        "gpu_tile_bytes",
    ] {
        assert!(s[key].is_number(), "stats lack {key}: {s}");
    }
    assert!(s["tiles_rendered"].as_u64().unwrap() > 0);
    assert!(s["draw_calls"].as_u64().unwrap() <= 10);
    assert_eq!(s["complete"], true);
    // A run that succeeds, without a runtime directory in its environment (the drivers' "error:
    // XDG_RUNTIME_DIR is invalid or not set" before), says nothing on stderr: logs are
    // warnings and errors only, and nothing was drawn to a terminal.
    let stderr = String::from_utf8_lossy(&out.stderr);
    assert!(
        stderr.trim().is_empty(),
        "a successful render printed: {stderr}"
    );
    std::fs::remove_dir_all(&dir).ok();
}

/// `--atmosphere none` takes the air away (a black sky over the ground), the default draws
/// the Earth's (a blue one), `--no-fog` and `--no-morph` are accepted, and an unknown air is
/// refused.
#[test]
fn render_draws_the_air_unless_told_there_is_none() {
    let dir = common::scratch("cli", "atmosphere");
    let sky = |extra: &[&str], name: &str| {
        let png = dir.join(name);
        let mut args = vec![
            "render",
            "--camera",
            "7.6,46,500,0,30",
            "--above-ground",
            "--size",
            "96x64",
            "--out",
            png.to_str().unwrap(),
        ];
        args.extend_from_slice(extra);
        let out = globus(&args);
        assert!(
            out.status.success(),
            "{name}: {}",
            String::from_utf8_lossy(&out.stderr)
        );
        let img = image::open(&png).expect("a PNG").to_rgba8();
        // The top middle of the picture: 60 degrees up.
        img.get_pixel(48, 2).0
    };
    let blue = sky(&["--no-fog", "--no-morph"], "earth.png");
    let black = sky(&["--atmosphere", "none"], "none.png");
    assert!(
        blue[2] > 60 && blue[2] > blue[0],
        "the Earth's sky {blue:?}"
    );
    assert!(
        u32::from(black[0]) + u32::from(black[1]) + u32::from(black[2]) < 15,
        "no air {black:?}"
    );
    fails_with_one_line(
        &[
            "render",
            "--camera",
            "0,0,1000,0,0",
            "--size",
            "8x8",
            "--out",
            "x.png",
            "--atmosphere",
            "mars",
        ],
        &["--atmosphere", "mars"],
    );
}

/// A CR/LF in a header from the config split every request and panicked the loader threads
/// (the run exited 0 without terrain): now refused when the config is read.
#[test]
fn a_header_with_cr_lf_in_the_config_is_refused_when_it_is_read() {
    let dir = std::env::temp_dir().join(format!("globus-cli-crlf-{}", std::process::id()));
    std::fs::create_dir_all(&dir).unwrap();
    let png = dir.join("x.png");
    for (name, toml) in [
        ("ua.toml", "[http]\nuser_agent = \"me\\r\\nX-Evil: 1\"\n"),
        (
            "header.toml",
            "[http]\nheaders = { \"X-Key\" = \"a\\nb\" }\n",
        ),
    ] {
        let config = dir.join(name);
        std::fs::write(&config, toml).unwrap();
        fails_with_one_line(
            &[
                "render",
                "--camera",
                "0,0,1000,0,0",
                "--size",
                "64x64",
                "--out",
                png.to_str().unwrap(),
                "--config",
                config.to_str().unwrap(),
            ],
            &[name, "control characters"],
        );
    }
    std::fs::remove_dir_all(&dir).ok();
}

/// A failed `render --out` over an existing file left it at 0 bytes, and on a full disk a
/// truncated PNG; `--stats` given the path of `--out` replaced the picture. Now the old file
/// stays whole (the new one is written beside it and renamed), and the same path is refused.
#[test]
fn failed_writes_leave_the_old_file_whole_and_one_path_is_not_two_outputs() {
    let dir = std::env::temp_dir().join(format!("globus-cli-atomic-{}", std::process::id()));
    std::fs::create_dir_all(&dir).unwrap();
    let png = dir.join("frame.png");
    std::fs::write(&png, b"the old picture").unwrap();
    // Its temporary points at /dev/full: every write fails with "no space left on device".
    let partial = dir.join("frame.png.partial");
    let _ = std::fs::remove_file(&partial);
    std::os::unix::fs::symlink("/dev/full", &partial).unwrap();
    let render = |out: &std::path::Path, extra: &[&str]| {
        let mut a = vec![
            "render",
            "--camera",
            "7.6,46,400000,0,-90",
            "--size",
            "64x64",
            "--out",
            out.to_str().unwrap(),
        ];
        a.extend(extra);
        a.iter().map(|s| s.to_string()).collect::<Vec<_>>()
    };
    let args = render(&png, &[]);
    let args: Vec<&str> = args.iter().map(String::as_str).collect();
    fails_with_one_line(&args, &["frame.png", "No space left on device"]);
    assert_eq!(std::fs::read(&png).unwrap(), b"the old picture");
    assert!(!partial.exists(), "the temporary is left behind");
    let stats = dir.join("./frame.png");
    let args = render(&png, &["--stats", stats.to_str().unwrap()]);
    let args: Vec<&str> = args.iter().map(String::as_str).collect();
    fails_with_one_line(&args, &["--stats", "same file"]);
    assert_eq!(std::fs::read(&png).unwrap(), b"the old picture");
    std::fs::remove_dir_all(&dir).ok();
}

/// Imagery that failed for good (every tile a 403) gave no stderr line, `complete: true` and
/// no failure counts: now one line per failing layer, its counts in the stats, and the frame
/// is not complete (it was drawn without the imagery asked for).
#[test]
fn imagery_failures_are_reported_per_layer() {
    use globus_test_support::http::{Fault, FaultServer};
    let server = FaultServer::in_memory();
    server.add_fault("/", Fault::Status(403), None);
    let imagery = server.url("/{z}/{x}/{y}.png");
    let dir = std::env::temp_dir().join(format!("globus-cli-403-{}", std::process::id()));
    std::fs::create_dir_all(&dir).unwrap();
    let png = dir.join("denied.png");
    let stats = dir.join("denied.json");
    let out = globus(&[
        "render",
        "--camera",
        "-120,10,20000000,0,-90",
        "--size",
        "96x64",
        "--imagery",
        &imagery,
        "--out",
        png.to_str().unwrap(),
        "--stats",
        stats.to_str().unwrap(),
        "--timeout-s",
        "60",
    ]);
    let err = String::from_utf8_lossy(&out.stderr);
    assert!(out.status.success(), "{err}");
    assert!(
        err.contains("tiles failed") && err.contains("HTTP 403"),
        "{err}"
    );
    assert!(
        err.contains("127.0.0.1"),
        "the failing URLs are named: {err}"
    );
    let s: serde_json::Value = serde_json::from_slice(&std::fs::read(&stats).unwrap()).unwrap();
    assert_eq!(s["complete"], false, "{s}");
    let f = &s["failures"][0];
    assert!(f["by_kind"]["HTTP 403"].as_u64().unwrap_or(0) > 0, "{s}");
    assert_eq!(f["tiles"], f["by_kind"]["HTTP 403"], "{s}");
    assert!(server.count("/") > 0);
    std::fs::remove_dir_all(&dir).ok();
}

#[test]
fn render_draws_vector_files_from_the_command_line_and_the_config() {
    let dir = common::scratch("cli", "vector");
    let line = dir.join("line.geojson");
    std::fs::write(
        &line,
        r#"{"type": "FeatureCollection", "features": [
            {"type": "Feature", "properties": {}, "geometry": {"type": "LineString", "coordinates": [[-130, 0], [-110, 20]]}},
            {"type": "Feature", "properties": {}, "geometry": {"type": "Polygon", "coordinates": [[[0, 0], [1, 0], [1, 1], [0, 1]]]}}
        ]}"#,
    )
    .unwrap();
    let other = dir.join("other.geojson");
    std::fs::write(
        &other,
        r#"{"type": "LineString", "coordinates": [[-135, -15], [-115, -5]]}"#,
    )
    .unwrap();
    let config = dir.join("globus.toml");
    std::fs::write(
        &config,
        "[vector_style]\nstroke = \"#ff00ff\"\nstroke-width = 6\n\n[[vector]]\nfile = \"line.geojson\"\nstyle = { stroke-opacity = 1 }\n",
    )
    .unwrap();
    let png = dir.join("v.png");
    let stats = dir.join("v.json");
    let out = globus(&[
        "render",
        "--camera",
        "-120,10,20000000,0,-90",
        "--size",
        "160x120",
        "--out",
        png.to_str().unwrap(),
        "--stats",
        stats.to_str().unwrap(),
        "--config",
        config.to_str().unwrap(),
        "--vector",
        &format!("{}#stroke=%2300ff00", other.display()),
    ]);
    let stderr = String::from_utf8_lossy(&out.stderr);
    assert!(out.status.success(), "{stderr}");
    // The unclosed ring is one warning naming the file and feature.
    assert_eq!(
        stderr
            .matches("line.geojson: feature 1: exterior ring: an unclosed ring")
            .count(),
        1,
        "{stderr}"
    );
    let s: serde_json::Value = serde_json::from_slice(&std::fs::read(&stats).unwrap()).unwrap();
    assert_eq!(s["vector"]["features"], 2, "{s}");
    assert!(s["vector"]["line_instances"].as_u64().unwrap() > 0, "{s}");
    // The config's line is magenta (its defaults), the command line's green (its override).
    let img = image::open(&png).expect("a PNG").to_rgba8();
    let (mut magenta, mut green) = (0, 0);
    for p in img.pixels() {
        let [r, g, b, _] = p.0;
        magenta += usize::from(r > 200 && g < 80 && b > 200);
        green += usize::from(g > 200 && r < 80 && b < 80);
    }
    assert!(
        magenta > 5 && green > 5,
        "magenta {magenta}, green {green} pixels"
    );
    // Bad style keys and files that are not GeoJSON are one line each.
    std::fs::write(&config, "[vector_style]\nstrokes = 1\n").unwrap();
    let csv = dir.join("airports.csv");
    std::fs::write(&csv, "icao,lat,lon\n").unwrap();
    for (flag, file, needles) in [
        (
            "--config",
            &config,
            ["vector_style", "`strokes` is not a style key"],
        ),
        ("--vector", &csv, ["airports.csv", "not GeoJSON"]),
    ] {
        let args = [
            "render",
            "--camera",
            "0,0,1e7,0,-90",
            "--size",
            "8x8",
            "--out",
            png.to_str().unwrap(),
            flag,
            file.to_str().unwrap(),
        ];
        fails_with_one_line(&args, &needles);
    }
}

/// A PMTiles archive whose root directory is a gzip bomb (80 MiB of zeros in 80 kB) is one
/// line naming the file and the limit, and says it once (a message that quotes its cause does
/// not print the cause again as the next link of the chain).
#[test]
fn a_pmtiles_bomb_is_refused_in_one_line_that_says_it_once() {
    use std::io::Write;
    let dir = common::scratch("cli", "pmtiles-bomb");
    let mut gz = flate2::write::GzEncoder::new(Vec::new(), flate2::Compression::best());
    let zeros = vec![0u8; 1 << 20];
    for _ in 0..80 {
        gz.write_all(&zeros).expect("gzip");
    }
    let bomb = gz.finish().expect("gzip");
    // A v3 header: the root directory right after it, gzip inside, PNG terrain, levels 0-10.
    let mut header = vec![0u8; 127];
    header[..7].copy_from_slice(b"PMTiles");
    header[7] = 3;
    let end = 127 + bomb.len() as u64;
    for (k, v) in [127, bomb.len() as u64, end, 0, end, 0, end, 0, 1, 1, 1]
        .into_iter()
        .enumerate()
    {
        header[8 + 8 * k..16 + 8 * k].copy_from_slice(&v.to_le_bytes());
    }
    header[96..102].copy_from_slice(&[1, 2, 1, 2, 0, 10]);
    for (k, v) in [-1_800_000_000i32, -850_000_000, 1_800_000_000, 850_000_000]
        .into_iter()
        .enumerate()
    {
        header[102 + 4 * k..106 + 4 * k].copy_from_slice(&v.to_le_bytes());
    }
    let file = dir.join("bomb.pmtiles");
    std::fs::write(&file, [header, bomb].concat()).expect("write");
    let out = dir.join("bomb.png");
    let args = [
        "render",
        "--camera",
        "10,10,2000000,0,-90",
        "--size",
        "64x48",
        "--terrain",
        common::s(&file),
        "--out",
        common::s(&out),
    ];
    fails_with_one_line(&args, &["bomb.pmtiles", "inflates past 67108864 bytes"]);
    let err = String::from_utf8_lossy(&globus(&args).stderr).to_string();
    assert_eq!(err.matches("inflates past").count(), 1, "{err}");
    // The file is named once too.
    assert_eq!(err.matches("bomb.pmtiles").count(), 1, "{err}");
}
