//! The error type shared by the library crates.

use std::path::PathBuf;

/// Errors of dgstereo's library crates. Each names the file, key or value at fault.
#[derive(Debug, thiserror::Error)]
pub enum Error {
    /// A file could not be opened, read or written.
    #[error("{path}: {source}")]
    Io {
        /// The file.
        path: PathBuf,
        /// The underlying error.
        source: std::io::Error,
    },
    /// A file was read but its contents are not what was expected.
    #[error("{path}: {message}")]
    Format {
        /// The file.
        path: PathBuf,
        /// What is wrong with it.
        message: String,
    },
    /// A checkpoint does not fit the model: a missing, unknown or mis-shaped key.
    #[error("{path}: {message}")]
    Checkpoint {
        /// The checkpoint file.
        path: PathBuf,
        /// The key and what is wrong with it.
        message: String,
    },
    /// A configuration value is invalid.
    #[error("config: {0}")]
    Config(String),
    /// Tensors of incompatible shapes were given.
    #[error("shape: {0}")]
    Shape(String),
    /// Anything else, with a message.
    #[error("{0}")]
    Other(String),
}

impl Error {
    /// An I/O error on `path`.
    pub fn io(path: impl Into<PathBuf>, source: std::io::Error) -> Self {
        Self::Io { path: path.into(), source }
    }

    /// A format error in `path`.
    pub fn format(path: impl Into<PathBuf>, message: impl Into<String>) -> Self {
        Self::Format { path: path.into(), message: message.into() }
    }

    /// An invalid configuration value: `key` is the dotted key (or option field) at fault,
    /// `reason` what is wrong with its value.
    pub fn config(key: impl Into<String>, reason: impl Into<String>) -> Self {
        Self::Config(format!("{}: {}", key.into(), reason.into()))
    }
}

/// Result with [`Error`].
pub type Result<T, E = Error> = std::result::Result<T, E>;
