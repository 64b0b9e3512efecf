//! The two kinds of pyramid, elevation and imagery: codecs that make a parent from its four
//! children and encode tiles ([`TileCodec`]), and layers that make the finest tiles from a
//! source ([`Layer`]).

use globus_tiling::{GeoRect, TileKey, TilingScheme};

use crate::encoding::ElevationEncoding;
use crate::error::Result;
use crate::format::{ImageFormat, encode_image, encode_png};
use crate::raster::RowSource;
use crate::resample::{SampleGrid, tile_taps};

/// How tiles of one kind are combined, encoded and decoded; needs no source, so shard
/// merging can build the top of a pyramid from the tiles the shards handed over.
pub trait TileCodec: Sync {
    /// A decoded tile.
    type Tile: Send + Sync + Clone;
    /// The sample grid of the tiles.
    fn grid(&self) -> SampleGrid;
    /// A tile from its children (north-west, north-east, south-west, south-east; `None`
    /// where a child lies outside the data).
    fn downsample(&self, children: &[Option<Self::Tile>; 4]) -> Self::Tile;
    /// The tile's file bytes.
    fn encode(&self, key: TileKey, tile: &Self::Tile) -> Result<Vec<u8>>;
    /// A tile back from its file bytes (to resume an interrupted run).
    fn decode(&self, key: TileKey, bytes: &[u8]) -> Result<Self::Tile>;
    /// The file extension of its tiles.
    fn extension(&self) -> &'static str;
    /// The tile's samples, exactly (little-endian), for handing a tile between machines.
    fn tile_to_raw(&self, tile: &Self::Tile) -> Vec<u8>;
    /// A tile from [`TileCodec::tile_to_raw`] bytes.
    fn raw_to_tile(&self, key: TileKey, raw: &[u8]) -> Result<Self::Tile>;
}

/// What a pyramid is made of: a codec and a way to make tiles at the finest level.
pub trait Layer: Sync {
    /// The codec of its tiles.
    type Codec: TileCodec;
    /// The codec.
    fn codec(&self) -> &Self::Codec;
    /// The tile at the finest level.
    fn leaf(&self, scheme: TilingScheme, key: TileKey) -> Result<<Self::Codec as TileCodec>::Tile>;
    /// Source voids filled while making leaves (sources that load lazily).
    fn voids_filled(&self) -> usize {
        0
    }
}

/// Elevation tiles: `size` x `size` heights in metres on a [`SampleGrid::Corners`] grid,
/// encoded as RGB PNG.
#[derive(Clone, Copy, Debug)]
pub struct ElevationCodec {
    /// Samples per tile side.
    pub size: usize,
    /// How heights become RGB.
    pub encoding: ElevationEncoding,
}

/// Imagery tiles: `size` x `size` straight RGBA cells.
#[derive(Clone, Copy, Debug)]
pub struct ImageryCodec {
    /// Pixels per tile side.
    pub size: usize,
    /// How tiles are written.
    pub format: ImageFormat,
}

fn raw_size_error(key: TileKey, got: usize, want: usize) -> crate::error::TilerError {
    crate::error::TilerError::Encode {
        key,
        problem: format!("handed-over tile has {got} bytes, expected {want}"),
    }
}

impl TileCodec for ElevationCodec {
    type Tile = Vec<f32>;

    fn grid(&self) -> SampleGrid {
        SampleGrid::Corners
    }

    fn downsample(&self, children: &[Option<Vec<f32>>; 4]) -> Vec<f32> {
        downsample_corners(children, self.size)
    }

    fn encode(&self, key: TileKey, tile: &Vec<f32>) -> Result<Vec<u8>> {
        let rgb: Vec<u8> = tile
            .iter()
            .flat_map(|&h| self.encoding.encode(f64::from(h)))
            .collect();
        encode_png(key, &rgb, self.size, 3)
    }

    fn decode(&self, key: TileKey, bytes: &[u8]) -> Result<Vec<f32>> {
        let rgba = decode_rgba(key, bytes, self.size)?;
        Ok(rgba
            .iter()
            .map(|p| self.encoding.decode([p[0], p[1], p[2]]) as f32)
            .collect())
    }

    fn extension(&self) -> &'static str {
        "png"
    }

    fn tile_to_raw(&self, tile: &Vec<f32>) -> Vec<u8> {
        tile.iter().flat_map(|v| v.to_le_bytes()).collect()
    }

    fn raw_to_tile(&self, key: TileKey, raw: &[u8]) -> Result<Vec<f32>> {
        let want = self.size * self.size * 4;
        if raw.len() != want {
            return Err(raw_size_error(key, raw.len(), want));
        }
        Ok(raw
            .chunks_exact(4)
            .map(|b| f32::from_le_bytes([b[0], b[1], b[2], b[3]]))
            .collect())
    }
}

