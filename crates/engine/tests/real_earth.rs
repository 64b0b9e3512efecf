//! The real Earth streamed over HTTP from a server on 127.0.0.1: world topography and the
//! Blue Marble tiled by `globus tile` (the library, as in `tools/real-earth-demo.sh`), served
//! by a server that also injects faults, rendered on lavapipe. The picture must be complete
//! (no hole inside the silhouette), the continents where they are, and failed tiles must
//! leave their ancestors in place.

use std::path::Path;
use std::time::Duration;

use globus_engine::{
    CameraSpec, Cartographic, Ellipsoid, GlobeBuilder, Headless, SourceSpec, holes_inside, save_png,
};
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

/// World topography (Terrarium, heights scaled to metres) tiled to `max_level`.
fn tile_topography(out: &Path, max_level: u8) {
    tile(
        JobKind::Dem {
            encoding: ElevationEncoding::Terrarium,
            height_scale: Some(25.1),
        },
        "earth-topology-2048x1024.png",
        out,
        Some(max_level),
    );
}

#[test]
fn the_real_earth_streams_over_http_through_faults_and_completes() {
    let root = std::env::temp_dir().join(format!("globus-real-earth-{}", std::process::id()));
    let _ = std::fs::remove_dir_all(&root);
    tile_topography(&root.join("topo"), 3);
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
    server.add_fault("/topo/1/1/0.png", Fault::Status(503), Some(2));
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
    let mut builder = GlobeBuilder::new();
    builder
        .terrain(SourceSpec::parse(&server.url("/topo")).expect("spec"))
        .imagery(SourceSpec::parse(&server.url("/bmng")).expect("spec"));
    let (w, h) = (640, 360);
    let mut off = Headless::new(&builder, w, h).expect("a GPU or lavapipe, and the sources");
    let cam = CameraSpec {
        lon_deg: 10.0,
        lat_deg: 30.0,
        alt_m: 12_000_000.0,
        heading_deg: 0.0,
        pitch_deg: -90.0,
        above_ground: false,
    };
    let view = cam.view(off.globe(), 60.0, w, h);
    let frame = off
        .render_complete(&view, Duration::from_secs(120), &mut [])
        .expect("render");
    let dir = globus_test_support::output_dir("real_earth");
    save_png(&frame.image, &dir.join("earth_over_http.png")).expect("save");
    assert!(frame.complete, "tiles still loading");
    // The tile that never decodes is reported, once, by its layer; the retried ones are not.
    let failures = off.globe().layer_failures();
    assert_eq!(failures.len(), 2, "{failures:?}");
    let (topo, bmng) = (&failures[0], &failures[1]);
    assert!(
        topo.layer.contains("/topo/") && bmng.layer.contains("/bmng/"),
        "{failures:?}"
    );
    assert_eq!(topo.tiles, 1, "{topo:?}");
    assert_eq!(topo.by_kind.get("undecodable"), Some(&1), "{topo:?}");
    assert!(topo.first[0].contains("/topo/1/2/0.png"), "{topo:?}");
    assert_eq!(bmng.tiles, 0, "{bmng:?}");

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

    // Every fault was met: the transient ones got past (the visible tiles they hit were
    // asked again after them, by their own loads' retries: a neighbour reading its normal
    // ring across the edge never retries), the broken tile failed once and for all (asked
    // once: a ring read and the tiles' own loads share one request and its outcome), and
    // its ancestor filled its place in the complete picture above. Only the engine tiles
    // that read the broken one failed, so the others' data arrived: the four level-2 tiles
    // under it (a 256-pixel source tile feeds 128-sample engine tiles a level deeper). Most
    // runs count one, as the first failure blocks their parent's refinement and the others'
    // loads are cancelled; sometimes a second fails before it is (stop 33 took that for a
    // scheduler race: the server's count shows the source tile asked once all the same).
    let stats = off.globe().layer().scheduler_stats();
    assert!(stats.retries >= 1, "{stats:?}");
    // A failed tile still wanted is asked again after its 30 s cool-down (the pyramid
    // answers from its cache without a request), which a loaded CI machine can reach.
    let cool_downs = (frame.load_ms / 30_000.0).floor() as u64;
    assert_eq!(
        server.count("/topo/1/2/0.png") as u64,
        1 + cool_downs,
        "the broken tile asked once ({} ms)",
        frame.load_ms
    );
    assert!(
        (1..=4 * (1 + cool_downs)).contains(&stats.failed),
        "{stats:?} in {} ms",
        frame.load_ms
    );
    assert!(
        server.count("/topo/1/1/0.png") >= 3,
        "two 503s and then the tile"
    );
    // The reset was met. Whether the tile is asked again depends on who met it: a load of
    // its own retries it, but when a neighbour's ring read meets it first and no load of
    // the final view reads that tile itself, nobody needs it again (seen once in 5 runs
    // beside other tests). Either way it is not a failure (the layer's failures above).
    assert!(
        server.count("/topo/1/2/1.png") >= 1,
        "the reset was never met"
    );
    assert_eq!(server.count("/topo/1/2/0.png"), 1);
    assert_eq!(server.count("/bmng/0/1/0.jpg"), 2);
    assert!(frame.load_ms >= 1000.0, "Retry-After: 1 was honoured");
    let _ = std::fs::remove_dir_all(&root);
}

