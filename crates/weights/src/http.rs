//! HTTP for downloads: requests that give up on a silent server, and bodies written to a
//! partial file that a later attempt continues with a ranged request.
//!
//! Design decision: every request of every source goes through one [`Http`], whose agent carries
//! the options' timeout for connecting, for the answer and for each read of the body, so no
//! source can hang; every failure is [`Error::Fetch`] naming the address, what arrived before
//! it, and that fetching again resumes.

use std::fs::OpenOptions;
use std::io::{Read, Write};
use std::path::Path;
use std::time::Duration;

use dgstereo_core::{Error, Result};

use crate::options::{FetchOptions, Progress, TIMEOUT_VARIABLE};

/// What a body's download came to.
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
pub(crate) enum Saved {
    /// The partial file holds the whole file.
    Complete,
    /// The server refused the range (the partial file was already whole or longer than the file
    /// is now): the partial file is gone, request the file again from its start.
    Restart,
}

/// Requests with the options' timeouts.
pub(crate) struct Http {
    following: ureq::Agent,
    not_following: ureq::Agent,
    timeout: Duration,
}

impl Http {
    /// An agent that waits at most `options.timeout` for a silent server, whichever step it is
    /// at; proxies come from the usual variables (`HTTPS_PROXY`, `ALL_PROXY`).
    pub(crate) fn new(options: &FetchOptions) -> Self {
        let builder = || {
            ureq::AgentBuilder::new()
                .try_proxy_from_env(true)
                .timeout_connect(options.timeout)
                .timeout_read(options.timeout)
                .timeout_write(options.timeout)
                .user_agent(concat!("dgstereo/", env!("CARGO_PKG_VERSION")))
        };
        Self { following: builder().build(), not_following: builder().redirects(0).build(), timeout: options.timeout }
    }

    /// GET `url`, asking for the bytes from `from` on when it is above 0; redirects are
    /// followed with `follow`, else a redirect is the answer. A refused range (416) is an
    /// answer too; other error statuses are errors.
    pub(crate) fn get(&self, url: &str, from: u64, follow: bool) -> Result<ureq::Response> {
        let agent = if follow { &self.following } else { &self.not_following };
        let mut request = agent.get(url);
        if from > 0 {
            request = request.set("Range", &format!("bytes={from}-"));
        }
        match request.call() {
            Ok(response) => Ok(response),
            Err(ureq::Error::Status(416, response)) if from > 0 => Ok(response),
            Err(ureq::Error::Status(code, response)) => {
                Err(Error::fetch(url, format!("the server answered {code} {}; {}", response.status_text(), kept(from))))
            }
            Err(ureq::Error::Transport(t)) => Err(Error::fetch(url, self.transport_cause(&t, from))),
        }
    }

    /// Why a request got no answer, and what is kept.
    fn transport_cause(&self, t: &ureq::Transport, have: u64) -> String {
        let timed_out =
            std::error::Error::source(t).and_then(|s| s.downcast_ref::<std::io::Error>()).is_some_and(is_timeout);
        if timed_out {
            format!("no answer within {} ({TIMEOUT_VARIABLE} sets the wait); {}", seconds(self.timeout), kept(have))
        } else {
            // The transport's own text starts with the address, which the error names already.
            let message = t.message().map(|m| format!(": {m}")).unwrap_or_default();
            let source = std::error::Error::source(t).map(|s| format!(" ({s})")).unwrap_or_default();
            format!("{}{message}{source}; {}", t.kind(), kept(have))
        }
    }

