//! HTTP(S): one shared client (connection reuse, rustls, timeouts, a User-Agent naming Globus,
//! custom headers, a per-host concurrency limit) and the URL-template tile source.
//!
//! Status codes map to what a tile pyramid means by them: 200/206 with a body is the tile;
//! 204, 404 and an empty body are "no data here"; 408, 429 and 5xx are transient (with the
//! server's Retry-After); other 4xx are permanent. Timeouts, resets and truncated bodies are
//! transient. Bodies are read in chunks, stop at a size limit, and stop when the load is
//! cancelled.
//!
//! `ureq` on the loader threads rather than an async runtime: tiles are a few hundred KiB,
//! concurrency is tens of requests, and blocking reads on the worker pool keep the scheduler
//! the one place that decides what runs.

use std::io::Read;
use std::sync::{Condvar, Mutex};
use std::time::{Duration, SystemTime};

use globus_tiling::{TileKey, TilingScheme};
use rustc_hash::FxHashMap;

use super::{Cancel, Fetch, FetchError, Fetched, OpenError, UrlTemplate};

/// The User-Agent Globus sends unless told otherwise.
pub const USER_AGENT: &str = concat!(
    "Globus/",
    env!("CARGO_PKG_VERSION"),
    " (planetary terrain engine; +https://example.invalid/globus)"
);

/// Knobs of the HTTP client.
#[derive(Clone, Debug)]
pub struct HttpOptions {
    /// User-Agent header.
    pub user_agent: String,
    /// Extra headers on every request (API keys, Referer).
    pub headers: Vec<(String, String)>,
    /// Requests in flight to one host at most.
    pub per_host: usize,
    /// Time to connect.
    pub connect_timeout: Duration,
    /// Time from sending the request to the response headers.
    pub response_timeout: Duration,
    /// Longest wait for any one read of the body (a server that stalls mid-body).
    pub read_timeout: Duration,
    /// Time for a whole request, body included.
    pub total_timeout: Duration,
    /// Largest body accepted, bytes.
    pub max_body_bytes: u64,
}

impl HttpOptions {
    /// Refuses what cannot go into a request: a User-Agent or header value with control
    /// characters (a CR or LF would split the request, and the HTTP library refuses it on every
    /// tile), a header name that is not an HTTP token, no requests in flight.
    pub fn check(&self) -> Result<(), OpenError> {
        let bad_value = |v: &str| v.chars().any(|c| c.is_control() && c != '\t');
        if bad_value(&self.user_agent) {
            return Err(OpenError::Spec(format!(
                "User-Agent {:?} holds control characters (CR, LF): not allowed in an HTTP header",
                self.user_agent
            )));
        }
        for (name, value) in &self.headers {
            let token = !name.is_empty()
                && name
                    .bytes()
                    .all(|b| b.is_ascii_alphanumeric() || b"!#$%&'*+-.^_`|~".contains(&b));
            if !token {
                return Err(OpenError::Spec(format!(
                    "header name {name:?} is not an HTTP token (letters, digits, - and the like)"
                )));
            }
            if bad_value(value) {
                return Err(OpenError::Spec(format!(
                    "header {name}: value {value:?} holds control characters (CR, LF): not allowed in an HTTP header"
                )));
            }
        }
        if self.per_host == 0 {
            return Err(OpenError::Spec(
                "at least one request per host must be allowed in flight".into(),
            ));
        }
        Ok(())
    }
}

impl Default for HttpOptions {
    fn default() -> Self {
        Self {
            user_agent: USER_AGENT.into(),
            headers: Vec::new(),
            per_host: 8,
            connect_timeout: Duration::from_secs(5),
            response_timeout: Duration::from_secs(15),
            read_timeout: Duration::from_secs(10),
            total_timeout: Duration::from_secs(60),
            max_body_bytes: 32 << 20,
        }
    }
}

/// A response that carried a body.
#[derive(Debug)]
pub struct HttpBody {
    /// The status (200 or 206).
    pub status: u16,
    /// The body.
    pub fetched: Fetched,
}

