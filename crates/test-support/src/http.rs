//! [`FaultServer`]: a real HTTP/1.1 server on 127.0.0.1 that serves files (with byte ranges)
//! and injects the faults tile clients meet in the wild: latency, 404, 500, 429 with
//! Retry-After, truncated bodies, bodies that are not images, images declaring absurd sizes,
//! a server that stalls mid-body, and connection resets. It logs every request (path,
//! headers) and the most requests it ever had in progress at once.
//!
//! One thread per connection; keep-alive honoured; good enough for tests, not for serving.

use std::collections::HashMap;
use std::io::{BufRead, BufReader, Read, Write};
use std::net::{Shutdown, SocketAddr, TcpListener, TcpStream};
use std::path::{Path, PathBuf};
use std::sync::atomic::{AtomicBool, AtomicUsize, Ordering};
use std::sync::{Arc, Mutex};
use std::time::Duration;

/// A fault to inject on matching requests.
#[derive(Clone, Debug, PartialEq)]
pub enum Fault {
    /// Answer with this status and an empty body.
    Status(u16),
    /// 429 (or the status given) with `Retry-After: secs`.
    RetryAfter {
        /// The status.
        status: u16,
        /// Seconds to wait.
        secs: u64,
    },
    /// Promise the whole body in Content-Length, send half of it, close.
    Truncate,
    /// 200 with an HTML error page.
    NotAnImage,
    /// 200 with a PNG whose header declares 60000 x 60000 pixels.
    AbsurdImage,
    /// Send the headers and half the body, then stall for this long before closing.
    Stall(Duration),
    /// Close the connection without answering (a reset).
    Reset,
    /// Wait this long, then serve normally.
    Delay(Duration),
}

struct Rule {
    prefix: String,
    fault: Fault,
    remaining: Option<u32>,
}

/// One logged request.
#[derive(Clone, Debug)]
pub struct Logged {
    /// The request target (path and query).
    pub target: String,
    /// Header names in lower case, with their values.
    pub headers: HashMap<String, String>,
}

#[derive(Default)]
struct State {
    root: Option<PathBuf>,
    files: Mutex<HashMap<String, Vec<u8>>>,
    rules: Mutex<Vec<Rule>>,
    latency: Mutex<Duration>,
    log: Mutex<Vec<Logged>>,
    active: AtomicUsize,
    max_active: AtomicUsize,
    shutdown: AtomicBool,
    cache_control: Mutex<Option<String>>,
}

/// A test HTTP server; stops when dropped.
pub struct FaultServer {
    addr: SocketAddr,
    state: Arc<State>,
}

impl FaultServer {
    /// Serves the files under `root` (URL path = path under root).
    pub fn serve_dir(root: &Path) -> Self {
        Self::start(State {
            root: Some(root.to_path_buf()),
            ..State::default()
        })
    }

    /// Serves files held in memory (added with [`FaultServer::put`]).
    pub fn in_memory() -> Self {
        Self::start(State::default())
    }

    fn start(state: State) -> Self {
        let listener = TcpListener::bind("127.0.0.1:0").expect("bind 127.0.0.1");
        let addr = listener.local_addr().expect("local address");
        let state = Arc::new(state);
        let s = Arc::clone(&state);
        std::thread::spawn(move || {
            for conn in listener.incoming() {
                if s.shutdown.load(Ordering::SeqCst) {
                    break;
                }
                let Ok(conn) = conn else { continue };
                let s = Arc::clone(&s);
                std::thread::spawn(move || serve(conn, &s));
            }
        });
        Self { addr, state }
    }

    /// `http://127.0.0.1:PORT` followed by `path`.
    pub fn url(&self, path: &str) -> String {
        format!("http://{}{path}", self.addr)
    }

    /// Adds an in-memory file at URL path `path`.
    pub fn put(&self, path: &str, bytes: Vec<u8>) {
        lock(&self.state.files).insert(path.to_string(), bytes);
    }

