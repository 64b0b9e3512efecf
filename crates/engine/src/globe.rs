//! [`Globe`]: the facade over the three subsystems, and one frame as named stages.
//!
//! ```text
//!  update(view):
//!   select ──> plan ──────────────> residency ─────────> draw list
//!   (LOD over    (load / upload /     (GPU uploads within   (offsets and indirect
//!    the layer,   defer, tiles in      the frame's budget,   draws for the tiles
//!    resident     use: recency for     late colours first)   selected)
//!    = drawable)  cache and pools)
//!                      │
//!                      └──> TerrainLayer::update (scheduler, cache)
//!  render(encoder, colour, overlays):
//!   terrain pass (sky, tiles) ──> world overlays ──> screen-aligned ──> screen (HUD)
//!        one colour target, one id buffer, one depth buffer kept for all but the last
//! ```
//!
//! Selection sees a tile as loaded only when it is both in the CPU cache and resident in the
//! GPU pools ([`crate::frame`]), so everything it draws can be drawn this very frame: no
//! holes while data streams in, only coarser ancestors.

use std::time::{Duration, Instant};

use globus_geo::{Atmosphere, Cartographic, DVec3, Ellipsoid, View};
use globus_render::{
    DrawStats, FrameCamera, FrameFormats, FrameInputs, FrameTargets, GlobeRenderer, Lighting,
    NEAR_PLANE_CAP_GL_M, NEAR_PLANE_CAP_M, NightLights, PoolStats, TilePool, near_plane_m,
};
use globus_stream::{LayerStats, TerrainLayer, TerrainLayerOptions, TerrainSource};
use globus_tiling::quality::QualityLoop;
use globus_tiling::{DrawTile, Selection, SelectionOptions, SelectionStats, select_into};

use crate::builder::Settings;
use crate::frame::detail::{BudgetUse, next_bound};
use crate::frame::plan::{FramePlan, Motion};
use crate::frame::select::ResidentOracle;
use crate::frame::upload::make_resident;
use crate::memory::{MemoryPlan, resident_bytes};
use crate::overlay::{FrameContext, Overlay, OverlayPass};
use crate::query::{self, TerrainHeight};
use crate::{EngineError, GlobeBuilder};

/// Bytes per pixel of a frame's targets: colour, its read-back copy, depth and the id buffer.
const FRAME_BYTES_PER_PIXEL: u64 = 16;
/// What a software rasteriser (lavapipe) takes at its first draw, on top of the footprint
/// measured before it: compiled shaders and binned geometry. Measured on the README's Alps
/// example: about 125 MiB fixed, and more with the triangles drawn...
const SOFTWARE_RASTER_BYTES: u64 = 128 << 20;
/// ...about 170 bytes a triangle drawn (binned vertices and their setup), measured over the
/// Alps dive. A memory budget gives the triangles this share of the total, and the error
/// bound rises when a frame draws more.
const SOFTWARE_BYTES_PER_TRIANGLE: u64 = 170;
const SOFTWARE_TRIANGLE_SHARE: u64 = 8;

/// What one frame did.
#[derive(Clone, Copy, Debug, Default)]
pub struct FrameReport {
    /// Selection counters.
    pub selection: SelectionStats,
    /// Microseconds spent in selection (wall clock).
    pub select_us: f64,
    /// CPU microseconds the render thread spent in selection (excludes time the thread was
    /// preempted by loaders or the software rasteriser on a busy machine).
    pub select_cpu_us: f64,
    /// CPU microseconds the render thread spent in the whole [`Globe::update`]: selection,
    /// load bookkeeping, uploads (morph targets included where the loader could not find
    /// them) and the draw list. What a frame costs the CPU before the GPU draws it.
    pub update_cpu_us: f64,
    /// Tiles wanted but not drawable yet (loading or uploading).
    pub wanted: u32,
    /// Data-side counters.
    pub layer: LayerStats,
    /// GPU pool counters.
    pub pool: PoolStats,
    /// What will be drawn.
    pub draw: DrawStats,
    /// The screen-space error bound used this frame (raised when budgets bind).
    pub sse_bound_px: f64,
    /// Wanted tiles not requested because the moving camera will have left them behind
    /// ([`Globe::set_request_lookahead_frames`]).
    pub requests_deferred: u32,
    /// Drawn tiles showing an ancestor's colour while their own loads (or waits for upload).
    pub colours_pending: u32,
}

impl FrameReport {
    /// Whether everything the selection wants is drawn, imagery included.
    pub fn is_complete(&self) -> bool {
        self.wanted == 0 && self.colours_pending == 0
    }
}

/// The memory budget and what its parts hold ([`Globe::memory_use`]), bytes.
#[derive(Clone, Copy, Debug)]
pub struct MemoryUse {
    /// The plan, if the globe has a budget.
    pub plan: Option<MemoryPlan>,
    /// Loaded tiles in the cache.
    pub tile_cache: u64,
    /// Budget of the tile cache.
    pub tile_cache_budget: u64,
    /// The sources' own caches (decoded source tiles, refinement bases).
    pub sources: u64,
    /// The GPU pools (allocated in full at start).
    pub gpu_pool: u64,
    /// Resident memory of the whole process (Linux).
    pub resident: Option<u64>,
}

