//! Planet-scale jobs across machines: a job splits at a *hand-over level* into shards of
//! roughly equal work; each shard builds the subtrees below its share of that level and
//! hands the exact samples of its hand-over tiles to `merge` in a side file
//! (`OUTPUT.shard`); `merge` copies every shard's tiles into one archive and builds the
//! levels above the hand-over level from those samples, exactly as a single run would, so
//! the merged archive is byte-identical to one made in one go.

use std::io::{BufRead, BufReader, Read, Write};
use std::path::{Path, PathBuf};
use std::time::Instant;

use globus_tiling::files::MAX_TILE_BYTES;
use globus_tiling::{GeoRect, TileKey, TilingScheme};
use rustc_hash::FxHashMap;
use serde_json::json;

use crate::encoding::ElevationEncoding;
use crate::error::{Result, TilerError};
use crate::format::ImageFormat;
use crate::job::{Summary, run_pyramid};
use crate::layer::{ElevationCodec, ImageryCodec, Layer, TileCodec};
use crate::pyramid::{Progress, ProgressFn, Pyramid, count_tiles, tile_range};
use crate::sink::{OutputOptions, OutputSink, PyramidMetadata, TileLayout};

/// Which shard of how many this process runs.
#[derive(Clone, Copy, Debug, PartialEq, Eq)]
pub struct ShardSpec {
    /// 0-based index.
    pub index: u32,
    /// Number of shards.
    pub count: u32,
}

/// The most shards a job splits into (a Kubernetes Indexed Job or Slurm array of 10,000 is
/// already far more than a pyramid's levels can share out evenly; a plan of 4e9 shards took
/// 96 GB before this limit).
pub const MAX_SHARDS: u32 = 10_000;

/// Refuses a shard count above [`MAX_SHARDS`] or of 0.
pub fn check_shard_count(option: &str, n: u32) -> Result<()> {
    if n == 0 || n > MAX_SHARDS {
        return Err(TilerError::BadOptions(format!(
            "{option} {n}: give 1 to {MAX_SHARDS} shards"
        )));
    }
    Ok(())
}

impl ShardSpec {
    /// Parses `K/N`, or `N` alone with K taken from the environment: `JOB_COMPLETION_INDEX`
    /// (Kubernetes Indexed Jobs) or `SLURM_ARRAY_TASK_ID` minus `SLURM_ARRAY_TASK_MIN`
    /// (Slurm job arrays, so `--array=1-8` works as well as `--array=0-7`).
    pub fn parse(text: &str, env: impl Fn(&str) -> Option<String>) -> Result<Self> {
        let bad = |why: &str| TilerError::BadOptions(format!("--shard {text:?}: {why}"));
        let number = |s: &str, what: &str| {
            s.trim()
                .parse::<u32>()
                .map_err(|_| bad(&format!("{what} {s:?} is not a whole number")))
        };
        let (index, count) = match text.split_once('/') {
            Some((k, n)) => (number(k, "index")?, number(n, "count")?),
            None => {
                let count = number(text, "count")?;
                let index = if let Some(k) = env("JOB_COMPLETION_INDEX") {
                    number(&k, "JOB_COMPLETION_INDEX")?
                } else if let Some(k) = env("SLURM_ARRAY_TASK_ID") {
                    let min = env("SLURM_ARRAY_TASK_MIN")
                        .map(|m| number(&m, "SLURM_ARRAY_TASK_MIN"))
                        .transpose()?
                        .unwrap_or(0);
                    number(&k, "SLURM_ARRAY_TASK_ID")?
                        .checked_sub(min)
                        .ok_or_else(|| bad("SLURM_ARRAY_TASK_ID is below SLURM_ARRAY_TASK_MIN"))?
                } else {
                    return Err(bad(
                        "give K/N, or N with JOB_COMPLETION_INDEX or SLURM_ARRAY_TASK_ID set",
                    ));
                };
                (index, count)
            }
        };
        check_shard_count("--shard", count)?;
        if index >= count {
            return Err(bad("the index must be below the number of shards"));
        }
        Ok(Self { index, count })
    }
}

/// How a job splits into shards.
#[derive(Clone, Debug, PartialEq, Eq)]
pub struct ShardPlan {
    /// The level whose tiles are shared out; shards write it and the levels below.
    pub split_level: u8,
    /// Each shard's tiles at the split level.
    pub shards: Vec<Vec<TileKey>>,
    /// Each shard's tile count (its work).
    pub tiles: Vec<u64>,
    /// Tiles above the split level, built by `merge`.
    pub merge_tiles: u64,
}

