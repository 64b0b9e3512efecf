//! Elevation pyramids from the real SRTM tile `../shared/data/N57E011.hgt`, read back through
//! the tiles and compared with the file itself.

#![allow(clippy::unwrap_used)] // test helpers: a failure should stop the test

mod common;

use std::path::Path;

use common::*;
use globus_tiler::{ElevationEncoding, JobKind};
use globus_tiling::TilingScheme;

fn dem(encoding: ElevationEncoding) -> JobKind {
    JobKind::Dem {
        encoding,
        height_scale: None,
    }
}

/// Decoded heights of tile (z, x, y) in an XYZ directory.
fn heights(dir: &Path, z: u8, x: u32, y: u32, enc: ElevationEncoding) -> Vec<f64> {
    decode_rgba(&dir.join(format!("{z}/{x}/{y}.png")))
        .pixels()
        .map(|p| enc.decode([p[0], p[1], p[2]]))
        .collect()
}

#[test]
fn finest_level_matches_the_srtm_file_within_quantisation() {
    let hgt = Hgt::load();
    for scheme in [TilingScheme::Geographic, TilingScheme::WebMercator] {
        for enc in [
            ElevationEncoding::Terrarium,
            ElevationEncoding::Mapbox,
            ElevationEncoding::Centimetre,
        ] {
            let out = fresh("tiler_elevation", &format!("{scheme}-{}", enc.name()));
            let summary =
                globus_tiler::run(&job(dem(enc), &[shared_data("N57E011.hgt")], &out, scheme))
                    .unwrap();
            let z = summary.levels.1;
            // The default finest level is the first as fine as 3 arc-seconds.
            let (nx, ny) = (scheme.tiles_x(z) as f64, scheme.tiles_y(z) as f64);
            let spacing = 360.0 / nx / 255.0;
            assert!(
                spacing <= 3.0 / 3600.0 && spacing * 2.0 > 3.0 / 3600.0,
                "{scheme} z{z}"
            );
            let mut checked = 0;
            let mut worst = 0.0f64;
            for entry in std::fs::read_dir(out.join(z.to_string())).unwrap() {
                let x: u32 = entry
                    .unwrap()
                    .file_name()
                    .to_string_lossy()
                    .parse()
                    .unwrap();
                for file in std::fs::read_dir(out.join(format!("{z}/{x}"))).unwrap() {
                    let name = file.unwrap().file_name().to_string_lossy().into_owned();
                    let y: u32 = name.trim_end_matches(".png").parse().unwrap();
                    let h = heights(&out, z, x, y, enc);
                    for j in 0..256 {
                        let lat = corner_lat(scheme, y, j, 256, ny);
                        for i in 0..256 {
                            let lon = corner_lon(x, i, 256, nx);
                            let inside =
                                (11.0..=12.0).contains(&lon) && (57.0..=58.0).contains(&lat);
                            let got = h[j * 256 + i];
                            if inside {
                                let err = (got - hgt.height(lon, lat)).abs();
                                worst = worst.max(err);
                                checked += 1;
                            } else {
                                assert!(got.abs() <= enc.step_m(), "outside the data: {got} m");
                            }
                        }
                    }
                }
            }
            assert!(checked > 1_000_000, "{checked} samples");
            assert!(
                worst <= enc.step_m() * 0.5 + 1e-3,
                "{scheme} {}: worst error {worst} m",
                enc.name()
            );
        }
    }
}

#[test]
fn neighbouring_tiles_share_edge_heights_exactly_at_every_level() {
    let enc = ElevationEncoding::Mapbox;
    let out = fresh("tiler_elevation", "edges");
    let s = globus_tiler::run(&job(
        dem(enc),
        &[shared_data("N57E011.hgt")],
        &out,
        TilingScheme::Geographic,
    ))
    .unwrap();
    let mut pairs = 0;
    for z in 0..=s.levels.1 {
        let tiles = read_tree(&out.join(z.to_string()));
        let has = |x: u32, y: u32| tiles.contains_key(&format!("{x}/{y}.png"));
        for key in tiles.keys() {
            let (x, y) = key.trim_end_matches(".png").split_once('/').unwrap();
            let (x, y): (u32, u32) = (x.parse().unwrap(), y.parse().unwrap());
            let a = heights(&out, z, x, y, enc);
            if has(x + 1, y) {
                let b = heights(&out, z, x + 1, y, enc);
                for j in 0..256 {
                    assert_eq!(
                        a[j * 256 + 255],
                        b[j * 256],
                        "z{z} {x}/{y} east edge row {j}"
                    );
                }
                pairs += 1;
            }
            if has(x, y + 1) {
                let b = heights(&out, z, x, y + 1, enc);
                assert_eq!(a[255 * 256..], b[..256], "z{z} {x}/{y} south edge");
                pairs += 1;
            }
        }
    }
    assert!(pairs > 20, "{pairs} edges compared");
}

#[test]
fn coarser_levels_follow_the_terrain() {
    let enc = ElevationEncoding::Terrarium;
    let scheme = TilingScheme::Geographic;
    let out = fresh("tiler_elevation", "coarse");
    let s = globus_tiler::run(&job(dem(enc), &[shared_data("N57E011.hgt")], &out, scheme)).unwrap();
    // Two levels up, samples are 4 source samples apart: smoothed, but still the terrain.
    let z = s.levels.1 - 2;
    // Away from the footprint's edge, where outside zeros blend in.
    let (mean, n) = mean_error_against_hgt(&out, scheme, z, enc, 1, 0.02);
    assert!(
        n > 10_000 && mean < 4.0,
        "mean |error| {mean} m over {n} samples"
    );
}

#[test]
fn greyscale_images_become_heights_with_the_given_scale() {
    // earth-topology-2048x1024.png: 8-bit grey over the whole world, about 25 m per level.
    let src = image::open(shared_data("earth-topology-2048x1024.png"))
        .unwrap()
        .into_luma8();
    let out = fresh("tiler_elevation", "grey");
    let mut j = job(
        JobKind::Dem {
            encoding: ElevationEncoding::Terrarium,
            height_scale: Some(25.1),
        },
        &[shared_data("earth-topology-2048x1024.png")],
        &out,
        TilingScheme::Geographic,
    );
    j.max_level = Some(2);
    globus_tiler::run(&j).unwrap();
    // At level 2 (45-degree tiles, 256 samples) the source has 1.1 pixels per sample: each
    // sample is the area mean of the pixels under it. Check the brightest place (the
    // Himalaya or the Andes) reads back as a high mountain and the oceans as 0 m.
    let (mut best, mut at) = (0u8, (0u32, 0u32));
    for (x, y, p) in src.enumerate_pixels() {
        if p[0] > best {
            best = p[0];
            at = (x, y);
        }
    }
    let lon = (f64::from(at.0) + 0.5) / 2048.0 * 360.0 - 180.0;
    let lat = 90.0 - (f64::from(at.1) + 0.5) / 1024.0 * 180.0;
    let (x, y) = (((lon + 180.0) / 45.0) as u32, ((90.0 - lat) / 45.0) as u32);
    let h = heights(&out, 2, x, y, ElevationEncoding::Terrarium);
    let top = h.iter().copied().fold(f64::MIN, f64::max);
    let expected = f64::from(best) * 25.1;
    assert!(
        top > 0.7 * expected && top <= expected + 1.0,
        "highest {top} m, brightest pixel {expected} m"
    );
    // Mid-Pacific (150 W, 0 N) is ocean: 0 m.
    let pacific = heights(&out, 2, 0, 1, ElevationEncoding::Terrarium);
    assert!(pacific[255 * 256 + 128].abs() < 0.01);
}
