//! The training loop: steps, log, progress events, validation, plot, checkpoints.
//!
//! Output folder layout:
//! - `config.toml`: the resolved experiment;
//! - `log.jsonl`: one JSON object per logged step (`kind = "train"`: step, loss, epe, bad3, lr,
//!   steps_per_s, grad_norm) and per validation (`kind = "validation"`: step and the eval
//!   crate's metrics), `step` counting completed steps; with `train.ema_decay` validation
//!   scores the moving average of the weights and its lines say `"weights": "ema"`;
//! - `curves.png`: training and validation curves, rewritten at every validation;
//! - `checkpoints/step-NNNNNNNN.safetensors`: the newest `keep_checkpoints` training checkpoints;
//! - `model.safetensors` and `summary.json`: the final weights (loadable by `dgstereo infer`; the
//!   moving average with `train.ema_decay`) and the final metrics, written when the run
//!   completes; their presence marks a finished run.
//!
//! Resuming ([`RunOptions::resume`]) continues from the newest checkpoint, starts a folder that
//! holds none, and leaves a finished run as it is (after checking that it is the same run). The
//! loop reports its progress as [`Progress`] events to the options' observer and draws nothing.

use std::io::Write;
use std::path::{Path, PathBuf};
use std::sync::Arc;
use std::sync::atomic::{AtomicBool, Ordering};
use std::time::Instant;

use burn::tensor::Device;
use dgstereo_collective::{Collective, SingleProcess, agree, writes_files};
use dgstereo_core::{Error, Result};
use serde_json::json;

use crate::checkpoint::{list_checkpoints, load_checkpoint, save_checkpoint};
use crate::data_parallel::check_batch_divides;
use crate::plot::write_plot;
use crate::progress::{Progress, ProgressObserver};
use crate::run_identity::{another_run, folder_differences, training_differences};
use crate::run_log::{read_log, truncate_log};
use crate::trainer::{StepReport, TrainParts, Trainer};
use crate::validate::ValidationSet;

/// How to run.
#[derive(Debug, Clone)]
pub struct RunOptions {
    /// The output folder.
    pub out: PathBuf,
    /// Continue from the newest checkpoint in `out`; with none, start the run there; a finished
    /// run (the same run, else an error) is left as it is.
    pub resume: bool,
    /// Stop (with a checkpoint) after this many completed steps, without changing the schedule.
    pub stop_after: Option<usize>,
    /// Receives the run's [`Progress`] (rank 0's); the library draws nothing itself.
    pub progress: Option<ProgressObserver>,
    /// Shown what the user should know before the run goes on (where a resumed run resumes,
    /// weights that kept their initialisation): the binary prints them; the library never does.
    pub notice: fn(&str),
    /// Set (by a signal handler) to end the run after the current step, with a checkpoint.
    pub stop: Option<Arc<AtomicBool>>,
}

/// What a run returns.
#[derive(Debug, Clone)]
pub struct RunSummary {
    /// Completed steps.
    pub steps: usize,
    /// The last logged training step.
    pub last: Option<StepReport>,
    /// The last validation's metrics.
    pub validation: Option<dgstereo_eval::Metrics>,
    /// The newest checkpoint.
    pub checkpoint: Option<PathBuf>,
    /// Whether all configured steps are done.
    pub finished: bool,
    /// Whether the run ended early because [`RunOptions::stop`] was set (its checkpoint holds
    /// the last completed step).
    pub stopped: bool,
    /// Whether the folder held this run finished, and a resume left it as it was.
    pub untouched: bool,
}

/// The checkpoint folder of a run folder.
pub fn checkpoint_dir(out: &Path) -> PathBuf {
    out.join("checkpoints")
}

/// Whether `out` holds a finished run (`summary.json` and `model.safetensors`).
pub fn is_finished(out: &Path) -> bool {
    out.join("summary.json").is_file() && out.join("model.safetensors").is_file()
}

fn append_line(path: &Path, value: &serde_json::Value) -> Result<()> {
    let mut f = std::fs::OpenOptions::new().create(true).append(true).open(path).map_err(|e| Error::io(path, e))?;
    writeln!(f, "{value}").map_err(|e| Error::io(path, e))
}

