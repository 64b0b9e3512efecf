//! An on-disk cache in front of any [`Fetch`], so a second session needs no network.
//!
//! * Each origin (a fetcher's name: a URL template, a WMS endpoint) gets a folder named by a
//!   hash of it; each tile a file `z/x/y` holding a 16-byte header (magic, the time the bytes
//!   stop being fresh, in seconds since 1970) and the bytes. "No data here" (404) is cached as
//!   a header without bytes.
//! * Freshness follows the origin: `Cache-Control: max-age` (or `Expires`); `no-store` and
//!   `no-cache` make an entry stale at once (it is still kept for offline use); without either,
//!   [`DiskCacheOptions::default_fresh_for`].
//! * A fresh entry is served without asking the origin. A stale one is refetched; if the
//!   origin cannot be reached (a transient failure: down, timing out, 5xx) the stale bytes are
//!   served anyway, which is what makes a session work offline.
//! * The folder stays under a size cap: when a write takes it over, the least recently used
//!   files (by modification time, refreshed on every hit) go until it is under 90 % of the cap.
//!
//! Files are written under a temporary name and renamed, so a crash never leaves a torn entry;
//! a file that does not parse is treated as missing.

use std::path::{Path, PathBuf};
use std::sync::Mutex;
use std::sync::atomic::{AtomicU64, Ordering};
use std::time::{Duration, SystemTime, UNIX_EPOCH};

use globus_tiling::TileKey;

use super::{Cancel, Fetch, FetchError, Fetched, OpenError};

const MAGIC: &[u8; 8] = b"GLBSTIL1";
const HEADER: usize = 16;

/// Knobs of the disk cache.
#[derive(Clone, Debug)]
pub struct DiskCacheOptions {
    /// The cache folder (shared by all origins).
    pub dir: PathBuf,
    /// Most bytes kept on disk.
    pub max_bytes: u64,
    /// Freshness of responses that say nothing about it.
    pub default_fresh_for: Duration,
}

/// Counters.
#[derive(Clone, Copy, Debug, Default, PartialEq, Eq)]
pub struct DiskCacheStats {
    /// Served fresh from disk.
    pub fresh_hits: u64,
    /// Served stale from disk because the origin could not be reached.
    pub stale_hits: u64,
    /// Fetched from the origin.
    pub misses: u64,
    /// Files removed to stay under the cap.
    pub evicted: u64,
}

/// A [`Fetch`] with an on-disk cache in front.
pub struct CachedFetch {
    inner: Box<dyn Fetch>,
    root: PathBuf,
    options: DiskCacheOptions,
    bytes: AtomicU64,
    stats: Mutex<DiskCacheStats>,
    evicting: Mutex<()>,
}

/// FNV-1a, enough to name an origin's folder stably across runs.
pub(crate) fn origin_hash(name: &str) -> u64 {
    name.bytes().fold(0xcbf2_9ce4_8422_2325, |h, b| {
        (h ^ u64::from(b)).wrapping_mul(0x0100_0000_01b3)
    })
}

fn now_s() -> u64 {
    SystemTime::now()
        .duration_since(UNIX_EPOCH)
        .map_or(0, |d| d.as_secs())
}

fn folder_bytes(dir: &Path) -> u64 {
    let mut total = 0;
    let mut stack = vec![dir.to_path_buf()];
    while let Some(d) = stack.pop() {
        let Ok(entries) = std::fs::read_dir(&d) else {
            continue;
        };
        for e in entries.flatten() {
            match e.file_type() {
                Ok(t) if t.is_dir() => stack.push(e.path()),
                Ok(_) => total += e.metadata().map_or(0, |m| m.len()),
                Err(_) => {}
            }
        }
    }
    total
}

impl CachedFetch {
    /// Puts a disk cache in front of `inner`.
    pub fn new(inner: Box<dyn Fetch>, options: DiskCacheOptions) -> Result<Self, OpenError> {
        let root = options
            .dir
            .join(format!("{:016x}", origin_hash(inner.name())));
        std::fs::create_dir_all(&root)
            .map_err(|e| OpenError::Unreadable(format!("disk cache {}: {e}", root.display())))?;
        // Note which origin the folder belongs to (for people looking at the cache).
        // (Whole or not at all, and never into a FIFO planted there, which would block.)
        let _ = globus_tiling::files::write_atomic(&root.join("ORIGIN"), inner.name().as_bytes());
        let bytes = folder_bytes(&options.dir);
        Ok(Self {
            inner,
            root,
            options,
            bytes: AtomicU64::new(bytes),
            stats: Mutex::new(DiskCacheStats::default()),
            evicting: Mutex::new(()),
        })
    }

