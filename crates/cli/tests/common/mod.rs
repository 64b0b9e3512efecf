//! Helpers the CLI tests share: run the `globus` binary, read its JSON, scratch directories.

#![allow(dead_code)] // each test file uses its own subset
#![allow(clippy::unwrap_used)] // test helpers: a failure should stop the test

use std::path::{Path, PathBuf};
use std::process::{Command, Output};

/// Runs `globus` with `args`, without a display (so `view` fails at once instead of opening)
/// and without a runtime directory, as on a fresh machine's console: the binary makes its own.
pub fn globus(args: &[&str]) -> Output {
    Command::new(env!("CARGO_BIN_EXE_globus"))
        .args(args)
        .env_remove("DISPLAY")
        .env_remove("WAYLAND_DISPLAY")
        .env_remove("XDG_RUNTIME_DIR")
        .output()
        .expect("run globus")
}

/// The JSON a successful run printed on stdout.
pub fn json(out: &Output) -> serde_json::Value {
    assert!(
        out.status.success(),
        "{}",
        String::from_utf8_lossy(&out.stderr)
    );
    serde_json::from_slice(&out.stdout).expect("JSON on stdout")
}

/// Fails with a non-zero status and exactly one line on stderr containing every needle.
pub fn fails_with_one_line(args: &[&str], needles: &[&str]) {
    globus_test_support::assert_one_line_failure(&format!("{args:?}"), &globus(args), needles);
}

/// An empty directory `name` under the test output folder of `group`.
pub fn scratch(group: &str, name: &str) -> PathBuf {
    let dir = globus_test_support::output_dir(group).join(name);
    let _ = std::fs::remove_dir_all(&dir);
    std::fs::create_dir_all(&dir).unwrap();
    dir
}

/// A path as a command-line argument.
pub fn s(p: &Path) -> &str {
    p.to_str().unwrap()
}