fn metrics_json(m: &dgstereo_eval::Metrics) -> serde_json::Value {
    m.to_json()
}

/// Trains `parts` on `device` into `options.out`, in this process alone.
///
/// A fresh run refuses a folder that already holds checkpoints (use `resume`). NaN or inf in
/// the loss or gradients stops the run with an error; the checkpoints already written stay.
pub fn train(parts: TrainParts, device: &Device, options: &RunOptions) -> Result<RunSummary> {
    train_among(parts, device, options, &SingleProcess)
}

/// Trains `parts` with every rank of `ranks`, each on its own `device`, into `options.out`.
///
/// `train.batch_size` is the global batch and must divide by the number of ranks
/// ([`Trainer::step_among`]). Every rank starts from rank 0's weights; a resumed run's ranks
/// must read the same checkpoint (the output folder is one folder every rank sees). Rank 0
/// alone writes the log, plot, validation, checkpoints and final model. A step that fails on
/// any rank fails on all of them with an error naming the rank; in one process this is
/// [`train`].
pub fn train_among(
    parts: TrainParts,
    device: &Device,
    options: &RunOptions,
    ranks: &dyn Collective,
) -> Result<RunSummary> {
    check_batch_divides(parts.train.batch_size, ranks.size())?;
    let writes = writes_files(ranks);
    let out = &options.out;
    let ckpt_dir = checkpoint_dir(out);
    let resumed_from = |path: &Path| -> Result<Trainer> {
        let stored = crate::checkpoint::read_metadata(path)?.remove("config").unwrap_or_default();
        let differences =
            if stored.is_empty() { Vec::new() } else { training_differences(&stored, &parts.resolved_toml)? };
        if !differences.is_empty() {
            return Err(another_run(out, &differences));
        }
        let trainer = load_checkpoint(parts.clone(), path, device)?;
        if writes {
            (options.notice)(&format!("resuming at step {} from {}", trainer.step, path.display()));
        }
        Ok(trainer)
    };
    if options.resume && is_finished(out) {
        return agree(ranks, finished_run(out, &parts));
    }
    let setup = || -> Result<(Trainer, Option<PathBuf>)> {
        if writes {
            std::fs::create_dir_all(&ckpt_dir).map_err(|e| Error::io(&ckpt_dir, e))?;
        }
        let existing = list_checkpoints(&ckpt_dir)?;
        if let Some((_, path)) = existing.last().filter(|_| options.resume) {
            return Ok((resumed_from(path)?, Some(path.clone())));
        }
        if options.resume && writes {
            (options.notice)(&format!("{} holds no checkpoint: starting the run", ckpt_dir.display()));
        }
        if let Some((_, p)) = existing.last().filter(|_| writes) {
            return Err(Error::config(
                "out",
                format!(
                    "{} already holds checkpoints ({}): resume the run to continue, or choose another output folder",
                    ckpt_dir.display(),
                    p.display()
                ),
            ));
        }
        Ok((Trainer::new(parts.clone(), device)?, None))
    };
    let (mut trainer, resumed_checkpoint) = agree(ranks, setup())?;
    if ranks.size() > 1 {
        start_from_rank_zero(&mut trainer, ranks, options)?;
    }
    for notice in trainer.notices.drain(..).filter(|_| writes) {
        (options.notice)(&notice);
    }
    if !writes {
        return follow(trainer, ranks, options);
    }
    let config_path = out.join("config.toml");
    crate::checkpoint::write_atomic(&config_path, trainer.parts.resolved_toml.as_bytes())?;
    let log_path = out.join("log.jsonl");
    let plot_path = out.join("curves.png");
    let log = truncate_log(&log_path, trainer.step)?;
    let mut curves = log.curves;
    let validation = ValidationSet::new(&trainer.parts.data.validation)?;

    let t = trainer.parts.train.clone();
    let end = options.stop_after.map_or(t.steps, |s| s.min(t.steps));
    let report = |event: Progress| {
        if let Some(observer) = &options.progress {
            observer.report(&event);
        }
    };
    report(Progress::Started { done: trainer.step, steps: t.steps });

    // What the kept log records stands until the resumed run logs anew.
    let mut summary = RunSummary {
        steps: trainer.step,
        last: log.last,
        validation: log.validation,
        checkpoint: resumed_checkpoint,
        finished: false,
        stopped: false,
        untouched: false,
    };
    let mut interval_start = Instant::now();
    let mut interval_steps = 0usize;
    while trainer.step < end {
        let step_report = match trainer.step_among(ranks, None) {
            Ok(r) => r,
            Err(e) => {
                report(Progress::Ended { finished: false });
                let _ =
                    append_line(&log_path, &json!({"kind": "error", "step": trainer.step, "message": e.to_string()}));
                let kept = summary.checkpoint.as_ref().map_or("none yet".to_string(), |p| p.display().to_string());
                return Err(e.context(format!("training stopped (last good checkpoint: {kept})")));
            }
        };
        interval_steps += 1;
        let done = trainer.step;
        let mut logged = None;
        if done % t.log_every == 0 || done == end {
            let rate = interval_steps as f64 / interval_start.elapsed().as_secs_f64().max(1e-9);
            let r = &step_report;
            let mut line = json!({"kind": "train", "step": done, "loss": r.loss, "epe": r.epe,
                                  "bad3": r.bad3, "lr": r.lr, "steps_per_s": rate, "grad_norm": r.grad_norm});
            if ranks.size() > 1 {
                line["world_size"] = json!(ranks.size());
                line["all_reduce_s"] = json!(trainer.last_step_seconds().all_reduce);
            }
            append_line(&log_path, &line)?;
            curves.train_loss.push((done as f64, r.loss));
            curves.train_epe.push((done as f64, r.epe));
            summary.last = Some(step_report);
            logged = Some((step_report, rate));
            interval_start = Instant::now();
            interval_steps = 0;
        }
        report(Progress::Step { done, logged });
        let validate_now =
            !validation.is_empty() && ((t.validate_every > 0 && done % t.validate_every == 0) || done == t.steps);
        if validate_now {
            let m = validation.evaluate(
                &trainer.shipped_model(),
                &trainer.parts.model,
                trainer.prior(),
                &trainer.device,
            )?;
            let mut line =
                json!({"kind": "validation", "step": done, "epe": m.epe, "bad3": m.bad_3, "metrics": metrics_json(&m)});
            if trainer.ema.is_some() {
                line["weights"] = json!("ema");
            }
            append_line(&log_path, &line)?;
            report(Progress::Validated { done, metrics: m, ema: trainer.ema.is_some() });
            curves.valid_epe.push((done as f64, m.epe));
            write_plot(&curves, &plot_path)?;
            summary.validation = Some(m);
        }
        let stop = stop_requested(options, ranks) && done < end;
        if (t.checkpoint_every > 0 && done % t.checkpoint_every == 0) || done == end || stop {
            let path = save_checkpoint(&trainer, &ckpt_dir, t.keep_checkpoints)?;
            report(Progress::Checkpoint { done, path: path.clone() });
            summary.checkpoint = Some(path);
        }
        if stop {
            report(Progress::Ended { finished: false });
            summary.steps = trainer.step;
            summary.stopped = true;
            return Ok(summary);
        }
    }
    summary.steps = trainer.step;
    summary.finished = trainer.step >= t.steps;
    report(Progress::Ended { finished: summary.finished });
    if summary.finished {
        if validation.is_empty() {
            write_plot(&curves, &plot_path)?;
        }
        let model_config =
            serde_json::to_string(&trainer.parts.model).map_err(|e| Error::encode("the model configuration", e))?;
        let ema_decay = trainer.ema.as_ref().map(|e| e.decay().to_string());
        let mut metadata = vec![("model_config", model_config.as_str()), ("config", &trainer.parts.resolved_toml)];
        metadata.extend(ema_decay.as_deref().map(|d| ("ema_decay", d)));
        dgstereo_model::checkpoint::save_safetensors(
            &trainer.shipped_model(),
            &out.join("model.safetensors"),
            &metadata,
        )?;
        let last = summary.last.as_ref().map(|r| json!({"loss": r.loss, "epe": r.epe, "bad3": r.bad3}));
        let mut summary_json = json!({
            "name": trainer.parts.name, "steps": trainer.step, "last_train": last,
            "validation": summary.validation.as_ref().map(metrics_json),
        });
        if let Some(ema) = &trainer.ema {
            summary_json["ema_decay"] = json!(ema.decay());
        }
        crate::checkpoint::write_atomic(&out.join("summary.json"), format!("{summary_json:#}\n").as_bytes())?;
    }
    Ok(summary)
}

