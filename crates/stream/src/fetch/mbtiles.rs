//! MBTiles 1.3: tiles in an SQLite file, rows counted from the south (TMS).
//!
//! Opened read-only; each loader thread borrows its own connection from a small pool
//! (SQLite connections are not shared between threads). Nothing in the file is trusted: a
//! query that runs longer than [`QUERY_LIMIT`] (a `tiles` view over an endless recursive
//! query) is interrupted by SQLite's progress handler, and a blob larger than
//! [`MAX_TILE_BYTES`] is refused without being read.

use std::path::{Path, PathBuf};
use std::sync::atomic::{AtomicU64, Ordering};
use std::sync::{Arc, Mutex, OnceLock};
use std::time::{Duration, Instant};

use globus_tiling::files::MAX_TILE_BYTES;
use globus_tiling::{TileKey, TilingScheme};
use rusqlite::{Connection, OpenFlags, OptionalExtension};
use rustc_hash::FxHashMap;

use super::{Cancel, Fetch, FetchError, Fetched, OpenError};

/// Reads tiles from an MBTiles file.
pub struct MbTilesFetch {
    path: PathBuf,
    name: String,
    scheme: TilingScheme,
    idle: Mutex<Vec<Guarded>>,
    metadata: FxHashMap<String, String>,
}

/// A tile's blob (`None` when larger than a tile may be) and its length.
type BlobRow = (Option<Vec<u8>>, i64);

/// The longest one query may run before SQLite interrupts it.
pub const QUERY_LIMIT: Duration = Duration::from_secs(5);

/// Milliseconds since the first call: the clock the progress handlers read.
fn now_ms() -> u64 {
    static START: OnceLock<Instant> = OnceLock::new();
    START.get_or_init(Instant::now).elapsed().as_millis() as u64
}

/// A connection whose queries are interrupted past their deadline.
struct Guarded {
    conn: Connection,
    deadline_ms: Arc<AtomicU64>,
}

impl Guarded {
    /// The connection, its next query allowed [`QUERY_LIMIT`] from now.
    fn start(&self) -> &Connection {
        self.deadline_ms
            .store(now_ms() + QUERY_LIMIT.as_millis() as u64, Ordering::Relaxed);
        &self.conn
    }
}

fn open(path: &Path) -> Result<Guarded, OpenError> {
    let conn = Connection::open_with_flags(
        path,
        OpenFlags::SQLITE_OPEN_READ_ONLY | OpenFlags::SQLITE_OPEN_NO_MUTEX,
    )
    .map_err(|e| OpenError::Unreadable(format!("MBTiles {}: {e}", path.display())))?;
    let deadline_ms = Arc::new(AtomicU64::new(u64::MAX));
    let d = deadline_ms.clone();
    // Every 10,000 virtual-machine steps (well under a millisecond).
    conn.progress_handler(10_000, Some(move || now_ms() > d.load(Ordering::Relaxed)));
    Ok(Guarded { conn, deadline_ms })
}

/// An SQLite error, saying so when it was the time limit that stopped the query.
fn sql_error(name: &str, what: &str, e: rusqlite::Error) -> String {
    if e.sqlite_error_code() == Some(rusqlite::ErrorCode::OperationInterrupted) {
        format!(
            "MBTiles {name}: {what}: stopped after {} s (a view over an endless query?)",
            QUERY_LIMIT.as_secs()
        )
    } else {
        format!("MBTiles {name}: {what}: {e}")
    }
}

