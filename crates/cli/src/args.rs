//! The command line: every subcommand's arguments, and their translation into engine
//! options. Every bad argument ends with one line naming it.

use std::path::{Path, PathBuf};

use anyhow::{Context, bail};
use clap::{Args, Parser, Subcommand};
use globus_engine::{Atmosphere, CameraSpec, Ellipsoid, GlobeBuilder, SourceSpec};

use crate::config::{self, Config};
use crate::geo_cmd;
use crate::mesh_cmd::MeshArgs;
use crate::tile_cmd::{MergeArgs, TileArgs};

/// Default total memory budget of `globus view|render|bench`, MiB, when the config file
/// sizes no cache itself.
pub const DEFAULT_MEMORY_MB: u64 = 1024;

#[derive(Parser)]
#[command(
    name = "globus",
    version,
    about = "Globus: a planetary terrain and virtual-globe engine"
)]
pub struct Cli {
    #[command(subcommand)]
    pub command: Command,
}

#[derive(Subcommand)]
pub enum Command {
    /// Open a window on the planet (left drag pans, wheel zooms, right drag looks around,
    /// middle drag or Ctrl + left drag orbits the point under the cursor).
    View(ViewArgs),
    /// Render one complete frame offscreen to a PNG.
    Render(RenderArgs),
    /// Replay a camera path offscreen and print timing statistics as JSON.
    Bench(BenchArgs),
    /// Build elevation or imagery tile pyramids from rasters.
    Tile {
        #[command(subcommand)]
        command: TileCommand,
    },
    /// Air traffic: replay a record on the planet in a window (--record FILE), or make
    /// synthetic records and summarise any (subcommands).
    Traffic(crate::traffic_cmd::TrafficArgs),
    /// Build one tile's adaptive mesh from an elevation PNG, or describe a quantized-mesh file.
    Mesh(MeshArgs),
    /// Geodesy and tile naming conversions.
    Geo {
        #[command(subcommand)]
        command: GeoCommand,
    },
}

