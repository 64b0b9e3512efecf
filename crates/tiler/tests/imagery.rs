//! Imagery pyramids from the Blue Marble world image: tiles against crops of the source,
//! MBTiles read with the sqlite3 client, determinism and resuming.

#![allow(clippy::unwrap_used)] // test helpers: a failure should stop the test

mod common;

use std::process::Command;

use common::*;
use globus_tiler::{ImageFormat, JobKind};
use globus_tiling::TilingScheme;

fn png() -> JobKind {
    JobKind::Imagery {
        format: ImageFormat::Png,
    }
}

fn bmng() -> Vec<std::path::PathBuf> {
    vec![shared_data("bmng-5400x2700.jpg")]
}

/// The source image, decoded here independently.
fn source() -> image::RgbImage {
    image::open(shared_data("bmng-5400x2700.jpg"))
        .expect("../shared/data/bmng-5400x2700.jpg")
        .into_rgb8()
}

/// Mean absolute difference per channel between tile pixels and a reference function.
fn mean_diff(tile: &image::RgbaImage, reference: impl Fn(u32, u32) -> [f64; 3]) -> f64 {
    let mut sum = 0.0;
    for (i, j, p) in tile.enumerate_pixels() {
        let r = reference(i, j);
        for c in 0..3 {
            sum += (f64::from(p[c]) - r[c]).abs();
        }
    }
    sum / f64::from(tile.width() * tile.height() * 3)
}

#[test]
fn tiles_match_crops_of_the_source() {
    let src = source();
    let (w, h) = (f64::from(src.width()), f64::from(src.height()));
    let out = fresh("tiler_imagery", "geographic");
    let mut j = job(png(), &bmng(), &out, TilingScheme::Geographic);
    j.max_level = Some(4);
    globus_tiler::run(&j).unwrap();
    // Level 4: 11.25-degree tiles, 0.044 degrees per pixel, finer than the source's 0.067:
    // compare with the source interpolated bilinearly at each pixel centre.
    // Tile 4/17/4 covers 11.25..22.5 E, 33.75..45 N (Italy, the Balkans).
    let tile = decode_rgba(&out.join("4/17/4.png"));
    let bilinear = |lon: f64, lat: f64| {
        let x = ((lon + 180.0) / 360.0 * w - 0.5).clamp(0.0, w - 1.0);
        let y = ((90.0 - lat) / 180.0 * h - 0.5).clamp(0.0, h - 1.0);
        let (x0, y0) = (x.floor(), y.floor());
        let (fx, fy) = (x - x0, y - y0);
        let px = |xx: f64, yy: f64| src.get_pixel(xx.min(w - 1.0) as u32, yy.min(h - 1.0) as u32);
        let mut out = [0.0; 3];
        for (c, o) in out.iter_mut().enumerate() {
            let top = f64::from(px(x0, y0)[c]) * (1.0 - fx) + f64::from(px(x0 + 1.0, y0)[c]) * fx;
            let bot = f64::from(px(x0, y0 + 1.0)[c]) * (1.0 - fx)
                + f64::from(px(x0 + 1.0, y0 + 1.0)[c]) * fx;
            *o = top * (1.0 - fy) + bot * fy;
        }
        out
    };
    let d = mean_diff(&tile, |i, jj| {
        let lon = 11.25 + (f64::from(i) + 0.5) / 256.0 * 11.25;
        let lat = 45.0 - (f64::from(jj) + 0.5) / 256.0 * 11.25;
        bilinear(lon, lat)
    });
    eprintln!("mean |difference| {d}");
    assert!(d < 0.5, "level 4 mean |difference| {d}");
    // Level 1: 90-degree tiles, 5.27 source pixels per tile pixel, built by three rounds of
    // 2x2 averaging from level 4: compare with the plain area mean of the source.
    let tile = decode_rgba(&out.join("1/2/0.png"));
    let d = mean_diff(&tile, |i, jj| {
        let (x0, x1) = (
            (f64::from(i) / 256.0 * 1350.0) as u32 + 2700,
            (f64::from(i + 1) / 256.0 * 1350.0) as u32 + 2700,
        );
        let (y0, y1) = (
            (f64::from(jj) / 256.0 * 1350.0) as u32,
            (f64::from(jj + 1) / 256.0 * 1350.0) as u32,
        );
        let mut acc = [0.0; 3];
        let mut n = 0.0;
        for y in y0..y1.max(y0 + 1) {
            for x in x0..x1.max(x0 + 1) {
                let p = src.get_pixel(x, y);
                for c in 0..3 {
                    acc[c] += f64::from(p[c]);
                }
                n += 1.0;
            }
        }
        acc.map(|a| a / n)
    });
    eprintln!("mean |difference| {d}");
    assert!(d < 2.0, "level 1 mean |difference| {d}");
    // A misplaced tile would compare a different region: check that the test can tell.
    let wrong = decode_rgba(&out.join("1/1/0.png"));
    let d_wrong = mean_diff(&wrong, |i, jj| {
        let p = tile.get_pixel(i, jj);
        [f64::from(p[0]), f64::from(p[1]), f64::from(p[2])]
    });
    assert!(d_wrong > 10.0, "{d_wrong}");
}

