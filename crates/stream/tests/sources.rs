//! Tile sources against real files and a real HTTP server on 127.0.0.1: the same pyramid
//! (the SRTM tile N57E011 through `globus tile`) read from a directory, MBTiles, PMTiles on
//! disk and PMTiles over HTTP range requests; a served directory with every fault injected.

use std::path::{Path, PathBuf};
use std::sync::Arc;
use std::time::{Duration, Instant};

use globus_geo::Ellipsoid;
use globus_stream::decode::DecodeLimits;
use globus_stream::fetch::{Cancel, HttpClient, HttpOptions};
use globus_stream::open::{
    DEFAULT_LAYER_CACHE_BYTES, ElevationFormat, LayerKind, SourceSpec, elevation_pyramid,
    open_layer,
};
use globus_stream::pyramid::SampleGrid;
use globus_stream::{
    Outcome, RasterTerrainSource, RetryPolicy, Scheduler, SchedulerOptions, SystemClock,
    TerrainSource, TileSource,
};
use globus_terrain::MeshOptions;
use globus_test_support::http::{Fault, FaultServer};
use globus_test_support::shared_data;
use globus_tiler::{ElevationEncoding, JobKind, TileJob};
use globus_tiling::{GLOBE_SCHEME, TileKey, TileRequest, TilingScheme};

const MAX_LEVEL: u8 = 7;

/// Tiles N57E011.hgt (geographic, Terrarium, levels 0-7) into `out` (a directory or an
/// archive) once per test process.
fn tile_srtm(out: &Path) {
    let job = TileJob {
        max_level: Some(MAX_LEVEL),
        threads: Some(2),
        ..TileJob::new(
            JobKind::Dem {
                encoding: ElevationEncoding::Terrarium,
                height_scale: None,
            },
            vec![shared_data("N57E011.hgt")],
            out.to_path_buf(),
        )
    };
    globus_tiler::run(&job).unwrap_or_else(|e| panic!("tiling into {}: {e}", out.display()));
}

fn scratch(name: &str) -> PathBuf {
    let d = std::env::temp_dir().join(format!("globus-sources-{name}-{}", std::process::id()));
    let _ = std::fs::remove_dir_all(&d);
    std::fs::create_dir_all(&d).expect("scratch dir");
    d
}

/// Every tile key present in a `{z}/{x}/{y}.png` directory.
fn keys_in(dir: &Path) -> Vec<TileKey> {
    let mut keys = Vec::new();
    for z in 0..=MAX_LEVEL {
        let Ok(xs) = std::fs::read_dir(dir.join(z.to_string())) else {
            continue;
        };
        for x in xs.flatten() {
            let xn: u32 = x.file_name().to_string_lossy().parse().expect("x");
            for y in std::fs::read_dir(x.path()).expect("ys").flatten() {
                let name = y.file_name().to_string_lossy().to_string();
                let yn: u32 = name.trim_end_matches(".png").parse().expect("y");
                keys.push(TileKey::new(z, xn, yn));
            }
        }
    }
    keys.sort();
    keys
}

fn client(options: HttpOptions) -> Arc<HttpClient> {
    Arc::new(HttpClient::new(options))
}

#[test]
fn directory_mbtiles_pmtiles_and_pmtiles_over_http_serve_the_same_tiles() {
    let base = scratch("containers");
    let dir = base.join("dem");
    tile_srtm(&dir);
    tile_srtm(&base.join("dem.mbtiles"));
    tile_srtm(&base.join("dem.pmtiles"));
    let server = FaultServer::serve_dir(&base);
    let http = client(HttpOptions::default());

    let specs = [
        dir.display().to_string(),
        base.join("dem.mbtiles").display().to_string(),
        base.join("dem.pmtiles").display().to_string(),
        server.url("/dem.pmtiles"),
        server.url("/dem"),
    ];
    let layers: Vec<_> = specs
        .iter()
        .map(|s| {
            let spec = SourceSpec::parse(s).expect("spec");
            open_layer(&spec, LayerKind::Elevation, &http, None)
                .unwrap_or_else(|e| panic!("{s}: {e}"))
        })
        .collect();
    for (s, l) in specs.iter().zip(&layers) {
        assert_eq!(l.spec.scheme, TilingScheme::Geographic, "{s}");
        assert_eq!((l.spec.min_level, l.spec.max_level), (0, MAX_LEVEL), "{s}");
        assert_eq!(l.spec.grid, SampleGrid::Corners, "{s}");
        assert_eq!(l.spec.tile_size, 256, "{s}");
        assert_eq!(
            l.encoding,
            Some(ElevationFormat::Rgb(ElevationEncoding::Terrarium)),
            "{s}"
        );
        let b = l.spec.bounds.to_degrees();
        assert!(
            (b[0] - 11.0).abs() < 0.01 && (b[3] - 58.0).abs() < 0.01,
            "{s}: {b:?}"
        );
    }

    let keys = keys_in(&dir);
    assert!(keys.len() >= 10, "{keys:?}");
    let cancel = Cancel::new();
    let ranges_before = server.count("/dem.pmtiles");
    for &k in &keys {
        let want = std::fs::read(dir.join(format!("{}/{}/{}.png", k.level(), k.x(), k.y())))
            .expect("tile file");
        for (s, l) in specs.iter().zip(&layers) {
            let got = l
                .fetch
                .fetch(k, &cancel)
                .unwrap_or_else(|e| panic!("{s} {k}: {e}"));
            assert_eq!(got.map(|f| f.bytes), Some(want.clone()), "{s} tile {k}");
        }
    }
    // A tile that was never written: no data, from every container.
    let empty = TileKey::new(5, 0, 0);
    for (s, l) in specs.iter().zip(&layers) {
        assert_eq!(l.fetch.fetch(empty, &cancel), Ok(None), "{s}");
    }
    // PMTiles over HTTP: one range request per tile (the root directory was read on
    // opening), each with a Range header.
    let pm: Vec<_> = server
        .requests()
        .into_iter()
        .filter(|r| r.target == "/dem.pmtiles")
        .collect();
    assert!(pm.iter().all(|r| {
        r.headers
            .get("range")
            .is_some_and(|v| v.starts_with("bytes="))
    }));
    assert_eq!(server.count("/dem.pmtiles") - ranges_before, keys.len());
    // Every request named Globus.
    assert!(server.requests().iter().all(|r| {
        r.headers
            .get("user-agent")
            .is_some_and(|u| u.starts_with("Globus/"))
    }));
    let _ = std::fs::remove_dir_all(&base);
}