/// What is under a pixel ([`Globe::pick`]).
#[derive(Clone, Copy, Debug, PartialEq)]
pub struct Pick {
    surface: Option<DVec3>,
    object: Option<u32>,
}

impl Pick {
    /// The terrain point under the pixel, ECEF metres on the drawn (exaggerated) surface:
    /// from the depth buffer, refined against the loaded terrain. `None` over the sky.
    pub fn surface(&self) -> Option<DVec3> {
        self.surface
    }

    /// The id an overlay wrote at the pixel, if any.
    pub fn object(&self) -> Option<u32> {
        self.object
    }
}

/// A planet: its data layer, its renderer, the frame's camera and the overlay passes. See
/// the crate documentation for how to embed one.
pub struct Globe {
    device: wgpu::Device,
    queue: wgpu::Queue,
    layer: TerrainLayer,
    renderer: GlobeRenderer,
    formats: FrameFormats,
    targets: Option<FrameTargets>,
    selection_options: SelectionOptions,
    /// Whether haze lowers the detail needed ([`Globe::set_fog`]).
    fog: bool,
    settings: Settings,
    selection: Selection,
    plan: FramePlan,
    lighting: Option<Lighting>,
    relax_detail: bool,
    /// How many frames of [`UPLOAD_PACE_FPS`] the last reported frame lasted (1 to
    /// [`MOST_UPLOAD_FRAMES`]): its uploads may be as many as theirs.
    upload_frames: f64,
    /// The error bound under frame-time feedback, with a target frame rate.
    quality: Option<QualityLoop>,
    request_lookahead_frames: f64,
    last_eye: Option<DVec3>,
    memory: Option<MemoryPlan>,
    /// On a software rasteriser under a memory budget, the most triangles a frame may draw
    /// ([`SOFTWARE_BYTES_PER_TRIANGLE`] each), and how many the last frame drew.
    max_triangles: Option<u64>,
    last_triangles: u64,
    /// The camera of the last update.
    camera: Option<FrameCamera>,
    /// The camera of the last render (what the targets hold).
    drawn_camera: Option<FrameCamera>,
    /// Largest near plane (depends on the backend's depth range).
    near_cap_m: f64,
    /// Whether the last render's overlay passes wrote the id buffer.
    ids_written: bool,
    /// Towards the sun in the last update (ECEF axes).
    sun_direction: DVec3,
}

impl Globe {
    /// A builder with the defaults (the procedural planet).
    pub fn builder() -> GlobeBuilder {
        GlobeBuilder::new()
    }

    pub(crate) fn new(
        builder: &GlobeBuilder,
        (device, queue, backend, software): (&wgpu::Device, &wgpu::Queue, wgpu::Backend, bool),
        colour_format: wgpu::TextureFormat,
        source: std::sync::Arc<dyn TerrainSource>,
    ) -> Result<Self, EngineError> {
        let settings = builder.settings();
        // The frame's targets first: a memory budget counts them in the process's footprint.
        let targets = settings
            .viewport
            .map(|(w, h)| FrameTargets::new(device, w, h));
        let workers = settings.layer_workers;
        // The frame's own pixels, counted in full: a driver maps target pages only as they
        // are first drawn, so the footprint measured now misses most of them (an 8192 x 8192
        // frame took 2.6 GB under a 1 GiB budget).
        let frame_bytes = settings.viewport.map_or(0, |(w, h)| {
            u64::from(w) * u64::from(h) * FRAME_BYTES_PER_PIXEL
        });
        let memory = match settings.memory_bytes {
            Some(total) => Some(MemoryPlan::new(
                total,
                resident_bytes().map(|r| {
                    r + frame_bytes
                        + settings.reserved_bytes
                        + builder.night_lights_ref().map_or(0, NightLights::gpu_bytes)
                        + if software {
                            SOFTWARE_RASTER_BYTES + total / SOFTWARE_TRIANGLE_SHARE
                        } else {
                            0
                        }
                }),
                // The terrain layer's loaders and as many for colour.
                2 * workers,
                settings.source_caches,
                |slots| settings.pool_options(slots).gpu_bytes(),
            )?),
            None => None,
        };
        let layer = TerrainLayer::new(
            source,
            TerrainLayerOptions {
                cache_bytes: memory.map_or(settings.cache_bytes, |m| m.tile_cache as usize),
                workers,
            },
        );
        let slots = memory.map_or(settings.gpu_slots, |m| m.gpu_slots);
        let pool = TilePool::new(device, settings.pool_options(slots));
        let selection_options = SelectionOptions {
            max_sse_px: settings.max_sse_px,
            occluder: *layer.occluder(),
            near_m: 0.01,
            max_level: layer.max_level(),
            fog: None, // update_fog
        };
        let formats = FrameFormats::new(colour_format);
        let atmosphere = builder.atmosphere_over(layer.ellipsoid());
        tracing::debug!(
            source = layer.source().name(),
            slots,
            cache_bytes = layer.cache_bytes().1,
            "globe built"
        );
        let mut globe = Self {
            device: device.clone(),
            queue: queue.clone(),
            layer,
            renderer: {
                let mut renderer = GlobeRenderer::new(device, queue, formats, pool);
                renderer.set_atmosphere(device, queue, atmosphere);
                renderer.set_night_lights(device, queue, builder.night_lights_ref());
                renderer.set_procedural_lights(!builder.uses_real_data());
                renderer.set_morph(builder.morph_on());
                renderer.set_marched_haze(builder.marched_haze_on());
                renderer
            },
            formats,
            targets,
            selection_options,
            fog: builder.fog_on(),
            settings,
            selection: Selection::default(),
            plan: FramePlan::default(),
            lighting: None,
            max_triangles: settings
                .memory_bytes
                .filter(|_| software)
                .map(|total| total / SOFTWARE_TRIANGLE_SHARE / SOFTWARE_BYTES_PER_TRIANGLE),
            last_triangles: 0,
            relax_detail: true,
            upload_frames: 1.0,
            quality: settings.quality.map(QualityLoop::new),
            request_lookahead_frames: settings.request_lookahead_frames,
            last_eye: None,
            memory,
            camera: None,
            drawn_camera: None,
            ids_written: false,
            sun_direction: DVec3::Z,
            near_cap_m: if backend == wgpu::Backend::Gl {
                NEAR_PLANE_CAP_GL_M
            } else {
                NEAR_PLANE_CAP_M
            },
        };
        globe.update_fog();
        Ok(globe)
    }

