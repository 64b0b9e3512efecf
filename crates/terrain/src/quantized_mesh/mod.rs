//! Cesium's quantized-mesh-1.0 terrain format
//! (<https://github.com/CesiumGS/quantized-mesh>), encoded and decoded.
//!
//! ```text
//! header      88 bytes: centre (3 x f64 ECEF), min/max height (2 x f32), bounding sphere
//!             (4 x f64), horizon occlusion point (3 x f64, ellipsoid-scaled space)
//! vertices    u32 count, then u, v, height arrays of u16 (0..=32767), each zig-zag
//!             delta-encoded from the previous vertex
//! indices     padded to 4 bytes when 32-bit; u32 triangle count, then indices (u16, or u32
//!             when there are more than 65536 vertices) high-water-mark encoded
//! edges       west, south, east, north: u32 count + plain indices each
//! extensions  repeated: u8 id, u32 length, bytes (1 oct normals, 2 water mask, 4 metadata)
//! ```
//!
//! Everything is little-endian. Files may be gzip'd (as servers usually store them); the
//! decoder recognises the gzip magic and inflates under [`MAX_INFLATED_BYTES`].
//!
//! Decoding takes untrusted bytes: every count is checked against the bytes that remain
//! before anything is allocated, every index against the vertex count, and no input makes it
//! panic (fuzzed with `cargo fuzz`, see `fuzz/`).

mod from_grid;

use std::io::Read;

use globus_geo::DVec3;

pub use from_grid::{BorderRing, QuantizedMeshOptions, TileProjection, from_adaptive_mesh};

/// Largest value of u, v and height.
pub const QUANTIZED_MAX: u16 = 32767;
/// The decoder refuses gzip'd input that inflates to more than this.
pub const MAX_INFLATED_BYTES: u64 = 256 << 20;
/// Bytes in the header.
pub const HEADER_BYTES: usize = 88;

/// Extension ids.
const EXT_NORMALS: u8 = 1;
const EXT_WATER_MASK: u8 = 2;
const EXT_METADATA: u8 = 4;

/// The fixed header of a quantized-mesh tile.
#[derive(Clone, Copy, Debug, Default, PartialEq)]
pub struct Header {
    /// Tile centre in ECEF metres; vertices are relative to it when rendered.
    pub centre: DVec3,
    /// Height that quantized height 0 stands for, metres above the ellipsoid.
    pub min_height_m: f32,
    /// Height that quantized height 32767 stands for.
    pub max_height_m: f32,
    /// Bounding sphere centre, ECEF.
    pub sphere_centre: DVec3,
    /// Bounding sphere radius, metres.
    pub sphere_radius_m: f64,
    /// Horizon occlusion point in ellipsoid-scaled space.
    pub horizon_occlusion_point: DVec3,
}

impl Header {
    /// Refuses what no tile can hold: non-finite values, heights beyond
    /// [`crate::MAX_ABS_HEIGHT_M`], a minimum above the maximum, a negative radius, a centre
    /// or sphere farther than a planet's size (a bounding volume of 1e30 m culls nothing and
    /// refines for ever).
    pub fn check(&self) -> Result<(), DecodeError> {
        let bad = |what: String| Err(DecodeError::BadHeader(what));
        let (lo, hi) = (f64::from(self.min_height_m), f64::from(self.max_height_m));
        if !(lo.abs() <= crate::MAX_ABS_HEIGHT_M && hi.abs() <= crate::MAX_ABS_HEIGHT_M) {
            return bad(format!(
                "heights {lo} .. {hi} m are not numbers within +-{} m",
                crate::MAX_ABS_HEIGHT_M
            ));
        }
        if lo > hi {
            return bad(format!("minimum height {lo} m is above the maximum {hi} m"));
        }
        // Farther than any body Globus draws (Jupiter's radius is 7.1e7 m).
        const FAR_M: f64 = 1e9;
        let near = |p: DVec3| p.is_finite() && p.length() <= FAR_M;
        if !near(self.centre) || !near(self.sphere_centre) {
            return bad(format!(
                "centre {:?} or bounding sphere centre {:?} is not a point near a planet",
                self.centre, self.sphere_centre
            ));
        }
        if !(self.sphere_radius_m >= 0.0 && self.sphere_radius_m <= FAR_M) {
            return bad(format!("bounding sphere radius {} m", self.sphere_radius_m));
        }
        if !self.horizon_occlusion_point.is_finite() {
            return bad(format!(
                "horizon occlusion point {:?}",
                self.horizon_occlusion_point
            ));
        }
        Ok(())
    }
}

