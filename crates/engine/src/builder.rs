//! [`GlobeBuilder`]: everything that configures a globe, and the source factory that turns
//! its layer descriptions into one terrain source.
//!
//! Sources can be opened on their own ([`GlobeBuilder::open_sources`]) before any window or
//! GPU context exists, so a source that cannot be opened fails first, with one error naming
//! it.

use std::sync::Arc;

use globus_geo::{Atmosphere, Ellipsoid};
use globus_render::{GpuContext, NightLights, TilePoolOptions};
use globus_stream::decode::DecodeLimits;
use globus_stream::fetch::{DiskCacheOptions, HttpClient, HttpOptions};
use globus_stream::open::{
    DEFAULT_LAYER_CACHE_BYTES, LayerKind, SourceSpec, elevation_pyramid, imagery_pyramid,
    open_layer,
};
use globus_stream::{
    DEFAULT_BASE_CACHE_BYTES, ProceduralSource, RasterTerrainSource, RefinedSource,
    TerrainLayerOptions, TerrainSource,
};
use globus_terrain::MeshOptions;
use globus_terrain::refine::RefineOptions;
use globus_tiling::quality::{QualityError, QualityOptions};

use crate::memory::SourceBudgets;
use crate::{EngineError, Globe};

/// The default planet: seed 24 has about a third land and a mountain range at 46 N 7.6 E,
/// where the benchmark path dives.
pub const DEFAULT_SEED: u64 = 24;

/// The smallest screen-space error bound, pixels.
pub const MIN_SSE_PX: f64 = 0.1;

/// Default of [`GlobeBuilder::request_lookahead_frames`].
pub const DEFAULT_REQUEST_LOOKAHEAD_FRAMES: f64 = 3.0;

/// Heights a real Earth's tiles may have before they are loaded (the deepest trench to above
/// the highest peak): bounds unloaded tiles and places the horizon-culling body.
const EARTH_HEIGHT_RANGE_M: (f64, f64) = (-11_000.0, 9_000.0);

/// Vertex and index room of the GPU pools, as a fraction of every slot at full grid size.
pub(crate) const GPU_POOL_FILL: f64 = 0.625;

/// Builds a [`Globe`]: data sources, budgets, the error bound, the body and the elevation
/// exaggeration. Setters take and return `&mut Self`, so options can be set conditionally;
/// nothing is opened until [`GlobeBuilder::open_sources`] or [`GlobeBuilder::build`].
///
/// Without layers the globe is the procedural planet of [`GlobeBuilder::seed`].
#[derive(Clone)]
pub struct GlobeBuilder {
    seed: u64,
    max_sse_px: f64,
    target_fps: Option<f64>,
    coarsest_sse_px: Option<f64>,
    max_level: u8,
    gpu_slots: u32,
    uploads_per_frame: u32,
    cache_bytes: usize,
    memory_bytes: Option<u64>,
    reserved_bytes: u64,
    workers: usize,
    mesh: MeshOptions,
    refine_below: Option<u8>,
    terrain: Vec<SourceSpec>,
    imagery: Vec<SourceSpec>,
    http: HttpOptions,
    disk_cache: Option<DiskCacheOptions>,
    request_lookahead_frames: f64,
    ellipsoid: Ellipsoid,
    viewport: Option<(u32, u32)>,
    source: Option<Arc<dyn TerrainSource>>,
    night_lights: Option<Arc<NightLights>>,
    night_imagery: Option<SourceSpec>,
    atmosphere: Option<Atmosphere>,
    fog: bool,
    morph: bool,
    marched_haze: bool,
}

