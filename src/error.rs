//! The crate-wide error type. Every error names the file (or the input) and the problem, so a
//! museum operator can act on it; none of the core's entry points panics on bad input.

use std::fmt;
use std::path::PathBuf;

/// Result with the crate's [`Error`].
pub type Result<T, E = Error> = std::result::Result<T, E>;

/// Everything that can go wrong in Pygmalion's core.
#[derive(Debug)]
pub enum Error {
    /// A PLY file could not be read or written (see [`crate::cloud::ply::PlyError`]).
    Ply(crate::cloud::ply::PlyError),
    /// A file other than a PLY could not be read or written.
    Io {
        path: PathBuf,
        source: std::io::Error,
    },
    /// A configuration or data file (template, pose, skeleton JSON, kiosk config) is invalid.
    Config { path: PathBuf, problem: String },
    /// An input that is not a file (a point cloud in memory, a command-line value) is invalid.
    Input(String),
}

impl Error {
    /// A configuration error about `path`.
    pub fn config(path: impl Into<PathBuf>, problem: impl Into<String>) -> Self {
        Error::Config {
            path: path.into(),
            problem: problem.into(),
        }
    }
    /// An input error.
    pub fn input(problem: impl Into<String>) -> Self {
        Error::Input(problem.into())
    }
}

impl fmt::Display for Error {
    fn fmt(&self, f: &mut fmt::Formatter<'_>) -> fmt::Result {
        match self {
            Error::Ply(e) => write!(f, "{e}"),
            Error::Io { path, source } => write!(f, "{}: {source}", path.display()),
            Error::Config { path, problem } => write!(f, "{}: {problem}", path.display()),
            Error::Input(problem) => write!(f, "{problem}"),
        }
    }
}

impl std::error::Error for Error {
    fn source(&self) -> Option<&(dyn std::error::Error + 'static)> {
        match self {
            Error::Ply(e) => Some(e),
            Error::Io { source, .. } => Some(source),
            _ => None,
        }
    }
}

impl From<crate::cloud::ply::PlyError> for Error {
    fn from(e: crate::cloud::ply::PlyError) -> Self {
        Error::Ply(e)
    }
}
