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

/// The most values one TIFF tag may hold (a tiled GeoTIFF of 2^22 tiles of 256 x 256 would
/// hold 2.7e14 pixels).
pub const MAX_TAG_VALUES: usize = 1 << 22;

/// The most pixels a side a GeoTIFF may declare (a whole Earth at 1 m is 4e7).
pub const MAX_SIDE: usize = 1 << 26;

/// The largest strip or tile, decoded, in bytes: 64 MiB (GDAL writes 256 x 256 tiles, or strips
/// of a few rows; a 16384 x 1024 strip of f32 fits).
pub const MAX_CHUNK_BYTES: usize = 256 << 20;

/// The most pixels of an elevation raster with voids, read whole for filling (4 GiB of f32).
pub const MAX_WHOLE_SAMPLES: usize = 1 << 30;

/// The largest height a sample may hold, in metres (anything larger is a void marker or a unit
/// mistake, and would be clipped by every tile encoding).
pub use globus_terrain::MAX_ABS_HEIGHT_M;

/// Converts one row of raw samples; returns the first sample that is no height, if any.
type Convert<T> = fn(&ChunkLayout, &[u8], &mut [T]) -> Option<(usize, f64)>;

/// A GeoTIFF read a chunk (strip or tile) at a time, decoded chunks kept in an LRU cache.
struct ChunkedSource<T> {
    path: std::path::PathBuf,
    file: std::fs::File,
    layout: ChunkLayout,
    georef: Georef,
    convert: Convert<T>,
    cache: std::sync::Mutex<Lru<usize, Vec<T>>>,
}