    /// The body the globe is on.
    pub fn ellipsoid(&self) -> Ellipsoid {
        *self.layer.ellipsoid()
    }

    /// The elevation exaggeration terrain (and anything placed through
    /// [`Globe::world_position`]) is drawn with.
    pub fn exaggeration(&self) -> f64 {
        self.settings.exaggeration
    }

    /// The ECEF point drawn for a geodetic position: its height above the ellipsoid times the
    /// exaggeration, as the terrain is drawn. Overlays place everything through this (or
    /// [`FrameContext::world_position`]), so a flight level stays at its height above the
    /// drawn ground.
    pub fn world_position(&self, at: Cartographic) -> DVec3 {
        exaggerated(self.layer.ellipsoid(), self.settings.exaggeration, at)
    }

    /// The geodetic position of a drawn ECEF point, its height in true metres (the inverse
    /// of [`Globe::world_position`]). `None` at the centre of the body.
    pub fn cartographic(&self, world: DVec3) -> Option<Cartographic> {
        let mut c = self.layer.ellipsoid().ecef_to_cartographic(world)?;
        let e = self.settings.exaggeration;
        if e > 0.0 {
            c.height_m /= e;
        }
        Some(c)
    }

    /// The formats of the frame's targets (for overlays' pipelines).
    pub fn formats(&self) -> FrameFormats {
        self.formats
    }

    /// The camera of the last [`Globe::update`]: origin, matrices, near plane, viewport and
    /// projection of world points to pixels.
    pub fn camera(&self) -> Option<&FrameCamera> {
        self.camera.as_ref()
    }

    /// The tiles the last [`Globe::update`] drew, with their screen-space errors.
    pub fn drawn_tiles(&self) -> &[DrawTile] {
        &self.selection.draw
    }

    /// Each data layer's tiles that failed for good so far (counts by kind, the first few
    /// URLs): what an application should tell its user, since the globe draws on over them
    /// with coarser data.
    pub fn layer_failures(&self) -> Vec<globus_stream::pyramid::LayerFailures> {
        self.layer().source().layer_failures()
    }

    /// The data layer (scheduler, cache and counters).
    pub fn layer(&self) -> &TerrainLayer {
        &self.layer
    }

    /// The data layer, to wait for tiles or track usage.
    pub fn layer_mut(&mut self) -> &mut TerrainLayer {
        &mut self.layer
    }

    /// Counters of the GPU pools.
    pub fn pool_stats(&self) -> PoolStats {
        self.renderer.pool().stats()
    }

    /// Sets the sun and exposure (`None`: a default sun for each view,
    /// [`Globe::default_lighting`]).
    pub fn set_lighting(&mut self, lighting: Option<Lighting>) {
        self.lighting = lighting;
    }

    /// Sets the air drawn over the body from the next frame (by default
    /// [`Atmosphere::for_body`]: the Earth's over an Earth-sized body, none over others);
    /// [`Atmosphere::none`] for none.
    pub fn set_atmosphere(&mut self, atmosphere: Atmosphere) {
        self.renderer
            .set_atmosphere(&self.device, &self.queue, atmosphere);
        self.update_fog();
    }

    /// Whether the haze lowers the detail loaded where it hides it (on by default with air;
    /// CesiumJS's `scene.fog`): a tile's screen-space error counts times the contrast the
    /// air lets through from it to the eye ([`globus_tiling::SelectionOptions::fog`]).
    pub fn set_fog(&mut self, on: bool) {
        self.fog = on;
        self.update_fog();
    }

    /// Whether tiles grow out of their parents (on by default): a tile that replaces its
    /// parent starts from the parent's surface, normals and colour and blends into its own
    /// as its level of detail's range runs out (geomorphing, by the fraction selection gives
    /// each drawn tile, [`globus_tiling::DrawTile::morph`]), so splits and merges never move
    /// a pixel in one frame. Off, each tile shows its own at once.
    pub fn set_morph(&mut self, on: bool) {
        self.renderer.set_morph(on);
    }

