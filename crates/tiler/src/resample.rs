//! Separable resampling from a source raster into tile samples.
//!
//! Both tiling schemes and both source CRSs map columns to longitudes and rows to latitudes
//! independently, so a tile's source positions are one list per axis. Each output column
//! (row) gets a list of weighted source columns (rows), its *taps*: two for bilinear
//! interpolation where the tile is finer than the source, and the area-weighted cells under
//! the output sample's footprint where it is coarser (a box filter, so minified imagery is
//! averaged, never aliased).

use globus_tiling::{GeoRect, TileKey, TilingScheme, mercator_y_to_lat};

use crate::raster::Georef;

/// Where a tile's samples lie within the tile.
#[derive(Clone, Copy, Debug, PartialEq, Eq)]
pub enum SampleGrid {
    /// `n` samples from edge to edge inclusive: sample `i` at `i / (n - 1)` of the tile, so
    /// neighbouring tiles share their edge samples exactly (elevation).
    Corners,
    /// `n` cells: sample `i` at the centre of cell `i`, `(i + 0.5) / n` (imagery).
    Cells,
}

impl SampleGrid {
    /// Fraction of the tile at sample `i` of `n`.
    #[inline]
    pub fn fraction(self, i: usize, n: usize) -> f64 {
        match self {
            SampleGrid::Corners => i as f64 / (n - 1) as f64,
            SampleGrid::Cells => (i as f64 + 0.5) / n as f64,
        }
    }
}

/// Longitudes (radians) of a tile's sample columns.
pub fn sample_lons(scheme: TilingScheme, key: TileKey, grid: SampleGrid, n: usize) -> Vec<f64> {
    let rect = scheme.rect(key);
    (0..n)
        .map(|i| {
            let f = grid.fraction(i, n);
            if f >= 1.0 {
                rect.east
            } else {
                rect.west + f * rect.width()
            }
        })
        .collect()
}

/// Latitudes (radians) of a tile's sample rows, north first.
pub fn sample_lats(scheme: TilingScheme, key: TileKey, grid: SampleGrid, n: usize) -> Vec<f64> {
    let rect = scheme.rect(key);
    let ny = scheme.tiles_y(key.level()) as f64;
    (0..n)
        .map(|j| {
            let f = grid.fraction(j, n);
            if f <= 0.0 {
                return rect.north;
            }
            if f >= 1.0 {
                return rect.south;
            }
            match scheme {
                TilingScheme::Geographic | TilingScheme::GeographicReduced => {
                    rect.north - f * rect.height()
                }
                TilingScheme::WebMercator => mercator_y_to_lat((f64::from(key.y()) + f) / ny),
            }
        })
        .collect()
}

/// Weighted source indices for each output sample along one axis.
#[derive(Clone, Debug, Default)]
pub struct Taps {
    /// `(source index, weight)`, grouped per output sample.
    pub taps: Vec<(u32, f32)>,
    /// Output sample `i` uses `taps[start[i]..start[i + 1]]`.
    pub start: Vec<u32>,
    /// Whether output sample `i` lies inside the data's footprint on this axis.
    pub inside: Vec<bool>,
}

impl Taps {
    /// The taps of output sample `i`.
    #[inline]
    pub fn of(&self, i: usize) -> &[(u32, f32)] {
        &self.taps[self.start[i] as usize..self.start[i + 1] as usize]
    }

    /// The first and last source index any output sample uses.
    pub fn span(&self) -> (u32, u32) {
        self.taps
            .iter()
            .fold((u32::MAX, 0), |(lo, hi), &(c, _)| (lo.min(c), hi.max(c)))
    }

