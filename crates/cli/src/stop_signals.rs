//! SIGINT, SIGTERM and SIGUSR1 during training: the first asks the run to stop after its
//! current step, with a checkpoint; a second one ends the process at once. SIGUSR1 is what a
//! Slurm batch script passes on at a preemption notice or before a time limit
//! (`--signal=B:USR1@120`).
//!
//! A training step cannot be cut short without losing it, and the steps since the last
//! checkpoint (up to `checkpoint_every - 1`) are lost with it, so the first signal only sets the
//! run's stop flag ([`dgstereo_train::RunOptions::stop`]); the exit status is still the
//! conventional `128 + signal` (130, 143, 138), so scripts see an interrupted run.

use std::process::ExitCode;
use std::sync::Arc;
use std::sync::atomic::{AtomicBool, AtomicUsize, Ordering};

/// The stop flag the handlers set, and which signal set it.
pub struct StopSignals {
    requested: Arc<AtomicBool>,
    signal: Arc<AtomicUsize>,
}

impl StopSignals {
    /// Installs the handlers of SIGINT, SIGTERM and SIGUSR1.
    pub fn install() -> anyhow::Result<Self> {
        let requested = Arc::new(AtomicBool::new(false));
        let signal = Arc::new(AtomicUsize::new(0));
        #[cfg(unix)]
        for sig in [signal_hook::consts::SIGINT, signal_hook::consts::SIGTERM, signal_hook::consts::SIGUSR1] {
            // Registered first, so it sees the flag as the previous signal left it: a second
            // signal finds it set and exits at once.
            signal_hook::flag::register_conditional_shutdown(sig, 128 + sig, Arc::clone(&requested))?;
            signal_hook::flag::register(sig, Arc::clone(&requested))?;
            signal_hook::flag::register_usize(sig, Arc::clone(&signal), sig as usize)?;
        }
        Ok(Self { requested, signal })
    }

    /// The flag a run watches.
    pub fn flag(&self) -> Arc<AtomicBool> {
        Arc::clone(&self.requested)
    }

    /// The signal's name (`SIGINT`, `SIGTERM`, `SIGUSR1`).
    pub fn name(&self) -> &'static str {
        match self.signal.load(Ordering::SeqCst) {
            15 => "SIGTERM",
            10 => "SIGUSR1",
            _ => "SIGINT",
        }
    }

    /// `128 + signal`: 130 for SIGINT, 143 for SIGTERM, 138 for SIGUSR1.
    pub fn exit_code(&self) -> ExitCode {
        let signal = match self.signal.load(Ordering::SeqCst) {
            0 => 2,
            s => s,
        };
        ExitCode::from(128 + signal as u8)
    }
}