/// The summary of the finished run in `out`, which a resume leaves as it is: the same run (its
/// `config.toml` trains what `parts` trains, else the error says which keys differ), its steps
/// and what its log records.
fn finished_run(out: &Path, parts: &TrainParts) -> Result<RunSummary> {
    let differences = folder_differences(out, &parts.resolved_toml)?;
    if !differences.is_empty() {
        return Err(another_run(out, &differences));
    }
    let log = read_log(&out.join("log.jsonl"), usize::MAX)?;
    let summary_path = out.join("summary.json");
    let text = std::fs::read_to_string(&summary_path).map_err(|e| Error::io(&summary_path, e))?;
    let recorded: serde_json::Value =
        serde_json::from_str(&text).map_err(|e| Error::format(&summary_path, format!("not JSON: {e}")))?;
    let steps = recorded["steps"].as_u64().map_or(parts.train.steps, |s| s as usize);
    let checkpoint = list_checkpoints(&checkpoint_dir(out))?.pop().map(|(_, path)| path);
    Ok(RunSummary {
        steps,
        last: log.last,
        validation: log.validation,
        checkpoint,
        finished: true,
        stopped: false,
        untouched: true,
    })
}

/// Makes every rank hold rank 0's weights before the first step. A fresh run's rank that
/// computed other initial weights takes rank 0's (and says so); a resumed run's ranks must
/// have read the same checkpoint, else every rank fails naming the one that differs.
fn start_from_rank_zero(trainer: &mut Trainer, ranks: &dyn Collective, options: &RunOptions) -> Result<()> {
    let steps = ranks.all_gather(&[trainer.step as f64]);
    let differing_step = steps.iter().position(|&s| s != steps[0]).map(|r| {
        let cause = format!(
            "resumed at step {}, rank 0 at step {}: the ranks read different checkpoints \
             (the output folder must be one folder every rank sees)",
            steps[r], steps[0]
        );
        Err(Error::Rank { rank: r, size: ranks.size(), cause })
    });
    if let Some(e) = differing_step {
        return e;
    }
    let check = trainer.share_weights(ranks)?;
    let differs = match (&check.first_difference, options.resume) {
        (None, _) => Ok(()),
        (Some(param), true) => Err(Error::mismatch(
            "resumed weights",
            format!("they differ from rank 0's from '{param}' on: the ranks read different checkpoints"),
        )),
        (Some(param), false) => {
            (options.notice)(&format!(
                "rank {}: initial weights differed from rank 0's from '{param}' on; training from rank 0's",
                ranks.rank()
            ));
            Ok(())
        }
    };
    agree(ranks, differs)
}

/// The loop of a rank other than 0: the same steps, no files. Its errors are those of the
/// step, which every rank shares.
fn follow(mut trainer: Trainer, ranks: &dyn Collective, options: &RunOptions) -> Result<RunSummary> {
    let t = trainer.parts.train.clone();
    let end = options.stop_after.map_or(t.steps, |s| s.min(t.steps));
    let mut last = None;
    let mut stopped = false;
    while trainer.step < end && !stopped {
        last = Some(trainer.step_among(ranks, None)?);
        stopped = stop_requested(options, ranks) && trainer.step < end;
    }
    let finished = trainer.step >= t.steps;
    Ok(RunSummary {
        steps: trainer.step,
        last,
        validation: None,
        checkpoint: None,
        finished,
        stopped,
        untouched: false,
    })
}

/// Whether any rank was asked to stop ([`RunOptions::stop`]); every rank calls it after every
/// step, so all stop after the same one.
fn stop_requested(options: &RunOptions, ranks: &dyn Collective) -> bool {
    let here = options.stop.as_ref().is_some_and(|s| s.load(Ordering::SeqCst));
    if ranks.size() == 1 {
        return here;
    }
    ranks.all_gather(&[f64::from(u8::from(here))]).iter().any(|&s| s != 0.0)
}
