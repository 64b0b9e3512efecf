//! PMTiles archives read back by the `pmtiles` Python package, tile by tile against the
//! same pyramid written as a directory.

#![allow(clippy::unwrap_used)] // test helpers: a failure should stop the test

mod common;

use std::process::Command;

use common::*;
use globus_tiler::{ElevationEncoding, ImageFormat, JobKind};
use globus_tiling::TilingScheme;

fn read_back(
    archive: &std::path::Path,
    dir: &std::path::Path,
    ext: &str,
    offset: u8,
) -> serde_json::Value {
    let script = std::path::Path::new(env!("CARGO_MANIFEST_DIR")).join("tests/read_pmtiles.py");
    let out = Command::new("python3")
        .arg(script)
        .arg(archive)
        .arg(dir)
        .arg(ext)
        .arg(offset.to_string())
        .output()
        .expect("python3 with the pmtiles package (pip install pmtiles)");
    assert!(
        out.status.success(),
        "{}",
        String::from_utf8_lossy(&out.stderr)
    );
    serde_json::from_slice(&out.stdout).unwrap()
}

fn build_both(
    kind: JobKind,
    input: &str,
    scheme: TilingScheme,
    max: u8,
    name: &str,
) -> (std::path::PathBuf, std::path::PathBuf) {
    let dir = fresh("tiler_pmtiles", name);
    let archive = fresh("tiler_pmtiles", &format!("{name}.pmtiles"));
    let mut j = job(kind, &[shared_data(input)], &dir, scheme);
    j.max_level = Some(max);
    globus_tiler::run(&j).unwrap();
    j.output = archive.clone();
    let s = globus_tiler::run(&j).unwrap();
    assert!(s.tiles > 0);
    assert!(!archive.with_extension("pmtiles.partial").exists());
    (dir, archive)
}

#[test]
fn web_mercator_imagery_reads_back_tile_for_tile() {
    let kind = JobKind::Imagery {
        format: ImageFormat::Jpeg { quality: 80 },
    };
    let (dir, archive) = build_both(
        kind,
        "bmng-5400x2700.jpg",
        TilingScheme::WebMercator,
        4,
        "bmng-mercator",
    );
    let v = read_back(&archive, &dir, "jpg", 0);
    assert_eq!(v["tiles"], 1 + 4 + 16 + 64 + 256, "{v}");
    assert_eq!(v["min_zoom"], 0);
    assert_eq!(v["max_zoom"], 4);
    assert_eq!(v["tile_type"], 3, "JPEG");
    assert_eq!(v["clustered"], true);
    assert_eq!(v["metadata"]["scheme"], "webmercator");
    assert_eq!(v["bounds_e7"][0], -1_800_000_000);
    assert_eq!(v["bounds_e7"][3], 850_511_288);
}

#[test]
fn geographic_elevation_is_stored_one_level_down() {
    let kind = JobKind::Dem {
        encoding: ElevationEncoding::Terrarium,
        height_scale: None,
    };
    let (dir, archive) = build_both(
        kind,
        "N57E011.hgt",
        TilingScheme::Geographic,
        8,
        "srtm-geographic",
    );
    let v = read_back(&archive, &dir, "png", 1);
    assert_eq!(v["min_zoom"], 1);
    assert_eq!(v["max_zoom"], 9);
    assert_eq!(v["tile_type"], 2, "PNG");
    assert_eq!(v["metadata"]["pmtiles_level_offset"], 1);
    assert_eq!(v["metadata"]["encoding"], "terrarium");
    assert_eq!(v["metadata"]["sample_grid"], "corners");
    assert!(v["tiles"].as_u64().unwrap() > 10, "{v}");
}

#[test]
fn archives_are_byte_identical_whatever_the_thread_count() {
    let mut files = Vec::new();
    for threads in [1, 2] {
        let archive = fresh("tiler_pmtiles", &format!("det-{threads}.pmtiles"));
        let mut j = job(
            JobKind::Imagery {
                format: ImageFormat::Png,
            },
            &[shared_data("bmng-5400x2700.jpg")],
            &archive,
            TilingScheme::Geographic,
        );
        j.max_level = Some(3);
        j.threads = Some(threads);
        globus_tiler::run(&j).unwrap();
        files.push(std::fs::read(&archive).unwrap());
    }
    assert!(files[0] == files[1]);
}

#[test]
fn large_archives_use_leaf_directories_that_clients_follow() {
    use globus_tiler::sink::{DirSink, PmTilesSink, PyramidMetadata, TileLayout, TileSink};
    use globus_tiling::{GeoRect, TileKey};
    // About 26,000 distinct small tiles scattered over level 8 (irregular IDs and lengths do
    // not compress away): too many entries for a 16 KiB root directory.
    let scheme = TilingScheme::WebMercator;
    let dir = fresh("tiler_pmtiles", "many");
    let archive = fresh("tiler_pmtiles", "many.pmtiles");
    let dsink = DirSink::create(&dir, scheme, TileLayout::Xyz, "png").unwrap();
    let psink = PmTilesSink::create(&archive, scheme).unwrap();
    let mut count = 0;
    for y in 0..256u32 {
        for x in 0..256u32 {
            let h = x.wrapping_mul(2_654_435_761) ^ y.wrapping_mul(40_503);
            if h % 5 >= 2 {
                continue;
            }
            count += 1;
            let key = TileKey::new(8, x, y);
            let bytes = format!("tile 8/{x}/{y} {}", "#".repeat((h % 41) as usize)).into_bytes();
            dsink.put(key, &bytes).unwrap();
            psink.put(key, &bytes).unwrap();
        }
    }
    let meta = PyramidMetadata {
        name: "many".into(),
        format: "png".into(),
        kind: "imagery".into(),
        encoding: None,
        scheme,
        tile_size: 256,
        sample_grid: "cells".into(),
        bounds: GeoRect::from_degrees(-180.0, 0.0, 180.0, 85.0),
        min_level: 8,
        max_level: 8,
    };
    psink.finish(&meta).unwrap();
    let v = read_back(&archive, &dir, "png", 0);
    assert_eq!(v["tiles"], count, "{v}");
    assert!(count > 20_000);
    assert!(v["leaf_directory_length"].as_u64().unwrap() > 0, "{v}");
}