    /// Whether every ground pixel marches the air between it and the eye (8 steps) instead of
    /// reading the frame's aerial-perspective table (off by default): the table (Hillaire's
    /// froxels, `globus_render`'s `aerial.rs`) is built once a frame from 1,024 rays and costs
    /// each pixel a few lookups; the march is the reference it is tested against.
    pub fn set_marched_haze(&mut self, on: bool) {
        self.renderer.set_marched_haze(on);
    }

    /// How long a tile's own imagery takes to replace the ancestor's it showed while it
    /// loaded (200 ms by default, [`globus_render::COLOUR_FADE`]; zero: at once). Frames that
    /// must settle ([`Globe::load_completely`]) show their own imagery at once whatever this
    /// says.
    pub fn set_colour_fade(&mut self, duration: Duration) {
        self.renderer.set_colour_fade(duration);
    }

    fn update_fog(&mut self) {
        let air = *self.renderer.atmosphere();
        self.selection_options.fog = (self.fog && !air.is_none()).then_some(air);
    }

    /// The air drawn over the body.
    pub fn atmosphere(&self) -> Atmosphere {
        *self.renderer.atmosphere()
    }

    /// Sets the screen-space error bound, pixels (what [`GlobeBuilder::max_sse_px`] set),
    /// from the next frame; budgets and the quality loop work from it as before.
    pub fn set_error_bound_px(&mut self, px: f64) -> Result<(), EngineError> {
        if !(crate::builder::MIN_SSE_PX..=1000.0).contains(&px) {
            return Err(EngineError::InvalidOption {
                option: "error bound",
                value: px.to_string(),
                expected: "a pixel error from 0.1 to 1000",
            });
        }
        self.settings.max_sse_px = px;
        self.selection_options.max_sse_px = px;
        Ok(())
    }

    /// Whether the procedural planet's towns light its night side (on by default for the
    /// procedural planet, off with real data; night lights from an image replace them).
    pub fn set_procedural_lights(&mut self, on: bool) {
        self.renderer.set_procedural_lights(on);
    }

    /// Whether the error bound may come back down after budgets forced it up (on by
    /// default; off for frames that must settle, as [`Globe::load_completely`] does).
    pub fn set_relax_detail(&mut self, relax: bool) {
        self.relax_detail = relax;
    }

    /// See [`GlobeBuilder::request_lookahead_frames`]; may be changed between frames.
    pub fn set_request_lookahead_frames(&mut self, frames: f64) {
        self.request_lookahead_frames = frames;
    }

    /// Tiles uploaded to the GPU per frame at most.
    pub fn set_uploads_per_frame(&mut self, n: u32) {
        self.renderer.pool_mut().set_uploads_per_frame(n);
    }

    /// The memory budget's plan (if the globe has one) and what each part holds now.
    pub fn memory_use(&self) -> MemoryUse {
        let (cache, budget) = self.layer.cache_bytes();
        MemoryUse {
            plan: self.memory,
            tile_cache: cache as u64,
            tile_cache_budget: budget as u64,
            sources: self.layer.source().cached_bytes() as u64,
            gpu_pool: self.renderer.pool().stats().gpu_bytes,
            resident: resident_bytes(),
        }
    }

    /// The height at a longitude and latitude (radians) from the finest loaded tiles around
    /// it (bilinear, the same on both sides of a tile edge), in true metres, with the level
    /// it came from. `None` where nothing is loaded yet.
    pub fn height_at(&self, lon_rad: f64, lat_rad: f64) -> Option<TerrainHeight> {
        query::height_at(&self.layer, lon_rad, lat_rad)
    }

    /// The unit normal of the drawn surface at a longitude and latitude (radians), from the
    /// loaded tiles. `None` where nothing is loaded.
    pub fn normal_at(&self, lon_rad: f64, lat_rad: f64) -> Option<DVec3> {
        query::normal_at(
            &self.layer,
            self.layer.ellipsoid(),
            self.settings.exaggeration,
            lon_rad,
            lat_rad,
        )
    }

    /// The best known ground height at a longitude and latitude (radians), true metres: the
    /// source's own full-resolution answer if it has one (the procedural planet), else the
    /// loaded tiles' ([`Globe::height_at`]), else 0.
    pub fn ground_height_m(&self, lon_rad: f64, lat_rad: f64) -> f64 {
        query::ground_height_m(&self.layer, lon_rad, lat_rad)
    }

    /// The ground height as drawn (times the exaggeration), metres above the ellipsoid.
    pub fn drawn_ground_m(&self, lon_rad: f64, lat_rad: f64) -> f64 {
        self.ground_height_m(lon_rad, lat_rad) * self.settings.exaggeration
    }