#[derive(Args, Clone)]
pub struct GlobeArgs {
    /// Screen-space error bound in pixels (default 2).
    #[arg(long)]
    pub sse: Option<f64>,
    /// Hold this frame rate: the error bound rises from --sse while frames are slower and
    /// falls back with headroom (the viewer's title and bench --path show it).
    #[arg(long = "target-fps", value_name = "FPS")]
    pub target_fps: Option<f64>,
    /// The coarsest error bound --target-fps may raise the bound to, pixels (default 4x --sse).
    #[arg(long = "sse-max", value_name = "PX")]
    pub sse_max: Option<f64>,
    /// An elevation layer: a `globus tile` directory, .mbtiles or .pmtiles file, a served
    /// directory URL, or an http(s) URL template with options after '#'
    /// (e.g. 'https://host/{z}/{x}/{y}.png#encoding=terrarium&maxzoom=15'). Repeatable;
    /// later layers lie on top.
    #[arg(long = "terrain")]
    pub terrain: Vec<String>,
    /// An imagery layer (same forms; WMS with '#wms_layers=NAME'). Repeatable; later layers
    /// are drawn over earlier ones.
    #[arg(long = "imagery")]
    pub imagery: Vec<String>,
    /// A TOML file naming sources, budgets, the error bound and HTTP settings.
    #[arg(long)]
    pub config: Option<PathBuf>,
    /// Keep tiles from services in this folder (2 GiB at most), so later sessions work offline.
    #[arg(long = "disk-cache")]
    pub disk_cache: Option<PathBuf>,
    /// Seed of the procedural planet (the default, 24, raises a mountain range where the
    /// Alps are on Earth).
    #[arg(long, default_value_t = globus_engine::DEFAULT_SEED)]
    pub seed: u64,
    /// Vertical field of view in degrees.
    #[arg(long = "fov-deg", default_value_t = 60.0)]
    pub fov_deg: f64,
    /// Orthographic top-down camera (an ATC screen): KM kilometres of ground from the top to
    /// the bottom of the frame, centred under the camera's LON,LAT with its heading (its
    /// altitude and pitch do not apply). The viewer's O key switches it on and off.
    #[arg(long = "ortho-km", allow_negative_numbers = true)]
    pub ortho_km: Option<f64>,
    /// Vertical error a tile's adaptive mesh may add, as a fraction of the tile's geometric
    /// error (0 draws every sample of the tile grid).
    #[arg(long = "mesh-error", default_value_t = globus_terrain::MeshOptions::default().error_fraction)]
    pub mesh_error: f64,
    /// Elevation exaggeration: draw heights this many times their value (terrain, bounds
    /// and culling follow; 1 is true heights).
    #[arg(long, allow_negative_numbers = true)]
    pub exaggeration: Option<f64>,
    /// Treat the planet's data as ending at this level and invent every deeper tile by
    /// procedural refinement (a stand-in for real data that ends, like 90 m SRTM).
    #[arg(long = "refine-below")]
    pub refine_below: Option<u8>,
    /// While the camera moves, do not request wanted tiles that will be out of view this many
    /// frames ahead at its current velocity (a drawn ancestor covers them meanwhile); 0
    /// requests every wanted tile (default 3).
    #[arg(long = "request-lookahead")]
    pub request_lookahead: Option<f64>,
    /// Memory budget in MiB for everything the globe holds (process, tile caches, decoded
    /// source tiles, GPU pools); the caches are sized from it (default 1024, unless the
    /// config file sizes them with cache_mb or gpu_tiles).
    #[arg(long = "memory-mb")]
    pub memory_mb: Option<u64>,
    /// Vector data to draw: a GeoJSON file (or RFC 8142 sequence, or a `traffic` airspace
    /// file) with style overrides after '#', e.g.
    /// 'countries.geojson#stroke=%23ffcc00&stroke-width=2' or 'firs.geojson#extrude=true'
    /// or 'airports.geojson#label={iata}' (keys: stroke, stroke-width, stroke-opacity,
    /// stroke-linejoin, stroke-linecap, stroke-dasharray, fill, fill-opacity, marker-color,
    /// marker-size, marker-symbol, marker-outline, marker-icon, label, label-size,
    /// label-color, extrude, lower, upper, units, clamp, path, wall, corridor,
    /// corridor-height). Repeatable.
    #[arg(long = "vector")]
    pub vector: Vec<String>,
    /// City lights on the night side, drawn where the Sun is down (see --time): an
    /// equirectangular image of the whole planet twice as wide as tall (a .jpg, .jpeg or .png
    /// file, e.g. ../shared/data/earth-night-4096x2048.jpg; wider than 8192 is scaled down),
    /// or an imagery pyramid in any form --imagery takes (e.g. that image tiled by `globus
    /// tile imagery`), read whole at start into one image at most 8192 wide.
    #[arg(long = "night-imagery")]
    pub night_imagery: Option<String>,
    /// The air: `earth` (Rayleigh and Mie scattering with ozone: the sky, haze over distant
    /// ground, reddened low sunlight) or `none` (black sky, no haze). Default: the Earth's.
    #[arg(long, value_parser = ["earth", "none"])]
    pub atmosphere: Option<String>,
    /// Load full detail where haze hides it (by default the error of distant tiles counts
    /// times the contrast the air lets through, as CesiumJS's fog does).
    #[arg(long)]
    pub no_fog: bool,
    /// Replace a tile by its children in one frame (by default they grow out of its surface
    /// and colour as they come into their level of detail: no popping).
    #[arg(long)]
    pub no_morph: bool,
    /// March the air between the eye and every ground pixel (the reference, slower) instead
    /// of reading the frame's aerial-perspective table.
    #[arg(long)]
    pub marched_haze: bool,
}

