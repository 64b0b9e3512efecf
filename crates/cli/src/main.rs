//! The `globus` binary: the command line over the engine and the tiler. Every failure ends
//! with one line on stderr and a non-zero exit; logs go through `tracing` (`RUST_LOG`
//! filters them; warnings and errors by default).

mod args;
mod bench;
mod config;
mod geo_cmd;
mod mesh_cmd;
mod path;
mod render_cmd;
mod tile_cmd;
mod traffic_cmd;
mod viewer;

use clap::Parser;

use crate::args::{Cli, Command, GeoCommand, TileCommand, TileJobCommand, ViewArgs};

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

/// Gives the GPU drivers a private runtime directory when the environment has none that is
/// usable: without one, every device start on Linux prints "error: XDG_RUNTIME_DIR is invalid
/// or not set in the environment." (the Wayland client library, which Mesa's Vulkan driver
/// loads), although nothing fails. Runs first in `main`, before any other thread exists.
#[cfg(target_os = "linux")]
#[allow(unsafe_code)]
fn ensure_runtime_dir() {
    use std::os::unix::fs::{MetadataExt, PermissionsExt};
    // Files under /proc/self belong to the process's user.
    let Ok(me) = std::fs::metadata("/proc/self").map(|m| m.uid()) else {
        return;
    };
    let usable = |dir: &std::path::Path| {
        std::fs::metadata(dir).is_ok_and(|m| m.is_dir() && m.uid() == me && m.mode() & 0o077 == 0)
    };
    if std::env::var_os("XDG_RUNTIME_DIR").is_some_and(|d| usable(d.as_ref())) {
        return;
    }
    let dir = std::env::temp_dir().join(format!("globus-runtime-{me}"));
    let _ = std::fs::create_dir(&dir);
    let _ = std::fs::set_permissions(&dir, std::fs::Permissions::from_mode(0o700));
    if usable(&dir) {
        // SAFETY: called at the start of `main`, before any other thread is started, so no
        // other thread reads the environment while it changes.
        unsafe { std::env::set_var("XDG_RUNTIME_DIR", &dir) };
    }
}

#[cfg(not(target_os = "linux"))]
fn ensure_runtime_dir() {}

/// Logs to stderr, filtered by `RUST_LOG` (e.g. `RUST_LOG=globus_stream=debug`); warnings
/// and errors only when it is not set.
fn init_logging() {
    use std::io::IsTerminal;
    use tracing_subscriber::EnvFilter;
    let filter = EnvFilter::try_from_default_env().unwrap_or_else(|_| EnvFilter::new("warn"));
    let verbose = std::env::var_os("RUST_LOG").is_some();
    let builder = tracing_subscriber::fmt()
        .with_env_filter(filter)
        .with_writer(std::io::stderr)
        .with_ansi(std::io::stderr().is_terminal())
        .with_target(verbose);
    // A warning is a line for a person ("globus: warning: ..." in spirit); timestamps only
    // when someone asked for a log.
    let _ = if verbose {
        builder.try_init()
    } else {
        builder.without_time().try_init()
    };
}

fn main() {
    ensure_runtime_dir();
    tune_allocator();
    init_logging();
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
            // clap's first paragraph, on one line (it names the missing arguments on the lines
            // after the first).
            let text = e.to_string();
            let first: Vec<&str> = text
                .lines()
                .take_while(|l| !l.trim().is_empty())
                .map(str::trim)
                .collect();
            let first = if first.is_empty() {
                "invalid arguments".to_string()
            } else {
                first.join(" ")
            };
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
        Command::Render(a) => render_cmd::run(a),
        Command::Bench(a) => bench::run(a),
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
        Command::Traffic(a) => match a.command {
            Some(command) => {
                println!("{}", traffic_cmd::run(command)?);
                Ok(())
            }
            None => traffic_cmd::view(a.view),
        },
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
                GeoCommand::Slopes {
                    lon,
                    lat,
                    window_km,
                    spacing_m,
                    seed,
                } => geo_cmd::slopes((lon, lat), window_km, spacing_m, seed)?,
            };
            println!("{out}");
            Ok(())
        }
    }
}

fn view(a: ViewArgs) -> anyhow::Result<()> {
    let (width, height) = args::parse_size(&a.size)?;
    let sun_time = match a.time.as_deref().unwrap_or("now").trim() {
        "fixed" => None,
        t => Some(traffic_cmd::parse_time(t, "--time")?),
    };
    let default_camera = args::default_view_camera(sun_time);
    let camera = args::parse_camera(
        a.camera.as_deref().unwrap_or(&default_camera),
        a.above_ground,
    )?;
    let exit_after = a.exit_after()?;
    let mut globe = args::globe_builder(&a.globe)?;
    let vectors = args::vector_layer(&a.globe, &mut globe)?;
    viewer::run(viewer::ViewerOptions {
        globe,
        camera,
        fov_deg: a.globe.fov_deg,
        ortho_m: a.globe.ortho_km.map(|km| km * 1e3),
        width,
        height,
        exit_after,
        vectors,
        traffic: None,
        sun_time,
    })
}
