//! GeoTIFF: single-band elevation (i16, u16, i32, f32, f64) or 8-bit RGB/RGBA/grey imagery,
//! striped or tiled, uncompressed, Deflate or LZW, georeferenced by a model tiepoint and
//! pixel scale or by a model transformation, in EPSG:4326 or EPSG:3857.

use std::io::BufReader;
use std::path::Path;

use tiff::decoder::{Decoder, DecodingResult, Limits};
use tiff::tags::Tag;

use crate::error::{Result, TilerError};
use crate::raster::{Crs, ElevationRaster, Georef, ImageRaster, Raster, Registration};

/// What a GeoTIFF holds.
#[derive(Debug)]
pub enum GeoTiff {
    /// One band of numbers: elevation in metres, `NaN` where the file says no data.
    Elevation(ElevationRaster),
    /// 8-bit colour.
    Image(ImageRaster),
}

// GeoKey IDs (GeoTIFF 1.1, section 7).
const GT_MODEL_TYPE: u16 = 1024;
const GT_RASTER_TYPE: u16 = 1025;
const GEOGRAPHIC_TYPE: u16 = 2048;
const PROJECTED_CS_TYPE: u16 = 3072;
const MODEL_TYPE_PROJECTED: u16 = 1;
const MODEL_TYPE_GEOGRAPHIC: u16 = 2;
const RASTER_PIXEL_IS_POINT: u16 = 2;
const USER_DEFINED: u16 = 32767;

/// The short-valued GeoKeys of a GeoKeyDirectory.
fn geo_keys(dir: &[u16]) -> Vec<(u16, u16)> {
    let count = dir.get(3).copied().unwrap_or(0) as usize;
    dir.get(4..)
        .unwrap_or_default()
        .chunks_exact(4)
        .take(count)
        // Location 0: the value is stored in the entry itself.
        .filter(|e| e[1] == 0)
        .map(|e| (e[0], e[3]))
        .collect()
}

fn crs_of(path: &Path, keys: &[(u16, u16)]) -> Result<Crs> {
    let key = |id: u16| keys.iter().find(|k| k.0 == id).map(|k| k.1);
    let unsupported = |what: String| {
        TilerError::bad_input(
            path,
            format!(
                "is in {what}; only EPSG:4326 and EPSG:3857 are supported (reproject it with gdalwarp -t_srs EPSG:4326)"
            ),
        )
    };
    match key(GT_MODEL_TYPE) {
        Some(MODEL_TYPE_GEOGRAPHIC) => match key(GEOGRAPHIC_TYPE) {
            Some(4326) => Ok(Crs::Geographic),
            Some(USER_DEFINED) | None => Err(unsupported("a user-defined geographic CRS".into())),
            Some(code) => Err(unsupported(format!("EPSG:{code}"))),
        },
        Some(MODEL_TYPE_PROJECTED) => match key(PROJECTED_CS_TYPE) {
            Some(3857 | 3785) => Ok(Crs::WebMercator),
            Some(USER_DEFINED) | None => Err(unsupported("a user-defined projected CRS".into())),
            Some(code) => Err(unsupported(format!("EPSG:{code}"))),
        },
        Some(other) => Err(unsupported(format!("model type {other}"))),
        None => Err(TilerError::bad_input(
            path,
            "has no GeoTIFF model type (GTModelTypeGeoKey)",
        )),
    }
}

