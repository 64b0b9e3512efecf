//! Tile file formats: PNG (elevation and imagery), JPEG and lossless WebP (imagery).

use crate::error::{Result, TilerError};
use globus_tiling::TileKey;

/// How imagery tiles are written.
#[derive(Clone, Copy, Debug, PartialEq, Eq)]
pub enum ImageFormat {
    /// JPEG at a quality 1..=100 (no transparency: outside the data is black).
    Jpeg {
        /// Encoder quality.
        quality: u8,
    },
    /// Lossless PNG, RGBA where some pixel is transparent, else RGB.
    Png,
    /// Lossless WebP.
    Webp,
}

impl ImageFormat {
    /// The file extension, also the MBTiles `format` metadata value.
    pub fn extension(self) -> &'static str {
        match self {
            ImageFormat::Jpeg { .. } => "jpg",
            ImageFormat::Png => "png",
            ImageFormat::Webp => "webp",
        }
    }

    /// Parses `jpeg`, `png` or `webp`, with the JPEG quality to use.
    pub fn parse(name: &str, jpeg_quality: u8) -> Option<Self> {
        match name {
            "jpeg" | "jpg" => Some(ImageFormat::Jpeg {
                quality: jpeg_quality,
            }),
            "png" => Some(ImageFormat::Png),
            "webp" => Some(ImageFormat::Webp),
            _ => None,
        }
    }
}

/// Encodes 8-bit RGB or RGBA (`channels` 3 or 4) as PNG with fast, deterministic settings.
pub fn encode_png(key: TileKey, pixels: &[u8], size: usize, channels: usize) -> Result<Vec<u8>> {
    let fail = |e: png::EncodingError| TilerError::Encode {
        key,
        problem: format!("PNG: {e}"),
    };
    let mut out = Vec::with_capacity(pixels.len() / 2);
    {
        let mut enc = png::Encoder::new(&mut out, size as u32, size as u32);
        enc.set_color(if channels == 4 {
            png::ColorType::Rgba
        } else {
            png::ColorType::Rgb
        });
        enc.set_depth(png::BitDepth::Eight);
        enc.set_compression(png::Compression::Fast);
        let mut w = enc.write_header().map_err(fail)?;
        w.write_image_data(pixels).map_err(fail)?;
        w.finish().map_err(fail)?;
    }
    Ok(out)
}

/// Encodes an RGBA tile in `format`.
pub fn encode_image(
    key: TileKey,
    rgba: &[[u8; 4]],
    size: usize,
    format: ImageFormat,
) -> Result<Vec<u8>> {
    let opaque = rgba.iter().all(|p| p[3] == 255);
    match format {
        ImageFormat::Png => {
            if opaque {
                let rgb: Vec<u8> = rgba.iter().flat_map(|p| [p[0], p[1], p[2]]).collect();
                encode_png(key, &rgb, size, 3)
            } else {
                encode_png(key, rgba.as_flattened(), size, 4)
            }
        }
        ImageFormat::Jpeg { quality } => {
            // JPEG has no alpha: transparent pixels are black, as other tilers write them.
            let rgb: Vec<u8> = rgba
                .iter()
                .flat_map(|p| {
                    let a = u16::from(p[3]);
                    [p[0], p[1], p[2]].map(|c| ((u16::from(c) * a + 127) / 255) as u8)
                })
                .collect();
            let mut out = Vec::with_capacity(size * size / 4);
            let enc = jpeg_encoder::Encoder::new(&mut out, quality.clamp(1, 100));
            enc.encode(&rgb, size as u16, size as u16, jpeg_encoder::ColorType::Rgb)
                .map_err(|e| TilerError::Encode {
                    key,
                    problem: format!("JPEG: {e}"),
                })?;
            Ok(out)
        }
        ImageFormat::Webp => {
            let mut out = Vec::new();
            let enc = image::codecs::webp::WebPEncoder::new_lossless(&mut out);
            let (data, colour) = if opaque {
                (
                    rgba.iter()
                        .flat_map(|p| [p[0], p[1], p[2]])
                        .collect::<Vec<u8>>(),
                    image::ExtendedColorType::Rgb8,
                )
            } else {
                (
                    rgba.as_flattened().to_vec(),
                    image::ExtendedColorType::Rgba8,
                )
            };
            enc.encode(&data, size as u32, size as u32, colour)
                .map_err(|e| TilerError::Encode {
                    key,
                    problem: format!("WebP: {e}"),
                })?;
            Ok(out)
        }
    }
}