#[derive(Args)]
pub struct ViewArgs {
    /// Start camera: LON,LAT,ALT_M,HEADING_DEG,PITCH_DEG (default: the whole planet from
    /// 15,000 km over 30 N, on the afternoon side of the Sun of --time with the evening
    /// terminator in view, or over 10 E with `--time fixed`; for a replay, looking down on
    /// its aircraft).
    #[arg(long, allow_hyphen_values = true)]
    pub camera: Option<String>,
    /// ALT_M is above the ground under the camera, not above the ellipsoid.
    #[arg(long)]
    pub above_ground: bool,
    /// Window size, WxH.
    #[arg(long, default_value = "1280x720")]
    pub size: String,
    #[command(flatten)]
    pub globe: GlobeArgs,
    /// Close the window after this many seconds (for automated checks).
    #[arg(long)]
    pub exit_after: Option<f64>,
    /// Light the planet by the Sun of this moment, RFC 3339 (2026-06-21T12:00:00Z), Unix
    /// seconds or `now`; the Sun's clock then runs at real speed ([ and ] move it by an
    /// hour); default now. `fixed`: a fixed light from the south-west of the view instead.
    #[arg(long)]
    pub time: Option<String>,
}

#[derive(Args)]
pub struct RenderArgs {
    /// Camera: LON,LAT,ALT_M,HEADING_DEG,PITCH_DEG (heading clockwise from north, pitch 0 at
    /// the horizon and -90 straight down, ALT_M above the ellipsoid).
    #[arg(long, allow_hyphen_values = true)]
    pub camera: String,
    /// ALT_M is above the ground under the camera.
    #[arg(long)]
    pub above_ground: bool,
    /// Image size, WxH.
    #[arg(long)]
    pub size: String,
    /// Output PNG.
    #[arg(long)]
    pub out: PathBuf,
    /// Also write statistics as JSON here.
    #[arg(long)]
    pub stats: Option<PathBuf>,
    #[command(flatten)]
    pub globe: GlobeArgs,
    /// Give up waiting for tiles after this many seconds (at most a day).
    #[arg(long, default_value_t = 300.0, allow_negative_numbers = true)]
    pub timeout_s: f64,
    #[command(flatten)]
    pub traffic: TrafficSceneArgs,
}

/// Air traffic drawn in a rendered or benchmarked scene.
#[derive(Args, Clone, Default)]
pub struct TrafficSceneArgs {
    /// An air traffic record (OpenSky state-vector CSV, plain or gzip) whose aircraft are
    /// drawn at --time.
    #[arg(long)]
    pub traffic: Option<PathBuf>,
    /// The moment drawn, RFC 3339 (2018-08-01T12:00:00Z), Unix seconds or `now`: the Sun
    /// stands where it stood then (night where it had set), and --traffic's aircraft are
    /// where they were (default: the record's first moment with --traffic; without it, a
    /// fixed light from the south-west of the view).
    #[arg(long)]
    pub time: Option<String>,
    /// Draw one kind of aircraft with a glTF 2.0 binary model: KIND=FILE.glb, KIND one of
    /// light, narrowbody, widebody, helicopter (metres, +Y up, +Z forward; materials named
    /// "accent" take the aircraft's colour). Repeatable.
    #[arg(long = "model", requires = "traffic")]
    pub models: Vec<String>,
}

