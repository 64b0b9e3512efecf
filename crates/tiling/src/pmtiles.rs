//! The PMTiles v3 layout (<https://github.com/protomaps/PMTiles/blob/main/spec/v3/spec.md>):
//! tile IDs along Hilbert curves, the 127-byte header, and directories of entries in the
//! specification's column layout. Compression of directories and metadata is the caller's
//! business (the tiler writes gzip, readers inflate), so this module stays dependency-free and
//! is shared by the writer (`globus-tiler`) and the reader (`globus-stream`).
//!
//! Parsing is for untrusted bytes: it never panics and never allocates more than the input
//! could describe.

/// Header size in bytes.
pub const HEADER_LEN: usize = 127;

/// The PMTiles tile ID of (z, x, y): the tiles of all lower zooms, then the position along
/// the Hilbert curve of zoom z (the specification's reference algorithm).
pub fn tile_id(z: u8, x: u32, y: u32) -> u64 {
    let mut acc: u64 = ((1u64 << (2 * u32::from(z))) - 1) / 3;
    let (mut x, mut y) = (i64::from(x), i64::from(y));
    for a in (0..u32::from(z)).rev() {
        let s = 1i64 << a;
        let rx = s & x;
        let ry = s & y;
        acc += (((3 * rx) ^ ry) as u64) << a;
        if ry == 0 {
            if rx != 0 {
                x = s - 1 - x;
                y = s - 1 - y;
            }
            std::mem::swap(&mut x, &mut y);
        }
    }
    acc
}

/// One directory entry: `run_length` consecutive tile IDs sharing the same bytes, or (with
/// `run_length` 0) a pointer to a leaf directory.
#[derive(Clone, Copy, Debug, PartialEq, Eq)]
pub struct Entry {
    /// First tile ID.
    pub tile_id: u64,
    /// Offset in the tile data (or leaf directory) section.
    pub offset: u64,
    /// Length in bytes.
    pub length: u32,
    /// How many consecutive tile IDs share this data; 0 for a leaf directory.
    pub run_length: u32,
}

/// Appends `v` as an unsigned LEB128 varint.
pub fn write_varint(out: &mut Vec<u8>, mut v: u64) {
    while v >= 0x80 {
        out.push((v as u8 & 0x7f) | 0x80);
        v >>= 7;
    }
    out.push(v as u8);
}

/// Why PMTiles bytes could not be read.
#[derive(Clone, Debug, PartialEq, Eq, thiserror::Error)]
pub enum PmTilesError {
    /// The bytes do not start with the PMTiles magic number.
    #[error("not a PMTiles archive (no magic number)")]
    NotPmTiles,
    /// A version other than 3.
    #[error("PMTiles version {0} (only 3 is read)")]
    Version(u8),
    /// A header or directory is cut short or inconsistent.
    #[error("{0}")]
    Malformed(String),
}

fn malformed(message: impl Into<String>) -> PmTilesError {
    PmTilesError::Malformed(message.into())
}

/// Reads a varint at `*at`, advancing it.
fn read_varint(bytes: &[u8], at: &mut usize) -> Result<u64, PmTilesError> {
    let mut v = 0u64;
    for shift in (0..64).step_by(7) {
        let b = *bytes
            .get(*at)
            .ok_or_else(|| malformed(format!("directory ends inside a varint at byte {at}")))?;
        *at += 1;
        v |= u64::from(b & 0x7f) << shift;
        if b & 0x80 == 0 {
            return Ok(v);
        }
    }
    Err(malformed(format!(
        "varint longer than 64 bits before byte {at}"
    )))
}

/// A directory, uncompressed, in the specification's column layout.
pub fn encode_directory(entries: &[Entry]) -> Vec<u8> {
    let mut out = Vec::with_capacity(entries.len() * 6);
    write_varint(&mut out, entries.len() as u64);
    let mut last = 0;
    for e in entries {
        write_varint(&mut out, e.tile_id - last);
        last = e.tile_id;
    }
    for e in entries {
        write_varint(&mut out, u64::from(e.run_length));
    }
    for e in entries {
        write_varint(&mut out, u64::from(e.length));
    }
    for (i, e) in entries.iter().enumerate() {
        if i > 0 && e.offset == entries[i - 1].offset + u64::from(entries[i - 1].length) {
            write_varint(&mut out, 0);
        } else {
            write_varint(&mut out, e.offset + 1);
        }
    }
    out
}

