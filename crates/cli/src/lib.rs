//! The Globus application: the engine that wires data, LOD and rendering, and the
//! subcommands of the `globus` binary.

pub mod config;
pub mod engine;
pub mod geo_cmd;
pub mod memory;
pub mod mesh_cmd;
pub mod offscreen;
pub mod path;
pub mod tile_cmd;
pub mod viewer;

pub use engine::{CameraSpec, FrameReport, Globe, GlobeOptions};
