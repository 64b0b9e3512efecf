//! [`Globe`]: one frame of Globus, wiring the three subsystems.
//!
//! ```text
//!  view ──> select (tiling) ──> draw list ──────────────> GlobeRenderer::prepare
//!              ▲      │ wanted tiles                          ▲
//!              │      ├─ loaded on the CPU, not on the GPU ──> TilePool::upload (budgeted)
//!   TerrainLayer│     └─ not loaded ─────────────────────────> TerrainLayer (scheduler, cache)
//!   (oracle) ───┘
//! ```
//!
//! Selection sees a tile as loaded only when it is both in the CPU cache and resident in the
//! GPU pool (the engine marks uploads and evictions with [`TerrainLayer::set_drawable`]), so
//! everything it draws can be drawn this very frame: no holes while data streams in, only
//! coarser ancestors.
//!
//! Imagery that loads on its own ([`TileColour`]) arrives after its tile's geometry: the
//! tile is uploaded without it, reading its nearest resident ancestor's colour cropped and
//! scaled (a root is uploaded first if no ancestor has colour on the GPU), and its own colour
//! follows when it arrives. Drawn tiles' colours go up before new tiles: they are on screen.

use std::sync::Arc;
use std::time::{Duration, Instant};

use globus_geo::{Cartographic, DVec3, Ellipsoid, Frustum, Intersection, View};
use globus_render::{
    DrawStats, FrameInputs, GlobeRenderer, Lighting, PoolStats, TilePool, TilePoolOptions,
    near_plane_m,
};
use globus_stream::decode::DecodeLimits;
use globus_stream::fetch::{DiskCacheOptions, HttpClient, HttpOptions};
use globus_stream::open::{
    DEFAULT_LAYER_CACHE_BYTES, LayerKind, SourceSpec, elevation_pyramid, imagery_pyramid,
    open_layer,
};
use globus_stream::{
    DEFAULT_BASE_CACHE_BYTES, LayerStats, ProceduralSource, RasterTerrainSource, RefinedSource,
    TerrainLayer, TerrainLayerOptions, TerrainSource, TileColour,
};
use globus_terrain::MeshOptions;
use globus_terrain::grid::{HEIGHT_GRID_SIDE, MESH_SEGMENTS};
use globus_terrain::refine::RefineOptions;

use crate::memory::{MemoryPlan, SourceBudgets, resident_bytes};
use globus_tiling::{
    Selection, SelectionOptions, SelectionStats, TileKey, TileOracle, TileRequest, TilingScheme,
    select_into,
};

/// The default planet: seed 24 has about a third land and a mountain range at 46 N 7.6 E,
/// where the benchmark path dives.
pub const DEFAULT_SEED: u64 = 24;

/// Everything that configures a globe.
#[derive(Clone, Debug)]
pub struct GlobeOptions {
    /// Seed of the procedural planet.
    pub seed: u64,
    /// Screen-space error bound, pixels.
    pub max_sse_px: f64,
    /// Deepest level of the procedural planet.
    pub max_level: u8,
    /// GPU tile slots.
    pub gpu_slots: u32,
    /// Tiles uploaded per frame.
    pub uploads_per_frame: u32,
    /// CPU cache budget, bytes.
    pub cache_bytes: usize,
    /// One budget for all memory the globe holds ([`crate::memory`]): when set, it sizes
    /// the tile cache, the GPU pools and the sources' caches, replacing `cache_bytes` and
    /// `gpu_slots`.
    pub memory_bytes: Option<u64>,
    /// Tile worker threads.
    pub workers: usize,
    /// How tile meshes are cut.
    pub mesh: MeshOptions,
    /// Treat the planet's data as ending at this level and invent everything deeper by
    /// procedural refinement ([`RefinedSource`]); `None` generates every level.
    pub refine_below: Option<u8>,
    /// Elevation layers, bottom first. Empty (with no imagery): the procedural planet.
    pub terrain: Vec<SourceSpec>,
    /// Imagery layers, bottom first.
    pub imagery: Vec<SourceSpec>,
    /// How tile services are spoken to.
    pub http: HttpOptions,
    /// An on-disk cache for tiles from services (none by default).
    pub disk_cache: Option<DiskCacheOptions>,
    /// Requests culled while moving: a wanted tile outside the view the camera will have
    /// after this many more frames at its current velocity is not requested while a loaded
    /// ancestor can stand in for it, since it would most likely arrive after the view left
    /// it. 0 requests everything. Cesium's `cullRequestsWhileMoving` serves the same end.
    pub request_lookahead_frames: f64,
}