/// Parses an uncompressed directory. Every entry takes at least four bytes, so a count larger
/// than the input allows is refused before anything is allocated.
pub fn decode_directory(bytes: &[u8]) -> Result<Vec<Entry>, PmTilesError> {
    let mut at = 0;
    let n = read_varint(bytes, &mut at)?;
    if n > (bytes.len() as u64) / 4 {
        return Err(malformed(format!(
            "directory claims {n} entries in {} bytes",
            bytes.len()
        )));
    }
    let n = n as usize;
    let mut entries = vec![
        Entry {
            tile_id: 0,
            offset: 0,
            length: 0,
            run_length: 0
        };
        n
    ];
    let mut last = 0u64;
    for e in &mut entries {
        last = last
            .checked_add(read_varint(bytes, &mut at)?)
            .ok_or_else(|| malformed("tile ID overflows"))?;
        e.tile_id = last;
    }
    for e in &mut entries {
        e.run_length = u32::try_from(read_varint(bytes, &mut at)?)
            .map_err(|_| malformed("run length over 32 bits"))?;
    }
    for e in &mut entries {
        e.length = u32::try_from(read_varint(bytes, &mut at)?)
            .map_err(|_| malformed("entry length over 32 bits"))?;
    }
    for i in 0..n {
        let v = read_varint(bytes, &mut at)?;
        entries[i].offset = if v == 0 {
            if i == 0 {
                return Err(malformed("first entry has a relative offset"));
            }
            let prev = entries[i - 1];
            prev.offset
                .checked_add(u64::from(prev.length))
                .ok_or_else(|| malformed("offset overflows"))?
        } else {
            v - 1
        };
    }
    Ok(entries)
}

/// The entry of a sorted directory that holds `tile_id`: a tile run covering it, or the leaf
/// directory whose range it falls in.
pub fn find_entry(entries: &[Entry], tile_id: u64) -> Option<Entry> {
    let i = entries.partition_point(|e| e.tile_id <= tile_id);
    let e = *entries.get(i.checked_sub(1)?)?;
    if e.run_length == 0 || tile_id - e.tile_id < u64::from(e.run_length) {
        Some(e)
    } else {
        None
    }
}

/// Compression codes of the header.
pub mod compression {
    /// Unknown.
    pub const UNKNOWN: u8 = 0;
    /// None.
    pub const NONE: u8 = 1;
    /// Gzip.
    pub const GZIP: u8 = 2;
}

/// The 127-byte header.
#[derive(Clone, Copy, Debug, Default, PartialEq, Eq)]
pub struct Header {
    /// Root directory offset and length.
    pub root: (u64, u64),
    /// JSON metadata offset and length.
    pub metadata: (u64, u64),
    /// Leaf directories section offset and length.
    pub leaves: (u64, u64),
    /// Tile data section offset and length.
    pub data: (u64, u64),
    /// Addressed tiles.
    pub addressed_tiles: u64,
    /// Tile entries.
    pub tile_entries: u64,
    /// Distinct tile contents.
    pub tile_contents: u64,
    /// Whether the data is in tile-ID order.
    pub clustered: bool,
    /// Compression of directories and metadata ([`compression`]).
    pub internal_compression: u8,
    /// Compression of tiles.
    pub tile_compression: u8,
    /// 1 MVT, 2 PNG, 3 JPEG, 4 WebP, 5 AVIF.
    pub tile_type: u8,
    /// Shallowest zoom.
    pub min_zoom: u8,
    /// Deepest zoom.
    pub max_zoom: u8,
    /// West, south, east, north in units of 1e-7 degrees.
    pub bounds_e7: [i32; 4],
    /// Zoom to open at.
    pub centre_zoom: u8,
    /// Longitude and latitude to open at, 1e-7 degrees.
    pub centre_e7: [i32; 2],
}

impl Header {
    /// The header's bytes.
    pub fn to_bytes(&self) -> [u8; HEADER_LEN] {
        let mut h = Vec::with_capacity(HEADER_LEN);
        h.extend_from_slice(b"PMTiles\x03");
        for v in [
            self.root.0,
            self.root.1,
            self.metadata.0,
            self.metadata.1,
            self.leaves.0,
            self.leaves.1,
            self.data.0,
            self.data.1,
            self.addressed_tiles,
            self.tile_entries,
            self.tile_contents,
        ] {
            h.extend_from_slice(&v.to_le_bytes());
        }
        h.extend_from_slice(&[
            u8::from(self.clustered),
            self.internal_compression,
            self.tile_compression,
            self.tile_type,
            self.min_zoom,
            self.max_zoom,
        ]);
        for v in self.bounds_e7 {
            h.extend_from_slice(&v.to_le_bytes());
        }
        h.push(self.centre_zoom);
        for v in self.centre_e7 {
            h.extend_from_slice(&v.to_le_bytes());
        }
        let mut out = [0u8; HEADER_LEN];
        out.copy_from_slice(&h);
        out
    }

