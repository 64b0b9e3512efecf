//! PMTiles v3: one file with a 127-byte header, gzip-compressed directories of tiles keyed
//! by Hilbert tile ID, JSON metadata and the tile data, readable over HTTP range requests.
//!
//! Tiles arrive in any order; their bytes go to `FILE.partial` as they come, with identical
//! tiles stored once. [`PmTilesSink::finish`] sorts the entries by tile ID and writes the
//! archive clustered (tile data in tile-ID order), so the file is byte-identical whatever
//! order the threads produced tiles in.
//!
//! PMTiles addresses square quadtrees (one root). A geographic pyramid (two roots) is stored
//! one level down: geographic tile (z, x, y) is PMTiles tile (z + 1, x, y), whose rows
//! `y < 2^z` form the top half of that level; the metadata says so
//! (`"scheme": "geographic"`, `"pmtiles_level_offset": 1`).

use std::fs::File;
use std::io::{BufWriter, Write};
use std::os::unix::fs::FileExt;
use std::path::{Path, PathBuf};
use std::sync::Mutex;

use globus_tiling::pmtiles::{Entry, HEADER_LEN, Header, compression, encode_directory};
use globus_tiling::{TileKey, TilingScheme};

pub use globus_tiling::pmtiles::tile_id;
use rustc_hash::FxHashMap;

use super::{PyramidMetadata, TileSink, with_suffix};
use crate::error::{Result, TilerError};

/// Header and the root directory must fit in the first 16 KiB.
const ROOT_LIMIT: usize = 16_384 - HEADER_LEN;

fn gzip(bytes: &[u8]) -> Vec<u8> {
    let mut enc = flate2::GzBuilder::new()
        .mtime(0)
        .write(Vec::new(), flate2::Compression::default());
    // Writing to a Vec cannot fail.
    let _ = enc.write_all(bytes);
    enc.finish().unwrap_or_default()
}

/// A directory in the specification's column layout, gzip-compressed.
pub fn serialize_directory(entries: &[Entry]) -> Vec<u8> {
    gzip(&encode_directory(entries))
}

/// The root directory and the leaf directories section for `entries` (sorted by tile ID):
/// everything in the root if it fits, else leaves of a growing number of entries each.
fn build_directories(entries: &[Entry]) -> (Vec<u8>, Vec<u8>) {
    let root = serialize_directory(entries);
    if root.len() <= ROOT_LIMIT {
        return (root, Vec::new());
    }
    let mut per_leaf = 4096;
    loop {
        let mut leaves = Vec::new();
        let mut pointers = Vec::new();
        for chunk in entries.chunks(per_leaf) {
            let leaf = serialize_directory(chunk);
            pointers.push(Entry {
                tile_id: chunk[0].tile_id,
                offset: leaves.len() as u64,
                length: leaf.len() as u32,
                run_length: 0,
            });
            leaves.extend_from_slice(&leaf);
        }
        let root = serialize_directory(&pointers);
        if root.len() <= ROOT_LIMIT {
            return (root, leaves);
        }
        per_leaf *= 2;
    }
}

struct Stored {
    /// (tile ID, offset in the partial file, length).
    tiles: Vec<(u64, u64, u32)>,
    /// Content hash and length -> offsets of distinct contents with that hash.
    contents: FxHashMap<(u64, u32), Vec<u64>>,
    file: File,
    len: u64,
}

/// Writes tiles into a PMTiles archive.
pub struct PmTilesSink {
    path: PathBuf,
    partial: PathBuf,
    level_offset: u8,
    state: Mutex<Stored>,
}

fn content_hash(bytes: &[u8]) -> u64 {
    use std::hash::{Hash, Hasher};
    let mut h = std::collections::hash_map::DefaultHasher::new();
    bytes.hash(&mut h);
    h.finish()
}

impl PmTilesSink {
    /// Starts `path` (tile data goes to `path.partial` until [`PmTilesSink::finish`]).
    pub fn create(path: &Path, scheme: TilingScheme) -> Result<Self> {
        let partial = with_suffix(path, ".partial");
        let _ = std::fs::remove_file(path);
        let file = File::options()
            .read(true)
            .write(true)
            .create(true)
            .truncate(true)
            .open(&partial)
            .map_err(|e| TilerError::output(&partial, e))?;
        Ok(Self {
            path: path.to_owned(),
            partial,
            level_offset: match scheme {
                TilingScheme::Geographic | TilingScheme::GeographicReduced => 1,
                TilingScheme::WebMercator => 0,
            },
            state: Mutex::new(Stored {
                tiles: Vec::new(),
                contents: FxHashMap::default(),
                file,
                len: 0,
            }),
        })
    }

