//! The TOML configuration file of `globus view|render|bench --config FILE`: data sources,
//! budgets, the error bound and how tile services are spoken to. Command-line flags win over
//! the file; `--terrain` and `--imagery` add layers on top of the file's.
//!
//! ```toml
//! sse = 2.0                 # screen-space error bound, pixels
//! cache_mb = 512            # decoded tiles kept in RAM
//! gpu_tiles = 1024          # tile slots in the GPU pools
//! workers = 16              # loader threads (also the most requests in flight)
//! refine_to_level = 22      # procedural detail below the data, down to this level
//!
//! [http]
//! user_agent = "my-app/1.0 (me@example.org)"
//! per_host = 8
//! timeout_s = 15
//! headers = { "X-Api-Key" = "..." }
//!
//! [[terrain]]
//! url = "https://tiles.example/terrarium/{z}/{x}/{y}.png"
//! encoding = "terrarium"
//! maxzoom = 15
//!
//! [[imagery]]
//! url = "https://{s}.imagery.example/{z}/{x}/{y}.jpg"
//! subdomains = ["a", "b", "c"]
//! maxzoom = 19
//! ```

use std::collections::BTreeMap;
use std::path::Path;
use std::time::Duration;

use anyhow::{Context, bail};
use globus_stream::open::SourceSpec;
use serde::Deserialize;

use crate::engine::GlobeOptions;

/// The file's contents.
#[derive(Clone, Debug, Default, Deserialize)]
#[serde(deny_unknown_fields)]
pub struct Config {
    /// Screen-space error bound, pixels.
    pub sse: Option<f64>,
    /// CPU cache budget, MiB.
    pub cache_mb: Option<u64>,
    /// GPU tile slots.
    pub gpu_tiles: Option<u32>,
    /// Loader threads.
    pub workers: Option<usize>,
    /// Deepest level procedural refinement goes to.
    pub refine_to_level: Option<u8>,
    /// HTTP settings.
    pub http: Option<HttpConfig>,
    /// Elevation layers, bottom first.
    #[serde(default)]
    pub terrain: Vec<SourceSpec>,
    /// Imagery layers, bottom first.
    #[serde(default)]
    pub imagery: Vec<SourceSpec>,
}

/// The `[http]` table.
#[derive(Clone, Debug, Default, Deserialize)]
#[serde(deny_unknown_fields)]
pub struct HttpConfig {
    /// User-Agent (default names Globus and its version).
    pub user_agent: Option<String>,
    /// Requests in flight per host.
    pub per_host: Option<usize>,
    /// Seconds to wait for a response (and between reads of a body).
    pub timeout_s: Option<f64>,
    /// Extra headers on every request.
    #[serde(default)]
    pub headers: BTreeMap<String, String>,
}

impl Config {
    /// Reads and checks `path`.
    pub fn load(path: &Path) -> anyhow::Result<Self> {
        let text = std::fs::read_to_string(path)
            .with_context(|| format!("cannot read {}", path.display()))?;
        let c: Config = toml::from_str(&text).map_err(|e| {
            let first = e.to_string();
            let first = first.lines().next().unwrap_or("invalid TOML").to_string();
            anyhow::anyhow!("{}: {first}", path.display())
        })?;
        c.check().with_context(|| path.display().to_string())?;
        Ok(c)
    }

    fn check(&self) -> anyhow::Result<()> {
        if let Some(s) = self.sse
            && !(s > 0.0 && s <= 1000.0)
        {
            bail!("sse = {s} must be above 0 and at most 1000 pixels");
        }
        if self.gpu_tiles == Some(0) || self.workers == Some(0) || self.cache_mb == Some(0) {
            bail!("gpu_tiles, workers and cache_mb must be above 0");
        }
        if let Some(l) = self.refine_to_level
            && l > globus_tiling::TileKey::MAX_LEVEL
        {
            bail!("refine_to_level = {l} is deeper than the deepest level, 29");
        }
        if let Some(h) = &self.http {
            if h.per_host == Some(0) {
                bail!("http.per_host must be at least 1");
            }
            if let Some(t) = h.timeout_s
                && !(t > 0.0 && t <= 600.0)
            {
                bail!("http.timeout_s = {t} must be above 0 and at most 600");
            }
        }
        Ok(())
    }

    /// Applies the file to `options` (before command-line flags are).
    pub fn apply(&self, options: &mut GlobeOptions) {
        if let Some(s) = self.sse {
            options.max_sse_px = s;
        }
        if let Some(mb) = self.cache_mb {
            options.cache_bytes = (mb as usize) << 20;
        }
        if let Some(n) = self.gpu_tiles {
            options.gpu_slots = n;
        }
        if let Some(n) = self.workers {
            options.workers = n;
        }
        if let Some(l) = self.refine_to_level {
            options.max_level = l;
        }
        if let Some(h) = &self.http {
            if let Some(ua) = &h.user_agent {
                options.http.user_agent = ua.clone();
            }
            if let Some(n) = h.per_host {
                options.http.per_host = n;
            }
            if let Some(t) = h.timeout_s {
                options.http.response_timeout = Duration::from_secs_f64(t);
                options.http.read_timeout = Duration::from_secs_f64(t);
            }
            options
                .http
                .headers
                .extend(h.headers.iter().map(|(k, v)| (k.clone(), v.clone())));
        }
        options.terrain.extend(self.terrain.iter().cloned());
        options.imagery.extend(self.imagery.iter().cloned());
    }
}
