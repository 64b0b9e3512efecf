//! Air traffic for Globus, on the CPU: reading recorded flights (OpenSky's historical
//! state-vector CSV layout, plain or gzip) into flights ([`record`]), making deterministic
//! synthetic records between real airports ([`synth`]), and the aircraft kinds drawn
//! ([`kind`]).
//!
//! Records play against a clock ([`replay`]) into a [`Fleet`] of moving objects
//! ([`fleet`]: columnar batches, interpolation, trails), which the engine's traffic layer
//! draws.

pub mod fleet;
pub mod kind;
pub mod record;
pub mod replay;
pub mod synth;

pub use fleet::{Batch, Fleet, FleetError, FleetOptions, Sample, Sampled};
pub use kind::AircraftKind;
pub use record::{
    FLIGHT_GAP_S, Record, RecordError, Report, Skip, SkipKind, Track, read_record, read_record_from,
};
pub use replay::{Replay, ReplayOptions, Step, altitude_colour};