fn describe(o: &Outcome<globus_stream::TerrainData>) -> String {
    match o {
        Outcome::Loaded(d) => format!(
            "loaded, heights {:.0}..{:.0} m",
            d.tile.min_height_m, d.tile.max_height_m
        ),
        Outcome::NoData => "no data".into(),
        Outcome::Failed(e) => format!("failed: {e}"),
    }
}

/// Loads `keys` through a scheduler until each has an outcome (or a deadline passes).
fn load_all(
    source: Arc<RasterTerrainSource>,
    keys: &[TileKey],
    retry: RetryPolicy,
) -> Vec<(TileKey, Outcome<globus_stream::TerrainData>)> {
    let s = Scheduler::with_clock(
        source,
        SchedulerOptions { workers: 4, retry },
        Arc::new(SystemClock::default()),
    );
    let requests: Vec<TileRequest> = keys
        .iter()
        .map(|&key| TileRequest { key, priority: 1.0 })
        .collect();
    let mut out = Vec::new();
    let deadline = Instant::now() + Duration::from_secs(60);
    while out.len() < keys.len() && Instant::now() < deadline {
        // The engine resubmits what it still wants every frame.
        let done: Vec<TileKey> = out.iter().map(|(k, _)| *k).collect();
        let wanted: Vec<TileRequest> = requests
            .iter()
            .filter(|r| !done.contains(&r.key))
            .copied()
            .collect();
        s.submit(&wanted);
        out.extend(s.wait_one(Duration::from_millis(50)));
    }
    out
}

#[test]
fn every_fault_ends_as_a_counted_tile_failure_and_the_rest_completes() {
    let base = scratch("faults");
    tile_srtm(&base.join("dem"));
    let dir = base.join("dem");
    let server = FaultServer::serve_dir(&base);
    server.set_latency(Duration::from_millis(5));
    let http = client(HttpOptions {
        read_timeout: Duration::from_millis(400),
        response_timeout: Duration::from_secs(2),
        total_timeout: Duration::from_secs(5),
        ..HttpOptions::default()
    });
    let layer = open_layer(
        &SourceSpec::parse(&server.url("/dem")).expect("spec"),
        LayerKind::Elevation,
        &http,
        None,
    )
    .expect("served directory");
    let pyramid = elevation_pyramid(layer, DecodeLimits::default(), DEFAULT_LAYER_CACHE_BYTES)
        .expect("pyramid");
    let source = Arc::new(
        RasterTerrainSource::new(
            vec![pyramid],
            Vec::new(),
            Ellipsoid::WGS84,
            (-100.0, 500.0),
            MeshOptions::default(),
        )
        .expect("source"),
    );

    // The pyramid's tiles that are engine tiles too (reduced rows at 57 N span two columns:
    // an engine tile reads its own data tile and the one to its east, never faulted).
    let keys: Vec<TileKey> = keys_in(&dir)
        .into_iter()
        .filter(|k| GLOBE_SCHEME.is_valid(*k))
        .collect();
    let url = |k: TileKey| format!("/dem/{}/{}/{}.png", k.level(), k.x(), k.y());
    // One fault per tile, on the deeper tiles; the rest load normally.
    let faults = [
        (Fault::Status(500), Some(1), "recovers"),
        (
            Fault::RetryAfter {
                status: 429,
                secs: 1,
            },
            Some(1),
            "recovers",
        ),
        (Fault::Reset, Some(2), "recovers"),
        (Fault::Status(404), None, "no data"),
        (Fault::Status(503), None, "fails"),
        (Fault::Truncate, None, "fails"),
        (Fault::NotAnImage, None, "fails"),
        (Fault::AbsurdImage, None, "fails"),
        (Fault::Stall(Duration::from_secs(3)), None, "fails"),
    ];
    let faulty: Vec<TileKey> = keys.iter().rev().take(faults.len()).copied().collect();
    for (k, (fault, times, _)) in faulty.iter().zip(&faults) {
        server.add_fault(&url(*k), fault.clone(), *times);
    }
    let retry = RetryPolicy {
        max_attempts: 3,
        base_delay: Duration::from_millis(20),
        ..RetryPolicy::default()
    };
    let started = Instant::now();
    let out = load_all(Arc::clone(&source), &keys, retry);
    assert_eq!(out.len(), keys.len(), "every tile ends somehow");
    let outcome = |k: TileKey| &out.iter().find(|(key, _)| *key == k).expect("outcome").1;
    for (k, (fault, _, expect)) in faulty.iter().zip(&faults) {
        let o = outcome(*k);
        let ok = match *expect {
            "recovers" => matches!(o, Outcome::Loaded(_)),
            "no data" => matches!(o, Outcome::NoData),
            _ => matches!(o, Outcome::Failed(e) if e.to_string().contains(&format!("{k}"))),
        };
        assert!(ok, "{fault:?} on {k}: {}", describe(o));
    }
    // Every other tile loaded.
    for k in keys.iter().filter(|k| !faulty.contains(k)) {
        assert!(
            matches!(outcome(*k), Outcome::Loaded(_)),
            "{k}: {}",
            describe(outcome(*k))
        );
    }
    // Retry-After was honoured (a second or more), permanent faults were asked once,
    // transient ones three times by their own tile's load (and at most once more when a
    // neighbouring tile read its normal ring across the edge before that load began: such
    // reads never retry, leave a failing tile alone for a while, and share a request
    // already under way), 404 once (and it is remembered by the layer above).
    let requests_for = |k: TileKey| server.count(&url(k));
    assert!(started.elapsed() >= Duration::from_secs(1));
    assert_eq!(requests_for(faulty[1]), 2);
    assert_eq!(requests_for(faulty[3]), 1);
    let always_503 = requests_for(faulty[4]);
    assert!(
        (3..=4).contains(&always_503),
        "503 asked {always_503} times"
    );
    assert_eq!(requests_for(faulty[6]), 1);
    assert_eq!(requests_for(faulty[7]), 1);
    if let Outcome::Failed(e) = outcome(faulty[7]) {
        assert!(e.to_string().contains("60000 x 60000"), "{e}");
    }
    let _ = std::fs::remove_dir_all(&base);
}

