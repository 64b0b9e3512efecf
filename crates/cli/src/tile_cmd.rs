//! `globus tile dem|imagery|plan|merge`: builds tile pyramids with `globus-tiler`.

use std::io::IsTerminal;
use std::path::PathBuf;

use anyhow::{Context, bail};
use clap::Args;
use globus_tiler::shard::{MergeJob, ShardSpec};
use globus_tiler::{ElevationEncoding, ImageFormat, JobKind, TileJob, TileLayout};
use globus_tiling::{GeoRect, TilingScheme};

/// Options shared by `globus tile dem` and `globus tile imagery`.
#[derive(Args, Clone, Debug)]
pub struct TileArgs {
    /// Input files: SRTM .hgt (several form a mosaic), one GeoTIFF (EPSG:4326 or 3857), or
    /// one JPEG/PNG image in equirectangular projection covering --bounds.
    #[arg(long = "in", required = true, num_args = 1..)]
    pub inputs: Vec<PathBuf>,
    /// Output: a directory ({z}/{x}/{y}.ext), FILE.mbtiles or FILE.pmtiles.
    #[arg(long)]
    pub out: PathBuf,
    /// Tiling scheme: geographic (two roots, EPSG:4326) or webmercator (EPSG:3857).
    #[arg(long, default_value = "geographic")]
    pub scheme: String,
    /// Elevation encoding: terrarium, mapbox or centimetre.
    #[arg(long, default_value = "terrarium")]
    pub encoding: String,
    /// Imagery format: jpeg, png or webp (lossless).
    #[arg(long, default_value = "jpeg")]
    pub format: String,
    /// JPEG quality, 1..=100.
    #[arg(long, default_value_t = 85)]
    pub quality: u8,
    /// Samples per tile side: 256 or 512.
    #[arg(long, default_value_t = 256)]
    pub tile_size: usize,
    /// Coarsest level written.
    #[arg(long, default_value_t = 0)]
    pub min_level: u8,
    /// Finest level (default: the first level as fine as the source).
    #[arg(long)]
    pub max_level: Option<u8>,
    /// W,S,E,N degrees: the extent of a plain image input (default the whole world), or a
    /// clip for georeferenced inputs.
    #[arg(long, allow_hyphen_values = true)]
    pub bounds: Option<String>,
    /// Metres per grey level of a greyscale elevation image.
    #[arg(long)]
    pub height_scale: Option<f64>,
    /// Worker threads (default: all cores).
    #[arg(long)]
    pub threads: Option<usize>,
    /// Continue an interrupted run, reusing the tiles it wrote.
    #[arg(long)]
    pub resume: bool,
    /// Replace an existing output.
    #[arg(long)]
    pub force: bool,
    /// Number rows from the south in directory output (TMS) instead of from the north (XYZ).
    #[arg(long)]
    pub tms: bool,
    /// Do one shard of the job: K/N, or N with K from JOB_COMPLETION_INDEX (Kubernetes
    /// Indexed Job) or SLURM_ARRAY_TASK_ID (Slurm array). Join shards with `globus tile merge`.
    #[arg(long)]
    pub shard: Option<String>,
}

/// Options of `globus tile merge`.
#[derive(Args, Clone, Debug)]
pub struct MergeArgs {
    /// The shard outputs (directories or MBTiles written with --shard).
    #[arg(long = "in", required = true, num_args = 1..)]
    pub inputs: Vec<PathBuf>,
    /// The merged pyramid: a directory, FILE.mbtiles or FILE.pmtiles.
    #[arg(long)]
    pub out: PathBuf,
    /// Replace an existing output.
    #[arg(long)]
    pub force: bool,
    /// Worker threads for the levels merge builds (default: all cores).
    #[arg(long)]
    pub threads: Option<usize>,
}

fn parse_bounds(text: &str) -> anyhow::Result<GeoRect> {
    let [w, s, e, n] = parse_bounds_deg(text)?;
    Ok(GeoRect::from_degrees(w, s, e, n))
}

/// `--bounds W,S,E,N` as four numbers (degrees), checked only for being four numbers.
pub(crate) fn parse_bounds_deg(text: &str) -> anyhow::Result<[f64; 4]> {
    let v: Vec<f64> = text
        .split(',')
        .map(|s| s.trim().parse::<f64>())
        .collect::<Result<_, _>>()
        .ok()
        .filter(|v: &Vec<f64>| v.len() == 4)
        .with_context(|| format!("--bounds {text:?} must be four numbers W,S,E,N in degrees"))?;
    Ok([v[0], v[1], v[2], v[3]])
}