impl ShardPlan {
    /// The plan as JSON.
    pub fn to_json(&self) -> serde_json::Value {
        json!({
            "split_level": self.split_level,
            "shards": self.shards.iter().zip(&self.tiles).enumerate().map(|(k, (s, t))| json!({
                "shard": k,
                "split_level_tiles": s.len(),
                "tiles": t,
            })).collect::<Vec<_>>(),
            "merge_tiles": self.merge_tiles,
            "total_tiles": self.tiles.iter().sum::<u64>() + self.merge_tiles,
        })
    }
}

/// Splits the pyramid of `levels` over `footprint` into `n` shards: the split level is the
/// first (from the coarsest written level) with at least 16 tiles per shard, or the finest
/// level; its tiles, in row order, go in contiguous runs to the shards so that each gets
/// about the same number of tiles below them.
pub fn plan(
    scheme: TilingScheme,
    footprint: &GeoRect,
    closed: bool,
    levels: (u8, u8),
    n: u32,
) -> ShardPlan {
    let n = n.max(1);
    let count_at = |l: u8| tile_range(scheme, l, footprint, closed).map_or(0, |r| r.count());
    let split_level = (levels.0..=levels.1)
        .find(|&l| count_at(l) >= 16 * u64::from(n))
        .unwrap_or(levels.1);
    let mut keys = Vec::new();
    if let Some(r) = tile_range(scheme, split_level, footprint, closed) {
        for y in r.y.0..=r.y.1 {
            for x in r.x.0..=r.x.1 {
                keys.push(TileKey::new(split_level, x, y));
            }
        }
    }
    let weights: Vec<u64> = keys
        .iter()
        .map(|&k| count_tiles(scheme, footprint, closed, (split_level, levels.1), k))
        .collect();
    let total: u64 = weights.iter().sum();
    let mut shards = vec![Vec::new(); n as usize];
    let mut tiles = vec![0u64; n as usize];
    let mut before = 0u64;
    for (k, w) in keys.into_iter().zip(weights) {
        // The shard whose share holds the middle of this tile's work.
        let mid = 2 * before + w;
        let s = ((u128::from(mid) * u128::from(n)) / (2 * u128::from(total.max(1)))) as usize;
        let s = s.min(n as usize - 1);
        shards[s].push(k);
        tiles[s] += w;
        before += w;
    }
    let merge_tiles = (levels.0..split_level).map(count_at).sum();
    ShardPlan {
        split_level,
        shards,
        tiles,
        merge_tiles,
    }
}

/// What a shard tells `merge` about the job it ran.
#[derive(Clone, Debug)]
pub struct HandoverHeader {
    /// The whole pyramid's metadata.
    pub meta: PyramidMetadata,
    /// Row order of directory output.
    pub layout: TileLayout,
    /// JPEG quality, for JPEG imagery.
    pub jpeg_quality: Option<u8>,
    /// The data's footprint (radians).
    pub footprint: GeoRect,
    /// Whether tiles touching the footprint count (corner grids).
    pub closed: bool,
    /// The hand-over level.
    pub split_level: u8,
    /// Which shard this is.
    pub shard: ShardSpec,
}

const MAGIC: &str = "globus-shard 1";

/// Tiles as raw samples ([`TileCodec::tile_to_raw`]), by key.
pub type RawTiles = Vec<(TileKey, Vec<u8>)>;

/// The side file of a shard output.
pub fn handover_path(output: &Path) -> PathBuf {
    crate::sink::with_suffix(output, ".shard")
}

impl HandoverHeader {
    fn to_json(&self) -> serde_json::Value {
        let f = &self.footprint;
        json!({
            "meta": self.meta.to_json(),
            "layout": match self.layout { TileLayout::Xyz => "xyz", TileLayout::Tms => "tms" },
            "jpeg_quality": self.jpeg_quality,
            "footprint_rad": [f.west, f.south, f.east, f.north],
            "closed": self.closed,
            "split_level": self.split_level,
            "shard": self.shard.index,
            "shards": self.shard.count,
        })
    }