impl TileCodec for ImageryCodec {
    type Tile = Vec<[u8; 4]>;

    fn grid(&self) -> SampleGrid {
        SampleGrid::Cells
    }

    fn downsample(&self, children: &[Option<Vec<[u8; 4]>>; 4]) -> Vec<[u8; 4]> {
        downsample_cells(children, self.size)
    }

    fn encode(&self, key: TileKey, tile: &Vec<[u8; 4]>) -> Result<Vec<u8>> {
        encode_image(key, tile, self.size, self.format)
    }

    fn decode(&self, key: TileKey, bytes: &[u8]) -> Result<Vec<[u8; 4]>> {
        decode_rgba(key, bytes, self.size)
    }

    fn extension(&self) -> &'static str {
        self.format.extension()
    }

    fn tile_to_raw(&self, tile: &Vec<[u8; 4]>) -> Vec<u8> {
        tile.as_flattened().to_vec()
    }

    fn raw_to_tile(&self, key: TileKey, raw: &[u8]) -> Result<Vec<[u8; 4]>> {
        let want = self.size * self.size * 4;
        if raw.len() != want {
            return Err(raw_size_error(key, raw.len(), want));
        }
        Ok(raw
            .chunks_exact(4)
            .map(|p| [p[0], p[1], p[2], p[3]])
            .collect())
    }
}

/// Elevation tiles resampled from a raster.
pub struct ElevationLayer {
    /// The (void-filled) source.
    pub source: Box<dyn RowSource<f32>>,
    /// Where the source has data, clipped to the requested bounds.
    pub footprint: GeoRect,
    /// Tile size and encoding.
    pub codec: ElevationCodec,
}

/// Height assigned outside the data's footprint: the ellipsoid (sea level), never a void
/// marker.
pub const OUTSIDE_HEIGHT_M: f32 = 0.0;

impl Layer for ElevationLayer {
    type Codec = ElevationCodec;

    fn codec(&self) -> &ElevationCodec {
        &self.codec
    }

    fn voids_filled(&self) -> usize {
        self.source.voids_filled()
    }

    fn leaf(&self, scheme: TilingScheme, key: TileKey) -> Result<Vec<f32>> {
        let n = self.codec.size;
        let src = &*self.source;
        let (cols, rows) = tile_taps(
            scheme,
            key,
            SampleGrid::Corners,
            n,
            src.georef(),
            &self.footprint,
            (src.width(), src.height()),
        );
        let mut out = vec![OUTSIDE_HEIGHT_M; n * n];
        // Separable: a vertical pass over the source columns the tile touches, then the
        // horizontal taps over that line.
        let (c_lo, c_hi) = cols.span();
        let span = (c_hi - c_lo + 1) as usize;
        let mut line = vec![0.0f32; span];
        let mut src_row = vec![0.0f32; span];
        for j in 0..n {
            if !rows.inside[j] {
                continue;
            }
            line.fill(0.0);
            for &(r, wr) in rows.of(j) {
                src.read_row(r as usize, c_lo as usize, &mut src_row)?;
                for (l, &v) in line.iter_mut().zip(&src_row) {
                    *l += wr * v;
                }
            }
            let out_row = &mut out[j * n..(j + 1) * n];
            for (i, o) in out_row.iter_mut().enumerate() {
                if cols.inside[i] {
                    *o = cols
                        .of(i)
                        .iter()
                        .map(|&(c, wc)| wc * line[(c - c_lo) as usize])
                        .sum();
                }
            }
        }
        Ok(out)
    }
}

