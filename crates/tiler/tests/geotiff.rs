//! GeoTIFF inputs written by GDAL (Debian gdal-bin) from the shared data: tiled and striped,
//! Deflate and LZW, i16 and f32, EPSG:4326 and EPSG:3857, nodata, and a CRS we refuse.

#![allow(clippy::unwrap_used)] // test helpers: a failure should stop the test

mod common;

use std::path::{Path, PathBuf};
use std::process::Command;

use common::*;
use globus_tiler::{ElevationEncoding, ImageFormat, JobKind};
use globus_tiling::TilingScheme;

/// Runs a GDAL tool, writing `out` under the test's folder.
fn gdal(tool: &str, args: &[&str], out: &str) -> PathBuf {
    let path = output_dir("tiler_geotiff").join(out);
    let _ = std::fs::remove_file(&path);
    let status = Command::new(tool)
        .args(["-q"])
        .args(args)
        .arg(&path)
        .status()
        .unwrap_or_else(|e| panic!("{tool} (Debian package gdal-bin): {e}"));
    assert!(status.success(), "{tool} {args:?}");
    path
}

fn dem() -> JobKind {
    JobKind::Dem {
        encoding: ElevationEncoding::Mapbox,
        height_scale: None,
    }
}

fn tiles_of(
    input: &Path,
    kind: JobKind,
    scheme: TilingScheme,
    max: u8,
    name: &str,
) -> (globus_tiler::Summary, PathBuf) {
    let out = fresh("tiler_geotiff", name);
    let mut j = job(kind, &[input.to_owned()], &out, scheme);
    j.max_level = Some(max);
    let s = globus_tiler::run(&j).unwrap();
    std::fs::remove_file(out.join("metadata.json")).unwrap();
    (s, out)
}

#[test]
fn srtm_as_geotiff_gives_the_same_tiles_as_the_hgt_file() {
    let hgt = shared_data("N57E011.hgt");
    let hgt_str = hgt.to_str().unwrap();
    let (_, reference) = tiles_of(&hgt, dem(), TilingScheme::Geographic, 9, "ref-hgt");
    let reference = read_tree(&reference);
    let variants = [
        (
            gdal(
                "gdal_translate",
                &["-co", "TILED=YES", "-co", "COMPRESS=DEFLATE", hgt_str],
                "tiled-deflate-i16.tif",
            ),
            "tiled",
        ),
        (
            gdal(
                "gdal_translate",
                &["-ot", "Float32", "-co", "COMPRESS=LZW", hgt_str],
                "striped-lzw-f32.tif",
            ),
            "striped",
        ),
        (
            gdal(
                "gdal_translate",
                &["-ot", "Int16", hgt_str],
                "striped-raw-i16.tif",
            ),
            "raw",
        ),
        (
            gdal(
                "gdal_translate",
                &[
                    "-co",
                    "TILED=YES",
                    "-co",
                    "BLOCKXSIZE=128",
                    "-co",
                    "BLOCKYSIZE=64",
                    "-co",
                    "COMPRESS=LZW",
                    "-co",
                    "PREDICTOR=2",
                    "-co",
                    "ENDIANNESS=BIG",
                    hgt_str,
                ],
                "tiled-lzw-predictor-bigendian.tif",
            ),
            "lzw-predictor-big-endian",
        ),
    ];
    for (tif, name) in variants {
        let (_, out) = tiles_of(&tif, dem(), TilingScheme::Geographic, 9, name);
        assert!(
            read_tree(&out) == reference,
            "{name}: tiles differ from the .hgt pyramid"
        );
    }
}

