//! The real Earth streamed over HTTP from a server on 127.0.0.1: world topography and the
//! Blue Marble tiled by `globus tile` (the library, as in `tools/real-earth-demo.sh`), served
//! by a server that also injects faults, rendered on lavapipe. The picture must be complete
//! (no hole inside the silhouette), the continents where they are, and failed tiles must
//! leave their ancestors in place.

mod common;

use std::path::Path;
use std::time::Duration;

use globus_app::engine::{CameraSpec, GlobeOptions};
use globus_app::offscreen::{Offscreen, holes_inside, save_png};
use globus_geo::{Cartographic, Ellipsoid};
use globus_stream::open::SourceSpec;
use globus_test_support::http::{Fault, FaultServer};
use globus_test_support::shared_data;
use globus_tiler::{ElevationEncoding, ImageFormat, JobKind, TileJob};
use globus_tiling::TilingScheme;

fn tile(kind: JobKind, input: &str, out: &Path, scale_max: Option<u8>) {
    let job = TileJob {
        max_level: scale_max,
        threads: Some(2),
        ..TileJob::new(kind, vec![shared_data(input)], out.to_path_buf())
    };
    globus_tiler::run(&job).unwrap_or_else(|e| panic!("tiling {input}: {e}"));
}

#[test]
fn the_real_earth_streams_over_http_through_faults_and_completes() {
    let root = std::env::temp_dir().join(format!("globus-real-earth-{}", std::process::id()));
    let _ = std::fs::remove_dir_all(&root);
    tile(
        JobKind::Dem {
            encoding: ElevationEncoding::Terrarium,
            height_scale: Some(25.1),
        },
        "earth-topology-2048x1024.png",
        &root.join("topo"),
        Some(3),
    );
    tile(
        JobKind::Imagery {
            format: ImageFormat::parse("jpeg", 85).expect("jpeg"),
        },
        "bmng-5400x2700.jpg",
        &root.join("bmng"),
        Some(3),
    );
    let server = FaultServer::serve_dir(&root);
    server.set_latency(Duration::from_millis(5));
    // This view needs topography level 1 and Blue Marble level 0 (128-texel engine tiles
    // at level 1 match 256-pixel imagery tiles at level 0). Transient faults that retries
    // get past, and one visible tile that never decodes (its ancestor must stand in).
    server.add_fault("/topo/1/3/", Fault::Status(503), Some(2));
    server.add_fault("/topo/1/2/1.png", Fault::Reset, Some(1));
    server.add_fault(
        "/bmng/0/1/0.jpg",
        Fault::RetryAfter {
            status: 429,
            secs: 1,
        },
        Some(1),
    );
    server.add_fault("/topo/1/2/0.png", Fault::NotAnImage, None);
    let options = GlobeOptions {
        terrain: vec![SourceSpec::parse(&server.url("/topo")).expect("spec")],
        imagery: vec![SourceSpec::parse(&server.url("/bmng")).expect("spec")],
        ..GlobeOptions::default()
    };
    let (w, h) = (640, 360);
    let mut off = Offscreen::new(&options, w, h).expect("a GPU or lavapipe, and the sources");
    let cam = CameraSpec {
        lon_deg: 10.0,
        lat_deg: 30.0,
        alt_m: 12_000_000.0,
        heading_deg: 0.0,
        pitch_deg: -90.0,
        above_ground: false,
    };
    let view = cam.view(&off.globe, 60.0, w, h);
    let frame = off
        .render_complete(&view, Duration::from_secs(120))
        .expect("render");
    let dir = globus_test_support::output_dir("real_earth");
    save_png(&frame.image, &dir.join("earth_over_http.png")).expect("save");
    assert!(frame.complete, "tiles still loading");

    // No hole inside the silhouette: rays that hit the ellipsoid 16 km below the surface must
    // hit terrain. The sea is the lowest surface here, but the broken level-1 tile is drawn
    // from its level-0 ancestor, whose flat cells (5.6 degrees, 7.9 across the diagonal) sag
    // up to 6378 km * (1 - cos 3.98 deg) = 15.4 km below the ellipsoid.
    let e = Ellipsoid::WGS84;
    let body = e.grown(-16_000.0);
    let img = &frame.image;
    let (inside, holes) = holes_inside(img, &view, &body);
    assert!(inside > 20_000 && holes == 0, "{holes} holes of {inside}");

    // The continents are where they are: deserts are much warmer (red minus blue) than the
    // sea, seen through the same air (the haze of the atmosphere model greys both).
    let warmth = |lon: f64, lat: f64| {
        let p = e.cartographic_to_ecef(Cartographic::new(lon.to_radians(), lat.to_radians(), 0.0));
        let (x, y) = view.project(p).expect("on screen");
        let i = ((y as u32 * w + x as u32) * 4) as usize;
        i32::from(img.pixels[i]) - i32::from(img.pixels[i + 2])
    };
    let sea = [("Atlantic", -30.0, 30.0), ("Mediterranean", 18.0, 34.5)];
    let desert = [
        ("Sahara (Algeria)", 3.0, 26.0),
        ("Libyan desert", 24.0, 25.0),
    ];
    for (d, dlon, dlat) in desert {
        for (s, slon, slat) in sea {
            let (a, b) = (warmth(dlon, dlat), warmth(slon, slat));
            assert!(a - b > 40, "{d} (red - blue {a}) vs {s} ({b})");
        }
    }

    // Every fault was met: the transient ones retried, the broken tile failed once and for
    // all (asked once), and its ancestor filled its place in the complete picture above.
    let stats = off.globe.layer().scheduler_stats();
    assert!(stats.retries >= 3, "{stats:?}");
    assert_eq!(stats.failed, 1, "{stats:?}");
    assert_eq!(server.count("/topo/1/2/0.png"), 1);
    assert_eq!(server.count("/bmng/0/1/0.jpg"), 2);
    assert!(frame.load_ms >= 1000.0, "Retry-After: 1 was honoured");
    let _ = std::fs::remove_dir_all(&root);
}