impl Default for GlobeBuilder {
    fn default() -> Self {
        Self {
            seed: DEFAULT_SEED,
            max_sse_px: 2.0,
            target_fps: None,
            coarsest_sse_px: None,
            max_level: 26,
            gpu_slots: 1024,
            uploads_per_frame: 24,
            cache_bytes: TerrainLayerOptions::default().cache_bytes,
            memory_bytes: None,
            reserved_bytes: 0,
            workers: TerrainLayerOptions::default().workers,
            mesh: MeshOptions::default(),
            refine_below: None,
            terrain: Vec::new(),
            imagery: Vec::new(),
            http: HttpOptions::default(),
            disk_cache: None,
            request_lookahead_frames: DEFAULT_REQUEST_LOOKAHEAD_FRAMES,
            ellipsoid: Ellipsoid::WGS84,
            viewport: None,
            source: None,
            night_lights: None,
            night_imagery: None,
            atmosphere: None,
            fog: true,
            morph: true,
            marched_haze: false,
        }
    }
}

impl std::fmt::Debug for GlobeBuilder {
    fn fmt(&self, f: &mut std::fmt::Formatter<'_>) -> std::fmt::Result {
        f.debug_struct("GlobeBuilder")
            .field("seed", &self.seed)
            .field("max_sse_px", &self.max_sse_px)
            .field("memory_bytes", &self.memory_bytes)
            .field("terrain", &self.terrain)
            .field("imagery", &self.imagery)
            .field("exaggeration", &self.mesh.exaggeration)
            .field("source", &self.source.as_ref().map(|s| s.name().to_owned()))
            .finish_non_exhaustive()
    }
}

impl GlobeBuilder {
    /// The defaults: the procedural planet of seed [`DEFAULT_SEED`] on WGS84, a 2 px error
    /// bound, a 512 MiB tile cache and 1024 GPU tile slots (no overall memory budget).
    pub fn new() -> Self {
        Self::default()
    }

    /// Seed of the procedural planet.
    pub fn seed(&mut self, seed: u64) -> &mut Self {
        self.seed = seed;
        self
    }

    /// Screen-space error bound, pixels (default 2).
    pub fn max_sse_px(&mut self, px: f64) -> &mut Self {
        self.max_sse_px = px;
        self
    }

    /// A frame rate to hold (none by default): the error bound then follows the frame times
    /// the application reports ([`Globe::frame_time`]), rising from [`GlobeBuilder::max_sse_px`]
    /// when frames are slower than `1 / fps` and falling back with headroom
    /// ([`globus_tiling::quality`]), never past [`GlobeBuilder::coarsest_sse_px`].
    ///
    /// [`Globe::frame_time`]: crate::Globe::frame_time
    pub fn target_fps(&mut self, fps: Option<f64>) -> &mut Self {
        self.target_fps = fps;
        self
    }

    /// The coarsest error bound a target frame rate may raise the bound to, pixels (default
    /// four times [`GlobeBuilder::max_sse_px`]).
    pub fn coarsest_sse_px(&mut self, px: f64) -> &mut Self {
        self.coarsest_sse_px = Some(px);
        self
    }

    /// Deepest level drawn: of the procedural planet, or of refinement below real data.
    pub fn max_level(&mut self, level: u8) -> &mut Self {
        self.max_level = level;
        self
    }

    /// GPU tile slots (ignored with a memory budget, which sizes the pools).
    pub fn gpu_tiles(&mut self, slots: u32) -> &mut Self {
        self.gpu_slots = slots;
        self
    }

    /// Tiles uploaded to the GPU per frame at most (default 24), for frames of 60 fps or
    /// faster; a slower frame reported to [`crate::Globe::frame_time`] may upload as many as
    /// the 60 fps frames in its time (at most 16 times as many).
    pub fn uploads_per_frame(&mut self, n: u32) -> &mut Self {
        self.uploads_per_frame = n;
        self
    }

    /// Bytes of loaded tiles kept in RAM (ignored with a memory budget).
    pub fn cache_bytes(&mut self, bytes: usize) -> &mut Self {
        self.cache_bytes = bytes;
        self
    }

    /// One budget for all memory the globe holds ([`crate::memory`]): it sizes the tile
    /// cache, the GPU pools and the sources' caches, replacing [`GlobeBuilder::cache_bytes`]
    /// and [`GlobeBuilder::gpu_tiles`]. `None` removes it.
    pub fn memory_budget(&mut self, bytes: Option<u64>) -> &mut Self {
        self.memory_bytes = bytes;
        self
    }

