//! SIGINT, SIGTERM and SIGUSR1 during training: the first asks the run to stop after its
//! current step, with a checkpoint; a second one, a second or more later, asks to end the process
//! at once, with what that drops. SIGUSR1 is what a Slurm batch script passes on at a preemption
//! notice or before a time limit (`--signal=B:USR1@120`).
//!
//! A training step cannot be cut short without losing it, and the steps since the last
//! checkpoint (up to `checkpoint_every - 1`) are lost with it, so the first signal only sets the
//! run's stop flag (the trainer's `RunOptions::stop`); the exit status is still the
//! conventional `128 + signal` (130, 143, 138), so scripts see an interrupted run.
//!
//! Design decision: one request can arrive as several signals. coreutils `timeout` sends SIGTERM
//! to its child and then to its process group, which holds the child, and a terminal's Ctrl-C
//! reaches every process of the foreground group; so signals within [`REPEAT_WINDOW`] of the
//! first are that same request. The signals are received on a thread of their own
//! (`signal_hook`'s iterator), which calls the caller's function with each request
//! ([`SignalEvent`]); unlike a signal handler, that function may print and end the process. The
//! position a request to stop at once reports ([`RunPosition`]) is kept by the progress observer
//! of the run in progress.
//!
//! A crate of its own: the trainer takes a stop flag as an argument and knows no signals (a
//! library takes its settings as arguments), a process's signals belong to the front end that
//! owns the process, and the binary only prints; so the rule of what a signal means, tested here,
//! sits on `core` alone, beside none of the pipeline's crates.
#![deny(missing_docs)]

use std::sync::Arc;
use std::sync::atomic::{AtomicBool, AtomicUsize, Ordering};
use std::time::{Duration, Instant};

use dgstereo_core::{Error, Result};

/// Signals this close to the first one are the same request.
pub const REPEAT_WINDOW: Duration = Duration::from_secs(1);

/// What a signal that arrives is, given when the first arrived.
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
pub enum Arrival {
    /// The first: stop after the current step, with a checkpoint.
    First,
    /// The first delivered again (within [`REPEAT_WINDOW`]): nothing more to do.
    Repeat,
    /// A second request: stop at once.
    Again,
}

/// Classifies a signal arriving at `now` when the first arrived at `first` (if any has).
pub fn arrival(first: Option<Instant>, now: Instant) -> Arrival {
    match first {
        None => Arrival::First,
        Some(at) if now.saturating_duration_since(at) < REPEAT_WINDOW => Arrival::Repeat,
        Some(_) => Arrival::Again,
    }
}

/// A signal's name (`SIGINT`, `SIGTERM`, `SIGUSR1`).
pub fn signal_name(signal: usize) -> &'static str {
    match signal {
        15 => "SIGTERM",
        10 => "SIGUSR1",
        _ => "SIGINT",
    }
}

const NONE: usize = usize::MAX;

/// Where the run in progress stands: its completed steps and its newest checkpoint. Kept by the
/// run's progress observer, read when a second signal stops the process at once.
#[derive(Debug)]
pub struct RunPosition {
    training: AtomicBool,
    done: AtomicUsize,
    checkpoint: AtomicUsize,
}

impl Default for RunPosition {
    fn default() -> Self {
        Self { training: AtomicBool::new(false), done: AtomicUsize::new(0), checkpoint: AtomicUsize::new(NONE) }
    }
}

impl RunPosition {
    /// A run starts after `done` steps (a resumed run: those of its checkpoint).
    pub fn started(&self, done: usize) {
        self.done.store(done, Ordering::SeqCst);
        self.checkpoint.store(if done > 0 { done } else { NONE }, Ordering::SeqCst);
        self.training.store(true, Ordering::SeqCst);
    }

    /// `done` steps are complete.
    pub fn stepped(&self, done: usize) {
        self.done.store(done, Ordering::SeqCst);
    }

    /// A checkpoint of `done` steps is written.
    pub fn checkpointed(&self, done: usize) {
        self.checkpoint.store(done, Ordering::SeqCst);
    }