#[derive(Args)]
pub struct BenchArgs {
    /// Camera path JSON (see paths/alps-dive.json).
    #[arg(long, conflicts_with_all = ["from", "to", "soak", "traffic", "popping"], required_unless_present_any = ["from", "soak", "traffic", "popping"])]
    pub path: Option<PathBuf>,
    /// Popping benchmark: at this still camera (LON,LAT,ALT_M,HEADING_DEG,PITCH_DEG) lower the
    /// error bound from 8 px to 1 px over 120 completely loaded frames and report how much
    /// each frame changes from the one before.
    #[arg(long, allow_hyphen_values = true, conflicts_with_all = ["from", "to", "soak", "traffic"])]
    pub popping: Option<String>,
    /// With --popping: come straight down from the camera's height to a quarter of it over
    /// the 120 frames at the configured bound (--sse, default 2 px) instead.
    #[arg(long, requires = "popping")]
    pub descent: bool,
    /// With --popping: also write every frame to this folder as NNN.png (made if missing),
    /// to look at the sweep and at what changed between two frames.
    #[arg(long, requires = "popping")]
    pub frames_dir: Option<PathBuf>,
    /// Traffic benchmark: replay this record (OpenSky state-vector CSV, plain or gzip) from
    /// --time at --speed for --frames frames at --fps, with the camera still at --camera
    /// (default: over the aircraft), and report the cost of ticks, of the layer's frames and
    /// of whole frames with and without the traffic.
    #[arg(long, conflicts_with_all = ["from", "to", "soak"])]
    pub traffic: Option<PathBuf>,
    /// The moment whose Sun lights the frames (RFC 3339, Unix seconds or `now`; default: a
    /// fixed light from the south-west of the view); with --traffic, the first moment
    /// replayed (default: when the most aircraft are in the air), whose Sun lights them.
    #[arg(long)]
    pub time: Option<String>,
    /// Traffic benchmark: seconds of record per second of frames.
    #[arg(
        long,
        default_value_t = 1.0,
        requires = "traffic",
        allow_negative_numbers = true
    )]
    pub speed: f64,
    /// Traffic benchmark: frames replayed.
    #[arg(long, default_value_t = 300, requires = "traffic")]
    pub frames: u32,
    /// Traffic benchmark: LON,LAT,ALT_M,HEADING_DEG,PITCH_DEG (default: looking down on the
    /// aircraft).
    #[arg(long, allow_hyphen_values = true, requires = "traffic")]
    pub camera: Option<String>,
    /// Traffic benchmark: a glTF model for a kind, KIND=FILE.glb (see `globus render
    /// --help`). Repeatable.
    #[arg(long = "model", requires = "traffic")]
    pub models: Vec<String>,
    /// Soak test: fly between random views for this many seconds in real time, printing one
    /// JSON line per second (resident memory, cache bytes, GPU tiles, loads, failures).
    #[arg(long, conflicts_with_all = ["from", "to"])]
    pub soak: Option<f64>,
    /// Jump benchmark: load everything at this camera (LON,LAT,ALT_M,HEADING_DEG,PITCH_DEG),
    /// then jump to --to and time how the new view fills in.
    #[arg(long, allow_hyphen_values = true, requires = "to")]
    pub from: Option<String>,
    /// Where the jump goes.
    #[arg(long, allow_hyphen_values = true, requires = "from")]
    pub to: Option<String>,
    /// Frame size, WxH.
    #[arg(long, default_value = "1920x1080")]
    pub size: String,
    /// Frames per second of path time.
    #[arg(long, default_value_t = 30.0)]
    pub fps: f64,
    /// Play the path in real time (a frame waits for its moment, as in a viewer), instead of
    /// as fast as frames render, starting once the first view is loaded; for streaming
    /// figures, where loads race the camera.
    #[arg(long)]
    pub realtime: bool,
    /// Path benchmark only: also write every frame's figures (time, tiles drawn, nodes
    /// visited, error bound, tiles wanted, loads) to this CSV file, to see where a summary's
    /// medians come from.
    #[arg(long = "frames-csv", requires = "path")]
    pub frames_csv: Option<PathBuf>,
    /// Jump benchmark only: prepare every frame (selection, loads, uploads) but rasterise
    /// only the first, so software rendering does not take the cores the loaders need.
    #[arg(long = "no-draw")]
    pub no_draw: bool,
    #[command(flatten)]
    pub globe: GlobeArgs,
}

#[derive(Subcommand)]
pub enum TileCommand {
    /// Elevation: SRTM .hgt, GeoTIFF DEMs or greyscale images to RGB-encoded PNG tiles.
    Dem(TileArgs),
    /// Imagery: a GeoTIFF or a JPEG/PNG world image to JPEG, PNG or WebP tiles.
    Imagery(TileArgs),
    /// Split a job into shards of roughly equal work and print the plan as JSON.
    Plan {
        /// Number of shards.
        #[arg(long)]
        shards: u32,
        #[command(subcommand)]
        job: TileJobCommand,
    },
    /// Join shard outputs into one pyramid.
    Merge(MergeArgs),
}

#[derive(Subcommand)]
pub enum TileJobCommand {
    /// An elevation job (same options as `globus tile dem`).
    Dem(TileArgs),
    /// An imagery job (same options as `globus tile imagery`).
    Imagery(TileArgs),
}