    /// Bytes of the memory budget the application's overlays may take beyond what they hold
    /// when the globe is made (e.g. [`crate::VectorLayer::set_gpu_budget`]): the plan
    /// counts them with the process's own footprint, so the tiles get the rest.
    pub fn reserve_memory(&mut self, bytes: u64) -> &mut Self {
        self.reserved_bytes = bytes;
        self
    }

    /// City lights drawn where the Sun is down (see [`NightLights`]); a memory budget counts
    /// their texture ([`NightLights::gpu_bytes`]). `None` (the default): no lights.
    pub fn night_lights(&mut self, lights: Option<Arc<NightLights>>) -> &mut Self {
        self.night_lights = lights;
        self
    }

    /// City lights from an imagery pyramid (any source [`GlobeBuilder::imagery`] takes, e.g. a
    /// `globus tile imagery` directory of NASA's Black Marble): the whole layer is read once,
    /// when the sources open, into one equirectangular image at most
    /// [`NightLights::MAX_WIDTH`] wide (the lights are a single texture, not streamed per
    /// tile), which is then as [`GlobeBuilder::night_lights`]. Lights set there take
    /// precedence.
    pub fn night_imagery(&mut self, spec: Option<SourceSpec>) -> &mut Self {
        self.night_imagery = spec;
        self
    }

    /// The pyramid [`GlobeBuilder::night_imagery`] names, if any.
    pub fn night_imagery_source(&self) -> Option<&SourceSpec> {
        self.night_imagery.as_ref()
    }

    /// The night lights [`GlobeBuilder::night_imagery`] names, read now (or those set with
    /// [`GlobeBuilder::night_lights`]).
    pub fn open_night_lights(&self) -> Result<Option<Arc<NightLights>>, EngineError> {
        let Some(spec) = self
            .night_imagery
            .as_ref()
            .filter(|_| self.night_lights.is_none())
        else {
            return Ok(self.night_lights.clone());
        };
        let client = Arc::new(HttpClient::new(self.http.clone()));
        let layer = open_layer(spec, LayerKind::Imagery, &client, self.disk_cache.as_ref())
            .map_err(|error| EngineError::Source {
                what: "night imagery",
                url: spec.url.clone(),
                error,
            })?;
        // A row of the deepest level's tiles at a time: 64 MiB holds 256 of 256 x 256.
        let pyramid = imagery_pyramid(layer, DecodeLimits::default(), 64 << 20);
        let image = globus_stream::mosaic::equirectangular(
            &pyramid,
            NightLights::MAX_WIDTH,
            &globus_stream::fetch::Cancel::new(),
        )
        .map_err(|error| EngineError::NightImagery {
            url: spec.url.clone(),
            error,
        })?;
        tracing::info!(
            "night imagery {}: {} x {} from its tiles",
            spec.url,
            image.width,
            image.height
        );
        let lights = NightLights::from_rgb(image.width, image.height, &image.rgb)
            .expect("a mosaic is twice as wide as tall and at most the widest lights");
        Ok(Some(Arc::new(lights)))
    }

    /// The air over the body (default `None`: [`Atmosphere::for_body`], the Earth's over an
    /// Earth-sized body and none over others); [`Atmosphere::none`] draws no sky or haze.
    /// It is moved onto the globe's body ([`Atmosphere::over`]).
    pub fn atmosphere(&mut self, atmosphere: Option<Atmosphere>) -> &mut Self {
        self.atmosphere = atmosphere;
        self
    }

    /// The air drawn over `body`.
    pub(crate) fn atmosphere_over(&self, body: &Ellipsoid) -> Atmosphere {
        self.atmosphere
            .map_or_else(|| Atmosphere::for_body(body), |a| a.over(body))
    }

    /// Whether haze lowers the detail loaded where it hides it (default on; see
    /// [`crate::Globe::set_fog`]).
    pub fn fog(&mut self, on: bool) -> &mut Self {
        self.fog = on;
        self
    }