#[test]
fn requests_per_host_stay_under_the_limit() {
    let server = FaultServer::in_memory();
    for i in 0..32 {
        server.put(&format!("/t/{i}"), vec![7u8; 1000]);
    }
    server.set_latency(Duration::from_millis(50));
    let http = client(HttpOptions {
        per_host: 4,
        headers: vec![("X-Api-Key".into(), "secret".into())],
        ..HttpOptions::default()
    });
    std::thread::scope(|s| {
        for i in 0..32 {
            let http = Arc::clone(&http);
            let url = server.url(&format!("/t/{i}"));
            s.spawn(move || {
                let got = http
                    .get(&url, None, &Cancel::new())
                    .expect("get")
                    .expect("body");
                assert_eq!(got.fetched.bytes.len(), 1000);
            });
        }
    });
    assert!(server.max_concurrent() <= 4, "{}", server.max_concurrent());
    assert!(server.max_concurrent() >= 3, "{}", server.max_concurrent());
    assert!(
        server
            .requests()
            .iter()
            .all(|r| r.headers.get("x-api-key").map(String::as_str) == Some("secret"))
    );
}

#[test]
fn a_cancelled_download_stops_mid_body() {
    let server = FaultServer::in_memory();
    server.put("/big", vec![1u8; 4 << 20]);
    server.add_fault("/big", Fault::Stall(Duration::from_secs(5)), None);
    let http = client(HttpOptions::default());
    let cancel = Cancel::new();
    let c2 = cancel.clone();
    let t = Instant::now();
    std::thread::spawn(move || {
        std::thread::sleep(Duration::from_millis(200));
        c2.cancel();
    });
    // The stall outlasts the cancellation; the read returns when the read timeout fires at
    // the latest, but a cancelled token is never reported as data.
    let r = http.get(&server.url("/big"), None, &cancel);
    assert!(
        r.is_err(),
        "{:?}",
        r.map(|b| b.map(|b| b.fetched.bytes.len()))
    );
    assert!(t.elapsed() < Duration::from_secs(11));
}

#[test]
fn terrain_tiles_from_a_pyramid_carry_its_heights() {
    let base = scratch("heights");
    let dir = base.join("dem");
    tile_srtm(&dir);
    let http = client(HttpOptions::default());
    let layer = open_layer(
        &SourceSpec::parse(&dir.display().to_string()).expect("spec"),
        LayerKind::Elevation,
        &http,
        None,
    )
    .expect("dir");
    let pyramid = elevation_pyramid(layer, DecodeLimits::default(), DEFAULT_LAYER_CACHE_BYTES)
        .expect("pyramid");
    let source = RasterTerrainSource::new(
        vec![pyramid],
        Vec::new(),
        Ellipsoid::WGS84,
        (-100.0, 500.0),
        MeshOptions::default(),
    )
    .expect("source");
    // Level 7 data in 256-sample tiles: real detail down to engine level 10.
    assert_eq!(source.max_level(), 10);
    let cancel = Cancel::new();
    // The level-10 tile holding 57.7 N 11.95 E (Gothenburg): the Swedish west coast (0-200 m),
    // real relief (not flat), and an error bound that is measured, not zero.
    let key = GLOBE_SCHEME
        .tile_at(11.95f64.to_radians(), 57.7f64.to_radians(), 10)
        .expect("key");
    let columns = GLOBE_SCHEME.columns(10, key.y());
    assert_eq!(columns, GLOBE_SCHEME.columns(10, key.y() + 1));
    let t = source.load(key, &cancel).expect("load").expect("data");
    assert!(
        t.tile.min_height_m >= -50.0 && t.tile.max_height_m < 400.0,
        "{:?}",
        (t.tile.min_height_m, t.tile.max_height_m)
    );
    assert!(t.tile.max_height_m - t.tile.min_height_m > 20.0);
    assert!(
        t.tile.geometric_error_m > 0.5 && t.tile.geometric_error_m < 200.0,
        "{}",
        t.tile.geometric_error_m
    );
    // The ring of heights one mesh cell outside the tile is the neighbours' own samples
    // (read from the pyramid, not extrapolated), so normals at shared edges agree: the
    // east ring column of this tile is the second column of its eastern neighbour, the
    // south ring row the second row of its southern one.
    let g = globus_terrain::grid::HEIGHT_GRID_SIDE;
    let at = |t: &globus_stream::TerrainData, i: usize, j: usize| t.tile.heights_m[j * g + i];
    let east = source
        .load(TileKey::new(10, key.x() + columns, key.y()), &cancel)
        .expect("load")
        .expect("east neighbour");
    let south = source
        .load(TileKey::new(10, key.x(), key.y() + 1), &cancel)
        .expect("load")
        .expect("south neighbour");
    let (mut worst, mut extrapolated_gap): (f32, f32) = (0.0, 0.0);
    for k in 1..g - 1 {
        // Ring column g - 1 of this tile against column 2 of the east one (column 1 is
        // the shared edge), same row.
        worst = worst.max((at(&t, g - 1, k) - at(&east, 2, k)).abs());
        worst = worst.max((at(&t, k, g - 1) - at(&south, k, 2)).abs());
        // What extrapolating the outermost cell's slope would have given.
        let guess = 2.0 * at(&t, g - 2, k) - at(&t, g - 3, k);
        extrapolated_gap = extrapolated_gap.max((guess - at(&east, 2, k)).abs());
    }
    assert!(
        worst < 0.01,
        "ring differs from the neighbours' samples by {worst} m"
    );
    assert!(
        extrapolated_gap > 1.0,
        "extrapolation would have matched too ({extrapolated_gap} m): the check proves nothing"
    );
    // Deeper than the data: no data (refinement takes over); outside the SRTM square at
    // level 5: no data either (nothing finer than the mesh there).
    assert!(
        source
            .load(TileKey::new(11, key.x() * 2, key.y() * 2), &cancel)
            .expect("load")
            .is_none()
    );
    assert!(
        source
            .load(TileKey::new(5, 0, 0), &cancel)
            .expect("load")
            .is_none()
    );
    let _ = std::fs::remove_dir_all(&base);
}