#[test]
fn web_mercator_tiles_are_reprojected() {
    let src = source();
    let out = fresh("tiler_imagery", "mercator");
    let mut j = job(png(), &bmng(), &out, TilingScheme::WebMercator);
    j.max_level = Some(3);
    globus_tiler::run(&j).unwrap();
    // Mercator level 3 tile 4/2 spans 0..45 E and 40.98..66.51 N; its rows are evenly
    // spaced in Mercator y, so row j's latitude follows the inverse Gudermannian.
    let tile = decode_rgba(&out.join("3/4/2.png"));
    let d = mean_diff(&tile, |i, jj| {
        let lon = (f64::from(i) + 0.5) / 256.0 * 45.0;
        let f = (2.0 + (f64::from(jj) + 0.5) / 256.0) / 8.0;
        let lat = (std::f64::consts::PI * (1.0 - 2.0 * f))
            .sinh()
            .atan()
            .to_degrees();
        // Nearest source pixel is enough at 3.4 source pixels per tile pixel.
        let p = src.get_pixel(
            ((lon + 180.0) / 360.0 * 5400.0) as u32,
            ((90.0 - lat) / 180.0 * 2700.0) as u32,
        );
        [f64::from(p[0]), f64::from(p[1]), f64::from(p[2])]
    });
    eprintln!("mean |difference| {d}");
    assert!(d < 4.0, "mean |difference| {d}");
}

fn sqlite(db: &std::path::Path, sql: &str) -> String {
    let out = Command::new("sqlite3")
        .arg(db)
        .arg(sql)
        .output()
        .expect("the sqlite3 client (Debian package sqlite3)");
    assert!(
        out.status.success(),
        "{}",
        String::from_utf8_lossy(&out.stderr)
    );
    String::from_utf8(out.stdout).unwrap()
}

#[test]
fn mbtiles_follow_the_spec_and_match_the_directory() {
    let dir = fresh("tiler_imagery", "mb-dir");
    let db = fresh("tiler_imagery", "bmng.mbtiles");
    let mut j = job(png(), &bmng(), &dir, TilingScheme::Geographic);
    j.max_level = Some(3);
    let s_dir = globus_tiler::run(&j).unwrap();
    j.output = db.clone();
    j.threads = Some(1);
    let s_db = globus_tiler::run(&j).unwrap();
    assert_eq!(s_dir.tiles, s_db.tiles);
    assert!(!db.with_extension("mbtiles.partial").exists());
    let schema = sqlite(&db, ".schema");
    for needle in [
        "CREATE TABLE metadata (name TEXT",
        "CREATE TABLE tiles (",
        "zoom_level INTEGER",
        "tile_column INTEGER",
        "tile_row INTEGER",
        "tile_data BLOB",
    ] {
        assert!(schema.contains(needle), "{needle} missing in\n{schema}");
    }
    let meta = sqlite(
        &db,
        "SELECT name || '=' || value FROM metadata ORDER BY name;",
    );
    for line in [
        "format=png",
        "minzoom=0",
        "maxzoom=3",
        "name=bmng-5400x2700",
        "bounds=-180.000000,-90.000000,180.000000,90.000000",
        "type=baselayer",
        "scheme=geographic",
    ] {
        assert!(meta.lines().any(|l| l == line), "{line} missing in\n{meta}");
    }
    let count = sqlite(&db, "SELECT count(*) FROM tiles;");
    assert_eq!(count.trim(), s_db.tiles.to_string());
    // Geographic level 3 has 16 x 8 tiles (2 + 8 + 32 + 128 = 170 in all).
    assert_eq!(s_db.tiles, 170);
    // tile_row counts from the south: XYZ row 2 at level 3 (8 rows) is TMS row 5.
    let hex = sqlite(
        &db,
        "SELECT hex(tile_data) FROM tiles WHERE zoom_level = 3 AND tile_column = 9 AND tile_row = 5;",
    );
    let file = std::fs::read(dir.join("3/9/2.png")).unwrap();
    let file_hex: String = file.iter().map(|b| format!("{b:02X}")).collect();
    assert_eq!(hex.trim(), file_hex);
}