/// The water mask extension.
#[derive(Clone, Debug, PartialEq)]
pub enum WaterMask {
    /// The whole tile: 0 = land, 255 = water.
    Uniform(u8),
    /// 256 x 256 bytes, north row first, 0 = land and 255 = water.
    Grid(Vec<u8>),
}

/// A decoded (or to-be-encoded) quantized-mesh tile.
#[derive(Clone, Debug, Default, PartialEq)]
pub struct QuantizedMesh {
    /// The header.
    pub header: Header,
    /// Per vertex, west (0) to east (32767).
    pub u: Vec<u16>,
    /// Per vertex, south (0) to north (32767).
    pub v: Vec<u16>,
    /// Per vertex, min height (0) to max height (32767).
    pub height: Vec<u16>,
    /// Triangle list, counter-clockwise seen from above.
    pub indices: Vec<u32>,
    /// Vertices on the west edge.
    pub west: Vec<u32>,
    /// Vertices on the south edge.
    pub south: Vec<u32>,
    /// Vertices on the east edge.
    pub east: Vec<u32>,
    /// Vertices on the north edge.
    pub north: Vec<u32>,
    /// Oct-encoded unit normals, two bytes per vertex (extension 1).
    pub normals: Option<Vec<[u8; 2]>>,
    /// Water mask (extension 2).
    pub water_mask: Option<WaterMask>,
    /// JSON metadata (extension 4).
    pub metadata: Option<String>,
}

/// Why bytes are not a quantized-mesh tile.
#[derive(Debug, thiserror::Error, PartialEq)]
pub enum DecodeError {
    /// The data ended early.
    #[error("quantized-mesh data ends at byte {at} while reading {what}")]
    Truncated {
        /// What was being read.
        what: &'static str,
        /// Offset where the data ran out.
        at: usize,
    },
    /// A count promises more data than there is.
    #[error("quantized-mesh {what} count {count} needs more bytes than the {left} left")]
    CountTooLarge {
        /// Which count.
        what: &'static str,
        /// The count read.
        count: u64,
        /// Bytes left.
        left: usize,
    },
    /// A vertex index points past the vertices.
    #[error("quantized-mesh {what} index {index} is out of range for {vertices} vertices")]
    IndexOutOfRange {
        /// Which list.
        what: &'static str,
        /// The index.
        index: u64,
        /// Vertex count.
        vertices: usize,
    },
    /// A quantized coordinate outside 0..=32767.
    #[error("quantized-mesh vertex {vertex} has {what} {value}, beyond 32767")]
    CoordinateOutOfRange {
        /// u, v or height.
        what: &'static str,
        /// The vertex.
        vertex: usize,
        /// Decoded value.
        value: i32,
    },
    /// An extension is malformed.
    #[error("quantized-mesh extension {id}: {why}")]
    BadExtension {
        /// Extension id.
        id: u8,
        /// What is wrong.
        why: String,
    },
    /// The header holds values no tile can have (NaN, heights beyond
    /// [`crate::MAX_ABS_HEIGHT_M`], a minimum above the maximum).
    #[error("quantized-mesh header: {0}")]
    BadHeader(String),
    /// The tile has no triangles (or fewer than three vertices).
    #[error("quantized-mesh tile is empty: {vertices} vertices, {triangles} triangles")]
    Empty {
        /// Vertex count.
        vertices: usize,
        /// Triangle count.
        triangles: usize,
    },
    /// gzip data is corrupt or inflates beyond [`MAX_INFLATED_BYTES`].
    #[error("quantized-mesh gzip data: {0}")]
    Gzip(String),
}

impl QuantizedMesh {
    /// Vertex count.
    pub fn vertex_count(&self) -> usize {
        self.u.len()
    }

    /// Triangle count.
    pub fn triangle_count(&self) -> usize {
        self.indices.len() / 3
    }

