//! The `globus` binary. Every failure ends with one line on stderr and a non-zero exit.

use std::path::{Path, PathBuf};
use std::time::{Duration, Instant};

use anyhow::{Context, bail};
use clap::{Args, Parser, Subcommand};
use globus_app::config::Config;
use globus_app::engine::{CameraSpec, GlobeOptions};
use globus_app::geo_cmd;
use globus_app::mesh_cmd::{self, MeshArgs};
use globus_app::offscreen::{Offscreen, holes_inside, save_png};
use globus_app::path::CameraPath;
use globus_app::tile_cmd::{self, MergeArgs, TileArgs};
use globus_app::viewer::{self, ViewerOptions};
use globus_stream::open::SourceSpec;
use serde_json::json;

#[derive(Parser)]
#[command(
    name = "globus",
    version,
    about = "Globus: a planetary terrain and virtual-globe engine"
)]
struct Cli {
    #[command(subcommand)]
    command: Command,
}

#[derive(Subcommand)]
enum Command {
    /// Open a window on the planet (left drag rotates, wheel zooms, right drag tilts and turns).
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
    /// Build one tile's adaptive mesh from an elevation PNG, or describe a quantized-mesh file.
    Mesh(MeshArgs),
    /// Geodesy and tile naming conversions.
    Geo {
        #[command(subcommand)]
        command: GeoCommand,
    },
}

#[derive(Args, Clone)]
struct GlobeArgs {
    /// Screen-space error bound in pixels (default 2).
    #[arg(long)]
    sse: Option<f64>,
    /// An elevation layer: a `globus tile` directory, .mbtiles or .pmtiles file, a served
    /// directory URL, or an http(s) URL template with options after '#'
    /// (e.g. 'https://host/{z}/{x}/{y}.png#encoding=terrarium&maxzoom=15'). Repeatable;
    /// later layers lie on top.
    #[arg(long = "terrain")]
    terrain: Vec<String>,
    /// An imagery layer (same forms; WMS with '#wms_layers=NAME'). Repeatable; later layers
    /// are drawn over earlier ones.
    #[arg(long = "imagery")]
    imagery: Vec<String>,
    /// A TOML file naming sources, budgets, the error bound and HTTP settings.
    #[arg(long)]
    config: Option<PathBuf>,
    /// Keep tiles from services in this folder (2 GiB at most), so later sessions work offline.
    #[arg(long = "disk-cache")]
    disk_cache: Option<PathBuf>,
    /// Seed of the procedural planet (the default, 24, raises a mountain range where the
    /// Alps are on Earth).
    #[arg(long, default_value_t = globus_app::engine::DEFAULT_SEED)]
    seed: u64,
    /// Vertical field of view in degrees.
    #[arg(long = "fov-deg", default_value_t = 60.0)]
    fov_deg: f64,
    /// Vertical error a tile's adaptive mesh may add, as a fraction of the tile's geometric
    /// error (0 draws every sample of the tile grid).
    #[arg(long = "mesh-error", default_value_t = globus_terrain::MeshOptions::default().error_fraction)]
    mesh_error: f64,
    /// Treat the planet's data as ending at this level and invent every deeper tile by
    /// procedural refinement (a stand-in for real data that ends, like 90 m SRTM).
    #[arg(long = "refine-below")]
    refine_below: Option<u8>,
    /// While the camera moves, do not request wanted tiles that will be out of view this many
    /// frames ahead at its current velocity (a drawn ancestor covers them meanwhile); 0
    /// requests every wanted tile (default 3).
    #[arg(long = "request-lookahead")]
    request_lookahead: Option<f64>,
    /// Memory budget in MiB for everything the globe holds (process, tile caches, decoded
    /// source tiles, GPU pools); the caches are sized from it (default 1024, unless the
    /// config file sizes them with cache_mb or gpu_tiles).
    #[arg(long = "memory-mb")]
    memory_mb: Option<u64>,
}

