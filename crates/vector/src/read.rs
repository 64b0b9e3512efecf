//! Reading GeoJSON without holding the file: RFC 7946 texts (a FeatureCollection, a Feature
//! or a bare geometry), RFC 8142 GeoJSON text sequences (records after an RS byte), and the
//! airspace layout of the `traffic` package (`{"name", "type", "shapes": [{"lower", "upper",
//! "polygon"}]}`, limits in flight levels).
//!
//! A FeatureCollection's `features` array is parsed one feature at a time through a serde
//! visitor (the `geojson` crate's own `FeatureReader` does the same, but stops at the first
//! feature that does not convert): each feature is handed to the caller and dropped, so
//! memory is bounded by the largest feature, which may take at most [`MAX_FEATURE_BYTES`]
//! of text. A feature that is not valid GeoJSON is an error for that feature alone; text that
//! is not JSON ends the read there (the features before it are kept) and is reported with its
//! line and column; a file that is neither of the layouts above is one error.

use std::cell::Cell;
use std::fmt;
use std::io::{BufRead, BufReader, Read};
use std::path::{Path, PathBuf};
use std::rc::Rc;

use serde::de::{DeserializeSeed, MapAccess, SeqAccess, Visitor};
use serde_json::{Map, Value};

/// Largest text of one feature (or one RFC 8142 record), bytes.
pub const MAX_FEATURE_BYTES: u64 = 16 << 20;

/// Why a file could not be read at all.
#[derive(Debug, thiserror::Error)]
pub enum ReadError {
    /// Opening or reading failed.
    #[error("{path}: {cause}")]
    Io {
        /// The file.
        path: PathBuf,
        /// What went wrong (quoted by the message and not also its `source()`, so a chain
        /// printed whole says it once).
        cause: std::io::Error,
    },
    /// The file is not GeoJSON (nor a text sequence or the airspace layout).
    #[error("{path}: not GeoJSON: {reason}")]
    NotGeoJson {
        /// The file.
        path: PathBuf,
        /// What was found instead.
        reason: String,
    },
}

/// How a read ended.
#[derive(Clone, Debug, Default, PartialEq, Eq)]
pub struct ReadSummary {
    /// Features handed to the sink (good or bad).
    pub features: usize,
    /// The read stopped early: what stopped it (text that is not JSON, a feature over
    /// [`MAX_FEATURE_BYTES`]); the features before it were delivered.
    pub stopped: Option<String>,
}