#[test]
fn sources_that_cannot_be_opened_fail_with_their_name() {
    let mut builder = GlobeBuilder::new();
    builder.terrain(SourceSpec::parse("/nonexistent/globus/dem").expect("spec"));
    let err = match Headless::new(&builder, 64, 64) {
        Ok(_) => panic!("opened a missing source"),
        Err(e) => format!("{e:#}"),
    };
    assert!(
        err.contains("/nonexistent/globus/dem") && err.contains("metadata.json"),
        "{err}"
    );
}

/// A terrain source whose separate colour loads wait until the gate opens (or they are
/// cancelled): imagery that is slow to arrive, under the test's control.
struct GatedImagery {
    inner: std::sync::Arc<dyn globus_stream::TerrainSource>,
    open: std::sync::atomic::AtomicBool,
}

impl globus_stream::TileSource for GatedImagery {
    type Tile = globus_stream::TerrainData;

    fn name(&self) -> &str {
        self.inner.name()
    }

    fn scheme(&self) -> TilingScheme {
        self.inner.scheme()
    }

    fn load(
        &self,
        key: globus_tiling::TileKey,
        cancel: &globus_stream::fetch::Cancel,
    ) -> Result<Option<Self::Tile>, globus_stream::SourceError> {
        self.inner.load(key, cancel)
    }

    fn byte_size(&self, tile: &Self::Tile) -> usize {
        tile.byte_size()
    }
}

impl globus_stream::TerrainSource for GatedImagery {
    fn ellipsoid(&self) -> &Ellipsoid {
        self.inner.ellipsoid()
    }

    fn occluder(&self) -> &Ellipsoid {
        self.inner.occluder()
    }

    fn height_range_m(&self) -> (f64, f64) {
        self.inner.height_range_m()
    }

    fn max_level(&self) -> u8 {
        self.inner.max_level()
    }

    fn load_colour(
        &self,
        data: &globus_stream::TerrainData,
        cancel: &globus_stream::fetch::Cancel,
    ) -> Result<Option<globus_terrain::ColourImage>, globus_stream::SourceError> {
        while !self.open.load(std::sync::atomic::Ordering::Acquire) {
            if cancel.is_cancelled() {
                return Err(globus_stream::SourceError::Cancelled { key: data.tile.key });
            }
            std::thread::sleep(Duration::from_millis(5));
        }
        self.inner.load_colour(data, cancel)
    }
}

/// Mean absolute difference of the colour channels of `a` and `b` (read `shift` pixels to
/// the right) averaged over 8 x 8 blocks, over blocks that are terrain in both: where the
/// pictures show the same things, whatever their sharpness.
fn block_difference(a: &globus_engine::RgbaImage, b: &globus_engine::RgbaImage, shift: u32) -> f64 {
    const B: u32 = 8;
    let mean = |img: &globus_engine::RgbaImage, x0: u32, y0: u32| {
        let mut sum = [0f64; 3];
        for y in y0..y0 + B {
            for x in x0..x0 + B {
                let i = ((y * img.width + x) * 4) as usize;
                if img.pixels[i + 3] != 255 {
                    return None;
                }
                (0..3).for_each(|c| sum[c] += f64::from(img.pixels[i + c]));
            }
        }
        Some(sum.map(|v| v / f64::from(B * B)))
    };
    let (mut total, mut n) = (0.0, 0.0);
    for by in 0..a.height / B {
        for bx in 0..(a.width - shift) / B {
            let (x, y) = (bx * B, by * B);
            if let (Some(p), Some(q)) = (mean(a, x, y), mean(b, x + shift, y)) {
                total += (0..3).map(|c| (p[c] - q[c]).abs()).sum::<f64>() / 3.0;
                n += 1.0;
            }
        }
    }
    total / f64::max(n, 1.0)
}

