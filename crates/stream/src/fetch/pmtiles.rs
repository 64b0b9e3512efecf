//! PMTiles v3 archives, read by byte ranges from a local file or over HTTP range requests.
//!
//! Opening reads the first 16 KiB (header and, in a well-formed archive, the root directory)
//! and the metadata; a tile then costs one range read, plus one per leaf directory not yet
//! cached. Geographic pyramids written by `globus tile` sit one level down in the archive
//! (`"pmtiles_level_offset": 1` in the metadata), which is honoured here.
//!
//! Everything read is untrusted: lengths are capped, decompression is bounded, leaf
//! directories nest at most four deep.
//!
//! With a disk cache, an archive over HTTP is read through [`KeptHead`] (what opening reads
//! is kept on disk, so the archive opens offline) and its tiles through
//! [`super::CachedFetch`]; a changed archive (its header differs from the kept one) drops
//! the tiles cached from the old one.

use std::fs::File;
use std::io::Read;
use std::os::unix::fs::FileExt;
use std::path::{Path, PathBuf};
use std::sync::{Arc, Mutex};

use globus_tiling::pmtiles::{
    Entry, HEADER_LEN, Header, compression, decode_directory, find_entry, tile_id,
};
use globus_tiling::{TileKey, TilingScheme};
use rustc_hash::FxHashMap;

use super::{Cancel, Fetch, FetchError, Fetched, HttpClient, OpenError};

/// Largest directory, metadata or tile accepted, bytes (compressed or not).
const MAX_PART_BYTES: u64 = 64 << 20;
/// Leaf directories kept decoded.
const LEAF_CACHE: usize = 64;

/// Random access to an archive's bytes.
pub trait RangeRead: Send + Sync + 'static {
    /// The file or URL.
    fn name(&self) -> &str;
    /// `len` bytes at `offset`.
    fn read_range(&self, offset: u64, len: u64, cancel: &Cancel) -> Result<Vec<u8>, FetchError>;
}

/// A local archive.
pub struct FileRange {
    file: File,
    name: String,
    len: u64,
}

impl FileRange {
    /// Opens `path`.
    pub fn open(path: &Path) -> Result<Self, OpenError> {
        let unreadable =
            |e: std::io::Error| OpenError::Unreadable(format!("PMTiles {}: {e}", path.display()));
        let file = globus_tiling::files::open_regular(path).map_err(unreadable)?;
        let len = file.metadata().map_err(unreadable)?.len();
        Ok(Self {
            file,
            name: path.display().to_string(),
            len,
        })
    }
}

impl RangeRead for FileRange {
    fn name(&self) -> &str {
        &self.name
    }

    fn read_range(&self, offset: u64, len: u64, _cancel: &Cancel) -> Result<Vec<u8>, FetchError> {
        let end = offset
            .checked_add(len)
            .filter(|&e| e <= self.len)
            .ok_or_else(|| {
                FetchError::Permanent(format!(
                    "{}: range {offset}+{len} beyond the file's {} bytes",
                    self.name, self.len
                ))
            })?;
        let mut buf = vec![0u8; (end - offset) as usize];
        self.file
            .read_exact_at(&mut buf, offset)
            .map_err(|e| FetchError::transient(format!("{}: {e}", self.name)))?;
        Ok(buf)
    }
}

/// An archive on a web server that answers range requests.
pub struct HttpRange {
    client: Arc<HttpClient>,
    url: String,
}

impl HttpRange {
    /// The archive at `url`.
    pub fn new(client: Arc<HttpClient>, url: &str) -> Self {
        Self {
            client,
            url: url.to_string(),
        }
    }
}

impl RangeRead for HttpRange {
    fn name(&self) -> &str {
        &self.url
    }