    /// Forgets every tile kept for this origin (its data changed under the same name).
    pub fn clear(&self) {
        let held = folder_bytes(&self.root);
        let _ = std::fs::remove_dir_all(&self.root);
        let _ = std::fs::create_dir_all(&self.root);
        let _ = globus_tiling::files::write_atomic(
            &self.root.join("ORIGIN"),
            self.inner.name().as_bytes(),
        );
        let total = self.bytes.load(Ordering::Relaxed);
        self.bytes
            .store(total.saturating_sub(held), Ordering::Relaxed);
    }

    /// Counters.
    pub fn stats(&self) -> DiskCacheStats {
        *self.stats.lock().unwrap_or_else(|p| p.into_inner())
    }

    fn count(&self, f: impl FnOnce(&mut DiskCacheStats)) {
        f(&mut self.stats.lock().unwrap_or_else(|p| p.into_inner()));
    }

    fn path(&self, key: TileKey) -> PathBuf {
        self.root
            .join(key.level().to_string())
            .join(key.x().to_string())
            .join(key.y().to_string())
    }

    /// The cached entry: (fresh until, bytes or `None` for "no data").
    fn read(&self, key: TileKey) -> Option<(u64, Option<Vec<u8>>)> {
        let bytes = globus_tiling::files::read_capped(
            &self.path(key),
            globus_tiling::files::MAX_TILE_BYTES + HEADER as u64,
        )
        .ok()?;
        if bytes.len() < HEADER || &bytes[..8] != MAGIC {
            return None;
        }
        let mut t = [0u8; 8];
        t.copy_from_slice(&bytes[8..16]);
        let until = u64::from_le_bytes(t);
        let body = bytes[HEADER..].to_vec();
        Some((until, (!body.is_empty()).then_some(body)))
    }

    fn write(&self, key: TileKey, fresh_for: Duration, body: Option<&[u8]>) {
        let path = self.path(key);
        let Some(dir) = path.parent() else { return };
        if std::fs::create_dir_all(dir).is_err() {
            return;
        }
        let mut out = Vec::with_capacity(HEADER + body.map_or(0, <[u8]>::len));
        out.extend_from_slice(MAGIC);
        out.extend_from_slice(&(now_s().saturating_add(fresh_for.as_secs())).to_le_bytes());
        out.extend_from_slice(body.unwrap_or_default());
        let old = std::fs::metadata(&path).map_or(0, |m| m.len());
        let tmp = path.with_extension(format!("tmp{}", std::process::id()));
        if std::fs::write(&tmp, &out).is_err() || std::fs::rename(&tmp, &path).is_err() {
            let _ = std::fs::remove_file(&tmp);
            return;
        }
        let added = out.len() as u64;
        let total = self.bytes.fetch_add(added, Ordering::Relaxed) + added;
        self.bytes.fetch_sub(old.min(total), Ordering::Relaxed);
        if total.saturating_sub(old) > self.options.max_bytes {
            self.evict();
        }
    }

    /// Removes the least recently used files until the folder is under 90 % of its cap.
    fn evict(&self) {
        let Ok(_guard) = self.evicting.try_lock() else {
            return;
        };
        let mut files = Vec::new();
        let mut stack = vec![self.options.dir.clone()];
        while let Some(d) = stack.pop() {
            let Ok(entries) = std::fs::read_dir(&d) else {
                continue;
            };
            for e in entries.flatten() {
                let Ok(m) = e.metadata() else { continue };
                if m.is_dir() {
                    stack.push(e.path());
                } else if e.file_name() != "ORIGIN" {
                    let t = m.modified().unwrap_or(UNIX_EPOCH);
                    files.push((t, m.len(), e.path()));
                }
            }
        }
        let mut total: u64 = files.iter().map(|f| f.1).sum();
        files.sort();
        let target = self.options.max_bytes / 10 * 9;
        let mut evicted = 0;
        for (_, len, path) in files {
            if total <= target {
                break;
            }
            if std::fs::remove_file(&path).is_ok() {
                total -= len;
                evicted += 1;
            }
        }
        self.bytes.store(total, Ordering::Relaxed);
        self.count(|s| s.evicted += evicted);
    }