    /// The first point where a ray (ECEF origin and direction) meets the drawn surface of
    /// the loaded terrain. `None` if it misses (or nothing is loaded where it would hit).
    pub fn ray_pick(&self, origin: DVec3, direction: DVec3) -> Option<DVec3> {
        let (lo, hi) = self.layer.source().height_range_m();
        query::ray_march(
            self.layer.ellipsoid(),
            |lon, lat| self.drawn_height_loaded(lon, lat),
            (lo.min(0.0), hi),
            origin,
            direction,
        )
    }

    /// The drawn height of the loaded terrain (`None` where nothing is loaded).
    fn drawn_height_loaded(&self, lon_rad: f64, lat_rad: f64) -> Option<f64> {
        self.height_at(lon_rad, lat_rad)
            .map(|h| h.height_m() * self.settings.exaggeration)
    }

    /// The default sun for a camera: over a point 35 degrees west of it and at half its
    /// latitude less 10 degrees, so that anywhere on Earth the view is lit from the
    /// south-west (north-west in the south) about 40 degrees above the horizon, and relief
    /// casts visible shading.
    pub fn default_lighting(view: &View, ellipsoid: &Ellipsoid) -> Lighting {
        let c = ellipsoid
            .ecef_to_cartographic(view.position)
            .unwrap_or_default();
        let lat = c.lat_rad * 0.5 - 10f64.to_radians() * c.lat_rad.signum();
        Lighting::sun_over(c.lon_rad - 35f64.to_radians(), lat)
    }

    /// Runs one frame's CPU work and uploads for `view`: selection, the plan, data requests,
    /// GPU residency and the draw list. Then [`Globe::render`] draws it.
    pub fn update(&mut self, view: &View) -> FrameReport {
        let update_started_cpu = cpu_time::ThreadTime::try_now().ok();
        let ellipsoid = self.ellipsoid();
        let eye = ellipsoid
            .ecef_to_cartographic(view.position)
            .unwrap_or_default();
        let ground = self.drawn_ground_m(eye.lon_rad, eye.lat_rad);
        let near_m = near_plane_m((eye.height_m - ground).max(0.0), self.near_cap_m);
        self.selection_options.near_m = near_m;
        let camera = match view.ortho_height_m() {
            None => FrameCamera::new(view, near_m),
            Some(_) => match ortho_far_m(view, &self.selection_options.occluder) {
                Some(far_m) => FrameCamera::with_far_m(view, near_m, far_m),
                None => FrameCamera::new(view, near_m),
            },
        };
        self.camera = Some(camera);
        self.renderer.pool_mut().begin_frame_of(self.upload_frames);

        // Select.
        let started = Instant::now();
        let started_cpu = cpu_time::ThreadTime::try_now().ok();
        let oracle = ResidentOracle {
            layer: &self.layer,
            residency: self.renderer.pool().residency(),
        };
        select_into(view, &oracle, &self.selection_options, &mut self.selection);
        let select_us = started.elapsed().as_secs_f64() * 1e6;
        let select_cpu_us = started_cpu.map_or(f64::NAN, |t| t.elapsed().as_secs_f64() * 1e6);

        // Plan: what to load, upload and defer.
        let last_eye = self.last_eye.replace(view.position);
        self.plan.make(
            &self.selection,
            &self.layer,
            self.renderer.pool().residency(),
            Motion {
                view,
                last_eye,
                lookahead_frames: self.request_lookahead_frames,
                near_m,
                above_ground_m: (eye.height_m - ground).max(0.0),
            },
        );
        let layer_stats =
            self.layer
                .update(&self.selection.draw, &self.plan.in_use, &self.plan.to_load);

        // GPU residency.
        let residency = make_resident(
            self.renderer.pool_mut(),
            &self.queue,
            &self.layer,
            &self.plan,
            &self.selection.draw,
        );
        self.adapt_detail(residency.pool_full, &layer_stats);

        // Draw list.
        let lighting = self
            .lighting
            .unwrap_or_else(|| Self::default_lighting(view, &ellipsoid));
        self.sun_direction = lighting.sun_direction;
        let draw = self.renderer.prepare(
            &self.device,
            &self.queue,
            &FrameInputs {
                camera: &camera,
                ellipsoid,
                lighting,
                tiles: &self.selection.draw,
            },
        );
        self.last_triangles = draw.triangles;
        FrameReport {
            selection: self.selection.stats,
            select_us,
            select_cpu_us,
            update_cpu_us: update_started_cpu.map_or(f64::NAN, |t| t.elapsed().as_secs_f64() * 1e6),
            wanted: self.selection.requests.len() as u32,
            layer: layer_stats,
            pool: self.renderer.pool().stats(),
            draw,
            sse_bound_px: self.selection_options.max_sse_px,
            requests_deferred: self.plan.deferred,
            colours_pending: residency.colours_pending,
        }
    }

