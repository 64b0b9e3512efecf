//! `globus-vector`: vector data for the globe, on the CPU.
//!
//! * [`read`]: GeoJSON (RFC 7946) and GeoJSON text sequences (RFC 8142) streamed feature by
//!   feature, and the airspace layout of the `traffic` package.
//! * [`style`]: simplestyle properties, vertical limits (`m`, `ft`, `FL`), overrides and
//!   defaults.
//! * [`feature`]: features checked part by part, each problem a warning.
//! * [`shape`]: positions, rings over the antimeridian and the poles, geodesic and rhumb
//!   densification, triangulation.
//! * [`drape`]: lines and fills cut along the triangles of a drawn terrain tile, so they lie
//!   on it exactly.
//! * [`simplify`]: lines ranked once for Douglas-Peucker at every tolerance, read per tile
//!   at the tolerance its size asks for.
//!
//! Everything here is deterministic f64 code tested without a GPU; the engine's vector
//! overlay (`globus_engine::vector`) turns it into GPU buffers.

pub mod drape;
pub mod feature;
pub mod load;
pub mod read;
pub mod shape;
pub mod simplify;
pub mod style;

pub use drape::{DrapeSurface, DrapedSegment, DrapedTriangle, SurfacePoint};
pub use feature::{Feature, from_geojson};
pub use load::{FeatureWarning, Loaded, load_file};
pub use read::{Flow, MAX_FEATURE_BYTES, ReadError, ReadSummary, read, read_file};
pub use simplify::{LineIndex, Selection};
pub use style::{Clamp, LineCap, LineJoin, PathKind, Rgba, Style, StyleRules, label_text};
