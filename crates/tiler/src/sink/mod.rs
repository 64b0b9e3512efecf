//! Where tiles go: a directory tree, an MBTiles file or a PMTiles archive. Every container is written under a
//! temporary name or without its completion marker until [`TileSink::finish`], so an
//! interrupted run never leaves output that looks complete.

pub mod dir;
pub mod mbtiles;
pub mod pmtiles;

pub use dir::{DirSink, TileLayout};
pub use mbtiles::MbTilesSink;
pub use pmtiles::PmTilesSink;

use std::path::{Path, PathBuf};

use globus_tiling::{GeoRect, TileKey, TilingScheme};

use crate::error::{Result, TilerError};

/// What is known about a finished pyramid, written into the container's metadata.
#[derive(Clone, Debug)]
pub struct PyramidMetadata {
    /// Human-readable name (the input file stem).
    pub name: String,
    /// Tile file extension / format: `png`, `jpg` or `webp`.
    pub format: String,
    /// `elevation` or `imagery`.
    pub kind: String,
    /// The elevation encoding, for elevation pyramids.
    pub encoding: Option<String>,
    /// The tiling scheme.
    pub scheme: TilingScheme,
    /// Samples per tile side.
    pub tile_size: usize,
    /// `corners` (samples on tile edges, shared with neighbours) or `cells`.
    pub sample_grid: String,
    /// The data's extent.
    pub bounds: GeoRect,
    /// Coarsest level written.
    pub min_level: u8,
    /// Finest level written.
    pub max_level: u8,
}

impl PyramidMetadata {
    /// The metadata as JSON (also the content of a directory's `metadata.json`).
    pub fn to_json(&self) -> serde_json::Value {
        let [w, s, e, n] = self.bounds.to_degrees();
        serde_json::json!({
            "name": self.name,
            "format": self.format,
            "type": self.kind,
            "encoding": self.encoding,
            "scheme": self.scheme.name(),
            "crs": match self.scheme {
                TilingScheme::Geographic | TilingScheme::GeographicReduced => "EPSG:4326",
                TilingScheme::WebMercator => "EPSG:3857",
            },
            "tile_size": self.tile_size,
            "sample_grid": self.sample_grid,
            "bounds": [w, s, e, n],
            "minzoom": self.min_level,
            "maxzoom": self.max_level,
            "generator": concat!("globus ", env!("CARGO_PKG_VERSION")),
        })
    }
}

/// `path` with `suffix` appended to its file name (`a.mbtiles` -> `a.mbtiles.partial`).
pub(crate) fn with_suffix(path: &Path, suffix: &str) -> std::path::PathBuf {
    let mut s = path.as_os_str().to_owned();
    s.push(suffix);
    s.into()
}

/// A destination for encoded tiles, shared by the worker threads.
pub trait TileSink: Sync {
    /// Stores one tile.
    fn put(&self, key: TileKey, bytes: &[u8]) -> Result<()>;
    /// The bytes of a tile already stored (by an earlier, interrupted run), for `--resume`.
    fn existing(&self, key: TileKey) -> Result<Option<Vec<u8>>>;
}

/// An open output of any kind.
pub enum OutputSink {
    /// A directory tree.
    Dir(DirSink),
    /// An MBTiles file.
    MbTiles(MbTilesSink),
    /// A PMTiles archive.
    PmTiles(PmTilesSink),
}

impl OutputSink {
    /// The sink as a trait object for the workers.
    pub fn as_dyn(&self) -> &dyn TileSink {
        match self {
            OutputSink::Dir(d) => d,
            OutputSink::MbTiles(m) => m,
            OutputSink::PmTiles(p) => p,
        }
    }

    /// Finishes the container (metadata, final name).
    pub fn finish(self, meta: &PyramidMetadata) -> Result<()> {
        match self {
            OutputSink::Dir(d) => d.finish(meta),
            OutputSink::MbTiles(m) => m.finish(meta),
            OutputSink::PmTiles(p) => p.finish(meta),
        }
    }
}

/// How to open an output.
#[derive(Clone, Copy, Debug)]
pub struct OutputOptions {
    /// The tiling scheme of the tiles.
    pub scheme: TilingScheme,
    /// Row order of directory output.
    pub layout: TileLayout,
    /// File extension of the tiles (directory output).
    pub extension: &'static str,
    /// Replace an existing output.
    pub force: bool,
    /// Continue an existing output.
    pub resume: bool,
}