/// The HTTP client shared by every HTTP source of a process.
pub struct HttpClient {
    agent: ureq::Agent,
    options: HttpOptions,
    hosts: Mutex<FxHashMap<String, usize>>,
    freed: Condvar,
}

struct HostSlot<'a> {
    client: &'a HttpClient,
    host: String,
}

impl Drop for HostSlot<'_> {
    fn drop(&mut self) {
        let mut hosts = self.client.lock_hosts();
        if let Some(n) = hosts.get_mut(&self.host) {
            *n -= 1;
            if *n == 0 {
                hosts.remove(&self.host);
            }
        }
        drop(hosts);
        self.client.freed.notify_all();
    }
}

impl HttpClient {
    /// A client with `options`.
    pub fn new(options: HttpOptions) -> Self {
        let config = ureq::Agent::config_builder()
            .http_status_as_error(false)
            .user_agent(options.user_agent.as_str())
            .timeout_connect(Some(options.connect_timeout))
            .timeout_recv_response(Some(options.response_timeout))
            .timeout_per_read(Some(options.read_timeout))
            .timeout_global(Some(options.total_timeout))
            .max_idle_connections_per_host(options.per_host.max(1))
            .build();
        Self {
            agent: config.new_agent(),
            options,
            hosts: Mutex::new(FxHashMap::default()),
            freed: Condvar::new(),
        }
    }

    /// The options.
    pub fn options(&self) -> &HttpOptions {
        &self.options
    }

    fn lock_hosts(&self) -> std::sync::MutexGuard<'_, FxHashMap<String, usize>> {
        self.hosts.lock().unwrap_or_else(|p| p.into_inner())
    }

    /// Waits for a free slot on `host` (or cancellation).
    fn acquire(&self, host: &str, cancel: &Cancel) -> Result<HostSlot<'_>, FetchError> {
        let mut hosts = self.lock_hosts();
        loop {
            if cancel.is_cancelled() {
                return Err(FetchError::Cancelled);
            }
            let n = hosts.entry(host.to_string()).or_insert(0);
            if *n < self.options.per_host.max(1) {
                *n += 1;
                return Ok(HostSlot {
                    client: self,
                    host: host.to_string(),
                });
            }
            hosts = self
                .freed
                .wait_timeout(hosts, Duration::from_millis(50))
                .map(|(g, _)| g)
                .unwrap_or_else(|p| p.into_inner().0);
        }
    }

    /// GETs `url` (bytes `range` inclusive, if given). `Ok(None)` is "no data here".
    pub fn get(
        &self,
        url: &str,
        range: Option<(u64, u64)>,
        cancel: &Cancel,
    ) -> Result<Option<HttpBody>, FetchError> {
        let _slot = self.acquire(host_of(url), cancel)?;
        if cancel.is_cancelled() {
            return Err(FetchError::Cancelled);
        }
        let mut req = self.agent.get(url);
        for (k, v) in &self.options.headers {
            req = req.header(k.as_str(), v.as_str());
        }
        if let Some((a, b)) = range {
            req = req.header("Range", format!("bytes={a}-{b}"));
        }
        let mut resp = req.call().map_err(|e| classify(url, e))?;
        let status = resp.status().as_u16();
        let header = |name: &str| {
            resp.headers()
                .get(name)
                .and_then(|v| v.to_str().ok())
                .map(str::to_string)
        };
        match status {
            200 | 206 => {}
            204 | 404 => return Ok(None),
            408 | 429 | 500..=599 => {
                return Err(FetchError::Transient {
                    message: format!("{url}: HTTP {status}"),
                    retry_after: header("retry-after")
                        .and_then(|v| parse_retry_after(&v, SystemTime::now())),
                });
            }
            _ => return Err(FetchError::Permanent(format!("{url}: HTTP {status}"))),
        }
        let fresh_for = freshness(
            header("cache-control").as_deref(),
            header("expires").as_deref(),
            SystemTime::now(),
        );
        let limit = self.options.max_body_bytes;
        if let Some(len) = resp.body().content_length()
            && len > limit
        {
            return Err(FetchError::Permanent(format!(
                "{url}: body of {len} bytes is over the {limit}-byte limit"
            )));
        }
        let mut reader = resp.body_mut().with_config().limit(limit).reader();
        let mut bytes = Vec::new();
        let mut chunk = vec![0u8; 64 << 10];
        loop {
            if cancel.is_cancelled() {
                return Err(FetchError::Cancelled);
            }
            match reader.read(&mut chunk) {
                Ok(0) => break,
                // The limit holds for the decoded body: a 2 GiB gzip bomb is a few MiB on the
                // wire.
                Ok(n) if (bytes.len() + n) as u64 > limit => {
                    return Err(FetchError::Permanent(format!(
                        "{url}: body decodes to more than the {limit}-byte limit"
                    )));
                }
                Ok(n) => bytes.extend_from_slice(&chunk[..n]),
                Err(e) => return Err(classify_io(url, &e)),
            }
        }
        if bytes.is_empty() {
            return Ok(None);
        }
        Ok(Some(HttpBody {
            status,
            fetched: Fetched { bytes, fresh_for },
        }))
    }
}