    fn read_range(&self, offset: u64, len: u64, cancel: &Cancel) -> Result<Vec<u8>, FetchError> {
        if len == 0 {
            return Ok(Vec::new());
        }
        let body = self
            .client
            .get(&self.url, Some((offset, offset + len - 1)), cancel)?
            .ok_or_else(|| FetchError::Permanent(format!("{}: not found", self.url)))?;
        let mut bytes = body.fetched.bytes;
        if body.status == 200 {
            // The server ignored the range and sent the whole file.
            let end = offset.saturating_add(len).min(bytes.len() as u64) as usize;
            let start = (offset as usize).min(end);
            bytes = bytes[start..end].to_vec();
        }
        if (bytes.len() as u64) < len.min(MAX_PART_BYTES) && body.status == 206 {
            return Err(FetchError::transient(format!(
                "{}: asked for {len} bytes at {offset}, got {}",
                self.url,
                bytes.len()
            )));
        }
        Ok(bytes)
    }
}

/// What one opening read: (offset, bytes) of each range.
type Parts = Vec<(u64, Vec<u8>)>;

const KEPT_MAGIC: &[u8; 8] = b"GLBSPMH1";

/// A [`RangeRead`] that keeps on disk the ranges read while an archive is opened (header,
/// root directory, metadata) and serves them when the origin cannot be reached, so an archive
/// over HTTP opens offline. Reads after [`KeptHead::opened`] pass straight through.
pub struct KeptHead<R: RangeRead> {
    inner: R,
    path: PathBuf,
    kept: Parts,
    recording: Mutex<Option<Parts>>,
}

impl<R: RangeRead> KeptHead<R> {
    /// `inner`, keeping its opening reads in the folder `dir` (a file named by a hash of
    /// the archive's name).
    pub fn new(inner: R, dir: &Path) -> Self {
        let path = dir.join(format!(
            "{:016x}.pmtiles-head",
            super::disk_cache::origin_hash(inner.name())
        ));
        let kept = globus_tiling::files::read_capped(&path, 4 * MAX_PART_BYTES)
            .ok()
            .and_then(|b| parse_parts(&b))
            .unwrap_or_default();
        Self {
            inner,
            path,
            kept,
            recording: Mutex::new(Some(Vec::new())),
        }
    }

    /// Ends the opening: keeps what it read (if it read the origin) and tells whether the
    /// archive differs from the one kept before (then tiles cached from that one are wrong).
    pub fn opened(&self) -> bool {
        let read = self
            .recording
            .lock()
            .unwrap_or_else(|p| p.into_inner())
            .take()
            .unwrap_or_default();
        let head = |parts: &Parts| parts.iter().find(|p| p.0 == 0).map(|p| p.1.clone());
        let changed = matches!((head(&self.kept), head(&read)), (Some(a), Some(b)) if a != b);
        if read != self.kept && !read.is_empty() {
            let mut out = KEPT_MAGIC.to_vec();
            for (offset, bytes) in &read {
                out.extend_from_slice(&offset.to_le_bytes());
                out.extend_from_slice(&(bytes.len() as u64).to_le_bytes());
                out.extend_from_slice(bytes);
            }
            if let Some(dir) = self.path.parent() {
                let _ = std::fs::create_dir_all(dir);
            }
            let tmp = self
                .path
                .with_extension(format!("tmp{}", std::process::id()));
            if std::fs::write(&tmp, &out).is_err() || std::fs::rename(&tmp, &self.path).is_err() {
                let _ = std::fs::remove_file(&tmp);
            }
        }
        changed
    }
}

/// The parts of a kept file, `None` if it is not one (torn, foreign).
fn parse_parts(b: &[u8]) -> Option<Parts> {
    let mut rest = b.strip_prefix(KEPT_MAGIC)?;
    let mut parts = Vec::new();
    let word = |r: &[u8]| -> Option<u64> { Some(u64::from_le_bytes(r.get(..8)?.try_into().ok()?)) };
    while !rest.is_empty() {
        let offset = word(rest)?;
        let len = usize::try_from(word(rest.get(8..)?)?).ok()?;
        let bytes = rest.get(16..16usize.checked_add(len)?)?;
        parts.push((offset, bytes.to_vec()));
        rest = &rest[16 + len..];
    }
    Some(parts)
}

impl<R: RangeRead> RangeRead for KeptHead<R> {
    fn name(&self) -> &str {
        self.inner.name()
    }