    /// Delays every request by `d`.
    pub fn set_latency(&self, d: Duration) {
        *lock(&self.state.latency) = d;
    }

    /// Sends this Cache-Control header with every file.
    pub fn set_cache_control(&self, value: Option<&str>) {
        *lock(&self.state.cache_control) = value.map(str::to_string);
    }

    /// Injects `fault` on requests whose target starts with `prefix`, `times` times (or
    /// always). Earlier rules win.
    pub fn add_fault(&self, prefix: &str, fault: Fault, times: Option<u32>) {
        lock(&self.state.rules).push(Rule {
            prefix: prefix.to_string(),
            fault,
            remaining: times,
        });
    }

    /// Removes every fault.
    pub fn clear_faults(&self) {
        lock(&self.state.rules).clear();
    }

    /// Every request so far.
    pub fn requests(&self) -> Vec<Logged> {
        lock(&self.state.log).clone()
    }

    /// Requests whose target starts with `prefix`.
    pub fn count(&self, prefix: &str) -> usize {
        lock(&self.state.log)
            .iter()
            .filter(|r| r.target.starts_with(prefix))
            .count()
    }

    /// The most requests in progress at once so far.
    pub fn max_concurrent(&self) -> usize {
        self.state.max_active.load(Ordering::SeqCst)
    }
}

impl Drop for FaultServer {
    fn drop(&mut self) {
        self.state.shutdown.store(true, Ordering::SeqCst);
        // Unblock accept().
        let _ = TcpStream::connect(self.addr);
    }
}

fn lock<T>(m: &Mutex<T>) -> std::sync::MutexGuard<'_, T> {
    m.lock().unwrap_or_else(|p| p.into_inner())
}

struct Active<'a>(&'a State);

impl Drop for Active<'_> {
    fn drop(&mut self) {
        self.0.active.fetch_sub(1, Ordering::SeqCst);
    }
}

fn serve(conn: TcpStream, state: &State) {
    let _ = conn.set_read_timeout(Some(Duration::from_secs(30)));
    let Ok(write_half) = conn.try_clone() else {
        return;
    };
    let mut out = write_half;
    let mut reader = BufReader::new(conn);
    loop {
        let mut line = String::new();
        match reader.read_line(&mut line) {
            Ok(0) | Err(_) => return,
            Ok(_) => {}
        }
        let mut parts = line.split_whitespace();
        let (Some(method), Some(target)) = (parts.next(), parts.next()) else {
            return;
        };
        let (method, target) = (method.to_string(), target.to_string());
        let mut headers = HashMap::new();
        loop {
            let mut h = String::new();
            if reader.read_line(&mut h).unwrap_or(0) == 0 {
                return;
            }
            let h = h.trim_end();
            if h.is_empty() {
                break;
            }
            if let Some((k, v)) = h.split_once(':') {
                headers.insert(k.trim().to_ascii_lowercase(), v.trim().to_string());
            }
        }
        if state.shutdown.load(Ordering::SeqCst) {
            return;
        }
        let n = state.active.fetch_add(1, Ordering::SeqCst) + 1;
        state.max_active.fetch_max(n, Ordering::SeqCst);
        let _active = Active(state);
        lock(&state.log).push(Logged {
            target: target.clone(),
            headers: headers.clone(),
        });
        let latency = *lock(&state.latency);
        if !latency.is_zero() {
            std::thread::sleep(latency);
        }
        let fault = {
            let mut rules = lock(&state.rules);
            let mut hit = None;
            for r in rules.iter_mut() {
                if target.starts_with(&r.prefix) && r.remaining != Some(0) {
                    if let Some(n) = &mut r.remaining {
                        *n -= 1;
                    }
                    hit = Some(r.fault.clone());
                    break;
                }
            }
            hit
        };
        let close = headers
            .get("connection")
            .is_some_and(|v| v.eq_ignore_ascii_case("close"));
        let keep = respond(&mut out, state, &method, &target, &headers, fault) && !close;
        if !keep {
            let _ = out.shutdown(Shutdown::Both);
            return;
        }
    }
}