/// The `host:port` part of a URL, for per-host limits.
pub fn host_of(url: &str) -> &str {
    let rest = url.split_once("://").map_or(url, |(_, r)| r);
    let end = rest.find(['/', '?', '#']).unwrap_or(rest.len());
    &rest[..end]
}

fn classify(url: &str, e: ureq::Error) -> FetchError {
    use ureq::Error as E;
    match e {
        E::BadUri(_) | E::InvalidProxyUrl | E::RedirectFailed | E::TooManyRedirects => {
            FetchError::Permanent(format!("{url}: {e}"))
        }
        E::BodyExceedsLimit(n) => {
            FetchError::Permanent(format!("{url}: body over the {n}-byte limit"))
        }
        E::Io(io) => classify_io(url, &io),
        other => FetchError::transient(format!("{url}: {other}")),
    }
}

fn classify_io(url: &str, e: &std::io::Error) -> FetchError {
    match e
        .get_ref()
        .and_then(|inner| inner.downcast_ref::<ureq::Error>())
    {
        Some(ureq::Error::BodyExceedsLimit(n)) => {
            FetchError::Permanent(format!("{url}: body over the {n}-byte limit"))
        }
        _ => FetchError::transient(format!("{url}: {e}")),
    }
}

/// Retry-After: delta-seconds or an HTTP date; at most an hour is believed.
pub fn parse_retry_after(value: &str, now: SystemTime) -> Option<Duration> {
    let v = value.trim();
    let d = if let Ok(secs) = v.parse::<u64>() {
        Duration::from_secs(secs)
    } else {
        let at = parse_http_date(v)?;
        at.duration_since(now).unwrap_or(Duration::ZERO)
    };
    Some(d.min(Duration::from_secs(3600)))
}

/// How long a response stays fresh: `max-age` (or `s-maxage`) wins over `Expires`;
/// `no-store` and `no-cache` mean not at all.
pub fn freshness(
    cache_control: Option<&str>,
    expires: Option<&str>,
    now: SystemTime,
) -> Option<Duration> {
    if let Some(cc) = cache_control {
        let mut max_age = None;
        for d in cc.split(',').map(str::trim) {
            let lower = d.to_ascii_lowercase();
            if lower == "no-store" || lower == "no-cache" {
                return Some(Duration::ZERO);
            }
            if let Some(v) = lower
                .strip_prefix("max-age=")
                .or_else(|| lower.strip_prefix("s-maxage="))
                && let Ok(s) = v.trim_matches('"').parse::<u64>()
            {
                max_age = Some(Duration::from_secs(s));
            }
        }
        if max_age.is_some() {
            return max_age;
        }
    }
    let at = parse_http_date(expires?)?;
    Some(at.duration_since(now).unwrap_or(Duration::ZERO))
}

