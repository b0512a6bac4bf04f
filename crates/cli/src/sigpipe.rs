//! A closed standard output ends the process quietly, as it ends `cat` or `grep`.
//!
//! Design decision: Rust programs start with SIGPIPE ignored, so writing to a pipe whose reader
//! has gone (`dgstereo bench | head -3`, `dgstereo metrics ... | jq` stopped early) is an error,
//! which `println!` turns into a panic with a backtrace on stderr. Restoring the default action
//! at start makes such a write end the process by the signal, with nothing printed: the shell's
//! convention for pipelines. The command stops at the same point as the panic stopped it.
#![allow(unsafe_code)]

/// Restores the default action of SIGPIPE (terminate). A no-op other than on Unix. Called once,
/// first thing in `main`, before any other thread exists.
pub fn restore_default_sigpipe() {
    #[cfg(unix)]
    // SAFETY: `signal` is given a valid signal number and `SIG_DFL`, and runs before any other
    // thread could be installing handlers.
    unsafe {
        libc::signal(libc::SIGPIPE, libc::SIG_DFL);
    }
}