    fn from_json(path: &Path, v: &serde_json::Value) -> Result<Self> {
        let bad = |what: &str| TilerError::bad_input(path, format!("shard header: bad {what}"));
        let m = &v["meta"];
        let text = |v: &serde_json::Value, what: &str| {
            v.as_str().map(str::to_owned).ok_or_else(|| bad(what))
        };
        let small = |v: &serde_json::Value, what: &str| {
            v.as_u64()
                .and_then(|x| u8::try_from(x).ok())
                .ok_or_else(|| bad(what))
        };
        let scheme = match m["scheme"].as_str() {
            Some("geographic") => TilingScheme::Geographic,
            Some("webmercator") => TilingScheme::WebMercator,
            _ => return Err(bad("scheme")),
        };
        let fp: Vec<f64> = v["footprint_rad"]
            .as_array()
            .map(|a| a.iter().filter_map(|x| x.as_f64()).collect())
            .unwrap_or_default();
        if fp.len() != 4 {
            return Err(bad("footprint"));
        }
        let footprint = GeoRect {
            west: fp[0],
            south: fp[1],
            east: fp[2],
            north: fp[3],
        };
        let shard = ShardSpec {
            index: v["shard"]
                .as_u64()
                .and_then(|x| u32::try_from(x).ok())
                .ok_or_else(|| bad("shard"))?,
            count: v["shards"]
                .as_u64()
                .and_then(|x| u32::try_from(x).ok())
                .ok_or_else(|| bad("shards"))?,
        };
        Ok(Self {
            meta: PyramidMetadata {
                name: text(&m["name"], "name")?,
                format: text(&m["format"], "format")?,
                kind: text(&m["type"], "type")?,
                encoding: m["encoding"].as_str().map(str::to_owned),
                scheme,
                tile_size: m["tile_size"].as_u64().ok_or_else(|| bad("tile_size"))? as usize,
                sample_grid: text(&m["sample_grid"], "sample_grid")?,
                bounds: footprint,
                min_level: small(&m["minzoom"], "minzoom")?,
                max_level: small(&m["maxzoom"], "maxzoom")?,
            },
            layout: if v["layout"] == "tms" {
                TileLayout::Tms
            } else {
                TileLayout::Xyz
            },
            jpeg_quality: v["jpeg_quality"]
                .as_u64()
                .and_then(|q| u8::try_from(q).ok()),
            footprint,
            closed: v["closed"].as_bool().ok_or_else(|| bad("closed"))?,
            split_level: small(&v["split_level"], "split_level")?,
            shard,
        })
    }

    /// Whether two shards belong to the same job.
    fn same_job(&self, other: &Self) -> bool {
        let mut a = self.to_json();
        let mut b = other.to_json();
        a["shard"] = json!(0);
        b["shard"] = json!(0);
        a == b
    }
}

/// Writes the hand-over side file of a shard output: a magic line, a JSON header line, then
/// per tile (in key order) its key (u64 LE), the length (u32 LE) and the deflated raw samples.
pub fn write_handover(
    output: &Path,
    header: &HandoverHeader,
    mut tiles: Vec<(TileKey, Vec<u8>)>,
) -> Result<()> {
    let path = handover_path(output);
    let err = |e: std::io::Error| TilerError::output(&path, e);
    tiles.sort_unstable_by_key(|t| t.0);
    let tmp = crate::sink::with_suffix(&path, ".tmp");
    let file = std::fs::File::create(&tmp).map_err(err)?;
    let mut w = std::io::BufWriter::new(file);
    writeln!(w, "{MAGIC}").map_err(err)?;
    writeln!(w, "{}", header.to_json()).map_err(err)?;
    for (key, raw) in tiles {
        let mut enc = flate2::write::DeflateEncoder::new(Vec::new(), flate2::Compression::fast());
        enc.write_all(&raw).map_err(err)?;
        let packed = enc.finish().map_err(err)?;
        w.write_all(&key.to_bits().to_le_bytes()).map_err(err)?;
        w.write_all(&(packed.len() as u32).to_le_bytes())
            .map_err(err)?;
        w.write_all(&packed).map_err(err)?;
    }
    w.into_inner()
        .map_err(|e| TilerError::output(&path, e.error().to_string()))?
        .sync_all()
        .map_err(err)?;
    std::fs::rename(&tmp, &path).map_err(err)
}