/// Why one record of a file is not a feature. Messages quote their cause, which is not also
/// their `source()`: a chain printed whole says it once.
#[derive(Debug, thiserror::Error)]
pub enum FeatureError {
    /// An RFC 8142 record that is not JSON.
    #[error("not JSON: {0}")]
    NotJson(serde_json::Error),
    /// JSON that the `geojson` crate does not take as a feature or geometry.
    #[error("{0}")]
    GeoJson(Box<geojson::Error>),
    /// An object of another type.
    #[error("a {0:?}, not a Feature")]
    NotAFeature(String),
    /// An object without `type`.
    #[error("an object without a \"type\"")]
    NoType,
    /// An airspace shape that is not an object with a `polygon`.
    #[error("a shape {0}")]
    Shape(&'static str),
}

impl From<serde_json::Error> for FeatureError {
    fn from(e: serde_json::Error) -> Self {
        Self::NotJson(e)
    }
}

impl From<Box<geojson::Error>> for FeatureError {
    fn from(e: Box<geojson::Error>) -> Self {
        Self::GeoJson(e)
    }
}

/// One feature as read, or why it is not one.
pub type RawFeature = Result<geojson::Feature, FeatureError>;

/// What a sink says after each feature: read on, or stop the read (for this reason, which
/// becomes [`ReadSummary::stopped`]).
pub type Flow = std::ops::ControlFlow<String>;

/// Reads `path`, handing each feature to `sink` with its index in the file, until the sink
/// says stop.
pub fn read_file(
    path: &Path,
    sink: &mut dyn FnMut(usize, RawFeature) -> Flow,
) -> Result<ReadSummary, ReadError> {
    let io = |cause| ReadError::Io {
        path: path.to_owned(),
        cause,
    };
    let file = globus_tiling::files::open_regular(path).map_err(io)?;
    read(path, file, sink)
}

/// Reads GeoJSON from `reader` (`path` names it in errors).
pub fn read(
    path: &Path,
    reader: impl Read,
    sink: &mut dyn FnMut(usize, RawFeature) -> Flow,
) -> Result<ReadSummary, ReadError> {
    let counter = Rc::new(Cell::new(0u64));
    let mut buffered = BufReader::with_capacity(
        1 << 16,
        Counted {
            inner: reader,
            read: counter.clone(),
        },
    );
    let first = loop {
        let buf = buffered.fill_buf().map_err(|cause| ReadError::Io {
            path: path.to_owned(),
            cause,
        })?;
        let Some(&b) = buf.first() else {
            return Err(not_geojson(path, "the file is empty"));
        };
        if b.is_ascii_whitespace() || b == 0xEF || b == 0xBB || b == 0xBF {
            buffered.consume(1); // whitespace or a UTF-8 byte-order mark
            continue;
        }
        break b;
    };
    match first {
        0x1E => Ok(read_sequence(path, buffered, sink)),
        b'{' => read_object(path, buffered, counter, sink),
        _ => Err(not_geojson(
            path,
            &format!("it starts with {:?}, not a JSON object", char::from(first)),
        )),
    }
}

fn not_geojson(path: &Path, reason: &str) -> ReadError {
    ReadError::NotGeoJson {
        path: path.to_owned(),
        reason: reason.to_owned(),
    }
}

/// A reader that counts the bytes read since the counter was last reset, and fails past
/// [`MAX_FEATURE_BYTES`].
struct Counted<R> {
    inner: R,
    read: Rc<Cell<u64>>,
}

impl<R: Read> Read for Counted<R> {
    fn read(&mut self, buf: &mut [u8]) -> std::io::Result<usize> {
        if self.read.get() > MAX_FEATURE_BYTES + (1 << 16) {
            return Err(std::io::Error::other(format!(
                "a feature larger than {} MiB",
                MAX_FEATURE_BYTES >> 20
            )));
        }
        let n = self.inner.read(buf)?;
        self.read.set(self.read.get() + n as u64);
        Ok(n)
    }
}

fn read_sequence(
    path: &Path,
    mut reader: impl BufRead,
    sink: &mut dyn FnMut(usize, RawFeature) -> Flow,
) -> ReadSummary {
    let mut summary = ReadSummary::default();
    let mut record = Vec::new();
    loop {
        record.clear();
        let limit = MAX_FEATURE_BYTES + 1;
        let n = match (&mut reader).take(limit).read_until(0x1E, &mut record) {
            Ok(n) => n,
            Err(e) => {
                summary.stopped = Some(format!("reading {}: {e}", path.display()));
                break;
            }
        };
        if n == 0 {
            break;
        }
        if record.last() == Some(&0x1E) {
            record.pop();
        } else if n as u64 >= limit {
            summary.stopped = Some(format!(
                "record {} is larger than {} MiB",
                summary.features,
                MAX_FEATURE_BYTES >> 20
            ));
            break;
        }
        if record.iter().all(u8::is_ascii_whitespace) {
            continue;
        }
        let feature = serde_json::from_slice::<Value>(&record)
            .map_err(FeatureError::from)
            .and_then(feature_from_value);
        let flow = sink(summary.features, feature);
        summary.features += 1;
        if let Flow::Break(why) = flow {
            summary.stopped = Some(format!("after record {}: {why}", summary.features - 1));
            break;
        }
    }
    summary
}

fn feature_from_value(value: Value) -> RawFeature {
    match value.get("type").and_then(Value::as_str) {
        Some("Feature") => geojson::Feature::try_from(value).map_err(|e| Box::new(e).into()),
        Some(
            "Point" | "MultiPoint" | "LineString" | "MultiLineString" | "Polygon" | "MultiPolygon"
            | "GeometryCollection",
        ) => geojson::Geometry::try_from(value)
            .map(geojson::Feature::from)
            .map_err(|e| Box::new(e).into()),
        Some(other) => Err(FeatureError::NotAFeature(other.to_owned())),
        None => Err(FeatureError::NoType),
    }
}

fn read_object(
    path: &Path,
    reader: impl Read,
    counter: Rc<Cell<u64>>,
    sink: &mut dyn FnMut(usize, RawFeature) -> Flow,
) -> Result<ReadSummary, ReadError> {
    let mut de = serde_json::Deserializer::from_reader(reader);
    let mut features = 0usize;
    let top = TopLevel {
        sink,
        counter,
        features: &mut features,
    };
    let result = serde::Deserializer::deserialize_map(&mut de, top);
    let rest = match result {
        Ok(rest) => rest,
        Err(e) if features > 0 => {
            return Ok(ReadSummary {
                features,
                stopped: Some(format!("after feature {}: {e}", features - 1)),
            });
        }
        // A read error (the size cap among them) is not a statement about the format.
        Err(e) if e.is_io() => {
            return Err(ReadError::Io {
                path: path.to_owned(),
                cause: std::io::Error::other(e.to_string()),
            });
        }
        Err(e) => return Err(not_geojson(path, &format!("{e}"))),
    };
    if let Err(e) = de.end() {
        return Ok(ReadSummary {
            features,
            stopped: Some(format!("after the top-level object: {e}")),
        });
    }
    let kind = rest.map.get("type").and_then(Value::as_str).unwrap_or("");
    if rest.had_features {
        return Ok(ReadSummary {
            features,
            stopped: None,
        });
    }
    match kind {
        "FeatureCollection" => Err(not_geojson(path, "a FeatureCollection without features")),
        _ if rest.map.contains_key("shapes") => airspace(path, rest.map, sink),
        "" => Err(not_geojson(path, "an object without a \"type\"")),
        "Feature" | "Point" | "MultiPoint" | "LineString" | "MultiLineString" | "Polygon"
        | "MultiPolygon" | "GeometryCollection" => {
            let stopped = sink(0, feature_from_value(Value::Object(rest.map))).break_value();
            Ok(ReadSummary {
                features: 1,
                stopped,
            })
        }
        other => Err(not_geojson(path, &format!("a {other:?} object"))),
    }
}

/// The `traffic` package's airspace layout: each shape becomes a feature whose properties
/// are the airspace's name and type and the shape's limits in flight levels.
fn airspace(
    path: &Path,
    mut map: Map<String, Value>,
    sink: &mut dyn FnMut(usize, RawFeature) -> Flow,
) -> Result<ReadSummary, ReadError> {
    let Some(Value::Array(shapes)) = map.remove("shapes") else {
        return Err(not_geojson(path, "\"shapes\" is not a list"));
    };
    let mut summary = ReadSummary::default();
    for (i, shape) in shapes.into_iter().enumerate() {
        let feature = (|| {
            let Value::Object(mut shape) = shape else {
                return Err(FeatureError::Shape("that is not an object"));
            };
            let polygon = shape
                .remove("polygon")
                .ok_or(FeatureError::Shape("without \"polygon\""))?;
            let geometry = geojson::Geometry::try_from(polygon)
                .map_err(|e| FeatureError::from(Box::new(e)))?;
            let mut properties = Map::new();
            for key in ["name", "type", "designator"] {
                if let Some(v) = map.get(key) {
                    properties.insert(key.to_owned(), v.clone());
                }
            }
            for key in ["lower", "upper"] {
                let v = shape.remove(key).unwrap_or(Value::Null);
                properties.insert(key.to_owned(), v);
            }
            properties.insert("units".to_owned(), Value::String("FL".to_owned()));
            Ok(geojson::Feature {
                geometry: Some(geometry),
                properties: Some(properties),
                ..Default::default()
            })
        })();
        let flow = sink(i, feature);
        summary.features += 1;
        if let Flow::Break(why) = flow {
            summary.stopped = Some(format!("after shape {i}: {why}"));
            break;
        }
    }
    Ok(summary)
}

/// The top-level object: `features` streamed to the sink, every other key kept.
struct TopLevel<'a> {
    sink: &'a mut dyn FnMut(usize, RawFeature) -> Flow,
    counter: Rc<Cell<u64>>,
    features: &'a mut usize,
}

