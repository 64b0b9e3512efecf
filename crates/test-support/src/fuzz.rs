//! A small deterministic mutation fuzzer for the readers of outside bytes, run by `cargo test`
//! on stable Rust (cargo-fuzz needs nightly and a network to set up; what matters here is
//! that every reader meets thousands of damaged inputs on every CI run).
//!
//! Each reader has a corpus of valid inputs in `fuzz/seeds/READER/` (kept in the
//! repository; files Globus or GDAL wrote from made-up values, no third-party data; the
//! ignored `fuzz/corpus` is the working corpus of the nightly cargo-fuzz target in `fuzz/`). [`run`] mutates them (bit
//! flips, bytes set to boundary values, 32-bit fields set to huge or negative numbers,
//! truncation, chunks duplicated or removed) with a fixed seed and hands each to the reader,
//! which must return (Ok or Err) without panicking. The budget is [`DEFAULT_CASES`] inputs per
//! reader, or `GLOBUS_FUZZ_SECS` seconds each when set (for longer runs by hand). An input that
//! panics is written to `target/fuzz-failures/READER-N` and named in the failure.

use std::path::PathBuf;
use std::time::{Duration, Instant};

/// Inputs tried per reader in a plain `cargo test`.
pub const DEFAULT_CASES: usize = 10_000;

/// What a run tried.
#[derive(Clone, Copy, Debug, Default)]
pub struct FuzzReport {
    /// Inputs tried.
    pub cases: usize,
    /// How many the reader accepted.
    pub accepted: usize,
}

/// The corpus of `reader`, sorted by name.
pub fn corpus(reader: &str) -> Vec<Vec<u8>> {
    let dir = crate::workspace_root().join("fuzz/seeds").join(reader);
    let mut files: Vec<PathBuf> = std::fs::read_dir(&dir)
        .unwrap_or_else(|e| panic!("fuzz corpus {}: {e}", dir.display()))
        .flatten()
        .map(|e| e.path())
        .collect();
    files.sort();
    files
        .iter()
        .map(|p| std::fs::read(p).unwrap_or_else(|e| panic!("{}: {e}", p.display())))
        .collect()
}

/// xorshift64*: a fixed sequence for a fixed seed.
struct Rng(u64);

impl Rng {
    fn next(&mut self) -> u64 {
        self.0 ^= self.0 >> 12;
        self.0 ^= self.0 << 25;
        self.0 ^= self.0 >> 27;
        self.0.wrapping_mul(0x2545_f491_4f6c_dd1d)
    }

    fn below(&mut self, n: usize) -> usize {
        (self.next() % n.max(1) as u64) as usize
    }
}

/// One mutation of `input` (up to 4 edits).
fn mutate(input: &[u8], rng: &mut Rng) -> Vec<u8> {
    let mut out = input.to_vec();
    for _ in 0..1 + rng.below(4) {
        if out.is_empty() {
            out.push(rng.next() as u8);
            continue;
        }
        let at = rng.below(out.len());
        match rng.below(7) {
            0 => out[at] ^= 1 << rng.below(8),
            1 => out[at] = [0, 1, 0x7f, 0x80, 0xff][rng.below(5)],
            2 => {
                let v: u32 = [u32::MAX, i32::MAX as u32, 0x8000_0000, 0, 65536, 4096][rng.below(6)];
                for (k, b) in v.to_le_bytes().into_iter().enumerate() {
                    if let Some(x) = out.get_mut(at + k) {
                        *x = b;
                    }
                }
            }
            3 => out.truncate(at),
            4 => {
                let len = rng.below(64).min(out.len() - at);
                let chunk = out[at..at + len].to_vec();
                let to = rng.below(out.len());
                out.splice(to..to, chunk);
            }
            5 => {
                let len = rng.below(64).min(out.len() - at);
                out.drain(at..at + len);
            }
            _ => out[at] = rng.next() as u8,
        }
    }
    out
}

/// Feeds `reader` mutations of its corpus; `read` returns whether it accepted an input.
pub fn run(reader: &str, read: impl Fn(&[u8]) -> bool) -> FuzzReport {
    let corpus = corpus(reader);
    assert!(!corpus.is_empty(), "fuzz corpus {reader} is empty");
    let secs = std::env::var("GLOBUS_FUZZ_SECS")
        .ok()
        .and_then(|s| s.parse::<f64>().ok());
    let deadline = secs.map(|s| Instant::now() + Duration::from_secs_f64(s));
    let mut rng = Rng(0x9e37_79b9_7f4a_7c15 ^ reader.len() as u64);
    let mut report = FuzzReport::default();
    for seed in &corpus {
        assert!(read(seed), "fuzz corpus {reader}: a seed input is refused");
    }
    loop {
        let done = match deadline {
            Some(d) => Instant::now() >= d,
            None => report.cases >= DEFAULT_CASES,
        };
        if done {
            break;
        }
        let input = mutate(&corpus[rng.below(corpus.len())], &mut rng);
        let outcome = std::panic::catch_unwind(std::panic::AssertUnwindSafe(|| read(&input)));
        match outcome {
            Ok(accepted) => report.accepted += usize::from(accepted),
            Err(_) => {
                let dir = crate::workspace_root().join("target/fuzz-failures");
                let _ = std::fs::create_dir_all(&dir);
                let path = dir.join(format!("{reader}-{}", report.cases));
                let _ = std::fs::write(&path, &input);
                panic!(
                    "fuzz {reader}: input {} panicked (kept in {})",
                    report.cases,
                    path.display()
                );
            }
        }
        report.cases += 1;
    }
    report
}
