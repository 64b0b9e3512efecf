//! MBTiles 1.3: tiles in an SQLite file, rows counted from the south (TMS).
//!
//! Opened read-only; each loader thread borrows its own connection from a small pool
//! (SQLite connections are not shared between threads).

use std::path::{Path, PathBuf};
use std::sync::Mutex;

use globus_tiling::{TileKey, TilingScheme};
use rusqlite::{Connection, OpenFlags, OptionalExtension};
use rustc_hash::FxHashMap;

use super::{Cancel, Fetch, FetchError, Fetched, OpenError};

/// Reads tiles from an MBTiles file.
pub struct MbTilesFetch {
    path: PathBuf,
    name: String,
    scheme: TilingScheme,
    idle: Mutex<Vec<Connection>>,
    metadata: FxHashMap<String, String>,
}

fn open(path: &Path) -> Result<Connection, OpenError> {
    Connection::open_with_flags(
        path,
        OpenFlags::SQLITE_OPEN_READ_ONLY | OpenFlags::SQLITE_OPEN_NO_MUTEX,
    )
    .map_err(|e| OpenError::Unreadable(format!("MBTiles {}: {e}", path.display())))
}

impl MbTilesFetch {
    /// Opens `path`. The scheme is the file's `scheme` metadata row if it names one of ours
    /// (`globus tile` writes it), else Web Mercator, as the MBTiles specification says.
    pub fn open(path: &Path) -> Result<Self, OpenError> {
        if !path.is_file() {
            return Err(OpenError::Unreadable(format!(
                "MBTiles {}: no such file",
                path.display()
            )));
        }
        let conn = open(path)?;
        let err =
            |e: rusqlite::Error| OpenError::Invalid(format!("MBTiles {}: {e}", path.display()));
        let metadata: FxHashMap<String, String> = {
            let mut stmt = conn
                .prepare("SELECT name, value FROM metadata")
                .map_err(err)?;
            let rows = stmt
                .query_map([], |r| Ok((r.get::<_, String>(0)?, r.get::<_, String>(1)?)))
                .map_err(err)?;
            rows.filter_map(Result::ok).collect()
        };
        conn.prepare("SELECT tile_data FROM tiles LIMIT 0")
            .map_err(err)?;
        let scheme = metadata
            .get("scheme")
            .and_then(|s| s.parse().ok())
            .unwrap_or(TilingScheme::WebMercator);
        Ok(Self {
            path: path.to_path_buf(),
            name: path.display().to_string(),
            scheme,
            idle: Mutex::new(vec![conn]),
            metadata,
        })
    }

    /// The tiling scheme of the file.
    pub fn scheme(&self) -> TilingScheme {
        self.scheme
    }

    /// The `metadata` table.
    pub fn metadata(&self) -> &FxHashMap<String, String> {
        &self.metadata
    }
}

impl Fetch for MbTilesFetch {
    fn name(&self) -> &str {
        &self.name
    }

    fn fetch(&self, key: TileKey, _cancel: &Cancel) -> Result<Option<Fetched>, FetchError> {
        let conn = self.idle.lock().unwrap_or_else(|p| p.into_inner()).pop();
        let conn = match conn {
            Some(c) => c,
            None => open(&self.path).map_err(|e| FetchError::transient(e.to_string()))?,
        };
        let row = self.scheme.tms_y(key);
        let got: Result<Option<Vec<u8>>, _> = conn
            .prepare_cached(
                "SELECT tile_data FROM tiles WHERE zoom_level = ?1 AND tile_column = ?2 AND tile_row = ?3",
            )
            .and_then(|mut s| {
                s.query_row((key.level(), key.x(), row), |r| r.get(0))
                    .optional()
            });
        self.idle
            .lock()
            .unwrap_or_else(|p| p.into_inner())
            .push(conn);
        match got {
            Ok(Some(b)) if !b.is_empty() => Ok(Some(Fetched::local(b))),
            Ok(_) => Ok(None),
            Err(e) => Err(FetchError::Permanent(format!(
                "{} tile {key}: {e}",
                self.name
            ))),
        }
    }
}
