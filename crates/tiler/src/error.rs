//! [`TilerError`]: every failure names the file, tile or option at fault.

use std::path::PathBuf;

use globus_tiling::TileKey;

/// What can go wrong while tiling. Each message is one line that names what is at fault.
#[derive(Debug, thiserror::Error)]
pub enum TilerError {
    /// An input file could not be read.
    #[error("{path}: {error}")]
    Io {
        /// The file.
        path: PathBuf,
        /// The operating system's error.
        error: std::io::Error,
    },
    /// An input file is not what it claims to be (truncated, corrupt, wrong size).
    #[error("{path}: {problem}")]
    BadInput {
        /// The file.
        path: PathBuf,
        /// What is wrong with it.
        problem: String,
    },
    /// The options contradict each other or the input.
    #[error("{0}")]
    BadOptions(String),
    /// Writing the output failed.
    #[error("{path}: {problem}")]
    Output {
        /// The output file or directory.
        path: PathBuf,
        /// What went wrong.
        problem: String,
    },
    /// Encoding one tile failed.
    #[error("tile {key:?}: {problem}")]
    Encode {
        /// The tile.
        key: TileKey,
        /// What went wrong.
        problem: String,
    },
}

impl TilerError {
    /// A [`TilerError::BadInput`] for `path`.
    pub fn bad_input(path: impl Into<PathBuf>, problem: impl Into<String>) -> Self {
        Self::BadInput {
            path: path.into(),
            problem: problem.into(),
        }
    }

    /// A [`TilerError::Output`] for `path`.
    pub fn output(path: impl Into<PathBuf>, problem: impl std::fmt::Display) -> Self {
        Self::Output {
            path: path.into(),
            problem: problem.to_string(),
        }
    }

    /// A [`TilerError::Io`] for `path`.
    pub fn io(path: impl Into<PathBuf>, error: std::io::Error) -> Self {
        Self::Io {
            path: path.into(),
            error,
        }
    }
}

/// Result of tiler operations.
pub type Result<T, E = TilerError> = std::result::Result<T, E>;