    /// Marks a hit as recently used.
    fn touch(&self, key: TileKey) {
        if let Ok(f) = std::fs::File::options().append(true).open(self.path(key)) {
            let _ = f.set_modified(SystemTime::now());
        }
    }
}

impl Fetch for CachedFetch {
    fn name(&self) -> &str {
        self.inner.name()
    }

    fn locate(&self, key: TileKey) -> String {
        self.inner.locate(key)
    }

    fn fetch(&self, key: TileKey, cancel: &Cancel) -> Result<Option<Fetched>, FetchError> {
        let cached = self.read(key);
        if let Some((until, body)) = &cached
            && *until > now_s()
        {
            self.touch(key);
            self.count(|s| s.fresh_hits += 1);
            return Ok(body.clone().map(Fetched::local));
        }
        match self.inner.fetch(key, cancel) {
            Ok(got) => {
                self.count(|s| s.misses += 1);
                let fresh_for = got
                    .as_ref()
                    .and_then(|f| f.fresh_for)
                    .unwrap_or(self.options.default_fresh_for);
                self.write(key, fresh_for, got.as_ref().map(|f| f.bytes.as_slice()));
                Ok(got)
            }
            Err(FetchError::Transient {
                message,
                retry_after,
            }) => match cached {
                Some((_, body)) => {
                    self.count(|s| s.stale_hits += 1);
                    Ok(body.map(Fetched::local))
                }
                None => Err(FetchError::Transient {
                    message,
                    retry_after,
                }),
            },
            Err(e) => Err(e),
        }
    }
}

#[cfg(test)]
mod tests {
    use super::*;
    use crate::fetch::DirectoryFetch;
    use globus_tiling::TilingScheme;

    /// FIFOs planted in the cache folder (as its ORIGIN note and as a cached tile) blocked a
    /// loader for ever: the cache opens, the tile comes from its origin, and the FIFO is
    /// replaced by the fresh entry.
    #[test]
    fn fifos_in_the_cache_folder_block_nothing() {
        let base = std::env::temp_dir().join(format!("globus-cache-fifo-{}", std::process::id()));
        let _ = std::fs::remove_dir_all(&base);
        let tiles = base.join("tiles");
        std::fs::create_dir_all(tiles.join("1/0")).unwrap();
        std::fs::write(tiles.join("1/0/0.png"), b"tile bytes").unwrap();
        let inner =
            DirectoryFetch::new(&tiles, "{z}/{x}/{y}.png", TilingScheme::Geographic).unwrap();
        let cache_dir = base.join("cache");
        let root = cache_dir.join(format!("{:016x}", origin_hash(inner.name())));
        std::fs::create_dir_all(root.join("1/0")).unwrap();
        globus_test_support::mkfifo(&root.join("ORIGIN"));
        globus_test_support::mkfifo(&root.join("1/0/0"));
        let (tx, rx) = std::sync::mpsc::sync_channel(1);
        std::thread::spawn(move || {
            let options = DiskCacheOptions {
                dir: cache_dir,
                max_bytes: 1 << 20,
                default_fresh_for: Duration::from_secs(60),
            };
            let got = CachedFetch::new(Box::new(inner), options)
                .map(|c| c.fetch(TileKey::new(1, 0, 0), &Cancel::new()));
            let _ = tx.send(got.map(|r| r.map(|f| f.map(|f| f.bytes))));
        });
        let got = rx
            .recv_timeout(Duration::from_secs(30))
            .expect("the cache blocked on a FIFO");
        assert_eq!(got.unwrap().unwrap().unwrap(), b"tile bytes");
        assert!(std::fs::metadata(root.join("1/0/0")).unwrap().is_file());
        std::fs::remove_dir_all(&base).ok();
    }
}
