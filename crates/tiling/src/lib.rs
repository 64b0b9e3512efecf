//! `globus-tiling`: the LOD side of Globus.
//!
//! * [`TileKey`]: a quadtree node (level, x, y) packed into a `u64`.
//! * [`TilingScheme`]: geographic (EPSG:4326, two 180 x 180 degree roots) and Web Mercator
//!   (EPSG:3857, one root clipped at +-85.0511 degrees), with XYZ, TMS and quadkey naming;
//!   and the engine's own tiles, [`GLOBE_SCHEME`]: the geographic grid reduced towards the
//!   poles, so polar tiles are about as wide as tall.
//! * [`TileBounds`]: a tile's oriented box, bounding sphere and horizon culling point.
//! * [`select`]: level-of-detail selection as a pure function of a [`globus_geo::View`] and a
//!   [`TileOracle`] that knows each tile's bounds, geometric error and load state.
//!
//! * [`quality`]: the error bound under frame-time feedback towards a target frame rate.
//!
//! * [`files`]: outside files read safely (regular files only, never more than a cap).
//!
//! Angles are radians inside the crate; degrees appear only in naming helpers that say so.

mod bounds;
pub mod files;
mod key;
pub mod pmtiles;
pub mod quality;
mod rect;
mod scheme;
pub mod select;

pub use bounds::TileBounds;
pub use key::{Direction, TileKey};
pub use rect::GeoRect;
pub use scheme::{
    Children, ParseTileNameError, TilingScheme, WEB_MERCATOR_MAX_LAT_DEG, lat_to_mercator_y,
    mercator_y_to_lat,
};
/// The scheme of the engine's terrain tiles (what a terrain source is asked for, what
/// selection walks): the geographic grid reduced towards the poles.
pub const GLOBE_SCHEME: TilingScheme = TilingScheme::GeographicReduced;

pub use select::{
    DrawTile, Quadrants, Selection, SelectionOptions, SelectionStats, TileInfo, TileOracle,
    TileRequest, TileState, keeps_longer, merge_touching, morph_fraction, select, select_into,
};