fn file(state: &State, target: &str) -> Option<Vec<u8>> {
    let path = target.split('?').next().unwrap_or(target);
    if let Some(b) = lock(&state.files).get(path) {
        return Some(b.clone());
    }
    let root = state.root.as_ref()?;
    let rel = path.trim_start_matches('/');
    if rel.split('/').any(|c| c == "..") {
        return None;
    }
    std::fs::read(root.join(rel)).ok()
}

fn head(out: &mut TcpStream, status: u16, extra: &[(&str, String)], len: usize) -> bool {
    let reason = match status {
        200 => "OK",
        204 => "No Content",
        206 => "Partial Content",
        404 => "Not Found",
        416 => "Range Not Satisfiable",
        429 => "Too Many Requests",
        500 => "Internal Server Error",
        503 => "Service Unavailable",
        _ => "Status",
    };
    let mut h = format!("HTTP/1.1 {status} {reason}\r\nContent-Length: {len}\r\n");
    for (k, v) in extra {
        h.push_str(&format!("{k}: {v}\r\n"));
    }
    h.push_str("\r\n");
    out.write_all(h.as_bytes()).is_ok()
}

/// Answers one request; returns whether the connection stays open.
fn respond(
    out: &mut TcpStream,
    state: &State,
    method: &str,
    target: &str,
    headers: &HashMap<String, String>,
    fault: Option<Fault>,
) -> bool {
    match fault {
        Some(Fault::Status(s)) => return head(out, s, &[], 0),
        Some(Fault::RetryAfter { status, secs }) => {
            return head(out, status, &[("Retry-After", secs.to_string())], 0);
        }
        Some(Fault::Reset) => {
            // SO_LINGER 0 is not in std; closing both halves unanswered is what clients see
            // as a reset or an unexpected EOF.
            return false;
        }
        Some(Fault::NotAnImage) => {
            let body = b"<html><body>Service temporarily overloaded</body></html>";
            return head(
                out,
                200,
                &[("Content-Type", "text/html".into())],
                body.len(),
            ) && out.write_all(body).is_ok();
        }
        Some(Fault::AbsurdImage) => {
            let body = absurd_png();
            return head(
                out,
                200,
                &[("Content-Type", "image/png".into())],
                body.len(),
            ) && out.write_all(&body).is_ok();
        }
        Some(Fault::Delay(d)) => std::thread::sleep(d),
        _ => {}
    }
    if method != "GET" && method != "HEAD" {
        return head(out, 405, &[], 0);
    }
    let Some(body) = file(state, target) else {
        return head(out, 404, &[], 0);
    };
    let mut extra = vec![("Accept-Ranges", "bytes".to_string())];
    if let Some(cc) = lock(&state.cache_control).clone() {
        extra.push(("Cache-Control", cc));
    }
    let (status, slice) = match headers
        .get("range")
        .and_then(|r| parse_range(r, body.len()))
    {
        Some(Ok((a, b))) => {
            extra.push(("Content-Range", format!("bytes {a}-{b}/{}", body.len())));
            (206, &body[a..=b])
        }
        Some(Err(())) => return head(out, 416, &[], 0),
        None => (200, &body[..]),
    };
    match fault {
        Some(Fault::Truncate) => {
            let _ = head(out, status, &extra, slice.len())
                && out.write_all(&slice[..slice.len() / 2]).is_ok();
            false
        }
        Some(Fault::Stall(d)) => {
            let _ = head(out, status, &extra, slice.len())
                && out.write_all(&slice[..slice.len() / 2]).is_ok()
                && out.flush().is_ok();
            std::thread::sleep(d);
            false
        }
        _ => {
            if !head(out, status, &extra, slice.len()) {
                return false;
            }
            method == "HEAD" || out.write_all(slice).is_ok()
        }
    }
}