#[test]
fn tiles_whose_imagery_is_loading_show_their_ancestors_imagery_cropped() {
    use std::sync::Arc;
    use std::sync::atomic::Ordering;

    let root = globus_test_support::output_dir("real_earth").join("imagery_apart");
    let _ = std::fs::remove_dir_all(&root);
    tile_topography(&root.join("topo"), 2);
    // Imagery of level 0 only, in 128-pixel tiles (the Blue Marble shrunk to 256 x 128): the
    // roots' 128-texel colours hold its pixels exactly, and a deeper tile's own colour samples
    // the same pixels, so cropping a root's colour must give the tile's own picture.
    let world = image::open(shared_data("bmng-5400x2700.jpg"))
        .expect("the Blue Marble")
        .resize_exact(256, 128, image::imageops::FilterType::Triangle)
        .to_rgba8();
    for x in 0..2 {
        let dir = root.join(format!("bmng/0/{x}"));
        std::fs::create_dir_all(&dir).expect("mkdir");
        image::imageops::crop_imm(&world, x * 128, 0, 128, 128)
            .to_image()
            .save(dir.join("0.png"))
            .expect("tile");
    }
    let meta = serde_json::json!({
        "scheme": "geographic", "minzoom": 0, "maxzoom": 0, "tile_size": 128,
        "sample_grid": "cells", "format": "png", "layout": "xyz",
        "bounds": [-180.0, -90.0, 180.0, 90.0],
    });
    std::fs::write(root.join("bmng/metadata.json"), meta.to_string()).expect("metadata");
    let path = |p: &Path| p.to_str().expect("utf-8 path").to_owned();
    let mut builder = GlobeBuilder::new();
    builder
        .terrain(SourceSpec::parse(&path(&root.join("topo"))).expect("spec"))
        .imagery(SourceSpec::parse(&path(&root.join("bmng"))).expect("spec"));
    let gated = Arc::new(GatedImagery {
        inner: builder.open_source().expect("sources"),
        open: false.into(),
    });
    builder.source(gated.clone());
    let (w, h) = (480, 270);
    let mut off = Headless::new(&builder, w, h).expect("a GPU or lavapipe");
    let cam = CameraSpec {
        lon_deg: 12.0,
        lat_deg: 42.0,
        alt_m: 2_500_000.0,
        heading_deg: 0.0,
        pitch_deg: -90.0,
        above_ground: false,
    };
    let view = cam.view(off.globe(), 60.0, w, h);

    // Flat light and no air: the pictures are the imagery itself.
    let airless = globus_engine::Atmosphere::none(&off.globe().ellipsoid());
    off.globe_mut().set_atmosphere(airless);
    off.globe_mut().set_lighting(Some(globus_engine::Lighting {
        ambient: 1.0,
        inscatter_gain: 0.0,
        exposure: 1.0,
        ..globus_engine::Lighting::sun_over(0.0, 0.0)
    }));
    // Every tile's geometry, none of their imagery (except the roots', which comes with them).
    off.globe_mut().set_relax_detail(false);
    off.globe_mut().set_uploads_per_frame(u32::MAX);
    let deadline = std::time::Instant::now() + Duration::from_secs(60);
    let borrowed = loop {
        let report = off.update(&view);
        if report.wanted == 0 {
            break report;
        }
        assert!(
            std::time::Instant::now() < deadline,
            "terrain never completed"
        );
        off.globe_mut()
            .layer_mut()
            .wait_for_tiles(Duration::from_millis(50));
    };
    let before = off.draw_and_read(&mut []).expect("render");
    let dir = globus_test_support::output_dir("real_earth");
    save_png(&before, &dir.join("imagery_loading.png")).expect("save");
    let d = borrowed.draw;
    assert!(d.tiles > 8, "{d:?}");
    assert_eq!(
        d.borrowed_colour, d.tiles,
        "every tile below the roots borrows: {d:?}"
    );
    assert_eq!(d.missing_colour, 0);
    assert_eq!(borrowed.colours_pending, d.tiles);
    let (inside, holes) = holes_inside(&before, &view, &Ellipsoid::WGS84.grown(-16_000.0));
    assert!(inside > 10_000 && holes == 0, "{holes} holes of {inside}");

    // The imagery arrives: every tile shows its own.
    gated.open.store(true, Ordering::Release);
    let frame = off
        .render_complete(&view, Duration::from_secs(60), &mut [])
        .expect("render");
    save_png(&frame.image, &dir.join("imagery_loaded.png")).expect("save");
    assert!(frame.complete);
    assert_eq!(
        frame.report.draw.borrowed_colour, 0,
        "{:?}",
        frame.report.draw
    );
    assert_eq!(frame.report.colours_pending, 0);

    // The borrowed picture is the loaded one: far closer to it than the loaded picture is to
    // itself moved by 4 pixels. Measured on lavapipe: 0.78 against 3.62; a crop half a root
    // texel (0.7 degrees) off gives 3.22, one swapping u and v 26.
    let same = block_difference(&before, &frame.image, 0);
    let moved = block_difference(&frame.image, &frame.image, 4);
    assert!(
        same < 0.35 * moved,
        "borrowed vs own {same:.2}, own vs own moved 4 px {moved:.2}"
    );
    let _ = std::fs::remove_dir_all(&root);
}