#[derive(Subcommand)]
pub enum GeoCommand {
    /// Longitude, latitude (degrees) and height (m) to ECEF metres.
    #[command(allow_negative_numbers = true)]
    Ecef { lon: f64, lat: f64, height: f64 },
    /// ECEF metres to longitude, latitude and height.
    #[command(allow_negative_numbers = true)]
    Cartographic { x: f64, y: f64, z: f64 },
    /// The tile containing a point, with its names and bounds.
    Tile {
        /// geographic or webmercator.
        #[arg(long)]
        scheme: String,
        /// Longitude, degrees.
        #[arg(long, allow_negative_numbers = true)]
        lon: f64,
        /// Latitude, degrees.
        #[arg(long, allow_negative_numbers = true)]
        lat: f64,
        /// Zoom level.
        #[arg(long)]
        level: u8,
    },
    /// How steep the procedural planet is in a square window: the share of the area steeper
    /// than 30 degrees (and 20, 40), the highest and mean heights.
    Slopes {
        /// Centre longitude, degrees.
        #[arg(long, allow_negative_numbers = true)]
        lon: f64,
        /// Centre latitude, degrees.
        #[arg(long, allow_negative_numbers = true)]
        lat: f64,
        /// Width of the window, kilometres.
        #[arg(long = "window-km", default_value_t = 20.0)]
        window_km: f64,
        /// Sample spacing, metres.
        #[arg(long = "spacing-m", default_value_t = 30.0)]
        spacing_m: f64,
        /// Seed of the procedural planet.
        #[arg(long, default_value_t = globus_engine::DEFAULT_SEED)]
        seed: u64,
    },
}

/// The planet-wide view `globus view` starts from under a fixed light.
pub const DEFAULT_VIEW_CAMERA: &str = "10,30,15000000,0,-90";

/// How far east of the subsolar point (degrees) the default view looks down under the Sun of
/// a moment: the afternoon side, with the evening terminator and the first city lights
/// inside the planet's disc (its edge is about 72 degrees from the centre at 15,000 km).
const DEFAULT_VIEW_EAST_OF_SUN_DEG: f64 = 35.0;

/// The planet-wide view `globus view` starts from: over 30 N on the afternoon side of the Sun
/// of `sun_time` (Unix seconds), or [`DEFAULT_VIEW_CAMERA`] under a fixed light.
pub fn default_view_camera(sun_time: Option<f64>) -> String {
    match sun_time {
        Some(t) => {
            let (lon, _) = globus_geo::SunPosition::at(t).subsolar_lon_lat();
            let lon =
                (lon.to_degrees() + DEFAULT_VIEW_EAST_OF_SUN_DEG + 540.0).rem_euclid(360.0) - 180.0;
            format!("{lon:.3},30,15000000,0,-90")
        }
        None => DEFAULT_VIEW_CAMERA.to_owned(),
    }
}

impl ViewArgs {
    /// `--exit-after` as a duration (checked).
    pub fn exit_after(&self) -> anyhow::Result<Option<std::time::Duration>> {
        match self.exit_after {
            Some(s) if !(s > 0.0 && s.is_finite()) => {
                bail!("--exit-after {s} must be a positive number of seconds")
            }
            other => Ok(other.map(std::time::Duration::from_secs_f64)),
        }
    }
}

