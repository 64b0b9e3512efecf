//! GeoTIFF: single-band elevation (i16, u16, i32, f32, f64) or 8-bit RGB/RGBA/grey imagery,
//! striped or tiled, uncompressed, Deflate or LZW, georeferenced by a model tiepoint and
//! pixel scale or by a model transformation, in EPSG:4326 or EPSG:3857.

use std::io::BufReader;
use std::path::Path;

use tiff::decoder::{Decoder, Limits};
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
    if dec
        .find_tag_unsigned::<u16>(Tag::PlanarConfiguration)
        .map_err(bad)?
        == Some(2)
    {
        return Err(TilerError::bad_input(
            path,
            "stores its bands in separate planes; rewrite it with gdal_translate -co INTERLEAVE=PIXEL",
        ));
    }
    let to_height = |v: f64| -> f32 {
        if Some(v) == nodata || !v.is_finite() {
            f32::NAN
        } else {
            v as f32
        }
    };
    let layout = ChunkLayout::read(path, &mut dec, width, height)?;
    let file = std::fs::File::open(path).map_err(|e| TilerError::io(path, e))?;
    let c = layout.channels;
    let mut bytes: Vec<u8> = Vec::new();
    let mut heights: Vec<f32> = Vec::new();
    match (layout.format, layout.bits) {
        (SampleFormat::Uint, 8) => bytes = vec![0u8; width * height * c],
        (SampleFormat::Uint | SampleFormat::Int, 16 | 32) | (SampleFormat::Float, 32 | 64)
            if c == 1 =>
        {
            heights = vec![0.0f32; width * height];
        }
        (f, b) => {
            return Err(TilerError::bad_input(
                path,
                format!(
                    "has {c} band(s) of {b}-bit {f:?} samples; expected one elevation band or 8-bit RGB/RGBA/grey"
                ),
            ));
        }
    }
    let mut raw = Vec::new();
    for i in 0..layout.offsets.len() {
        layout.read_chunk(path, &file, i, &mut raw)?;
        let (x0, y0, dw, dh) = layout.placement(i);
        let row_bytes = layout.chunk_w * c * layout.bits / 8;
        for r in 0..dh {
            let src = &raw[r * row_bytes..][..dw * c * layout.bits / 8];
            if bytes.is_empty() {
                let dst = &mut heights[(y0 + r) * width + x0..][..dw];
                let bits = layout.bits;
                for (k, d) in dst.iter_mut().enumerate() {
                    let v = &src[k * bits / 8..(k + 1) * bits / 8];
                    *d = to_height(layout.value(v));
                }
            } else {
                bytes[((y0 + r) * width + x0) * c..][..dw * c].copy_from_slice(src);
            }
        }
    }
    let image = |data: Vec<[u8; 4]>| {
        GeoTiff::Image(Raster {
            width,
            height,
            data,
            georef,
        })
    };
    Ok(match (bytes.is_empty(), c) {
        (false, 3) => image(
            bytes
                .chunks_exact(3)
                .map(|p| [p[0], p[1], p[2], 255])
                .collect(),
        ),
        (false, 4) => image(
            bytes
                .chunks_exact(4)
                .map(|p| [p[0], p[1], p[2], p[3]])
                .collect(),
        ),
        (false, 1) => image(bytes.into_iter().map(|g| [g, g, g, 255]).collect()),
        (true, _) => GeoTiff::Elevation(Raster {
            width,
            height,
            data: heights,
            georef,
        }),
        (false, n) => {
            return Err(TilerError::bad_input(
                path,
                format!("has {n} 8-bit bands; expected RGB, RGBA or grey"),
            ));
        }
    })
}

#[derive(Clone, Copy, Debug, PartialEq, Eq)]
enum SampleFormat {
    Uint,
    Int,
    Float,
}

#[derive(Clone, Copy, Debug, PartialEq, Eq)]
enum Compression {
    None,
    Lzw,
    Deflate,
}

/// How the pixels of a TIFF are cut into strips or tiles, compressed and stored. Chunks are
/// read and decompressed here rather than by the tiff crate, whose LZW reader rejects the
/// tiled LZW files GDAL writes (image-rs/image-tiff#395).
struct ChunkLayout {
    width: usize,
    height: usize,
    chunk_w: usize,
    chunk_h: usize,
    across: usize,
    offsets: Vec<u64>,
    counts: Vec<u64>,
    channels: usize,
    bits: usize,
    format: SampleFormat,
    compression: Compression,
    horizontal_predictor: bool,
    little_endian: bool,
}