#[test]
fn the_disk_cache_serves_a_second_session_with_the_server_down() {
    use globus_stream::fetch::{CachedFetch, DiskCacheOptions, Fetch, TemplateFetch};
    let base = scratch("diskcache");
    let dir = base.join("dem");
    tile_srtm(&dir);
    let keys = keys_in(&dir);
    let cache_dir = base.join("cache");
    let options = |max_bytes| DiskCacheOptions {
        dir: cache_dir.clone(),
        max_bytes,
        default_fresh_for: Duration::from_secs(86_400),
    };
    let http = client(HttpOptions {
        connect_timeout: Duration::from_millis(500),
        ..HttpOptions::default()
    });
    let session = |server: &FaultServer, max_bytes| {
        let template = format!("{}/{{z}}/{{x}}/{{y}}.png", server.url("/dem"));
        let f = TemplateFetch::new(Arc::clone(&http), &template, &[], TilingScheme::Geographic)
            .expect("template");
        CachedFetch::new(Box::new(f), options(max_bytes)).expect("cache")
    };
    let cancel = Cancel::new();
    let want = |k: TileKey| {
        std::fs::read(dir.join(format!("{}/{}/{}.png", k.level(), k.x(), k.y()))).expect("tile")
    };

    // Fresh for an hour: a second session does not ask the server at all.
    let fresh = FaultServer::serve_dir(&base);
    fresh.set_cache_control(Some("public, max-age=3600"));
    let first = session(&fresh, 1 << 30);
    for &k in &keys {
        assert_eq!(
            first.fetch(k, &cancel).expect("fetch").map(|f| f.bytes),
            Some(want(k))
        );
    }
    let asked = fresh.count("/dem/");
    let second = session(&fresh, 1 << 30);
    for &k in &keys {
        assert_eq!(
            second.fetch(k, &cancel).expect("fetch").map(|f| f.bytes),
            Some(want(k))
        );
    }
    assert_eq!(
        fresh.count("/dem/"),
        asked,
        "fresh entries are served from disk"
    );
    assert_eq!(second.stats().fresh_hits, keys.len() as u64);

    // `no-cache`: stale at once, so a session online asks again, and a session with the
    // server gone serves the stale copies (and knows what has no data).
    let _ = std::fs::remove_dir_all(&cache_dir);
    let revalidate = FaultServer::serve_dir(&base);
    revalidate.set_cache_control(Some("no-cache"));
    let layer_spec = SourceSpec::parse(&revalidate.url("/dem")).expect("spec");
    let online = open_layer(
        &layer_spec,
        LayerKind::Elevation,
        &http,
        Some(&options(1 << 30)),
    )
    .expect("open online");
    let empty = TileKey::new(5, 0, 0);
    for &k in keys.iter().chain([&empty]) {
        let _ = online.fetch.fetch(k, &cancel).expect("fetch");
    }
    let warm = session(&revalidate, 1 << 30);
    let _ = warm.fetch(keys[0], &cancel).expect("fetch");
    assert_eq!(
        warm.stats().misses,
        1,
        "a no-cache entry is fetched again while online"
    );
    drop(revalidate);

    let offline = open_layer(
        &layer_spec,
        LayerKind::Elevation,
        &http,
        Some(&options(1 << 30)),
    )
    .expect("the layer opens offline from the cached metadata");
    assert_eq!(offline.spec.max_level, MAX_LEVEL);
    for &k in &keys {
        let got = offline.fetch.fetch(k, &cancel);
        assert_eq!(
            got.expect("served stale").map(|f| f.bytes),
            Some(want(k)),
            "{k}"
        );
    }
    assert_eq!(offline.fetch.fetch(empty, &cancel), Ok(None));
    // A tile never fetched is a transient failure offline, not a panic or "no data".
    let never = TileKey::new(7, 0, 0);
    assert!(matches!(
        offline.fetch.fetch(never, &cancel),
        Err(globus_stream::fetch::FetchError::Transient { .. })
    ));

    // The size cap holds: a cache capped at half the pyramid keeps recent tiles and no more.
    let _ = std::fs::remove_dir_all(&cache_dir);
    let pyramid_bytes: u64 = keys.iter().map(|&k| want(k).len() as u64).sum();
    let cap = pyramid_bytes / 2;
    let capped_server = FaultServer::serve_dir(&base);
    let capped = session(&capped_server, cap);
    for &k in &keys {
        let _ = capped.fetch(k, &cancel).expect("fetch");
    }
    let on_disk: u64 = walk_bytes(&cache_dir);
    assert!(on_disk <= cap, "{on_disk} bytes on disk, cap {cap}");
    assert!(capped.stats().evicted > 0);
    // The last tile fetched is still there.
    let last = *keys.last().expect("keys");
    let before = capped_server.count("/dem/");
    let _ = capped.fetch(last, &cancel).expect("fetch");
    assert_eq!(capped_server.count("/dem/"), before);
    let _ = std::fs::remove_dir_all(&base);
}