    /// Writes the body of `response` (an answer to [`Http::get`] from `have`) into `partial`:
    /// appended to the `have` bytes there for a 206 that continues them, in their place for a
    /// 200. Reports progress as `file`. On an error the bytes received stay for the next attempt.
    pub(crate) fn save(
        &self,
        response: ureq::Response,
        url: &str,
        partial: &Path,
        have: u64,
        file: &str,
        options: &FetchOptions,
    ) -> Result<Saved> {
        if response.status() == 416 {
            std::fs::remove_file(partial).map_err(|e| Error::io(partial, e))?;
            return Ok(Saved::Restart);
        }
        let resumed = response.status() == 206;
        let (start, total) = if resumed {
            let (start, total) = content_range(response.header("Content-Range"));
            if start != Some(have) {
                let _ = std::fs::remove_file(partial);
                return Err(Error::fetch(
                    url,
                    format!(
                        "asked for the bytes from {have} on, the server sent a range starting at {}; the partial \
                         download was removed: fetch again to start anew",
                        start.map_or("an unstated byte".to_string(), |s| s.to_string())
                    ),
                ));
            }
            (have, total)
        } else {
            (0, response.header("Content-Length").and_then(|l| l.trim().parse::<u64>().ok()))
        };
        let mut out = OpenOptions::new()
            .create(true)
            .write(true)
            .append(resumed)
            .truncate(!resumed)
            .open(partial)
            .map_err(|e| Error::io(partial, e))?;
        let report = |done: u64, finished: bool| {
            options.report(Progress { file: file.to_string(), done, total, finished });
        };
        report(start, false);
        let mut reader = response.into_reader();
        let mut buffer = vec![0u8; 1 << 16];
        let mut written = start;
        let result = loop {
            let n = match reader.read(&mut buffer) {
                Ok(0) => break Ok(()),
                Ok(n) => n,
                Err(e) if e.kind() == std::io::ErrorKind::Interrupted => continue,
                Err(e) if is_timeout(&e) => {
                    break Err(Error::fetch(
                        url,
                        format!(
                            "the server went silent for {} after {written} bytes ({TIMEOUT_VARIABLE} sets the wait); {}",
                            seconds(self.timeout),
                            kept(written)
                        ),
                    ));
                }
                Err(e) => {
                    break Err(Error::fetch(
                        url,
                        format!("the connection broke after {written} bytes ({e}); {}", kept(written)),
                    ));
                }
            };
            if let Err(e) = out.write_all(&buffer[..n]) {
                break Err(Error::io(partial, e));
            }
            written += n as u64;
            report(written, false);
        };
        report(written, true);
        result?;
        out.sync_all().map_err(|e| Error::io(partial, e))?;
        match total {
            Some(total) if written != total => Err(Error::fetch(
                url,
                format!("the server closed the connection after {written} of {total} bytes; {}", kept(written)),
            )),
            _ => Ok(Saved::Complete),
        }
    }

    /// Downloads `url` into `partial`, continuing from the bytes it already has (a server that
    /// ignores the range sends the whole file, which then replaces them). Redirects are followed.
    pub(crate) fn download(&self, url: &str, partial: &Path, file: &str, options: &FetchOptions) -> Result<()> {
        for _ in 0..2 {
            let have = std::fs::metadata(partial).map(|m| m.len()).unwrap_or(0);
            let response = self.get(url, have, true)?;
            if self.save(response, url, partial, have, file, options)? == Saved::Complete {
                return Ok(());
            }
        }
        Err(Error::fetch(url, "the server refused the range of a file it had just sent from its start"))
    }
}

/// `bytes START-END/TOTAL`: the start and the total, where stated.
fn content_range(header: Option<&str>) -> (Option<u64>, Option<u64>) {
    let Some(range) = header.and_then(|h| h.trim().strip_prefix("bytes ")) else { return (None, None) };
    let (span, total) = range.split_once('/').unwrap_or((range, "*"));
    let start = span.split_once('-').and_then(|(s, _)| s.trim().parse().ok());
    (start, total.trim().parse().ok())
}

fn is_timeout(e: &std::io::Error) -> bool {
    matches!(e.kind(), std::io::ErrorKind::TimedOut | std::io::ErrorKind::WouldBlock)
}

fn seconds(d: Duration) -> String {
    format!("{} s", d.as_secs_f64())
}

/// What a failed attempt leaves for the next one.
fn kept(bytes: u64) -> String {
    if bytes == 0 {
        "nothing arrived: fetch again to retry".to_string()
    } else {
        format!("the {bytes} bytes that arrived are kept: fetch again to resume")
    }
}

/// `location` (a redirect's target) as an absolute address, relative ones against `base`.
pub(crate) fn join(base: &str, location: &str) -> String {
    if location.contains("://") {
        return location.to_string();
    }
    let scheme_end = base.find("://").map_or(0, |i| i + 3);
    let origin_end = base[scheme_end..].find('/').map_or(base.len(), |i| scheme_end + i);
    if location.starts_with('/') {
        format!("{}{location}", &base[..origin_end])
    } else {
        let path = base.split(['?', '#']).next().unwrap_or(base);
        let dir_end = path.rfind('/').filter(|&i| i >= origin_end).map_or(path.len(), |i| i + 1);
        let dir = &path[..dir_end];
        if dir.ends_with('/') { format!("{dir}{location}") } else { format!("{dir}/{location}") }
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn redirect_targets_become_absolute() {
        assert_eq!(join("http://h:1/a/b?x=1", "https://cdn/x"), "https://cdn/x");
        assert_eq!(join("http://h:1/a/b?x=1", "/c/d"), "http://h:1/c/d");
        assert_eq!(join("http://h:1/a/b?x=1", "c"), "http://h:1/a/c");
        assert_eq!(join("http://h:1", "c"), "http://h:1/c");
    }

    #[test]
    fn content_ranges_give_start_and_total() {
        assert_eq!(content_range(Some("bytes 10-99/100")), (Some(10), Some(100)));
        assert_eq!(content_range(Some("bytes 10-99/*")), (Some(10), None));
        assert_eq!(content_range(None), (None, None));
    }
}
