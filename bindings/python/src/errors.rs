//! The library's errors as the package's exception classes, and panics kept on the Rust side.
//!
//! The classes live in the pure-Python layer (`dgstereo/errors.py`): [`Error`] derives from
//! `Exception`, `InputError` also from `ValueError` (bad arrays and options) and `FileError`
//! also from `OSError` (files that cannot be read, written or parsed). Which one an error
//! becomes follows the library's [`Error`]: a file's error (`Io`, `Format`, `Checkpoint`) makes
//! a `FileError`; the caller names the kind of the rest.

use std::cell::Cell;
use std::panic::{AssertUnwindSafe, catch_unwind};
use std::sync::Once;

use dgstereo_core::Error;
use pyo3::prelude::*;

/// The exception class an error becomes.
#[derive(Clone, Copy, Debug, PartialEq, Eq)]
pub enum Kind {
    /// `dgstereo.Error`.
    Error,
    /// `dgstereo.InputError` (a `ValueError`).
    Input,
    /// `dgstereo.FileError` (an `OSError`).
    File,
}

impl Kind {
    fn class_name(self) -> &'static str {
        match self {
            Kind::Error => "Error",
            Kind::Input => "InputError",
            Kind::File => "FileError",
        }
    }
}

/// The exception of class `kind` with `message`.
pub fn raise(kind: Kind, message: impl Into<String>) -> PyErr {
    let message = message.into();
    Python::attach(|py| {
        let made = py
            .import("dgstereo.errors")
            .and_then(|m| m.getattr(kind.class_name()))
            .and_then(|class| class.call1((message.clone(),)));
        match made {
            Ok(value) => PyErr::from_value(value),
            // The pure-Python layer is missing (the module imported on its own).
            Err(_) => pyo3::exceptions::PyRuntimeError::new_err(message),
        }
    })
}

/// A bad array or option.
pub fn input(message: impl Into<String>) -> PyErr {
    raise(Kind::Input, message)
}

/// Whether `e` is about a file that could not be read, written or parsed (under any context).
fn is_file_error(e: &Error) -> bool {
    matches!(e.root(), Error::Io { .. } | Error::Format { .. } | Error::Checkpoint { .. })
}

/// `e` as an exception: a `FileError` when a file is at fault, else of class `kind`.
pub fn convert(e: Error, kind: Kind) -> PyErr {
    let kind = if is_file_error(&e) { Kind::File } else { kind };
    raise(kind, dgstereo_inference::error_chain(&e))
}

/// A library result as a Python one (see [`convert`]).
pub fn from_library<T>(result: Result<T, Error>, kind: Kind) -> PyResult<T> {
    result.map_err(|e| convert(e, kind))
}

thread_local! {
    /// Whether this thread is inside [`guarded`], whose caller reports a panic as an exception.
    static GUARDED: Cell<bool> = const { Cell::new(false) };
}

/// Installs, once, a panic hook that stays silent for panics inside [`guarded`] on the calling
/// thread (their message becomes the exception; Rust's report and backtrace on stderr would only
/// repeat it to a Python user) and hands every other panic to the hook it replaces.
fn quiet_inside_guarded() {
    static ONCE: Once = Once::new();
    ONCE.call_once(|| {
        let previous = std::panic::take_hook();
        std::panic::set_hook(Box::new(move |info| {
            if !GUARDED.with(Cell::get) {
                previous(info);
            }
        }));
    });
}

/// Runs `f`, turning a panic into a `dgstereo.Error` ("internal error: ...") instead of letting
/// it cross into the interpreter, and without Rust's panic report on stderr.
pub fn guarded<T>(f: impl FnOnce() -> Result<T, Error>) -> Result<T, Error> {
    quiet_inside_guarded();
    let outer = GUARDED.with(|g| g.replace(true));
    let outcome = catch_unwind(AssertUnwindSafe(f));
    GUARDED.with(|g| g.set(outer));
    match outcome {
        Ok(result) => result,
        Err(panic) => Err(Error::Internal(Error::panic_message(&*panic))),
    }
}
