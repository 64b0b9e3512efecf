//! Test fixtures shared by the Globus crates (never a dependency of shipped code).
//!
//! * [`MemoryOracle`]: a [`globus_tiling::TileOracle`] with controllable load states and a
//!   simple error model, so selection can be tested deterministically without any data.
//! * [`image`](mod@image): reading, comparing and inspecting rendered frames.
//! * [`http::FaultServer`]: a real HTTP server on 127.0.0.1 that injects faults.
//! * [`shared_data`]: the path of a file in `../shared/data`.
//! * [`fuzz`]: a deterministic mutation fuzzer for readers of outside bytes.
//! * [`eventually`]: waiting (in real time, bounded) for other threads to reach a state.

pub mod fuzz;
pub mod http;
pub mod image;
mod oracle;

pub use oracle::{LoadRule, MemoryOracle};

use std::path::PathBuf;

/// The path of `name` in the shared data folder (`../shared/data` beside the repository).
pub fn shared_data(name: &str) -> PathBuf {
    workspace_root().join("../shared/data").join(name)
}

/// The workspace root (the folder holding the top `Cargo.toml`).
pub fn workspace_root() -> PathBuf {
    PathBuf::from(env!("CARGO_MANIFEST_DIR")).join("../..")
}

/// A folder under `target/` for test outputs (images to look at), created if needed.
pub fn output_dir(test_name: &str) -> PathBuf {
    let dir = workspace_root().join("target/test-output").join(test_name);
    // Failing to create it only loses the artefacts, not the test.
    let _ = std::fs::create_dir_all(&dir);
    dir
}

/// Asserts that a command the test ran (described by `what`) failed with a non-zero status
/// and exactly one line on stderr containing every needle, and did not panic.
pub fn assert_one_line_failure(what: &str, out: &std::process::Output, needles: &[&str]) {
    let err = String::from_utf8_lossy(&out.stderr);
    assert!(!out.status.success(), "{what} succeeded");
    assert_eq!(err.trim_end().lines().count(), 1, "{what} printed:\n{err}");
    for n in needles {
        assert!(err.contains(n), "{what}: {err} (wanted {n:?})");
    }
    assert!(!err.contains("panicked"), "{what}: {err}");
}

/// Waits (real time, polling every millisecond) until `cond` holds; panics naming `what`
/// after 10 s, so a test of threads fails instead of hanging.
pub fn eventually(what: &str, cond: impl Fn() -> bool) {
    let deadline = std::time::Instant::now() + std::time::Duration::from_secs(10);
    while !cond() {
        assert!(
            std::time::Instant::now() < deadline,
            "timed out waiting: {what}"
        );
        std::thread::sleep(std::time::Duration::from_millis(1));
    }
}

/// Makes a FIFO at `path` (replacing what is there): an input that blocks a reader for ever.
pub fn mkfifo(path: &std::path::Path) {
    let _ = std::fs::remove_file(path);
    let made = std::process::Command::new("mkfifo").arg(path).status();
    assert!(made.is_ok_and(|s| s.success()), "mkfifo {}", path.display());
}

/// A deterministic stream of numbers for tests (SplitMix64, Steele, Lea and Flood 2014):
/// the same seed gives the same numbers on every machine.
pub struct SplitMix64(pub u64);

impl SplitMix64 {
    /// The next 64 random bits.
    pub fn next_u64(&mut self) -> u64 {
        self.0 = self.0.wrapping_add(0x9e37_79b9_7f4a_7c15);
        let mut z = self.0;
        z = (z ^ (z >> 30)).wrapping_mul(0xbf58_476d_1ce4_e5b9);
        z = (z ^ (z >> 27)).wrapping_mul(0x94d0_49bb_1331_11eb);
        z ^ (z >> 31)
    }

    /// A number in 0..1.
    pub fn unit(&mut self) -> f64 {
        (self.next_u64() >> 11) as f64 / (1u64 << 53) as f64
    }
}