impl OutputSink {
    /// Opens `out` by its name: `*.mbtiles`, `*.pmtiles`, else a directory. An existing
    /// output is refused unless `force` (replace) or `resume` (continue).
    pub fn open(out: &Path, o: OutputOptions) -> Result<Self> {
        let ext = out
            .extension()
            .and_then(|e| e.to_str())
            .map(str::to_ascii_lowercase)
            .unwrap_or_default();
        let exists = out.symlink_metadata().is_ok();
        if exists && !o.force && !o.resume {
            return Err(TilerError::output(
                out,
                "already exists; pass --force to replace it or --resume to continue it",
            ));
        }
        if exists {
            check_replaceable(out, &ext)?;
        }
        match ext.as_str() {
            "mbtiles" => Ok(OutputSink::MbTiles(MbTilesSink::create(
                out, o.scheme, o.resume,
            )?)),
            "pmtiles" => {
                if o.resume {
                    return Err(TilerError::output(
                        out,
                        "--resume works with directory and MBTiles output, not PMTiles",
                    ));
                }
                Ok(OutputSink::PmTiles(PmTilesSink::create(out, o.scheme)?))
            }
            _ => {
                if exists && o.force && !o.resume {
                    remove_tile_dir(out)?;
                }
                Ok(OutputSink::Dir(DirSink::create(
                    out,
                    o.scheme,
                    o.layout,
                    o.extension,
                )?))
            }
        }
    }
}

/// An exclusive hold on an output for one run: `OUT.lock` beside it, locked (advisory, by the
/// operating system, so a killed run lets go). A second `globus tile` writing the same output
/// is refused at once instead of failing at its end with "disk I/O error".
pub struct OutputLock {
    _file: std::fs::File,
    path: PathBuf,
}

impl OutputLock {
    /// Takes the lock on `out`, or says which output is busy.
    pub fn take(out: &Path) -> Result<Self> {
        let path = with_suffix(out, ".lock");
        // The folder the output goes in, as the sinks make it.
        if let Some(parent) = out.parent().filter(|p| !p.as_os_str().is_empty()) {
            std::fs::create_dir_all(parent).map_err(|e| TilerError::output(parent, e))?;
        }
        let file = std::fs::OpenOptions::new()
            .write(true)
            .create(true)
            .truncate(false)
            .open(&path)
            .map_err(|e| TilerError::output(&path, e))?;
        match file.try_lock() {
            Ok(()) => Ok(Self { _file: file, path }),
            Err(std::fs::TryLockError::WouldBlock) => Err(TilerError::output(
                out,
                format!(
                    "another globus tile is writing it (it holds {}); wait for it or choose another --out",
                    path.display()
                ),
            )),
            Err(std::fs::TryLockError::Error(e)) => Err(TilerError::output(&path, e)),
        }
    }
}

impl Drop for OutputLock {
    fn drop(&mut self) {
        let _ = std::fs::remove_file(&self.path);
    }
}

/// What `--force` may replace: an MBTiles or PMTiles archive (by its first bytes, not its
/// name) or a pyramid directory; never a device, a FIFO or an unrelated file (as root,
/// `--out /dev/null --force` deleted `/dev/null`).
fn check_replaceable(out: &Path, kind: &str) -> Result<()> {
    let meta = std::fs::symlink_metadata(out).map_err(|e| TilerError::output(out, e))?;
    let refuse = |what: &str| {
        Err(TilerError::output(
            out,
            format!("--force refuses to replace it: {what}"),
        ))
    };
    if meta.file_type().is_symlink() {
        return refuse("it is a symbolic link");
    }
    let magic: &[u8] = match kind {
        "mbtiles" => b"SQLite format 3\0",
        "pmtiles" => b"PMTiles",
        _ if meta.is_dir() => return Ok(()),
        _ => return refuse("it is not a directory, so not a tile pyramid"),
    };
    if !meta.is_file() {
        return refuse("it is not a regular file (a device, FIFO or directory)");
    }
    let mut head = vec![0u8; magic.len()];
    let read =
        std::fs::File::open(out).and_then(|mut f| std::io::Read::read_exact(&mut f, &mut head));
    if read.is_err() || head != magic {
        return refuse(&format!("it is not an {} archive", kind.to_uppercase()));
    }
    Ok(())
}

/// Removes a directory for `--force`, but only one that holds nothing but a pyramid
/// (numbered level directories and `metadata.json`): a mistyped `--out ~` must not
/// delete a home directory.
fn remove_tile_dir(dir: &Path) -> Result<()> {
    let entries = std::fs::read_dir(dir).map_err(|e| TilerError::output(dir, e))?;
    for entry in entries {
        let entry = entry.map_err(|e| TilerError::output(dir, e))?;
        let name = entry.file_name();
        let name = name.to_string_lossy();
        let is_level = name.parse::<u8>().is_ok() && entry.path().is_dir();
        if !(is_level || name == dir::METADATA_FILE) {
            return Err(TilerError::output(
                dir,
                format!("--force refuses to delete it: {name} is not part of a tile pyramid"),
            ));
        }
    }
    std::fs::remove_dir_all(dir).map_err(|e| TilerError::output(dir, e))
}