    /// When the GPU pool, the CPU cache or the software rasteriser's triangle share cannot
    /// hold what the view needs, raise the error bound (less detail) instead of thrashing
    /// or growing; lower it again when all have room (unless relaxing is off, as for
    /// offline frames, which must settle), down to the quality loop's bound, which follows
    /// the frame times. Live frames move it a few percent a frame, so morphing carries the
    /// merges and splits ([`crate::frame::detail`]).
    fn adapt_detail(&mut self, pool_full: bool, layer: &LayerStats) {
        let floor = match (&self.quality, self.relax_detail) {
            (Some(q), true) => q.sse_px(),
            _ => self.settings.max_sse_px,
        };
        let budgets = BudgetUse {
            // Drawn tiles plus the ancestors selection walks through: about 4/3 of the drawn.
            slots_needed: self.selection.draw.len() as f64 * 4.0 / 3.0,
            slots: f64::from(self.renderer.pool().capacity()),
            pool_full,
            cache_in_use: layer.in_use_bytes as f64,
            cache_budget: layer.budget_bytes as f64,
            cache_over: layer.over_budget,
            triangles: self.last_triangles as f64,
            triangle_cap: self.max_triangles.map(|m| m as f64),
        };
        let sse = &mut self.selection_options.max_sse_px;
        *sse = next_bound(*sse, floor, &budgets, self.relax_detail);
    }

    /// Reports how long the last frame took, seconds (from one frame's start to the next's,
    /// as a viewer measures it). With a target frame rate ([`GlobeBuilder::target_fps`]) the
    /// error bound of the next frames follows: coarser while frames are slower than the
    /// target, finer again with headroom. And a frame slower than 60 fps may upload as many
    /// tiles as the 60 fps frames in its time would have ([`GlobeBuilder::uploads_per_frame`]
    /// each, up to 16 times as many): on a software rasteriser, where a frame takes a second,
    /// 24 uploads a frame left most tiles that arrived during a dive waiting until the view
    /// had left them.
    pub fn frame_time(&mut self, seconds: f64) {
        if let Some(q) = self.quality.as_mut() {
            q.record(seconds);
        }
        self.upload_frames = if seconds.is_finite() {
            (seconds * UPLOAD_PACE_FPS).clamp(1.0, MOST_UPLOAD_FRAMES)
        } else {
            1.0
        };
    }

    /// The frame-time loop, with a target frame rate: its bound and smoothed frame time.
    pub fn quality(&self) -> Option<&QualityLoop> {
        self.quality.as_ref()
    }

    /// Records the frame prepared by [`Globe::update`] into `encoder`, drawing into `colour`
    /// (of the format the globe was built for, the size of the view): the terrain, then each
    /// pass of `overlays` in order ([`crate::overlay`]). The depth and id buffers are the
    /// globe's, kept for [`Globe::pick`].
    pub fn render(
        &mut self,
        encoder: &mut wgpu::CommandEncoder,
        colour: &wgpu::TextureView,
        overlays: &mut [&mut dyn Overlay],
    ) {
        let Some(camera) = self.camera else {
            return;
        };
        let (w, h) = camera.viewport_px();
        if self.targets.as_ref().is_none_or(|t| t.size() != (w, h)) {
            self.targets = Some(FrameTargets::new(&self.device, w, h));
        }
        let Some(targets) = self.targets.as_ref() else {
            return;
        };
        let frame = FrameContext {
            device: &self.device,
            queue: &self.queue,
            camera: &camera,
            formats: self.formats,
            ellipsoid: *self.layer.ellipsoid(),
            exaggeration: self.settings.exaggeration,
            drawn: &self.selection.draw,
            layer: &self.layer,
            terrain_depth: targets.terrain_depth_view(),
            morph: self.renderer.morph(),
            sun_direction: self.sun_direction,
            screen_boxes: Default::default(),
        };
        for o in overlays.iter_mut() {
            o.prepare(&frame);
        }
        for o in overlays.iter_mut() {
            o.place_labels(&frame);
        }
        {
            let mut pass = begin_pass(encoder, "terrain", colour, targets, Attach::Terrain);
            self.renderer.draw(&mut pass);
        }
        if overlays.iter().any(|o| o.wants_terrain_depth()) {
            targets.copy_terrain_depth(encoder);
        }
        for o in overlays.iter_mut() {
            o.record(&frame, encoder);
        }
        // The id buffer is cleared by the first overlay pass: a frame without overlays never
        // touches it (and picks find no object).
        let draws_in = |p: OverlayPass| overlays.iter().any(|o| o.passes().contains(&p));
        let mut ids = IdBuffer::Clear;
        if draws_in(OverlayPass::World) || draws_in(OverlayPass::ScreenAligned) {
            let mut pass = begin_pass(
                encoder,
                "world overlays",
                colour,
                targets,
                Attach::World(ids),
            );
            for p in [OverlayPass::World, OverlayPass::ScreenAligned] {
                for o in overlays.iter().filter(|o| o.passes().contains(&p)) {
                    o.draw(p, &frame, &mut pass);
                }
            }
            ids = IdBuffer::Load;
        }
        if draws_in(OverlayPass::Screen) {
            let mut pass = begin_pass(
                encoder,
                "screen overlays",
                colour,
                targets,
                Attach::Screen(ids),
            );
            for o in overlays
                .iter()
                .filter(|o| o.passes().contains(&OverlayPass::Screen))
            {
                o.draw(OverlayPass::Screen, &frame, &mut pass);
            }
            ids = IdBuffer::Load;
        }
        self.ids_written = ids == IdBuffer::Load;
        self.drawn_camera = Some(camera);
    }