/// Reads a shard's side file: its header and its hand-over tiles (raw samples).
pub fn read_handover(output: &Path) -> Result<(HandoverHeader, RawTiles)> {
    let path = handover_path(output);
    let file = globus_tiling::files::open_regular(&path).map_err(|e| {
        TilerError::bad_input(
            output,
            format!("is not a finished shard output ({}: {e})", path.display()),
        )
    })?;
    let mut r = BufReader::new(file);
    let truncated = || TilerError::bad_input(&path, "truncated shard hand-over file");
    let mut line = String::new();
    r.read_line(&mut line)
        .map_err(|e| TilerError::io(&path, e))?;
    if line.trim_end() != MAGIC {
        return Err(TilerError::bad_input(
            &path,
            "not a globus shard hand-over file",
        ));
    }
    line.clear();
    r.read_line(&mut line)
        .map_err(|e| TilerError::io(&path, e))?;
    let v: serde_json::Value = serde_json::from_str(&line)
        .map_err(|e| TilerError::bad_input(&path, format!("shard header: {e}")))?;
    let header = HandoverHeader::from_json(&path, &v)?;
    let mut tiles = Vec::new();
    loop {
        let mut k = [0u8; 8];
        match r.read_exact(&mut k) {
            Ok(()) => {}
            Err(e) if e.kind() == std::io::ErrorKind::UnexpectedEof => break,
            Err(e) => return Err(TilerError::io(&path, e)),
        }
        let key = TileKey::from_bits(u64::from_le_bytes(k)).ok_or_else(truncated)?;
        let mut l = [0u8; 4];
        r.read_exact(&mut l).map_err(|_| truncated())?;
        let len = u64::from(u32::from_le_bytes(l));
        let too_big = || {
            TilerError::bad_input(
                &path,
                format!("tile {key:?} is over {MAX_TILE_BYTES} bytes"),
            )
        };
        if len > MAX_TILE_BYTES {
            return Err(too_big());
        }
        let mut packed = vec![0u8; len as usize];
        r.read_exact(&mut packed).map_err(|_| truncated())?;
        let mut raw = Vec::new();
        flate2::read::DeflateDecoder::new(&packed[..])
            .take(MAX_TILE_BYTES + 1)
            .read_to_end(&mut raw)
            .map_err(|_| truncated())?;
        if raw.len() as u64 > MAX_TILE_BYTES {
            return Err(too_big());
        }
        tiles.push((key, raw));
    }
    Ok((header, tiles))
}

/// Every tile of a shard output (a directory or an MBTiles file).
fn read_tiles(
    output: &Path,
    header: &HandoverHeader,
    mut each: impl FnMut(TileKey, Vec<u8>) -> Result<()>,
) -> Result<()> {
    let scheme = header.meta.scheme;
    let is_mbtiles = output
        .extension()
        .and_then(|e| e.to_str())
        .is_some_and(|e| e.eq_ignore_ascii_case("mbtiles"));
    let key_of = |z: u8, x: u32, row: u32, tms: bool| -> Result<TileKey> {
        let key = if tms {
            scheme.from_tms(z, x, row)
        } else {
            scheme.key(z, x, row)
        };
        key.ok_or_else(|| {
            TilerError::bad_input(
                output,
                format!("holds a tile {z}/{x}/{row} outside the {scheme} scheme"),
            )
        })
    };
    if is_mbtiles {
        let db = rusqlite::Connection::open_with_flags(
            output,
            rusqlite::OpenFlags::SQLITE_OPEN_READ_ONLY,
        )
        .map_err(|e| TilerError::bad_input(output, e.to_string()))?;
        let mut stmt = db
            .prepare("SELECT zoom_level, tile_column, tile_row, tile_data FROM tiles")
            .map_err(|e| TilerError::bad_input(output, e.to_string()))?;
        let rows = stmt
            .query_map([], |r| {
                Ok((
                    r.get::<_, u8>(0)?,
                    r.get::<_, u32>(1)?,
                    r.get::<_, u32>(2)?,
                    r.get::<_, Vec<u8>>(3)?,
                ))
            })
            .map_err(|e| TilerError::bad_input(output, e.to_string()))?;
        for row in rows {
            let (z, x, y, data) = row.map_err(|e| TilerError::bad_input(output, e.to_string()))?;
            each(key_of(z, x, y, true)?, data)?;
        }
        return Ok(());
    }
    let tms = header.layout == TileLayout::Tms;
    let list = |dir: &Path| -> Result<Vec<(String, PathBuf)>> {
        let mut v: Vec<(String, PathBuf)> = std::fs::read_dir(dir)
            .map_err(|e| TilerError::io(dir, e))?
            .filter_map(|e| e.ok())
            .map(|e| (e.file_name().to_string_lossy().into_owned(), e.path()))
            .collect();
        v.sort();
        Ok(v)
    };
    for (z_name, z_dir) in list(output)? {
        let Ok(z) = z_name.parse::<u8>() else {
            continue;
        };
        for (x_name, x_dir) in list(&z_dir)? {
            let Ok(x) = x_name.parse::<u32>() else {
                continue;
            };
            for (y_name, file) in list(&x_dir)? {
                let Some(y) = y_name.split('.').next().and_then(|y| y.parse::<u32>().ok()) else {
                    continue;
                };
                let data = globus_tiling::files::read_capped(&file, MAX_TILE_BYTES)
                    .map_err(|e| TilerError::io(&file, e))?;
                each(key_of(z, x, y, tms)?, data)?;
            }
        }
    }
    Ok(())
}

