//! The one-cycle learning-rate schedule of RAFT-Stereo.
//!
//! PyTorch's `OneCycleLR(max_lr, total_steps, pct_start, cycle_momentum=False,
//! anneal_strategy='linear')` with its defaults `div_factor = 25`, `final_div_factor = 1e4` and
//! two phases: from `max_lr / 25` up to `max_lr` at step `pct_start · total_steps − 1`, then down
//! to `max_lr / 25 / 1e4` at step `total_steps − 1`. The schedule is a pure function of the step
//! index, so its position in a checkpoint is the step itself and resuming cannot drift.

use dgstereo_core::{Error, Result};
use serde::{Deserialize, Serialize};

/// PyTorch's `div_factor` default: the first learning rate is `max_lr / 25`.
pub const DIV_FACTOR: f64 = 25.0;
/// PyTorch's `final_div_factor` default: the last learning rate is the first one `/ 1e4`.
pub const FINAL_DIV_FACTOR: f64 = 1e4;

/// The one-cycle schedule (linear annealing, no momentum cycling).
#[derive(Debug, Clone, Copy, PartialEq, Serialize, Deserialize)]
pub struct OneCycleLr {
    /// Peak learning rate.
    pub max_lr: f64,
    /// Number of steps the schedule is defined for.
    pub total_steps: usize,
    /// Fraction of the steps spent increasing the learning rate.
    pub pct_start: f64,
}

impl OneCycleLr {
    /// A schedule; fails when `total_steps` is 0 or `pct_start` is outside `(0, 1)`.
    pub fn new(max_lr: f64, total_steps: usize, pct_start: f64) -> Result<Self> {
        if total_steps == 0 {
            return Err(Error::config("total_steps", "must be at least 1 (one-cycle schedule)"));
        }
        if !(pct_start > 0.0 && pct_start < 1.0) {
            return Err(Error::config("pct_start", format!("{pct_start} must lie in (0, 1) (one-cycle schedule)")));
        }
        Ok(Self { max_lr, total_steps, pct_start })
    }

    /// The first learning rate, `max_lr / div_factor`.
    pub fn initial_lr(&self) -> f64 {
        self.max_lr / DIV_FACTOR
    }

    /// The last learning rate, `initial_lr / final_div_factor`.
    pub fn min_lr(&self) -> f64 {
        self.initial_lr() / FINAL_DIV_FACTOR
    }

    /// The learning rate of optimiser step `step` (0-based: the first `optimizer.step()` uses
    /// `lr(0)`, as PyTorch's scheduler before its first `scheduler.step()`).
    ///
    /// Steps past `total_steps - 1` keep the last value (PyTorch raises instead). When a phase
    /// has zero length (tiny `total_steps`), its end value is used.
    pub fn lr(&self, step: usize) -> f64 {
        let step = step.min(self.total_steps - 1) as f64;
        let warmup_end = self.pct_start * self.total_steps as f64 - 1.0;
        let phases =
            [(warmup_end, self.initial_lr(), self.max_lr), (self.total_steps as f64 - 1.0, self.max_lr, self.min_lr())];
        let mut start = 0.0;
        for (i, &(end, start_lr, end_lr)) in phases.iter().enumerate() {
            if step <= end || i == phases.len() - 1 {
                let span = end - start;
                let pct = if span == 0.0 { 1.0 } else { (step - start) / span };
                return (end_lr - start_lr) * pct + start_lr;
            }
            start = end;
        }
        unreachable!("the last phase always returns")
    }
}