/// `bytes=a-b` (or `a-`, or `-n`) against a body of `len` bytes.
fn parse_range(value: &str, len: usize) -> Option<Result<(usize, usize), ()>> {
    let spec = value.strip_prefix("bytes=")?;
    let (a, b) = spec.split_once('-')?;
    let r = match (a.parse::<usize>().ok(), b.parse::<usize>().ok()) {
        (Some(a), Some(b)) => (a, b.min(len.saturating_sub(1))),
        (Some(a), None) => (a, len.saturating_sub(1)),
        (None, Some(n)) => (len.saturating_sub(n), len.saturating_sub(1)),
        (None, None) => return Some(Err(())),
    };
    Some(if r.0 > r.1 || r.0 >= len {
        Err(())
    } else {
        Ok(r)
    })
}

/// A PNG signature and IHDR chunk declaring 60000 x 60000 RGBA pixels (valid CRCs), a tiny
/// IDAT and IEND: a few dozen bytes that would need 14 GB decoded.
pub fn absurd_png() -> Vec<u8> {
    let mut b = vec![0x89, b'P', b'N', b'G', 0x0d, 0x0a, 0x1a, 0x0a];
    let mut chunk = |kind: &[u8; 4], data: &[u8]| {
        b.extend_from_slice(&(data.len() as u32).to_be_bytes());
        let mut c = kind.to_vec();
        c.extend_from_slice(data);
        b.extend_from_slice(&c);
        b.extend_from_slice(&crc32(&c).to_be_bytes());
    };
    let mut ihdr = Vec::new();
    ihdr.extend_from_slice(&60_000u32.to_be_bytes());
    ihdr.extend_from_slice(&60_000u32.to_be_bytes());
    ihdr.extend_from_slice(&[8, 6, 0, 0, 0]);
    chunk(b"IHDR", &ihdr);
    // An empty zlib stream, so decoders that look for image data find some.
    chunk(b"IDAT", &[0x78, 0x9c, 0x03, 0x00, 0x00, 0x00, 0x00, 0x01]);
    chunk(b"IEND", &[]);
    b
}

fn crc32(bytes: &[u8]) -> u32 {
    let mut c = !0u32;
    for &b in bytes {
        c ^= u32::from(b);
        for _ in 0..8 {
            c = if c & 1 != 0 {
                0xEDB8_8320 ^ (c >> 1)
            } else {
                c >> 1
            };
        }
    }
    !c
}

/// Reads a whole response from a raw socket (for tests of the server itself).
pub fn raw_get(addr: &str, target: &str, extra: &str) -> String {
    let mut s = TcpStream::connect(addr).expect("connect");
    let _ = write!(
        s,
        "GET {target} HTTP/1.1\r\nHost: x\r\nConnection: close\r\n{extra}\r\n"
    );
    let mut out = Vec::new();
    let _ = s.read_to_end(&mut out);
    String::from_utf8_lossy(&out).into_owned()
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn serves_ranges_and_faults() {
        let srv = FaultServer::in_memory();
        srv.put("/a.bin", b"0123456789".to_vec());
        let addr = srv.url("").trim_start_matches("http://").to_string();
        let r = raw_get(&addr, "/a.bin", "Range: bytes=2-4\r\n");
        assert!(r.starts_with("HTTP/1.1 206") && r.ends_with("234"), "{r}");
        assert!(raw_get(&addr, "/nope", "").starts_with("HTTP/1.1 404"));
        srv.add_fault(
            "/a",
            Fault::RetryAfter {
                status: 429,
                secs: 3,
            },
            Some(1),
        );
        let r = raw_get(&addr, "/a.bin", "");
        assert!(
            r.starts_with("HTTP/1.1 429") && r.contains("Retry-After: 3"),
            "{r}"
        );
        assert!(raw_get(&addr, "/a.bin", "").ends_with("0123456789"));
        assert_eq!(srv.count("/a.bin"), 3);
    }
}
