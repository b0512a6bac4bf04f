//! One training step shared by the ranks of a data-parallel run.
//!
//! Design decision: the run is defined by its global batch, whatever the number of ranks. Rank
//! `r` of `N` computes elements `r, r + N, ...` of the step's batch, each the same pair with the
//! same augmentation as in one process ([`crate::batch`] draws an element from `(seed, step,
//! element)` alone). The loss is split into a sum and a count that add over images
//! ([`dgstereo_loss::LossTerms`]): the ranks exchange their counts, each takes the gradient of its
//! own sum over the batch's total count, and the gradients summed over the ranks
//! ([`crate::gradient_exchange`]) are the whole batch's. Clipping and AdamW then see the same
//! gradient on every rank and keep the ranks' weights equal without sending them again.

use std::time::Instant;

use burn::module::Module;
use burn::optim::GradientsParams;
use dgstereo_collective::{Collective, agree};
use dgstereo_core::{Error, Result};
use dgstereo_eval::MetricSums;
use dgstereo_loss::{DisparityLoss, LossTerms, Predictions};
use dgstereo_model::TrainingDisparities;
use rayon::prelude::*;

use crate::batch::{TensorBatch, to_tensors};
use crate::ema::Ema;
use crate::gradient_exchange::{WeightCheck, share_weights, sum_gradients};
use crate::step_timing::StepSeconds;
use crate::trainer::{StepInternals, StepReport, Trainer, batch_metrics, stopping_at};

/// The elements of a global batch of `batch_size` that rank `rank` of `size` computes.
pub fn rank_elements(batch_size: usize, rank: usize, size: usize) -> Vec<usize> {
    (rank..batch_size).step_by(size.max(1)).collect()
}

/// Checks that a global batch divides among the ranks.
pub fn check_batch_divides(batch_size: usize, ranks: usize) -> Result<()> {
    if ranks == 0 || !batch_size.is_multiple_of(ranks) {
        return Err(Error::config(
            "train.batch_size",
            format!(
                "{batch_size} does not divide among {ranks} ranks: the batch is the global batch, \
                 so it must be a multiple of the number of ranks"
            ),
        ));
    }
    Ok(())
}

/// What one rank computed of a step before the exchange.
struct Shard {
    predictions: TrainingDisparities,
    loss_sum: burn::tensor::Tensor<1>,
    /// `[count, loss sum, valid pixels, absolute error, bad x5, d1]`.
    numbers: [f64; SHARD_NUMBERS],
}

const SHARD_NUMBERS: usize = 10;

fn sums_to_numbers(count: f64, loss: f64, s: &MetricSums) -> [f64; SHARD_NUMBERS] {
    let b = s.bad.map(|c| c as f64);
    [count, loss, s.valid_pixels as f64, s.abs_error, b[0], b[1], b[2], b[3], b[4], s.d1 as f64]
}

fn numbers_to_sums(n: &[f64]) -> MetricSums {
    MetricSums {
        valid_pixels: n[2] as u64,
        abs_error: n[3],
        bad: [n[4] as u64, n[5] as u64, n[6] as u64, n[7] as u64, n[8] as u64],
        d1: n[9] as u64,
    }
}

