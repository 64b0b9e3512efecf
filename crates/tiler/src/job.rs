//! [`TileJob`]: everything `globus tile dem|imagery` asks for, checked, run, summarised.

use std::path::{Path, PathBuf};
use std::sync::atomic::{AtomicBool, Ordering};
use std::time::Instant;

use globus_tiling::{GeoRect, TileKey, TilingScheme, WEB_MERCATOR_MAX_LAT_DEG};

use crate::encoding::ElevationEncoding;
use crate::error::{Result, TilerError};
use crate::fill::fill_voids;
use crate::format::ImageFormat;
use crate::input;
use crate::layer::{ElevationCodec, ElevationLayer, ImageryCodec, ImageryLayer, Layer, TileCodec};
use crate::pyramid::{Handover, Progress, ProgressFn, Pyramid, report_progress};
use crate::raster::{RowSource, intersect};
use crate::resample::SampleGrid;
use crate::shard::{self, ShardSpec};
use crate::sink::{OutputOptions, OutputSink, PyramidMetadata, TileLayout};

/// What the pyramid holds.
#[derive(Clone, Copy, Debug, PartialEq)]
pub enum JobKind {
    /// Elevation, RGB-encoded in lossless PNG.
    Dem {
        /// The RGB encoding.
        encoding: ElevationEncoding,
        /// Metres per grey level, for greyscale image inputs.
        height_scale: Option<f64>,
    },
    /// Imagery.
    Imagery {
        /// The tile format.
        format: ImageFormat,
    },
}

/// A tiling job.
#[derive(Clone, Debug)]
pub struct TileJob {
    /// Elevation or imagery.
    pub kind: JobKind,
    /// Input files.
    pub inputs: Vec<PathBuf>,
    /// A directory, `FILE.mbtiles` or `FILE.pmtiles`.
    pub output: PathBuf,
    /// The tiling scheme.
    pub scheme: TilingScheme,
    /// 256 or 512.
    pub tile_size: usize,
    /// Coarsest level (default 0).
    pub min_level: u8,
    /// Finest level (default: the first level as fine as the source).
    pub max_level: Option<u8>,
    /// For plain images, the extent they cover; for georeferenced inputs, a clip.
    pub bounds: Option<GeoRect>,
    /// Worker threads (default: all cores).
    pub threads: Option<usize>,
    /// Continue an interrupted run, reusing its tiles.
    pub resume: bool,
    /// Replace an existing output.
    pub force: bool,
    /// Row order of directory output.
    pub layout: TileLayout,
    /// Do only this shard of the job.
    pub shard: Option<ShardSpec>,
}

impl TileJob {
    /// A job of `kind` from `inputs` to `output` with the command line's defaults: geographic
    /// 256-sample tiles from level 0 to the first level as fine as the source, all cores, XYZ
    /// rows, an existing output replaced, no shard.
    pub fn new(kind: JobKind, inputs: Vec<PathBuf>, output: PathBuf) -> Self {
        Self {
            kind,
            inputs,
            output,
            scheme: TilingScheme::Geographic,
            tile_size: 256,
            min_level: 0,
            max_level: None,
            bounds: None,
            threads: None,
            resume: false,
            force: true,
            layout: TileLayout::Xyz,
            shard: None,
        }
    }
}

/// The result of a job, printed as one JSON line.
#[derive(Clone, Debug, PartialEq)]
pub struct Summary {
    /// Tiles written by this run.
    pub tiles: u64,
    /// Tiles reused from an earlier run (`--resume`).
    pub tiles_reused: u64,
    /// Bytes of tile data written.
    pub bytes: u64,
    /// Wall time, seconds.
    pub seconds: f64,
    /// Levels written.
    pub levels: (u8, u8),
    /// Source samples that were voids and got filled.
    pub voids_filled: usize,
}

impl Summary {
    /// The JSON summary line.
    pub fn to_json(&self) -> serde_json::Value {
        serde_json::json!({
            "tiles": self.tiles,
            "tiles_reused": self.tiles_reused,
            "bytes": self.bytes,
            "seconds": (self.seconds * 1000.0).round() / 1000.0,
            "tiles_per_second": (self.tiles as f64 / self.seconds.max(1e-9) * 10.0).round() / 10.0,
            "min_level": self.levels.0,
            "max_level": self.levels.1,
            "voids_filled": self.voids_filled,
        })
    }
}