    /// What is under pixel (`x_px`, `y_px`) of the last rendered frame (`x` right, `y` down
    /// from the top-left corner): the id an overlay wrote there, and the terrain point (from
    /// the depth buffer where terrain is in front, refined against the loaded terrain; a ray
    /// pick against the loaded terrain where an overlay covers it). Waits for the GPU. `None`
    /// before any frame was rendered or outside the frame.
    pub fn pick(&self, x_px: f64, y_px: f64) -> Result<Option<Pick>, EngineError> {
        let (Some(camera), Some(targets)) = (self.drawn_camera, self.targets.as_ref()) else {
            return Ok(None);
        };
        if !(x_px >= 0.0 && y_px >= 0.0) {
            return Ok(None);
        }
        let Some(read) = targets.read_pixel(&self.device, &self.queue, x_px as u32, y_px as u32)?
        else {
            return Ok(None);
        };
        let object = (self.ids_written && read.id != 0).then_some(read.id);
        let (origin, dir) = camera.ray(x_px, y_px);
        let from_depth = camera.unproject(x_px, y_px, f64::from(read.depth));
        let surface = match (object, from_depth) {
            // Terrain in front: its depth, refined against the loaded heights.
            (None, Some(p)) => {
                let t0 = (p - origin).length();
                let margin = (t0 * 0.02).max(5.0);
                let refined = query::refine_hit(
                    self.layer.ellipsoid(),
                    |lon, lat| self.drawn_height_loaded(lon, lat),
                    origin,
                    dir,
                    t0,
                    margin,
                );
                Some(refined.unwrap_or(p))
            }
            (None, None) => None,
            // An overlay in front: the terrain behind it.
            (Some(_), _) => self.ray_pick(origin, dir),
        };
        Ok(Some(Pick { surface, object }))
    }

    /// Frames until everything the selection wants is loaded and resident, imagery included
    /// (or `timeout`). Returns the last frame's report and whether it completed. While it
    /// settles, uploads are unlimited and the bound only rises; both are as before when it
    /// returns, so live frames after it upload and relax as configured.
    pub fn load_completely(&mut self, view: &View, timeout: Duration) -> (FrameReport, bool) {
        self.load_completely_reporting(view, timeout, &mut |_| {})
    }

    /// [`Globe::load_completely`], handing every frame's report to `on_frame` (to show
    /// progress: tiles drawn, still wanted, imagery loading).
    pub fn load_completely_reporting(
        &mut self,
        view: &View,
        timeout: Duration,
        on_frame: &mut dyn FnMut(&FrameReport),
    ) -> (FrameReport, bool) {
        let deadline = Instant::now() + timeout;
        // Settling changes how uploads and the bound move; live frames after it go on as
        // they were configured (a viewer that shows its start view complete, then flies).
        let live = (self.renderer.pool().uploads_per_frame(), self.relax_detail);
        self.set_uploads_per_frame(u32::MAX);
        // Start from the configured bound and only raise it if budgets force it, so the same
        // view always settles on the same tiles.
        self.selection_options.max_sse_px = self.settings.max_sse_px;
        self.relax_detail = false;
        // A settled frame shows every tile's own imagery, not a fade towards it.
        let fade = self.renderer.colour_fade();
        self.renderer.set_colour_fade(Duration::ZERO);
        let mut stalled = 0;
        // A pool whose vertex room holds fewer of the wanted tiles than a split needs evicts
        // one wanted tile for another, frame after frame, without ever being full: when
        // tiles are evicted for CHURN_FRAMES frames and the wanted count reaches no new
        // low, detail drops as if the pool were full.
        const CHURN_FRAMES: u32 = 8;
        let (mut churn, mut least_wanted) = (0, u32::MAX);
        let mut evicted_before = self.renderer.pool().stats().evicted_total;
        let settled = loop {
            let sse_before = self.selection_options.max_sse_px;
            let report = self.update(view);
            let evicted = report.pool.evicted_total.saturating_sub(evicted_before);
            evicted_before = report.pool.evicted_total;
            if report.wanted < least_wanted || report.sse_bound_px != sse_before {
                least_wanted = report.wanted;
                churn = 0;
            } else if evicted > 0 {
                churn += 1;
                if churn > CHURN_FRAMES {
                    tracing::debug!(
                        wanted = report.wanted,
                        "tiles evicted for tiles frame after frame: less detail"
                    );
                    self.selection_options.max_sse_px *= 1.25;
                    (churn, least_wanted) = (0, u32::MAX);
                }
            }
            // Nothing is drawn while settling, so nothing else would submit this frame's
            // uploads: their staging copies would pile up frame after frame (gigabytes when
            // a tight budget evicts and uploads tiles again).
            if report.pool.uploaded_this_frame > 0 {
                self.queue.submit([]);
                let _ = self.device.poll(wgpu::PollType::wait_indefinitely());
            }
            on_frame(&report);
            if report.is_complete() {
                break (report, true);
            }
            if Instant::now() > deadline {
                break (report, false);
            }
            let progress = report.pool.uploaded_this_frame > 0 || report.sse_bound_px != sse_before;
            // Wait for tiles only if nothing could be uploaded this frame.
            if !progress {
                let idle = self.layer.loading() == 0 && self.layer.colours_loading() == 0;
                if idle && report.layer.arrived == 0 && report.layer.colours_arrived == 0 {
                    stalled += 1;
                    if stalled > 3 {
                        break (report, false);
                    }
                }
                self.layer.wait_for_tiles(Duration::from_millis(200));
            } else {
                stalled = 0;
            }
        };
        self.renderer.set_colour_fade(fade);
        self.set_uploads_per_frame(live.0);
        self.relax_detail = live.1;
        settled
    }