impl<T: Copy + Default + Send + Sync> ChunkedSource<T> {
    fn new(path: &Path, layout: ChunkLayout, georef: Georef, convert: Convert<T>) -> Result<Self> {
        let chunk_bytes = layout.chunk_w * layout.chunk_h * std::mem::size_of::<T>();
        Ok(Self {
            path: path.to_owned(),
            file: crate::input::open_regular(path)?,
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
            if let Some((c, v)) = (self.convert)(
                l,
                &raw[r * row_bytes..(r + 1) * row_bytes],
                &mut out[r * l.chunk_w..(r + 1) * l.chunk_w],
            ) {
                let (x0, y0, _, _) = l.placement(i);
                return Err(implausible_height(&self.path, v, x0 + c, y0 + r));
            }
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

/// Heights of one row; the index of the first value that is no height in metres (beyond
/// [`MAX_ABS_HEIGHT_M`], infinite or NaN in a raster without nodata), if any.
fn heights_of(l: &ChunkLayout, raw: &[u8], out: &mut [f32]) -> Option<(usize, f64)> {
    let b = l.bits / 8;
    let mut bad = None;
    for (i, (o, v)) in out.iter_mut().zip(raw.chunks_exact(b)).enumerate() {
        let v = l.value(v);
        if bad.is_none() && (v.is_nan() || v.abs() > MAX_ABS_HEIGHT_M) {
            bad = Some((i, v));
        }
        *o = v as f32;
    }
    bad
}

fn implausible_height(path: &Path, v: f64, x: usize, y: usize) -> TilerError {
    TilerError::bad_input(
        path,
        format!(
            "pixel ({x}, {y}) holds {v}, which is no height in metres (|h| <= {MAX_ABS_HEIGHT_M}); mark voids with GDAL_NODATA"
        ),
    )
}

/// Refuses georeferencing whose raster reaches outside its CRS (a pixel scale of 1e10 degrees).
fn check_extent(
    path: &Path,
    crs: Crs,
    (ox, oy): (f64, f64),
    (sx, sy): (f64, f64),
    (width, height): (usize, usize),
) -> Result<()> {
    let (x1, y1) = (ox + sx * width as f64, oy - sy * height as f64);
    // A pixel of slack: rasters often overhang the edges by half a pixel.
    let (lim_x, lim_y, unit) = match crs {
        Crs::Geographic => (540.0, 90.0, "degrees"),
        Crs::WebMercator => (2.0 * 20_037_508.342_789_244, 20_037_508.342_789_244, "m"),
    };
    let inside = |v: f64, lim: f64, step: f64| v.abs() <= lim + step;
    if !(inside(ox, lim_x, sx)
        && inside(x1, lim_x, sx)
        && inside(oy, lim_y, sy)
        && inside(y1, lim_y, sy))
    {
        return Err(TilerError::bad_input(
            path,
            format!(
                "covers x {ox}..{x1}, y {y1}..{oy} {unit}, outside its CRS (wrong pixel scale or tiepoint?)"
            ),
        ));
    }
    Ok(())
}

fn rgba_of(l: &ChunkLayout, raw: &[u8], out: &mut [[u8; 4]]) -> Option<(usize, f64)> {
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
    None
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
    let file = crate::input::open_regular(path)?;
    let file_len = file.metadata().map_err(|e| TilerError::io(path, e))?.len();
    let bad = |e: tiff::TiffError| TilerError::bad_input(path, format!("TIFF: {e}"));
    // No tag can hold more values than the file has bytes, nor more than MAX_TAG_VALUES (the
    // tiff crate sizes a tag's vector from its declared count: the fuzzer found a 137 GB one);
    // chunks are read by hand below.
    let mut limits = Limits::unlimited();
    limits.ifd_value_size = usize::try_from(file_len).unwrap_or(usize::MAX);
    let values = usize::try_from(file_len)
        .unwrap_or(usize::MAX)
        .min(MAX_TAG_VALUES);
    limits.decoding_buffer_size =
        values.saturating_mul(std::mem::size_of::<tiff::decoder::ifd::Value>());
    let mut dec = Decoder::new(BufReader::new(file))
        .map_err(bad)?
        .with_limits(limits);
    let (width, height) = dec.dimensions().map_err(bad)?;
    let (width, height) = (width as usize, height as usize);
    if width < 2 || height < 2 {
        return Err(TilerError::bad_input(
            path,
            format!("is only {width}x{height} pixels"),
        ));
    }
    if width > MAX_SIDE || height > MAX_SIDE {
        return Err(TilerError::bad_input(
            path,
            format!(
                "declares {width}x{height} pixels; at most {MAX_SIDE} a side are supported (split it with gdal_translate -srcwin)"
            ),
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
    if !(sx > 0.0 && sy > 0.0 && sx.is_finite() && sy.is_finite()) {
        return Err(TilerError::bad_input(
            path,
            format!(
                "has an unusable pixel size {sx} x {sy} (north-up rasters have positive x and negative y steps)"
            ),
        ));
    }
    if !(ox.is_finite() && oy.is_finite()) {
        return Err(TilerError::bad_input(
            path,
            format!("has an unusable origin ({ox}, {oy}) in its tiepoint or transformation"),
        ));
    }
    check_extent(path, crs, (ox, oy), (sx, sy), (width, height))?;
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
    let nodata = match dec.find_tag(Tag::GdalNodata).map_err(bad)? {
        None => None,
        Some(v) => {
            let text = v.into_string().map_err(bad)?;
            let text = text.trim_matches(char::from(0)).trim();
            match text.parse::<f64>() {
                Ok(v) => Some(v),
                // GDAL writes "nan" for float rasters whose voids are NaN: voids already.
                Err(_) if text.eq_ignore_ascii_case("nan") => None,
                Err(_) => {
                    return Err(TilerError::bad_input(
                        path,
                        format!("has GDAL_NODATA {text:?}, which is not a number"),
                    ));
                }
            }
        }
    };
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
    let layout = ChunkLayout::read(path, &mut dec, width, height, file_len)?;
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
    if width * height > MAX_WHOLE_SAMPLES {
        return Err(TilerError::bad_input(
            path,
            format!(
                "has a nodata value and {width}x{height} pixels; rasters with voids are read whole for filling, up to {MAX_WHOLE_SAMPLES} pixels (split it with gdal_translate -srcwin, or fill its voids first)"
            ),
        ));
    }
    let file = crate::input::open_regular(path)?;
    let mut heights = vec![0.0f32; width * height];
    let mut raw = Vec::new();
    let mut line = Vec::new();
    for i in 0..layout.offsets.len() {
        layout.read_chunk(path, &file, i, &mut raw)?;
        let (x0, y0, dw, dh) = layout.placement(i);
        let row_bytes = layout.chunk_w * layout.bits / 8;
        line.resize(layout.chunk_w, 0.0f64);
        for r in 0..dh {
            let src = &raw[r * row_bytes..(r + 1) * row_bytes];
            for (o, v) in line.iter_mut().zip(src.chunks_exact(layout.bits / 8)) {
                *o = layout.value(v);
            }
            let dst = &mut heights[(y0 + r) * width + x0..][..dw];
            for (c, (d, &v)) in dst.iter_mut().zip(&line).enumerate() {
                *d = if Some(v) == nodata || v.is_nan() {
                    f32::NAN
                } else if v.abs() <= MAX_ABS_HEIGHT_M {
                    v as f32
                } else {
                    return Err(implausible_height(path, v, x0 + c, y0 + r));
                };
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
        file_len: u64,
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
        // TIFF tiles are multiples of 16 and may overhang the image, but not by more than a tile.
        if chunk_w > width.next_multiple_of(16).max(1024)
            || chunk_h > height.next_multiple_of(16).max(1024)
        {
            return Err(unsupported(format!(
                "declares {chunk_w}x{chunk_h} tiles over a {width}x{height} image"
            )));
        }
        let chunk_bytes = chunk_w * chunk_h * channels * bits / 8;
        if chunk_bytes > MAX_CHUNK_BYTES {
            return Err(unsupported(format!(
                "has {chunk_w}x{chunk_h} strips or tiles of {} MiB each; at most {} MiB are supported (rewrite it with gdal_translate -co TILED=YES)",
                chunk_bytes >> 20,
                MAX_CHUNK_BYTES >> 20
            )));
        }
        let across = width.div_ceil(chunk_w);
        let expected = across * height.div_ceil(chunk_h);
        if offsets.len() != expected || counts.len() != expected {
            return Err(unsupported(format!(
                "lists {} chunks where {expected} are needed (band-separate planes are not supported)",
                offsets.len()
            )));
        }
        // Compressed data can exceed what it holds a little; not by more than an eighth.
        let max_count = (chunk_bytes + chunk_bytes / 8 + 4096) as u64;
        for (i, (&o, &n)) in offsets.iter().zip(&counts).enumerate() {
            if n > max_count || o.checked_add(n).is_none_or(|end| end > file_len) {
                return Err(unsupported(format!(
                    "chunk {i} claims {n} bytes at offset {o}, beyond the file's {file_len} bytes or its {chunk_bytes}-byte chunk size (truncated or corrupt)"
                )));
            }
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

    /// A little-endian classic TIFF written tag by tag, for crafting what GDAL never writes.
    struct Crafted {
        entries: Vec<(u16, u16, u32, Vec<u8>)>,
        pixels: Vec<u8>,
    }

    const SHORT: u16 = 3;
    const LONG: u16 = 4;
    const DOUBLE: u16 = 12;
    const ASCII: u16 = 2;

    impl Crafted {
        /// `width` x `height` single-band 16-bit signed elevation in EPSG:4326, one strip
        /// holding `pixels`, 0.01 degree pixels from (7, 47).
        fn elevation(width: u32, height: u32, pixels: Vec<u8>) -> Self {
            let mut c = Self {
                entries: Vec::new(),
                pixels,
            };
            c.long(256, &[width]);
            c.long(257, &[height]);
            c.short(258, &[16]);
            c.short(259, &[1]);
            c.short(262, &[1]);
            c.short(277, &[1]);
            c.long(278, &[height]);
            c.short(339, &[2]);
            c.double(33550, &[0.01, 0.01, 0.0]);
            c.double(33922, &[0.0, 0.0, 0.0, 7.0, 47.0, 0.0]);
            c.short(34735, &[1, 1, 0, 2, 1024, 0, 1, 2, 2048, 0, 1, 4326]);
            c
        }

        fn set(&mut self, tag: u16, typ: u16, count: u32, bytes: Vec<u8>) {
            self.entries.retain(|e| e.0 != tag);
            self.entries.push((tag, typ, count, bytes));
        }

        fn short(&mut self, tag: u16, v: &[u16]) {
            let b = v.iter().flat_map(|x| x.to_le_bytes()).collect();
            self.set(tag, SHORT, v.len() as u32, b);
        }

        fn long(&mut self, tag: u16, v: &[u32]) {
            let b = v.iter().flat_map(|x| x.to_le_bytes()).collect();
            self.set(tag, LONG, v.len() as u32, b);
        }

        fn double(&mut self, tag: u16, v: &[f64]) {
            let b = v.iter().flat_map(|x| x.to_le_bytes()).collect();
            self.set(tag, DOUBLE, v.len() as u32, b);
        }

        fn ascii(&mut self, tag: u16, v: &str) {
            let mut b = v.as_bytes().to_vec();
            b.push(0);
            self.set(tag, ASCII, b.len() as u32, b);
        }

        /// Writes it, the strip or tile offsets pointing at the pixels (unless set already).
        fn write(mut self, name: &str) -> std::path::PathBuf {
            let tiled = self.entries.iter().any(|e| e.0 == 322);
            let (off_tag, count_tag) = if tiled { (324, 325) } else { (273, 279) };
            let n = self.pixels.len() as u32;
            if !self.entries.iter().any(|e| e.0 == count_tag) {
                self.long(count_tag, &[n]);
            }
            self.long(off_tag, &[8]);
            self.entries.sort_by_key(|e| e.0);
            let mut out = b"II*\0".to_vec();
            let ifd = 8 + self.pixels.len();
            out.extend((ifd as u32).to_le_bytes());
            out.extend(&self.pixels);
            let mut extra = ifd + 2 + 12 * self.entries.len() + 4;
            let mut tail: Vec<u8> = Vec::new();
            out.extend((self.entries.len() as u16).to_le_bytes());
            for (tag, typ, count, bytes) in &self.entries {
                out.extend(tag.to_le_bytes());
                out.extend(typ.to_le_bytes());
                out.extend(count.to_le_bytes());
                if bytes.len() <= 4 {
                    let mut v = bytes.clone();
                    v.resize(4, 0);
                    out.extend(v);
                } else {
                    out.extend((extra as u32).to_le_bytes());
                    tail.extend(bytes);
                    extra += bytes.len();
                }
            }
            out.extend(0u32.to_le_bytes());
            out.extend(tail);
            let dir = std::env::temp_dir().join(format!("globus-geotiff-{}", std::process::id()));
            std::fs::create_dir_all(&dir).unwrap();
            let path = dir.join(name);
            std::fs::write(&path, out).unwrap();
            path
        }
    }

    fn heights(v: &[i16]) -> Vec<u8> {
        v.iter().flat_map(|h| h.to_le_bytes()).collect()
    }

    fn refused(c: Crafted, name: &str, needle: &str) {
        let path = c.write(name);
        let e = match read_geotiff(&path) {
            Ok(_) => panic!("{name} was accepted"),
            Err(e) => e.to_string(),
        };
        assert!(e.contains(name) && e.contains(needle), "{name}: {e}");
    }

    /// The crafted writer makes files the reader takes: heights come back where they were.
    #[test]
    fn a_crafted_tiff_reads_back() {
        let path = Crafted::elevation(3, 2, heights(&[1, 2, 3, -4, 5, 8848])).write("ok.tif");
        let Ok(GeoTiff::ElevationStream(src)) = read_geotiff(&path) else {
            panic!("not streamed elevation");
        };
        let mut row = [0.0f32; 3];
        src.read_row(1, 0, &mut row).unwrap();
        assert_eq!(row, [-4.0, 5.0, 8848.0]);
        assert!((src.georef().x0 - 7.005).abs() < 1e-12);
    }

    /// Dimensions of 2^31-1 a side or 2^32-1 wide aborted on a 9.2 EB allocation; a tile
    /// width of 2^31 panicked with "capacity overflow"; one 65536 x 65536 tile over a
    /// 256 x 256 image took 12.3 GB: each is refused before anything is allocated.
    #[test]
    fn giant_dimensions_and_tiles_are_refused_before_allocating() {
        refused(
            Crafted::elevation(i32::MAX as u32, i32::MAX as u32, heights(&[0; 4])),
            "huge.tif",
            "pixels",
        );
        refused(
            Crafted::elevation(u32::MAX, 2, heights(&[0; 4])),
            "wide.tif",
            "pixels",
        );
        let mut c = Crafted::elevation(256, 256, heights(&[0; 4]));
        c.long(322, &[1 << 31]);
        c.long(323, &[16]);
        // The tiff crate itself may refuse it first: either way one error naming the file.
        refused(c, "tilewidth.tif", "");
        let mut c = Crafted::elevation(256, 256, heights(&[0; 4]));
        c.long(322, &[65536]);
        c.long(323, &[65536]);
        refused(c, "bigtile.tif", "tiles over a 256x256 image");
        // A chunk claiming more bytes than the file has.
        let mut c = Crafted::elevation(64, 64, heights(&[0; 4]));
        c.long(279, &[8192]);
        refused(c, "short.tif", "beyond the file");
    }

    /// Georeferencing and sample nonsense: a pixel scale of 1e10 degrees, an infinite
    /// tiepoint, GDAL_NODATA "abc", heights of 1e38 and infinity (clipped to 32,768 m before).
    #[test]
    fn nonsense_georeferencing_and_heights_are_refused() {
        let mut c = Crafted::elevation(2, 2, heights(&[0; 4]));
        c.double(33550, &[1e10, 1e10, 0.0]);
        refused(c, "scale.tif", "outside its CRS");
        let mut c = Crafted::elevation(2, 2, heights(&[0; 4]));
        c.double(33922, &[0.0, 0.0, 0.0, f64::INFINITY, 47.0, 0.0]);
        refused(c, "inf-tie.tif", "unusable origin");
        let mut c = Crafted::elevation(2, 2, heights(&[0; 4]));
        c.ascii(42113, "abc");
        refused(c, "nodata.tif", "\"abc\"");
        for (name, v) in [("e38.tif", 1e38f32), ("inf.tif", f32::INFINITY)] {
            let px: Vec<u8> = [0.0, 1.0, v, 2.0]
                .iter()
                .flat_map(|h: &f32| h.to_le_bytes())
                .collect();
            let mut c = Crafted::elevation(2, 2, px);
            c.short(258, &[32]);
            c.short(339, &[3]);
            let path = c.write(name);
            let src = match read_geotiff(&path) {
                Ok(GeoTiff::ElevationStream(s)) => s,
                _ => panic!("{name}: not read as streamed elevation"),
            };
            let mut row = [0.0f32; 2];
            let e = src.read_row(1, 0, &mut row).unwrap_err().to_string();
            assert!(e.contains(name) && e.contains("no height"), "{e}");
            // With a nodata value the raster is read whole: refused there too.
            let mut c = Crafted::elevation(
                2,
                2,
                [0.0f32, 1.0, v, 2.0]
                    .iter()
                    .flat_map(|h| h.to_le_bytes())
                    .collect(),
            );
            c.short(258, &[32]);
            c.short(339, &[3]);
            c.ascii(42113, "-9999");
            refused(c, name, "no height");
        }
    }

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

    /// Mutations of GDAL-written GeoTIFFs (tiled Deflate i16, LZW-predicted f32 strips with
    /// nodata, RGB in Web Mercator): every one is read to its last row or refused, none panics.
    #[test]
    fn fuzz_geotiff() {
        let dir = std::env::temp_dir().join(format!("globus-fuzz-tiff-{}", std::process::id()));
        std::fs::create_dir_all(&dir).unwrap();
        let path = dir.join("case.tif");
        let r = globus_test_support::fuzz::run("geotiff", |b| {
            std::fs::write(&path, b).unwrap();
            fn rows<T: Copy + Default>(s: &dyn RowSource<T>) -> bool {
                let mut row = vec![T::default(); s.width()];
                (0..s.height()).all(|y| s.read_row(y, 0, &mut row).is_ok())
            }
            match read_geotiff(&path) {
                Err(_) => false,
                Ok(GeoTiff::Elevation(_)) => true,
                Ok(GeoTiff::ElevationStream(s)) => rows(s.as_ref()),
                Ok(GeoTiff::Image { source, .. }) => rows(source.as_ref()),
            }
        });
        std::fs::remove_dir_all(&dir).ok();
        assert!(r.cases > 0 && r.accepted < r.cases, "{r:?}");
    }
}
