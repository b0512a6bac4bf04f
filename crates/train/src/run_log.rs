//! A run's `log.jsonl` as a resumed run finds it: the lines of the steps its checkpoint holds,
//! the curves they draw, and the last training report and validation they record.
//!
//! A resumed run redoes the steps after its checkpoint, so their lines are dropped; the rest
//! give the run's summary its values where the resumed run logs nothing more (a run whose
//! checkpoint is its last step), so `summary.json` never loses what the log holds.

use std::path::Path;

use dgstereo_core::{Error, Result};
use dgstereo_eval::Metrics;

use crate::plot::Curves;
use crate::trainer::StepReport;

/// What the log of a run holds up to a step.
#[derive(Debug, Default)]
pub struct RunLog {
    /// The kept lines, each ending in a newline.
    pub kept: String,
    /// Whether lines after the step were dropped.
    pub dropped: bool,
    /// The training and validation curves of the kept lines.
    pub curves: Curves,
    /// The last kept training report.
    pub last: Option<StepReport>,
    /// The last kept validation's metrics.
    pub validation: Option<Metrics>,
}

/// Reads the log at `path` up to completed step `step` (no file: an empty log). Lines that are
/// not JSON are dropped.
pub fn read_log(path: &Path, step: usize) -> Result<RunLog> {
    let mut log = RunLog::default();
    if !path.is_file() {
        return Ok(log);
    }
    let text = std::fs::read_to_string(path).map_err(|e| Error::io(path, e))?;
    for line in text.lines() {
        let Ok(v) = serde_json::from_str::<serde_json::Value>(line) else {
            log.dropped = true;
            continue;
        };
        let s = v["step"].as_u64().unwrap_or(u64::MAX) as usize;
        if s > step {
            log.dropped = true;
            continue;
        }
        log.kept.push_str(line);
        log.kept.push('\n');
        let f = |k: &str| v[k].as_f64().unwrap_or(f64::NAN);
        match v["kind"].as_str() {
            Some("train") => {
                log.curves.train_loss.push((s as f64, f("loss")));
                log.curves.train_epe.push((s as f64, f("epe")));
                log.last = Some(StepReport {
                    step: s.saturating_sub(1),
                    loss: f("loss"),
                    epe: f("epe"),
                    bad3: f("bad3"),
                    lr: f("lr"),
                    grad_norm: f("grad_norm"),
                });
            }
            Some("validation") => {
                log.curves.valid_epe.push((s as f64, f("epe")));
                log.validation = Metrics::from_json(&v["metrics"]).or(log.validation);
            }
            _ => {}
        }
    }
    Ok(log)
}

/// Keeps the lines of completed steps `<= step` of the log at `path` (rewriting it only when a
/// line goes) and returns what they hold.
pub fn truncate_log(path: &Path, step: usize) -> Result<RunLog> {
    let log = read_log(path, step)?;
    if log.dropped {
        crate::checkpoint::write_atomic(path, log.kept.as_bytes())?;
    }
    Ok(log)
}
