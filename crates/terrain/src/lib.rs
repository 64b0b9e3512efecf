//! `globus-terrain`: terrain on the CPU, no GPU code.
//!
//! * [`ProceduralPlanet`]: the default data source, an Earth-sized planet with oceans,
//!   continents, mountain ranges and detail down to 0.15 m, deterministic for a seed.
//! * [`TerrainTile`]: one tile's height grid (with a border), colour image and errors.
//! * [`TileMesh`]: the tile's adaptive mesh (an error-bounded cut of its grid) with vertices
//!   relative to its own origin (f32), normals, skirts and exact bounds, ready to upload.
//! * [`grid`]: the sample grid every tile shares.
//! * [`MorphVertex`]: where a mesh's vertices lie on its parent's surface (geomorphing).
//! * [`adaptive`]: meshes with an exact vertical error bound (RTIN, and RTIN followed by
//!   vertex removal after Kaiser's decimation).
//! * [`quantized_mesh`]: Cesium's quantized-mesh-1.0, encoded and decoded (untrusted input).
//! * [`refine`]: procedural refinement below the data (terrain and imagery).
//! * [`encoding`]: elevation as RGB (Terrarium, Mapbox Terrain-RGB, Kaiser's centimetres).

pub mod adaptive;
pub mod biome;
pub mod encoding;
mod generate;
pub mod grid;
mod mesh;
pub mod morph;
pub mod noise;
mod planet;
pub mod quantized_mesh;
pub mod refine;
pub mod slopes;
mod tile;

/// The largest height above or below the ellipsoid any input may claim, metres. Earth spans
/// -11 km to +9 km and Mars -8 km to +22 km; anything beyond 100 km is a void marker, a unit
/// mistake or a crafted file, and is refused where it is read.
pub const MAX_ABS_HEIGHT_M: f64 = 100_000.0;

pub use mesh::{
    MeshOptions, MeshQuadrants, TerrainVertex, TileMesh, decode_oct_normal, encode_oct_normal,
};
pub use morph::MorphVertex;
pub use planet::{Drainage, Fields, ProceduralPlanet, Relief};
pub use tile::{ColourImage, TerrainTile};