#[test]
fn a_pmtiles_archive_over_http_opens_offline_from_the_disk_cache_and_is_dropped_when_it_changes() {
    use globus_stream::fetch::{DiskCacheOptions, FetchError};
    let base = scratch("pm-diskcache");
    let dir = base.join("dem");
    tile_srtm(&dir);
    tile_srtm(&base.join("dem.pmtiles"));
    let keys = keys_in(&dir);
    let want = |k: TileKey| {
        std::fs::read(dir.join(format!("{}/{}/{}.png", k.level(), k.x(), k.y()))).expect("tile")
    };
    let options = DiskCacheOptions {
        dir: base.join("cache"),
        max_bytes: 1 << 30,
        default_fresh_for: Duration::from_secs(86_400),
    };
    let http = client(HttpOptions {
        connect_timeout: Duration::from_millis(500),
        ..HttpOptions::default()
    });
    let server = FaultServer::serve_dir(&base);
    let spec = SourceSpec::parse(&server.url("/dem.pmtiles")).expect("spec");
    let open = || open_layer(&spec, LayerKind::Elevation, &http, Some(&options));
    let cancel = Cancel::new();

    // First session: every tile but the last by a range request, kept on disk.
    let (last, kept) = keys.split_last().expect("keys");
    let first = open().expect("open online");
    for &k in kept {
        let got = first.fetch.fetch(k, &cancel).expect("fetch");
        assert_eq!(got.map(|f| f.bytes), Some(want(k)), "{k}");
    }
    // Second session online: opening reads the archive's head again (to see whether it
    // changed), the tiles come from disk without one range request.
    let second = open().expect("open again");
    let opened = server.count("/dem.pmtiles");
    for &k in kept {
        let got = second.fetch.fetch(k, &cancel).expect("fetch");
        assert_eq!(got.map(|f| f.bytes), Some(want(k)), "{k}");
    }
    assert_eq!(
        server.count("/dem.pmtiles"),
        opened,
        "tiles served from disk"
    );

    // The archive replaced (Mapbox encoding now) under the same URL: the tiles kept from
    // the old one are dropped and the new archive's are served.
    let changed = base.join("changed.pmtiles");
    let job = TileJob {
        max_level: Some(MAX_LEVEL),
        threads: Some(2),
        ..TileJob::new(
            JobKind::Dem {
                encoding: ElevationEncoding::Mapbox,
                height_scale: None,
            },
            vec![shared_data("N57E011.hgt")],
            changed.clone(),
        )
    };
    globus_tiler::run(&job).expect("tiling the new archive");
    let local = open_layer(
        &SourceSpec::parse(&changed.display().to_string()).expect("spec"),
        LayerKind::Elevation,
        &http,
        None,
    )
    .expect("the new archive on disk");
    let new_tile = |k: TileKey| {
        local
            .fetch
            .fetch(k, &cancel)
            .expect("local")
            .map(|f| f.bytes)
    };
    assert!(
        new_tile(kept[0]) != Some(want(kept[0])),
        "the archives differ"
    );
    std::fs::rename(&changed, base.join("dem.pmtiles")).expect("replace");
    let renewed = open().expect("open the new archive");
    assert_eq!(
        renewed.encoding,
        Some(ElevationFormat::Rgb(ElevationEncoding::Mapbox))
    );
    for &k in kept {
        let got = renewed.fetch.fetch(k, &cancel).expect("fetch");
        assert!(
            got.map(|f| f.bytes) == new_tile(k),
            "{k}: not the new archive's tile"
        );
    }

    // The server gone: the archive opens from the kept head, same layout, every tile
    // fetched before is there.
    drop(server);
    let offline = open().expect("the archive opens offline");
    assert_eq!(offline.spec, renewed.spec);
    assert_eq!(offline.encoding, renewed.encoding);
    for &k in kept {
        let got = offline.fetch.fetch(k, &cancel).expect("served from disk");
        assert!(
            got.map(|f| f.bytes) == new_tile(k),
            "{k}: not the new archive's tile"
        );
    }
    // A tile of the archive never fetched is a transient failure offline (asked again
    // later); one the kept directory says is not in the archive is "no data".
    assert!(matches!(
        offline.fetch.fetch(*last, &cancel),
        Err(FetchError::Transient { .. })
    ));
    assert_eq!(
        offline.fetch.fetch(TileKey::new(7, 0, 0), &cancel),
        Ok(None)
    );
    let _ = std::fs::remove_dir_all(&base);
}

fn walk_bytes(dir: &Path) -> u64 {
    let mut total = 0;
    for e in std::fs::read_dir(dir).into_iter().flatten().flatten() {
        let m = e.metadata().expect("metadata");
        total += if m.is_dir() {
            walk_bytes(&e.path())
        } else {
            m.len()
        };
    }
    total
}

/// Writes a synthetic `{z}/{x}/{y}.png` pyramid with its metadata.json.
#[allow(clippy::too_many_arguments)]
fn write_pyramid(
    dir: &Path,
    scheme: TilingScheme,
    max_level: u8,
    size: u32,
    grid: &str,
    encoding: Option<&str>,
    skip: &[TileKey],
    region: Option<globus_tiling::GeoRect>,
    pixel: impl Fn(TileKey, u32, u32) -> [u8; 4],
) {
    for z in 0..=max_level {
        for x in 0..scheme.tiles_x(z) as u32 {
            for y in 0..scheme.tiles_y(z) as u32 {
                let key = TileKey::new(z, x, y);
                let r = scheme.rect(key);
                let outside = region.is_some_and(|g| {
                    r.east <= g.west || r.west >= g.east || r.north <= g.south || r.south >= g.north
                });
                if skip.contains(&key) || outside {
                    continue;
                }
                let mut px = Vec::with_capacity((size * size * 4) as usize);
                for j in 0..size {
                    for i in 0..size {
                        px.extend_from_slice(&pixel(key, i, j));
                    }
                }
                let path = dir.join(format!("{z}/{x}/{y}.png"));
                std::fs::create_dir_all(path.parent().expect("dir")).expect("mkdir");
                let file = std::fs::File::create(&path).expect("create");
                let mut enc = png::Encoder::new(std::io::BufWriter::new(file), size, size);
                enc.set_color(png::ColorType::Rgba);
                enc.set_depth(png::BitDepth::Eight);
                let mut w = enc.write_header().expect("header");
                w.write_image_data(&px).expect("pixels");
            }
        }
    }
    let bounds = region.map_or([-180.0, -90.0, 180.0, 90.0], |g| g.to_degrees());
    let meta = serde_json::json!({
        "scheme": scheme.name(), "minzoom": 0, "maxzoom": max_level, "tile_size": size,
        "sample_grid": grid, "encoding": encoding, "format": "png", "layout": "xyz",
        "bounds": bounds,
    });
    std::fs::write(dir.join("metadata.json"), meta.to_string()).expect("metadata");
}