enum InputKind {
    Hgt,
    Image,
    GeoTiff,
}

fn input_kind(path: &Path) -> Result<InputKind> {
    let ext = path
        .extension()
        .and_then(|e| e.to_str())
        .map(str::to_ascii_lowercase)
        .unwrap_or_default();
    match ext.as_str() {
        "hgt" => Ok(InputKind::Hgt),
        "jpg" | "jpeg" | "png" | "webp" => Ok(InputKind::Image),
        "tif" | "tiff" => Ok(InputKind::GeoTiff),
        _ => Err(TilerError::bad_input(
            path,
            "unknown input type; expected .hgt, .tif/.tiff, .jpg, .png or .webp",
        )),
    }
}

fn single_input<'a>(job: &'a TileJob, what: &str) -> Result<&'a Path> {
    match job.inputs.as_slice() {
        [one] => Ok(one),
        _ => Err(TilerError::BadOptions(format!(
            "a {what} input must be the only input ({} given)",
            job.inputs.len()
        ))),
    }
}

fn check_bounds(b: &GeoRect) -> Result<()> {
    let [w, s, e, n] = b.to_degrees();
    let ok = w.is_finite()
        && s.is_finite()
        && e.is_finite()
        && n.is_finite()
        && (-180.0..180.0).contains(&w)
        && w < e
        && e <= 180.0
        && (-90.0..90.0).contains(&s)
        && s < n
        && n <= 90.0;
    if ok {
        Ok(())
    } else {
        Err(TilerError::BadOptions(format!(
            "--bounds {w},{s},{e},{n} is not a rectangle W,S,E,N in degrees with W < E and S < N"
        )))
    }
}

/// The elevation source and the number of voids filled while reading it (a mosaic of SRTM
/// files fills its voids as files load; see [`RowSource::voids_filled`]).
fn read_elevation(
    job: &TileJob,
    height_scale: Option<f64>,
) -> Result<(Box<dyn RowSource<f32>>, usize)> {
    let first = job
        .inputs
        .first()
        .ok_or_else(|| TilerError::BadOptions("no --in file".into()))?;
    let mut raster = match input_kind(first)? {
        InputKind::Hgt => {
            if let Some(p) = job
                .inputs
                .iter()
                .find(|p| !matches!(input_kind(p), Ok(InputKind::Hgt)))
            {
                return Err(TilerError::bad_input(p, "cannot be mixed with .hgt inputs"));
            }
            return Ok((Box::new(input::read_hgt_mosaic(&job.inputs)?), 0));
        }
        InputKind::Image => {
            let path = single_input(job, "plain image")?;
            let scale = height_scale.ok_or_else(|| {
                TilerError::bad_input(
                    path,
                    "a greyscale image needs --height-scale (metres per grey level)",
                )
            })?;
            input::read_grey_elevation(path, job.bounds.unwrap_or(GeoRect::WORLD), scale)?
        }
        InputKind::GeoTiff => {
            let path = single_input(job, "GeoTIFF")?;
            match input::read_geotiff(path)? {
                input::GeoTiff::Elevation(r) => r,
                input::GeoTiff::ElevationStream(source) => return Ok((source, 0)),
                input::GeoTiff::Image { .. } => {
                    return Err(TilerError::bad_input(
                        path,
                        "holds colour imagery; use `globus tile imagery` for it",
                    ));
                }
            }
        }
    };
    let filled = fill_voids(&mut raster.data, raster.width, raster.height)
        .ok_or_else(|| TilerError::bad_input(first, "has no valid elevation sample (all voids)"))?;
    Ok((Box::new(raster), filled))
}

/// An imagery source read a row at a time.
type ImageSource = Box<dyn RowSource<[u8; 4]>>;

/// The imagery source and whether it is fully opaque.
fn read_imagery(job: &TileJob) -> Result<(ImageSource, bool)> {
    let path = single_input(job, "imagery")?;
    match input_kind(path)? {
        InputKind::Image => {
            let r = input::read_world_image(path, job.bounds.unwrap_or(GeoRect::WORLD))?;
            let opaque = r.data.iter().all(|px| px[3] == 255);
            Ok((Box::new(r), opaque))
        }
        InputKind::Hgt => Err(TilerError::bad_input(
            path,
            "is elevation; use `globus tile dem` for it",
        )),
        InputKind::GeoTiff => match input::read_geotiff(path)? {
            input::GeoTiff::Image { source, opaque } => Ok((source, opaque)),
            input::GeoTiff::Elevation(_) | input::GeoTiff::ElevationStream(_) => {
                Err(TilerError::bad_input(
                    path,
                    "holds elevation (one numeric band); use `globus tile dem` for it",
                ))
            }
        },
    }
}