    /// Whether [`GlobeBuilder::fog`] is on.
    pub(crate) fn fog_on(&self) -> bool {
        self.fog
    }

    /// Whether tiles grow out of their parents' surfaces and colours instead of replacing
    /// them in one frame (default on; see [`crate::Globe::set_morph`]).
    pub fn morph(&mut self, on: bool) -> &mut Self {
        self.morph = on;
        self
    }

    /// Whether [`GlobeBuilder::morph`] is on.
    pub(crate) fn morph_on(&self) -> bool {
        self.morph
    }

    /// Whether every ground pixel marches the air along its own line of sight instead of
    /// reading the frame's aerial-perspective table (default off; see
    /// [`crate::Globe::set_marched_haze`]).
    pub fn marched_haze(&mut self, on: bool) -> &mut Self {
        self.marched_haze = on;
        self
    }

    /// Whether [`GlobeBuilder::marched_haze`] is on.
    pub(crate) fn marched_haze_on(&self) -> bool {
        self.marched_haze
    }

    /// The night lights, if set.
    pub(crate) fn night_lights_ref(&self) -> Option<&NightLights> {
        self.night_lights.as_deref()
    }

    /// Tile loader threads.
    pub fn workers(&mut self, n: usize) -> &mut Self {
        self.workers = n;
        self
    }

    /// Vertical error a tile's adaptive mesh may add, as a fraction of the tile's geometric
    /// error (0 draws every sample of the tile grid; default 0.25).
    pub fn mesh_error(&mut self, fraction: f64) -> &mut Self {
        self.mesh.error_fraction = fraction;
        self
    }

    /// Elevation exaggeration (Kaiser 2018, 3.4): terrain is drawn this many times its height
    /// above the ellipsoid, with skirts, bounds, culling and LOD errors to match. Anything
    /// placed at an altitude through [`Globe::world_position`] is raised the same way, so
    /// flight levels keep their place above the ground. Default 1.
    pub fn exaggeration(&mut self, factor: f64) -> &mut Self {
        self.mesh.exaggeration = factor;
        self
    }

    /// Treat the procedural planet's data as ending at this level and invent everything
    /// deeper by procedural refinement (a stand-in for real data that ends); `None`
    /// generates every level.
    pub fn refine_below(&mut self, level: Option<u8>) -> &mut Self {
        self.refine_below = level;
        self
    }

    /// Adds an elevation layer on top of the others.
    pub fn terrain(&mut self, spec: SourceSpec) -> &mut Self {
        self.terrain.push(spec);
        self.source = None;
        self
    }

    /// Adds an imagery layer over the others.
    pub fn imagery(&mut self, spec: SourceSpec) -> &mut Self {
        self.imagery.push(spec);
        self.source = None;
        self
    }

    /// How tile services are spoken to.
    pub fn http(&mut self, options: HttpOptions) -> &mut Self {
        self.http = options;
        self
    }

    /// An on-disk cache for tiles from services.
    pub fn disk_cache(&mut self, options: Option<DiskCacheOptions>) -> &mut Self {
        self.disk_cache = options;
        self
    }

    /// Requests culled while moving: a wanted tile outside the view the camera will have
    /// after this many more frames at its current velocity is not requested while a loaded
    /// ancestor can stand in for it. 0 requests everything (default 3; Cesium's
    /// `cullRequestsWhileMoving` serves the same end).
    pub fn request_lookahead_frames(&mut self, frames: f64) -> &mut Self {
        self.request_lookahead_frames = frames;
        self
    }

    /// The body the terrain is on (default WGS84). Real layers are georeferenced on it; the
    /// procedural planet is generated on it.
    pub fn ellipsoid(&mut self, ellipsoid: Ellipsoid) -> &mut Self {
        self.ellipsoid = ellipsoid;
        self.source = None;
        self
    }

