//! Whole training steps timed as a run pays for them (`dgstereo bench --train`): the steps
//! `dgstereo train` makes, after a warm-up, with the trainer's own split of each
//! ([`crate::step_timing::StepSeconds`]) and the forward's counted work.

use std::time::Instant;

use dgstereo_collective::Collective;
use dgstereo_core::Result;
use dgstereo_kernels::count_work;

use crate::batch::TensorBatch;
use crate::step_timing::StepSeconds;
use crate::trainer::Trainer;

/// Steps timed by [`time_steps`].
#[derive(Debug, Clone, PartialEq)]
pub struct StepTiming {
    /// Each timed step's wall-clock seconds and its parts (the warm-up's left out).
    pub steps: Vec<(f64, StepSeconds)>,
    /// Multiply-accumulates of the forward pass in one step, counted by its operations
    /// ([`dgstereo_kernels::count_work`]: direct convolutions and matrix products).
    pub macs: u64,
}

/// Times `runs` steps of `trainer` on `batch` with every rank of `ranks`, after `warmup` untimed
/// ones: the call `dgstereo train` makes ([`Trainer::step_on_among`]: forward, loss, backward,
/// clipping, the optimiser), without loading data, with the trainer's own split of each step
/// ([`Trainer::last_step_seconds`]).
///
/// # Errors
/// A step's error.
pub fn time_steps(
    trainer: &mut Trainer,
    batch: &TensorBatch,
    ranks: &dyn Collective,
    warmup: usize,
    runs: usize,
) -> Result<StepTiming> {
    let mut macs = 0;
    let mut step = |trainer: &mut Trainer| -> Result<(f64, StepSeconds)> {
        let start = Instant::now();
        let (stepped, work) = count_work(|| trainer.step_on_among(batch, ranks, None));
        stepped?;
        macs = work.macs;
        Ok((start.elapsed().as_secs_f64(), trainer.last_step_seconds()))
    };
    for _ in 0..warmup {
        step(trainer)?;
    }
    let steps = (0..runs).map(|_| step(trainer)).collect::<Result<Vec<_>>>()?;
    Ok(StepTiming { steps, macs })
}