/// The vector layer of the config file's `[[vector]]` tables and the `--vector` arguments
/// (`None` without any): every file read, each bad feature a warning, a file that cannot be
/// read or is not GeoJSON an error. The config's `[vector_style]` gives every file's
/// defaults. Under the builder's memory budget, the layer may take a quarter of it in
/// positions read (counted in the globe's footprint when it is made) and a quarter in GPU
/// buffers (reserved in the builder's plan).
pub fn vector_layer(
    a: &GlobeArgs,
    builder: &mut GlobeBuilder,
) -> anyhow::Result<Option<globus_engine::VectorLayer>> {
    let config = a.config.as_deref().map(Config::load).transpose()?;
    let defaults = match &config {
        Some(c) => config::style_map(&c.vector_style, "vector_style")?,
        None => serde_json::Map::new(),
    };
    let from_config = config.as_ref().map_or(0, |c| c.vector.len());
    if a.vector.is_empty() && from_config == 0 {
        return Ok(None);
    }
    let mut layer = globus_engine::VectorLayer::new();
    if let Some(bytes) = builder.memory_budget_bytes() {
        layer.set_max_positions(globus_engine::VectorLayer::positions_for_bytes(bytes / 4));
        layer.set_gpu_budget(bytes / 4);
        builder.reserve_memory(bytes / 4);
    }
    if let (Some(c), Some(path)) = (&config, &a.config) {
        let base = path.parent().unwrap_or(Path::new("."));
        for (i, v) in c.vector.iter().enumerate() {
            let rules = globus_engine::StyleRules {
                overrides: config::style_map(&v.style, &format!("vector[{i}].style"))?,
                defaults: defaults.clone(),
            };
            let file = base.join(&v.file);
            let (loaded, ids) = layer
                .add_file(&file, &rules)
                .with_context(|| format!("{}: vector[{i}]", path.display()))?;
            tracing::info!(
                "{}: {} of {} features drawn ({} warnings)",
                file.display(),
                ids.len(),
                loaded.read,
                loaded.warning_count
            );
        }
    }
    for spec in &a.vector {
        // A file whose name holds '#' is taken whole when it exists.
        let (file, fragment) = match spec.rsplit_once('#') {
            Some((f, frag)) if !Path::new(spec).exists() => (f, frag),
            _ => (spec.as_str(), ""),
        };
        let mut rules = globus_engine::StyleRules::from_fragment(fragment)
            .map_err(|e| anyhow::anyhow!("--vector {spec}: {e}"))?;
        rules.defaults = defaults.clone();
        let (loaded, ids) = layer
            .add_file(Path::new(file), &rules)
            .with_context(|| format!("--vector {spec}"))?;
        tracing::info!(
            "{file}: {} of {} features drawn ({} warnings)",
            ids.len(),
            loaded.read,
            loaded.warning_count
        );
    }
    Ok(Some(layer))
}

/// Reads `--night-imagery`: an equirectangular image, scaled down to at most
/// [`NightLights::MAX_WIDTH`] wide.
fn night_lights(path: &std::path::Path) -> anyhow::Result<globus_engine::NightLights> {
    let image = image::ImageReader::open(path)
        .and_then(|r| r.with_guessed_format())
        .map_err(|e| anyhow::anyhow!("--night-imagery {}: {e}", path.display()))?
        .decode()
        .map_err(|e| anyhow::anyhow!("--night-imagery {}: {e}", path.display()))?;
    let max = globus_engine::NightLights::MAX_WIDTH;
    let image = if image.width() > max && image.width() == 2 * image.height() {
        image.resize_exact(max, max / 2, image::imageops::FilterType::Triangle)
    } else {
        image
    };
    let rgb = image.to_rgb8();
    globus_engine::NightLights::from_rgb(rgb.width(), rgb.height(), rgb.as_raw())
        .map_err(|e| anyhow::anyhow!("--night-imagery {}: {e}", path.display()))
}

