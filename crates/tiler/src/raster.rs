//! Georeferenced rasters held in memory, and the mapping from longitude/latitude to their
//! sample grid.
//!
//! A raster's georeference names the CRS coordinate of the *centre* of sample (0, 0) and the
//! spacing between samples. How far the data reaches beyond the outermost centres depends on
//! the registration: pixel-is-area images (a JPEG world image) cover half a pixel more on
//! every side; pixel-is-point grids (SRTM) end at their outermost samples.

use globus_tiling::GeoRect;

/// Earth radius of the spherical Web Mercator projection (EPSG:3857), metres.
pub const MERCATOR_RADIUS_M: f64 = 6_378_137.0;

/// The coordinate reference systems the tiler reads and writes.
#[derive(Clone, Copy, Debug, PartialEq, Eq)]
pub enum Crs {
    /// EPSG:4326 longitude/latitude in degrees (axis order x = longitude).
    Geographic,
    /// EPSG:3857 Web Mercator metres.
    WebMercator,
}

impl Crs {
    /// CRS x coordinate of a longitude in radians.
    pub fn x_of_lon(self, lon_rad: f64) -> f64 {
        match self {
            Crs::Geographic => lon_rad.to_degrees(),
            Crs::WebMercator => lon_rad * MERCATOR_RADIUS_M,
        }
    }

    /// CRS y coordinate of a latitude in radians.
    pub fn y_of_lat(self, lat_rad: f64) -> f64 {
        match self {
            Crs::Geographic => lat_rad.to_degrees(),
            Crs::WebMercator => lat_rad.tan().asinh() * MERCATOR_RADIUS_M,
        }
    }

    /// Longitude in radians of a CRS x coordinate.
    pub fn lon_of_x(self, x: f64) -> f64 {
        match self {
            Crs::Geographic => x.to_radians(),
            Crs::WebMercator => x / MERCATOR_RADIUS_M,
        }
    }

    /// Latitude in radians of a CRS y coordinate.
    pub fn lat_of_y(self, y: f64) -> f64 {
        match self {
            Crs::Geographic => y.to_radians(),
            Crs::WebMercator => (y / MERCATOR_RADIUS_M).sinh().atan(),
        }
    }
}

/// Whether sample values stand for points or for cells.
#[derive(Clone, Copy, Debug, PartialEq, Eq)]
pub enum Registration {
    /// Each value is the value at its sample centre (SRTM, GeoTIFF `PixelIsPoint`).
    Point,
    /// Each value covers its whole cell (images, GeoTIFF `PixelIsArea`).
    Area,
}

/// Where a raster lies: sample (col, row) has its centre at
/// `(x0 + col * dx, y0 - row * dy)` in `crs` coordinates (rows run southwards).
#[derive(Clone, Copy, Debug, PartialEq)]
pub struct Georef {
    /// The CRS of `x0`, `y0`, `dx`, `dy`.
    pub crs: Crs,
    /// x of the centre of the first column.
    pub x0: f64,
    /// y of the centre of the first row.
    pub y0: f64,
    /// Column spacing, positive.
    pub dx: f64,
    /// Row spacing, positive (rows run southwards).
    pub dy: f64,
    /// What a value stands for.
    pub registration: Registration,
}

impl Georef {
    /// The georeference of an image of `width` x `height` cells covering `bounds` exactly
    /// (pixel-is-area, geographic), as for a plain equirectangular world image.
    pub fn area_covering(bounds: GeoRect, width: usize, height: usize) -> Self {
        let [w, s, e, n] = bounds.to_degrees();
        let dx = (e - w) / width as f64;
        let dy = (n - s) / height as f64;
        Self {
            crs: Crs::Geographic,
            x0: w + 0.5 * dx,
            y0: n - 0.5 * dy,
            dx,
            dy,
            registration: Registration::Area,
        }
    }

    /// The region the data covers, in radians, for a raster of `width` x `height` samples,
    /// clipped to the Web Mercator latitude limit where the CRS is Web Mercator.
    pub fn footprint(&self, width: usize, height: usize) -> GeoRect {
        let (half_x, half_y) = match self.registration {
            Registration::Point => (0.0, 0.0),
            Registration::Area => (0.5 * self.dx, 0.5 * self.dy),
        };
        let x_west = self.x0 - half_x;
        let x_east = self.x0 + (width as f64 - 1.0) * self.dx + half_x;
        let y_north = self.y0 + half_y;
        let y_south = self.y0 - (height as f64 - 1.0) * self.dy - half_y;
        GeoRect {
            west: self.crs.lon_of_x(x_west),
            east: self.crs.lon_of_x(x_east),
            north: self.crs.lat_of_y(y_north),
            south: self.crs.lat_of_y(y_south),
        }
    }