    /// Parses a header (the first 127 bytes of `bytes`).
    pub fn parse(bytes: &[u8]) -> Result<Self, PmTilesError> {
        if bytes.len() < HEADER_LEN {
            return Err(malformed(format!(
                "header needs {HEADER_LEN} bytes, got {}",
                bytes.len()
            )));
        }
        if &bytes[..7] != b"PMTiles" {
            return Err(PmTilesError::NotPmTiles);
        }
        if bytes[7] != 3 {
            return Err(PmTilesError::Version(bytes[7]));
        }
        let u64_at = |i: usize| {
            let mut b = [0u8; 8];
            b.copy_from_slice(&bytes[8 + 8 * i..16 + 8 * i]);
            u64::from_le_bytes(b)
        };
        let i32_at = |o: usize| {
            let mut b = [0u8; 4];
            b.copy_from_slice(&bytes[o..o + 4]);
            i32::from_le_bytes(b)
        };
        Ok(Self {
            root: (u64_at(0), u64_at(1)),
            metadata: (u64_at(2), u64_at(3)),
            leaves: (u64_at(4), u64_at(5)),
            data: (u64_at(6), u64_at(7)),
            addressed_tiles: u64_at(8),
            tile_entries: u64_at(9),
            tile_contents: u64_at(10),
            clustered: bytes[96] == 1,
            internal_compression: bytes[97],
            tile_compression: bytes[98],
            tile_type: bytes[99],
            min_zoom: bytes[100],
            max_zoom: bytes[101],
            bounds_e7: [i32_at(102), i32_at(106), i32_at(110), i32_at(114)],
            centre_zoom: bytes[118],
            centre_e7: [i32_at(119), i32_at(123)],
        })
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn tile_ids_follow_the_specification() {
        // Values checked with the `pmtiles` Python package's zxy_to_tileid (3.8.1).
        assert_eq!(tile_id(0, 0, 0), 0);
        assert_eq!(tile_id(1, 0, 0), 1);
        assert_eq!(tile_id(1, 0, 1), 2);
        assert_eq!(tile_id(1, 1, 1), 3);
        assert_eq!(tile_id(1, 1, 0), 4);
        assert_eq!(tile_id(2, 0, 0), 5);
        assert_eq!(tile_id(12, 3423, 1763), 19_078_479);
        // Every tile of a level gets a distinct ID in the level's range.
        let z = 5;
        let mut ids: Vec<u64> = (0..32)
            .flat_map(|x| (0..32).map(move |y| tile_id(z, x, y)))
            .collect();
        ids.sort_unstable();
        ids.dedup();
        assert_eq!(ids.len(), 1024);
        assert_eq!(ids[0], (4u64.pow(5) - 1) / 3);
    }

    #[test]
    fn directories_and_headers_round_trip() {
        let entries = vec![
            Entry {
                tile_id: 0,
                offset: 0,
                length: 100,
                run_length: 1,
            },
            Entry {
                tile_id: 5,
                offset: 100,
                length: 7,
                run_length: 3,
            },
            Entry {
                tile_id: 9,
                offset: 20,
                length: 300,
                run_length: 0,
            },
        ];
        let bytes = encode_directory(&entries);
        assert_eq!(decode_directory(&bytes), Ok(entries.clone()));
        assert_eq!(find_entry(&entries, 6).map(|e| e.tile_id), Some(5));
        assert_eq!(find_entry(&entries, 8), None);
        assert_eq!(find_entry(&entries, 1000).map(|e| e.tile_id), Some(9));
        let h = Header {
            root: (127, 40),
            data: (1000, 5),
            min_zoom: 1,
            max_zoom: 9,
            bounds_e7: [-1_800_000_000, -850_000_000, 1_800_000_000, 850_000_000],
            tile_type: 2,
            clustered: true,
            ..Header::default()
        };
        assert_eq!(Header::parse(&h.to_bytes()), Ok(h));
    }

    #[test]
    fn hostile_directories_fail_cleanly() {
        assert!(decode_directory(&[]).is_err());
        assert!(decode_directory(&[0xff; 11]).is_err());
        // A count of a billion entries in five bytes: refused before allocating.
        let mut b = Vec::new();
        write_varint(&mut b, 1 << 30);
        assert!(decode_directory(&b).is_err());
        for len in 0..40 {
            let bytes: Vec<u8> = (0..len).map(|i| (i * 37 + 11) as u8).collect();
            let _ = decode_directory(&bytes);
            let _ = Header::parse(&bytes);
        }
        assert!(Header::parse(&[0u8; 127]).is_err());
    }
}
