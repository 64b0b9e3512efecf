//! Plain JPEG/PNG images in equirectangular projection (pixel-is-area) over given bounds:
//! world images for imagery pyramids, and greyscale images with a linear height scale for
//! elevation.

use std::path::Path;

use globus_tiling::GeoRect;

use crate::error::{Result, TilerError};
use crate::raster::{ElevationRaster, Georef, ImageRaster};

fn decode(path: &Path) -> Result<image::DynamicImage> {
    let file = crate::input::open_regular(path)?;
    let mut reader = image::ImageReader::new(std::io::BufReader::new(file));
    if let Ok(f) = image::ImageFormat::from_path(path) {
        reader.set_format(f);
    }
    let reader = reader
        .with_guessed_format()
        .map_err(|e| TilerError::io(path, e))?;
    if reader.format().is_none() {
        return Err(TilerError::bad_input(
            path,
            "not a JPEG, PNG or WebP image (unrecognised header)",
        ));
    }
    reader
        .decode()
        .map_err(|e| TilerError::bad_input(path, format!("cannot decode image: {e}")))
}

/// Reads an RGB(A) image covering `bounds` (equirectangular, first row at the north edge).
pub fn read_world_image(path: &Path, bounds: GeoRect) -> Result<ImageRaster> {
    let img = decode(path)?.into_rgba8();
    let (width, height) = (img.width() as usize, img.height() as usize);
    let data = img
        .into_raw()
        .chunks_exact(4)
        .map(|p| [p[0], p[1], p[2], p[3]])
        .collect();
    Ok(ImageRaster {
        width,
        height,
        data,
        georef: Georef::area_covering(bounds, width, height),
    })
}

/// Reads a greyscale image covering `bounds` as elevation: `height = value * scale_m`
/// (value 0..255 for 8-bit images, 0..65535 for 16-bit ones).
pub fn read_grey_elevation(path: &Path, bounds: GeoRect, scale_m: f64) -> Result<ElevationRaster> {
    if !(scale_m > 0.0 && scale_m <= 1000.0) {
        return Err(TilerError::BadOptions(format!(
            "--height-scale must be a positive number of metres per grey level up to 1000, not {scale_m:e}"
        )));
    }
    let img = decode(path)?;
    let (width, height) = (img.width() as usize, img.height() as usize);
    let data: Vec<f32> = match img {
        image::DynamicImage::ImageLuma16(g) => g
            .into_raw()
            .into_iter()
            .map(|v| (f64::from(v) * scale_m) as f32)
            .collect(),
        other => other
            .into_luma8()
            .into_raw()
            .into_iter()
            .map(|v| (f64::from(v) * scale_m) as f32)
            .collect(),
    };
    let top = data.iter().fold(0.0f32, |m, &v| m.max(v));
    if f64::from(top) > crate::input::geotiff::MAX_ABS_HEIGHT_M {
        return Err(TilerError::bad_input(
            path,
            format!(
                "its brightest grey level times --height-scale {scale_m} is {top} m, more than any height on a planet ({} m)",
                crate::input::geotiff::MAX_ABS_HEIGHT_M
            ),
        ));
    }
    Ok(ElevationRaster {
        width,
        height,
        data,
        georef: Georef::area_covering(bounds, width, height),
    })
}