    /// Writes the archive and removes the partial file.
    pub fn finish(self, meta: &PyramidMetadata) -> Result<()> {
        let err = |e: &dyn std::fmt::Display| TilerError::output(&self.path, e);
        let mut st = self
            .state
            .into_inner()
            .map_err(|_| err(&"a writer thread panicked"))?;
        st.tiles.sort_unstable_by_key(|t| t.0);
        // Lay the data out in tile-ID order, each distinct content once.
        let mut placed: FxHashMap<u64, u64> = FxHashMap::default();
        let mut order: Vec<(u64, u32)> = Vec::new();
        let mut data_len = 0u64;
        let mut entries: Vec<Entry> = Vec::new();
        for &(id, src, len) in &st.tiles {
            let offset = *placed.entry(src).or_insert_with(|| {
                order.push((src, len));
                data_len += u64::from(len);
                data_len - u64::from(len)
            });
            match entries.last_mut() {
                Some(last)
                    if last.offset == offset && last.tile_id + u64::from(last.run_length) == id =>
                {
                    last.run_length += 1;
                }
                _ => entries.push(Entry {
                    tile_id: id,
                    offset,
                    length: len,
                    run_length: 1,
                }),
            }
        }
        let (root, leaves) = build_directories(&entries);
        let mut json = meta.to_json();
        json["pmtiles_level_offset"] = serde_json::Value::from(self.level_offset);
        let metadata = gzip(json.to_string().as_bytes());

        let root_offset = HEADER_LEN as u64;
        let meta_offset = root_offset + root.len() as u64;
        let leaf_offset = meta_offset + metadata.len() as u64;
        let data_offset = leaf_offset + leaves.len() as u64;
        let [w, s, e, n] = meta.bounds.to_degrees();
        let e7 = |d: f64| (d * 1e7).round() as i32;
        let (min_zoom, max_zoom) = (
            meta.min_level + self.level_offset,
            meta.max_level + self.level_offset,
        );
        let header = Header {
            root: (root_offset, root.len() as u64),
            metadata: (meta_offset, metadata.len() as u64),
            leaves: (leaf_offset, leaves.len() as u64),
            data: (data_offset, data_len),
            addressed_tiles: st.tiles.len() as u64,
            tile_entries: entries.len() as u64,
            tile_contents: order.len() as u64,
            clustered: true,
            internal_compression: compression::GZIP,
            // Tiles are stored as encoded (PNG, JPEG, WebP), not compressed further.
            tile_compression: compression::NONE,
            tile_type: match meta.format.as_str() {
                "png" => 2,
                "jpg" => 3,
                "webp" => 4,
                _ => 0,
            },
            min_zoom,
            max_zoom,
            bounds_e7: [e7(w), e7(s), e7(e), e7(n)],
            centre_zoom: min_zoom.max(max_zoom.saturating_sub(2)),
            centre_e7: [e7((w + e) * 0.5), e7((s + n) * 0.5)],
        };
        let h = header.to_bytes();

        let staging = with_suffix(&self.path, ".tmp");
        let out = File::create(&staging).map_err(|e| TilerError::output(&staging, e))?;
        let mut out = BufWriter::with_capacity(1 << 20, out);
        let write = |out: &mut BufWriter<File>, b: &[u8]| {
            out.write_all(b)
                .map_err(|e| TilerError::output(&staging, e))
        };
        for part in [&h[..], &root, &metadata, &leaves] {
            write(&mut out, part)?;
        }
        let mut buf = Vec::new();
        for (src, len) in order {
            buf.resize(len as usize, 0);
            st.file
                .read_exact_at(&mut buf, src)
                .map_err(|e| TilerError::output(&self.partial, e))?;
            write(&mut out, &buf)?;
        }
        out.into_inner()
            .map_err(|e| TilerError::output(&staging, e.error().to_string()))?
            .sync_all()
            .map_err(|e| TilerError::output(&staging, e))?;
        std::fs::rename(&staging, &self.path).map_err(|e| err(&e))?;
        drop(st);
        std::fs::remove_file(&self.partial).map_err(|e| TilerError::output(&self.partial, e))
    }
}

impl TileSink for PmTilesSink {
    fn put(&self, key: TileKey, bytes: &[u8]) -> Result<()> {
        let id = tile_id(key.level() + self.level_offset, key.x(), key.y());
        let hash = (content_hash(bytes), bytes.len() as u32);
        let mut st = self
            .state
            .lock()
            .map_err(|_| TilerError::output(&self.partial, "a writer thread panicked"))?;
        // Identical contents (open ocean, empty land) are stored once; compare the bytes,
        // not just the hash.
        let mut same = None;
        if let Some(candidates) = st.contents.get(&hash) {
            let mut buf = vec![0u8; bytes.len()];
            for &off in candidates {
                st.file
                    .read_exact_at(&mut buf, off)
                    .map_err(|e| TilerError::output(&self.partial, e))?;
                if buf == bytes {
                    same = Some(off);
                    break;
                }
            }
        }
        let offset = match same {
            Some(off) => off,
            None => {
                let off = st.len;
                st.file
                    .write_all_at(bytes, off)
                    .map_err(|e| TilerError::output(&self.partial, e))?;
                st.len += bytes.len() as u64;
                st.contents.entry(hash).or_default().push(off);
                off
            }
        };
        st.tiles.push((id, offset, bytes.len() as u32));
        Ok(())
    }

    fn existing(&self, _key: TileKey) -> Result<Option<Vec<u8>>> {
        Ok(None)
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn big_directories_spill_into_leaves_and_the_root_fits() {
        let entries: Vec<Entry> = (0..200_000u64)
            .map(|i| Entry {
                tile_id: i * 3,
                offset: i * 1000,
                length: 999 + (i % 7) as u32,
                run_length: 1,
            })
            .collect();
        let (root, leaves) = build_directories(&entries);
        assert!(root.len() <= ROOT_LIMIT);
        assert!(!leaves.is_empty());
    }
}
