//! Fetching a tile's bytes: from a directory, a tile service (URL template or WMS), an MBTiles
//! file or a PMTiles archive (local, or over HTTP range requests).
//!
//! A [`Fetch`] answers one question, "the bytes of tile (z, x, y), please", with bytes, "no
//! data here" (`Ok(None)`: 404, 204, an empty body, a tile missing from an archive) or an
//! error that says whether trying again later may help ([`FetchError::Transient`], with the
//! server's Retry-After if it gave one) or not. Retrying, ordering and cancelling are the
//! scheduler's business; decoding is the source's.

pub mod dir;
pub mod disk_cache;
pub mod http;
pub mod mbtiles;
pub mod pmtiles;
pub mod template;
pub mod wms;

use std::sync::Arc;
use std::sync::atomic::{AtomicBool, Ordering};
use std::time::Duration;

use globus_tiling::{TileKey, TilingScheme};

pub use dir::DirectoryFetch;
// (OpenError is defined below.)
pub use disk_cache::{CachedFetch, DiskCacheOptions, DiskCacheStats};
pub use http::{HttpClient, HttpOptions, TemplateFetch};
pub use mbtiles::MbTilesFetch;
pub use pmtiles::{KeptHead, PmTilesFetch, RangeRead};
pub use template::UrlTemplate;
pub use wms::{WmsFetch, WmsVersion};

/// A flag a load checks between slow steps; set when nobody wants the tile any more.
#[derive(Clone, Debug, Default)]
pub struct Cancel(Arc<AtomicBool>);

impl Cancel {
    /// A token that is not cancelled.
    pub fn new() -> Self {
        Self::default()
    }

    /// Cancels.
    pub fn cancel(&self) {
        self.0.store(true, Ordering::Relaxed);
    }

    /// Whether the load should stop.
    pub fn is_cancelled(&self) -> bool {
        self.0.load(Ordering::Relaxed)
    }
}

/// Why a source of tiles could not be opened. Every message names the file, folder or URL
/// at fault.
#[derive(Clone, Debug, PartialEq, thiserror::Error)]
pub enum OpenError {
    /// The source's description (a URL template, a setting) is malformed or asks for what is
    /// not supported.
    #[error("{0}")]
    Spec(String),
    /// A file, folder or URL the source needs cannot be read (missing, unreachable, refused).
    #[error("{0}")]
    Unreadable(String),
    /// What was read is not what a source of this kind holds (an archive's header or
    /// directory, metadata).
    #[error("{0}")]
    Invalid(String),
}

/// Why bytes could not be fetched.
#[derive(Clone, Debug, PartialEq, thiserror::Error)]
pub enum FetchError {
    /// Trying again later may succeed (timeouts, resets, truncated bodies, 5xx, 429).
    #[error("{message}")]
    Transient {
        /// What happened, naming the URL or file.
        message: String,
        /// How long the server asked us to wait (Retry-After).
        retry_after: Option<Duration>,
    },
    /// Trying again will not help (403, a malformed archive, a body over the size limit).
    #[error("{0}")]
    Permanent(String),
    /// The load was cancelled.
    #[error("cancelled")]
    Cancelled,
}

impl FetchError {
    /// A transient error without a Retry-After.
    pub fn transient(message: impl Into<String>) -> Self {
        Self::Transient {
            message: message.into(),
            retry_after: None,
        }
    }
}

/// Bytes of one tile.
#[derive(Clone, Debug, PartialEq, Eq)]
pub struct Fetched {
    /// The tile's bytes, as stored (PNG, JPEG, WebP, ...).
    pub bytes: Vec<u8>,
    /// How long the bytes stay fresh (Cache-Control max-age or Expires), if the origin says.
    pub fresh_for: Option<Duration>,
}

impl Fetched {
    /// Bytes with no freshness information (files and archives).
    pub fn local(bytes: Vec<u8>) -> Self {
        Self {
            bytes,
            fresh_for: None,
        }
    }
}

/// Where a pyramid's tile bytes come from.
pub trait Fetch: Send + Sync + 'static {
    /// The URL, path or file, for logs and errors.
    fn name(&self) -> &str;
    /// Where `key` is read from (its URL or file), for errors.
    fn locate(&self, key: TileKey) -> String {
        format!("{} tile {key}", self.name())
    }
    /// The bytes of `key` (a key of the pyramid's own scheme); `Ok(None)` if there is no tile.
    fn fetch(&self, key: TileKey, cancel: &Cancel) -> Result<Option<Fetched>, FetchError>;
}

/// What a pyramid is, as far as reading it goes.
#[derive(Clone, Copy, Debug, PartialEq, Eq)]
pub struct PyramidLayout {
    /// The tiling scheme of its keys.
    pub scheme: TilingScheme,
    /// Shallowest level with tiles.
    pub min_level: u8,
    /// Deepest level with tiles.
    pub max_level: u8,
}