/// Parses an IMF-fixdate (`Sun, 06 Nov 1994 08:49:37 GMT`), the form HTTP/1.1 servers send.
pub fn parse_http_date(s: &str) -> Option<SystemTime> {
    let parts: Vec<&str> = s.split_whitespace().collect();
    let [_, day, month, year, time, "GMT"] = parts.as_slice() else {
        return None;
    };
    let day: i64 = day.parse().ok()?;
    let month = [
        "Jan", "Feb", "Mar", "Apr", "May", "Jun", "Jul", "Aug", "Sep", "Oct", "Nov", "Dec",
    ]
    .iter()
    .position(|m| m == month)? as i64
        + 1;
    let year: i64 = year.parse().ok()?;
    let hms: Vec<i64> = time.split(':').filter_map(|t| t.parse().ok()).collect();
    let [h, m, sec] = hms.as_slice() else {
        return None;
    };
    // Days from 1970-01-01 (the civil-from-days algorithm run backwards).
    let (y, mo) = if month <= 2 {
        (year - 1, month + 9)
    } else {
        (year, month - 3)
    };
    let era = y.div_euclid(400);
    let yoe = y - era * 400;
    let doy = (153 * mo + 2) / 5 + day - 1;
    let doe = yoe * 365 + yoe / 4 - yoe / 100 + doy;
    let days = era * 146_097 + doe - 719_468;
    let secs = days * 86_400 + h * 3600 + m * 60 + sec;
    let secs = u64::try_from(secs).ok()?;
    Some(SystemTime::UNIX_EPOCH + Duration::from_secs(secs))
}

/// Tiles from an HTTP(S) URL template.
pub struct TemplateFetch {
    client: std::sync::Arc<HttpClient>,
    template: UrlTemplate,
    scheme: TilingScheme,
}

impl TemplateFetch {
    /// Tiles of `scheme` at `template` (with `{s}` rotating through `subdomains`).
    pub fn new(
        client: std::sync::Arc<HttpClient>,
        template: &str,
        subdomains: &[&str],
        scheme: TilingScheme,
    ) -> Result<Self, OpenError> {
        if !(template.starts_with("http://") || template.starts_with("https://")) {
            return Err(OpenError::Spec(format!(
                "tile URL {template:?} must start with http:// or https://"
            )));
        }
        Ok(Self {
            client,
            template: UrlTemplate::parse(template, subdomains)?,
            scheme,
        })
    }

    /// The URL of a tile.
    pub fn url(&self, key: TileKey) -> String {
        self.template.expand(self.scheme, key)
    }
}

impl Fetch for TemplateFetch {
    fn name(&self) -> &str {
        self.template.as_str()
    }

    fn locate(&self, key: TileKey) -> String {
        self.url(key)
    }