impl MbTilesFetch {
    /// Opens `path`. The scheme is the file's `scheme` metadata row if it names one of ours
    /// (`globus tile` writes it), else Web Mercator, as the MBTiles specification says.
    pub fn open(path: &Path) -> Result<Self, OpenError> {
        let name = path.display().to_string();
        // Only a regular file (SQLite would block on a FIFO).
        globus_tiling::files::open_regular(path)
            .map_err(|e| OpenError::Unreadable(format!("MBTiles {name}: {e}")))?;
        let guarded = open(path)?;
        let err = |what: &str| {
            let name = name.clone();
            let what = what.to_string();
            move |e: rusqlite::Error| OpenError::Invalid(sql_error(&name, &what, e))
        };
        let conn = guarded.start();
        let metadata: FxHashMap<String, String> = {
            let mut stmt = conn
                .prepare("SELECT name, value FROM metadata LIMIT 10000")
                .map_err(err("metadata"))?;
            let rows = stmt
                .query_map([], |r| Ok((r.get::<_, String>(0)?, r.get::<_, String>(1)?)))
                .map_err(err("metadata"))?;
            let mut m = FxHashMap::default();
            for row in rows {
                let (k, v) = row.map_err(err("metadata"))?;
                m.insert(k, v);
            }
            m
        };
        conn.prepare("SELECT tile_data FROM tiles LIMIT 0")
            .map_err(err("tiles"))?;
        let scheme = match metadata.get("scheme") {
            None => None,
            Some(s) => TilingScheme::parse_container(s)
                .map_err(|e| OpenError::Invalid(format!("MBTiles {name}: metadata scheme: {e}")))?,
        }
        .unwrap_or(TilingScheme::WebMercator);
        Ok(Self {
            path: path.to_path_buf(),
            name: path.display().to_string(),
            scheme,
            idle: Mutex::new(vec![guarded]),
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
        // The blob is read only when it is no larger than a tile may be.
        let got: Result<Option<BlobRow>, _> = conn
            .start()
            .prepare_cached(
                "SELECT CASE WHEN length(tile_data) <= ?4 THEN tile_data END, length(tile_data) \
                 FROM tiles WHERE zoom_level = ?1 AND tile_column = ?2 AND tile_row = ?3 LIMIT 1",
            )
            .and_then(|mut s| {
                s.query_row((key.level(), key.x(), row, MAX_TILE_BYTES as i64), |r| {
                    Ok((r.get(0)?, r.get::<_, Option<i64>>(1)?.unwrap_or(0)))
                })
                .optional()
            });
        self.idle
            .lock()
            .unwrap_or_else(|p| p.into_inner())
            .push(conn);
        match got {
            Ok(Some((Some(b), _))) if !b.is_empty() => Ok(Some(Fetched::local(b))),
            Ok(Some((None, len))) if len > 0 => Err(FetchError::Permanent(format!(
                "MBTiles {} tile {key}: {len} bytes, more than a tile may be ({MAX_TILE_BYTES})",
                self.name
            ))),
            Ok(_) => Ok(None),
            Err(e) => Err(FetchError::Permanent(sql_error(
                &self.name,
                &format!("tile {key}"),
                e,
            ))),
        }
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    fn archive(name: &str, sql: &str) -> PathBuf {
        let dir = std::env::temp_dir().join(format!("globus-mbtiles-{}", std::process::id()));
        std::fs::create_dir_all(&dir).unwrap();
        let path = dir.join(name);
        let _ = std::fs::remove_file(&path);
        let c = Connection::open(&path).unwrap();
        c.execute_batch(sql).unwrap();
        path
    }

    const TABLES: &str = "CREATE TABLE metadata (name TEXT, value TEXT);
        CREATE TABLE tiles (zoom_level INTEGER, tile_column INTEGER, tile_row INTEGER, tile_data BLOB);";

    /// A `tiles` view over an endless recursive query hung a loader thread for ever (and the
    /// process never exited): the query is interrupted and the tile fails with a reason.
    #[test]
    fn an_endless_tiles_view_is_interrupted() {
        let path = archive(
            "endless.mbtiles",
            "CREATE TABLE metadata (name TEXT, value TEXT);
             CREATE VIEW tiles AS WITH RECURSIVE r(n) AS (SELECT 0 UNION ALL SELECT n + 1 FROM r)
             SELECT 0 AS zoom_level, 0 AS tile_column, 0 AS tile_row, x'00' AS tile_data
             FROM r WHERE n < 0;",
        );
        let f = MbTilesFetch::open(&path).unwrap();
        let (tx, rx) = std::sync::mpsc::sync_channel(1);
        std::thread::spawn(move || {
            let _ = tx.send(f.fetch(TileKey::new(0, 0, 0), &Cancel::new()));
        });
        let got = rx
            .recv_timeout(QUERY_LIMIT * 6)
            .expect("the query was not interrupted");
        let e = got.unwrap_err().to_string();
        assert!(
            e.contains("endless.mbtiles") && e.contains("stopped after"),
            "{e}"
        );
    }

    /// A 64 MiB + 1 blob is refused without being read; a nonsense scheme is refused at open.
    #[test]
    fn oversized_blobs_and_unknown_schemes_are_refused() {
        let path = archive(
            "big.mbtiles",
            &format!(
                "{TABLES} INSERT INTO tiles VALUES (0, 0, 0, zeroblob({}));
                 INSERT INTO tiles VALUES (1, 0, 0, x'0102');",
                MAX_TILE_BYTES + 1
            ),
        );
        let f = MbTilesFetch::open(&path).unwrap();
        let c = Cancel::new();
        let e = f.fetch(TileKey::new(0, 0, 0), &c).unwrap_err().to_string();
        assert!(
            e.contains("big.mbtiles") && e.contains("more than a tile"),
            "{e}"
        );
        let small = f.fetch(TileKey::new(1, 0, 1), &c).unwrap().unwrap();
        assert_eq!(small.bytes, [1, 2]);
        std::fs::remove_file(&path).ok();

        let mars = archive(
            "mars.mbtiles",
            &format!("{TABLES} INSERT INTO metadata VALUES ('scheme', 'mars');"),
        );
        let e = MbTilesFetch::open(&mars).err().unwrap().to_string();
        assert!(e.contains("mars.mbtiles") && e.contains("\"mars\""), "{e}");
        let tms = archive(
            "tms.mbtiles",
            &format!("{TABLES} INSERT INTO metadata VALUES ('scheme', 'tms');"),
        );
        assert_eq!(
            MbTilesFetch::open(&tms).unwrap().scheme(),
            TilingScheme::WebMercator
        );
    }
}