/// Reads a GeoTIFF into memory.
pub fn read_geotiff(path: &Path) -> Result<GeoTiff> {
    let file = std::fs::File::open(path).map_err(|e| TilerError::io(path, e))?;
    let bad = |e: tiff::TiffError| TilerError::bad_input(path, format!("TIFF: {e}"));
    let mut dec = Decoder::new(BufReader::new(file))
        .map_err(bad)?
        .with_limits(Limits::unlimited());
    let (width, height) = dec.dimensions().map_err(bad)?;
    let (width, height) = (width as usize, height as usize);
    if width < 2 || height < 2 {
        return Err(TilerError::bad_input(
            path,
            format!("is only {width}x{height} pixels"),
        ));
    }
    let key_dir = dec
        .find_tag(Tag::GeoKeyDirectoryTag)
        .map_err(bad)?
        .ok_or_else(|| {
            TilerError::bad_input(path, "is a plain TIFF without GeoTIFF georeferencing")
        })?
        .into_u16_vec()
        .map_err(bad)?;
    let keys = geo_keys(&key_dir);
    let crs = crs_of(path, &keys)?;
    let registration = if keys.contains(&(GT_RASTER_TYPE, RASTER_PIXEL_IS_POINT)) {
        Registration::Point
    } else {
        Registration::Area
    };
    // Raster to model: x = x0 + i * sx, y = y0 - j * sy, with (i, j) the raster position.
    let (ox, oy, sx, sy) = if let Some(m) =
        dec.find_tag(Tag::ModelTransformationTag).map_err(bad)?
    {
        let m = m.into_f64_vec().map_err(bad)?;
        if m.len() < 16 {
            return Err(TilerError::bad_input(
                path,
                "ModelTransformationTag has fewer than 16 values",
            ));
        }
        if m[1] != 0.0 || m[4] != 0.0 {
            return Err(TilerError::bad_input(
                path,
                "is rotated or sheared; only north-up rasters are supported",
            ));
        }
        (m[3], m[7], m[0], -m[5])
    } else {
        let tie = dec
            .find_tag(Tag::ModelTiepointTag)
            .map_err(bad)?
            .ok_or_else(|| {
                TilerError::bad_input(path, "has neither a model tiepoint nor a transformation")
            })?
            .into_f64_vec()
            .map_err(bad)?;
        let scale = dec
            .find_tag(Tag::ModelPixelScaleTag)
            .map_err(bad)?
            .ok_or_else(|| TilerError::bad_input(path, "has a tiepoint but no ModelPixelScaleTag"))?
            .into_f64_vec()
            .map_err(bad)?;
        if tie.len() < 6 || scale.len() < 2 {
            return Err(TilerError::bad_input(
                path,
                "has a malformed tiepoint or pixel scale",
            ));
        }
        (
            tie[3] - tie[0] * scale[0],
            tie[4] + tie[1] * scale[1],
            scale[0],
            scale[1],
        )
    };
    if !(sx > 0.0 && sy > 0.0 && ox.is_finite() && oy.is_finite()) {
        return Err(TilerError::bad_input(
            path,
            format!(
                "has an unusable pixel size {sx} x {sy} (north-up rasters have positive x and negative y steps)"
            ),
        ));
    }
    // Sample centres: half a pixel in for pixel-is-area rasters.
    let half = match registration {
        Registration::Area => 0.5,
        Registration::Point => 0.0,
    };
    let georef = Georef {
        crs,
        x0: ox + half * sx,
        y0: oy - half * sy,
        dx: sx,
        dy: sy,
        registration,
    };
    let nodata: Option<f64> = dec
        .find_tag(Tag::GdalNodata)
        .map_err(bad)?
        .and_then(|v| v.into_string().ok())
        .and_then(|s| s.trim_matches(char::from(0)).trim().parse().ok());
    let samples = width * height;
    let colour = dec.colortype().map_err(bad)?;
    let data = dec.read_image().map_err(bad)?;
    let channels = data_len(&data) / samples.max(1);
    let to_height = |v: f64| -> f32 {
        if Some(v) == nodata || !v.is_finite() {
            f32::NAN
        } else {
            v as f32
        }
    };
    let elevation = |values: Vec<f32>| {
        GeoTiff::Elevation(Raster {
            width,
            height,
            data: values,
            georef,
        })
    };
    Ok(match (data, channels) {
        (DecodingResult::U8(v), 3) => GeoTiff::Image(Raster {
            width,
            height,
            data: v.chunks_exact(3).map(|p| [p[0], p[1], p[2], 255]).collect(),
            georef,
        }),
        (DecodingResult::U8(v), 4) => GeoTiff::Image(Raster {
            width,
            height,
            data: v
                .chunks_exact(4)
                .map(|p| [p[0], p[1], p[2], p[3]])
                .collect(),
            georef,
        }),
        (DecodingResult::U8(v), 1) => GeoTiff::Image(Raster {
            width,
            height,
            data: v.into_iter().map(|g| [g, g, g, 255]).collect(),
            georef,
        }),
        (DecodingResult::I16(v), 1) => {
            elevation(v.into_iter().map(|x| to_height(f64::from(x))).collect())
        }
        (DecodingResult::U16(v), 1) => {
            elevation(v.into_iter().map(|x| to_height(f64::from(x))).collect())
        }
        (DecodingResult::I32(v), 1) => {
            elevation(v.into_iter().map(|x| to_height(f64::from(x))).collect())
        }
        (DecodingResult::F32(v), 1) => {
            elevation(v.into_iter().map(|x| to_height(f64::from(x))).collect())
        }
        (DecodingResult::F64(v), 1) => elevation(v.into_iter().map(to_height).collect()),
        (_, n) => {
            return Err(TilerError::bad_input(
                path,
                format!(
                    "has {n} band(s) of {colour:?}; expected one elevation band or 8-bit RGB/RGBA/grey"
                ),
            ));
        }
    })
}

fn data_len(d: &DecodingResult) -> usize {
    match d {
        DecodingResult::U8(v) => v.len(),
        DecodingResult::U16(v) => v.len(),
        DecodingResult::U32(v) => v.len(),
        DecodingResult::U64(v) => v.len(),
        DecodingResult::F16(v) => v.len(),
        DecodingResult::F32(v) => v.len(),
        DecodingResult::F64(v) => v.len(),
        DecodingResult::I8(v) => v.len(),
        DecodingResult::I16(v) => v.len(),
        DecodingResult::I32(v) => v.len(),
        DecodingResult::I64(v) => v.len(),
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn geo_keys_are_read_from_the_directory() {
        // Version 1.1.0, 3 keys: model geographic, raster pixel-is-area, EPSG:4326.
        let dir = [1, 1, 0, 3, 1024, 0, 1, 2, 1025, 0, 1, 1, 2048, 0, 1, 4326];
        let keys = geo_keys(&dir);
        assert_eq!(keys, vec![(1024, 2), (1025, 1), (2048, 4326)]);
        assert_eq!(crs_of(Path::new("x.tif"), &keys).unwrap(), Crs::Geographic);
        let utm = [(1024, 1), (3072, 32633)];
        let e = crs_of(Path::new("utm.tif"), &utm).unwrap_err().to_string();
        assert!(e.contains("utm.tif") && e.contains("EPSG:32633"), "{e}");
    }
}
