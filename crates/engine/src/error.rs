//! The engine's errors: one enum for everything that can fail when a globe is built or
//! asked something, each naming what failed. A message that quotes its cause does not also
//! return it as `source()`: a chain printed whole (`{:#}`) says each thing once.

use std::time::Duration;

/// Why a globe could not be built, or a request to it failed.
#[derive(Debug, thiserror::Error)]
pub enum EngineError {
    /// A data source named in the options could not be opened.
    #[error("{}", source_message(what, url, error))]
    Source {
        /// "terrain", "imagery" or "night imagery".
        what: &'static str,
        /// The source's location, as given.
        url: String,
        /// What went wrong (part of the message, not a separate source: printed once).
        error: globus_stream::fetch::OpenError,
    },
    /// A tile of the night imagery could not be read.
    #[error("night imagery {url}: {error}")]
    NightImagery {
        /// The source's location, as given.
        url: String,
        /// What went wrong, naming the tile's URL or file.
        error: globus_stream::fetch::FetchError,
    },
    /// The HTTP settings cannot be sent (control characters in a header, say).
    #[error("HTTP settings: {0}")]
    Http(globus_stream::fetch::OpenError),
    /// The layers opened but cannot be combined into a terrain source.
    #[error("the terrain and imagery layers cannot be combined: {0}")]
    Layers(globus_stream::fetch::OpenError),
    /// The memory budget cannot hold the process and a usable cache and pool.
    #[error(
        "a memory budget of {total_mib} MiB is too small: this process and its frame already hold \
         {baseline_mib} MiB before any tile, and with {workers} loader threads it needs at \
         least {least_mib} MiB"
    )]
    MemoryBudget {
        /// The budget asked for, MiB.
        total_mib: u64,
        /// What the process held before any tile, MiB.
        baseline_mib: u64,
        /// Loader threads the budget must leave room for.
        workers: usize,
        /// The least budget that works, MiB.
        least_mib: u64,
    },
    /// An option is out of its range.
    #[error("{option} {value}: {expected}")]
    InvalidOption {
        /// The option's name.
        option: &'static str,
        /// The value given.
        value: String,
        /// What it must be.
        expected: &'static str,
    },
    /// A budget larger than the machine.
    #[error("{option} of {value_mib} MiB: this machine has {largest_mib} MiB; give at most that")]
    TooLarge {
        /// The option's name.
        option: &'static str,
        /// The value given, MiB.
        value_mib: u64,
        /// The largest that makes sense, MiB.
        largest_mib: u64,
    },
    /// A frame the device cannot draw (larger than its largest texture).
    #[error("a frame of {width}x{height} pixels: this device draws 1 to {largest} pixels a side")]
    FrameSize {
        /// Width asked for.
        width: u32,
        /// Height asked for.
        height: u32,
        /// The device's largest texture side.
        largest: u32,
    },
    /// The GPU could not do what was asked (no adapter, a failed readback).
    #[error(transparent)]
    Render(#[from] globus_render::RenderError),
    /// A measurement needed complete frames and the tiles did not all load in time.
    #[error("tiles still loading after {timeout:?}: frame {frame} of {what}")]
    Incomplete {
        /// What was measured.
        what: &'static str,
        /// The frame that was not complete.
        frame: u32,
        /// How long it waited.
        timeout: Duration,
    },
}

/// "terrain URL: why", or "terrain why" when the reason already names the URL (an
/// archive's own errors name their file): the location is said once.
fn source_message(what: &str, url: &str, error: &globus_stream::fetch::OpenError) -> String {
    let why = error.to_string();
    if why.contains(url) {
        format!("{what} {why}")
    } else {
        format!("{what} {url}: {why}")
    }
}