    /// One [`Globe::update`] of a settled view, as [`Globe::load_completely`] makes them: the
    /// bound does not relax (the frame after a complete load draws what was loaded).
    pub(crate) fn update_settled(&mut self, view: &View) -> FrameReport {
        let relax = std::mem::replace(&mut self.relax_detail, false);
        let report = self.update(view);
        self.relax_detail = relax;
        report
    }
}

/// The frame rate [`GlobeBuilder::uploads_per_frame`] is meant for.
const UPLOAD_PACE_FPS: f64 = 60.0;
/// A slow frame uploads at most this many times [`GlobeBuilder::uploads_per_frame`].
const MOST_UPLOAD_FRAMES: f64 = 16.0;

/// The ECEF point of a geodetic position with its height raised by `exaggeration`.
pub(crate) fn exaggerated(ellipsoid: &Ellipsoid, exaggeration: f64, at: Cartographic) -> DVec3 {
    ellipsoid.cartographic_to_ecef(Cartographic {
        height_m: at.height_m * exaggeration,
        ..at
    })
}

/// What the id buffer does in an overlay pass.
#[derive(Clone, Copy, Debug, PartialEq, Eq)]
enum IdBuffer {
    /// The frame's first overlay pass clears it.
    Clear,
    /// Later passes keep what earlier ones wrote.
    Load,
}

/// The attachments of one of the frame's passes.
#[derive(Clone, Copy, Debug)]
enum Attach {
    /// Colour and depth, both cleared.
    Terrain,
    /// Colour and depth kept, the id buffer.
    World(IdBuffer),
    /// Colour kept, the id buffer, no depth.
    Screen(IdBuffer),
}

/// Clears to `clear_to` (if `clear`) or keeps what is there, and stores.
fn ops<T>(clear: bool, clear_to: T) -> wgpu::Operations<T> {
    wgpu::Operations {
        load: if clear {
            wgpu::LoadOp::Clear(clear_to)
        } else {
            wgpu::LoadOp::Load
        },
        store: wgpu::StoreOp::Store,
    }
}

/// Begins one of the frame's passes over `colour` and the globe's targets.
fn begin_pass<'e>(
    encoder: &'e mut wgpu::CommandEncoder,
    label: &str,
    colour: &wgpu::TextureView,
    targets: &FrameTargets,
    attach: Attach,
) -> wgpu::RenderPass<'e> {
    let attachment = |view, clear, clear_to| {
        Some(wgpu::RenderPassColorAttachment {
            view,
            depth_slice: None,
            resolve_target: None,
            ops: ops(clear, clear_to),
        })
    };
    let terrain = matches!(attach, Attach::Terrain);
    let colour_attachment = attachment(colour, terrain, wgpu::Color::BLACK);
    let ids = match attach {
        Attach::Terrain => None,
        Attach::World(ids) | Attach::Screen(ids) => Some(attachment(
            targets.id_view(),
            ids == IdBuffer::Clear,
            wgpu::Color::TRANSPARENT,
        )),
    };
    let both;
    let colour_attachments: &[_] = match ids {
        None => std::slice::from_ref(&colour_attachment),
        Some(ids) => {
            both = [colour_attachment.clone(), ids];
            &both
        }
    };
    let depth = !matches!(attach, Attach::Screen(_));
    encoder.begin_render_pass(&wgpu::RenderPassDescriptor {
        label: Some(label),
        color_attachments: colour_attachments,
        depth_stencil_attachment: depth.then(|| wgpu::RenderPassDepthStencilAttachment {
            view: targets.depth_view(),
            // Reversed-Z: 0 is infinitely far.
            depth_ops: Some(ops(terrain, 0.0)),
            stencil_ops: None,
        }),
        timestamp_writes: None,
        occlusion_query_set: None,
        multiview_mask: None,
    })
}

/// The far plane of an orthographic view: just past the deepest point of `lowest` (the body
/// shrunk to the lowest ground) at the viewport's corners (over a convex body the depth of the
/// surface seen through a rectangle is greatest at a corner), plus 1 km. `None` when a corner
/// misses the body: then the whole near side may be in view.
fn ortho_far_m(view: &View, lowest: &Ellipsoid) -> Option<f64> {
    let (w, h) = (f64::from(view.width_px), f64::from(view.height_px));
    let mut far: f64 = 0.0;
    for (x, y) in [(0.0, 0.0), (w, 0.0), (0.0, h), (w, h)] {
        let (origin, dir) = view.ray(x, y);
        // The far side of the body is hidden: its entry is what the corner sees.
        let (entry, _) = lowest.intersect_ray(origin, dir)?;
        far = far.max(entry);
    }
    Some(far + 1_000.0)
}
