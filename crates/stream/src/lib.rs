//! `globus-stream`: the data side of Globus.
//!
//! Tiles come from a [`TileSource`] (today the procedural planet, and [`RefinedSource`], which
//! continues any terrain source below its data with procedural detail; directories, tile
//! services and archives through [`open`]), slowly and maybe never. A [`Scheduler`] runs loads on a small pool
//! of worker threads in priority order, drops requests nobody wants any more, and hands
//! results back through a bounded channel that the render thread drains without blocking.
//! A [`TerrainLayer`] keeps loaded tiles in a byte-budgeted LRU cache and answers LOD
//! selection's questions as a [`globus_tiling::TileOracle`].

mod cache;
mod colour_jobs;
pub mod decode;
pub mod fetch;
mod layer;
pub mod mosaic;
mod nodes;
pub mod open;
mod procedural;
pub mod pyramid;
mod raster_terrain;
mod refined;
mod scheduler;
mod source;
mod terrain_jobs;

pub use cache::LruCache;
pub use layer::{LayerStats, TerrainLayer, TerrainLayerOptions, TileColour, UsageStats};
pub use procedural::ProceduralSource;
pub use raster_terrain::RasterTerrainSource;
pub use refined::{DEFAULT_BASE_CACHE_BYTES, RefinedSource};
pub use scheduler::{
    Clock, Outcome, RetryPolicy, Scheduler, SchedulerOptions, SchedulerStats, SystemClock,
};
pub use source::{SourceError, TerrainData, TerrainSource, TileSource, child_bounds};
