//! The TOML configuration file of `globus view|render|bench --config FILE`: data sources,
//! budgets, the error bound and how tile services are spoken to. Command-line flags win over
//! the file; `--terrain` and `--imagery` add layers on top of the file's.
//!
//! ```toml
//! sse = 2.0                 # screen-space error bound, pixels
//! target_fps = 30           # hold 30 frames per second: the bound rises while slower
//! sse_max = 8.0             #   but never past 8 px (default 4 x sse)
//! memory_mb = 1024          # everything Globus holds, CPU and GPU: sizes the caches below
//! # cache_mb = 512          # or size the two big parts yourself (not with memory_mb):
//! # gpu_tiles = 1024        #   loaded tiles kept in RAM, tile slots in the GPU pools
//! workers = 16              # loader threads (also the most requests in flight)
//! refine_to_level = 22      # procedural detail below the data, down to this level
//! request_lookahead_frames = 3  # a moving camera skips tiles it leaves within 3 frames
//! exaggeration = 1          # elevation exaggeration of terrain and everything at an altitude
//!
//! [http]
//! user_agent = "my-app/1.0 (me@example.org)"
//! per_host = 8
//! timeout_s = 15
//! headers = { "X-Api-Key" = "..." }
//!
//! [disk_cache]            # tiles from services kept on disk: a second session works offline
//! dir = "/var/cache/globus"
//! max_mb = 2048
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
//!
//! [night_imagery]         # city lights where the Sun is down (read whole at start)
//! url = "./night"           # e.g. earth-night-4096x2048.jpg tiled by `globus tile imagery`
//!
//! [vector_style]          # defaults for features without these properties
//! stroke = "#ffcc00"
//! stroke-width = 2
//!
//! [[vector]]              # drawn like --vector (paths relative to this file)
//! file = "countries.geojson"
//! style = { fill-opacity = 0.3 }   # overrides, like FILE#key=value
//! ```

use std::collections::BTreeMap;
use std::path::Path;
use std::time::Duration;

use anyhow::{Context, bail};
use globus_stream::fetch::DiskCacheOptions;
use globus_stream::open::SourceSpec;
use serde::Deserialize;

use globus_engine::GlobeBuilder;

/// The file's contents.
#[derive(Clone, Debug, Default, Deserialize)]
#[serde(deny_unknown_fields)]
pub struct Config {
    /// Screen-space error bound, pixels.
    pub sse: Option<f64>,
    /// A frame rate to hold ([`GlobeBuilder::target_fps`]).
    pub target_fps: Option<f64>,
    /// The coarsest error bound the frame rate may raise the bound to, pixels.
    pub sse_max: Option<f64>,
    /// One budget for all memory, MiB ([`globus_engine::memory`]).
    pub memory_mb: Option<u64>,
    /// CPU cache budget, MiB.
    pub cache_mb: Option<u64>,
    /// GPU tile slots.
    pub gpu_tiles: Option<u32>,
    /// Loader threads.
    pub workers: Option<usize>,
    /// Deepest level procedural refinement goes to.
    pub refine_to_level: Option<u8>,
    /// Frames ahead a moving camera's requests look
    /// ([`GlobeBuilder::request_lookahead_frames`]).
    pub request_lookahead_frames: Option<f64>,
    /// Elevation exaggeration.
    pub exaggeration: Option<f64>,
    /// HTTP settings.
    pub http: Option<HttpConfig>,
    /// On-disk tile cache.
    pub disk_cache: Option<DiskCacheConfig>,
    /// Elevation layers, bottom first.
    #[serde(default)]
    pub terrain: Vec<SourceSpec>,
    /// Imagery layers, bottom first.
    #[serde(default)]
    pub imagery: Vec<SourceSpec>,
    /// City lights on the night side, from an imagery pyramid (`--night-imagery` wins).
    pub night_imagery: Option<SourceSpec>,
    /// Style defaults of vector features (simplestyle keys and Globus's own).
    #[serde(default)]
    pub vector_style: BTreeMap<String, toml::Value>,
    /// Vector files drawn.
    #[serde(default)]
    pub vector: Vec<VectorConfig>,
}

