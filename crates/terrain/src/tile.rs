//! What a terrain tile is on the CPU: a height grid with a border, a colour image with its
//! mip chain, and the numbers LOD selection needs.

use globus_tiling::{GeoRect, TileKey};

use crate::grid::HEIGHT_GRID_SIDE;

/// Part of a texel's ground size that counts as error for LOD selection.
const TEXEL_ERROR_FRACTION: f64 = 2.0 / 3.0;

/// One terrain tile's data, as produced by a data source on a worker thread.
#[derive(Clone, Debug)]
pub struct TerrainTile {
    /// The tile.
    pub key: TileKey,
    /// Its rectangle, radians.
    pub rect: GeoRect,
    /// Heights of the rendered surface in metres (the sea surface where there is water),
    /// [`HEIGHT_GRID_SIDE`]^2 samples row-major from the north-west border sample:
    /// vertex (i, j) of the mesh is `heights_m[(j + 1) * HEIGHT_GRID_SIDE + i + 1]`.
    pub heights_m: Vec<f32>,
    /// Colour image over the rectangle.
    pub colour: ColourImage,
    /// Largest vertical distance, metres, between this tile's mesh and the full-resolution
    /// surface it stands for (measured on a 4x finer grid, plus the ellipsoid's bulge between
    /// vertices, plus a bound of all finer detail the tile leaves out).
    pub geometric_error_m: f64,
    /// Ground size of one colour texel, metres (north-south).
    pub texel_size_m: f64,
    /// Lowest height in the tile, metres.
    pub min_height_m: f64,
    /// Highest height in the tile, metres.
    pub max_height_m: f64,
}

impl TerrainTile {
    /// The height of mesh vertex (`i`, `j`), `i, j` in `-1..=MESH_SEGMENTS + 1`.
    pub fn height_at(&self, i: i32, j: i32) -> f32 {
        let side = HEIGHT_GRID_SIDE as i32;
        self.heights_m[((j + 1) * side + i + 1) as usize]
    }

    /// The error that LOD selection should use: the larger of the geometric error and two
    /// thirds of the colour texel size. A tile is then also refined when its colour would be
    /// magnified past 1.5 times the pixel bound (3 px per texel at the default 2 px), which
    /// keeps ground texture crisp without refining flat, smooth terrain for geometry it does
    /// not need.
    pub fn lod_error_m(&self) -> f64 {
        self.geometric_error_m
            .max(self.texel_size_m * TEXEL_ERROR_FRACTION)
    }

    /// Approximate bytes held, for cache budgets.
    pub fn byte_size(&self) -> usize {
        self.heights_m.len() * 4 + self.colour.byte_size() + std::mem::size_of::<Self>()
    }
}

/// The lowest and highest of a tile's heights, metres.
pub(crate) fn height_range(heights_m: &[f32]) -> (f64, f64) {
    heights_m
        .iter()
        .fold((f64::INFINITY, f64::NEG_INFINITY), |(lo, hi), &h| {
            (lo.min(f64::from(h)), hi.max(f64::from(h)))
        })
}

/// A square RGBA8 image (sRGB colour, alpha = 255 on land and 0 on water) with its full mip
/// chain, level 0 first.
#[derive(Clone, Debug, PartialEq)]
pub struct ColourImage {
    /// Width and height of level 0.
    pub size: u32,
    /// Level `m` holds `(size >> m)^2 * 4` bytes.
    pub mips: Vec<Vec<u8>>,
}

impl ColourImage {
    /// Builds the mip chain of a `size` x `size` RGBA8 image by 2x2 box filtering.
    pub fn with_mips(size: u32, level0: Vec<u8>) -> Self {
        let mut mips = vec![level0];
        let mut s = size;
        while s > 1 {
            let prev = mips.last().map(Vec::as_slice).unwrap_or_default();
            let half = s / 2;
            let mut next = vec![0u8; (half * half * 4) as usize];
            for y in 0..half {
                for x in 0..half {
                    for c in 0..4 {
                        let at =
                            |xx: u32, yy: u32| u32::from(prev[((yy * s + xx) * 4 + c) as usize]);
                        let sum = at(2 * x, 2 * y)
                            + at(2 * x + 1, 2 * y)
                            + at(2 * x, 2 * y + 1)
                            + at(2 * x + 1, 2 * y + 1);
                        next[((y * half + x) * 4 + c) as usize] = ((sum + 2) / 4) as u8;
                    }
                }
            }
            mips.push(next);
            s = half;
        }
        Self { size, mips }
    }

    /// Number of mip levels.
    pub fn mip_count(&self) -> u32 {
        self.mips.len() as u32
    }

    /// Bytes in all levels.
    pub fn byte_size(&self) -> usize {
        self.mips.iter().map(Vec::len).sum()
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn mip_chain_averages_down_to_one_pixel() {
        let mut px = vec![0u8; 4 * 4 * 4];
        for (i, p) in px.chunks_exact_mut(4).enumerate() {
            p.copy_from_slice(&[if i % 2 == 0 { 200 } else { 100 }, 0, 0, 255]);
        }
        let img = ColourImage::with_mips(4, px);
        assert_eq!(img.mip_count(), 3);
        assert_eq!(img.mips[2], vec![150, 0, 0, 255]);
    }
}
