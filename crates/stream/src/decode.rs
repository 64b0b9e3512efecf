//! Decoding tile bytes: PNG, JPEG and WebP images, and RGB-encoded elevation.
//!
//! An image's declared size is read from its header and checked against [`DecodeLimits`]
//! before any pixel buffer is allocated, so a 60000 x 60000 PNG of a few hundred bytes is
//! refused, not decoded.

use std::io::Cursor;

use globus_terrain::encoding::ElevationEncoding;

/// Limits on what a tile may decode to.
#[derive(Clone, Copy, Debug, PartialEq, Eq)]
pub struct DecodeLimits {
    /// Largest width or height, pixels.
    pub max_side: u32,
}

impl Default for DecodeLimits {
    fn default() -> Self {
        Self { max_side: 4096 }
    }
}

/// A decoded RGBA8 image.
#[derive(Clone, Debug, PartialEq, Eq)]
pub struct Rgba {
    /// Width, pixels.
    pub width: u32,
    /// Height, pixels.
    pub height: u32,
    /// Row-major RGBA8, top row first.
    pub pixels: Vec<u8>,
}

impl Rgba {
    /// The pixel at (`x`, `y`).
    pub fn at(&self, x: u32, y: u32) -> [u8; 4] {
        let i = ((y * self.width + x) * 4) as usize;
        [
            self.pixels[i],
            self.pixels[i + 1],
            self.pixels[i + 2],
            self.pixels[i + 3],
        ]
    }
}

/// Why tile bytes could not be decoded. The messages name what was expected; the caller
/// adds the tile and source.
#[derive(Clone, Debug, PartialEq, thiserror::Error)]
pub enum DecodeError {
    /// The bytes are not an image of a format that is read (with the first bytes shown).
    #[error("{0}")]
    NotAnImage(String),
    /// An image declaring more pixels than the limits allow (refused before decoding).
    #[error(
        "{format} declares {width} x {height} pixels; at most {max_side} x {max_side} is accepted"
    )]
    TooLarge {
        /// The image format.
        format: String,
        /// Declared width.
        width: u32,
        /// Declared height.
        height: u32,
        /// The largest side accepted.
        max_side: u32,
    },
    /// The image or mesh is corrupt or of the wrong kind for the layer.
    #[error("{0}")]
    Corrupt(String),
}

/// Decodes an image (format from its magic bytes).
pub fn decode_image(bytes: &[u8], limits: DecodeLimits) -> Result<Rgba, DecodeError> {
    let reader = || {
        image::ImageReader::new(Cursor::new(bytes))
            .with_guessed_format()
            .map_err(|e| DecodeError::NotAnImage(format!("cannot read the image: {e}")))
    };
    let r = reader()?;
    let Some(format) = r.format() else {
        let head: String = bytes
            .iter()
            .take(16)
            .map(|&b| {
                if b.is_ascii_graphic() {
                    char::from(b)
                } else {
                    '.'
                }
            })
            .collect();
        return Err(DecodeError::NotAnImage(format!(
            "not an image ({} bytes starting {head:?})",
            bytes.len()
        )));
    };
    if !matches!(
        format,
        image::ImageFormat::Png | image::ImageFormat::Jpeg | image::ImageFormat::WebP
    ) {
        return Err(DecodeError::NotAnImage(format!(
            "{format:?} images are not read (PNG, JPEG, WebP are)"
        )));
    }
    let (w, h) = r
        .into_dimensions()
        .map_err(|e| DecodeError::Corrupt(format!("{format:?} header: {e}")))?;
    if w == 0 || h == 0 || w > limits.max_side || h > limits.max_side {
        return Err(DecodeError::TooLarge {
            format: format!("{format:?}"),
            width: w,
            height: h,
            max_side: limits.max_side,
        });
    }
    let mut r = reader()?;
    let mut l = image::Limits::default();
    l.max_image_width = Some(limits.max_side);
    l.max_image_height = Some(limits.max_side);
    l.max_alloc = Some(u64::from(limits.max_side).pow(2) * 16);
    r.limits(l);
    let img = r
        .decode()
        .map_err(|e| DecodeError::Corrupt(format!("{format:?}: {e}")))?;
    let rgba = img.to_rgba8();
    Ok(Rgba {
        width: rgba.width(),
        height: rgba.height(),
        pixels: rgba.into_raw(),
    })
}

