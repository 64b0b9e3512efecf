//! Air traffic for Globus, on the CPU: reading recorded flights (OpenSky's historical
//! state-vector CSV layout, plain or gzip) into per-aircraft tracks.
//!
//! This is the first part of the air-traffic issue: the replay clock, synthetic traffic, the
//! columnar entity batches and their drawing build on these tracks.

pub mod record;

pub use record::{
    FLIGHT_GAP_S, Record, RecordError, Report, Skip, SkipKind, Track, read_record, read_record_from,
};