#[derive(Args)]
struct ViewArgs {
    /// Start camera: LON,LAT,ALT_M,HEADING_DEG,PITCH_DEG.
    #[arg(
        long,
        allow_hyphen_values = true,
        default_value = "10,30,15000000,0,-90"
    )]
    camera: String,
    /// ALT_M is above the ground under the camera, not above the ellipsoid.
    #[arg(long)]
    above_ground: bool,
    /// Window size, WxH.
    #[arg(long, default_value = "1280x720")]
    size: String,
    #[command(flatten)]
    globe: GlobeArgs,
    /// Close the window after this many seconds (for automated checks).
    #[arg(long)]
    exit_after: Option<f64>,
}

#[derive(Args)]
struct RenderArgs {
    /// Camera: LON,LAT,ALT_M,HEADING_DEG,PITCH_DEG (heading clockwise from north, pitch 0 at
    /// the horizon and -90 straight down, ALT_M above the ellipsoid).
    #[arg(long, allow_hyphen_values = true)]
    camera: String,
    /// ALT_M is above the ground under the camera.
    #[arg(long)]
    above_ground: bool,
    /// Image size, WxH.
    #[arg(long)]
    size: String,
    /// Output PNG.
    #[arg(long)]
    out: PathBuf,
    /// Also write statistics as JSON here.
    #[arg(long)]
    stats: Option<PathBuf>,
    #[command(flatten)]
    globe: GlobeArgs,
    /// Give up waiting for tiles after this many seconds.
    #[arg(long, default_value_t = 300.0)]
    timeout_s: f64,
}

#[derive(Args)]
struct BenchArgs {
    /// Camera path JSON (see paths/alps-dive.json).
    #[arg(long, conflicts_with_all = ["from", "to", "soak"], required_unless_present_any = ["from", "soak"])]
    path: Option<PathBuf>,
    /// Soak test: fly between random views for this many seconds in real time, printing one
    /// JSON line per second (resident memory, cache bytes, GPU tiles, loads, failures).
    #[arg(long, conflicts_with_all = ["from", "to"])]
    soak: Option<f64>,
    /// Jump benchmark: load everything at this camera (LON,LAT,ALT_M,HEADING_DEG,PITCH_DEG),
    /// then jump to --to and time how the new view fills in.
    #[arg(long, allow_hyphen_values = true, requires = "to")]
    from: Option<String>,
    /// Where the jump goes.
    #[arg(long, allow_hyphen_values = true, requires = "from")]
    to: Option<String>,
    /// Frame size, WxH.
    #[arg(long, default_value = "1920x1080")]
    size: String,
    /// Frames per second of path time.
    #[arg(long, default_value_t = 30.0)]
    fps: f64,
    /// Play the path in real time (a frame waits for its moment, as in a viewer), instead of
    /// as fast as frames render, starting once the first view is loaded; for streaming
    /// figures, where loads race the camera.
    #[arg(long)]
    realtime: bool,
    /// Jump benchmark only: prepare every frame (selection, loads, uploads) but rasterise
    /// only the first, so software rendering does not take the cores the loaders need.
    #[arg(long = "no-draw")]
    no_draw: bool,
    #[command(flatten)]
    globe: GlobeArgs,
}