pub(crate) fn parse_scheme(name: &str) -> anyhow::Result<TilingScheme> {
    match name {
        "geographic" | "EPSG:4326" => Ok(TilingScheme::Geographic),
        "webmercator" | "mercator" | "EPSG:3857" => Ok(TilingScheme::WebMercator),
        other => bail!("unknown tiling scheme {other:?} (use geographic or webmercator)"),
    }
}

/// Builds the job for `kind` ("dem" or "imagery") from the arguments.
pub fn job(kind: &str, a: &TileArgs) -> anyhow::Result<TileJob> {
    let kind = match kind {
        "dem" => JobKind::Dem {
            encoding: ElevationEncoding::parse(&a.encoding).with_context(|| {
                format!(
                    "unknown elevation encoding {:?} (use terrarium, mapbox or centimetre)",
                    a.encoding
                )
            })?,
            height_scale: a.height_scale,
        },
        _ => {
            if !(1..=100).contains(&a.quality) {
                bail!("--quality must be between 1 and 100, not {}", a.quality);
            }
            JobKind::Imagery {
                format: ImageFormat::parse(&a.format, a.quality).with_context(|| {
                    format!(
                        "unknown image format {:?} (use jpeg, png or webp)",
                        a.format
                    )
                })?,
            }
        }
    };
    Ok(TileJob {
        kind,
        inputs: a.inputs.clone(),
        output: a.out.clone(),
        scheme: parse_scheme(&a.scheme)?,
        tile_size: a.tile_size,
        min_level: a.min_level,
        max_level: a.max_level,
        bounds: a.bounds.as_deref().map(parse_bounds).transpose()?,
        threads: a.threads,
        resume: a.resume,
        force: a.force,
        layout: if a.tms {
            TileLayout::Tms
        } else {
            TileLayout::Xyz
        },
        shard: a
            .shard
            .as_deref()
            .map(|text| ShardSpec::parse(text, |k| std::env::var(k).ok()))
            .transpose()?,
    })
}

/// Runs `globus tile plan --shards N dem|imagery ...` and returns the plan as JSON.
pub fn plan(shards: u32, kind: &str, a: &TileArgs) -> anyhow::Result<String> {
    let job = job(kind, a)?;
    Ok(globus_tiler::job::plan_shards(&job, shards)?
        .to_json()
        .to_string())
}

/// Runs `globus tile merge` and returns the JSON summary line.
pub fn merge(a: &MergeArgs) -> anyhow::Result<String> {
    let bar = ProgressBar::new();
    let summary = globus_tiler::shard::merge_with_progress(
        &MergeJob {
            inputs: a.inputs.clone(),
            output: a.out.clone(),
            force: a.force,
            threads: a.threads.unwrap_or(0),
        },
        &|p| bar.update(p),
    )?;
    bar.finish();
    Ok(summary.to_json().to_string())
}

/// Runs `globus tile dem|imagery` and returns the JSON summary line.
pub fn run(kind: &str, a: &TileArgs) -> anyhow::Result<String> {
    let job = job(kind, a)?;
    let bar = ProgressBar::new();
    let summary = globus_tiler::run_with_progress(&job, &|p| bar.update(p))?;
    bar.finish();
    Ok(summary.to_json().to_string())
}

/// Tiles done, rate and time left, drawn on stderr while a job runs, if stderr is a
/// terminal (nothing otherwise).
struct ProgressBar(Option<indicatif::ProgressBar>);

impl ProgressBar {
    fn new() -> Self {
        if !std::io::stderr().is_terminal() {
            return Self(None);
        }
        let bar = indicatif::ProgressBar::new(0);
        let style = indicatif::ProgressStyle::with_template(
            "{bar:30} {pos}/{len} tiles ({percent}%)  {per_sec}  ETA {eta}",
        )
        .unwrap_or_else(|_| indicatif::ProgressStyle::default_bar());
        bar.set_style(style);
        Self(Some(bar))
    }

    fn update(&self, p: &globus_tiler::ProgressReport) {
        if let Some(bar) = &self.0 {
            bar.set_length(p.tiles_total);
            bar.set_position(p.tiles_done);
        }
    }

    fn finish(&self) {
        if let Some(bar) = &self.0 {
            bar.finish_and_clear();
        }
    }
}