#[test]
fn sources_that_cannot_be_opened_fail_with_their_name() {
    let options = GlobeOptions {
        terrain: vec![SourceSpec::parse("/nonexistent/globus/dem").expect("spec")],
        ..GlobeOptions::default()
    };
    let err = match Offscreen::new(&options, 64, 64) {
        Ok(_) => panic!("opened a missing source"),
        Err(e) => format!("{e:#}"),
    };
    assert!(
        err.contains("/nonexistent/globus/dem") && err.contains("metadata.json"),
        "{err}"
    );
}

#[test]
fn quantized_mesh_terrain_matches_the_pyramid_it_was_meshed_from() {
    use globus_stream::TileSource;
    use globus_stream::decode::DecodeLimits;
    use globus_stream::fetch::{Cancel, HttpClient, HttpOptions};
    use globus_stream::open::{LayerKind, elevation_pyramid, open_layer};
    use std::sync::Arc;

    let root = common::scratch("real_earth", "quantized_mesh");
    let rgb = root.join("srtm");
    tile(
        JobKind::Dem {
            encoding: ElevationEncoding::Terrarium,
            height_scale: None,
        },
        "N57E011.hgt",
        &rgb,
        Some(7),
    );
    // Every level-7 tile meshed with a 1 m bound by `globus mesh`, written as Cesium lays
    // quantized-mesh out: TMS rows (geographic level 7 has 128 rows).
    let qm = root.join("qm");
    let mut meshed = 0;
    for x in std::fs::read_dir(rgb.join("7")).expect("level 7").flatten() {
        let xs = x.file_name().to_string_lossy().to_string();
        for y in std::fs::read_dir(x.path()).expect("ys").flatten() {
            let ys = y
                .file_name()
                .to_string_lossy()
                .trim_end_matches(".png")
                .to_string();
            let row: u32 = ys.parse().expect("row");
            let out = qm.join(format!("7/{xs}/{}.terrain", 127 - row));
            std::fs::create_dir_all(out.parent().expect("dir")).expect("mkdir");
            let o = common::globus(&[
                "mesh",
                "--in",
                common::s(&y.path()),
                "--encoding",
                "terrarium",
                "--max-error",
                "1",
                "--tile",
                &format!("7/{xs}/{ys}"),
                "--scheme",
                "geographic",
                "--out",
                common::s(&out),
            ]);
            assert!(o.status.success(), "{}", String::from_utf8_lossy(&o.stderr));
            meshed += 1;
        }
    }
    assert!(meshed >= 2);
    std::fs::write(
        qm.join("metadata.json"),
        r#"{"scheme": "geographic", "minzoom": 7, "maxzoom": 7, "bounds": [11, 57, 12, 58],
            "format": "terrain", "encoding": "quantized-mesh", "layout": "tms"}"#,
    )
    .expect("metadata");

    let server = FaultServer::serve_dir(&root);
    let http = Arc::new(HttpClient::new(HttpOptions::default()));
    let source = |url: String| {
        let layer = open_layer(
            &SourceSpec::parse(&url).expect("spec"),
            LayerKind::Elevation,
            &http,
            None,
        )
        .unwrap_or_else(|e| panic!("{url}: {e}"));
        let pyramid = elevation_pyramid(layer, DecodeLimits::default()).expect("pyramid");
        globus_stream::RasterTerrainSource::new(
            vec![pyramid],
            Vec::new(),
            Ellipsoid::WGS84,
            (-100.0, 500.0),
            globus_terrain::MeshOptions::default(),
        )
        .expect("source")
    };
    let from_qm = source(server.url("/qm"));
    let from_rgb = source(server.url("/srtm"));
    let cancel = Cancel::new();
    // Engine tiles at levels 7 and 8 over Gothenburg: the mesh vertices' heights agree with
    // the pyramid the meshes were cut from within the 1 m bound of the meshes (measured:
    // 0.01 m RMS, 0.11 m at worst; with rows read from the north instead, the tiles are not
    // found at all).
    let (mut worst, mut sum, mut n) = (0f64, 0f64, 0f64);
    for level in [7u8, 8] {
        let key = TilingScheme::Geographic
            .tile_at(11.95f64.to_radians(), 57.7f64.to_radians(), level)
            .expect("key");
        let a = from_qm.load(key, &cancel).expect("qm").expect("qm data");
        let b = from_rgb.load(key, &cancel).expect("rgb").expect("rgb data");
        for j in 0..=32 {
            for i in 0..=32 {
                let d = f64::from(a.tile.height_at(i, j) - b.tile.height_at(i, j)).abs();
                worst = worst.max(d);
                sum += d * d;
                n += 1.0;
            }
        }
        assert!(
            b.tile.max_height_m - b.tile.min_height_m > 20.0,
            "relief at level {level}"
        );
    }
    let rms = (sum / n).sqrt();
    assert!(
        rms < 0.25 && worst <= 1.0,
        "rms {rms:.2} m, worst {worst:.2} m"
    );
    assert!(server.count("/qm/7/") >= 1);
    let _ = std::fs::remove_dir_all(&root);
}