/// The globe the arguments (and their config file) describe. Checks every value the
/// command line adds; the engine checks the rest when the globe is built.
pub fn globe_builder(a: &GlobeArgs) -> anyhow::Result<GlobeBuilder> {
    let mut builder = GlobeBuilder::new();
    let mut caches_sized = false;
    if let Some(path) = &a.config {
        let config = Config::load(path)?;
        config.apply(&mut builder);
        caches_sized = config.sizes_caches();
    }
    match a.memory_mb {
        Some(0) => bail!("--memory-mb must be above 0"),
        Some(_) if caches_sized => bail!(
            "--memory-mb sizes the tile cache and the GPU pools itself, but the config file \
             sizes them too (cache_mb or gpu_tiles)"
        ),
        Some(mb) => {
            builder.memory_budget(Some(mb.saturating_mul(1 << 20)));
        }
        None if !caches_sized && builder.memory_budget_bytes().is_none() => {
            builder.memory_budget(Some(DEFAULT_MEMORY_MB << 20));
        }
        None => {}
    }
    if let Some(sse) = a.sse {
        builder.max_sse_px(sse);
    }
    let sse = builder.error_bound_px();
    if !(globus_engine::MIN_SSE_PX..=1000.0).contains(&sse) {
        bail!("--sse {sse}: the error bound must be a pixel error from 0.1 to 1000");
    }
    if let Some(fps) = a.target_fps {
        builder.target_fps(Some(fps));
    }
    if let Some(px) = a.sse_max {
        builder.coarsest_sse_px(px);
    }
    if let Some(fps) = builder.target_frame_rate()
        && !(fps > 0.0 && fps <= 1000.0)
    {
        bail!("--target-fps {fps} must be above 0 and at most 1000 frames per second");
    }
    let coarsest = builder.coarsest_px();
    if !(sse..=1000.0).contains(&coarsest) {
        bail!("--sse-max {coarsest} must be from the error bound ({sse} px) to 1000 pixels");
    }
    if !(a.fov_deg > 0.5 && a.fov_deg < 170.0) {
        bail!(
            "--fov-deg {} must be between 0.5 and 170 degrees",
            a.fov_deg
        );
    }
    if let Some(km) = a.ortho_km
        && !(0.01..=40_000.0).contains(&km)
    {
        bail!("--ortho-km {km} must be from 0.01 to 40000 kilometres");
    }
    if !(0.0..=4.0).contains(&a.mesh_error) {
        bail!(
            "--mesh-error {} must be a fraction of the tile error from 0 to 4",
            a.mesh_error
        );
    }
    builder.mesh_error(a.mesh_error);
    if let Some(e) = a.exaggeration {
        if !(0.0..=1000.0).contains(&e) {
            bail!("--exaggeration {e} must be a factor from 0 to 1000");
        }
        builder.exaggeration(e);
    }
    for t in &a.terrain {
        builder.terrain(SourceSpec::parse(t).map_err(|e| anyhow::anyhow!("--terrain: {e}"))?);
    }
    match a.atmosphere.as_deref() {
        Some("none") => {
            builder.atmosphere(Some(Atmosphere::none(&Ellipsoid::WGS84)));
        }
        Some(_) => {
            builder.atmosphere(Some(Atmosphere::earth(&Ellipsoid::WGS84)));
        }
        None => {}
    }
    builder.fog(!a.no_fog);
    builder.morph(!a.no_morph);
    builder.marched_haze(a.marched_haze);
    if let Some(night) = &a.night_imagery {
        let is_image = std::path::Path::new(night)
            .extension()
            .and_then(|e| e.to_str())
            .is_some_and(|e| ["jpg", "jpeg", "png"].contains(&e.to_ascii_lowercase().as_str()));
        if is_image {
            let lights = night_lights(std::path::Path::new(night))?;
            builder.night_lights(Some(std::sync::Arc::new(lights)));
        } else {
            let spec =
                SourceSpec::parse(night).map_err(|e| anyhow::anyhow!("--night-imagery: {e}"))?;
            builder.night_imagery(Some(spec));
        }
    }
    for t in &a.imagery {
        builder.imagery(SourceSpec::parse(t).map_err(|e| anyhow::anyhow!("--imagery: {e}"))?);
    }
    if let Some(dir) = &a.disk_cache {
        builder.disk_cache(Some(config::disk_cache_options(
            dir,
            config::DEFAULT_DISK_CACHE_MB,
        )));
    }
    if builder.uses_real_data() && a.refine_below.is_some() {
        bail!("--refine-below cuts the procedural planet; real data is refined below its own end");
    }
    builder.seed(a.seed).refine_below(a.refine_below);
    if let Some(f) = a.request_lookahead {
        builder.request_lookahead_frames(f);
    }
    let lookahead = builder.lookahead_frames();
    if !(0.0..=1000.0).contains(&lookahead) {
        bail!("--request-lookahead {lookahead} must be a number of frames from 0 to 1000");
    }
    Ok(builder)
}

/// `WxH` in pixels.
pub fn parse_size(s: &str) -> anyhow::Result<(u32, u32)> {
    let (w, h) = s
        .split_once(['x', 'X'])
        .with_context(|| format!("--size {s:?} must look like 1920x1080"))?;
    let w: u32 = w
        .trim()
        .parse()
        .with_context(|| format!("--size {s:?}: width is not a whole number"))?;
    let h: u32 = h
        .trim()
        .parse()
        .with_context(|| format!("--size {s:?}: height is not a whole number"))?;
    if !(1..=16384).contains(&w) || !(1..=16384).contains(&h) {
        bail!("--size {s:?}: width and height must be 1 to 16384 pixels");
    }
    Ok((w, h))
}

