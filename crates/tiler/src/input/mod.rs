//! Readers that turn input files into georeferenced rasters.

mod geotiff;
mod hgt;
mod image;

pub use geotiff::{GeoTiff, read_geotiff};
pub use hgt::{HgtMosaic, HgtName, read_hgt_mosaic};
pub use image::{read_grey_elevation, read_world_image};
