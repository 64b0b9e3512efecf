//! Readers that turn input files into georeferenced rasters.

pub(crate) mod geotiff;
mod hgt;
mod image;

/// Opens an input file if it is a regular file (a FIFO would block, `/dev/zero` never ends).
pub(crate) fn open_regular(path: &std::path::Path) -> crate::error::Result<std::fs::File> {
    globus_tiling::files::open_regular(path).map_err(|e| crate::error::TilerError::io(path, e))
}

pub use geotiff::{GeoTiff, read_geotiff};
pub use hgt::{HgtMosaic, HgtName, read_hgt_mosaic};
pub use image::{read_grey_elevation, read_world_image};
