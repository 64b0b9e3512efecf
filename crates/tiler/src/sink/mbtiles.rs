//! MBTiles 1.3: one SQLite file with `metadata` and `tiles` (rows counted from the south,
//! as TMS). Tiles go into `FILE.partial`; [`MbTilesSink::finish`] writes the metadata and
//! then copies the database in key order (`VACUUM INTO`) to the final name, so the file is
//! byte-identical whatever order the threads wrote tiles in, and only a finished archive
//! ever carries the final name.

use std::path::{Path, PathBuf};
use std::sync::Mutex;

use globus_tiling::{TileKey, TilingScheme};
use rusqlite::{Connection, OptionalExtension, params};

use super::{PyramidMetadata, TileSink, with_suffix};
use crate::error::{Result, TilerError};

/// Writes tiles into an MBTiles file.
pub struct MbTilesSink {
    path: PathBuf,
    partial: PathBuf,
    scheme: TilingScheme,
    db: Mutex<Connection>,
}

impl MbTilesSink {
    /// Starts `path` (through `path.partial`). With `resume`, an earlier run's tiles are
    /// kept and reused.
    pub fn create(path: &Path, scheme: TilingScheme, resume: bool) -> Result<Self> {
        let partial = with_suffix(path, ".partial");
        let err = |e: &dyn std::fmt::Display| TilerError::output(path, e);
        if resume && path.exists() && !partial.exists() {
            std::fs::rename(path, &partial).map_err(|e| err(&e))?;
        } else if !resume {
            for p in [&partial, path] {
                match std::fs::remove_file(p) {
                    Ok(()) => {}
                    Err(e) if e.kind() == std::io::ErrorKind::NotFound => {}
                    Err(e) => return Err(err(&e)),
                }
            }
        }
        let db = Connection::open(&partial).map_err(|e| err(&e))?;
        db.execute_batch(
            "PRAGMA journal_mode = OFF;
             PRAGMA synchronous = OFF;
             CREATE TABLE IF NOT EXISTS metadata (name TEXT NOT NULL PRIMARY KEY, value TEXT);
             CREATE TABLE IF NOT EXISTS tiles (
                 zoom_level INTEGER NOT NULL,
                 tile_column INTEGER NOT NULL,
                 tile_row INTEGER NOT NULL,
                 tile_data BLOB NOT NULL,
                 PRIMARY KEY (zoom_level, tile_column, tile_row)
             ) WITHOUT ROWID;
             BEGIN;",
        )
        .map_err(|e| err(&e))?;
        Ok(Self {
            path: path.to_owned(),
            partial,
            scheme,
            db: Mutex::new(db),
        })
    }

    /// Writes the metadata and moves the finished archive to its final name.
    pub fn finish(self, meta: &PyramidMetadata) -> Result<()> {
        let err = |e: &dyn std::fmt::Display| TilerError::output(&self.path, e);
        let db = self
            .db
            .into_inner()
            .map_err(|_| err(&"a writer thread panicked"))?;
        let [w, s, e, n] = meta.bounds.to_degrees();
        let centre_zoom = meta
            .min_level
            .max(meta.max_level.saturating_sub(2).min(meta.max_level));
        let json = meta.to_json();
        let mut rows: Vec<(&str, String)> = vec![
            ("name", meta.name.clone()),
            ("format", meta.format.clone()),
            ("bounds", format!("{w:.6},{s:.6},{e:.6},{n:.6}")),
            (
                "center",
                format!("{:.6},{:.6},{centre_zoom}", (w + e) * 0.5, (s + n) * 0.5),
            ),
            ("minzoom", meta.min_level.to_string()),
            ("maxzoom", meta.max_level.to_string()),
            ("type", "baselayer".into()),
            ("version", "1.0".into()),
            (
                "description",
                format!(
                    "{} pyramid by globus, {} scheme",
                    meta.kind,
                    meta.scheme.name()
                ),
            ),
            ("scheme", meta.scheme.name().into()),
            ("crs", json["crs"].as_str().unwrap_or_default().into()),
            ("tile_size", meta.tile_size.to_string()),
            ("sample_grid", meta.sample_grid.clone()),
        ];
        if let Some(enc) = &meta.encoding {
            rows.push(("encoding", enc.clone()));
        }
        {
            let mut stmt = db
                .prepare("INSERT OR REPLACE INTO metadata (name, value) VALUES (?1, ?2)")
                .map_err(|e| err(&e))?;
            for (k, v) in &rows {
                stmt.execute(params![k, v]).map_err(|e| err(&e))?;
            }
        }
        db.execute_batch("COMMIT;").map_err(|e| err(&e))?;
        let staging = with_suffix(&self.path, ".vacuum");
        let _ = std::fs::remove_file(&staging);
        db.execute("VACUUM INTO ?1", params![staging.to_string_lossy()])
            .map_err(|e| err(&e))?;
        drop(db);
        std::fs::rename(&staging, &self.path).map_err(|e| err(&e))?;
        std::fs::remove_file(&self.partial).map_err(|e| err(&e))?;
        Ok(())
    }
}

impl MbTilesSink {
    /// Runs `f` on the database, naming `key` in any error.
    fn with_db<T>(
        &self,
        key: TileKey,
        f: impl FnOnce(&Connection) -> rusqlite::Result<T>,
    ) -> Result<T> {
        let db = self
            .db
            .lock()
            .map_err(|_| TilerError::output(&self.partial, "a writer thread panicked"))?;
        f(&db).map_err(|e| TilerError::output(&self.partial, format!("tile {key:?}: {e}")))
    }
}

impl TileSink for MbTilesSink {
    fn put(&self, key: TileKey, bytes: &[u8]) -> Result<()> {
        let row = self.scheme.tms_y(key);
        self.with_db(key, |db| {
            db.prepare_cached(
                "INSERT OR REPLACE INTO tiles (zoom_level, tile_column, tile_row, tile_data) \
                 VALUES (?1, ?2, ?3, ?4)",
            )?
            .execute(params![key.level(), key.x(), row, bytes])
        })?;
        Ok(())
    }

    fn existing(&self, key: TileKey) -> Result<Option<Vec<u8>>> {
        let row = self.scheme.tms_y(key);
        self.with_db(key, |db| {
            db.prepare_cached(
                "SELECT tile_data FROM tiles \
                 WHERE zoom_level = ?1 AND tile_column = ?2 AND tile_row = ?3",
            )?
            .query_row(params![key.level(), key.x(), row], |r| {
                r.get::<_, Vec<u8>>(0)
            })
            .optional()
        })
    }
}