    /// The run's loop ended.
    pub fn ended(&self) {
        self.training.store(false, Ordering::SeqCst);
    }

    /// What stopping now drops.
    pub fn dropped(&self) -> String {
        let checkpoint = Some(self.checkpoint.load(Ordering::SeqCst)).filter(|c| *c != NONE);
        dropped_work(self.training.load(Ordering::SeqCst), self.done.load(Ordering::SeqCst), checkpoint)
    }
}

/// What stopping at once drops of a run with `done` completed steps whose newest checkpoint is
/// `checkpoint`: the steps after it and the work in progress.
pub fn dropped_work(training: bool, done: usize, checkpoint: Option<usize>) -> String {
    if !training {
        return "no training step was in progress".to_string();
    }
    match checkpoint {
        Some(c) if c >= done => {
            format!("dropped the work in progress after step {done}; the checkpoint of step {c} is kept")
        }
        Some(c) if c + 1 == done => format!(
            "dropped step {done} and the work in progress after it; the checkpoint of step {c} is kept, a resumed run continues there"
        ),
        Some(c) => format!(
            "dropped steps {}..{done} and the work in progress after them; the checkpoint of step {c} is kept, a resumed run continues there",
            c + 1
        ),
        None if done == 0 => "dropped the work in progress: no step was completed yet".to_string(),
        None if done == 1 => {
            "dropped step 1 and the work in progress after it: no checkpoint was written yet".to_string()
        }
        None => format!("dropped steps 1..{done} and the work in progress after them: no checkpoint was written yet"),
    }
}

/// A request the signals made, for the caller to say (and, for [`StopNow`](Self::StopNow), to
/// carry out).
#[derive(Debug, Clone, PartialEq, Eq)]
pub enum SignalEvent {
    /// The first signal: the stop flag is set, the run stops after its current step.
    Stopping {
        /// The signal's name (`SIGINT`).
        signal: &'static str,
    },
    /// A second request: the process should end at once.
    StopNow {
        /// The signal's name.
        signal: &'static str,
        /// What stopping now drops ([`RunPosition::dropped`]).
        dropped: String,
        /// The conventional exit status, `128 + signal`.
        status: i32,
    },
}

/// The stop flag the signals set, which signal set it, and the position a second one reports.
pub struct StopSignals {
    requested: Arc<AtomicBool>,
    signal: Arc<AtomicUsize>,
    position: Arc<RunPosition>,
}

impl StopSignals {
    /// Starts receiving SIGINT, SIGTERM and SIGUSR1 (on a thread of their own), calling
    /// `on_signal` with each request (a repeat within [`REPEAT_WINDOW`] is none).
    ///
    /// # Errors
    /// The signals cannot be received on this system ([`Error::Unsupported`]).
    pub fn install(on_signal: impl Fn(&SignalEvent) + Send + 'static) -> Result<Self> {
        let requested = Arc::new(AtomicBool::new(false));
        let signal = Arc::new(AtomicUsize::new(0));
        let position = Arc::new(RunPosition::default());
        #[cfg(unix)]
        {
            use signal_hook::consts::{SIGINT, SIGTERM, SIGUSR1};
            let refused =
                |e: std::io::Error| Error::unsupported("receiving SIGINT, SIGTERM and SIGUSR1", e.to_string());
            let mut signals = signal_hook::iterator::Signals::new([SIGINT, SIGTERM, SIGUSR1]).map_err(refused)?;
            let (requested, signal, position) = (Arc::clone(&requested), Arc::clone(&signal), Arc::clone(&position));
            std::thread::Builder::new()
                .name("stop-signals".into())
                .spawn(move || {
                    let mut first = None;
                    for sig in signals.forever() {
                        let now = Instant::now();
                        let name = signal_name(sig as usize);
                        match arrival(first, now) {
                            Arrival::First => {
                                first = Some(now);
                                signal.store(sig as usize, Ordering::SeqCst);
                                requested.store(true, Ordering::SeqCst);
                                on_signal(&SignalEvent::Stopping { signal: name });
                            }
                            Arrival::Repeat => {}
                            Arrival::Again => on_signal(&SignalEvent::StopNow {
                                signal: name,
                                dropped: position.dropped(),
                                status: 128 + sig,
                            }),
                        }
                    }
                })
                .map_err(refused)?;
        }
        #[cfg(not(unix))]
        drop(on_signal);
        Ok(Self { requested, signal, position })
    }

