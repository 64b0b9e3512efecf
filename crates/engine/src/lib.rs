//! `globus-engine`: the Globus engine as a library.
//!
//! A [`Globe`] streams terrain and imagery (or generates the procedural planet), selects per
//! frame the tiles whose screen-space error stays under a pixel bound, keeps them on the GPU
//! and draws them camera-relative with reversed-Z depth; anything an application draws
//! goes through the [`Overlay`] trait into the same colour and depth buffers, in world,
//! screen-aligned and screen passes. It answers [`Globe::pick`] (object id and surface point
//! under a pixel), terrain queries ([`Globe::height_at`], [`Globe::normal_at`],
//! [`Globe::ray_pick`]), and a [`CameraController`] drives the camera from pixel input.
//!
//! Everything on the planet is f64 ECEF; f32 appears only relative to the frame's origin
//! ([`FrameCamera::relative`]).
//!
//! # Embedding
//!
//! ```no_run
//! use std::time::Duration;
//! use globus_engine::{CameraSpec, Globe, Headless, save_png};
//!
//! # fn main() -> Result<(), Box<dyn std::error::Error>> {
//! // The procedural planet, 1280x720, without a window (`GpuContext::with_adapter` and a
//! // window surface work the same way).
//! let mut builder = Globe::builder();
//! builder.max_sse_px(2.0).exaggeration(1.0);
//! let mut headless = Headless::new(&builder, 1280, 720)?;
//! let camera = CameraSpec {
//!     lon_deg: 7.6,
//!     lat_deg: 46.0,
//!     alt_m: 3000.0,
//!     heading_deg: 200.0,
//!     pitch_deg: -10.0,
//!     above_ground: true,
//! };
//! let view = camera.view(headless.globe(), 60.0, 1280, 720);
//! // Load everything the view needs, draw it (with no overlays) and read it back.
//! let frame = headless.render_complete(&view, Duration::from_secs(60), &mut [])?;
//! save_png(&frame.image, "alps.png".as_ref())?;
//! // What is at the centre of the picture: an overlay's object, and the ground behind it.
//! let pick = headless.globe().pick(640.0, 360.0)?;
//! let ground = pick.and_then(|p| p.surface());
//! # let _ = ground;
//! # Ok(()) }
//! ```
//!
//! In a window: build the globe with [`GlobeBuilder::build`] on a [`GpuContext`] made for
//! the window's surface, then each frame call [`Globe::update`] with the controller's view
//! and [`Globe::render`] into the surface texture with your overlays. The crate's
//! `examples/` hold a headless program with a marker overlay and a windowed one with the
//! camera controller and a HUD.
//!
//! # Frame
//!
//! ```text
//!  update(view): select ─> plan ─> residency ─> draw list      (frame module)
//!  render(...):  terrain ─> world overlays ─> screen-aligned ─> screen
//!  pick(x, y):   id buffer + depth buffer of the last render, refined on the loaded terrain
//! ```

mod builder;
mod camera_spec;
pub mod controller;
mod error;
mod frame;
mod globe;
mod gpu_util;
mod headless;
pub mod labels;
pub mod memory;
pub mod overlay;
mod query;
pub mod text;
pub mod traffic;
pub mod vector;

pub use builder::{DEFAULT_REQUEST_LOOKAHEAD_FRAMES, DEFAULT_SEED, GlobeBuilder, MIN_SSE_PX};
pub use camera_spec::CameraSpec;
pub use controller::{CameraController, Ground, ORTHO_EYE_HEIGHT_M};
pub use error::EngineError;
pub use globe::{FrameReport, Globe, MemoryUse, Pick};
pub use globus_vector::{Feature, StyleRules};
pub use headless::{
    FrameChange, Headless, RenderedFrame, Sweep, SweepFrame, frame_change, geometric_steps,
    holes_inside, save_png,
};
pub use overlay::{FrameContext, Overlay, OverlayPass};
pub use query::{TerrainHeight, ray_march};
pub use traffic::{Follow, TrafficLayer, TrafficStats, TrafficStyle};
pub use vector::{FeatureId, VectorLayer, VectorStats};

pub use globus_geo::{Atmosphere, Cartographic, DQuat, DVec2, DVec3, Ellipsoid, Projection, View};
pub use globus_render::{
    DrawStats, FrameCamera, FrameFormats, GpuContext, Lighting, NightLights, NightLightsError,
    PoolStats, RgbaImage,
};
pub use globus_stream::open::SourceSpec;
pub use globus_stream::{LayerStats, SchedulerStats, TerrainLayer, TerrainSource};
pub use globus_tiling::{DrawTile, TileKey};