    fn read_range(&self, offset: u64, len: u64, cancel: &Cancel) -> Result<Vec<u8>, FetchError> {
        let mut recording = self.recording.lock().unwrap_or_else(|p| p.into_inner());
        let Some(read) = recording.as_mut() else {
            drop(recording);
            return self.inner.read_range(offset, len, cancel);
        };
        let bytes = match self.inner.read_range(offset, len, cancel) {
            Ok(b) => b,
            Err(FetchError::Transient {
                message,
                retry_after,
            }) => self
                .kept
                .iter()
                .find(|p| p.0 == offset && p.1.len() as u64 == len)
                .map(|p| p.1.clone())
                .ok_or(FetchError::Transient {
                    message: format!("{message} (and no copy kept on disk)"),
                    retry_after,
                })?,
            Err(e) => return Err(e),
        };
        read.push((offset, bytes.clone()));
        Ok(bytes)
    }
}

/// Reads tiles from a PMTiles v3 archive.
pub struct PmTilesFetch<R: RangeRead> {
    reader: R,
    header: Header,
    root: Vec<Entry>,
    metadata: serde_json::Value,
    level_offset: u8,
    scheme: TilingScheme,
    leaves: Mutex<FxHashMap<u64, Arc<Vec<Entry>>>>,
}

fn inflate(name: &str, what: &str, bytes: &[u8], codec: u8) -> Result<Vec<u8>, FetchError> {
    match codec {
        compression::NONE | compression::UNKNOWN => Ok(bytes.to_vec()),
        compression::GZIP => {
            let mut out = Vec::new();
            flate2::read::GzDecoder::new(bytes)
                .take(MAX_PART_BYTES + 1)
                .read_to_end(&mut out)
                .map_err(|e| FetchError::Permanent(format!("{name}: {what}: gzip: {e}")))?;
            if out.len() as u64 > MAX_PART_BYTES {
                return Err(FetchError::Permanent(format!(
                    "{name}: {what} inflates past {MAX_PART_BYTES} bytes"
                )));
            }
            Ok(out)
        }
        other => Err(FetchError::Permanent(format!(
            "{name}: {what} uses compression {other} (only none and gzip are read)"
        ))),
    }
}

/// How deep leaf directories may nest (the writers nest one level; the specification allows
/// more, a directory that points at itself would loop).
const MAX_LEAF_DEPTH: usize = 4;

impl<R: RangeRead> PmTilesFetch<R> {
    /// Opens the archive behind `reader`.
    pub fn open(reader: R) -> Result<Self, OpenError> {
        let cancel = Cancel::new();
        let name = reader.name().to_string();
        let unreadable = |e: FetchError| OpenError::Unreadable(format!("{name}: {e}"));
        let invalid = |what: &str, m: &dyn std::fmt::Display| {
            OpenError::Invalid(format!("{name}: {what}{m}"))
        };
        let head = reader
            .read_range(0, HEADER_LEN as u64, &cancel)
            .map_err(unreadable)?;
        let header = Header::parse(&head).map_err(|m| invalid("", &m))?;
        // Raster tiles Globus decodes (0: unknown, told by the tiles' own bytes).
        match header.tile_type {
            0 | 2..=4 => {}
            1 => {
                return Err(invalid(
                    "",
                    &"holds vector tiles (MVT); Globus reads raster tiles",
                ));
            }
            5 => {
                return Err(invalid(
                    "",
                    &"holds AVIF tiles; Globus reads PNG, JPEG and WebP",
                ));
            }
            t => {
                return Err(invalid(
                    "",
                    &format!("has tile type {t}, which PMTiles does not define"),
                ));
            }
        }
        let part = |(offset, len): (u64, u64), what: &str| -> Result<Vec<u8>, OpenError> {
            if len > MAX_PART_BYTES {
                return Err(invalid(what, &format!(" of {len} bytes is too large")));
            }
            let raw = reader
                .read_range(offset, len, &cancel)
                .map_err(unreadable)?;
            inflate(&name, what, &raw, header.internal_compression)
                .map_err(|e| OpenError::Invalid(e.to_string()))
        };
        let root = decode_directory(&part(header.root, "root directory")?)
            .map_err(|m| invalid("root directory: ", &m))?;
        let metadata: serde_json::Value = if header.metadata.1 == 0 {
            serde_json::Value::Null
        } else {
            serde_json::from_slice(&part(header.metadata, "metadata")?)
                .map_err(|m| invalid("metadata: ", &m))?
        };
        let scheme = metadata["scheme"]
            .as_str()
            .and_then(|s| s.parse().ok())
            .unwrap_or(TilingScheme::WebMercator);
        let level_offset = match (scheme, metadata["pmtiles_level_offset"].as_u64()) {
            (_, Some(n)) if n <= 1 => n as u8,
            (TilingScheme::Geographic, None) => 1,
            (_, None) => 0,
            (_, Some(n)) => {
                return Err(OpenError::Invalid(format!(
                    "{name}: pmtiles_level_offset {n} is not 0 or 1"
                )));
            }
        };
        Ok(Self {
            reader,
            header,
            root,
            metadata,
            level_offset,
            scheme,
            leaves: Mutex::new(FxHashMap::default()),
        })
    }