/// The hand-over tiles as the finest level of the top of the pyramid.
struct HandoverLayer<C: TileCodec> {
    codec: C,
    tiles: FxHashMap<TileKey, C::Tile>,
}

impl<C: TileCodec> Layer for HandoverLayer<C> {
    type Codec = C;

    fn codec(&self) -> &C {
        &self.codec
    }

    fn leaf(&self, _scheme: TilingScheme, key: TileKey) -> Result<C::Tile> {
        self.tiles
            .get(&key)
            .cloned()
            .ok_or_else(|| TilerError::BadOptions(format!("no shard handed over tile {key:?}")))
    }
}

/// Options of `globus tile merge`.
#[derive(Clone, Debug)]
pub struct MergeJob {
    /// The shard outputs.
    pub inputs: Vec<PathBuf>,
    /// The merged archive.
    pub output: PathBuf,
    /// Replace an existing output.
    pub force: bool,
    /// Worker threads for the top levels (0: all cores).
    pub threads: usize,
}

/// Joins shard outputs into one archive and builds the levels above the hand-over level.
pub fn merge(job: &MergeJob) -> Result<Summary> {
    merge_with_progress(job, &|_| {})
}

/// [`merge`], calling `on_progress` with the levels it builds as it goes.
pub fn merge_with_progress(job: &MergeJob, on_progress: &ProgressFn<'_>) -> Result<Summary> {
    let start = Instant::now();
    let _lock = crate::sink::OutputLock::take(&job.output)?;
    let mut headers: Vec<HandoverHeader> = Vec::new();
    let mut handed: Vec<(TileKey, Vec<u8>)> = Vec::new();
    for input in &job.inputs {
        let (h, tiles) = read_handover(input)?;
        if let Some(first) = headers.first()
            && !first.same_job(&h)
        {
            return Err(TilerError::bad_input(
                input,
                format!(
                    "is a shard of a different job than {}",
                    job.inputs[0].display()
                ),
            ));
        }
        if headers.iter().any(|o| o.shard.index == h.shard.index) {
            return Err(TilerError::bad_input(
                input,
                format!("shard {}/{} is given twice", h.shard.index, h.shard.count),
            ));
        }
        headers.push(h);
        handed.extend(tiles);
    }
    let Some(head) = headers.first().cloned() else {
        return Err(TilerError::BadOptions(
            "no shard outputs given to merge".into(),
        ));
    };
    let missing: Vec<String> = (0..head.shard.count)
        .filter(|k| !headers.iter().any(|h| h.shard.index == *k))
        .map(|k| k.to_string())
        .collect();
    if !missing.is_empty() {
        return Err(TilerError::BadOptions(format!(
            "shards {} of {} are missing",
            missing.join(", "),
            head.shard.count
        )));
    }
    let size = head.meta.tile_size;
    match head.meta.encoding.as_deref() {
        Some(enc) => {
            let encoding = ElevationEncoding::parse(enc).ok_or_else(|| {
                TilerError::bad_input(&job.inputs[0], format!("unknown encoding {enc}"))
            })?;
            merge_with(
                job,
                &head,
                ElevationCodec { size, encoding },
                (handed, start),
                on_progress,
            )
        }
        None => {
            let format = ImageFormat::parse(&head.meta.format, head.jpeg_quality.unwrap_or(85))
                .ok_or_else(|| {
                    TilerError::bad_input(
                        &job.inputs[0],
                        format!("unknown format {}", head.meta.format),
                    )
                })?;
            merge_with(
                job,
                &head,
                ImageryCodec { size, format },
                (handed, start),
                on_progress,
            )
        }
    }
}