/// The footprint to tile: the source's, clipped to `--bounds` for georeferenced inputs and
/// to the scheme's latitude range.
fn footprint(job: &TileJob, source: GeoRect, georeferenced: bool) -> Result<GeoRect> {
    let mut fp = source;
    if georeferenced && let Some(b) = &job.bounds {
        fp = intersect(&fp, b, false).ok_or_else(|| {
            let [w, s, e, n] = source.to_degrees();
            TilerError::BadOptions(format!(
                "the input covers {w:.4},{s:.4},{e:.4},{n:.4}, which does not intersect --bounds {}",
                b.to_degrees().map(|d| format!("{d}")).join(",")
            ))
        })?;
    }
    if job.scheme == TilingScheme::WebMercator {
        let lim = WEB_MERCATOR_MAX_LAT_DEG.to_radians();
        fp.north = fp.north.min(lim);
        fp.south = fp.south.max(-lim);
        if fp.south >= fp.north {
            return Err(TilerError::BadOptions(
                "the input lies entirely beyond the Web Mercator latitude limit (85.0511)".into(),
            ));
        }
    }
    Ok(fp)
}

/// The first level whose sample spacing is at least as fine as the source's.
fn native_level(
    scheme: TilingScheme,
    grid: SampleGrid,
    size: usize,
    source_spacing_rad: f64,
) -> u8 {
    let per_tile = match grid {
        SampleGrid::Corners => (size - 1) as f64,
        SampleGrid::Cells => size as f64,
    };
    (0..=24u8)
        .find(|&z| {
            2.0 * std::f64::consts::PI / scheme.tiles_x(z) as f64 / per_tile
                <= source_spacing_rad * (1.0 + 1e-9)
        })
        .unwrap_or(24)
}

/// Workers per core at most: tiling is CPU-bound, and 10,000 threads on 2 cores took minutes
/// for what the default does in 0.06 s.
pub const MAX_THREADS_PER_CORE: usize = 4;

/// `threads` (0: all cores), at most [`MAX_THREADS_PER_CORE`] per core, with a warning when cut.
fn capped_threads(threads: usize) -> usize {
    let cores = std::thread::available_parallelism().map_or(1, |n| n.get());
    let max = MAX_THREADS_PER_CORE * cores;
    if threads > max {
        tracing::warn!(
            "--threads {threads}: using {max} ({MAX_THREADS_PER_CORE} per core on {cores} cores)"
        );
        max
    } else {
        threads
    }
}

/// Runs `pyramid` on a pool of `threads` workers (0: all cores), reporting progress to
/// `on_progress`.
pub(crate) fn run_pyramid<L: Layer>(
    pyramid: &Pyramid<'_, L>,
    threads: usize,
    on_progress: &ProgressFn<'_>,
) -> Result<()> {
    let start = Instant::now();
    let progress = pyramid.progress;
    progress.total.store(pyramid.count(), Ordering::Relaxed);
    let threads = capped_threads(threads);
    let pool = rayon::ThreadPoolBuilder::new()
        .num_threads(threads)
        .thread_name(|i| format!("globus-tile-{i}"))
        .build()
        .map_err(|e| TilerError::BadOptions(format!("--threads {threads}: {e}")))?;
    let done = AtomicBool::new(false);
    std::thread::scope(|s| {
        s.spawn(|| report_progress(progress, &done, start, on_progress));
        let r = pool.install(|| pyramid.run());
        done.store(true, Ordering::Relaxed);
        r
    })
}

/// A job with its source read and its levels decided.
struct Prepared<L> {
    layer: L,
    footprint: GeoRect,
    max_level: u8,
    meta: PyramidMetadata,
    voids_filled: usize,
}

