//! A training run's progress on the terminal: the train crate's [`Progress`] events drawn as an
//! indicatif bar (hidden with `--quiet`, or when standard error is not a terminal), validation
//! lines above it, and the run's position kept for a stop at once ([`RunPosition`]).

use std::sync::Arc;

use dgstereo_train::{Progress, ProgressObserver};
use indicatif::{ProgressBar, ProgressStyle};

use dgstereo_signals::RunPosition;

/// The observer of one run: draws its bar when `show`, and keeps `position` either way.
pub fn observer(show: bool, position: Arc<RunPosition>) -> ProgressObserver {
    let bar = if show { ProgressBar::new(0) } else { ProgressBar::hidden() };
    bar.set_style(
        ProgressStyle::with_template("{spinner} {pos}/{len} [{elapsed_precise} < {eta_precise}] {wide_bar} {msg}")
            .expect("a valid template"),
    );
    ProgressObserver::new(move |event| match event {
        Progress::Started { done, steps } => {
            bar.set_length(*steps as u64);
            bar.set_position(*done as u64);
            bar.reset_eta();
            position.started(*done);
        }
        Progress::Step { done, logged } => {
            bar.set_position(*done as u64);
            if let Some((r, rate)) = logged {
                bar.set_message(format!(
                    "loss {:.3} epe {:.3} bad3 {:.1}% lr {:.2e} {rate:.2} steps/s",
                    r.loss, r.epe, r.bad3, r.lr
                ));
            }
            position.stepped(*done);
        }
        Progress::Validated { done, metrics, ema } => {
            let weights = if *ema { " (EMA weights)" } else { "" };
            bar.println(format!(
                "validation{weights} at step {done}: EPE {:.3} px, bad-3 {:.2} %",
                metrics.epe, metrics.bad_3
            ));
        }
        Progress::Checkpoint { done, .. } => position.checkpointed(*done),
        Progress::Ended { finished } => {
            if *finished {
                bar.finish();
            } else {
                bar.abandon();
            }
            position.ended();
        }
    })
}