    /// The height of vertex `i` in metres.
    pub fn height_m(&self, i: usize) -> f64 {
        let (lo, hi) = (
            f64::from(self.header.min_height_m),
            f64::from(self.header.max_height_m),
        );
        lo + (hi - lo) * f64::from(self.height[i]) / f64::from(QUANTIZED_MAX)
    }

    /// Encodes the tile; `gzip` compresses the result as tile servers store it.
    pub fn encode(&self, gzip: bool) -> Vec<u8> {
        let mut out = Vec::with_capacity(HEADER_BYTES + self.u.len() * 6 + self.indices.len() * 4);
        let h = &self.header;
        for c in [h.centre.x, h.centre.y, h.centre.z] {
            out.extend_from_slice(&c.to_le_bytes());
        }
        out.extend_from_slice(&h.min_height_m.to_le_bytes());
        out.extend_from_slice(&h.max_height_m.to_le_bytes());
        for c in [
            h.sphere_centre.x,
            h.sphere_centre.y,
            h.sphere_centre.z,
            h.sphere_radius_m,
            h.horizon_occlusion_point.x,
            h.horizon_occlusion_point.y,
            h.horizon_occlusion_point.z,
        ] {
            out.extend_from_slice(&c.to_le_bytes());
        }
        let n = self.u.len();
        out.extend_from_slice(&(n as u32).to_le_bytes());
        for values in [&self.u, &self.v, &self.height] {
            let mut prev = 0i32;
            for &value in values.iter() {
                let value = i32::from(value);
                out.extend_from_slice(&(zigzag(value - prev) as u16).to_le_bytes());
                prev = value;
            }
        }
        let wide = n > 65536;
        if wide {
            while out.len() % 4 != 0 {
                out.push(0);
            }
        }
        let put = |out: &mut Vec<u8>, i: u32| {
            if wide {
                out.extend_from_slice(&i.to_le_bytes());
            } else {
                out.extend_from_slice(&(i as u16).to_le_bytes());
            }
        };
        out.extend_from_slice(&((self.indices.len() / 3) as u32).to_le_bytes());
        // High-water mark: 0 for the next new vertex, otherwise the distance back from it
        // (modulo the index width, as Cesium decodes it).
        let mut highest = 0u32;
        for &i in &self.indices[..self.indices.len() / 3 * 3] {
            let code = highest.wrapping_sub(i);
            put(&mut out, code);
            if code == 0 {
                highest += 1;
            }
        }
        for edge in [&self.west, &self.south, &self.east, &self.north] {
            out.extend_from_slice(&(edge.len() as u32).to_le_bytes());
            for &i in edge.iter() {
                put(&mut out, i);
            }
        }
        self.encode_extensions(&mut out);
        if gzip { gzip_bytes(&out) } else { out }
    }

    fn encode_extensions(&self, out: &mut Vec<u8>) {
        let mut extension = |id: u8, data: &[u8]| {
            out.push(id);
            out.extend_from_slice(&(data.len() as u32).to_le_bytes());
            out.extend_from_slice(data);
        };
        if let Some(normals) = &self.normals {
            extension(EXT_NORMALS, normals.as_flattened());
        }
        match &self.water_mask {
            Some(WaterMask::Uniform(b)) => extension(EXT_WATER_MASK, &[*b]),
            Some(WaterMask::Grid(g)) => extension(EXT_WATER_MASK, g),
            None => {}
        }
        if let Some(json) = &self.metadata {
            let mut data = (json.len() as u32).to_le_bytes().to_vec();
            data.extend_from_slice(json.as_bytes());
            extension(EXT_METADATA, &data);
        }
    }

    /// Decodes a tile, gzip'd or not.
    pub fn decode(bytes: &[u8]) -> Result<Self, DecodeError> {
        if bytes.starts_with(&[0x1f, 0x8b]) {
            let mut inflated = Vec::new();
            flate2::read::GzDecoder::new(bytes)
                .take(MAX_INFLATED_BYTES + 1)
                .read_to_end(&mut inflated)
                .map_err(|e| DecodeError::Gzip(e.to_string()))?;
            if inflated.len() as u64 > MAX_INFLATED_BYTES {
                return Err(DecodeError::Gzip(format!(
                    "inflates to more than {MAX_INFLATED_BYTES} bytes"
                )));
            }
            return Self::decode_raw(&inflated);
        }
        Self::decode_raw(bytes)
    }