    /// The size frames will have, if known now: the frame's depth and id buffers are then
    /// made before the memory budget measures the process.
    pub fn viewport(&mut self, width_px: u32, height_px: u32) -> &mut Self {
        self.viewport = Some((width_px, height_px));
        self
    }

    /// Draws terrain from `source` instead of the layers or the procedural planet: any
    /// [`TerrainSource`], for example one of the application's own or a wrapper around
    /// [`GlobeBuilder::open_source`]'s.
    pub fn source(&mut self, source: Arc<dyn TerrainSource>) -> &mut Self {
        self.source = Some(source);
        self
    }

    /// Opens the data sources now (if not opened already) and keeps them for
    /// [`GlobeBuilder::build`]: call it before creating a window, so that a source that cannot
    /// be opened fails first.
    pub fn open_sources(&mut self) -> Result<&mut Self, EngineError> {
        if self.source.is_none() {
            self.source = Some(self.open_source()?);
        }
        if self.night_lights.is_none() {
            self.night_lights = self.open_night_lights()?;
        }
        Ok(self)
    }

    /// The terrain source the options describe (the one given with
    /// [`GlobeBuilder::source`], if any): the procedural planet (optionally cut at a level
    /// and refined below), or real elevation and imagery layers refined below their data.
    pub fn open_source(&self) -> Result<Arc<dyn TerrainSource>, EngineError> {
        if let Some(source) = &self.source {
            return Ok(Arc::clone(source));
        }
        // Before opening anything: 5,000 layers would each be opened first.
        self.check()?;
        let budgets = self.source_budgets();
        let refined = |data: Arc<dyn TerrainSource>| -> Arc<dyn TerrainSource> {
            Arc::new(
                RefinedSource::new(data, RefineOptions::default(), self.max_level, self.mesh)
                    .with_base_cache_bytes(budgets.refine_bases),
            )
        };
        if !self.uses_real_data() {
            let planet = |level: u8| {
                ProceduralSource::with_ellipsoid(self.seed, self.ellipsoid, level)
                    .with_mesh_options(self.mesh)
            };
            return Ok(match self.refine_below {
                None => Arc::new(planet(self.max_level)),
                Some(level) => refined(Arc::new(planet(level.min(self.max_level)))),
            });
        }
        let client = Arc::new(HttpClient::new(self.http.clone()));
        let limits = DecodeLimits::default();
        let open = |spec: &SourceSpec, kind: LayerKind| {
            let what = match kind {
                LayerKind::Elevation => "terrain",
                LayerKind::Imagery => "imagery",
            };
            let fail = |error| EngineError::Source {
                what,
                url: spec.url.clone(),
                error,
            };
            open_layer(spec, kind, &client, self.disk_cache.as_ref()).map_err(fail)
        };
        let mut elevation = Vec::new();
        for spec in &self.terrain {
            let layer = open(spec, LayerKind::Elevation)?;
            let pyramid = elevation_pyramid(layer, limits, budgets.per_layer).map_err(|error| {
                EngineError::Source {
                    what: "terrain",
                    url: spec.url.clone(),
                    error,
                }
            })?;
            elevation.push(pyramid);
        }
        let mut imagery = Vec::new();
        for spec in &self.imagery {
            let layer = open(spec, LayerKind::Imagery)?;
            imagery.push(imagery_pyramid(layer, limits, budgets.per_layer));
        }
        let raster = RasterTerrainSource::new(
            elevation,
            imagery,
            self.ellipsoid,
            EARTH_HEIGHT_RANGE_M,
            self.mesh,
        )
        .map_err(EngineError::Layers)?;
        Ok(refined(Arc::new(raster)))
    }

    /// Builds the globe on `gpu`, drawing into colour targets of `colour_format`, opening the
    /// sources first if [`GlobeBuilder::open_sources`] has not. With a memory budget the
    /// process's footprint is measured now and the rest is shared out
    /// ([`crate::memory::MemoryPlan`]); a budget too small for it fails here.
    pub fn build(
        &self,
        gpu: &GpuContext,
        colour_format: wgpu::TextureFormat,
    ) -> Result<Globe, EngineError> {
        let info = gpu.adapter.get_info();
        let software = info.device_type == wgpu::DeviceType::Cpu;
        self.build_with(
            &gpu.device,
            &gpu.queue,
            info.backend,
            software,
            colour_format,
        )
    }