/// A parent on a corner grid from its children: the children form a `(2n - 1)` mosaic
/// whose even samples coincide with the parent's. Interior parent samples take the
/// binomial 3x3 filter `[1 2 1] x [1 2 1] / 16` around their coincident sample; samples on a
/// tile edge take `[1 2 1] / 4` along the edge only, and corners are copied, so a parent's
/// edge depends only on the shared edge line and neighbouring parents agree exactly.
/// Missing children count as [`OUTSIDE_HEIGHT_M`].
pub fn downsample_corners(children: &[Option<Vec<f32>>; 4], n: usize) -> Vec<f32> {
    let m = 2 * n - 1;
    let mut mosaic = vec![OUTSIDE_HEIGHT_M; m * m];
    for (q, child) in children.iter().enumerate() {
        let Some(child) = child else { continue };
        let (ox, oy) = ((q & 1) * (n - 1), (q >> 1) * (n - 1));
        for r in 0..n {
            mosaic[(oy + r) * m + ox..][..n].copy_from_slice(&child[r * n..(r + 1) * n]);
        }
    }
    let at = |x: usize, y: usize| mosaic[y * m + x];
    let mut out = vec![0.0f32; n * n];
    for j in 0..n {
        let y = 2 * j;
        let edge_y = j == 0 || j == n - 1;
        for i in 0..n {
            let x = 2 * i;
            let edge_x = i == 0 || i == n - 1;
            out[j * n + i] = match (edge_x, edge_y) {
                (true, true) => at(x, y),
                (false, true) => 0.25 * (at(x - 1, y) + 2.0 * at(x, y) + at(x + 1, y)),
                (true, false) => 0.25 * (at(x, y - 1) + 2.0 * at(x, y) + at(x, y + 1)),
                (false, false) => {
                    let row = |yy: usize| at(x - 1, yy) + 2.0 * at(x, yy) + at(x + 1, yy);
                    (row(y - 1) + 2.0 * row(y) + row(y + 1)) / 16.0
                }
            };
        }
    }
    out
}

/// Imagery tiles resampled from an image.
pub struct ImageryLayer {
    /// The source image.
    pub source: Box<dyn RowSource<[u8; 4]>>,
    /// Where the source has data, clipped to the requested bounds.
    pub footprint: GeoRect,
    /// Tile size and format.
    pub codec: ImageryCodec,
    /// Whether every source pixel is opaque (enables a faster resampler).
    pub opaque: bool,
}

impl Layer for ImageryLayer {
    type Codec = ImageryCodec;

    fn codec(&self) -> &ImageryCodec {
        &self.codec
    }

    fn leaf(&self, scheme: TilingScheme, key: TileKey) -> Result<Vec<[u8; 4]>> {
        let n = self.codec.size;
        let src = &*self.source;
        let (cols, rows) = tile_taps(
            scheme,
            key,
            SampleGrid::Cells,
            n,
            src.georef(),
            &self.footprint,
            (src.width(), src.height()),
        );
        let mut out = vec![[0u8; 4]; n * n];
        // Separable: a vertical pass into premultiplied RGBA over the source columns the tile
        // touches, then the horizontal taps over that line.
        let (c_lo, c_hi) = cols.span();
        if self.opaque {
            resample_rgba::<true>(src, &cols, &rows, (c_lo, c_hi), &mut out, n)?;
        } else {
            resample_rgba::<false>(src, &cols, &rows, (c_lo, c_hi), &mut out, n)?;
        }
        Ok(out)
    }
}

/// Separable resampling of RGBA: a vertical pass into premultiplied sums over the source
/// columns `c_lo..=c_hi`, then the horizontal taps. `OPAQUE` sources skip the alpha weighting.
fn resample_rgba<const OPAQUE: bool>(
    src: &dyn RowSource<[u8; 4]>,
    cols: &crate::resample::Taps,
    rows: &crate::resample::Taps,
    (c_lo, c_hi): (u32, u32),
    out: &mut [[u8; 4]],
    n: usize,
) -> Result<()> {
    let span = (c_hi - c_lo + 1) as usize;
    let mut line = vec![[0.0f32; 4]; span];
    let mut src_row = vec![[0u8; 4]; span];
    for j in 0..n {
        if !rows.inside[j] {
            continue;
        }
        line.fill([0.0; 4]);
        for &(r, wr) in rows.of(j) {
            src.read_row(r as usize, c_lo as usize, &mut src_row)?;
            for (l, p) in line.iter_mut().zip(&src_row) {
                let a = if OPAQUE { wr } else { f32::from(p[3]) * wr };
                l[0] += f32::from(p[0]) * a;
                l[1] += f32::from(p[1]) * a;
                l[2] += f32::from(p[2]) * a;
                l[3] += a;
            }
        }
        let out_row = &mut out[j * n..(j + 1) * n];
        for (i, o) in out_row.iter_mut().enumerate() {
            if !cols.inside[i] {
                continue;
            }
            let mut acc = [0.0f32; 4];
            for &(c, wc) in cols.of(i) {
                let l = &line[(c - c_lo) as usize];
                for (a, v) in acc.iter_mut().zip(l) {
                    *a += v * wc;
                }
            }
            *o = if OPAQUE {
                [
                    (acc[0] + 0.5) as u8,
                    (acc[1] + 0.5) as u8,
                    (acc[2] + 0.5) as u8,
                    255,
                ]
            } else {
                unpremultiply(acc)
            };
        }
    }
    Ok(())
}