/// Terrain from the server's `/dem` pyramid draped with its `/img` pyramid (heights 0-200 m).
fn dem_and_imagery(server: &FaultServer, http: HttpOptions) -> RasterTerrainSource {
    use globus_stream::open::imagery_pyramid;
    let http = client(http);
    let open = |path: &str, kind| {
        open_layer(
            &SourceSpec::parse(&server.url(path)).expect("spec"),
            kind,
            &http,
            None,
        )
        .expect("layer")
    };
    let dem = elevation_pyramid(
        open("/dem", LayerKind::Elevation),
        DecodeLimits::default(),
        DEFAULT_LAYER_CACHE_BYTES,
    )
    .expect("dem");
    let img = imagery_pyramid(
        open("/img", LayerKind::Imagery),
        DecodeLimits::default(),
        DEFAULT_LAYER_CACHE_BYTES,
    );
    RasterTerrainSource::new(
        vec![dem],
        vec![img],
        Ellipsoid::WGS84,
        (0.0, 200.0),
        MeshOptions::default(),
    )
    .expect("source")
}

/// A geographic Terrarium pyramid of 256-sample corner grids to `max_level`, flat at 100 m.
fn write_flat_dem(dir: &Path, max_level: u8) {
    let terrarium = ElevationEncoding::Terrarium.encode(100.0);
    write_pyramid(
        dir,
        TilingScheme::Geographic,
        max_level,
        256,
        "corners",
        Some("terrarium"),
        &[],
        None,
        |_, _, _| [terrarium[0], terrarium[1], terrarium[2], 255],
    );
}

/// A solid colour naming a tile: red = 20 * level, green = x, blue = y.
fn key_colour(k: TileKey) -> [u8; 4] {
    [
        20 * k.level(),
        (k.x() % 256) as u8,
        (k.y() % 256) as u8,
        255,
    ]
}

/// The texel at the centre of the north-west quadrant.
fn quadrant_texel(c: &globus_terrain::ColourImage) -> [u8; 3] {
    let s = c.size as usize;
    let i = ((s / 4) * s + s / 4) * 4;
    [c.mips[0][i], c.mips[0][i + 1], c.mips[0][i + 2]]
}

#[test]
fn imagery_deeper_than_terrain_reaches_refined_tiles_and_falls_back_to_ancestors() {
    use globus_stream::RefinedSource;
    use globus_terrain::refine::RefineOptions;

    let base = scratch("imagery-depth");
    // Elevation to level 2 (a flat 100 m), imagery in 64-pixel tiles to level 8 (over six
    // degrees square only): each imagery tile one colour.
    write_flat_dem(&base.join("dem"), 2);
    let region = globus_tiling::GeoRect::from_degrees(8.0, 54.0, 14.0, 60.0);
    let geo = TilingScheme::Geographic;
    let engine = |lon: f64, lat: f64| {
        GLOBE_SCHEME
            .tile_at(lon.to_radians(), lat.to_radians(), 7)
            .expect("key")
    };
    let (a, b, c) = (engine(10.0, 58.5), engine(11.5, 58.5), engine(10.0, 57.0));
    // The level-8 imagery tile under the texel `quadrant_texel` reads (a quarter of the way
    // into the tile, which at 58 N spans two geographic columns).
    let nw = |k: TileKey| {
        let (lon, lat) = GLOBE_SCHEME
            .rect(k)
            .lon_lat_at(0.25 + 0.5 / 128.0, 0.25 + 0.5 / 128.0);
        geo.tile_at(lon, lat, 8).expect("imagery key")
    };
    // Holes: one imagery tile missing, one broken (not an image).
    let (missing, broken) = (nw(b), nw(c));
    write_pyramid(
        &base.join("img"),
        geo,
        8,
        64,
        "cells",
        None,
        &[missing],
        Some(region),
        |k, _, _| key_colour(k),
    );
    std::fs::write(
        base.join(format!("img/8/{}/{}.png", broken.x(), broken.y())),
        b"<html>oops</html>",
    )
    .expect("broken tile");
    let server = FaultServer::serve_dir(&base);
    let raster = dem_and_imagery(&server, HttpOptions::default());
    // Elevation data ends at engine level 5 (256-sample level-2 tiles); refinement below.
    assert_eq!(raster.max_level(), 5);
    let refined = RefinedSource::new(
        Arc::new(raster),
        RefineOptions::default(),
        12,
        MeshOptions::default(),
    );
    let cancel = Cancel::new();
    let imagery_requests = |level: u8| server.count(&format!("/img/{level}/"));
    // 64-pixel imagery at level 8 matches 128-texel engine tiles at level 7: a texel in the
    // north-west quadrant of engine tile 7/x/y shows the level-8 imagery tile under it, real
    // colour, two levels below the terrain's data.
    for (key, want_from) in [
        (a, nw(a)),
        // Missing: the level-7 imagery tile over it, cropped and scaled.
        (b, b),
        // Broken: the same, and it was asked for once only.
        (c, c),
    ] {
        // The refined geometry comes without waiting for the deeper imagery: that is a
        // load of its own.
        let before = imagery_requests(8);
        let t = refined.load(key, &cancel).expect("load").expect("tile");
        assert!(t.generated, "{key} is refined below the data");
        assert!(t.colour_separate, "{key}: its imagery loads on its own");
        assert_eq!(
            imagery_requests(8),
            before,
            "{key}: the geometry waited for level-8 imagery"
        );
        let colour = refined
            .load_colour(&t, &cancel)
            .expect("colour")
            .expect("imagery here");
        let want = key_colour(want_from);
        assert_eq!(
            quadrant_texel(&colour),
            [want[0], want[1], want[2]],
            "{key}"
        );
    }
    let _ = refined.load(c, &cancel).expect("again");
    // Outside the imagery's region the refined colour comes with the tile.
    let outside = refined
        .load(engine(30.0, 40.0), &cancel)
        .expect("load")
        .expect("tile");
    assert!(!outside.colour_separate && outside.tile.colour.size > 1);
    assert_eq!(
        server.count(&format!("/img/8/{}/{}.png", broken.x(), broken.y())),
        1
    );
    let _ = std::fs::remove_dir_all(&base);
}