#[test]
fn web_mercator_geotiff_is_read_in_its_own_crs() {
    let warped = gdal(
        "gdalwarp",
        &[
            "-t_srs",
            "EPSG:3857",
            "-r",
            "bilinear",
            shared_data("N57E011.hgt").to_str().unwrap(),
        ],
        "srtm-3857.tif",
    );
    // Into both schemes: Web Mercator tiles, and geographic tiles reprojected from it.
    for (scheme, max) in [
        (TilingScheme::WebMercator, 11),
        (TilingScheme::Geographic, 10),
    ] {
        let (s, out) = tiles_of(&warped, dem(), scheme, max, &format!("from-3857-{scheme}"));
        let (mean, n) =
            mean_error_against_hgt(&out, scheme, s.levels.1, ElevationEncoding::Mapbox, 5, 0.01);
        assert!(
            n > 5000 && mean < 2.0,
            "{scheme}: mean |error| {mean} m over {n} samples"
        );
    }
}

#[test]
fn imagery_geotiff_matches_the_jpeg_pyramid() {
    let jpg = shared_data("bmng-5400x2700.jpg");
    let tif = gdal(
        "gdal_translate",
        &[
            "-a_ullr",
            "-180",
            "90",
            "180",
            "-90",
            "-a_srs",
            "EPSG:4326",
            "-co",
            "TILED=YES",
            "-co",
            "COMPRESS=LZW",
            jpg.to_str().unwrap(),
        ],
        "bmng.tif",
    );
    let png = JobKind::Imagery {
        format: ImageFormat::Png,
    };
    let (_, a) = tiles_of(&jpg, png, TilingScheme::Geographic, 2, "bmng-jpg");
    let (_, b) = tiles_of(&tif, png, TilingScheme::Geographic, 2, "bmng-tif");
    let (a, b) = (read_tree(&a), read_tree(&b));
    assert_eq!(a.keys().collect::<Vec<_>>(), b.keys().collect::<Vec<_>>());
    // GDAL's libjpeg and our decoder may round a few pixels differently.
    for (name, bytes) in &a {
        let ia = image::load_from_memory(bytes).unwrap().into_rgb8();
        let ib = image::load_from_memory(&b[name]).unwrap().into_rgb8();
        let diff: f64 = ia
            .as_raw()
            .iter()
            .zip(ib.as_raw())
            .map(|(x, y)| f64::from(x.abs_diff(*y)))
            .sum::<f64>()
            / ia.as_raw().len() as f64;
        assert!(diff < 1.0, "{name}: mean difference {diff}");
    }
}

#[test]
fn truncated_geotiff_is_refused_with_its_name() {
    let tif = gdal(
        "gdal_translate",
        &[
            "-co",
            "COMPRESS=DEFLATE",
            shared_data("N57E011.hgt").to_str().unwrap(),
        ],
        "whole.tif",
    );
    let bytes = std::fs::read(&tif).unwrap();
    let cut = output_dir("tiler_geotiff").join("cut.tif");
    std::fs::write(&cut, &bytes[..bytes.len() * 2 / 3]).unwrap();
    let out = fresh("tiler_geotiff", "cut");
    let e = globus_tiler::run(&job(dem(), &[cut], &out, TilingScheme::Geographic))
        .unwrap_err()
        .to_string();
    assert!(e.contains("cut.tif") && e.contains("truncated"), "{e}");
}

#[test]
fn nodata_is_filled_and_foreign_crs_is_refused() {
    let hgt = shared_data("N57E011.hgt");
    let with_nodata = gdal(
        "gdal_translate",
        &["-a_nodata", "0", hgt.to_str().unwrap()],
        "nodata0.tif",
    );
    let zeros = Hgt::load().samples.iter().filter(|&&v| v == 0).count();
    let (s, _) = tiles_of(&with_nodata, dem(), TilingScheme::Geographic, 6, "nodata");
    assert_eq!(s.voids_filled, zeros);
    let utm = gdal(
        "gdal_translate",
        &["-a_srs", "EPSG:32633", hgt.to_str().unwrap()],
        "utm.tif",
    );
    let out = fresh("tiler_geotiff", "utm");
    let e = globus_tiler::run(&job(dem(), &[utm], &out, TilingScheme::Geographic))
        .unwrap_err()
        .to_string();
    assert!(e.contains("utm.tif") && e.contains("EPSG:32633"), "{e}");
    assert!(!out.exists());
}