fn merge_with<C: TileCodec>(
    job: &MergeJob,
    head: &HandoverHeader,
    codec: C,
    (handed, start): (Vec<(TileKey, Vec<u8>)>, Instant),
    on_progress: &ProgressFn<'_>,
) -> Result<Summary> {
    let scheme = head.meta.scheme;
    let sink = OutputSink::open(
        &job.output,
        OutputOptions {
            scheme,
            layout: head.layout,
            extension: codec.extension(),
            force: job.force,
            resume: false,
        },
    )?;
    let progress = Progress::default();
    let (mut copied, mut bytes) = (0u64, 0u64);
    for input in &job.inputs {
        read_tiles(input, head, |key, data| {
            copied += 1;
            bytes += data.len() as u64;
            sink.as_dyn().put(key, &data)
        })?;
    }
    let mut tiles = FxHashMap::default();
    for (key, raw) in handed {
        tiles.insert(key, codec.raw_to_tile(key, &raw)?);
    }
    let (min, split) = (head.meta.min_level, head.split_level);
    if split > min {
        let layer = HandoverLayer { codec, tiles };
        let pyramid = Pyramid {
            layer: &layer,
            sink: sink.as_dyn(),
            scheme,
            footprint: head.footprint,
            closed: head.closed,
            starts: scheme.roots().to_vec(),
            write_levels: (min, split - 1),
            max_level: split,
            resume: false,
            handover: None,
            progress: &progress,
        };
        run_pyramid(&pyramid, job.threads, on_progress)?;
    }
    sink.finish(&head.meta)?;
    let built = progress.written.load(std::sync::atomic::Ordering::Relaxed);
    Ok(Summary {
        tiles: copied + built,
        tiles_reused: 0,
        bytes: bytes + progress.bytes.load(std::sync::atomic::Ordering::Relaxed),
        seconds: start.elapsed().as_secs_f64(),
        levels: (min, head.meta.max_level),
        voids_filled: 0,
    })
}

#[cfg(test)]
mod tests {
    use super::*;

    fn env<'a>(vars: &'a [(&'a str, &'a str)]) -> impl Fn(&str) -> Option<String> + 'a {
        move |k| {
            vars.iter()
                .find(|(n, _)| *n == k)
                .map(|(_, v)| v.to_string())
        }
    }

    #[test]
    fn shard_specs_come_from_arguments_or_the_scheduler() {
        assert_eq!(
            ShardSpec::parse("2/8", env(&[])).unwrap(),
            ShardSpec { index: 2, count: 8 }
        );
        assert_eq!(
            ShardSpec::parse("8", env(&[("JOB_COMPLETION_INDEX", "5")]))
                .unwrap()
                .index,
            5
        );
        let slurm = [("SLURM_ARRAY_TASK_ID", "4"), ("SLURM_ARRAY_TASK_MIN", "1")];
        assert_eq!(ShardSpec::parse("8", env(&slurm)).unwrap().index, 3);
        assert!(ShardSpec::parse("8/8", env(&[])).is_err());
        assert!(ShardSpec::parse("8", env(&[])).is_err());
        assert!(ShardSpec::parse("x/2", env(&[])).is_err());
        // 4e9 shards took 96 GB to plan: refused at once.
        let e = ShardSpec::parse("0/4000000000", env(&[]))
            .unwrap_err()
            .to_string();
        assert!(e.contains("4000000000") && e.contains("10000"), "{e}");
        assert!(ShardSpec::parse("0/10000", env(&[])).is_ok());
    }

    #[test]
    fn plans_share_the_work_evenly_and_completely() {
        let fp = GeoRect::from_degrees(-180.0, -90.0, 180.0, 90.0);
        let p = plan(TilingScheme::Geographic, &fp, false, (0, 8), 5);
        assert_eq!(
            p.split_level, 3,
            "first level with 16 x 5 tiles: 128 at level 3"
        );
        let mut all: Vec<TileKey> = p.shards.iter().flatten().copied().collect();
        all.sort_unstable();
        all.dedup();
        assert_eq!(all.len(), 128);
        let total: u64 = p.tiles.iter().sum();
        assert_eq!(
            total + p.merge_tiles,
            (0..=8).map(|l| 2u64 << (2 * l)).sum::<u64>()
        );
        let (lo, hi) = (p.tiles.iter().min().unwrap(), p.tiles.iter().max().unwrap());
        assert!((*hi as f64) < (*lo as f64) * 1.1, "{:?}", p.tiles);
        // A small footprint: fewer tiles than shards at every level is still a valid plan.
        let small = GeoRect::from_degrees(11.0, 57.0, 12.0, 58.0);
        let p = plan(TilingScheme::Geographic, &small, false, (0, 3), 4);
        assert_eq!(p.split_level, 3);
        assert_eq!(p.shards.iter().flatten().count(), 1);
    }
}
