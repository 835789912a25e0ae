//! The one error type of the core. Every fallible public function returns `Result<_, LgiError>`;
//! messages name the file, element or bundle at fault so a user can act on them.

use std::path::PathBuf;

/// Everything that can go wrong in lgi-core. The Python binding maps each variant to an
/// exception class (`lgi.DatasetError`, `lgi.InputError`, ...).
#[derive(Debug, thiserror::Error)]
pub enum LgiError {
    /// A file could not be opened or read (missing, permissions, ...).
    #[error("cannot read {path}: {message}")]
    Io {
        /// The file.
        path: PathBuf,
        /// What the operating system said.
        message: String,
    },
    /// A file could not be written (directory missing, permissions, disk full, ...).
    #[error("cannot write {path}: {message}")]
    Write {
        /// The file.
        path: PathBuf,
        /// What the operating system said.
        message: String,
    },
    /// A file was read but its content is malformed.
    #[error("{path}:{line}: {message}")]
    Parse {
        /// The file.
        path: PathBuf,
        /// 1-based line (0 when the format has no lines, e.g. binary glTF).
        line: usize,
        /// What is wrong and, where possible, how to fix it.
        message: String,
    },
    /// The dataset is inconsistent (vertex counts, NaNs, degenerate UVs, ...).
    #[error("invalid dataset: {0}")]
    Dataset(String),
    /// An argument is out of its domain (shape, NaN, range, ...).
    #[error("invalid input: {0}")]
    Input(String),
    /// A marker lies too far from the neutral surface: probably mislabelled.
    #[error(
        "marker {index} is {distance:.6} from the neutral surface (tolerance {tolerance:.6}); \
         it is probably mislabelled or in another unit: fix it or raise the tolerance"
    )]
    MarkerOffSurface {
        /// Marker (bundle) index.
        index: usize,
        /// Its distance to the closest point of the neutral.
        distance: f64,
        /// The tolerance in force, in the data's units.
        tolerance: f64,
    },
    /// A saved model is corrupt, truncated, of another version or not an lgi model at all.
    #[error("model file {path}: {message}")]
    ModelFormat {
        /// The file.
        path: PathBuf,
        /// What is wrong.
        message: String,
    },
}

/// Shorthand used throughout the core.
pub type Result<T, E = LgiError> = std::result::Result<T, E>;

impl LgiError {
    /// An `Io` error for `path` from a `std::io::Error`.
    pub fn io(path: impl Into<PathBuf>, err: &std::io::Error) -> Self {
        LgiError::Io {
            path: path.into(),
            message: err.to_string(),
        }
    }

    /// A `Write` error for `path` from a `std::io::Error`.
    pub fn write(path: impl Into<PathBuf>, err: &std::io::Error) -> Self {
        LgiError::Write {
            path: path.into(),
            message: err.to_string(),
        }
    }

    /// A `Parse` error at `path:line`.
    pub fn parse(path: impl Into<PathBuf>, line: usize, message: impl Into<String>) -> Self {
        LgiError::Parse {
            path: path.into(),
            line,
            message: message.into(),
        }
    }
}