fn execute<L: Layer>(
    job: &TileJob,
    p: &Prepared<L>,
    on_progress: &ProgressFn<'_>,
) -> Result<Summary> {
    let start = Instant::now();
    let codec = p.layer.codec();
    let closed = codec.grid() == SampleGrid::Corners;
    let levels = (job.min_level, p.max_level);
    let (starts, write_levels, split) = match job.shard {
        None => (job.scheme.roots().to_vec(), levels, None),
        Some(spec) => {
            let plan = shard::plan(job.scheme, &p.footprint, closed, levels, spec.count);
            let mine = plan.shards[spec.index as usize].clone();
            (
                mine,
                (plan.split_level, p.max_level),
                Some(plan.split_level),
            )
        }
    };
    if job.shard.is_some() && is_pmtiles(&job.output) {
        return Err(TilerError::output(
            &job.output,
            "write shards as directories or MBTiles; `globus tile merge` can then write PMTiles",
        ));
    }
    let sink = OutputSink::open(
        &job.output,
        OutputOptions {
            scheme: job.scheme,
            layout: job.layout,
            extension: codec.extension(),
            force: job.force,
            resume: job.resume,
        },
    )?;
    let progress = Progress::default();
    let handover = Handover::default();
    let pyramid = Pyramid {
        layer: &p.layer,
        sink: sink.as_dyn(),
        scheme: job.scheme,
        footprint: p.footprint,
        closed,
        starts,
        write_levels,
        max_level: p.max_level,
        resume: job.resume,
        handover: split.map(|l| (l, &handover)),
        progress: &progress,
    };
    run_pyramid(&pyramid, job.threads.unwrap_or(0), on_progress)?;
    sink.finish(&p.meta)?;
    if let (Some(spec), Some(split_level)) = (job.shard, split) {
        let tiles = handover
            .into_inner()
            .map_err(|_| TilerError::BadOptions("a worker panicked".into()))?;
        shard::write_handover(
            &job.output,
            &shard::HandoverHeader {
                meta: p.meta.clone(),
                layout: job.layout,
                jpeg_quality: match job.kind {
                    JobKind::Imagery {
                        format: ImageFormat::Jpeg { quality },
                    } => Some(quality),
                    _ => None,
                },
                footprint: p.footprint,
                closed,
                split_level,
                shard: spec,
            },
            tiles,
        )?;
    }
    let written = progress.written.load(Ordering::Relaxed);
    Ok(Summary {
        tiles: written,
        tiles_reused: progress.tiles.load(Ordering::Relaxed) - written,
        bytes: progress.bytes.load(Ordering::Relaxed),
        seconds: start.elapsed().as_secs_f64(),
        levels,
        voids_filled: p.voids_filled + p.layer.voids_filled(),
    })
}

fn is_pmtiles(path: &Path) -> bool {
    path.extension()
        .and_then(|e| e.to_str())
        .is_some_and(|e| e.eq_ignore_ascii_case("pmtiles"))
}

fn check_job(job: &TileJob) -> Result<()> {
    if job.inputs.is_empty() {
        return Err(TilerError::BadOptions("no --in file given".into()));
    }
    if job.tile_size != 256 && job.tile_size != 512 {
        return Err(TilerError::BadOptions(format!(
            "--tile-size must be 256 or 512, not {}",
            job.tile_size
        )));
    }
    if let Some(b) = &job.bounds {
        check_bounds(b)?;
    }
    if let Some(spec) = job.shard {
        shard::check_shard_count("--shard", spec.count)?;
    }
    if let Some(spec) = job.shard
        && spec.index >= spec.count
    {
        return Err(TilerError::BadOptions(format!(
            "--shard {}/{}: the index must be below the number of shards",
            spec.index, spec.count
        )));
    }
    if job.min_level > TileKey::MAX_LEVEL - 1 {
        return Err(TilerError::BadOptions(format!(
            "--min-level {} is too deep",
            job.min_level
        )));
    }
    Ok(())
}

fn levels(job: &TileJob, native: u8) -> Result<u8> {
    let max = job.max_level.unwrap_or(native.max(job.min_level));
    if max < job.min_level || max > 24 {
        return Err(TilerError::BadOptions(format!(
            "--max-level {max} must be between --min-level {} and 24",
            job.min_level
        )));
    }
    Ok(max)
}

fn stem(job: &TileJob) -> String {
    job.inputs
        .first()
        .and_then(|p| p.file_stem())
        .map(|s| s.to_string_lossy().into_owned())
        .unwrap_or_else(|| "globus".into())
}

/// The levels and metadata of a job once its source is read.
struct Plan {
    footprint: GeoRect,
    max_level: u8,
    meta: PyramidMetadata,
}