    /// Taps for output samples at fractional source positions `pos` (source sample centres at
    /// whole numbers) over `len` source samples. `inside[i]` says whether sample `i` is in the
    /// footprint.
    pub fn new(pos: &[f64], len: usize, inside: Vec<bool>) -> Self {
        let mut out = Taps {
            taps: Vec::with_capacity(pos.len() * 2),
            start: Vec::with_capacity(pos.len() + 1),
            inside,
        };
        let last = (len - 1) as f64;
        for (i, &p) in pos.iter().enumerate() {
            out.start.push(out.taps.len() as u32);
            // Output sample spacing in source samples, from the neighbouring positions.
            let gaps = match (i > 0, i + 1 < pos.len()) {
                (true, true) => (pos[i + 1] - pos[i - 1]) * 0.5,
                (false, true) => pos[i + 1] - p,
                (true, false) => p - pos[i - 1],
                (false, false) => 1.0,
            }
            .abs();
            if gaps <= 1.0 {
                let c = p.clamp(0.0, last);
                let c0 = c.floor();
                let f = c - c0;
                let i0 = c0 as u32;
                if f > 0.0 && (i0 as usize) < len - 1 {
                    out.taps.push((i0, (1.0 - f) as f32));
                    out.taps.push((i0 + 1, f as f32));
                } else {
                    out.taps.push((i0, 1.0));
                }
            } else {
                // Box filter: source cells [k - 0.5, k + 0.5] overlapping [p - g/2, p + g/2].
                let (lo, hi) = (p - 0.5 * gaps, p + 0.5 * gaps);
                let k0 = (lo + 0.5).floor().clamp(0.0, last) as u32;
                let k1 = (hi + 0.5).floor().clamp(0.0, last) as u32;
                let first = out.taps.len();
                let mut total = 0.0;
                for k in k0..=k1 {
                    let kf = f64::from(k);
                    let w = (hi.min(kf + 0.5) - lo.max(kf - 0.5)).max(0.0);
                    if w > 0.0 {
                        out.taps.push((k, w as f32));
                        total += w;
                    }
                }
                if total > 0.0 {
                    for t in &mut out.taps[first..] {
                        t.1 = (f64::from(t.1) / total) as f32;
                    }
                } else {
                    out.taps.push((k0, 1.0));
                }
            }
        }
        out.start.push(out.taps.len() as u32);
        out
    }
}

/// Column and row taps of one tile over a source raster of `width` x `height`.
pub fn tile_taps(
    scheme: TilingScheme,
    key: TileKey,
    grid: SampleGrid,
    n: usize,
    georef: &Georef,
    footprint: &GeoRect,
    (width, height): (usize, usize),
) -> (Taps, Taps) {
    const EPS: f64 = 1e-12;
    let lons = sample_lons(scheme, key, grid, n);
    let lats = sample_lats(scheme, key, grid, n);
    let cols: Vec<f64> = lons.iter().map(|&l| georef.col_of_lon(l)).collect();
    let rows: Vec<f64> = lats.iter().map(|&l| georef.row_of_lat(l)).collect();
    let in_x = lons
        .iter()
        .map(|&l| l >= footprint.west - EPS && l <= footprint.east + EPS)
        .collect();
    let in_y = lats
        .iter()
        .map(|&l| l >= footprint.south - EPS && l <= footprint.north + EPS)
        .collect();
    (
        Taps::new(&cols, width, in_x),
        Taps::new(&rows, height, in_y),
    )
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn upsampling_interpolates_between_two_samples() {
        let t = Taps::new(&[0.0, 0.25, 0.5, 0.75, 3.0], 4, vec![true; 5]);
        assert_eq!(t.of(0), &[(0, 1.0)]);
        assert_eq!(t.of(1), &[(0, 0.75), (1, 0.25)]);
        assert_eq!(t.of(2), &[(0, 0.5), (1, 0.5)]);
        // Past the last sample: clamped to it.
        let t = Taps::new(&[3.0, 3.5, 4.0], 4, vec![true; 3]);
        assert_eq!(t.of(2), &[(3, 1.0)]);
    }

    #[test]
    fn downsampling_averages_the_cells_underneath() {
        // Output samples 4 source cells apart, centred between cells 1 and 2, 5 and 6.
        let t = Taps::new(&[1.5, 5.5], 8, vec![true; 2]);
        let w: Vec<_> = t.of(0).to_vec();
        assert_eq!(w.iter().map(|x| x.0).collect::<Vec<_>>(), vec![0, 1, 2, 3]);
        assert!(w.iter().all(|x| (x.1 - 0.25).abs() < 1e-6));
        let sum: f32 = t.of(1).iter().map(|x| x.1).sum();
        assert!((sum - 1.0).abs() < 1e-6);
    }

    #[test]
    fn corner_grids_share_edges_with_their_neighbours() {
        let s = TilingScheme::WebMercator;
        let a = TileKey::new(5, 10, 12);
        let b = TileKey::new(5, 11, 12);
        let c = TileKey::new(5, 10, 13);
        let n = 17;
        let la = sample_lons(s, a, SampleGrid::Corners, n);
        let lb = sample_lons(s, b, SampleGrid::Corners, n);
        assert_eq!(la[n - 1].to_bits(), lb[0].to_bits());
        let ya = sample_lats(s, a, SampleGrid::Corners, n);
        let yc = sample_lats(s, c, SampleGrid::Corners, n);
        assert_eq!(ya[n - 1].to_bits(), yc[0].to_bits());
        // Mercator rows are evenly spaced in projected y, not in latitude.
        let y = |lat: f64| globus_tiling::lat_to_mercator_y(lat);
        let d1 = y(ya[1]) - y(ya[0]);
        let d2 = y(ya[n - 1]) - y(ya[n - 2]);
        assert!((d1 - d2).abs() < 1e-12);
    }
}
