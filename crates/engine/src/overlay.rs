//! [`Overlay`]: how an application (and the engine's built-in layers) draws over the terrain.
//!
//! A frame is drawn in passes, in this order, into one colour target, one id buffer (cleared
//! by the first overlay pass; the terrain writes no ids) and (but for the last) one depth
//! buffer, which the terrain leaves behind (Kaiser 2018, 5.3):
//!
//! | pass | what | depth |
//! |---|---|---|
//! | terrain | sky and tiles (the engine's own) | cleared, written |
//! | [`OverlayPass::World`] | vector data, volumes, models: camera-relative like the tiles | tested and written as the overlay likes |
//! | [`OverlayPass::ScreenAligned`] | billboards, labels: anchored in the world, facing the screen, a size in pixels | tested against everything before (hidden behind terrain) |
//! | [`OverlayPass::Screen`] | HUD: pixel coordinates | none |
//!
//! Each frame the engine calls [`Overlay::prepare`] on every overlay (on the render thread,
//! with the device, queue and the frame's [`FrameCamera`]), then [`Overlay::place_labels`] on
//! every overlay (once all have claimed their symbols' screen boxes, so labels keep off every
//! layer's symbols and earlier layers' labels), then [`Overlay::draw`] once per
//! pass the overlay draws in ([`Overlay::passes`]), recording into a render pass the engine
//! began. Pipelines declare the frame's targets through [`FrameFormats`]: colour at location
//! 0, the id buffer at location 1 (write non-zero object ids there to be pickable, see
//! [`crate::Globe::pick`]), and the shared depth buffer (reversed-Z: nearer is greater) in
//! the world and screen-aligned passes. Positions reach shaders relative to
//! [`FrameCamera::origin`] ([`FrameCamera::relative`]: subtracted in f64), and with
//! [`FrameCamera::clip_from_eye`] they land exactly where the terrain under them is drawn.

use std::borrow::Cow;

use globus_geo::{Cartographic, DVec3, Ellipsoid};
use globus_render::{FrameCamera, FrameFormats};
use globus_stream::TerrainLayer;
use globus_terrain::{MorphVertex, TileMesh};
use globus_tiling::{DrawTile, GeoRect, TileKey};

/// One of the passes overlays draw in, in drawing order.
#[derive(Clone, Copy, Debug, PartialEq, Eq, Hash)]
pub enum OverlayPass {
    /// World space, depth-tested against the terrain: lines, polygons, volumes, models.
    World,
    /// Anchored in the world and facing the screen (billboards, labels), depth-tested
    /// against the terrain and the world pass so terrain hides them where it should.
    ScreenAligned,
    /// Screen space, no depth buffer: heads-up displays.
    Screen,
}

impl OverlayPass {
    /// Every pass, in drawing order.
    pub const ALL: [OverlayPass; 3] = [Self::World, Self::ScreenAligned, Self::Screen];

    /// Whether the pass has the depth buffer attached (pipelines drawing in it must then
    /// declare [`FrameFormats::depth_test`], and must not in the others).
    pub fn has_depth(self) -> bool {
        !matches!(self, Self::Screen)
    }
}

/// What an overlay gets every frame: the GPU, the frame's camera and targets, and the body
/// with its elevation exaggeration (everything placed at an altitude is raised by it, as the
/// terrain is).
pub struct FrameContext<'a> {
    pub(crate) device: &'a wgpu::Device,
    pub(crate) queue: &'a wgpu::Queue,
    pub(crate) camera: &'a FrameCamera,
    pub(crate) formats: FrameFormats,
    pub(crate) ellipsoid: Ellipsoid,
    pub(crate) exaggeration: f64,
    pub(crate) drawn: &'a [DrawTile],
    pub(crate) layer: &'a TerrainLayer,
    pub(crate) terrain_depth: &'a wgpu::TextureView,
    /// Whether tiles grow out of their parents this frame ([`crate::Globe::set_morph`]).
    pub(crate) morph: bool,
    pub(crate) sun_direction: DVec3,
    /// Screen boxes overlays prepared earlier this frame drew labels and symbols in.
    pub(crate) screen_boxes: std::cell::RefCell<Vec<[f32; 4]>>,
}