struct Rest {
    map: Map<String, Value>,
    had_features: bool,
}

impl<'de> Visitor<'de> for TopLevel<'_> {
    type Value = Rest;

    fn expecting(&self, f: &mut fmt::Formatter) -> fmt::Result {
        f.write_str("a GeoJSON object")
    }

    fn visit_map<A: MapAccess<'de>>(self, mut access: A) -> Result<Rest, A::Error> {
        let mut rest = Rest {
            map: Map::new(),
            had_features: false,
        };
        let TopLevel {
            sink,
            counter,
            features,
        } = self;
        while let Some(key) = access.next_key::<String>()? {
            if key == "features" {
                rest.had_features = true;
                access.next_value_seed(Features {
                    sink: &mut *sink,
                    counter: counter.clone(),
                    features: &mut *features,
                })?;
            } else {
                let v: Value = access.next_value()?;
                rest.map.insert(key, v);
            }
        }
        Ok(rest)
    }
}

struct Features<'a> {
    sink: &'a mut dyn FnMut(usize, RawFeature) -> Flow,
    counter: Rc<Cell<u64>>,
    features: &'a mut usize,
}

impl<'de> DeserializeSeed<'de> for Features<'_> {
    type Value = ();

    fn deserialize<D: serde::Deserializer<'de>>(self, d: D) -> Result<(), D::Error> {
        d.deserialize_seq(self)
    }
}