fn plan(
    job: &TileJob,
    source_footprint: GeoRect,
    georeferenced: bool,
    grid: SampleGrid,
    lon_spacing_rad: f64,
    format: &str,
    encoding: Option<ElevationEncoding>,
) -> Result<Plan> {
    let footprint = footprint(job, source_footprint, georeferenced)?;
    let max_level = levels(
        job,
        native_level(job.scheme, grid, job.tile_size, lon_spacing_rad),
    )?;
    let meta = PyramidMetadata {
        name: stem(job),
        format: format.into(),
        kind: if encoding.is_some() {
            "elevation"
        } else {
            "imagery"
        }
        .into(),
        encoding: encoding.map(|e| e.name().into()),
        scheme: job.scheme,
        tile_size: job.tile_size,
        sample_grid: match grid {
            SampleGrid::Corners => "corners",
            SampleGrid::Cells => "cells",
        }
        .into(),
        bounds: footprint,
        min_level: job.min_level,
        max_level,
    };
    Ok(Plan {
        footprint,
        max_level,
        meta,
    })
}

fn prepare_elevation(
    job: &TileJob,
    encoding: ElevationEncoding,
    height_scale: Option<f64>,
) -> Result<Prepared<ElevationLayer>> {
    let georeferenced = !matches!(input_kind(&job.inputs[0])?, InputKind::Image);
    let (source, voids_filled) = read_elevation(job, height_scale)?;
    let p = plan(
        job,
        source.footprint(),
        georeferenced,
        SampleGrid::Corners,
        source.georef().lon_spacing_rad(),
        "png",
        Some(encoding),
    )?;
    Ok(Prepared {
        layer: ElevationLayer {
            source,
            footprint: p.footprint,
            codec: ElevationCodec {
                size: job.tile_size,
                encoding,
            },
        },
        footprint: p.footprint,
        max_level: p.max_level,
        meta: p.meta,
        voids_filled,
    })
}

fn prepare_imagery(job: &TileJob, format: ImageFormat) -> Result<Prepared<ImageryLayer>> {
    let (source, opaque) = read_imagery(job)?;
    let georeferenced = matches!(input_kind(&job.inputs[0])?, InputKind::GeoTiff);
    let p = plan(
        job,
        source.footprint(),
        georeferenced,
        SampleGrid::Cells,
        source.georef().lon_spacing_rad(),
        format.extension(),
        None,
    )?;
    Ok(Prepared {
        layer: ImageryLayer {
            source,
            opaque,
            footprint: p.footprint,
            codec: ImageryCodec {
                size: job.tile_size,
                format,
            },
        },
        footprint: p.footprint,
        max_level: p.max_level,
        meta: p.meta,
        voids_filled: 0,
    })
}

/// Runs a job (or, with [`TileJob::shard`], one shard of it).
pub fn run(job: &TileJob) -> Result<Summary> {
    run_with_progress(job, &|_| {})
}

/// Runs a job, calling `on_progress` a few times a second with the tiles done so far (a
/// terminal program draws a progress bar from it; the library prints nothing).
pub fn run_with_progress(job: &TileJob, on_progress: &ProgressFn<'_>) -> Result<Summary> {
    check_job(job)?;
    let _lock = crate::sink::OutputLock::take(&job.output)?;
    match job.kind {
        JobKind::Dem {
            encoding,
            height_scale,
        } => execute(
            job,
            &prepare_elevation(job, encoding, height_scale)?,
            on_progress,
        ),
        JobKind::Imagery { format } => execute(job, &prepare_imagery(job, format)?, on_progress),
    }
}

/// Splits a job into `shards` parts of roughly equal work (see [`shard::plan`]).
pub fn plan_shards(job: &TileJob, shards: u32) -> Result<shard::ShardPlan> {
    check_job(job)?;
    shard::check_shard_count("--shards", shards)?;
    let levels_of = |fp: GeoRect, max: u8, closed: bool| {
        shard::plan(job.scheme, &fp, closed, (job.min_level, max), shards)
    };
    Ok(match job.kind {
        JobKind::Dem {
            encoding,
            height_scale,
        } => {
            let p = prepare_elevation(job, encoding, height_scale)?;
            levels_of(p.footprint, p.max_level, true)
        }
        JobKind::Imagery { format } => {
            let p = prepare_imagery(job, format)?;
            levels_of(p.footprint, p.max_level, false)
        }
    })
}