impl Default for GlobeOptions {
    fn default() -> Self {
        Self {
            seed: DEFAULT_SEED,
            max_sse_px: 2.0,
            max_level: 26,
            gpu_slots: 1024,
            uploads_per_frame: 24,
            cache_bytes: TerrainLayerOptions::default().cache_bytes,
            memory_bytes: None,
            workers: TerrainLayerOptions::default().workers,
            mesh: MeshOptions::default(),
            refine_below: None,
            terrain: Vec::new(),
            imagery: Vec::new(),
            http: HttpOptions::default(),
            disk_cache: None,
            request_lookahead_frames: REQUEST_LOOKAHEAD_FRAMES,
        }
    }
}

impl GlobeOptions {
    /// Whether the globe streams real data (else it is the procedural planet).
    pub fn uses_real_data(&self) -> bool {
        !(self.terrain.is_empty() && self.imagery.is_empty())
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

    /// Whether the terrain source keeps caches of its own (decoded source tiles, bases).
    fn source_caches(&self) -> bool {
        self.uses_real_data() || self.refine_below.is_some()
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

/// Heights a real Earth's tiles may have before they are loaded (the deepest trench to above
/// the highest peak): bounds unloaded tiles and places the horizon-culling body.
const EARTH_HEIGHT_RANGE_M: (f64, f64) = (-11_000.0, 9_000.0);

/// Vertex and index room of the GPU pools, as a fraction of every slot at full grid size.
const GPU_POOL_FILL: f64 = 0.625;

/// Default of [`Globe::request_lookahead_frames`].
const REQUEST_LOOKAHEAD_FRAMES: f64 = 3.0;

/// The terrain source `options` describe: the procedural planet (optionally cut at a level
/// and refined below), or real elevation and imagery layers refined below their data.
pub fn terrain_source(options: &GlobeOptions) -> anyhow::Result<Arc<dyn TerrainSource>> {
    let budgets = options.source_budgets();
    // Data continued below its end by procedural refinement.
    let refined = |data: Arc<dyn TerrainSource>| -> Arc<dyn TerrainSource> {
        Arc::new(
            RefinedSource::new(
                data,
                RefineOptions::default(),
                options.max_level,
                options.mesh,
            )
            .with_base_cache_bytes(budgets.refine_bases),
        )
    };
    if !options.uses_real_data() {
        return Ok(match options.refine_below {
            None => Arc::new(
                ProceduralSource::new(options.seed, options.max_level)
                    .with_mesh_options(options.mesh),
            ),
            Some(level) => refined(Arc::new(
                ProceduralSource::new(options.seed, level.min(options.max_level))
                    .with_mesh_options(options.mesh),
            )),
        });
    }
    let client = Arc::new(HttpClient::new(options.http.clone()));
    let limits = DecodeLimits::default();
    let open = |spec: &SourceSpec, kind: LayerKind| {
        open_layer(spec, kind, &client, options.disk_cache.as_ref()).map_err(|e| {
            let what = match kind {
                LayerKind::Elevation => "terrain",
                LayerKind::Imagery => "imagery",
            };
            anyhow::anyhow!("{what} {}: {e}", spec.url)
        })
    };
    let mut elevation = Vec::new();
    for spec in &options.terrain {
        let layer = open(spec, LayerKind::Elevation)?;
        elevation
            .push(elevation_pyramid(layer, limits, budgets.per_layer).map_err(anyhow::Error::msg)?);
    }
    let mut imagery = Vec::new();
    for spec in &options.imagery {
        imagery.push(imagery_pyramid(
            open(spec, LayerKind::Imagery)?,
            limits,
            budgets.per_layer,
        ));
    }
    let raster = RasterTerrainSource::new(
        elevation,
        imagery,
        Ellipsoid::WGS84,
        EARTH_HEIGHT_RANGE_M,
        options.mesh,
    )
    .map_err(anyhow::Error::msg)?;
    Ok(refined(Arc::new(raster)))
}

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
    /// ([`Globe::request_lookahead_frames`]).
    pub requests_deferred: u32,
    /// Drawn tiles showing an ancestor's colour while their own loads (or waits for upload).
    pub colours_pending: u32,
}

/// The procedural planet, its data layer and its renderer.
pub struct Globe {
    layer: TerrainLayer,
    /// The renderer and its pools.
    pub renderer: GlobeRenderer,
    options: SelectionOptions,
    configured_sse_px: f64,
    selection: Selection,
    /// Sun and air.
    pub lighting: Option<Lighting>,
    /// Whether the error bound may come back down after budgets forced it up.
    pub relax_detail: bool,
    /// See [`GlobeOptions::request_lookahead_frames`]; may be changed between frames.
    pub request_lookahead_frames: f64,
    /// The eye position of the previous frame.
    last_eye: Option<DVec3>,
    /// How the memory budget is shared, if there is one.
    memory: Option<MemoryPlan>,
}

/// The memory budget and what its parts hold ([`Globe::memory_use`]), bytes.
#[derive(Clone, Copy, Debug)]
pub struct MemoryUse {
    /// The plan, if the globe has a budget.
    pub plan: Option<MemoryPlan>,
    /// Loaded tiles in the cache.
    pub tile_cache: u64,
    /// The sources' own caches (decoded source tiles, refinement bases).
    pub sources: u64,
    /// The GPU pools (allocated in full at start).
    pub gpu_pool: u64,
    /// Resident memory of the whole process (Linux).
    pub resident: Option<u64>,
}

impl Globe {
    /// A globe rendering into `colour_format` on `device`; fails if a data source named in
    /// `options` cannot be opened.
    pub fn new(
        device: &wgpu::Device,
        colour_format: wgpu::TextureFormat,
        options: &GlobeOptions,
    ) -> anyhow::Result<Self> {
        Self::with_source(device, colour_format, options, terrain_source(options)?)
    }

    /// A globe over a terrain source opened beforehand (see [`terrain_source`]), so that a
    /// source that cannot be opened fails before any window or GPU context exists. With a
    /// memory budget, the process's footprint is measured now and the rest is shared out
    /// ([`MemoryPlan`]); a budget too small for it fails here.
    pub fn with_source(
        device: &wgpu::Device,
        colour_format: wgpu::TextureFormat,
        options: &GlobeOptions,
        source: Arc<dyn TerrainSource>,
    ) -> anyhow::Result<Self> {
        let workers = options.layer_workers();
        let pool_options = |slots| TilePoolOptions {
            uploads_per_frame: options.uploads_per_frame,
            ..TilePoolOptions::with_slots(slots, GPU_POOL_FILL)
        };
        let memory = match options.memory_bytes {
            Some(total) => Some(
                MemoryPlan::new(
                    total,
                    resident_bytes(),
                    // The terrain layer's loaders and as many for colour.
                    2 * workers,
                    options.source_caches(),
                    |slots| pool_options(slots).gpu_bytes(),
                )
                .map_err(anyhow::Error::msg)?,
            ),
            None => None,
        };
        let layer = TerrainLayer::new(
            source,
            TerrainLayerOptions {
                cache_bytes: memory.map_or(options.cache_bytes, |m| m.tile_cache as usize),
                workers,
            },
        );
        let pool = TilePool::new(
            device,
            pool_options(memory.map_or(options.gpu_slots, |m| m.gpu_slots)),
        );
        let selection_options = SelectionOptions {
            max_sse_px: options.max_sse_px,
            occluder: *layer.occluder(),
            near_m: 0.01,
            max_level: layer.max_level(),
        };
        Ok(Self {
            layer,
            renderer: GlobeRenderer::new(device, colour_format, pool),
            options: selection_options,
            configured_sse_px: options.max_sse_px,
            selection: Selection::default(),
            lighting: None,
            relax_detail: true,
            request_lookahead_frames: options.request_lookahead_frames,
            last_eye: None,
            memory,
        })
    }

    /// The memory budget's plan (if the globe has one) and what each part holds now.
    pub fn memory_use(&self) -> MemoryUse {
        MemoryUse {
            plan: self.memory,
            tile_cache: self.layer.cache_bytes().0 as u64,
            sources: self.layer.source().cached_bytes() as u64,
            gpu_pool: self.renderer.pool.stats().gpu_bytes,
            resident: resident_bytes(),
        }
    }

    /// The planet's ellipsoid.
    pub fn ellipsoid(&self) -> Ellipsoid {
        *self.layer.ellipsoid()
    }

    /// The data layer.
    pub fn layer(&self) -> &TerrainLayer {
        &self.layer
    }

    /// The data layer, for benchmarks that inspect it.
    pub fn layer_mut(&mut self) -> &mut TerrainLayer {
        &mut self.layer
    }

    /// The last selection.
    pub fn selection(&self) -> &Selection {
        &self.selection
    }

    /// Height of the surface at a longitude and latitude (radians), metres: from the source
    /// if it can say, else from the deepest loaded tile, else 0.
    pub fn ground_height_m(&self, lon_rad: f64, lat_rad: f64) -> f64 {
        if let Some(h) = self.layer.source().height_at(lon_rad, lat_rad) {
            return h;
        }
        let scheme = TilingScheme::Geographic;
        let mut best = None;
        for level in 0..=self.layer.max_level() {
            let Some(key) = scheme.tile_at(lon_rad, lat_rad, level) else {
                break;
            };
            match self.layer.get(key) {
                Some(data) => best = Some(data.clone()),
                None => break,
            }
        }
        best.map_or(0.0, |d| sample_heights(&d.tile, lon_rad, lat_rad))
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

    /// Runs one frame's CPU work: selection, data requests, uploads, and the draw list.
    pub fn frame(
        &mut self,
        device: &wgpu::Device,
        queue: &wgpu::Queue,
        view: &View,
    ) -> FrameReport {
        let ellipsoid = self.ellipsoid();
        let eye = ellipsoid
            .ecef_to_cartographic(view.position)
            .unwrap_or_default();
        let ground = self.ground_height_m(eye.lon_rad, eye.lat_rad);
        let height_above_ground = (eye.height_m - ground).max(0.0);
        self.options.near_m = near_plane_m(height_above_ground);
        let pool = &mut self.renderer.pool;
        pool.begin_frame();

        let started = Instant::now();
        let started_cpu = cpu_time::ThreadTime::try_now().ok();
        select_into(view, &self.layer, &self.options, &mut self.selection);
        let select_us = started.elapsed().as_secs_f64() * 1e6;
        let select_cpu_us = started_cpu.map_or(f64::NAN, |t| t.elapsed().as_secs_f64() * 1e6);

        // Wanted tiles already on the CPU go to the GPU; the rest to the loaders, unless the
        // camera is moving away from them.
        let (to_upload, mut to_load): (Vec<TileRequest>, Vec<TileRequest>) = self
            .selection
            .requests
            .iter()
            .partition(|r| self.layer.get(r.key).is_some());
        let last_eye = self.last_eye.replace(view.position);
        let requests_deferred = defer_requests_left_behind(
            &self.layer,
            view,
            last_eye,
            self.request_lookahead_frames,
            self.options.near_m,
            |key| {
                std::iter::successors(key.parent(), |k| k.parent())
                    .any(|k| self.layer.get(k).is_some())
            },
            &mut to_load,
        );
        let layer_stats = self.layer.update(&self.selection.draw, &to_load);
        for d in &self.selection.draw {
            let mut key = Some(d.key);
            while let Some(k) = key {
                pool.touch(k);
                key = k.parent();
            }
        }
        // Colours that arrived for tiles on screen first, then new tiles.
        let mut colours_pending = 0;
        for d in &self.selection.draw {
            if pool.resident(d.key).is_none_or(|r| r.own_colour) {
                continue;
            }
            match self.layer.colour(d.key) {
                Some(TileColour::Ready(c)) => {
                    if !pool.upload_colour(queue, d.key, c) {
                        colours_pending += 1;
                    }
                }
                Some(TileColour::Loading) => colours_pending += 1,
                Some(TileColour::Borrowed) | None => {}
            }
        }
        let mut pool_full = false;
        let mut evicted = Vec::new();
        let mut uploaded = Vec::new();
        for r in &to_upload {
            if !pool.can_upload() {
                break;
            }
            let (Some(data), Some(colour)) = (self.layer.get(r.key), self.layer.colour(r.key))
            else {
                continue;
            };
            let own = match colour {
                TileColour::Ready(c) => Some(c),
                TileColour::Loading | TileColour::Borrowed => None,
            };
            if own.is_none()
                && !colour_to_borrow(pool, queue, &self.layer, r.key, &mut evicted, &mut uploaded)
            {
                continue;
            }
            // The root may have taken the frame's last upload.
            if !pool.can_upload() {
                break;
            }
            if pool
                .upload(queue, r.key, &data.mesh, own, &mut evicted)
                .is_none()
            {
                pool_full = true;
                break;
            }
            uploaded.push(r.key);
        }
        for k in evicted {
            self.layer.set_drawable(k, false);
        }
        for k in uploaded {
            // A tile evicted after its own upload (to make room later this frame) is not
            // resident; ask the pool, not the list.
            self.layer.set_drawable(k, pool.is_resident(k));
        }
        let budget_bound = pool_full || layer_stats.over_budget;
        self.adapt_detail(budget_bound);

        let lighting = self
            .lighting
            .unwrap_or_else(|| Self::default_lighting(view, &ellipsoid));
        let tiles: Vec<TileKey> = self.selection.draw.iter().map(|d| d.key).collect();
        let draw = self.renderer.prepare(
            device,
            queue,
            &FrameInputs {
                view,
                near_m: self.options.near_m,
                eye_height_m: eye.height_m,
                eye_up: ellipsoid.geodetic_normal_from_lon_lat(eye.lon_rad, eye.lat_rad),
                planet_radius_m: ellipsoid.mean_radius(),
                lighting,
                tiles: &tiles,
            },
        );
        FrameReport {
            selection: self.selection.stats,
            select_us,
            select_cpu_us,
            wanted: self.selection.requests.len() as u32,
            layer: layer_stats,
            pool: self.renderer.pool.stats(),
            draw,
            sse_bound_px: self.options.max_sse_px,
            requests_deferred,
            colours_pending,
        }
    }

    /// When the GPU pool or the CPU cache cannot hold what the view needs, raise the error
    /// bound (less detail) instead of thrashing or growing; relax it again when there is
    /// room (unless [`Globe::relax_detail`] is off, as for offline frames, which must settle).
    fn adapt_detail(&mut self, budget_bound: bool) {
        let capacity = f64::from(self.renderer.pool.capacity());
        // Drawn tiles plus the ancestors selection walks through: about 4/3 of the drawn.
        let needed = self.selection.draw.len() as f64 * 4.0 / 3.0;
        let sse = &mut self.options.max_sse_px;
        if needed > capacity * 0.9 || budget_bound {
            *sse *= 1.25;
        } else if self.relax_detail && needed < capacity * 0.6 && *sse > self.configured_sse_px {
            *sse = (*sse / 1.1).max(self.configured_sse_px);
        }
    }

    /// Records the frame prepared by [`Globe::frame`].
    pub fn render(
        &self,
        encoder: &mut wgpu::CommandEncoder,
        colour: &wgpu::TextureView,
        depth: &wgpu::TextureView,
    ) {
        self.renderer.render(encoder, colour, depth);
    }

    /// Frames until everything the selection wants is loaded and resident (or `timeout`).
    /// Returns the last frame's report and whether it completed.
    pub fn load_completely(
        &mut self,
        device: &wgpu::Device,
        queue: &wgpu::Queue,
        view: &View,
        timeout: Duration,
    ) -> (FrameReport, bool) {
        let deadline = Instant::now() + timeout;
        self.renderer.pool.set_uploads_per_frame(u32::MAX);
        // Start from the configured bound and only raise it if budgets force it, so the same
        // view always settles on the same tiles.
        self.options.max_sse_px = self.configured_sse_px;
        self.relax_detail = false;
        let mut stalled = 0;
        loop {
            let sse_before = self.options.max_sse_px;
            let report = self.frame(device, queue, view);
            if report.wanted == 0 && report.colours_pending == 0 {
                return (report, true);
            }
            if Instant::now() > deadline {
                return (report, false);
            }
            let progress = report.pool.uploaded_this_frame > 0 || report.sse_bound_px != sse_before;
            // Wait for tiles only if nothing could be uploaded this frame.
            if !progress {
                let idle = self.layer.loading() == 0 && self.layer.colours_loading() == 0;
                if idle && report.layer.arrived == 0 && report.layer.colours_arrived == 0 {
                    stalled += 1;
                    if stalled > 3 {
                        return (report, false);
                    }
                }
                self.layer.wait_for_tiles(Duration::from_millis(200));
            } else {
                stalled = 0;
            }
        }
    }
}

/// Makes sure a tile about to be uploaded without its own colour has colour to borrow on the
/// GPU: the nearest ancestor's that is resident (kept for this frame), else the root's (loaded
/// with its colour and never evicted from the CPU cache), uploaded now and pushed to
/// `uploaded`. False if neither can be had this frame.
fn colour_to_borrow(
    pool: &mut TilePool,
    queue: &wgpu::Queue,
    layer: &TerrainLayer,
    key: TileKey,
    evicted: &mut Vec<TileKey>,
    uploaded: &mut Vec<TileKey>,
) -> bool {
    if let Some(source) = pool.colour_source(key) {
        pool.touch(source.from);
        return true;
    }
    let Some(root) = key.ancestor_at(0) else {
        return false;
    };
    let (Some(data), Some(TileColour::Ready(colour))) = (layer.get(root), layer.colour(root))
    else {
        return false;
    };
    let placed = if pool.is_resident(root) {
        pool.upload_colour(queue, root, colour)
    } else {
        pool.upload(queue, root, &data.mesh, Some(colour), evicted)
            .is_some()
    };
    if placed {
        uploaded.push(root);
    }
    placed
}

/// Bilinear height of a tile's grid at a longitude and latitude inside it.
fn sample_heights(tile: &globus_terrain::TerrainTile, lon_rad: f64, lat_rad: f64) -> f64 {
    let (u, v) = tile.rect.uv(lon_rad, lat_rad);
    let n = f64::from(MESH_SEGMENTS);
    let (x, y) = ((u * n).clamp(0.0, n), (v * n).clamp(0.0, n));
    let (i, j) = (
        (x.floor() as i32).min(MESH_SEGMENTS as i32 - 1),
        (y.floor() as i32).min(MESH_SEGMENTS as i32 - 1),
    );
    let (fx, fy) = (x - f64::from(i), y - f64::from(j));
    let h = |a: i32, b: i32| f64::from(tile.height_at(a, b));
    let top = h(i, j) * (1.0 - fx) + h(i + 1, j) * fx;
    let bottom = h(i, j + 1) * (1.0 - fx) + h(i + 1, j + 1) * fx;
    debug_assert!(HEIGHT_GRID_SIDE > MESH_SEGMENTS as usize);
    top * (1.0 - fy) + bottom * fy
}

/// A camera from the command-line convention: degrees, metres, heading clockwise from north,
/// pitch 0 at the horizon and -90 straight down.
#[derive(Clone, Copy, Debug, PartialEq)]
pub struct CameraSpec {
    /// Longitude, degrees.
    pub lon_deg: f64,
    /// Latitude, degrees.
    pub lat_deg: f64,
    /// Altitude, metres (above the ellipsoid, or above the ground if `above_ground`).
    pub alt_m: f64,
    /// Heading, degrees clockwise from north.
    pub heading_deg: f64,
    /// Pitch, degrees (0 horizon, -90 down).
    pub pitch_deg: f64,
    /// Whether `alt_m` is above the ground under the camera.
    pub above_ground: bool,
}

impl From<crate::path::Pose> for CameraSpec {
    /// A path's pose (altitude above the ellipsoid).
    fn from(p: crate::path::Pose) -> Self {
        Self {
            lon_deg: p.lon,
            lat_deg: p.lat,
            alt_m: p.alt,
            heading_deg: p.heading,
            pitch_deg: p.pitch,
            above_ground: false,
        }
    }
}

impl CameraSpec {
    /// The view for this camera on `globe`.
    pub fn view(&self, globe: &Globe, fov_y_deg: f64, width: u32, height: u32) -> View {
        let e = globe.ellipsoid();
        let (lon, lat) = (self.lon_deg.to_radians(), self.lat_deg.to_radians());
        let alt = if self.above_ground {
            globe.ground_height_m(lon, lat) + self.alt_m
        } else {
            self.alt_m
        };
        View::from_geodetic(
            &e,
            Cartographic::new(lon, lat, alt),
            self.heading_deg.to_radians(),
            self.pitch_deg.to_radians(),
            fov_y_deg.to_radians(),
            width,
            height,
        )
    }
}

/// Drops from `to_load` the tiles outside the view predicted `lookahead_frames` frames ahead
/// (same orientation, the eye moved on at its velocity since `last_eye`) whose place a loaded
/// ancestor can take meanwhile (`covered`), so no hole opens; returns how many.
fn defer_requests_left_behind(
    layer: &TerrainLayer,
    view: &View,
    last_eye: Option<DVec3>,
    lookahead_frames: f64,
    near_m: f64,
    covered: impl Fn(TileKey) -> bool,
    to_load: &mut Vec<TileRequest>,
) -> u32 {
    let Some(last) = last_eye else {
        return 0;
    };
    let step = view.position - last;
    if lookahead_frames <= 0.0 || step == DVec3::ZERO {
        return 0;
    }
    let mut ahead = *view;
    ahead.position += step * lookahead_frames;
    let frustum = Frustum::from_view(&ahead, near_m);
    let before = to_load.len();
    // The ancestor walk only for tiles the predicted view misses.
    to_load.retain(|r| {
        frustum.intersect_box(&layer.tile(r.key).bounds.obb) != Intersection::Outside
            || !covered(r.key)
    });
    (before - to_load.len()) as u32
}

#[cfg(test)]
mod tests {
    use super::*;

    /// A camera 10 km up looking north 30 degrees down, flying north at 20 km a frame: a
    /// wanted tile just inside the bottom of the view is left behind within three frames and
    /// not requested; one 100 km ahead is; nothing is dropped while the camera stands still
    /// or with the lookahead switched off.
    #[test]
    fn requests_the_camera_is_leaving_behind_are_deferred() {
        let source = Arc::new(ProceduralSource::new(DEFAULT_SEED, 16));
        let layer = TerrainLayer::new(source, TerrainLayerOptions::default());
        let ellipsoid = Ellipsoid::WGS84;
        let eye = Cartographic::from_degrees(10.0, 45.0, 10_000.0);
        let view = View::from_geodetic(
            &ellipsoid,
            eye,
            0.0,
            -30f64.to_radians(),
            60f64.to_radians(),
            960,
            540,
        );
        let north_by = |km: f64| -> TileKey {
            let lat = eye.lat_rad + km * 1000.0 / 6_371_000.0;
            TilingScheme::Geographic
                .tile_at(eye.lon_rad, lat, 12)
                .expect("tile")
        };
        let (behind, ahead) = (north_by(9.0), north_by(100.0));
        // Both are in today's view.
        let now = Frustum::from_view(&view, 1.0);
        for key in [behind, ahead] {
            assert_ne!(
                now.intersect_box(&layer.tile(key).bounds.obb),
                Intersection::Outside
            );
        }
        let request = |key| TileRequest { key, priority: 1.0 };
        let step = ellipsoid
            .cartographic_to_ecef(Cartographic::from_degrees(10.0, 45.18, 10_000.0))
            - view.position;
        let last_eye = Some(view.position - step);
        let covered = |_| true;
        let mut to_load = vec![request(behind), request(ahead)];
        let deferred =
            defer_requests_left_behind(&layer, &view, last_eye, 3.0, 1.0, covered, &mut to_load);
        assert_eq!(deferred, 1);
        assert_eq!(to_load.iter().map(|r| r.key).collect::<Vec<_>>(), [ahead]);
        // Standing still, lookahead off, first frame, or nothing loaded above the tile to
        // stand in for it: everything is requested.
        for (last, lookahead, covered) in [
            (Some(view.position), 3.0, true),
            (last_eye, 0.0, true),
            (None, 3.0, true),
            (last_eye, 3.0, false),
        ] {
            let mut to_load = vec![request(behind), request(ahead)];
            let deferred = defer_requests_left_behind(
                &layer,
                &view,
                last,
                lookahead,
                1.0,
                |_| covered,
                &mut to_load,
            );
            assert_eq!(deferred, 0);
            assert_eq!(to_load.len(), 2);
        }
    }
}