    fn decode_raw(bytes: &[u8]) -> Result<Self, DecodeError> {
        let mut r = Reader { bytes, at: 0 };
        let header = Header {
            centre: r.dvec3("header")?,
            min_height_m: r.f32("header")?,
            max_height_m: r.f32("header")?,
            sphere_centre: r.dvec3("header")?,
            sphere_radius_m: r.f64("header")?,
            horizon_occlusion_point: r.dvec3("header")?,
        };
        header.check()?;
        let n = r.count("vertex", 6)?;
        let mut coords = [Vec::new(), Vec::new(), Vec::new()];
        for (values, what) in coords.iter_mut().zip(["u", "v", "height"]) {
            values.reserve_exact(n);
            let mut value = 0i32;
            for vertex in 0..n {
                value += unzigzag(r.u16(what)?);
                if !(0..=i32::from(QUANTIZED_MAX)).contains(&value) {
                    return Err(DecodeError::CoordinateOutOfRange {
                        what,
                        vertex,
                        value,
                    });
                }
                values.push(value as u16);
            }
        }
        let [u, v, height] = coords;
        let wide = n > 65536;
        if wide {
            r.at = r.at.div_ceil(4) * 4;
        }
        let width = if wide { 4 } else { 2 };
        let triangles = r.count("triangle", 3 * width)?;
        let mut indices = Vec::with_capacity(triangles * 3);
        // Cesium decodes into a typed array, so `highest - code` wraps modulo the index
        // width; encoders (quantized-mesh-encoder among them) rely on it for vertices that
        // are not numbered in order of first use.
        let mask: u64 = if wide {
            u64::from(u32::MAX)
        } else {
            u64::from(u16::MAX)
        };
        let mut highest = 0u64;
        for _ in 0..triangles * 3 {
            let code = r.index(wide)?;
            let index = highest.wrapping_sub(code) & mask;
            if index >= n as u64 {
                return Err(DecodeError::IndexOutOfRange {
                    what: "triangle",
                    index,
                    vertices: n,
                });
            }
            indices.push(index as u32);
            if code == 0 {
                highest += 1;
            }
        }
        let mut edges: [Vec<u32>; 4] = Default::default();
        for (edge, what) in edges.iter_mut().zip(["west", "south", "east", "north"]) {
            let count = r.count(what, width)?;
            edge.reserve_exact(count);
            for _ in 0..count {
                let index = r.index(wide)?;
                if index >= n as u64 {
                    return Err(DecodeError::IndexOutOfRange {
                        what,
                        index,
                        vertices: n,
                    });
                }
                edge.push(index as u32);
            }
        }
        let [west, south, east, north] = edges;
        if n < 3 || triangles == 0 {
            return Err(DecodeError::Empty {
                vertices: n,
                triangles,
            });
        }
        let mut mesh = Self {
            header,
            u,
            v,
            height,
            indices,
            west,
            south,
            east,
            north,
            ..Self::default()
        };
        mesh.decode_extensions(&mut r)?;
        Ok(mesh)
    }

    fn decode_extensions(&mut self, r: &mut Reader<'_>) -> Result<(), DecodeError> {
        while r.at < r.bytes.len() {
            let id = r.u8("extension id")?;
            let len = r.count("extension", 1)?;
            let data = &r.bytes[r.at..r.at + len];
            r.at += len;
            let bad = |why: String| DecodeError::BadExtension { id, why };
            match id {
                EXT_NORMALS => {
                    if len != 2 * self.u.len() {
                        return Err(bad(format!(
                            "{len} bytes of normals for {} vertices",
                            self.u.len()
                        )));
                    }
                    self.normals = Some(data.chunks_exact(2).map(|c| [c[0], c[1]]).collect());
                }
                EXT_WATER_MASK => {
                    self.water_mask = Some(match len {
                        1 => WaterMask::Uniform(data[0]),
                        65536 => WaterMask::Grid(data.to_vec()),
                        _ => return Err(bad(format!("water mask of {len} bytes"))),
                    });
                }
                EXT_METADATA => {
                    let json_len = data
                        .get(..4)
                        .map(|b| u32::from_le_bytes([b[0], b[1], b[2], b[3]]) as usize)
                        .ok_or_else(|| bad("metadata shorter than its length field".into()))?;
                    let json = data
                        .get(4..4usize.saturating_add(json_len))
                        .ok_or_else(|| bad(format!("metadata length {json_len} beyond data")))?;
                    let json = std::str::from_utf8(json)
                        .map_err(|e| bad(format!("metadata is not UTF-8: {e}")))?;
                    self.metadata = Some(json.to_owned());
                }
                _ => {} // Unknown extensions are skipped, as Cesium does.
            }
        }
        Ok(())
    }
}