/// A decoded elevation tile: heights in metres, row-major from the north-west.
#[derive(Clone, Debug, PartialEq)]
pub struct HeightImage {
    /// Samples per row.
    pub width: u32,
    /// Rows.
    pub height: u32,
    /// Metres.
    pub heights_m: Vec<f32>,
}

/// Decodes an RGB-encoded elevation tile. Fully transparent pixels are 0 m (outside the
/// data, as `globus tile` and most services write them).
pub fn decode_elevation(
    bytes: &[u8],
    encoding: ElevationEncoding,
    limits: DecodeLimits,
) -> Result<HeightImage, DecodeError> {
    let img = decode_image(bytes, limits)?;
    let heights_m = img
        .pixels
        .chunks_exact(4)
        .map(|p| {
            if p[3] == 0 {
                0.0
            } else {
                encoding.decode([p[0], p[1], p[2]]) as f32
            }
        })
        .collect();
    Ok(HeightImage {
        width: img.width,
        height: img.height,
        heights_m,
    })
}

/// Samples per side of the height grid a quantized-mesh tile is rasterised onto.
/// (129: engine tiles read data four times finer than their 33-sample meshes.)
pub const QUANTIZED_MESH_GRID: u32 = 129;

/// Decodes a quantized-mesh-1.0 tile (gzip'd or not) and rasterises its triangles onto a
/// `side` x `side` corner grid (sample `i` at `i / (side - 1)` of the tile, north row first),
/// interpolating heights linearly inside each triangle, as the mesh draws them.
pub fn decode_quantized_mesh(bytes: &[u8], side: u32) -> Result<HeightImage, DecodeError> {
    use globus_terrain::quantized_mesh::QuantizedMesh;
    let qm = QuantizedMesh::decode(bytes)
        .map_err(|e| DecodeError::Corrupt(format!("quantized-mesh: {e}")))?;
    if qm.triangle_count() == 0 {
        return Err(DecodeError::Corrupt("quantized-mesh: no triangles".into()));
    }
    let n = side.max(2) as usize;
    let scale = (n - 1) as f64 / 32767.0;
    // Grid coordinates: x east, y south.
    let xy = |i: usize| {
        (
            f64::from(qm.u[i]) * scale,
            (32767.0 - f64::from(qm.v[i])) * scale,
        )
    };
    let mut heights = vec![f64::NAN; n * n];
    for t in qm.indices.chunks_exact(3) {
        let [a, b, c] = [t[0] as usize, t[1] as usize, t[2] as usize];
        let (pa, pb, pc) = (xy(a), xy(b), xy(c));
        let (ha, hb, hc) = (qm.height_m(a), qm.height_m(b), qm.height_m(c));
        let det = (pb.1 - pc.1) * (pa.0 - pc.0) + (pc.0 - pb.0) * (pa.1 - pc.1);
        if det.abs() < 1e-12 {
            continue;
        }
        let x0 = pa.0.min(pb.0).min(pc.0).floor().max(0.0) as usize;
        let x1 = (pa.0.max(pb.0).max(pc.0).ceil() as usize).min(n - 1);
        let y0 = pa.1.min(pb.1).min(pc.1).floor().max(0.0) as usize;
        let y1 = (pa.1.max(pb.1).max(pc.1).ceil() as usize).min(n - 1);
        for y in y0..=y1 {
            for x in x0..=x1 {
                let (px, py) = (x as f64, y as f64);
                let l1 = ((pb.1 - pc.1) * (px - pc.0) + (pc.0 - pb.0) * (py - pc.1)) / det;
                let l2 = ((pc.1 - pa.1) * (px - pc.0) + (pa.0 - pc.0) * (py - pc.1)) / det;
                let l3 = 1.0 - l1 - l2;
                let eps = -1e-9;
                if l1 >= eps && l2 >= eps && l3 >= eps {
                    heights[y * n + x] = l1 * ha + l2 * hb + l3 * hc;
                }
            }
        }
    }
    // Samples no triangle covered (a mesh with holes): the nearest covered sample in the row,
    // else in the column, else the lowest height.
    let lowest = f64::from(qm.header.min_height_m);
    let mut filled = heights.clone();
    for y in 0..n {
        for x in 0..n {
            if filled[y * n + x].is_nan() {
                let row = (0..n)
                    .filter(|&i| !heights[y * n + i].is_nan())
                    .min_by_key(|&i| i.abs_diff(x))
                    .map(|i| heights[y * n + i]);
                let col = (0..n)
                    .filter(|&j| !heights[j * n + x].is_nan())
                    .min_by_key(|&j| j.abs_diff(y))
                    .map(|j| heights[j * n + x]);
                filled[y * n + x] = row.or(col).unwrap_or(lowest);
            }
        }
    }
    Ok(HeightImage {
        width: n as u32,
        height: n as u32,
        heights_m: filled.into_iter().map(|h| h as f32).collect(),
    })
}

