//! Readers that turn input files into georeferenced rasters.

mod hgt;
mod image;

pub use hgt::{HgtName, read_hgt_mosaic};
pub use image::{read_grey_elevation, read_world_image};