    /// What the archive is read through.
    pub fn reader(&self) -> &R {
        &self.reader
    }

    /// The header.
    pub fn header(&self) -> &Header {
        &self.header
    }

    /// The JSON metadata.
    pub fn metadata(&self) -> &serde_json::Value {
        &self.metadata
    }

    /// The tiling scheme of the pyramid inside.
    pub fn scheme(&self) -> TilingScheme {
        self.scheme
    }

    /// The pyramid's levels (archive zooms less the level offset).
    pub fn levels(&self) -> (u8, u8) {
        (
            self.header.min_zoom.saturating_sub(self.level_offset),
            self.header.max_zoom.saturating_sub(self.level_offset),
        )
    }

    fn leaf(
        &self,
        offset: u64,
        length: u32,
        cancel: &Cancel,
    ) -> Result<Arc<Vec<Entry>>, FetchError> {
        if let Some(d) = self.lock_leaves().get(&offset) {
            return Ok(Arc::clone(d));
        }
        let name = self.reader.name();
        let (base, section) = self.header.leaves;
        if offset.saturating_add(u64::from(length)) > section {
            return Err(FetchError::Permanent(format!(
                "{name}: leaf directory at {offset} lies outside the leaf section"
            )));
        }
        let raw = self
            .reader
            .read_range(base + offset, u64::from(length), cancel)?;
        let bytes = inflate(
            name,
            "leaf directory",
            &raw,
            self.header.internal_compression,
        )?;
        let dir = Arc::new(
            decode_directory(&bytes)
                .map_err(|m| FetchError::Permanent(format!("{name}: leaf directory: {m}")))?,
        );
        let mut leaves = self.lock_leaves();
        if leaves.len() >= LEAF_CACHE {
            leaves.clear();
        }
        leaves.insert(offset, Arc::clone(&dir));
        Ok(dir)
    }

    fn lock_leaves(&self) -> std::sync::MutexGuard<'_, FxHashMap<u64, Arc<Vec<Entry>>>> {
        self.leaves.lock().unwrap_or_else(|p| p.into_inner())
    }
}

impl<R: RangeRead> Fetch for PmTilesFetch<R> {
    fn name(&self) -> &str {
        self.reader.name()
    }

    fn fetch(&self, key: TileKey, cancel: &Cancel) -> Result<Option<Fetched>, FetchError> {
        let z = key.level() + self.level_offset;
        if z > 31 {
            return Ok(None);
        }
        let id = tile_id(z, key.x(), key.y());
        let mut entry = find_entry(&self.root, id);
        for _ in 0..MAX_LEAF_DEPTH {
            match entry {
                Some(e) if e.run_length == 0 => {
                    let dir = self.leaf(e.offset, e.length, cancel)?;
                    entry = find_entry(&dir, id);
                }
                _ => break,
            }
        }
        if let Some(e) = entry.filter(|e| e.run_length == 0) {
            return Err(FetchError::Permanent(format!(
                "{} tile {key}: leaf directories nest deeper than {MAX_LEAF_DEPTH} (the one at {} refers to itself?)",
                self.reader.name(),
                e.offset
            )));
        }
        let Some(e) = entry.filter(|e| e.run_length > 0) else {
            return Ok(None);
        };
        let name = self.reader.name();
        if u64::from(e.length) > MAX_PART_BYTES
            || e.offset.saturating_add(u64::from(e.length)) > self.header.data.1
        {
            return Err(FetchError::Permanent(format!(
                "{name} tile {key}: entry ({} bytes at {}) lies outside the data section",
                e.length, e.offset
            )));
        }
        let raw =
            self.reader
                .read_range(self.header.data.0 + e.offset, u64::from(e.length), cancel)?;
        let bytes = inflate(name, "tile", &raw, self.header.tile_compression)?;
        Ok((!bytes.is_empty()).then(|| Fetched::local(bytes)))
    }
}