impl FrameContext<'_> {
    /// The device (create pipelines and buffers with it).
    pub fn device(&self) -> &wgpu::Device {
        self.device
    }

    /// Screen boxes (min x, min y, max x, max y, pixels) where overlays prepared earlier in
    /// this frame draw labels and symbols. An overlay that places labels keeps them off these
    /// and then claims its own ([`FrameContext::claim_screen_boxes`]), so the labels of
    /// different overlays never overlap one another (the earlier overlay's win).
    pub fn screen_boxes(&self) -> Vec<[f32; 4]> {
        self.screen_boxes.borrow().clone()
    }

    /// Adds boxes where this overlay draws labels or symbols (see
    /// [`FrameContext::screen_boxes`]).
    pub fn claim_screen_boxes(&self, boxes: impl IntoIterator<Item = [f32; 4]>) {
        self.screen_boxes.borrow_mut().extend(boxes);
    }

    /// The queue (write buffers with it; the engine submits).
    pub fn queue(&self) -> &wgpu::Queue {
        self.queue
    }

    /// The frame's camera.
    pub fn camera(&self) -> &FrameCamera {
        self.camera
    }

    /// The formats of the frame's targets.
    pub fn formats(&self) -> FrameFormats {
        self.formats
    }

    /// The body the globe is on.
    pub fn ellipsoid(&self) -> &Ellipsoid {
        &self.ellipsoid
    }

    /// The globe's elevation exaggeration.
    pub fn exaggeration(&self) -> f64 {
        self.exaggeration
    }

    /// The terrain tiles drawn this frame.
    pub fn drawn_tiles(&self) -> &[DrawTile] {
        self.drawn
    }

    /// The mesh a loaded tile is drawn with (every drawn tile is loaded): vertices relative
    /// to its centre, exaggerated, surface triangles first.
    pub fn tile_mesh(&self, key: TileKey) -> Option<&TileMesh> {
        self.layer.get(key).map(|d| &d.mesh)
    }

    /// Where the vertices of a loaded tile's mesh ([`FrameContext::tile_mesh`]) lie on its
    /// parent's surface, one per vertex (empty: it has none to grow out of): what draped
    /// geometry needs to follow the terrain's geomorphing.
    pub fn tile_morph_targets(&self, key: TileKey) -> Cow<'_, [MorphVertex]> {
        crate::frame::upload::morph_targets(self.layer, key)
    }

    /// How far a drawn tile has grown out of its parent this frame: its
    /// [`DrawTile::morph`], or 1 (its own surface) with geomorphing off.
    pub fn morph_of(&self, tile: &DrawTile) -> f64 {
        if self.morph { tile.morph } else { 1.0 }
    }

    /// A loaded tile's rectangle (radians).
    pub fn tile_rect(&self, key: TileKey) -> Option<GeoRect> {
        self.layer.get(key).map(|d| d.tile.rect)
    }

    /// The depth buffer as the terrain pass left it (reversed-Z, `Depth32Float`), to be read
    /// with `textureLoad` in the world and screen-aligned passes by overlays whose
    /// [`Overlay::wants_terrain_depth`] is true (it is copied only then).
    pub fn terrain_depth(&self) -> &wgpu::TextureView {
        self.terrain_depth
    }

    /// Towards the sun the terrain is lit by (unit, ECEF axes): overlays light their models
    /// with it.
    pub fn sun_direction(&self) -> DVec3 {
        self.sun_direction
    }

    /// The ground height (true metres above the ellipsoid) at a longitude and latitude
    /// (radians): the source's own answer if it has one, else the finest loaded tiles', else 0.
    pub fn ground_height_m(&self, lon_rad: f64, lat_rad: f64) -> f64 {
        crate::query::ground_height_m(self.layer, lon_rad, lat_rad)
    }

    /// The ground height (true metres) of the terrain loaded at a longitude and latitude
    /// (radians): what is drawn there, from the cached tiles' grids (a quick lookup), or
    /// [`FrameContext::ground_height_m`] where nothing is loaded. What moving objects stand
    /// on, so they meet the drawn ground.
    pub fn loaded_ground_m(&self, lon_rad: f64, lat_rad: f64) -> f64 {
        crate::query::height_at(self.layer, lon_rad, lat_rad).map_or_else(
            || crate::query::ground_height_m(self.layer, lon_rad, lat_rad),
            |h| h.height_m(),
        )
    }

    /// The ECEF point drawn for a geodetic position: its height above the ellipsoid raised
    /// by the exaggeration, as the terrain's is (see [`crate::Globe::world_position`]).
    pub fn world_position(&self, at: Cartographic) -> DVec3 {
        crate::globe::exaggerated(&self.ellipsoid, self.exaggeration, at)
    }
}

/// Something drawn over the terrain. See the module documentation for the passes and the
/// conventions pipelines follow.
pub trait Overlay {
    /// The passes this overlay draws in.
    fn passes(&self) -> &[OverlayPass];

    /// Called once a frame before any pass is recorded: update buffers for this frame's
    /// camera, create pipelines the first time.
    fn prepare(&mut self, frame: &FrameContext<'_>);

    /// Called once a frame after every overlay's [`Overlay::prepare`]: place labels. By then
    /// every overlay has claimed the screen boxes of its symbols
    /// ([`FrameContext::claim_screen_boxes`]), so labels keep off all of them; each overlay's
    /// labels then keep off those placed before (overlays in the order given).
    fn place_labels(&mut self, frame: &FrameContext<'_>) {
        let _ = frame;
    }

    /// Whether [`FrameContext::terrain_depth`] must hold the terrain's depth this frame
    /// (costs one depth-buffer copy per frame when any overlay wants it).
    fn wants_terrain_depth(&self) -> bool {
        false
    }

    /// Records passes of the overlay's own into `encoder`, after the terrain pass and before
    /// the world pass (e.g. order-independent transparency into targets of its own, with
    /// [`FrameContext::terrain_depth`] attached read-only as their depth). Nothing by default.
    fn record(&mut self, frame: &FrameContext<'_>, encoder: &mut wgpu::CommandEncoder) {
        let _ = (frame, encoder);
    }

    /// Records this overlay's draws for `pass` into `render_pass` (called once per pass in
    /// [`Overlay::passes`], after every overlay was prepared).
    fn draw(
        &self,
        pass: OverlayPass,
        frame: &FrameContext<'_>,
        render_pass: &mut wgpu::RenderPass<'_>,
    );
}
