//! One equirectangular image of a whole imagery pyramid, for what is drawn from a single
//! planet-wide texture (the night lights) rather than streamed tile by tile.
//!
//! The level whose pixels are closest to (not coarser than) the image's is read tile by tile
//! through the pyramid, and each image pixel is the bilinear sample at its longitude and
//! latitude, so pyramids of either scheme and any tile size come out alike: Web Mercator is
//! reprojected (rows beyond its square, past about 85.05 degrees, are black), as are places
//! outside the layer's bounds and tiles it does not have. Transparent pixels count as black.

use std::f64::consts::PI;
use std::sync::Arc;

use globus_tiling::{TileKey, TilingScheme, mercator_y_to_lat};

use crate::decode::Rgba;
use crate::fetch::{Cancel, FetchError};
use crate::pyramid::{RasterPyramid, SampleGrid};

/// An equirectangular RGB image of the whole planet: column 0 at 180 degrees west, row 0 at
/// the north pole, twice as wide as tall.
#[derive(Clone, Debug, PartialEq, Eq)]
pub struct Equirect {
    /// Width, pixels.
    pub width: u32,
    /// Height, pixels (half the width).
    pub height: u32,
    /// Row-major RGB8, top row first.
    pub rgb: Vec<u8>,
}

/// The whole of `pyramid` as one equirectangular image at most `max_width` wide (and no
/// wider than its deepest level holds). Fails with the first tile that cannot be read.
pub fn equirectangular(
    pyramid: &RasterPyramid<Rgba>,
    max_width: u32,
    cancel: &Cancel,
) -> Result<Equirect, FetchError> {
    let spec = *pyramid.spec();
    let per_tile = spec.tile_size - u32::from(spec.grid == SampleGrid::Corners);
    let native = spec
        .scheme
        .tiles_x(spec.max_level)
        .saturating_mul(u64::from(per_tile.max(1)));
    let width = (native.min(u64::from(max_width)) as u32 & !1).max(2);
    let height = width / 2;
    let level = spec.level_for_spacing(PI / f64::from(height));
    // Web Mercator holds latitudes up to here.
    let mercator_limit = mercator_y_to_lat(0.0);
    let mut rgb = vec![0u8; width as usize * height as usize * 3];
    let mut last: Option<(TileKey, Option<Arc<Rgba>>)> = None;
    for row in 0..height {
        let lat = PI / 2.0 - (f64::from(row) + 0.5) / f64::from(height) * PI;
        if spec.scheme == TilingScheme::WebMercator && lat.abs() > mercator_limit {
            continue;
        }
        for col in 0..width {
            let lon = (f64::from(col) + 0.5) / f64::from(width) * 2.0 * PI - PI;
            if !spec.bounds.contains(lon, lat) {
                continue;
            }
            let Some((key, px, py)) = spec.locate(lon, lat, level) else {
                continue;
            };
            let tile = match &last {
                Some((k, tile)) if *k == key => tile.clone(),
                _ => {
                    let tile = pyramid.tile(key, cancel)?;
                    last = Some((key, tile.clone()));
                    tile
                }
            };
            if let Some(tile) = tile {
                let i = (row as usize * width as usize + col as usize) * 3;
                rgb[i..i + 3].copy_from_slice(&sample(&tile, spec.tile_size, px, py));
            }
        }
    }
    Ok(Equirect { width, height, rgb })
}

/// The bilinear sample of `tile` at (`px`, `py`) in the pyramid's samples (`tile_size` per
/// side; a decoded tile of another size is scaled to it), weighted by alpha.
fn sample(tile: &Rgba, tile_size: u32, px: f64, py: f64) -> [u8; 3] {
    if tile.width == 0 || tile.height == 0 {
        return [0; 3];
    }
    let scale_x = f64::from(tile.width) / f64::from(tile_size.max(1));
    let scale_y = f64::from(tile.height) / f64::from(tile_size.max(1));
    let x = ((px + 0.5) * scale_x - 0.5).clamp(0.0, f64::from(tile.width - 1));
    let y = ((py + 0.5) * scale_y - 0.5).clamp(0.0, f64::from(tile.height - 1));
    let (x0, y0) = (x.floor() as u32, y.floor() as u32);
    let (x1, y1) = ((x0 + 1).min(tile.width - 1), (y0 + 1).min(tile.height - 1));
    let (fx, fy) = (x - f64::from(x0), y - f64::from(y0));
    let mut out = [0.0f64; 3];
    for (xx, yy, w) in [
        (x0, y0, (1.0 - fx) * (1.0 - fy)),
        (x1, y0, fx * (1.0 - fy)),
        (x0, y1, (1.0 - fx) * fy),
        (x1, y1, fx * fy),
    ] {
        let p = tile.at(xx, yy);
        let a = f64::from(p[3]) / 255.0;
        for c in 0..3 {
            out[c] += w * a * f64::from(p[c]);
        }
    }
    out.map(|v| v.round().clamp(0.0, 255.0) as u8)
}