    /// Fractional column of a longitude in radians.
    pub fn col_of_lon(&self, lon_rad: f64) -> f64 {
        (self.crs.x_of_lon(lon_rad) - self.x0) / self.dx
    }

    /// Fractional row of a latitude in radians.
    pub fn row_of_lat(&self, lat_rad: f64) -> f64 {
        (self.y0 - self.crs.y_of_lat(lat_rad)) / self.dy
    }

    /// The spacing between columns as a longitude difference in radians (at the equator for
    /// Web Mercator).
    pub fn lon_spacing_rad(&self) -> f64 {
        match self.crs {
            Crs::Geographic => self.dx.to_radians(),
            Crs::WebMercator => self.dx / MERCATOR_RADIUS_M,
        }
    }
}

/// A raster of samples of type `T` in memory, row-major from the north-west corner.
#[derive(Clone, Debug)]
pub struct Raster<T> {
    /// Columns.
    pub width: usize,
    /// Rows.
    pub height: usize,
    /// `width * height` samples.
    pub data: Vec<T>,
    /// Where it lies.
    pub georef: Georef,
}

impl<T: Copy> Raster<T> {
    /// The sample at (col, row).
    #[inline]
    pub fn get(&self, col: usize, row: usize) -> T {
        self.data[row * self.width + col]
    }

    /// The region the data covers, radians.
    pub fn footprint(&self) -> GeoRect {
        self.georef.footprint(self.width, self.height)
    }
}

/// A source of samples read a row segment at a time: a raster in memory, or a mosaic of
/// files loaded on demand ([`crate::input::HgtMosaic`]) so that memory stays bounded.
pub trait RowSource<T>: Send + Sync {
    /// Columns.
    fn width(&self) -> usize;
    /// Rows.
    fn height(&self) -> usize;
    /// Where it lies.
    fn georef(&self) -> &Georef;
    /// Copies samples `c0 .. c0 + out.len()` of `row` into `out`.
    fn read_row(&self, row: usize, c0: usize, out: &mut [T]) -> crate::error::Result<()>;
    /// Voids filled so far (sources that fill as they load).
    fn voids_filled(&self) -> usize {
        0
    }
    /// The region the data covers, radians.
    fn footprint(&self) -> GeoRect {
        self.georef().footprint(self.width(), self.height())
    }
}

impl<T: Copy + Send + Sync> RowSource<T> for Raster<T> {
    fn width(&self) -> usize {
        self.width
    }

    fn height(&self) -> usize {
        self.height
    }

    fn georef(&self) -> &Georef {
        &self.georef
    }

    fn read_row(&self, row: usize, c0: usize, out: &mut [T]) -> crate::error::Result<()> {
        out.copy_from_slice(&self.data[row * self.width + c0..][..out.len()]);
        Ok(())
    }
}

/// An elevation raster: metres, `NaN` where the source had no data.
pub type ElevationRaster = Raster<f32>;

/// An image raster: straight (not premultiplied) RGBA.
pub type ImageRaster = Raster<[u8; 4]>;

/// The intersection of two rectangles, if it has positive area (`closed`: also when they
/// only touch along an edge or at a corner).
pub fn intersect(a: &GeoRect, b: &GeoRect, closed: bool) -> Option<GeoRect> {
    let r = GeoRect {
        west: a.west.max(b.west),
        east: a.east.min(b.east),
        south: a.south.max(b.south),
        north: a.north.min(b.north),
    };
    let ok = if closed {
        r.west <= r.east && r.south <= r.north
    } else {
        r.west < r.east && r.south < r.north
    };
    ok.then_some(r)
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn world_image_cells_map_to_their_centres() {
        let g = Georef::area_covering(GeoRect::WORLD, 360, 180);
        // The cell of (0.5 E, 0.5 N) is column 180, row 89.
        assert!((g.col_of_lon(0.5f64.to_radians()) - 180.0).abs() < 1e-9);
        assert!((g.row_of_lat(0.5f64.to_radians()) - 89.0).abs() < 1e-9);
        let f = g.footprint(360, 180);
        assert!((f.west + std::f64::consts::PI).abs() < 1e-12);
        assert!((f.north - std::f64::consts::FRAC_PI_2).abs() < 1e-12);
    }

    #[test]
    fn mercator_round_trips() {
        for lat in [-85.0f64, -30.0, 0.0, 45.0, 85.0] {
            let y = Crs::WebMercator.y_of_lat(lat.to_radians());
            assert!((Crs::WebMercator.lat_of_y(y).to_degrees() - lat).abs() < 1e-10);
        }
        // 85.0511 N is the top of the square: y = pi R.
        let top = Crs::WebMercator.y_of_lat(globus_tiling::WEB_MERCATOR_MAX_LAT_DEG.to_radians());
        assert!((top - std::f64::consts::PI * MERCATOR_RADIUS_M).abs() < 1e-6);
    }
}