#[cfg(test)]
mod tests {
    use super::*;
    use globus_tiling::pmtiles::{Header, encode_directory};

    /// An archive in memory.
    struct Bytes(Vec<u8>);

    impl RangeRead for Bytes {
        fn name(&self) -> &str {
            "crafted.pmtiles"
        }
        fn read_range(&self, offset: u64, len: u64, _: &Cancel) -> Result<Vec<u8>, FetchError> {
            let (a, b) = (offset as usize, (offset + len) as usize);
            self.0
                .get(a..b)
                .map(<[u8]>::to_vec)
                .ok_or_else(|| FetchError::Permanent("beyond the end".into()))
        }
    }

    /// An uncompressed archive whose root points every tile at a leaf directory that points
    /// at itself, of `tile_type`.
    fn crafted(tile_type: u8) -> Bytes {
        let leaf = encode_directory(&[Entry {
            tile_id: 0,
            offset: 0,
            length: 0,
            run_length: 0,
        }]);
        let leaf = {
            // The leaf's own length is known only once encoded: encode again with it.
            let n = leaf.len() as u32;
            let again = encode_directory(&[Entry {
                tile_id: 0,
                offset: 0,
                length: n,
                run_length: 0,
            }]);
            assert_eq!(again.len() as u32, n);
            again
        };
        let root = encode_directory(&[Entry {
            tile_id: 0,
            offset: 0,
            length: leaf.len() as u32,
            run_length: 0,
        }]);
        let root_at = HEADER_LEN as u64;
        let leaves_at = root_at + root.len() as u64;
        let header = Header {
            root: (root_at, root.len() as u64),
            metadata: (leaves_at, 0),
            leaves: (leaves_at, leaf.len() as u64),
            data: (leaves_at + leaf.len() as u64, 0),
            internal_compression: compression::NONE,
            tile_compression: compression::NONE,
            tile_type,
            min_zoom: 0,
            max_zoom: 3,
            ..Header::default()
        };
        let mut bytes = header.to_bytes().to_vec();
        bytes.extend(root);
        bytes.extend(leaf);
        Bytes(bytes)
    }

    /// A leaf directory that refers to itself was "no data" without a word; tile type 99 was
    /// accepted: both are errors naming the archive.
    #[test]
    fn self_referencing_leaves_and_unknown_tile_types_are_refused() {
        let p = PmTilesFetch::open(crafted(2)).expect("a well-formed header");
        let e = p.fetch(TileKey::new(0, 0, 0), &Cancel::new()).unwrap_err();
        assert!(e.to_string().contains("refers to itself"), "{e}");
        for (t, needle) in [(99, "tile type 99"), (1, "vector"), (5, "AVIF")] {
            let e = PmTilesFetch::open(crafted(t))
                .err()
                .expect("refused")
                .to_string();
            assert!(e.contains("crafted.pmtiles") && e.contains(needle), "{e}");
        }
    }

    /// Mutations of a real archive: opening and reading every tile returns, never panics.
    #[test]
    fn fuzz_pmtiles() {
        let r = globus_test_support::fuzz::run("pmtiles", |b| {
            let Ok(p) = PmTilesFetch::open(Bytes(b.to_vec())) else {
                return false;
            };
            let c = Cancel::new();
            let mut ok = true;
            for key in [
                TileKey::new(0, 0, 0),
                TileKey::new(0, 1, 0),
                TileKey::new(1, 2, 1),
            ] {
                ok &= p.fetch(key, &c).is_ok();
            }
            ok
        });
        assert!(r.cases > 0 && r.accepted < r.cases, "{r:?}");
    }
}