impl Trainer {
    /// Takes this rank's part of one step of a data-parallel run: its elements of the global
    /// batch, prior, forward, its loss terms; then the ranks exchange counts and gradients, and
    /// every rank clips and updates identically. `observe` sees the gradient summed over the
    /// ranks (the whole batch's), before clipping. With [`dgstereo_collective::SingleProcess`]
    /// this is [`Trainer::step`]: the one process's elements are the whole batch.
    ///
    /// A rank that cannot read a sample or computes a non-finite loss fails the step on every
    /// rank, with an error naming it; the weights stay those of the completed steps.
    pub fn step_among(
        &mut self,
        ranks: &dyn Collective,
        observe: Option<&mut dyn FnMut(StepInternals<'_>)>,
    ) -> Result<StepReport> {
        let batch = agree(ranks, self.rank_batch(ranks))?;
        self.step_on_among(&batch, ranks, observe)
    }

    /// This rank's elements of the current step's global batch, on the autodiff device.
    fn rank_batch(&self, ranks: &dyn Collective) -> Result<TensorBatch> {
        let elements = rank_elements(self.parts.train.batch_size, ranks.rank(), ranks.size());
        let (data, step) = (&self.data, self.step);
        let pairs = elements.into_par_iter().map(|e| data.pair(step, e)).collect::<Result<Vec<_>>>()?;
        to_tensors(&pairs, &self.autodiff)
    }

    /// Takes one step on `batch`, this rank's part of the global batch, as
    /// [`Trainer::step_among`] does after building it: the one body of every training step
    /// ([`Trainer::step_on`] is this with [`dgstereo_collective::SingleProcess`];
    /// `dgstereo bench --train` under `mpirun` times steps on random parts). The non-finite
    /// loss check, the metrics, the timing and the `observe` hook live here alone.
    pub fn step_on_among(
        &mut self,
        batch: &TensorBatch,
        ranks: &dyn Collective,
        observe: Option<&mut dyn FnMut(StepInternals<'_>)>,
    ) -> Result<StepReport> {
        let started = Instant::now();
        let shard = agree(ranks, self.shard(batch, ranks))?;
        let gathered = ranks.all_gather(&shard.numbers);
        let mut total = [0.0; SHARD_NUMBERS];
        for numbers in gathered.chunks(SHARD_NUMBERS) {
            for (t, n) in total.iter_mut().zip(numbers) {
                *t += n;
            }
        }
        let normalizer = total[0].max(1.0);
        let loss_value = total[1] / normalizer;
        let sums = numbers_to_sums(&total);
        let forward_done = Instant::now();
        let loss = shard.loss_sum.div_scalar(normalizer);
        let grads = GradientsParams::from_grads(loss.backward(), &self.model);
        let backward_done = Instant::now();
        let (grads, exchange) = sum_gradients(&self.model, grads, ranks);
        if let Some(observe) = observe {
            let predictions = &shard.predictions;
            let (initial, predictions) = (predictions.initial.as_ref(), predictions.iterations.as_slice());
            observe(StepInternals { model: &self.model, predictions, initial, grads: &grads });
        }
        self.last_exchange_bytes = exchange.bytes;
        let seconds = StepSeconds {
            forward: (forward_done - started).as_secs_f64(),
            backward: (backward_done - forward_done).as_secs_f64(),
            all_reduce: exchange.seconds,
            optimizer: 0.0,
        };
        self.apply_gradients(grads, loss_value, &sums, seconds)
    }

    /// This rank's part of the current step: forward, loss terms and metric sums.
    ///
    /// The loss is split into a sum and a count that add over the ranks ([`LossTerms`]). A world
    /// of one takes the loss itself as its sum over a count of 1: the batch's mean as the loss
    /// crate (and the official code) computes it, which the split form equals only up to
    /// rounding, so a single process trains bit for bit as the recipe's loss says.
    fn shard(&self, batch: &TensorBatch, ranks: &dyn Collective) -> Result<Shard> {
        let step = self.step;
        let predictions = self.predictions(batch)?;
        let read = Predictions { iterations: &predictions.iterations, initial: predictions.initial.as_ref() };
        let terms = if ranks.size() == 1 {
            LossTerms { sum: self.parts.loss.loss(read, &batch.target)?, count: 1.0 }
        } else {
            self.parts.loss.terms(read, &batch.target)?
        };
        let loss_sum = f64::from(dgstereo_core::tensor::to_vec(terms.sum.clone().detach())[0]);
        if !loss_sum.is_finite() {
            let what = format!("the loss ({loss_sum}; pairs: {})", batch.names.join(", "));
            return Err(Error::not_finite(what).context(stopping_at(step)));
        }
        let last = predictions.iterations.last().expect("at least one iteration").clone().detach();
        let sums = batch_metrics(last, batch.target.disparity_bilinear.clone(), batch.target.valid.clone())?;
        Ok(Shard { predictions, loss_sum: terms.sum, numbers: sums_to_numbers(terms.count, loss_sum, &sums) })
    }

    /// Gives this rank rank 0's weights ([`share_weights`]). A fresh run's moving average
    /// restarts at them; the caller decides whether a difference is an error (a resumed run's
    /// ranks must have loaded the same checkpoint).
    pub fn share_weights(&mut self, ranks: &dyn Collective) -> Result<WeightCheck> {
        let (model, check) = share_weights(self.model.clone(), ranks)?;
        if check.first_difference.is_some() {
            self.model = model;
            if let Some(ema) = &self.ema {
                self.ema = Some(Ema::new(ema.decay(), self.model.valid()));
            }
        }
        Ok(check)
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn ranks_take_interleaved_elements_that_cover_the_batch_once() {
        assert_eq!(rank_elements(6, 0, 3), vec![0, 3]);
        assert_eq!(rank_elements(6, 2, 3), vec![2, 5]);
        let mut all: Vec<usize> = (0..4).flat_map(|r| rank_elements(8, r, 4)).collect();
        all.sort_unstable();
        assert_eq!(all, (0..8).collect::<Vec<_>>());
        assert_eq!(rank_elements(2, 0, 1), vec![0, 1]);
    }

    #[test]
    fn a_batch_that_does_not_divide_names_the_key_and_the_ranks() {
        check_batch_divides(8, 4).unwrap();
        let e = check_batch_divides(6, 4).unwrap_err().to_string();
        assert!(e.contains("train.batch_size") && e.contains("6") && e.contains("4 ranks"), "{e}");
    }

    #[test]
    fn shard_numbers_round_trip_the_metric_sums() {
        let sums = MetricSums { valid_pixels: 7, abs_error: 2.5, bad: [5, 4, 3, 2, 1], d1: 1 };
        let n = sums_to_numbers(3.0, 1.25, &sums);
        assert_eq!((n[0], n[1]), (3.0, 1.25));
        assert_eq!(numbers_to_sums(&n), sums);
    }
}
