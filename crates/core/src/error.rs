//! The error type shared by the library crates, and [`Problem`], one thing wrong with a
//! configuration.
//!
//! A configuration error is typed: it carries the dotted key at fault and the reason apart, so a
//! caller that nests one configuration in another prefixes the key ([`Problem::within`]) instead
//! of parsing it back out of a message.

use std::fmt;
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
    /// A configuration value is invalid: the key at fault and why.
    #[error("config: {0}")]
    Config(Problem),
    /// Tensors of incompatible shapes were given.
    #[error("shape: {0}")]
    Shape(String),
    /// A download failed: the address, what arrived (or that nothing did) and why.
    #[error("{url}: {cause}")]
    Fetch {
        /// The address requested.
        url: String,
        /// What went wrong, including what arrived before it did.
        cause: String,
    },
    /// One rank of a data-parallel job failed in a phase every rank ends together (`agree`):
    /// every rank returns this error, naming the failing one, so none waits for another.
    #[error("rank {rank} of {size}: {cause}")]
    Rank {
        /// The lowest failing rank.
        rank: usize,
        /// The number of ranks.
        size: usize,
        /// That rank's error, as its text (it crossed the process boundary).
        cause: String,
    },
    /// An operation this build, backend or exporter does not support.
    #[error("{operation} is not supported: {reason}")]
    Unsupported {
        /// What was asked for (an ONNX operation, a backend feature).
        operation: String,
        /// Why not, and what to do instead where there is a way.
        reason: String,
    },
    /// An error with what was being done when it happened (`reading pair 3`, `left image`).
    #[error("{context}: {source}")]
    Context {
        /// What was being done.
        context: String,
        /// The error itself, its kind kept.
        #[source]
        source: Box<Error>,
    },
    /// A value that must be finite is not: a loss, a gradient, a disparity.
    #[error("{what} is not finite")]
    NotFinite {
        /// The value and where it came from (`the loss (NaN; pairs: a, b)`).
        what: String,
    },
    /// Inputs that each look right but contradict each other: shards of different evaluations,
    /// ranks that read different checkpoints.
    #[error("{what}: {reason}")]
    Mismatch {
        /// What disagrees.
        what: String,
        /// With what, and what to do about it.
        reason: String,
    },
    /// A sample of a data set that cannot serve as asked: it lacks ground truth, or it is not in
    /// the set.
    #[error("{sample}: {reason}")]
    Sample {
        /// The sample's name (`middlebury/Cones`).
        sample: String,
        /// What is wrong with it.
        reason: String,
    },
    /// A value that could not be written in its format: a checkpoint, a plot, an ONNX model.
    #[error("cannot encode {what}: {cause}")]
    Encode {
        /// What was being written.
        what: String,
        /// The encoder's error.
        cause: String,
    },
    /// A broken invariant of dgstereo itself, never bad input: a caught panic, a pass that gave
    /// no output. It is a bug to report.
    #[error("internal error: {0}")]
    Internal(String),
}

impl Error {
    /// The message of a caught panic's payload (`catch_unwind`'s `Err`): the `String` or `&str`
    /// it was raised with, "unknown panic" otherwise.
    pub fn panic_message(payload: &(dyn std::any::Any + Send)) -> String {
        payload
            .downcast_ref::<String>()
            .cloned()
            .or_else(|| payload.downcast_ref::<&str>().map(|s| s.to_string()))
            .unwrap_or_else(|| "unknown panic".into())
    }

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
        Self::Config(Problem::new(key, reason))
    }

    /// A failed download of `url`.
    pub fn fetch(url: impl Into<String>, cause: impl Into<String>) -> Self {
        Self::Fetch { url: url.into(), cause: cause.into() }
    }

    /// An operation that is not supported, and why.
    pub fn unsupported(operation: impl Into<String>, reason: impl Into<String>) -> Self {
        Self::Unsupported { operation: operation.into(), reason: reason.into() }
    }

    /// A value that is not finite; `what` names it and where it came from.
    pub fn not_finite(what: impl Into<String>) -> Self {
        Self::NotFinite { what: what.into() }
    }

    /// Inputs that contradict each other: `what` disagrees, `reason` says with what.
    pub fn mismatch(what: impl Into<String>, reason: impl Into<String>) -> Self {
        Self::Mismatch { what: what.into(), reason: reason.into() }
    }

    /// A sample that cannot serve as asked.
    pub fn sample(sample: impl Into<String>, reason: impl Into<String>) -> Self {
        Self::Sample { sample: sample.into(), reason: reason.into() }
    }

    /// A value that could not be encoded.
    pub fn encode(what: impl Into<String>, cause: impl ToString) -> Self {
        Self::Encode { what: what.into(), cause: cause.to_string() }
    }

    /// Whether this error, under its [`Context`](Self::Context) wrappers, is one every rank of a
    /// data-parallel job returned together ([`Rank`](Self::Rank)), so that no rank is left
    /// waiting for another and the job may end normally.
    pub fn is_rank_failure(&self) -> bool {
        matches!(self.root(), Self::Rank { .. })
    }

    /// This error with `context` (what was being done) written before it; its kind stays
    /// reachable through [`root`](Self::root).
    #[must_use]
    pub fn context(self, context: impl Into<String>) -> Self {
        Self::Context { context: context.into(), source: Box::new(self) }
    }

    /// The error under every [`Context`](Self::Context) wrapper: what a caller branches on.
    pub fn root(&self) -> &Error {
        match self {
            Self::Context { source, .. } => source.root(),
            other => other,
        }
    }

    /// The error as seen from the table that holds the configuration under `table`: a
    /// configuration error's key is prefixed ([`Problem::within`]), other errors are unchanged.
    #[must_use]
    pub fn within(self, table: &str) -> Self {
        match self {
            Self::Config(problem) => Self::Config(problem.within(table)),
            Self::Context { context, source } => Self::Context { context, source: Box::new(source.within(table)) },
            other => other,
        }
    }
}