    /// Like [`GlobeBuilder::build`], on a device and queue the application made itself (an
    /// engine that already has its wgpu context). `backend` is its adapter's
    /// (`adapter.get_info().backend`): OpenGL's depth range needs a larger near plane. A
    /// memory budget here assumes a hardware rasteriser; [`GlobeBuilder::build`] also counts
    /// what a software one (lavapipe) takes at its first draw.
    pub fn build_on(
        &self,
        device: &wgpu::Device,
        queue: &wgpu::Queue,
        backend: wgpu::Backend,
        colour_format: wgpu::TextureFormat,
    ) -> Result<Globe, EngineError> {
        self.build_with(device, queue, backend, false, colour_format)
    }

    /// Both builds: checks, opens the sources and makes the globe; `software` says whether
    /// the device rasterises on the CPU (its first draw is then counted in the budget).
    fn build_with(
        &self,
        device: &wgpu::Device,
        queue: &wgpu::Queue,
        backend: wgpu::Backend,
        software: bool,
        colour_format: wgpu::TextureFormat,
    ) -> Result<Globe, EngineError> {
        self.check()?;
        if self.night_lights.is_none() && self.night_imagery.is_some() {
            let mut opened = self.clone();
            opened.night_lights = self.open_night_lights()?;
            return opened.build_with(device, queue, backend, software, colour_format);
        }
        let source = self.open_source()?;
        Globe::new(
            self,
            (device, queue, backend, software),
            colour_format,
            source,
        )
    }

    /// Refuses options out of their ranges, naming the option.
    fn check(&self) -> Result<(), EngineError> {
        let invalid = |option, value: f64, expected| EngineError::InvalidOption {
            option,
            value: value.to_string(),
            expected,
        };
        // Below a tenth of a pixel no error can be seen, and the cut grows without end
        // (1e-300 asked for 10 GB of tiles).
        if !(MIN_SSE_PX..=1000.0).contains(&self.max_sse_px) {
            return Err(invalid(
                "error bound",
                self.max_sse_px,
                "must be a pixel error from 0.1 to 1000",
            ));
        }
        if let Some(fps) = self.target_fps {
            self.quality_options()
                .map_err(|e| EngineError::InvalidOption {
                    option: "target frame rate",
                    value: format!(
                        "{fps} fps, {} to {} px",
                        self.max_sse_px,
                        self.coarsest_px()
                    ),
                    expected: match e {
                        QualityError::TargetFps(_) => {
                            "must be above 0 and at most 1000 frames per second"
                        }
                        QualityError::Range { .. } => {
                            "needs a coarsest error bound at least the error bound, at most 1000 px"
                        }
                    },
                })?;
        }
        if !(0.0..=4.0).contains(&self.mesh.error_fraction) {
            return Err(invalid(
                "mesh error",
                self.mesh.error_fraction,
                "must be a fraction of the tile error from 0 to 4",
            ));
        }
        if !(0.0..=1000.0).contains(&self.mesh.exaggeration) {
            return Err(invalid(
                "exaggeration",
                self.mesh.exaggeration,
                "must be a factor from 0 to 1000",
            ));
        }
        if !(0.0..=1000.0).contains(&self.request_lookahead_frames) {
            return Err(invalid(
                "request lookahead",
                self.request_lookahead_frames,
                "must be a number of frames from 0 to 1000",
            ));
        }
        self.http.check().map_err(EngineError::Http)?;
        if self.memory_bytes == Some(0) {
            return Err(invalid("memory budget", 0.0, "must be above 0"));
        }
        // Budgets beyond the machine are refused, naming the largest that makes sense.
        if let Some(ram) = crate::memory::physical_bytes() {
            let mib = |b: u64| b >> 20;
            for (option, bytes) in [
                ("memory budget", self.memory_bytes.unwrap_or(0)),
                ("tile cache", self.cache_bytes as u64),
            ] {
                if bytes > ram {
                    return Err(EngineError::TooLarge {
                        option,
                        value_mib: mib(bytes),
                        largest_mib: mib(ram),
                    });
                }
            }
        }
        let layers = self.terrain.len() + self.imagery.len();
        if layers > crate::memory::MAX_LAYERS {
            return Err(invalid(
                "layers",
                layers as f64,
                "must be at most 64 terrain and imagery layers together",
            ));
        }
        if self.gpu_slots == 0 || self.gpu_slots > crate::memory::MAX_GPU_TILES {
            return Err(invalid(
                "GPU tiles",
                f64::from(self.gpu_slots),
                "must be from 1 to 65536 tile slots",
            ));
        }
        if self.workers == 0 || self.workers > crate::memory::MAX_WORKERS {
            return Err(invalid(
                "workers",
                self.workers as f64,
                "must be from 1 to 256 loader threads",
            ));
        }
        if self.uses_real_data() && self.refine_below.is_some() {
            return Err(EngineError::InvalidOption {
                option: "refine below",
                value: format!("{:?}", self.refine_below),
                expected: "cuts the procedural planet; real data is refined below its own end",
            });
        }
        Ok(())
    }

