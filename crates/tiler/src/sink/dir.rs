//! A directory tree `{z}/{x}/{y}.{ext}` with `metadata.json` written last.

use std::path::{Path, PathBuf};

use globus_tiling::{TileKey, TilingScheme};

use super::{PyramidMetadata, TileSink};
use crate::error::{Result, TilerError};

/// Row numbering of a directory tree.
#[derive(Clone, Copy, Debug, PartialEq, Eq)]
pub enum TileLayout {
    /// Row 0 at the north (XYZ, slippy map).
    Xyz,
    /// Row 0 at the south (TMS).
    Tms,
}

/// Writes tiles as files. A run interrupted mid-write can leave a truncated tile; `--resume`
/// rebuilds any tile it cannot decode, and only a finished run writes `metadata.json`.
pub struct DirSink {
    root: PathBuf,
    scheme: TilingScheme,
    layout: TileLayout,
    extension: &'static str,
}

/// The file that marks a finished directory pyramid.
pub const METADATA_FILE: &str = "metadata.json";

impl DirSink {
    /// A sink writing under `root` (created if missing).
    pub fn create(
        root: &Path,
        scheme: TilingScheme,
        layout: TileLayout,
        extension: &'static str,
    ) -> Result<Self> {
        std::fs::create_dir_all(root).map_err(|e| TilerError::output(root, e))?;
        // An unfinished run must not look finished.
        match std::fs::remove_file(root.join(METADATA_FILE)) {
            Ok(()) => {}
            Err(e) if e.kind() == std::io::ErrorKind::NotFound => {}
            Err(e) => return Err(TilerError::output(root.join(METADATA_FILE), e)),
        }
        Ok(Self {
            root: root.to_owned(),
            scheme,
            layout,
            extension,
        })
    }

    /// The path of a tile's file.
    pub fn tile_path(&self, key: TileKey) -> PathBuf {
        let y = match self.layout {
            TileLayout::Xyz => key.y(),
            TileLayout::Tms => self.scheme.tms_y(key),
        };
        self.root
            .join(key.level().to_string())
            .join(key.x().to_string())
            .join(format!("{y}.{}", self.extension))
    }

    /// Writes `metadata.json`, marking the pyramid complete.
    pub fn finish(self, meta: &PyramidMetadata) -> Result<()> {
        let mut json = meta.to_json();
        json["layout"] = serde_json::Value::from(match self.layout {
            TileLayout::Xyz => "xyz",
            TileLayout::Tms => "tms",
        });
        let path = self.root.join(METADATA_FILE);
        let text = serde_json::to_string_pretty(&json).unwrap_or_default();
        write_atomically(&path, text.as_bytes())
    }
}

fn write_atomically(path: &Path, bytes: &[u8]) -> Result<()> {
    let tmp = super::with_suffix(path, ".tmp");
    std::fs::write(&tmp, bytes).map_err(|e| {
        let _ = std::fs::remove_file(&tmp);
        TilerError::output(path, e)
    })?;
    std::fs::rename(&tmp, path).map_err(|e| TilerError::output(path, e))
}

impl TileSink for DirSink {
    fn put(&self, key: TileKey, bytes: &[u8]) -> Result<()> {
        let path = self.tile_path(key);
        if let Some(dir) = path.parent() {
            std::fs::create_dir_all(dir).map_err(|e| TilerError::output(dir, e))?;
        }
        std::fs::write(&path, bytes).map_err(|e| TilerError::output(&path, e))
    }

    fn existing(&self, key: TileKey) -> Result<Option<Vec<u8>>> {
        let path = self.tile_path(key);
        match globus_tiling::files::read_capped(&path, globus_tiling::files::MAX_TILE_BYTES) {
            Ok(b) => Ok(Some(b)),
            Err(e) if e.kind() == std::io::ErrorKind::NotFound => Ok(None),
            Err(e) => Err(TilerError::output(&path, e)),
        }
    }
}