impl<'de> Visitor<'de> for Features<'_> {
    type Value = ();

    fn expecting(&self, f: &mut fmt::Formatter) -> fmt::Result {
        f.write_str("a list of features")
    }

    fn visit_seq<A: SeqAccess<'de>>(self, mut seq: A) -> Result<(), A::Error> {
        self.counter.set(0);
        while let Some(v) = seq.next_element::<Value>()? {
            self.counter.set(0);
            let flow = (self.sink)(*self.features, feature_from_value(v));
            *self.features += 1;
            if let Flow::Break(why) = flow {
                return Err(serde::de::Error::custom(why));
            }
        }
        Ok(())
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    fn read_all(text: &[u8]) -> Result<(Vec<RawFeature>, ReadSummary), ReadError> {
        let mut out = Vec::new();
        let summary = read(Path::new("test.geojson"), text, &mut |i, f| {
            assert_eq!(i, out.len());
            out.push(f);
            Flow::Continue(())
        })?;
        Ok((out, summary))
    }

    #[test]
    fn a_collection_streams_its_features_and_keeps_going_past_bad_ones() {
        let text = br#"{"type": "FeatureCollection", "name": "x", "features": [
            {"type": "Feature", "properties": {"a": 1}, "geometry": {"type": "Point", "coordinates": [1, 2]}},
            {"type": "Feature", "geometry": {"type": "Hexagon", "coordinates": []}},
            {"type": "Banana"},
            {"type": "Feature", "properties": null, "geometry": {"type": "LineString", "coordinates": [[0, 0], [1, 1]]}}
        ]}"#;
        let (f, s) = read_all(text).unwrap();
        assert_eq!(
            s,
            ReadSummary {
                features: 4,
                stopped: None
            }
        );
        assert!(f[0].is_ok() && f[3].is_ok());
        assert!(f[1].is_err() && f[2].is_err(), "{f:?}");
    }

    #[test]
    fn text_that_breaks_off_keeps_the_features_before() {
        let text = br#"{"type": "FeatureCollection", "features": [
            {"type": "Feature", "properties": {}, "geometry": {"type": "Point", "coordinates": [1, 2]}},
            {"type": "Feature", "geometry": {"type": "Point", "coord"#;
        let (f, s) = read_all(text).unwrap();
        assert_eq!(f.len(), 1);
        assert!(
            s.stopped
                .as_deref()
                .is_some_and(|m| m.contains("after feature 0")),
            "{s:?}"
        );
    }

    #[test]
    fn sequences_single_features_and_bare_geometries() {
        let seq = b"\x1e{\"type\":\"Feature\",\"properties\":{},\"geometry\":{\"type\":\"Point\",\"coordinates\":[1,2]}}\n\x1e{oops\n\x1e{\"type\":\"Point\",\"coordinates\":[3,4]}\n";
        let (f, s) = read_all(seq).unwrap();
        assert_eq!(s.features, 3);
        assert!(f[0].is_ok() && f[1].is_err() && f[2].is_ok());
        let (f, _) =
            read_all(br#"{"type": "Polygon", "coordinates": [[[0,0],[1,0],[1,1],[0,0]]]}"#)
                .unwrap();
        assert!(f[0].as_ref().is_ok_and(|f| f.geometry.is_some()));
    }

    #[test]
    fn what_is_not_geojson_is_one_error() {
        for text in [
            &b""[..],
            b"   ",
            b"[1, 2]",
            b"PK\x03\x04zip",
            b"{\"a\": 1}",
            b"{\"type\": \"Topology\"}",
            b"{nope",
        ] {
            let e = read_all(text).err();
            assert!(
                matches!(e, Some(ReadError::NotGeoJson { .. })),
                "{:?}: {e:?}",
                String::from_utf8_lossy(text)
            );
        }
    }

    #[test]
    fn the_airspace_layout_becomes_features_with_flight_levels() {
        let text = br#"{"name": "SIV", "type": "AUA", "shapes": [
            {"upper": 65.0, "lower": 0.0, "polygon": {"type": "Polygon", "coordinates": [[[1,44],[2,44],[2,43],[1,44]]]}},
            {"upper": 115.0, "lower": 65.0}
        ]}"#;
        let (f, s) = read_all(text).unwrap();
        assert_eq!(s.features, 2);
        let p = f[0].as_ref().unwrap().properties.clone().unwrap();
        assert_eq!(p["upper"], 65.0);
        assert_eq!(p["units"], "FL");
        assert!(f[1].is_err());
    }

    #[test]
    fn a_feature_over_the_cap_stops_the_read_without_taking_its_size() {
        // A 40 MiB coordinate list: refused after at most the cap was read.
        let mut text = br#"{"type": "FeatureCollection", "features": [{"type": "Feature", "properties": {}, "geometry": {"type": "LineString", "coordinates": ["#.to_vec();
        let point = b"[1.0, 2.0],";
        while text.len() < 40 << 20 {
            text.extend_from_slice(point);
        }
        text.extend_from_slice(b"[1, 2]]}}]}");
        let e = read_all(&text).err();
        assert!(
            matches!(&e, Some(ReadError::Io { .. }))
                && e.as_ref()
                    .is_some_and(|e| e.to_string().contains("larger than 16 MiB")),
            "{e:?}"
        );
    }
}