    /// Whether the globe streams real data (else it is the procedural planet).
    pub fn uses_real_data(&self) -> bool {
        !(self.terrain.is_empty() && self.imagery.is_empty())
    }

    /// The screen-space error bound, pixels.
    pub fn error_bound_px(&self) -> f64 {
        self.max_sse_px
    }

    /// The frame rate to hold, if any.
    pub fn target_frame_rate(&self) -> Option<f64> {
        self.target_fps
    }

    /// The coarsest error bound a target frame rate may raise the bound to, pixels.
    pub fn coarsest_px(&self) -> f64 {
        self.coarsest_sse_px.unwrap_or(4.0 * self.max_sse_px)
    }

    /// The quality loop's settings for the target frame rate (none without one).
    fn quality_options(&self) -> Result<Option<QualityOptions>, QualityError> {
        let Some(fps) = self.target_fps else {
            return Ok(None);
        };
        let coarsest = self.coarsest_px();
        if coarsest > 1000.0 {
            return Err(QualityError::Range {
                min: self.max_sse_px,
                max: coarsest,
            });
        }
        QualityOptions::new(fps, self.max_sse_px, coarsest).map(Some)
    }

    /// The memory budget, bytes, if there is one.
    pub fn memory_budget_bytes(&self) -> Option<u64> {
        self.memory_bytes
    }

    /// The tile cache's size without a memory budget, bytes.
    pub fn tile_cache_bytes(&self) -> usize {
        self.cache_bytes
    }

    /// GPU tile slots without a memory budget.
    pub fn gpu_tile_slots(&self) -> u32 {
        self.gpu_slots
    }

    /// Tile loader threads asked for.
    pub fn worker_threads(&self) -> usize {
        self.workers
    }

    /// The deepest level drawn.
    pub fn deepest_level(&self) -> u8 {
        self.max_level
    }

    /// The HTTP settings.
    pub fn http_options(&self) -> &HttpOptions {
        &self.http
    }

    /// The disk cache, if any.
    pub fn disk_cache_options(&self) -> Option<&DiskCacheOptions> {
        self.disk_cache.as_ref()
    }

    /// The elevation layers, bottom first.
    pub fn terrain_layers(&self) -> &[SourceSpec] {
        &self.terrain
    }

    /// The imagery layers, bottom first.
    pub fn imagery_layers(&self) -> &[SourceSpec] {
        &self.imagery
    }

    /// The request lookahead, frames.
    pub fn lookahead_frames(&self) -> f64 {
        self.request_lookahead_frames
    }

    /// The elevation exaggeration.
    pub fn exaggeration_factor(&self) -> f64 {
        self.mesh.exaggeration
    }