/// Oct-encodes a unit normal into two bytes the way Cesium's `AttributeCompression.octEncode`
/// does for quantized-mesh (range 0..=255).
pub fn oct_encode_u8(n: DVec3) -> [u8; 2] {
    let p = crate::mesh::oct_project(n);
    let q = |v: f64| ((v.clamp(-1.0, 1.0) * 0.5 + 0.5) * 255.0).round() as u8;
    [q(p.x), q(p.y)]
}

/// Inverse of [`oct_encode_u8`].
pub fn oct_decode_u8(e: [u8; 2]) -> DVec3 {
    let f = |b: u8| f64::from(b) / 255.0 * 2.0 - 1.0;
    crate::mesh::oct_unproject(globus_geo::DVec2::new(f(e[0]), f(e[1])))
}

fn zigzag(v: i32) -> u32 {
    ((v << 1) ^ (v >> 31)) as u32
}

fn unzigzag(v: u16) -> i32 {
    let v = i32::from(v);
    (v >> 1) ^ -(v & 1)
}

fn gzip_bytes(data: &[u8]) -> Vec<u8> {
    use std::io::Write;
    let mut enc = flate2::write::GzEncoder::new(Vec::new(), flate2::Compression::default());
    // Writing to a Vec cannot fail.
    let _ = enc.write_all(data);
    enc.finish().unwrap_or_default()
}

struct Reader<'a> {
    bytes: &'a [u8],
    at: usize,
}

impl Reader<'_> {
    fn take<const N: usize>(&mut self, what: &'static str) -> Result<[u8; N], DecodeError> {
        let at = self.at;
        let chunk = self.bytes.get(at..at + N).ok_or(DecodeError::Truncated {
            what,
            at: at.min(self.bytes.len()),
        })?;
        self.at += N;
        let mut out = [0u8; N];
        out.copy_from_slice(chunk);
        Ok(out)
    }
    fn u8(&mut self, what: &'static str) -> Result<u8, DecodeError> {
        Ok(self.take::<1>(what)?[0])
    }
    fn u16(&mut self, what: &'static str) -> Result<u16, DecodeError> {
        Ok(u16::from_le_bytes(self.take(what)?))
    }
    fn u32(&mut self, what: &'static str) -> Result<u32, DecodeError> {
        Ok(u32::from_le_bytes(self.take(what)?))
    }
    fn f32(&mut self, what: &'static str) -> Result<f32, DecodeError> {
        Ok(f32::from_le_bytes(self.take(what)?))
    }
    fn f64(&mut self, what: &'static str) -> Result<f64, DecodeError> {
        Ok(f64::from_le_bytes(self.take(what)?))
    }
    fn dvec3(&mut self, what: &'static str) -> Result<DVec3, DecodeError> {
        Ok(DVec3::new(
            self.f64(what)?,
            self.f64(what)?,
            self.f64(what)?,
        ))
    }
    fn index(&mut self, wide: bool) -> Result<u64, DecodeError> {
        Ok(if wide {
            u64::from(self.u32("indices")?)
        } else {
            u64::from(self.u16("indices")?)
        })
    }
    /// Reads a u32 count of items of `item_bytes` each and checks that they fit in the rest.
    fn count(&mut self, what: &'static str, item_bytes: usize) -> Result<usize, DecodeError> {
        let count = self.u32(what)?;
        let left = self.bytes.len().saturating_sub(self.at);
        let need = u64::from(count) * item_bytes as u64;
        if need > left as u64 {
            return Err(DecodeError::CountTooLarge {
                what,
                count: u64::from(count),
                left,
            });
        }
        Ok(count as usize)
    }
}

#[cfg(test)]
mod tests;
