//! What a training run reports as it goes, for whoever shows it.
//!
//! Design decision: the library draws nothing. [`crate::run::train_among`] hands each
//! [`Progress`] event to the [`ProgressObserver`] of its [`RunOptions`](crate::RunOptions) (rank
//! 0's alone); the binary renders them as a progress bar and keeps the position a second signal
//! reports, a test may collect them, and a run without an observer reports to no one.

use std::path::PathBuf;
use std::sync::Arc;

use dgstereo_eval::Metrics;

use crate::trainer::StepReport;

/// One event of a run. In order: `Started`, then per step `Step` (followed by `Validated` and
/// `Checkpoint` where the step validates or checkpoints), then `Ended`.
#[derive(Debug, Clone, PartialEq)]
pub enum Progress {
    /// The loop starts after `done` completed steps (a resumed run's checkpoint; 0 for a new
    /// run) of `steps`.
    Started {
        /// Steps already completed.
        done: usize,
        /// The run's configured steps.
        steps: usize,
    },
    /// A step completed; `done` steps are complete. `logged` is the step's report and the steps
    /// per second since the previously logged step, when this step was logged.
    Step {
        /// Steps complete.
        done: usize,
        /// The logged report and rate.
        logged: Option<(StepReport, f64)>,
    },
    /// A validation after `done` steps; `ema` when it scored the moving average of the weights.
    Validated {
        /// Steps complete.
        done: usize,
        /// The validation set's metrics.
        metrics: Metrics,
        /// Whether the moving average was scored.
        ema: bool,
    },
    /// A checkpoint of `done` steps was written to `path`.
    Checkpoint {
        /// The checkpoint's step.
        done: usize,
        /// Its file.
        path: PathBuf,
    },
    /// The loop ended: `finished` when every configured step is done, else it stopped (a
    /// signal, `stop_after`) or failed.
    Ended {
        /// Whether the run is complete.
        finished: bool,
    },
}

/// Receives a run's [`Progress`] events.
#[derive(Clone)]
pub struct ProgressObserver(Arc<dyn Fn(&Progress) + Send + Sync>);

impl ProgressObserver {
    /// An observer calling `report` with each event.
    pub fn new(report: impl Fn(&Progress) + Send + Sync + 'static) -> Self {
        Self(Arc::new(report))
    }

    /// Hands `event` to the observer.
    pub fn report(&self, event: &Progress) {
        (self.0)(event);
    }
}

impl std::fmt::Debug for ProgressObserver {
    fn fmt(&self, f: &mut std::fmt::Formatter<'_>) -> std::fmt::Result {
        f.write_str("ProgressObserver")
    }
}
