//! Where tiles go: a directory tree or an MBTiles file. Every container is written under a
//! temporary name or without its completion marker until [`TileSink::finish`], so an
//! interrupted run never leaves output that looks complete.

pub mod dir;
pub mod mbtiles;

pub use dir::{DirSink, TileLayout};
pub use mbtiles::MbTilesSink;

use globus_tiling::{GeoRect, TileKey, TilingScheme};

use crate::error::Result;

/// What is known about a finished pyramid, written into the container's metadata.
#[derive(Clone, Debug)]
pub struct PyramidMetadata {
    /// Human-readable name (the input file stem).
    pub name: String,
    /// Tile file extension / format: `png`, `jpg` or `webp`.
    pub format: String,
    /// `elevation` or `imagery`.
    pub kind: String,
    /// The elevation encoding, for elevation pyramids.
    pub encoding: Option<String>,
    /// The tiling scheme.
    pub scheme: TilingScheme,
    /// Samples per tile side.
    pub tile_size: usize,
    /// `corners` (samples on tile edges, shared with neighbours) or `cells`.
    pub sample_grid: String,
    /// The data's extent.
    pub bounds: GeoRect,
    /// Coarsest level written.
    pub min_level: u8,
    /// Finest level written.
    pub max_level: u8,
}

impl PyramidMetadata {
    /// The metadata as JSON (also the content of a directory's `metadata.json`).
    pub fn to_json(&self) -> serde_json::Value {
        let [w, s, e, n] = self.bounds.to_degrees();
        serde_json::json!({
            "name": self.name,
            "format": self.format,
            "type": self.kind,
            "encoding": self.encoding,
            "scheme": self.scheme.name(),
            "crs": match self.scheme {
                TilingScheme::Geographic => "EPSG:4326",
                TilingScheme::WebMercator => "EPSG:3857",
            },
            "tile_size": self.tile_size,
            "sample_grid": self.sample_grid,
            "bounds": [w, s, e, n],
            "minzoom": self.min_level,
            "maxzoom": self.max_level,
            "generator": concat!("globus ", env!("CARGO_PKG_VERSION")),
        })
    }
}

/// A destination for encoded tiles, shared by the worker threads.
pub trait TileSink: Sync {
    /// Stores one tile.
    fn put(&self, key: TileKey, bytes: &[u8]) -> Result<()>;
    /// The bytes of a tile already stored (by an earlier, interrupted run), for `--resume`.
    fn existing(&self, key: TileKey) -> Result<Option<Vec<u8>>>;
}
