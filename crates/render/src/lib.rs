//! `globus-render`: the render side of Globus, and the only crate (with the app) that knows
//! wgpu.
//!
//! * [`GpuContext`]: instance, adapter, device and queue, with or without a window.
//! * [`TilePool`]: fixed-size GPU pools mirroring the CPU tile cache: shared vertex and index
//!   buffers sub-allocated per tile ([`RangeAllocator`]), so every tile can have its own
//!   (adaptive) mesh, and a colour texture array; least-recently-used eviction and an upload
//!   budget per frame.
//! * [`GlobeRenderer`]: draws the sky and all terrain tiles with two draw calls, whatever the
//!   number of tiles and their meshes: one `multi_draw_indexed_indirect` over the pools,
//!   recorded into a render pass its caller owns (so more can be drawn into the same colour,
//!   id and depth buffers). Positions are f32 offsets from each tile's centre plus a
//!   centre-to-eye offset computed in f64 every frame (camera-relative rendering), and depth
//!   is reversed-Z with an infinite far plane in a 32-bit float buffer.
//! * [`NightLights`]: city lights on the night side, from an equirectangular image.
//! * [`FrameCamera`]: the frame's camera-relative origin (f64), matrices, near plane and
//!   viewport, and the projection of f64 world points to pixels.
//! * [`FrameTargets`]: the depth buffer and the id buffer (Kaiser's item buffer, for picking)
//!   a frame's passes share; [`FrameFormats`] says what pipelines drawing into them declare.
//! * [`OffscreenTarget`]: rendering without a window, read back as RGBA.

mod aerial;
mod air;
mod camera;
mod context;
mod fade;
mod globe;
mod night;
mod pool;
mod ranges;
pub mod shaders;
mod target;

pub use camera::{FrameCamera, NEAR_PLANE_CAP_GL_M, NEAR_PLANE_CAP_M, near_plane_m};
pub use context::{GpuContext, RenderError};
pub use fade::COLOUR_FADE;
pub use globe::{DrawStats, FrameInputs, GlobeRenderer, Lighting, array_layers, fragment_texture};
pub use night::{NightLights, NightLightsError};
pub use pool::{
    ColourSource, MAX_TILE_INDICES, MAX_TILE_VERTICES, PoolStats, Residency, Resident, TilePool,
    TilePoolOptions, VertexExtra,
};
pub use ranges::RangeAllocator;
pub use target::{
    DEPTH_FORMAT, FrameFormats, FrameTargets, ID_FORMAT, OFFSCREEN_FORMAT, OffscreenTarget,
    PixelRead, RgbaImage,
};