    fn fetch(&self, key: TileKey, cancel: &Cancel) -> Result<Option<Fetched>, FetchError> {
        Ok(self
            .client
            .get(&self.url(key), None, cancel)?
            .map(|b| b.fetched))
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    /// A CR or LF in a header would split the request (the loader threads panicked on every
    /// tile): refused up front, naming the header.
    #[test]
    fn headers_that_cannot_be_sent_are_refused() {
        assert!(HttpOptions::default().check().is_ok());
        let with = |ua: &str, headers: &[(&str, &str)]| HttpOptions {
            user_agent: ua.into(),
            headers: headers
                .iter()
                .map(|(k, v)| ((*k).to_string(), (*v).to_string()))
                .collect(),
            ..HttpOptions::default()
        };
        assert!(
            with("app/1 (me@example.org)", &[("X-Api-Key", "k 1")])
                .check()
                .is_ok()
        );
        for (o, needle) in [
            (with("me\r\nX-Evil: 1", &[]), "User-Agent"),
            (with("me", &[("X-Key", "a\nb")]), "X-Key"),
            (with("me", &[("Bad Name", "v")]), "Bad Name"),
            (with("me", &[("", "v")]), "header name"),
        ] {
            let e = o.check().expect_err(needle).to_string();
            assert!(e.contains(needle), "{e}");
        }
    }

    /// A gzip bomb (a few KiB on the wire, far more decoded) got past the body limit, which
    /// counted wire bytes: the decoded body is what is limited now.
    #[test]
    fn the_body_limit_holds_for_the_decoded_gzip_body() {
        use std::io::{BufRead, Write};
        let mut gz = flate2::write::GzEncoder::new(Vec::new(), flate2::Compression::best());
        gz.write_all(&vec![0u8; 8 << 20]).unwrap();
        let bomb = gz.finish().unwrap();
        assert!(bomb.len() < 64 << 10);
        let listener = std::net::TcpListener::bind("127.0.0.1:0").unwrap();
        let addr = listener.local_addr().unwrap();
        std::thread::spawn(move || {
            for stream in listener.incoming().take(2) {
                let Ok(mut s) = stream else { return };
                let mut r = std::io::BufReader::new(s.try_clone().unwrap());
                let mut line = String::new();
                while r.read_line(&mut line).is_ok_and(|n| n > 2) {
                    line.clear();
                }
                let head = format!(
                    "HTTP/1.1 200 OK\r\nContent-Type: image/png\r\nContent-Encoding: gzip\r\nContent-Length: {}\r\nConnection: close\r\n\r\n",
                    bomb.len()
                );
                let _ = s.write_all(head.as_bytes());
                let _ = s.write_all(&bomb);
            }
        });
        let client = HttpClient::new(HttpOptions {
            max_body_bytes: 1 << 20,
            ..HttpOptions::default()
        });
        let url = format!("http://{addr}/0/0/0.png");
        let e = match client.get(&url, None, &Cancel::new()) {
            Ok(b) => panic!(
                "a body of {} bytes got past the limit",
                b.map_or(0, |b| b.fetched.bytes.len())
            ),
            Err(e) => e,
        };
        assert!(
            matches!(&e, FetchError::Permanent(m) if m.contains("decodes to more")),
            "{e}"
        );
        // Within the limit, the same bomb decodes.
        let roomy = HttpClient::new(HttpOptions {
            max_body_bytes: 16 << 20,
            ..HttpOptions::default()
        });
        let body = roomy.get(&url, None, &Cancel::new()).unwrap().unwrap();
        assert_eq!(body.fetched.bytes.len(), 8 << 20);
    }

    #[test]
    fn http_dates_and_cache_headers() {
        // RFC 9110's example date.
        let t = parse_http_date("Sun, 06 Nov 1994 08:49:37 GMT").unwrap();
        assert_eq!(
            t.duration_since(SystemTime::UNIX_EPOCH).unwrap().as_secs(),
            784_111_777
        );
        let now = t - Duration::from_secs(120);
        assert_eq!(
            parse_retry_after("Sun, 06 Nov 1994 08:49:37 GMT", now),
            Some(Duration::from_secs(120))
        );
        assert_eq!(parse_retry_after(" 7 ", now), Some(Duration::from_secs(7)));
        assert_eq!(parse_retry_after("soon", now), None);
        assert_eq!(
            freshness(Some("public, max-age=3600"), None, now),
            Some(Duration::from_secs(3600))
        );
        assert_eq!(freshness(Some("no-cache"), None, now), Some(Duration::ZERO));
        assert_eq!(
            freshness(None, Some("Sun, 06 Nov 1994 08:49:37 GMT"), now),
            Some(Duration::from_secs(120))
        );
        assert_eq!(freshness(None, None, now), None);
        assert_eq!(
            host_of("https://a.tile.example:8080/1/2/3.png"),
            "a.tile.example:8080"
        );
        assert_eq!(host_of("http://h?x=1"), "h");
    }
}
