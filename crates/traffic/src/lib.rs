//! Air traffic for Globus, on the CPU: reading recorded flights (OpenSky's historical
//! state-vector CSV layout, plain or gzip) into flights ([`record`]), making deterministic
//! synthetic records between real airports ([`synth`]), and the aircraft kinds drawn
//! ([`kind`]).
//!
//! This is the first part of the air-traffic issue: the replay clock, synthetic traffic, the
//! columnar entity batches and their drawing build on these tracks.

pub mod fleet;
pub mod kind;
pub mod record;
pub mod synth;

pub use fleet::{Batch, Fleet, FleetError, FleetOptions, Sample, Sampled};
pub use kind::AircraftKind;
pub use record::{
    FLIGHT_GAP_S, Record, RecordError, Report, Skip, SkipKind, Track, read_record, read_record_from,
};