    /// The flag a run watches.
    pub fn flag(&self) -> Arc<AtomicBool> {
        Arc::clone(&self.requested)
    }

    /// Whether a signal asked to stop.
    pub fn requested(&self) -> bool {
        self.requested.load(Ordering::SeqCst)
    }

    /// The position of the run in progress, for its progress observer to keep.
    pub fn position(&self) -> Arc<RunPosition> {
        Arc::clone(&self.position)
    }

    /// The signal's name (`SIGINT`, `SIGTERM`, `SIGUSR1`).
    pub fn name(&self) -> &'static str {
        signal_name(self.signal.load(Ordering::SeqCst))
    }

    /// The exit status of a run the signal stopped, `128 + signal`: 130 for SIGINT, 143 for
    /// SIGTERM, 138 for SIGUSR1.
    pub fn exit_status(&self) -> u8 {
        let signal = match self.signal.load(Ordering::SeqCst) {
            0 => 2,
            s => s,
        };
        128 + signal as u8
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn repeats_within_a_second_are_one_request() {
        let t0 = Instant::now();
        assert_eq!(arrival(None, t0), Arrival::First);
        assert_eq!(arrival(Some(t0), t0 + Duration::from_millis(3)), Arrival::Repeat);
        assert_eq!(arrival(Some(t0), t0 + Duration::from_millis(999)), Arrival::Repeat);
        assert_eq!(arrival(Some(t0), t0 + REPEAT_WINDOW), Arrival::Again);
        assert_eq!(arrival(Some(t0), t0 + Duration::from_secs(30)), Arrival::Again);
    }

    #[test]
    fn a_stop_at_once_says_what_it_drops() {
        let position = RunPosition::default();
        assert_eq!(position.dropped(), "no training step was in progress");
        position.started(0);
        assert_eq!(position.dropped(), "dropped the work in progress: no step was completed yet");
        position.stepped(7);
        assert!(position.dropped().starts_with("dropped steps 1..7 and"), "{}", position.dropped());
        assert!(position.dropped().contains("no checkpoint was written"));
        position.checkpointed(5);
        assert!(position.dropped().starts_with("dropped steps 6..7 and"), "{}", position.dropped());
        assert!(position.dropped().contains("checkpoint of step 5 is kept"));
        position.stepped(6);
        assert!(position.dropped().starts_with("dropped step 6 and"), "{}", position.dropped());
        position.checkpointed(6);
        assert!(position.dropped().starts_with("dropped the work in progress after step 6"), "{}", position.dropped());
        // A resumed run's checkpoint is the one it started from.
        position.started(40);
        position.stepped(43);
        assert!(position.dropped().starts_with("dropped steps 41..43"), "{}", position.dropped());
        position.ended();
        assert_eq!(position.dropped(), "no training step was in progress");
    }

    #[cfg(unix)]
    #[test]
    fn a_signal_sets_the_flag_and_is_reported() {
        use signal_hook::consts::SIGUSR1;
        let (sender, received) = std::sync::mpsc::channel();
        let stop = StopSignals::install(move |event| sender.send(event.clone()).unwrap()).unwrap();
        assert!(!stop.requested());
        signal_hook::low_level::raise(SIGUSR1).unwrap();
        let event = received.recv_timeout(Duration::from_secs(60)).unwrap();
        assert_eq!(event, SignalEvent::Stopping { signal: "SIGUSR1" });
        assert!(stop.requested() && stop.flag().load(Ordering::SeqCst));
        assert_eq!((stop.name(), stop.exit_status()), ("SIGUSR1", 138));
    }
}