/// The view of `camera` on `globe` with the field of view and projection of `a`
/// (orthographic top-down with --ortho-km).
pub fn camera_view(
    camera: &CameraSpec,
    globe: &globus_engine::Globe,
    a: &GlobeArgs,
    width: u32,
    height: u32,
) -> globus_engine::View {
    match a.ortho_km {
        Some(km) => camera.orthographic_view(globe, km * 1e3, a.fov_deg, width, height),
        None => camera.view(globe, a.fov_deg, width, height),
    }
}

/// `LON,LAT,ALT_M,HEADING_DEG,PITCH_DEG`.
pub fn parse_camera(s: &str, above_ground: bool) -> anyhow::Result<CameraSpec> {
    let parts: Vec<&str> = s.split(',').map(str::trim).collect();
    if parts.len() != 5 {
        bail!("--camera {s:?} must be LON,LAT,ALT_M,HEADING_DEG,PITCH_DEG (5 numbers)");
    }
    let mut v = [0.0; 5];
    for (i, (p, name)) in parts
        .iter()
        .zip(["LON", "LAT", "ALT_M", "HEADING_DEG", "PITCH_DEG"])
        .enumerate()
    {
        v[i] = p
            .parse::<f64>()
            .ok()
            .filter(|x| x.is_finite())
            .with_context(|| format!("--camera {s:?}: {name} {p:?} is not a number"))?;
    }
    let [lon, lat, alt, heading, pitch] = v;
    geo_cmd::check_lon_lat(lon, lat).with_context(|| format!("--camera {s:?}"))?;
    if !(-90.0..=90.0).contains(&pitch) {
        bail!("--camera {s:?}: pitch {pitch} is outside -90..90 degrees");
    }
    let min_alt = if above_ground { 0.01 } else { -500.0 };
    if !(min_alt..=1.0e9).contains(&alt) {
        bail!("--camera {s:?}: altitude {alt} m is outside {min_alt}..1e9 m");
    }
    Ok(CameraSpec {
        lon_deg: lon,
        lat_deg: lat,
        alt_m: alt,
        heading_deg: heading.rem_euclid(360.0),
        pitch_deg: pitch,
        above_ground,
    })
}

/// Fails early, with the path, if a file cannot be written there.
pub fn check_writable(path: &Path) -> anyhow::Result<()> {
    globus_tiling::files::check_writable(path)
        .with_context(|| format!("cannot write {}", path.display()))
}

#[cfg(test)]
mod tests {
    use super::*;

    /// The default view looks down on daylight with the Sun west of it (afternoon), at any
    /// moment of the year and day, the longitude wrapped into -180..180.
    #[test]
    fn default_view_is_on_the_afternoon_side() {
        let ellipsoid = globus_geo::Ellipsoid::WGS84;
        assert_eq!(default_view_camera(None), DEFAULT_VIEW_CAMERA);
        // 2026-12-05 09:13, 2026-06-21 00:00, 2027-03-20 15:30, 2026-09-23 21:00 UTC.
        for t in [
            1_796_461_980.0,
            1_782_000_000.0,
            1_805_556_600.0,
            1_790_197_200.0,
        ] {
            let text = default_view_camera(Some(t));
            let spec = parse_camera(&text, false).expect("the default camera parses");
            assert!((-180.0..180.0).contains(&spec.lon_deg), "{text}");
            let up = ellipsoid
                .geodetic_normal_from_lon_lat(spec.lon_deg.to_radians(), spec.lat_deg.to_radians());
            let east = globus_geo::DVec3::Z.cross(up).normalize();
            let sun = globus_geo::SunPosition::at(t).direction();
            let elevation = up.dot(sun).asin().to_degrees();
            assert!(elevation > 10.0, "{text}: the Sun is {elevation} deg high");
            assert!(east.dot(sun) < -0.2, "{text}: the Sun is not in the west");
        }
    }
}
