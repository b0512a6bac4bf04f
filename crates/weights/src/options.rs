//! How a [`crate::Fetcher`] downloads: offline or not, how long a silent server is waited for,
//! and whom it tells about progress.
//!
//! Design decision: these are values the caller passes, never process-wide flags, and the
//! environment is read in one place ([`FetchOptions::from_env`]), which the front ends (the
//! command line, the Python bindings) call; the library itself draws nothing and reads no
//! variable while it works.

use std::fmt;
use std::sync::Arc;
use std::time::Duration;

use dgstereo_core::{Error, Result};

/// How long a request waits for a server that sends nothing (to connect, to answer, and between
/// two reads of the body) unless `DGSTEREO_HTTP_TIMEOUT` says otherwise.
pub const DEFAULT_TIMEOUT: Duration = Duration::from_secs(30);

/// The variable that sets [`FetchOptions::timeout`], in seconds.
pub const TIMEOUT_VARIABLE: &str = "DGSTEREO_HTTP_TIMEOUT";

/// How far one download has come.
#[derive(Debug, Clone, PartialEq, Eq)]
pub struct Progress {
    /// The file being downloaded (`depth_anything_v2_vits.pth`, `models.zip`).
    pub file: String,
    /// Bytes on disk, those of an earlier attempt included.
    pub done: u64,
    /// The file's size, where the server states it.
    pub total: Option<u64>,
    /// Whether the download has ended (completed or not): the last report of this file.
    pub finished: bool,
}

/// Receives [`Progress`] reports, from the thread that downloads.
pub type ProgressFn = Arc<dyn Fn(&Progress) + Send + Sync>;

/// How to download: see the module's documentation.
#[derive(Clone)]
pub struct FetchOptions {
    /// Never download: a name missing from the cache is an error naming the command that
    /// fetches it.
    pub offline: bool,
    /// How long a silent server is waited for: to connect, to answer, and between two reads.
    pub timeout: Duration,
    /// Told how each download progresses; `None` for no reports.
    pub progress: Option<ProgressFn>,
}

impl Default for FetchOptions {
    /// Online, [`DEFAULT_TIMEOUT`], no progress reports.
    fn default() -> Self {
        Self { offline: false, timeout: DEFAULT_TIMEOUT, progress: None }
    }
}

impl fmt::Debug for FetchOptions {
    fn fmt(&self, f: &mut fmt::Formatter<'_>) -> fmt::Result {
        f.debug_struct("FetchOptions")
            .field("offline", &self.offline)
            .field("timeout", &self.timeout)
            .field("progress", &self.progress.as_ref().map(|_| "callback"))
            .finish()
    }
}

impl FetchOptions {
    /// The options the environment sets: offline with `DGSTEREO_OFFLINE` or `HF_HUB_OFFLINE`
    /// (`1`, `true`, `yes`, `on`), the timeout from `DGSTEREO_HTTP_TIMEOUT` (seconds, above 0),
    /// no progress reports.
    ///
    /// # Errors
    /// [`Error::Config`] keyed by the variable when `DGSTEREO_HTTP_TIMEOUT` is not a positive
    /// number of seconds.
    pub fn from_env() -> Result<Self> {
        let offline = env_flag("DGSTEREO_OFFLINE") || env_flag("HF_HUB_OFFLINE");
        let timeout = match std::env::var(TIMEOUT_VARIABLE) {
            Ok(text) if !text.trim().is_empty() => parse_timeout(&text)?,
            _ => DEFAULT_TIMEOUT,
        };
        Ok(Self { offline, timeout, progress: None })
    }

    /// Reports `progress`, if anyone listens.
    pub(crate) fn report(&self, progress: Progress) {
        if let Some(listener) = &self.progress {
            listener(&progress);
        }
    }
}

/// A timeout in seconds (`30`, `2.5`), as `DGSTEREO_HTTP_TIMEOUT` gives it.
///
/// # Errors
/// [`Error::Config`] keyed by the variable for anything but a positive, finite number.
pub fn parse_timeout(text: &str) -> Result<Duration> {
    match text.trim().parse::<f64>() {
        Ok(seconds) if seconds > 0.0 && seconds.is_finite() && seconds < 1e9 => Ok(Duration::from_secs_f64(seconds)),
        _ => Err(Error::config(
            TIMEOUT_VARIABLE,
            format!("'{}' is not a number of seconds above 0 (e.g. 30)", text.trim()),
        )),
    }
}

fn env_flag(name: &str) -> bool {
    std::env::var(name).is_ok_and(|v| matches!(v.trim().to_ascii_lowercase().as_str(), "1" | "true" | "yes" | "on"))
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn timeouts_are_positive_seconds_and_bad_ones_name_the_variable() {
        assert_eq!(parse_timeout("30").unwrap(), Duration::from_secs(30));
        assert_eq!(parse_timeout(" 0.25 ").unwrap(), Duration::from_millis(250));
        for bad in ["0", "-1", "soon", "inf", ""] {
            let e = parse_timeout(bad).unwrap_err();
            assert!(matches!(&e, Error::Config(p) if p.key == TIMEOUT_VARIABLE), "{bad}: {e}");
        }
    }
}