impl ChunkLayout {
    fn read<R: std::io::Read + std::io::Seek>(
        path: &Path,
        dec: &mut Decoder<R>,
        width: usize,
        height: usize,
    ) -> Result<Self> {
        let unsupported = |what: String| TilerError::bad_input(path, what);
        let tag = |dec: &mut Decoder<R>, t: Tag| {
            dec.find_tag_unsigned::<u32>(t)
                .map_err(|e| TilerError::bad_input(path, format!("TIFF tag {t:?}: {e}")))
        };
        let channels = tag(dec, Tag::SamplesPerPixel)?.unwrap_or(1) as usize;
        let bits_all = dec
            .find_tag_unsigned_vec::<u16>(Tag::BitsPerSample)
            .map_err(|e| TilerError::bad_input(path, format!("TIFF tag BitsPerSample: {e}")))?
            .unwrap_or_else(|| vec![1]);
        let bits = usize::from(bits_all[0]);
        if bits_all.iter().any(|&b| usize::from(b) != bits) || !matches!(bits, 8 | 16 | 32 | 64) {
            return Err(unsupported(format!("has {bits_all:?} bits per sample")));
        }
        // One value per band.
        let format = dec
            .find_tag_unsigned_vec::<u16>(Tag::SampleFormat)
            .map_err(|e| TilerError::bad_input(path, format!("TIFF tag SampleFormat: {e}")))?
            .and_then(|v| v.first().copied())
            .unwrap_or(1);
        let format = match format {
            1 => SampleFormat::Uint,
            2 => SampleFormat::Int,
            3 => SampleFormat::Float,
            f => return Err(unsupported(format!("has sample format {f}"))),
        };
        let compression = match tag(dec, Tag::Compression)?.unwrap_or(1) {
            1 => Compression::None,
            5 => Compression::Lzw,
            8 | 32946 => Compression::Deflate,
            c => {
                return Err(unsupported(format!(
                    "uses TIFF compression {c}; uncompressed, LZW and Deflate are supported (gdal_translate -co COMPRESS=DEFLATE)"
                )));
            }
        };
        let horizontal_predictor = match tag(dec, Tag::Predictor)?.unwrap_or(1) {
            1 => false,
            2 if format != SampleFormat::Float => true,
            p => {
                return Err(unsupported(format!(
                    "uses TIFF predictor {p}; rewrite it with -co PREDICTOR=1 or 2"
                )));
            }
        };
        let tiled = tag(dec, Tag::TileWidth)?.is_some();
        let (chunk_w, chunk_h, off_tag, count_tag) = if tiled {
            (
                tag(dec, Tag::TileWidth)?.unwrap_or(0) as usize,
                tag(dec, Tag::TileLength)?.unwrap_or(0) as usize,
                Tag::TileOffsets,
                Tag::TileByteCounts,
            )
        } else {
            (
                width,
                (tag(dec, Tag::RowsPerStrip)?.map_or(height, |r| r as usize)).min(height),
                Tag::StripOffsets,
                Tag::StripByteCounts,
            )
        };
        let vec = |dec: &mut Decoder<R>, t: Tag| {
            dec.find_tag_unsigned_vec::<u64>(t)
                .map_err(|e| TilerError::bad_input(path, format!("TIFF tag {t:?}: {e}")))?
                .ok_or_else(|| unsupported(format!("lacks the {t:?} tag")))
        };
        let offsets = vec(dec, off_tag)?;
        let counts = vec(dec, count_tag)?;
        if chunk_w == 0 || chunk_h == 0 {
            return Err(unsupported("has an empty tile or strip size".into()));
        }
        let across = width.div_ceil(chunk_w);
        let expected = across * height.div_ceil(chunk_h);
        if offsets.len() != expected || counts.len() != expected {
            return Err(unsupported(format!(
                "lists {} chunks where {expected} are needed (band-separate planes are not supported)",
                offsets.len()
            )));
        }
        Ok(Self {
            width,
            height,
            chunk_w,
            chunk_h,
            across,
            offsets,
            counts,
            channels,
            bits,
            format,
            compression,
            horizontal_predictor,
            little_endian: dec.byte_order() == tiff::tags::ByteOrder::LittleEndian,
        })
    }

    /// Where chunk `i` goes: its top-left pixel and the size of its valid part.
    fn placement(&self, i: usize) -> (usize, usize, usize, usize) {
        let (x0, y0) = (
            (i % self.across) * self.chunk_w,
            (i / self.across) * self.chunk_h,
        );
        (
            x0,
            y0,
            self.chunk_w.min(self.width - x0),
            self.chunk_h.min(self.height - y0),
        )
    }