#[test]
fn web_mercator_imagery_leaves_no_hole_or_smear_at_the_poles() {
    use globus_stream::open::imagery_pyramid;

    let base = scratch("poles");
    // Web Mercator imagery whose top rows alternate red and green pixels and whose bottom
    // rows are white: the caps must be the even mix, not the streaks of a stretched row.
    write_pyramid(
        &base.join("merc"),
        TilingScheme::WebMercator,
        2,
        256,
        "cells",
        None,
        &[],
        None,
        |_, i, j| match j {
            0..=1 if i % 2 == 0 => [255, 0, 0, 255],
            0..=1 => [0, 255, 0, 255],
            254..=255 => [255, 255, 255, 255],
            _ => [0, 0, 128, 255],
        },
    );
    let http = client(HttpOptions::default());
    let layer = open_layer(
        &SourceSpec::parse(&base.join("merc").display().to_string()).expect("spec"),
        LayerKind::Imagery,
        &http,
        None,
    )
    .expect("layer");
    let source = RasterTerrainSource::new(
        Vec::new(),
        vec![imagery_pyramid(
            layer,
            DecodeLimits::default(),
            DEFAULT_LAYER_CACHE_BYTES,
        )],
        Ellipsoid::WGS84,
        (0.0, 0.0),
        MeshOptions::default(),
    )
    .expect("source");
    assert_eq!(source.max_level(), 2);
    let cancel = Cancel::new();
    for (key, want) in [
        // Geographic level 2 tiles touching the north and south poles (45..90 degrees).
        // (Engine tiles: the polar rows span two columns.)
        (TileKey::new(2, 2, 0), [128u8, 128, 0]),
        (TileKey::new(2, 4, 3), [255, 255, 255]),
    ] {
        let t = source.load(key, &cancel).expect("load").expect("tile");
        // Below the roots imagery is a load of its own.
        assert!(t.colour_separate && t.tile.colour.size == 1, "{key}");
        let c = &source
            .load_colour(&t, &cancel)
            .expect("colour")
            .expect("imagery there");
        let s = c.size as usize;
        // Texel rows beyond 86.05 degrees (the limit plus the blend): the top (or bottom)
        // 128 * (90 - 86.06) / 45 = 11 rows, the rows nearest the pole first.
        for row in 0..11 {
            let r = if key.y() == 0 { row } else { s - 1 - row };
            for col in (0..s).step_by(7) {
                let i = (r * s + col) * 4;
                let got = [c.mips[0][i], c.mips[0][i + 1], c.mips[0][i + 2]];
                for k in 0..3 {
                    assert!(
                        got[k].abs_diff(want[k]) <= 2,
                        "{key} row {r} col {col}: {got:?} vs cap {want:?}"
                    );
                }
            }
        }
    }
    let _ = std::fs::remove_dir_all(&base);
}

#[test]
fn wms_and_subdomain_templates_against_a_loopback_server() {
    use globus_stream::fetch::{Fetch, TemplateFetch, WmsFetch, WmsVersion};
    let server = FaultServer::in_memory();
    let mut png = Vec::new();
    {
        let mut enc = png::Encoder::new(&mut png, 4, 4);
        enc.set_color(png::ColorType::Rgba);
        enc.set_depth(png::BitDepth::Eight);
        let mut w = enc.write_header().expect("header");
        w.write_image_data(&[200u8; 64]).expect("pixels");
    }
    server.put("/wms", png.clone());
    server.put(
        "/broken-wms",
        br#"<?xml version="1.0"?><ServiceExceptionReport><ServiceException>Layer not defined</ServiceException></ServiceExceptionReport>"#.to_vec(),
    );
    let http = client(HttpOptions::default());
    let cancel = Cancel::new();
    let wms = WmsFetch::new(
        Arc::clone(&http),
        &server.url("/wms"),
        "relief",
        WmsVersion::V1_3_0,
        TilingScheme::Geographic,
        "image/png",
        256,
    )
    .expect("wms");
    // Geographic level 2, x 5, y 1: lon 45..90 E, lat 0..45 N; 1.3.0 puts latitude first.
    let got = wms
        .fetch(TileKey::new(2, 5, 1), &cancel)
        .expect("fetch")
        .expect("bytes");
    assert_eq!(got.bytes, png);
    let target = server.requests().last().expect("request").target.clone();
    assert!(
        target.starts_with("/wms?SERVICE=WMS&REQUEST=GetMap&VERSION=1.3.0"),
        "{target}"
    );
    assert!(
        target.contains("CRS=EPSG:4326&BBOX=0,45,45,90&WIDTH=256&HEIGHT=256"),
        "{target}"
    );
    let broken = WmsFetch::new(
        Arc::clone(&http),
        &server.url("/broken-wms"),
        "relief",
        WmsVersion::V1_1_1,
        TilingScheme::Geographic,
        "image/png",
        256,
    )
    .expect("wms");
    let e = broken
        .fetch(TileKey::new(2, 5, 1), &cancel)
        .unwrap_err()
        .to_string();
    assert!(e.contains("XML") && e.contains("Layer not defined"), "{e}");

    // `{s}` over two names of the loopback host: both are used, each tile always the same.
    server.put("/t/3/4/2.png", png.clone());
    server.put("/t/3/5/2.png", png.clone());
    let port = server.url("").rsplit(':').next().expect("port").to_string();
    let t = TemplateFetch::new(
        Arc::clone(&http),
        &format!("http://{{s}}:{port}/t/{{z}}/{{x}}/{{y}}.png"),
        &["127.0.0.1", "localhost"],
        TilingScheme::Geographic,
    )
    .expect("template");
    for _ in 0..2 {
        for x in [4, 5] {
            assert!(
                t.fetch(TileKey::new(3, x, 2), &cancel)
                    .expect("fetch")
                    .is_some()
            );
        }
    }
    let hosts: Vec<String> = server
        .requests()
        .iter()
        .filter(|r| r.target.starts_with("/t/"))
        .map(|r| {
            format!(
                "{} {}",
                r.target,
                r.headers.get("host").cloned().unwrap_or_default()
            )
        })
        .collect();
    assert_eq!(hosts.len(), 4);
    assert_eq!(hosts[0], hosts[2], "tile 3/4/2 goes to the same host twice");
    assert_ne!(
        hosts[0].split(' ').nth(1).map(|h| h.split(':').next()),
        hosts[1].split(' ').nth(1).map(|h| h.split(':').next()),
        "neighbouring tiles go to different hosts: {hosts:?}"
    );
}