/// One thing wrong with a configuration: the key at fault and what is wrong with its value.
///
/// A configuration names keys relative to its own table (`tau` in `LossConfig`); whoever holds
/// that table under a name prefixes it ([`within`](Self::within): `loss.tau`).
#[derive(Debug, Clone, PartialEq, Eq)]
pub struct Problem {
    /// Dotted key (or option field), e.g. `updater.guidance` or `sources[0].weight`; empty for
    /// the table itself.
    pub key: String,
    /// What is wrong, and how to fix it where that is not obvious.
    pub reason: String,
}

impl Problem {
    /// A problem with `key`.
    pub fn new(key: impl Into<String>, reason: impl Into<String>) -> Self {
        Self { key: key.into(), reason: reason.into() }
    }

    /// The problem as seen from the table that holds this one under `table` (`tau` becomes
    /// `loss.tau`; an index such as `sources[0]` joins without a dot: `data.sources[0].weight`).
    #[must_use]
    pub fn within(self, table: &str) -> Self {
        let key = match (table.is_empty(), self.key.is_empty()) {
            (true, _) => self.key,
            (false, true) => table.to_string(),
            (false, false) if self.key.starts_with('[') => format!("{table}{}", self.key),
            (false, false) => format!("{table}.{}", self.key),
        };
        Self { key, reason: self.reason }
    }

    /// `Ok` when `problems` is empty, else the first as [`Error::Config`].
    ///
    /// # Errors
    /// The first problem.
    pub fn first(problems: impl IntoIterator<Item = Problem>) -> Result<()> {
        match problems.into_iter().next() {
            None => Ok(()),
            Some(problem) => Err(Error::Config(problem)),
        }
    }
}

impl fmt::Display for Problem {
    fn fmt(&self, f: &mut fmt::Formatter<'_>) -> fmt::Result {
        if self.key.is_empty() { write!(f, "{}", self.reason) } else { write!(f, "{}: {}", self.key, self.reason) }
    }
}

impl From<Problem> for Error {
    fn from(problem: Problem) -> Self {
        Self::Config(problem)
    }
}

/// Result with [`Error`].
pub type Result<T, E = Error> = std::result::Result<T, E>;

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn context_keeps_the_kind_reachable_and_reads_outside_in() {
        let e = Error::fetch("http://127.0.0.1:9/x.pth", "no answer in 60 s").context("fetching raftstereo-eth3d");
        assert_eq!(e.to_string(), "fetching raftstereo-eth3d: http://127.0.0.1:9/x.pth: no answer in 60 s");
        assert!(matches!(e.root(), Error::Fetch { url, .. } if url.ends_with("x.pth")));
        let keyed = Error::config("tau", "must be positive").context("loss").within("model");
        assert!(matches!(keyed.root(), Error::Config(p) if p.key == "model.tau"), "{keyed}");
    }

    /// A caught panic reads as the text it was raised with, formatted or literal.
    #[test]
    fn a_panics_payload_gives_its_message() {
        let caught = |f: fn()| std::panic::catch_unwind(f).expect_err("it panics");
        let formatted = caught(|| panic!("row {} of {}", 3, 4));
        let literal = caught(|| panic!("a literal"));
        let other = caught(|| std::panic::panic_any(7u8));
        assert_eq!(Error::panic_message(&*formatted), "row 3 of 4");
        assert_eq!(Error::panic_message(&*literal), "a literal");
        assert_eq!(Error::panic_message(&*other), "unknown panic");
    }
}