    /// The mesh error fraction.
    pub fn mesh_error_fraction(&self) -> f64 {
        self.mesh.error_fraction
    }

    pub(crate) fn settings(&self) -> Settings {
        Settings {
            max_sse_px: self.max_sse_px,
            // Checked by `check` before any globe is built.
            quality: self.quality_options().ok().flatten(),
            gpu_slots: self.gpu_slots,
            uploads_per_frame: self.uploads_per_frame,
            cache_bytes: self.cache_bytes,
            memory_bytes: self.memory_bytes,
            reserved_bytes: self.reserved_bytes,
            layer_workers: self.layer_workers(),
            source_caches: self.uses_real_data() || self.refine_below.is_some(),
            request_lookahead_frames: self.request_lookahead_frames,
            exaggeration: self.mesh.exaggeration,
            viewport: self.viewport,
        }
    }

    /// Loader threads of the terrain layer (its colour loads have as many again).
    fn layer_workers(&self) -> usize {
        // Loads from tile services mostly wait on the network: enough of them to keep two
        // hosts at their concurrency limit.
        if self.uses_real_data() {
            self.workers.max(2 * self.http.per_host)
        } else {
            self.workers
        }
    }

    /// The sources' share of the memory budget (their defaults without one).
    fn source_budgets(&self) -> SourceBudgets {
        match self.memory_bytes {
            Some(total) => SourceBudgets::of(total, self.terrain.len() + self.imagery.len()),
            None => SourceBudgets {
                per_layer: DEFAULT_LAYER_CACHE_BYTES,
                refine_bases: DEFAULT_BASE_CACHE_BYTES,
            },
        }
    }
}

/// What [`Globe`] keeps of the builder.
#[derive(Clone, Copy, Debug)]
pub(crate) struct Settings {
    pub max_sse_px: f64,
    pub quality: Option<QualityOptions>,
    pub gpu_slots: u32,
    pub uploads_per_frame: u32,
    pub cache_bytes: usize,
    pub memory_bytes: Option<u64>,
    pub reserved_bytes: u64,
    pub layer_workers: usize,
    pub source_caches: bool,
    pub request_lookahead_frames: f64,
    pub exaggeration: f64,
    pub viewport: Option<(u32, u32)>,
}

impl Settings {
    /// Pools of `slots` slots with the configured upload budget.
    pub fn pool_options(&self, slots: u32) -> TilePoolOptions {
        TilePoolOptions {
            uploads_per_frame: self.uploads_per_frame,
            ..TilePoolOptions::with_slots(slots, GPU_POOL_FILL)
        }
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    fn refused(b: &GlobeBuilder, needle: &str) {
        match b.open_source() {
            Ok(_) => panic!("accepted; wanted an error with {needle:?}"),
            Err(e) => assert!(e.to_string().contains(needle), "{e}"),
        }
    }

    /// Budget-like settings at the extremes took gigabytes (a billion GPU slots, 5,000
    /// layers, an error bound of 1e-300): each is refused before anything is opened.
    #[test]
    fn absurd_settings_are_refused_before_anything_is_opened() {
        let mut b = GlobeBuilder::new();
        for i in 0..65 {
            // Paths that do not exist: opening any of them would fail differently.
            b.imagery(SourceSpec::parse(&format!("/nonexistent/layer-{i}")).expect("spec"));
        }
        refused(&b, "layers 65");
        refused(GlobeBuilder::new().gpu_tiles(1_000_000_000), "GPU tiles");
        refused(GlobeBuilder::new().workers(0), "workers");
        refused(GlobeBuilder::new().workers(10_000), "workers");
        refused(GlobeBuilder::new().max_sse_px(1e-300), "error bound");
        if let Some(ram) = crate::memory::physical_bytes() {
            refused(
                GlobeBuilder::new().memory_budget(Some(ram + (1 << 30))),
                "this machine has",
            );
        }
        assert!(GlobeBuilder::new().gpu_tiles(65_536).open_source().is_ok());
    }
}