    /// Reads and decompresses chunk `i` into `out` (its full stored size, rows of
    /// `chunk_w` pixels; strips may end early), undoing the predictor.
    fn read_chunk(
        &self,
        path: &Path,
        file: &std::fs::File,
        i: usize,
        out: &mut Vec<u8>,
    ) -> Result<()> {
        use std::os::unix::fs::FileExt;
        let (_, _, _, dh) = self.placement(i);
        let row_bytes = self.chunk_w * self.channels * self.bits / 8;
        let rows = if self.chunk_w == self.width {
            dh
        } else {
            self.chunk_h
        };
        let want = row_bytes * rows;
        let mut packed = vec![0u8; self.counts[i] as usize];
        file.read_exact_at(&mut packed, self.offsets[i])
            .map_err(|e| {
                TilerError::bad_input(path, format!("chunk {i}: {e} (truncated file?)"))
            })?;
        out.clear();
        out.resize(want, 0);
        let got = match self.compression {
            Compression::None => {
                let n = packed.len().min(want);
                out[..n].copy_from_slice(&packed[..n]);
                n
            }
            Compression::Lzw => {
                let mut dec =
                    weezl::decode::Decoder::with_tiff_size_switch(weezl::BitOrder::Msb, 8);
                let mut produced = 0;
                let mut consumed = 0;
                // Stop when the chunk is full: writers may omit the end-of-information code.
                while produced < want {
                    let r = dec.decode_bytes(&packed[consumed..], &mut out[produced..]);
                    consumed += r.consumed_in;
                    produced += r.consumed_out;
                    match r.status {
                        Ok(weezl::LzwStatus::Ok) if r.consumed_in + r.consumed_out > 0 => {}
                        Ok(_) => break,
                        Err(e) => {
                            return Err(TilerError::bad_input(
                                path,
                                format!("chunk {i}: corrupt LZW data ({e})"),
                            ));
                        }
                    }
                }
                produced
            }
            Compression::Deflate => {
                use std::io::Read;
                let mut z = flate2::read::ZlibDecoder::new(&packed[..]);
                let mut produced = 0;
                while produced < want {
                    match z.read(&mut out[produced..]) {
                        Ok(0) => break,
                        Ok(n) => produced += n,
                        Err(e) => {
                            return Err(TilerError::bad_input(
                                path,
                                format!("chunk {i}: corrupt Deflate data ({e})"),
                            ));
                        }
                    }
                }
                produced
            }
        };
        if got < row_bytes * dh {
            return Err(TilerError::bad_input(
                path,
                format!(
                    "chunk {i} holds {got} bytes, {} expected (truncated or corrupt)",
                    row_bytes * dh
                ),
            ));
        }
        if self.horizontal_predictor {
            self.undo_predictor(out, row_bytes);
        }
        Ok(())
    }

    /// Horizontal differencing: each sample is stored as the difference to the one a pixel
    /// to its left, in its own integer width and byte order.
    fn undo_predictor(&self, data: &mut [u8], row_bytes: usize) {
        let bytes = self.bits / 8;
        let stride = self.channels * bytes;
        for row in data.chunks_exact_mut(row_bytes) {
            for k in stride..row.len() / bytes * bytes {
                if k % bytes != 0 {
                    continue;
                }
                let prev = self.read_uint(&row[k - stride..k - stride + bytes]);
                let cur = self.read_uint(&row[k..k + bytes]);
                let sum = prev.wrapping_add(cur);
                self.write_uint(&mut row[k..k + bytes], sum);
            }
        }
    }

    fn read_uint(&self, b: &[u8]) -> u64 {
        let mut v = 0u64;
        if self.little_endian {
            for (i, &x) in b.iter().enumerate() {
                v |= u64::from(x) << (8 * i);
            }
        } else {
            for &x in b {
                v = (v << 8) | u64::from(x);
            }
        }
        v
    }

    fn write_uint(&self, b: &mut [u8], v: u64) {
        let n = b.len();
        for i in 0..n {
            let byte = (v >> (8 * i)) as u8;
            if self.little_endian {
                b[i] = byte;
            } else {
                b[n - 1 - i] = byte;
            }
        }
    }

    /// One sample's value from its bytes.
    fn value(&self, b: &[u8]) -> f64 {
        let u = self.read_uint(b);
        match (self.format, self.bits) {
            (SampleFormat::Uint, _) => u as f64,
            (SampleFormat::Int, 16) => f64::from(u as u16 as i16),
            (SampleFormat::Int, 32) => f64::from(u as u32 as i32),
            (SampleFormat::Float, 32) => f64::from(f32::from_bits(u as u32)),
            (SampleFormat::Float, 64) => f64::from_bits(u),
            _ => f64::NAN,
        }
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
