//! # globus-tiler
//!
//! Builds tile pyramids from rasters: SRTM `.hgt` mosaics and greyscale images become
//! RGB-encoded elevation tiles ([`encoding`]), JPEG/PNG world images become imagery tiles,
//! in the geographic or Web Mercator scheme, written to a directory tree or MBTiles.
//!
//! ## Sample registration
//! - **Elevation** tiles are *corner grids*: a 256-sample tile has its first and last
//!   columns exactly on its west and east edges (sample `i` at `i / 255` of the tile), so
//!   neighbouring tiles share their edge samples and hold identical values there.
//! - **Imagery** tiles are *cell grids*: pixel `i` covers `[i, i + 1] / 256` of the tile, as
//!   every slippy-map client expects.
//!
//! ## Levels
//! The finest level is resampled from the source (bilinear where the tile is finer than the
//! source, an area average where it is coarser); every coarser level is made from the level
//! below ([`layer::downsample_corners`], [`layer::downsample_cells`]). Voids in elevation
//! sources are filled by push-pull interpolation ([`fill`]); outside the data's footprint
//! elevation is 0 m and imagery is transparent.

pub use globus_terrain::encoding;
pub mod error;
pub mod fill;
pub mod format;
pub mod input;
pub mod job;
pub mod layer;
pub mod lru;
pub mod pyramid;
pub mod raster;
pub mod resample;
pub mod shard;
pub mod sink;

pub use encoding::ElevationEncoding;
pub use error::{Result, TilerError};
pub use format::ImageFormat;
pub use job::{JobKind, Summary, TileJob, run, run_with_progress};
pub use pyramid::{ProgressFn, ProgressReport};
pub use sink::TileLayout;