#[cfg(test)]
mod tests {
    use super::*;

    fn png(w: u32, h: u32, rgba: &[u8]) -> Vec<u8> {
        let mut out = Vec::new();
        let mut enc = png::Encoder::new(&mut out, w, h);
        enc.set_color(png::ColorType::Rgba);
        enc.set_depth(png::BitDepth::Eight);
        let mut wr = enc.write_header().unwrap();
        wr.write_image_data(rgba).unwrap();
        wr.finish().unwrap();
        out
    }

    #[test]
    fn decodes_elevation_and_refuses_absurd_sizes_before_allocating() {
        let e = ElevationEncoding::Terrarium;
        let mut px = Vec::new();
        for h in [0.0, 1234.5, -20.0, 8848.0] {
            let [r, g, b] = e.encode(h);
            px.extend_from_slice(&[r, g, b, 255]);
        }
        let img = decode_elevation(&png(2, 2, &px), e, DecodeLimits::default()).unwrap();
        assert_eq!((img.width, img.height), (2, 2));
        for (got, want) in img.heights_m.iter().zip([0.0, 1234.5, -20.0, 8848.0]) {
            assert!(
                (f64::from(*got) - want).abs() <= e.step_m(),
                "{got} vs {want}"
            );
        }
        // A PNG of a few dozen bytes declaring 60000 x 60000 pixels: refused by its header.
        let huge = globus_test_support::http::absurd_png();
        let err = decode_image(&huge, DecodeLimits::default()).unwrap_err();
        assert!(
            matches!(
                err,
                DecodeError::TooLarge {
                    width: 60000,
                    height: 60000,
                    ..
                }
            ),
            "{err}"
        );
        assert!(err.to_string().contains("60000 x 60000"), "{err}");
        let err = decode_image(b"<html>503</html>", DecodeLimits::default()).unwrap_err();
        assert!(
            matches!(&err, DecodeError::NotAnImage(m) if m.contains("not an image")),
            "{err}"
        );
        assert!(decode_image(&px, DecodeLimits::default()).is_err());
    }

    #[test]
    fn quantized_mesh_tiles_rasterise_to_the_planes_they_draw() {
        use globus_terrain::quantized_mesh::QuantizedMesh;
        // Two triangles over the tile: a plane rising 100 m from west to east and 50 m from
        // south to north.
        let plane = |u: u16, v: u16| 100.0 * f64::from(u) / 32767.0 + 50.0 * f64::from(v) / 32767.0;
        let corners = [(0u16, 0u16), (32767, 0), (32767, 32767), (0, 32767)];
        let mut qm = QuantizedMesh::default();
        qm.header.min_height_m = 0.0;
        qm.header.max_height_m = 150.0;
        for &(u, v) in &corners {
            qm.u.push(u);
            qm.v.push(v);
            qm.height
                .push((plane(u, v) / 150.0 * 32767.0).round() as u16);
        }
        qm.indices = vec![0, 1, 2, 0, 2, 3];
        qm.west = vec![0, 3];
        qm.south = vec![0, 1];
        qm.east = vec![1, 2];
        qm.north = vec![3, 2];
        let img = decode_quantized_mesh(&qm.encode(true), 5).expect("decode");
        assert_eq!((img.width, img.height), (5, 5));
        for y in 0..5u32 {
            for x in 0..5u32 {
                let u = (f64::from(x) / 4.0 * 32767.0) as u16;
                let v = ((1.0 - f64::from(y) / 4.0) * 32767.0) as u16;
                let got = f64::from(img.heights_m[(y * 5 + x) as usize]);
                assert!(
                    (got - plane(u, v)).abs() < 0.05,
                    "({x},{y}): {got} vs {}",
                    plane(u, v)
                );
            }
        }
        assert!(decode_quantized_mesh(b"not a mesh at all", 5).is_err());
    }

    /// Mutations of PNG, JPEG and WebP tiles: every one decodes within the limits or is
    /// refused, none panics.
    #[test]
    fn fuzz_image() {
        let r = globus_test_support::fuzz::run("image", |b| {
            decode_image(b, DecodeLimits::default()).is_ok()
        });
        assert!(r.cases > 0 && r.accepted < r.cases, "{r:?}");
    }
}