/// Decodes a tile file of `size` x `size` pixels to RGBA.
fn decode_rgba(key: TileKey, bytes: &[u8], size: usize) -> Result<Vec<[u8; 4]>> {
    let img = image::load_from_memory(bytes)
        .map_err(|e| crate::error::TilerError::Encode {
            key,
            problem: format!("existing tile cannot be decoded: {e}"),
        })?
        .into_rgba8();
    if img.width() as usize != size || img.height() as usize != size {
        return Err(crate::error::TilerError::Encode {
            key,
            problem: format!(
                "existing tile is {}x{}, not {size}x{size}",
                img.width(),
                img.height()
            ),
        });
    }
    Ok(img
        .into_raw()
        .chunks_exact(4)
        .map(|p| [p[0], p[1], p[2], p[3]])
        .collect())
}

/// Straight RGBA from premultiplied sums `[r*a, g*a, b*a, a]` (alpha in 0..=255 units).
#[inline]
fn unpremultiply(acc: [f32; 4]) -> [u8; 4] {
    if acc[3] <= 0.0 {
        return [0; 4];
    }
    let inv = 1.0 / acc[3];
    [
        (acc[0] * inv + 0.5).min(255.0) as u8,
        (acc[1] * inv + 0.5).min(255.0) as u8,
        (acc[2] * inv + 0.5).min(255.0) as u8,
        (acc[3] + 0.5).min(255.0) as u8,
    ]
}

/// A parent on a cell grid from its children: each parent cell is the alpha-weighted mean of
/// the 2x2 child cells it covers (an area average). Missing children are transparent.
pub fn downsample_cells(children: &[Option<Vec<[u8; 4]>>; 4], n: usize) -> Vec<[u8; 4]> {
    let half = n / 2;
    let mut out = vec![[0u8; 4]; n * n];
    for (q, child) in children.iter().enumerate() {
        let Some(child) = child else { continue };
        let (ox, oy) = ((q & 1) * half, (q >> 1) * half);
        for j in 0..half {
            for i in 0..half {
                let mut acc = [0u32; 4];
                for (dx, dy) in [(0, 0), (1, 0), (0, 1), (1, 1)] {
                    let p = child[(2 * j + dy) * n + 2 * i + dx];
                    let a = u32::from(p[3]);
                    acc[0] += u32::from(p[0]) * a;
                    acc[1] += u32::from(p[1]) * a;
                    acc[2] += u32::from(p[2]) * a;
                    acc[3] += a;
                }
                out[(oy + j) * n + ox + i] = if acc[3] == 0 {
                    [0; 4]
                } else {
                    let h = acc[3] / 2;
                    [
                        ((acc[0] + h) / acc[3]) as u8,
                        ((acc[1] + h) / acc[3]) as u8,
                        ((acc[2] + h) / acc[3]) as u8,
                        ((acc[3] + 2) / 4) as u8,
                    ]
                };
            }
        }
    }
    out
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn corner_downsampling_keeps_planes_and_coincident_samples() {
        let n = 5;
        // A plane z = 3x + 2y over the 9x9 mosaic; children cut from it.
        let child = |q: usize| -> Option<Vec<f32>> {
            let (ox, oy) = ((q & 1) * (n - 1), (q >> 1) * (n - 1));
            Some(
                (0..n * n)
                    .map(|k| (3 * (ox + k % n) + 2 * (oy + k / n)) as f32)
                    .collect(),
            )
        };
        let parent = downsample_corners(&[child(0), child(1), child(2), child(3)], n);
        for j in 0..n {
            for i in 0..n {
                assert_eq!(parent[j * n + i], (3 * 2 * i + 2 * 2 * j) as f32);
            }
        }
    }

    #[test]
    fn cell_downsampling_is_an_area_average_and_ignores_transparency() {
        let n = 4;
        let mut c0 = vec![[200u8, 100, 0, 255]; n * n];
        c0[0] = [0, 0, 0, 0];
        let parent = downsample_cells(&[Some(c0), None, None, None], n);
        assert_eq!(parent[0], [200, 100, 0, 191]);
        assert_eq!(parent[1], [200, 100, 0, 255]);
        assert_eq!(parent[2], [0, 0, 0, 0], "missing child is transparent");
    }
}