#[cfg(test)]
mod tests {
    use super::*;
    use crate::fetch::{Fetch, Fetched};
    use crate::pyramid::{Decoder, PyramidSpec};
    use globus_tiling::{GeoRect, lat_to_mercator_y};

    /// Tiles whose bytes are their key; decoded to 64 x 64 pixels whose red is the tile's
    /// column, green its row within the level, and blue its pixel row (so a test can tell
    /// where a sample came from).
    struct Keys;

    impl Fetch for Keys {
        fn name(&self) -> &str {
            "keys"
        }
        fn fetch(&self, key: TileKey, _: &Cancel) -> Result<Option<Fetched>, FetchError> {
            let mut b = vec![key.level()];
            b.extend_from_slice(&key.x().to_le_bytes());
            b.extend_from_slice(&key.y().to_le_bytes());
            Ok(Some(Fetched::local(b)))
        }
    }

    fn pyramid(scheme: TilingScheme, max_level: u8) -> RasterPyramid<Rgba> {
        let decode: Box<Decoder<Rgba>> = Box::new(|b: &[u8]| {
            let x = u32::from_le_bytes([b[1], b[2], b[3], b[4]]);
            let y = u32::from_le_bytes([b[5], b[6], b[7], b[8]]);
            let mut pixels = Vec::with_capacity(64 * 64 * 4);
            for row in 0..64u32 {
                for _ in 0..64 {
                    pixels.extend_from_slice(&[x as u8 * 10, y as u8 * 10, row as u8, 255]);
                }
            }
            Ok(Rgba {
                width: 64,
                height: 64,
                pixels,
            })
        });
        RasterPyramid::new(
            Arc::new(Keys),
            PyramidSpec {
                scheme,
                min_level: 0,
                max_level,
                tile_size: 64,
                grid: SampleGrid::Cells,
                bounds: GeoRect::WORLD,
            },
            decode,
            16 << 20,
        )
    }

    fn at(img: &Equirect, col: u32, row: u32) -> [u8; 3] {
        let i = ((row * img.width + col) * 3) as usize;
        [img.rgb[i], img.rgb[i + 1], img.rgb[i + 2]]
    }

    #[test]
    fn a_geographic_pyramid_comes_out_pixel_for_pixel() {
        // Level 2: 8 x 4 tiles of 64 = 512 x 256, the deepest level's size.
        let img = equirectangular(&pyramid(TilingScheme::Geographic, 2), 8192, &Cancel::new())
            .expect("mosaic");
        assert_eq!((img.width, img.height), (512, 256));
        // Pixel (col, row) comes from tile (col / 64, row / 64), pixel row row % 64.
        for (col, row) in [(0, 0), (70, 5), (511, 255), (300, 130)] {
            assert_eq!(
                at(&img, col, row),
                [
                    (col / 64) as u8 * 10,
                    (row / 64) as u8 * 10,
                    (row % 64) as u8
                ],
                "({col}, {row})"
            );
        }
        // At most the width asked for, from the level that fits it.
        let half = equirectangular(&pyramid(TilingScheme::Geographic, 2), 256, &Cancel::new())
            .expect("mosaic");
        assert_eq!((half.width, half.height), (256, 128));
        assert_eq!(at(&half, 255, 127), [30, 10, 63]);
    }

    #[test]
    fn web_mercator_is_reprojected_and_black_beyond_its_square() {
        // Level 3: 8 x 8 tiles of 64 = 512 wide.
        let img = equirectangular(&pyramid(TilingScheme::WebMercator, 3), 8192, &Cancel::new())
            .expect("mosaic");
        assert_eq!((img.width, img.height), (512, 256));
        // Rows beyond 85.05 degrees (within the first 3 of 256) are black.
        assert_eq!(at(&img, 100, 0), [0, 0, 0]);
        assert_eq!(at(&img, 100, 255), [0, 0, 0]);
        // 45 N: Mercator y 0.3597 of the square, tile row 2 of 8, pixel row 0.877 * 64 - 0.5.
        let row = ((0.5 - 45.0 / 180.0) * 256.0 - 0.5) as u32;
        let lat = 90.0 - (f64::from(row) + 0.5) / 256.0 * 180.0;
        let fy = lat_to_mercator_y(lat.to_radians()) * 8.0;
        let want_row = ((fy - fy.floor()) * 64.0 - 0.5).round() as u8;
        let got = at(&img, 256, row);
        assert_eq!(got[..2], [40, fy.floor() as u8 * 10], "row {row}");
        assert!(
            got[2].abs_diff(want_row) <= 1,
            "{got:?} against pixel row {want_row}"
        );
    }
}