#[test]
fn imagery_loads_on_its_own_after_the_terrain_it_drapes() {
    use globus_stream::{TerrainLayer, TerrainLayerOptions, TileColour};
    use globus_tiling::{DrawTile, TileRequest};

    let base = scratch("imagery-apart");
    write_flat_dem(&base.join("dem"), 1);
    write_pyramid(
        &base.join("img"),
        TilingScheme::Geographic,
        3,
        64,
        "cells",
        None,
        &[],
        None,
        |k, _, _| key_colour(k),
    );
    let server = FaultServer::serve_dir(&base);
    // Imagery is slow; one tile's imagery stalls for good (the first matching rule holds).
    let stalled = TileKey::new(3, 12, 2);
    server.add_fault(
        &format!("/img/3/{}/{}.png", stalled.x(), stalled.y()),
        Fault::Delay(Duration::from_secs(30)),
        None,
    );
    server.add_fault("/img/", Fault::Delay(Duration::from_millis(300)), None);
    // A response that does not start within 2 s ends the load (the wait for headers is not
    // interruptible; reads are).
    let source = dem_and_imagery(
        &server,
        HttpOptions {
            response_timeout: Duration::from_secs(2),
            ..HttpOptions::default()
        },
    );
    let mut layer = TerrainLayer::new(
        Arc::new(source),
        TerrainLayerOptions {
            cache_bytes: 64 << 20,
            workers: 2,
        },
    );
    layer.track_usage();
    // 128-texel engine tiles at level 2 take 64-pixel imagery of level 3: the north-west
    // quadrant of 2/4/1 is imagery tile 3/8/2.
    let (tile, other) = (TileKey::new(2, 4, 1), TileKey::new(2, 6, 1));
    let wanted = [tile, other].map(|key| TileRequest {
        key,
        priority: 10.0,
    });
    let deadline = Instant::now() + Duration::from_secs(20);
    while layer.get(tile).is_none() || layer.get(other).is_none() {
        assert!(Instant::now() < deadline, "terrain never arrived");
        layer.update(&[], &[], &wanted);
        layer.wait_for_tiles(Duration::from_millis(50));
    }
    // The geometry came although the other tile's imagery stalls: it did not wait for it.
    assert!(matches!(layer.colour(other), Some(TileColour::Loading)));

    // Drawn, the tiles' colours are asked for and arrive on their own.
    let drawn = [tile, other].map(|key| DrawTile {
        key,
        sse_px: 4.0,
        distance_m: 1e6,
        morph: 1.0,
        parts: globus_tiling::Quadrants::ALL,
    });
    while !matches!(layer.colour(tile), Some(TileColour::Ready(_))) {
        assert!(Instant::now() < deadline, "imagery never arrived");
        layer.update(&drawn, &[tile, other], &[]);
        layer.wait_for_tiles(Duration::from_millis(50));
    }
    let Some(TileColour::Ready(colour)) = layer.colour(tile) else {
        unreachable!()
    };
    let want = key_colour(TileKey::new(3, 8, 2));
    assert_eq!(quadrant_texel(colour), [want[0], want[1], want[2]]);
    let colour_bytes = colour.byte_size();
    let stats = layer.update(&drawn, &[tile, other], &[]);
    assert_eq!(layer.usage().map(|u| u.colours_loaded), Some(1));
    let data_bytes: usize = [tile, other]
        .iter()
        .map(|&k| layer.get(k).expect("loaded").byte_size())
        .sum();
    assert_eq!(
        stats.cached_bytes,
        data_bytes + colour_bytes,
        "the colour counts in the budget"
    );
    // The other tile's imagery (3/12/2 stalls) is still loading, its terrain long drawn.
    assert!(matches!(layer.colour(other), Some(TileColour::Loading)));
    assert_eq!(stats.colours_loading, 1);

    // Nobody draws it any more: its colour load is cancelled, not left to finish.
    let before = layer.colour_scheduler_stats();
    layer.update(&[], &[], &[]);
    let after = layer.colour_scheduler_stats();
    assert_eq!(
        after.cancelled + after.cancelled_in_flight,
        before.cancelled + before.cancelled_in_flight + 1,
        "{after:?}"
    );
    let deadline = Instant::now() + Duration::from_secs(10);
    while layer.colours_loading() > 0 {
        assert!(
            Instant::now() < deadline,
            "cancelled colour load still running"
        );
        layer.update(&[], &[], &[]);
        std::thread::sleep(Duration::from_millis(20));
    }
    assert!(matches!(layer.colour(other), Some(TileColour::Loading)));
    let _ = std::fs::remove_dir_all(&base);
}