/// A `[[vector]]` table.
#[derive(Clone, Debug, Deserialize)]
#[serde(deny_unknown_fields)]
pub struct VectorConfig {
    /// The GeoJSON file (relative to the config file).
    pub file: std::path::PathBuf,
    /// Style overrides.
    #[serde(default)]
    pub style: BTreeMap<String, toml::Value>,
}

/// Style keys and values of a config table as JSON, each key checked.
pub fn style_map(
    table: &BTreeMap<String, toml::Value>,
    what: &str,
) -> anyhow::Result<serde_json::Map<String, serde_json::Value>> {
    let mut out = serde_json::Map::new();
    for (k, v) in table {
        globus_vector::style::check_key(k).with_context(|| what.to_owned())?;
        out.insert(k.clone(), serde_json::to_value(v)?);
    }
    Ok(out)
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

/// The `[disk_cache]` table.
#[derive(Clone, Debug, Deserialize)]
#[serde(deny_unknown_fields)]
pub struct DiskCacheConfig {
    /// The folder.
    pub dir: std::path::PathBuf,
    /// Most MiB kept (default 2048).
    pub max_mb: Option<u64>,
}

/// The largest disk cache, MiB (16 TiB).
pub const MAX_DISK_CACHE_MB: u64 = 16 << 20;

/// One line for a TOML error: the file, the line of the key at fault and the reason. The
/// `toml` crate points errors of the top-level table at line 1, column 1 and puts the reason
/// on a later line; the line is found from the key the message names where it can be.
fn toml_error(path: &Path, text: &str, e: &toml::de::Error) -> anyhow::Error {
    let message = e.message().trim().replace('\n', " ");
    let line_of = |at: usize| text[..at.min(text.len())].matches('\n').count() + 1;
    // A key named in backticks (`unknown field `memroy_mb``, `missing field `url``).
    let named = message
        .split('`')
        .nth(1)
        .filter(|k| !k.is_empty() && !k.contains(' '))
        .and_then(|key| {
            text.lines().position(|l| {
                let l = l.trim_start();
                l.strip_prefix(key)
                    .is_some_and(|rest| rest.trim_start().starts_with('='))
            })
        })
        .map(|i| i + 1);
    let line = match (e.span(), named) {
        (Some(span), _) if span.start > 0 => Some(line_of(span.start)),
        (_, Some(l)) => Some(l),
        (Some(span), None) => Some(line_of(span.start)),
        (None, None) => None,
    };
    match line {
        Some(l) => anyhow::anyhow!("{}: line {l}: {message}", path.display()),
        None => anyhow::anyhow!("{}: {message}", path.display()),
    }
}

/// Default size of the disk cache, MiB.
pub const DEFAULT_DISK_CACHE_MB: u64 = 2048;

/// Disk cache options for `dir` holding at most `max_mb` MiB.
pub fn disk_cache_options(dir: &Path, max_mb: u64) -> DiskCacheOptions {
    DiskCacheOptions {
        dir: dir.to_path_buf(),
        max_bytes: max_mb.saturating_mul(1 << 20),
        default_fresh_for: Duration::from_secs(7 * 86_400),
    }
}

/// The largest configuration file read. A real one is a few kilobytes; the TOML parser
/// needs about 50 times a file's size for deeply nested arrays (a 16 MiB file of brackets
/// took 807 MiB before it was refused), so the cap bounds the parse to tens of megabytes.
const MAX_CONFIG_BYTES: u64 = 1 << 20;

impl Config {
    /// Reads and checks `path`.
    pub fn load(path: &Path) -> anyhow::Result<Self> {
        let text = globus_tiling::files::read_text_capped(path, MAX_CONFIG_BYTES)
            .with_context(|| format!("cannot read {}", path.display()))?;
        let c: Config = toml::from_str(&text).map_err(|e| toml_error(path, &text, &e))?;
        c.check().with_context(|| path.display().to_string())?;
        Ok(c)
    }

    fn check(&self) -> anyhow::Result<()> {
        style_map(&self.vector_style, "vector_style")?;
        for (i, v) in self.vector.iter().enumerate() {
            style_map(&v.style, &format!("vector[{i}].style"))?;
        }
        if let Some(d) = &self.disk_cache
            && let Some(mb) = d.max_mb
            && mb > MAX_DISK_CACHE_MB
        {
            bail!("disk_cache.max_mb = {mb} is more than {MAX_DISK_CACHE_MB} (16 TiB)");
        }
        if let Some(s) = self.sse
            && !(globus_engine::MIN_SSE_PX..=1000.0).contains(&s)
        {
            bail!("sse = {s} must be from 0.1 to 1000 pixels");
        }
        if let Some(f) = self.target_fps
            && !(f > 0.0 && f <= 1000.0)
        {
            bail!("target_fps = {f} must be above 0 and at most 1000 frames per second");
        }
        if let Some(m) = self.sse_max
            && !(m >= self.sse.unwrap_or(globus_engine::MIN_SSE_PX) && m <= 1000.0)
        {
            bail!("sse_max = {m} must be from sse to 1000 pixels");
        }
        if self.gpu_tiles == Some(0)
            || self.workers == Some(0)
            || self.cache_mb == Some(0)
            || self.memory_mb == Some(0)
        {
            bail!("memory_mb, gpu_tiles, workers and cache_mb must be above 0");
        }
        if self.memory_mb.is_some() && self.sizes_caches() {
            bail!(
                "memory_mb sizes the tile cache and the GPU pools itself: give memory_mb, or \
                 cache_mb and gpu_tiles, not both"
            );
        }
        if let Some(l) = self.refine_to_level
            && l > globus_tiling::TileKey::MAX_LEVEL
        {
            bail!("refine_to_level = {l} is deeper than the deepest level, 29");
        }
        if let Some(f) = self.request_lookahead_frames
            && !(0.0..=1000.0).contains(&f)
        {
            bail!("request_lookahead_frames = {f} must be from 0 to 1000 frames");
        }
        if let Some(e) = self.exaggeration
            && !(0.0..=1000.0).contains(&e)
        {
            bail!("exaggeration = {e} must be a factor from 0 to 1000");
        }
        if let Some(d) = &self.disk_cache
            && d.max_mb == Some(0)
        {
            bail!("disk_cache.max_mb must be above 0");
        }
        if let Some(h) = &self.http {
            if h.per_host == Some(0) {
                bail!("http.per_host must be at least 1");
            }
            let mut http = globus_stream::fetch::HttpOptions::default();
            if let Some(ua) = &h.user_agent {
                http.user_agent = ua.clone();
            }
            http.headers = h
                .headers
                .iter()
                .map(|(k, v)| (k.clone(), v.clone()))
                .collect();
            http.check().map_err(|e| anyhow::anyhow!("[http]: {e}"))?;
            if let Some(t) = h.timeout_s
                && !(t > 0.0 && t <= 600.0)
            {
                bail!("http.timeout_s = {t} must be above 0 and at most 600");
            }
        }
        Ok(())
    }

    /// Whether the file sizes the tile cache or the GPU pools itself (so no total memory
    /// budget applies).
    pub fn sizes_caches(&self) -> bool {
        self.cache_mb.is_some() || self.gpu_tiles.is_some()
    }

    /// Applies the file to `builder` (before command-line flags are).
    pub fn apply(&self, builder: &mut GlobeBuilder) {
        if let Some(s) = self.sse {
            builder.max_sse_px(s);
        }
        if let Some(f) = self.target_fps {
            builder.target_fps(Some(f));
        }
        if let Some(m) = self.sse_max {
            builder.coarsest_sse_px(m);
        }
        if let Some(mb) = self.memory_mb {
            builder.memory_budget(Some(mb.saturating_mul(1 << 20)));
        }
        if let Some(mb) = self.cache_mb {
            builder.cache_bytes(usize::try_from(mb.saturating_mul(1 << 20)).unwrap_or(usize::MAX));
        }
        if let Some(n) = self.gpu_tiles {
            builder.gpu_tiles(n);
        }
        if let Some(n) = self.workers {
            builder.workers(n);
        }
        if let Some(l) = self.refine_to_level {
            builder.max_level(l);
        }
        if let Some(f) = self.request_lookahead_frames {
            builder.request_lookahead_frames(f);
        }
        if let Some(e) = self.exaggeration {
            builder.exaggeration(e);
        }
        if let Some(h) = &self.http {
            let mut http = builder.http_options().clone();
            if let Some(ua) = &h.user_agent {
                http.user_agent = ua.clone();
            }
            if let Some(n) = h.per_host {
                http.per_host = n;
            }
            if let Some(t) = h.timeout_s {
                http.response_timeout = Duration::from_secs_f64(t);
                http.read_timeout = Duration::from_secs_f64(t);
            }
            http.headers
                .extend(h.headers.iter().map(|(k, v)| (k.clone(), v.clone())));
            builder.http(http);
        }
        if let Some(d) = &self.disk_cache {
            builder.disk_cache(Some(disk_cache_options(
                &d.dir,
                d.max_mb.unwrap_or(DEFAULT_DISK_CACHE_MB),
            )));
        }
        for spec in &self.terrain {
            builder.terrain(spec.clone());
        }
        for spec in &self.imagery {
            builder.imagery(spec.clone());
        }
        if let Some(spec) = &self.night_imagery {
            builder.night_imagery(Some(spec.clone()));
        }
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    fn parse(text: &str) -> anyhow::Result<Config> {
        let c: Config = toml::from_str(text)?;
        c.check()?;
        Ok(c)
    }

    #[test]
    fn a_full_file_configures_the_globe() {
        let c = parse(
            r#"
            sse = 3.5
            target_fps = 30
            sse_max = 9
            cache_mb = 256
            gpu_tiles = 512
            workers = 12
            refine_to_level = 22
            request_lookahead_frames = 0
            exaggeration = 5
            [http]
            user_agent = "test/1"
            per_host = 4
            timeout_s = 7
            headers = { "X-Api-Key" = "k" }
            [disk_cache]
            dir = "/tmp/globus-cache"
            [[terrain]]
            url = "https://t.example/{z}/{x}/{y}.png"
            encoding = "terrarium"
            maxzoom = 15
            [[imagery]]
            url = "https://{s}.i.example/{z}/{x}/{y}.jpg"
            subdomains = ["a", "b"]
            [night_imagery]
            url = "./night"
            "#,
        )
        .expect("valid");
        let mut o = GlobeBuilder::new();
        c.apply(&mut o);
        assert_eq!(o.error_bound_px(), 3.5);
        assert_eq!((o.target_frame_rate(), o.coarsest_px()), (Some(30.0), 9.0));
        assert_eq!(o.tile_cache_bytes(), 256 << 20);
        assert!(c.sizes_caches() && o.memory_budget_bytes().is_none());
        let mut m = GlobeBuilder::new();
        parse("memory_mb = 768").expect("valid").apply(&mut m);
        assert_eq!(m.memory_budget_bytes(), Some(768 << 20));
        assert_eq!(
            (o.gpu_tile_slots(), o.worker_threads(), o.deepest_level()),
            (512, 12, 22)
        );
        assert_eq!(o.lookahead_frames(), 0.0);
        assert_eq!(o.exaggeration_factor(), 5.0);
        let http = o.http_options();
        assert_eq!(http.user_agent, "test/1");
        assert_eq!(http.per_host, 4);
        assert_eq!(http.read_timeout, Duration::from_secs(7));
        assert_eq!(
            http.headers,
            vec![("X-Api-Key".to_string(), "k".to_string())]
        );
        let d = o.disk_cache_options().expect("disk cache");
        assert_eq!(d.max_bytes, DEFAULT_DISK_CACHE_MB << 20);
        assert_eq!(o.terrain_layers().len(), 1);
        assert_eq!(o.terrain_layers()[0].maxzoom, Some(15));
        assert_eq!(
            o.imagery_layers()[0].subdomains.as_deref(),
            Some(&["a".to_string(), "b".to_string()][..])
        );
        assert_eq!(
            o.night_imagery_source().map(|s| s.url.as_str()),
            Some("./night")
        );
    }

    #[test]
    fn bad_files_are_refused() {
        for bad in [
            "sse = -1",
            "workers = 0",
            "colour = 'red'",
            "[http]\nper_host = 0",
            "[[terrain]]\nurl = 'x'\nencodin = 'terrarium'",
            "[disk_cache]\ndir = '/tmp'\nmax_mb = 0",
            "refine_to_level = 40",
            "request_lookahead_frames = -1",
            "request_lookahead_frames = nan",
            "exaggeration = -1",
            "exaggeration = 1e9",
            "target_fps = 0",
            "target_fps = nan",
            "sse = 4\nsse_max = 2",
            "sse_max = 1e9",
            "memory_mb = 0",
            "memory_mb = 512\ncache_mb = 256",
            "memory_mb = 512\ngpu_tiles = 256",
            // CR/LF would split the request (the loader threads panicked on it before).
            "[http]\nuser_agent = \"me\\r\\nX-Evil: 1\"",
            "[http]\nheaders = { \"X-Key\" = \"a\\nb\" }",
            "[http]\nheaders = { \"Bad Name\" = \"v\" }",
        ] {
            assert!(parse(bad).is_err(), "{bad}");
        }
    }

    /// A 16 MiB file of nested brackets took 807 MiB to refuse: files past 1 MiB are refused
    /// unread, and the deepest nesting that fits is refused with the line.
    #[test]
    fn deeply_nested_and_oversized_files_are_refused_cheaply() {
        let dir = std::env::temp_dir().join(format!("globus-config-deep-{}", std::process::id()));
        std::fs::create_dir_all(&dir).unwrap();
        let deep = |n: usize| format!("sse = {}{}\n", "[".repeat(n), "]".repeat(n));
        let big = dir.join("big.toml");
        std::fs::write(&big, deep(600_000)).unwrap();
        let e = format!("{:#}", Config::load(&big).expect_err("refused"));
        assert!(
            e.contains("big.toml") && e.contains("1048576-byte limit"),
            "{e}"
        );
        let fits = dir.join("fits.toml");
        std::fs::write(&fits, deep(500_000)).unwrap();
        let e = format!("{:#}", Config::load(&fits).expect_err("refused"));
        assert!(e.contains("fits.toml") && e.contains("line 1"), "{e}");
        std::fs::remove_dir_all(&dir).ok();
    }

    /// Every config error said only "TOML parse error at line 1, column 1": now the line of
    /// the key, the key and what was expected.
    #[test]
    fn config_errors_name_the_line_the_key_and_the_reason() {
        let dir = std::env::temp_dir().join(format!("globus-config-{}", std::process::id()));
        std::fs::create_dir_all(&dir).unwrap();
        for (text, needles) in [
            (
                "sse = 2\nmemroy_mb = 512\n",
                &["line 2", "memroy_mb", "memory_mb"][..],
            ),
            ("sse = 'two'\n", &["line 1", "string", "f64"]),
            ("workers = 4\nmemory_mb = -5\n", &["line 2", "-5"]),
            ("memory_mb = 1e12\n", &["line 1", "float", "u64"]),
            (
                "[http]\nper_host = 4\ntimeout = 3\n",
                &["line 3", "timeout"],
            ),
            (
                "[disk_cache]\ndir = '/tmp'\nmax_mb = 1000000000\n",
                &["max_mb", "16 TiB"],
            ),
        ] {
            let path = dir.join("bad.toml");
            std::fs::write(&path, text).unwrap();
            let e = format!("{:#}", Config::load(&path).unwrap_err());
            assert_eq!(e.lines().count(), 1, "{e}");
            assert!(e.contains("bad.toml"), "{e}");
            for n in needles {
                assert!(e.contains(n), "{text:?}: {e} lacks {n:?}");
            }
        }
        std::fs::remove_dir_all(&dir).ok();
    }

    /// Mutations of two config files: every one is read or refused with a line, none panics.
    #[test]
    fn fuzz_config() {
        let r = globus_test_support::fuzz::run("config", |b| {
            std::str::from_utf8(b).is_ok_and(|t| parse(t).is_ok())
        });
        assert!(r.cases > 0 && r.accepted < r.cases, "{r:?}");
    }
}
