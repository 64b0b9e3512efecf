//! The whole planet as a mosaic of level-2 colour tiles: continents, oceans, ice caps.
//! Writes `target/test-output/world_mosaic/level2.png` to look at.

use globus_terrain::ProceduralPlanet;
use globus_terrain::grid::COLOUR_SIZE;
use globus_test_support::image::Rgba;
use globus_tiling::TileKey;

#[test]
fn level_two_mosaic_shows_oceans_continents_and_ice() {
    // Seed 24 is the planet `globus` shows by default.
    let planet = ProceduralPlanet::new(24);
    let level = 2u8;
    let (nx, ny) = (8u32, 4u32);
    let size = COLOUR_SIZE;
    let mut img = Rgba {
        width: nx * size,
        height: ny * size,
        pixels: vec![0; (nx * size * ny * size * 4) as usize],
    };
    let (mut water, mut white, mut green) = (0u64, 0u64, 0u64);
    for y in 0..ny {
        for x in 0..nx {
            let t = planet.generate_tile(TileKey::new(level, x, y));
            assert!(t.min_height_m >= 0.0);
            let px = &t.colour.mips[0];
            for row in 0..size {
                for col in 0..size {
                    let src = ((row * size + col) * 4) as usize;
                    let dst = (((y * size + row) * img.width + x * size + col) * 4) as usize;
                    img.pixels[dst..dst + 4].copy_from_slice(&px[src..src + 4]);
                    let [r, g, b, a] = [px[src], px[src + 1], px[src + 2], px[src + 3]];
                    if r > 200 && g > 200 && b > 200 {
                        white += 1;
                    } else if a == 0 {
                        water += 1;
                    } else if g > r && g > b {
                        green += 1;
                    }
                }
            }
        }
    }
    let total = f64::from(img.width * img.height);
    let out = globus_test_support::output_dir("world_mosaic").join("level2.png");
    img.save_png(&out, true).expect("write png");
    let water = water as f64 / total;
    assert!((0.45..0.8).contains(&water), "water fraction {water}");
    assert!(
        white as f64 / total > 0.01,
        "ice caps and snow: {}",
        white as f64 / total
    );
    assert!(
        green as f64 / total > 0.03,
        "vegetation: {}",
        green as f64 / total
    );
}