#[test]
fn output_is_identical_whatever_the_thread_count() {
    let mut trees = Vec::new();
    let mut dbs = Vec::new();
    for threads in [1, 2] {
        let dir = fresh("tiler_imagery", &format!("det-{threads}"));
        let mut j = job(
            JobKind::Imagery {
                format: ImageFormat::Jpeg { quality: 80 },
            },
            &bmng(),
            &dir,
            TilingScheme::WebMercator,
        );
        j.max_level = Some(3);
        j.threads = Some(threads);
        globus_tiler::run(&j).unwrap();
        trees.push(read_tree(&dir));
        let db = fresh("tiler_imagery", &format!("det-{threads}.mbtiles"));
        j.output = db.clone();
        globus_tiler::run(&j).unwrap();
        dbs.push(std::fs::read(&db).unwrap());
    }
    assert_eq!(trees[0].len(), 85 + 1);
    assert!(trees[0] == trees[1], "directory trees differ");
    assert!(dbs[0] == dbs[1], "MBTiles files differ");
}

#[test]
fn resume_completes_an_interrupted_run_with_the_same_tiles() {
    let dir = fresh("tiler_imagery", "resume");
    let mut j = job(png(), &bmng(), &dir, TilingScheme::Geographic);
    j.max_level = Some(3);
    let first = globus_tiler::run(&j).unwrap();
    let complete = read_tree(&dir);
    // Simulate an interruption as it happens: tiles are written children first, so what is
    // missing is the metadata (written last), the roots, and the tiles above and beside the
    // last ones written; the very last one was cut short.
    for gone in [
        "metadata.json",
        "0/1/0.png",
        "1/2/0.png",
        "1/3/1.png",
        "2/4/1.png",
        "3/9/2.png",
    ] {
        std::fs::remove_file(dir.join(gone)).unwrap();
    }
    std::fs::write(dir.join("3/9/3.png"), b"\x89PNG\r\n").unwrap();
    j.force = false;
    j.resume = true;
    let second = globus_tiler::run(&j).unwrap();
    assert!(second.tiles < first.tiles / 2, "{second:?}");
    assert!(second.tiles_reused > 0, "{second:?}");
    let resumed = read_tree(&dir);
    assert_eq!(
        complete.keys().collect::<Vec<_>>(),
        resumed.keys().collect::<Vec<_>>()
    );
    for (k, v) in &complete {
        assert!(resumed[k] == *v, "{k} differs after resuming");
    }
}

#[test]
fn webp_and_tms_outputs_hold_the_same_pixels() {
    let png_dir = fresh("tiler_imagery", "fmt-png");
    let webp_dir = fresh("tiler_imagery", "fmt-webp-tms");
    let mut j = job(png(), &bmng(), &png_dir, TilingScheme::Geographic);
    j.max_level = Some(2);
    globus_tiler::run(&j).unwrap();
    j.output = webp_dir.clone();
    j.kind = JobKind::Imagery {
        format: ImageFormat::Webp,
    };
    j.layout = globus_tiler::TileLayout::Tms;
    globus_tiler::run(&j).unwrap();
    // Level 2 has 4 rows: XYZ row 1 is TMS row 2. Both formats are lossless.
    let a = decode_rgba(&png_dir.join("2/3/1.png"));
    let b = decode_rgba(&webp_dir.join("2/3/2.webp"));
    assert!(a == b, "WebP tile differs from the PNG tile");
    let meta: serde_json::Value =
        serde_json::from_slice(&std::fs::read(webp_dir.join("metadata.json")).unwrap()).unwrap();
    assert_eq!(meta["layout"], "tms");
    assert_eq!(meta["format"], "webp");
}

/// The progress callback sees the count grow to the job's total of tiles, from 0 to what it
/// writes, and the library writes nothing to the terminal itself.
#[test]
fn progress_reaches_the_total_through_the_callback() {
    let dir = fresh("tiler_imagery", "progress");
    let mut j = job(png(), &bmng(), &dir, TilingScheme::WebMercator);
    j.max_level = Some(4);
    let reports = std::sync::Mutex::new(Vec::new());
    let summary =
        globus_tiler::run_with_progress(&j, &|p| reports.lock().unwrap().push(*p)).unwrap();
    let reports = reports.into_inner().unwrap();
    let last = reports.last().expect("at least the final report");
    // Levels 0 to 4 of Web Mercator: 1 + 4 + 16 + 64 + 256 tiles.
    assert_eq!((last.tiles_done, last.tiles_total), (341, 341));
    assert_eq!(summary.tiles, 341);
    assert!(last.bytes > 0 && last.bytes == summary.bytes);
    assert!(
        reports
            .windows(2)
            .all(|w| w[0].tiles_done <= w[1].tiles_done && w[0].elapsed <= w[1].elapsed)
    );
}
