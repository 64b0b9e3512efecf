//! GeoTIFF: single-band elevation (i16, u16, i32, f32, f64) or 8-bit RGB/RGBA/grey imagery,
//! striped or tiled, uncompressed, Deflate or LZW, georeferenced by a model tiepoint and
//! pixel scale or by a model transformation, in EPSG:4326 or EPSG:3857.

use std::io::BufReader;
use std::path::Path;

use tiff::decoder::{Decoder, Limits};
use tiff::tags::Tag;

use crate::error::{Result, TilerError};
use crate::lru::Lru;
use crate::raster::{Crs, ElevationRaster, Georef, Raster, Registration, RowSource};

/// What a GeoTIFF holds.
pub enum GeoTiff {
    /// One band of numbers with a nodata value, read whole so that its voids (`NaN`) can be
    /// filled across the raster.
    Elevation(ElevationRaster),
    /// One band of numbers without nodata, read strip by strip or tile by tile as needed.
    ElevationStream(Box<dyn RowSource<f32>>),
    /// 8-bit colour, read as needed.
    Image {
        /// The pixels.
        source: Box<dyn RowSource<[u8; 4]>>,
        /// Whether it has no alpha band.
        opaque: bool,
    },
}

/// Decoded chunks a streamed GeoTIFF keeps in memory by default, in bytes.
pub const CHUNK_CACHE_BYTES: usize = 512 << 20;

/// A GeoTIFF read a chunk (strip or tile) at a time, decoded chunks kept in an LRU cache.
struct ChunkedSource<T> {
    path: std::path::PathBuf,
    file: std::fs::File,
    layout: ChunkLayout,
    georef: Georef,
    convert: fn(&ChunkLayout, &[u8], &mut [T]),
    cache: std::sync::Mutex<Lru<usize, Vec<T>>>,
}

impl<T: Copy + Default + Send + Sync> ChunkedSource<T> {
    fn new(
        path: &Path,
        layout: ChunkLayout,
        georef: Georef,
        convert: fn(&ChunkLayout, &[u8], &mut [T]),
    ) -> Result<Self> {
        let chunk_bytes = layout.chunk_w * layout.chunk_h * std::mem::size_of::<T>();
        Ok(Self {
            path: path.to_owned(),
            file: std::fs::File::open(path).map_err(|e| TilerError::io(path, e))?,
            cache: std::sync::Mutex::new(Lru::new(CHUNK_CACHE_BYTES / chunk_bytes.max(1))),
            layout,
            georef,
            convert,
        })
    }

    /// Chunk `i` decoded: `chunk_w` samples per row, its valid rows.
    fn chunk(&self, i: usize) -> Result<std::sync::Arc<Vec<T>>> {
        let poisoned = || TilerError::BadOptions("a worker panicked".into());
        if let Some(c) = self.cache.lock().map_err(|_| poisoned())?.get(i) {
            return Ok(c);
        }
        let mut raw = Vec::new();
        self.layout
            .read_chunk(&self.path, &self.file, i, &mut raw)?;
        let (_, _, _, dh) = self.layout.placement(i);
        let l = &self.layout;
        let row_bytes = l.chunk_w * l.channels * l.bits / 8;
        let mut out = vec![T::default(); l.chunk_w * dh];
        for r in 0..dh {
            (self.convert)(
                l,
                &raw[r * row_bytes..(r + 1) * row_bytes],
                &mut out[r * l.chunk_w..(r + 1) * l.chunk_w],
            );
        }
        let out = std::sync::Arc::new(out);
        self.cache
            .lock()
            .map_err(|_| poisoned())?
            .insert(i, out.clone());
        Ok(out)
    }
}

impl<T: Copy + Default + Send + Sync> RowSource<T> for ChunkedSource<T> {
    fn width(&self) -> usize {
        self.layout.width
    }

    fn height(&self) -> usize {
        self.layout.height
    }

    fn georef(&self) -> &Georef {
        &self.georef
    }

    fn read_row(&self, row: usize, c0: usize, out: &mut [T]) -> Result<()> {
        let l = &self.layout;
        let (cy, rr) = (row / l.chunk_h, row % l.chunk_h);
        let mut done = 0;
        while done < out.len() {
            let c = c0 + done;
            let (cx, cc) = (c / l.chunk_w, c % l.chunk_w);
            let i = cy * l.across + cx;
            let (_, _, dw, _) = l.placement(i);
            let run = (dw - cc).min(out.len() - done);
            let chunk = self.chunk(i)?;
            out[done..done + run].copy_from_slice(&chunk[rr * l.chunk_w + cc..][..run]);
            done += run;
        }
        Ok(())
    }
}

fn heights_of(l: &ChunkLayout, raw: &[u8], out: &mut [f32]) {
    let b = l.bits / 8;
    for (o, v) in out.iter_mut().zip(raw.chunks_exact(b)) {
        *o = l.value(v) as f32;
    }
}

fn rgba_of(l: &ChunkLayout, raw: &[u8], out: &mut [[u8; 4]]) {
    match l.channels {
        1 => out
            .iter_mut()
            .zip(raw)
            .for_each(|(o, &g)| *o = [g, g, g, 255]),
        3 => out
            .iter_mut()
            .zip(raw.chunks_exact(3))
            .for_each(|(o, p)| *o = [p[0], p[1], p[2], 255]),
        _ => out
            .iter_mut()
            .zip(raw.chunks_exact(l.channels))
            .for_each(|(o, p)| *o = [p[0], p[1], p[2], p[3]]),
    }
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
    let c = layout.channels;
    match (layout.format, layout.bits, c) {
        (SampleFormat::Uint, 8, 1 | 3 | 4) => {
            return Ok(GeoTiff::Image {
                source: Box::new(ChunkedSource::new(path, layout, georef, rgba_of)?),
                opaque: c != 4,
            });
        }
        (_, 16 | 32 | 64, 1) if nodata.is_none() => {
            return Ok(GeoTiff::ElevationStream(Box::new(ChunkedSource::new(
                path, layout, georef, heights_of,
            )?)));
        }
        _ => {}
    }
    if c != 1 || !matches!(layout.bits, 16 | 32 | 64) {
        return Err(TilerError::bad_input(
            path,
            format!(
                "has {c} band(s) of {}-bit {:?} samples; expected one elevation band or 8-bit RGB/RGBA/grey",
                layout.bits, layout.format
            ),
        ));
    }
    // Elevation with a nodata value: read whole, voids become NaN for filling.
    let file = std::fs::File::open(path).map_err(|e| TilerError::io(path, e))?;
    let mut heights = vec![0.0f32; width * height];
    let mut raw = Vec::new();
    let mut line = Vec::new();
    for i in 0..layout.offsets.len() {
        layout.read_chunk(path, &file, i, &mut raw)?;
        let (x0, y0, dw, dh) = layout.placement(i);
        let row_bytes = layout.chunk_w * layout.bits / 8;
        line.resize(layout.chunk_w, 0.0f32);
        for r in 0..dh {
            heights_of(&layout, &raw[r * row_bytes..(r + 1) * row_bytes], &mut line);
            let dst = &mut heights[(y0 + r) * width + x0..][..dw];
            for (d, &v) in dst.iter_mut().zip(&line) {
                *d = to_height(f64::from(v));
            }
        }
    }
    Ok(GeoTiff::Elevation(Raster {
        width,
        height,
        data: heights,
        georef,
    }))
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