#[derive(Subcommand)]
enum TileCommand {
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
enum TileJobCommand {
    /// An elevation job (same options as `globus tile dem`).
    Dem(TileArgs),
    /// An imagery job (same options as `globus tile imagery`).
    Imagery(TileArgs),
}

#[derive(Subcommand)]
enum GeoCommand {
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
}

/// Makes glibc's malloc give freed tiles back to the system: a thread calls `malloc_trim`
/// once a second. By default the mmap threshold rises to 32 MiB after the first large block is
/// freed; from then on tiles (64 KiB to a few MiB) come from up to eight heaps per core, whose
/// freed pages stay resident, and the process's memory creeps past its budget (a 4-minute
/// soak at 512 MiB: 523 MiB resident with nothing done, median 401 MiB trimming). Pinning the
/// mmap threshold at 64 KiB instead held memory as well, but every large block was then
/// mapped afresh: a jump rendering every frame on lavapipe took 7.67 s instead of 6.89 s.
#[cfg(all(target_os = "linux", target_env = "gnu"))]
#[allow(unsafe_code)]
fn tune_allocator() {
    let _ = std::thread::Builder::new()
        .name("malloc-trim".into())
        .spawn(|| {
            loop {
                std::thread::sleep(std::time::Duration::from_secs(1));
                // SAFETY: malloc_trim takes malloc's own locks and only releases free pages.
                unsafe {
                    libc::malloc_trim(0);
                }
            }
        });
}

#[cfg(not(all(target_os = "linux", target_env = "gnu")))]
fn tune_allocator() {}

fn main() {
    tune_allocator();
    let cli = match Cli::try_parse() {
        Ok(cli) => cli,
        Err(e) => {
            use clap::error::ErrorKind;
            if matches!(
                e.kind(),
                ErrorKind::DisplayHelp
                    | ErrorKind::DisplayVersion
                    | ErrorKind::DisplayHelpOnMissingArgumentOrSubcommand
            ) {
                let _ = e.print();
                std::process::exit(
                    if e.kind() == ErrorKind::DisplayHelpOnMissingArgumentOrSubcommand {
                        2
                    } else {
                        0
                    },
                );
            }
            let text = e.to_string();
            let first = text.lines().next().unwrap_or("invalid arguments");
            eprintln!(
                "globus: {} (see globus --help)",
                first.trim_start_matches("error: ")
            );
            std::process::exit(2);
        }
    };
    if let Err(e) = run(cli) {
        eprintln!("globus: error: {e:#}");
        std::process::exit(1);
    }
}

fn run(cli: Cli) -> anyhow::Result<()> {
    match cli.command {
        Command::View(a) => view(a),
        Command::Render(a) => render(a),
        Command::Bench(a) => bench(a),
        Command::Tile { command } => {
            let line = match command {
                TileCommand::Dem(a) => tile_cmd::run("dem", &a)?,
                TileCommand::Imagery(a) => tile_cmd::run("imagery", &a)?,
                TileCommand::Plan { shards, job } => match job {
                    TileJobCommand::Dem(a) => tile_cmd::plan(shards, "dem", &a)?,
                    TileJobCommand::Imagery(a) => tile_cmd::plan(shards, "imagery", &a)?,
                },
                TileCommand::Merge(a) => tile_cmd::merge(&a)?,
            };
            println!("{line}");
            Ok(())
        }
        Command::Mesh(args) => {
            let report = mesh_cmd::run(&args)?;
            if args.json {
                println!("{report}");
            } else {
                println!("{}", mesh_cmd::summary_line(&report));
            }
            Ok(())
        }
        Command::Geo { command } => {
            let out = match command {
                GeoCommand::Ecef { lon, lat, height } => geo_cmd::ecef(lon, lat, height)?,
                GeoCommand::Cartographic { x, y, z } => geo_cmd::cartographic(x, y, z)?,
                GeoCommand::Tile {
                    scheme,
                    lon,
                    lat,
                    level,
                } => geo_cmd::tile(&scheme, lon, lat, level)?,
            };
            println!("{out}");
            Ok(())
        }
    }
}

fn globe_options(a: &GlobeArgs) -> anyhow::Result<GlobeOptions> {
    let mut options = GlobeOptions::default();
    let mut caches_sized = false;
    if let Some(path) = &a.config {
        let config = Config::load(path)?;
        config.apply(&mut options);
        caches_sized = config.sizes_caches();
    }
    match a.memory_mb {
        Some(0) => bail!("--memory-mb must be above 0"),
        Some(_) if caches_sized => bail!(
            "--memory-mb sizes the tile cache and the GPU pools itself, but the config file \
             sizes them too (cache_mb or gpu_tiles)"
        ),
        Some(mb) => options.memory_bytes = Some(mb << 20),
        None if !caches_sized && options.memory_bytes.is_none() => {
            options.memory_bytes = Some(globus_app::memory::DEFAULT_MEMORY_MB << 20);
        }
        None => {}
    }
    if let Some(sse) = a.sse {
        options.max_sse_px = sse;
    }
    if !(options.max_sse_px > 0.0 && options.max_sse_px <= 1000.0) {
        bail!(
            "--sse {} must be a pixel error above 0 and at most 1000",
            options.max_sse_px
        );
    }
    if !(a.fov_deg > 0.5 && a.fov_deg < 170.0) {
        bail!(
            "--fov-deg {} must be between 0.5 and 170 degrees",
            a.fov_deg
        );
    }
    if !(0.0..=4.0).contains(&a.mesh_error) {
        bail!(
            "--mesh-error {} must be a fraction of the tile error from 0 to 4",
            a.mesh_error
        );
    }
    for t in &a.terrain {
        options
            .terrain
            .push(SourceSpec::parse(t).map_err(|e| anyhow::anyhow!("--terrain: {e}"))?);
    }
    for t in &a.imagery {
        options
            .imagery
            .push(SourceSpec::parse(t).map_err(|e| anyhow::anyhow!("--imagery: {e}"))?);
    }
    if let Some(dir) = &a.disk_cache {
        options.disk_cache = Some(globus_app::config::disk_cache_options(
            dir,
            globus_app::config::DEFAULT_DISK_CACHE_MB,
        ));
    }
    if options.uses_real_data() && a.refine_below.is_some() {
        bail!("--refine-below cuts the procedural planet; real data is refined below its own end");
    }
    options.seed = a.seed;
    options.mesh = globus_terrain::MeshOptions {
        error_fraction: a.mesh_error,
    };
    options.refine_below = a.refine_below;
    if let Some(f) = a.request_lookahead {
        options.request_lookahead_frames = f;
    }
    let lookahead = options.request_lookahead_frames;
    if !(0.0..=1000.0).contains(&lookahead) {
        bail!("--request-lookahead {lookahead} must be a number of frames from 0 to 1000");
    }
    Ok(options)
}

fn parse_size(s: &str) -> anyhow::Result<(u32, u32)> {
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

fn parse_camera(s: &str, above_ground: bool) -> anyhow::Result<CameraSpec> {
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
fn check_writable(path: &Path) -> anyhow::Result<()> {
    std::fs::OpenOptions::new()
        .create(true)
        .append(true)
        .open(path)
        .map(drop)
        .with_context(|| format!("cannot write {}", path.display()))
}

fn view(a: ViewArgs) -> anyhow::Result<()> {
    let (width, height) = parse_size(&a.size)?;
    let camera = parse_camera(&a.camera, a.above_ground)?;
    let globe = globe_options(&a.globe)?;
    if let Some(s) = a.exit_after
        && !(s > 0.0 && s.is_finite())
    {
        bail!("--exit-after {s} must be a positive number of seconds");
    }
    viewer::run(ViewerOptions {
        globe,
        camera,
        fov_deg: a.globe.fov_deg,
        width,
        height,
        exit_after: a.exit_after.map(Duration::from_secs_f64),
    })
}

fn render(a: RenderArgs) -> anyhow::Result<()> {
    let (width, height) = parse_size(&a.size)?;
    let camera = parse_camera(&a.camera, a.above_ground)?;
    let options = globe_options(&a.globe)?;
    check_writable(&a.out)?;
    if let Some(s) = &a.stats {
        check_writable(s)?;
    }
    let mut off = Offscreen::new(&options, width, height)?;
    let timeout = Duration::from_secs_f64(a.timeout_s.max(0.0));
    let mut view = camera.view(&off.globe, a.globe.fov_deg, width, height);
    let mut frame = off.render_complete(&view, timeout)?;
    // Above the ground of streamed data: the ground is known once the tiles under the
    // camera have loaded, so place the camera again and finish the picture from there.
    for _ in 0..3 {
        let placed = camera.view(&off.globe, a.globe.fov_deg, width, height);
        if !camera.above_ground || (placed.position - view.position).length() < 0.1 {
            break;
        }
        view = placed;
        frame = off.render_complete(&view, timeout)?;
    }
    if !frame.complete {
        eprintln!(
            "globus: warning: gave up waiting for tiles after {:.1} s; the picture is coarser than the SSE bound asks",
            frame.load_ms / 1e3
        );
    }
    save_png(&frame.image, &a.out)?;
    if let Some(path) = &a.stats {
        let r = &frame.report;
        let s = &r.selection;
        let per_slot = r.pool.gpu_bytes / u64::from(r.pool.capacity.max(1));
        let stats = json!({
            "tiles_rendered": r.draw.tiles,
            "nodes_visited": s.nodes_visited,
            "culled_frustum": s.culled_frustum,
            "culled_horizon": s.culled_horizon,
            "max_level": s.max_level,
            "max_sse_px": s.max_sse_px,
            "sse_bound_px": r.sse_bound_px,
            "triangles": r.draw.triangles,
            "draw_calls": r.draw.draw_calls,
            "select_us": r.select_us,
            "select_cpu_us": r.select_cpu_us,
            "load_ms": frame.load_ms,
            "complete": frame.complete,
            "tiles_loaded": off.globe.layer().scheduler_stats().loaded,
            "gpu_tile_bytes": per_slot * u64::from(r.pool.resident),
            "gpu_pool_bytes": r.pool.gpu_bytes,
            "adapter": off.ctx.adapter_description(),
            "camera": {"lon": camera.lon_deg, "lat": camera.lat_deg, "alt_m": view_altitude(&off, &view),
                        "heading": camera.heading_deg, "pitch": camera.pitch_deg},
            "size": [width, height],
        });
        std::fs::write(path, serde_json::to_string_pretty(&stats)? + "\n")
            .with_context(|| format!("cannot write {}", path.display()))?;
    }
    Ok(())
}

fn view_altitude(off: &Offscreen, view: &globus_geo::View) -> f64 {
    off.globe
        .ellipsoid()
        .ecef_to_cartographic(view.position)
        .map_or(f64::NAN, |c| c.height_m)
}

fn bench(a: BenchArgs) -> anyhow::Result<()> {
    let (width, height) = parse_size(&a.size)?;
    let options = globe_options(&a.globe)?;
    if !(a.fps > 0.0 && a.fps <= 1000.0) {
        bail!("--fps {} must be above 0 and at most 1000", a.fps);
    }
    if let (Some(from), Some(to)) = (&a.from, &a.to) {
        return bench_jump(&a, &options, from, to, width, height);
    }
    if let Some(seconds) = a.soak {
        if !(seconds > 0.0 && seconds.is_finite()) {
            bail!("--soak {seconds} must be a positive number of seconds");
        }
        return bench_soak(&a, &options, seconds, width, height);
    }
    let Some(path_file) = &a.path else {
        bail!("bench needs --path FILE.json, or --from CAMERA --to CAMERA");
    };
    let text = std::fs::read_to_string(path_file)
        .with_context(|| format!("cannot read {}", path_file.display()))?;
    let mut off = Offscreen::new(&options, width, height)?;
    let sse_px = options.max_sse_px;
    let origin = path_file.display().to_string();
    if options.uses_real_data() {
        // Streamed data knows its ground only once tiles are loaded: load the ground under
        // every keyframe given above the ground (from 15 km up, looking down) first.
        let points = std::cell::RefCell::new(Vec::new());
        CameraPath::parse(&text, &origin, |lon, lat| {
            points.borrow_mut().push((lon, lat));
            0.0
        })?;
        for (lon, lat) in points.into_inner() {
            let look_down = parse_camera(&format!("{lon},{lat},15000,0,-90"), false)?;
            let view = look_down.view(&off.globe, a.globe.fov_deg, width, height);
            off.render_complete(&view, Duration::from_secs(120))?;
        }
    }
    let path = {
        let globe = &off.globe;
        CameraPath::parse(&text, &origin, |lon, lat| {
            globe.ground_height_m(lon.to_radians(), lat.to_radians())
        })?
    };
    if a.realtime {
        // A viewer opens on its start view and shows it complete before the flight starts:
        // load it first, so the flight is not timed from a cold start (pipeline compilation
        // and the first tiles take the first second).
        let start = CameraSpec::from(path.pose(0.0));
        let view = start.view(&off.globe, a.globe.fov_deg, width, height);
        off.render_complete(&view, Duration::from_secs(120))?;
    }
    // Counting starts with the path.
    off.globe.layer_mut().track_usage();
    let frames = (path.duration() * a.fps).floor() as usize + 1;
    let mut samples: Vec<[f64; 9]> = Vec::with_capacity(frames);
    let mut deferred = 0u64;
    let clock = Instant::now();
    for i in 0..frames {
        let t = i as f64 / a.fps;
        if a.realtime {
            let ahead = t - clock.elapsed().as_secs_f64();
            if ahead > 0.0 {
                std::thread::sleep(Duration::from_secs_f64(ahead));
            }
        }
        let camera = CameraSpec::from(path.pose(t));
        let view = camera.view(&off.globe, a.globe.fov_deg, width, height);
        let started = Instant::now();
        let r = off.globe.frame(&off.ctx.device, &off.ctx.queue, &view);
        off.draw();
        let frame_ms = started.elapsed().as_secs_f64() * 1e3;
        samples.push([
            r.select_us,
            frame_ms,
            f64::from(r.draw.tiles),
            f64::from(r.selection.nodes_visited),
            f64::from(r.draw.draw_calls),
            r.draw.triangles as f64,
            r.select_cpu_us,
            f64::from(r.wanted),
            f64::from(r.colours_pending),
        ]);
        deferred += u64::from(r.requests_deferred);
    }
    let names = [
        "select_us",
        "frame_ms",
        "tiles_rendered",
        "nodes_visited",
        "draw_calls",
        "triangles",
        "select_cpu_us",
        "tiles_wanted_not_drawable",
        "tiles_showing_ancestor_imagery",
    ];
    let mut summary = serde_json::Map::new();
    let complete = samples
        .iter()
        .filter(|s| s[7] == 0.0 && s[8] == 0.0)
        .count();
    summary.insert(
        "complete_frames_fraction".into(),
        json!(complete as f64 / frames.max(1) as f64),
    );
    summary.insert("requests_deferred_while_moving".into(), json!(deferred));
    summary.insert("frames".into(), json!(frames));
    summary.insert("size".into(), json!([width, height]));
    summary.insert("sse_px".into(), json!(sse_px));
    summary.insert("realtime".into(), json!(a.realtime));
    summary.insert("wall_s".into(), json!(clock.elapsed().as_secs_f64()));
    summary.insert("mesh_error".into(), json!(a.globe.mesh_error));
    for (k, name) in names.iter().enumerate() {
        let mut v: Vec<f64> = samples.iter().map(|s| s[k]).collect();
        v.sort_by(f64::total_cmp);
        let q = |p: f64| v[((v.len() - 1) as f64 * p).round() as usize];
        summary.insert(
            (*name).into(),
            json!({"median": q(0.5), "p95": q(0.95), "max": q(1.0)}),
        );
    }
    let mut per_tile: Vec<f64> = samples
        .iter()
        .filter(|s| s[2] > 0.0)
        .map(|s| s[3] / s[2])
        .collect();
    per_tile.sort_by(f64::total_cmp);
    if !per_tile.is_empty() {
        let q = |p: f64| per_tile[((per_tile.len() - 1) as f64 * p).round() as usize];
        summary.insert(
            "nodes_visited_per_tile".into(),
            json!({"median": q(0.5), "p95": q(0.95), "max": q(1.0)}),
        );
    }
    let st = off.globe.layer().scheduler_stats();
    summary.insert("tiles_requested".into(), json!(st.requested));
    summary.insert("tiles_loaded".into(), json!(st.loaded));
    summary.insert("requests_cancelled".into(), json!(st.cancelled));
    summary.insert(
        "loads_stopped_in_flight".into(),
        json!(st.cancelled_in_flight),
    );
    summary.insert("retries".into(), json!(st.retries));
    summary.insert("tiles_failed".into(), json!(st.failed));
    let cs = off.globe.layer().colour_scheduler_stats();
    summary.insert("imagery_requested".into(), json!(cs.requested));
    summary.insert("imagery_loaded".into(), json!(cs.loaded));
    summary.insert(
        "imagery_stopped_in_flight".into(),
        json!(cs.cancelled_in_flight),
    );
    if let Some(u) = off.globe.layer().usage() {
        summary.insert("loaded_never_drawn".into(), json!(u.loaded_never_drawn));
        summary.insert(
            "loaded_never_drawn_fraction".into(),
            json!(u.loaded_never_drawn as f64 / u.loaded.max(1) as f64),
        );
        summary.insert("fetched".into(), json!(u.fetched));
        summary.insert("fetched_never_drawn".into(), json!(u.fetched_never_drawn));
        summary.insert(
            "fetched_never_drawn_fraction".into(),
            json!(u.fetched_never_drawn as f64 / u.fetched.max(1) as f64),
        );
        summary.insert(
            "loaded_again_while_cached".into(),
            json!(u.loaded_again_while_cached),
        );
        summary.insert(
            "loaded_again_after_eviction".into(),
            json!(u.loaded_again_after_eviction),
        );
    }
    summary.insert("adapter".into(), json!(off.ctx.adapter_description()));
    println!("{}", serde_json::Value::Object(summary));
    Ok(())
}

/// The jump benchmark: everything loaded at one view, then a jump to another; reports when
/// the first frame of the new view is out (and whether it has holes), when every tile its
/// selection wants is loaded and resident (`geometry_loaded_ms`), and when every drawn tile
/// shows its own imagery too (`all_loaded_ms`).
fn bench_jump(
    a: &BenchArgs,
    options: &GlobeOptions,
    from: &str,
    to: &str,
    width: u32,
    height: u32,
) -> anyhow::Result<()> {
    let from = parse_camera(from, false).context("--from")?;
    let to = parse_camera(to, false).context("--to")?;
    let mut off = Offscreen::new(options, width, height)?;
    off.globe.layer_mut().track_usage();
    let view_a = from.view(&off.globe, a.globe.fov_deg, width, height);
    let settled = off.render_complete(&view_a, Duration::from_secs(300))?;
    if !settled.complete {
        bail!("the first view did not finish loading in 300 s");
    }
    let before = off.globe.layer().scheduler_stats();
    let colours_before = off.globe.layer().colour_scheduler_stats();
    let view_b = to.view(&off.globe, a.globe.fov_deg, width, height);
    off.globe.relax_detail = false;
    let started = Instant::now();
    let mut first_frame_ms = f64::NAN;
    let mut first_frame_holes = (0u32, 0u32);
    let mut all_loaded_ms = None;
    let mut geometry_loaded_ms = None;
    let mut frames = 0u32;
    let mut last = None;
    while started.elapsed() < Duration::from_secs(120) {
        let report = off.globe.frame(&off.ctx.device, &off.ctx.queue, &view_b);
        frames += 1;
        if frames == 1 {
            let image = off.draw_and_read()?;
            first_frame_ms = started.elapsed().as_secs_f64() * 1e3;
            first_frame_holes =
                holes_inside(&image, &view_b, &off.globe.ellipsoid().grown(-16_000.0));
        } else if !a.no_draw {
            off.draw();
        } else {
            // Uploads still reach the GPU.
            off.ctx.queue.submit([]);
        }
        if report.wanted == 0 && geometry_loaded_ms.is_none() {
            geometry_loaded_ms = Some(started.elapsed().as_secs_f64() * 1e3);
        }
        let done = report.wanted == 0 && report.colours_pending == 0;
        last = Some(report);
        if done {
            all_loaded_ms = Some(started.elapsed().as_secs_f64() * 1e3);
            break;
        }
    }
    let after = off.globe.layer().scheduler_stats();
    let colours_after = off.globe.layer().colour_scheduler_stats();
    let e = off.globe.ellipsoid();
    let c = |cam: &CameraSpec| {
        globus_geo::Cartographic::new(cam.lon_deg.to_radians(), cam.lat_deg.to_radians(), 0.0)
    };
    let last = last.context("no frame ran")?;
    let out = json!({
        "jump_km": e.great_circle_distance(c(&from), c(&to)) / 1e3,
        "size": [width, height],
        "first_frame_ms": first_frame_ms,
        "first_frame_pixels_on_planet": first_frame_holes.0,
        "first_frame_holes": first_frame_holes.1,
        "all_loaded_ms": all_loaded_ms,
        "geometry_loaded_ms": geometry_loaded_ms,
        "frames": frames,
        "tiles_drawn": last.draw.tiles,
        "max_level": last.selection.max_level,
        "tiles_requested": after.requested - before.requested,
        "tiles_loaded": after.loaded - before.loaded,
        "imagery_loaded": colours_after.loaded - colours_before.loaded,
        "retries": after.retries - before.retries,
        "tiles_failed": after.failed - before.failed,
        "per_host": options.http.per_host,
        "frames_drawn": !a.no_draw,
        "adapter": off.ctx.adapter_description(),
    });
    println!("{out}");
    Ok(())
}

/// Bytes as MiB for reports (NaN when unknown).
fn mib(bytes: Option<u64>) -> f64 {
    bytes.map_or(f64::NAN, |b| b as f64 / 1048576.0)
}

/// The soak test: random flights between random views, in real time at 10 frames per second.
fn bench_soak(
    a: &BenchArgs,
    options: &GlobeOptions,
    seconds: f64,
    width: u32,
    height: u32,
) -> anyhow::Result<()> {
    let mut off = Offscreen::new(options, width, height)?;
    let mut state = 0x2545_F491_4F6C_DD1Du64;
    let mut uniform = move || {
        state ^= state << 13;
        state ^= state >> 7;
        state ^= state << 17;
        (state >> 11) as f64 / (1u64 << 53) as f64
    };
    let mut random_pose = || {
        let alt = (300f64.ln() + uniform() * (8.0e6f64.ln() - 300f64.ln())).exp();
        CameraSpec {
            lon_deg: uniform() * 360.0 - 180.0,
            lat_deg: (uniform() * 2.0 - 1.0)
                .asin()
                .to_degrees()
                .clamp(-80.0, 80.0),
            alt_m: alt,
            heading_deg: uniform() * 360.0,
            pitch_deg: if alt > 500_000.0 {
                -90.0
            } else {
                -90.0 + uniform() * 80.0
            },
            above_ground: true,
        }
    };
    const LEG_S: f64 = 4.0;
    let (mut from, mut to) = (random_pose(), random_pose());
    let started = Instant::now();
    let (mut leg_start, mut next_sample, mut frame) = (0.0, 0.0, 0u64);
    let mut max_rss: f64 = 0.0;
    loop {
        let t = started.elapsed().as_secs_f64();
        if t > seconds {
            break;
        }
        if t - leg_start >= LEG_S {
            from = to;
            to = random_pose();
            leg_start = t;
        }
        let f = ((t - leg_start) / LEG_S).clamp(0.0, 1.0);
        let s = f * f * (3.0 - 2.0 * f);
        let mix = |x: f64, y: f64| x + (y - x) * s;
        let pose = CameraSpec {
            lon_deg: mix(from.lon_deg, to.lon_deg),
            lat_deg: mix(from.lat_deg, to.lat_deg),
            alt_m: mix(from.alt_m.ln(), to.alt_m.ln()).exp(),
            heading_deg: mix(from.heading_deg, to.heading_deg),
            pitch_deg: mix(from.pitch_deg, to.pitch_deg),
            above_ground: true,
        };
        let view = pose.view(&off.globe, a.globe.fov_deg, width, height);
        let r = off.globe.frame(&off.ctx.device, &off.ctx.queue, &view);
        off.draw();
        frame += 1;
        if t >= next_sample {
            next_sample += 1.0;
            let memory = off.globe.memory_use();
            let rss = mib(memory.resident);
            max_rss = max_rss.max(rss);
            let st = off.globe.layer().scheduler_stats();
            println!(
                "{}",
                json!({
                    "t_s": t,
                    "rss_mib": rss,
                    "cache_mib": mib(Some(memory.tile_cache)),
                    "cache_budget_mib": mib(Some(off.globe.layer().cache_bytes().1 as u64)),
                    "source_caches_mib": mib(Some(memory.sources)),
                    "gpu_pool_mib": mib(Some(memory.gpu_pool)),
                    "memory_budget_mib": mib(memory.plan.map(|p| p.total)),
                    "baseline_mib": mib(memory.plan.map(|p| p.baseline)),
                    "gpu_tiles": r.pool.resident,
                    "gpu_capacity": r.pool.capacity,
                    "loading": r.layer.loading,
                    "loaded": st.loaded,
                    "failed": st.failed,
                    "retries": st.retries,
                    "sse_bound_px": r.sse_bound_px,
                    "frames": frame,
                })
            );
        }
        let ahead = frame as f64 / 10.0 - started.elapsed().as_secs_f64();
        if ahead > 0.0 {
            std::thread::sleep(Duration::from_secs_f64(ahead));
        }
    }
    let st = off.globe.layer().scheduler_stats();
    println!(
        "{}",
        json!({"summary": true, "seconds": seconds, "frames": frame, "max_rss_mib": max_rss,
               "memory_budget_mib": mib(off.globe.memory_use().plan.map(|p| p.total)),
               "loaded": st.loaded, "failed": st.failed, "retries": st.retries,
               "no_data": st.no_data, "stopped_in_flight": st.cancelled_in_flight})
    );
    Ok(())
}
