//! The native half of the `dgstereo` Python package: the inference library's engine, the eval
//! crate's metrics and the data crate's file formats over NumPy arrays.
//!
//! Design decision: this crate is a thin layer on `dgstereo-inference` and holds no model
//! logic, so Python predicts what `dgstereo infer` predicts with the same options. Argument
//! conversions and checks that need Rust (arrays of any strides, the library's option types)
//! live here; the pure-Python layer (`python/dgstereo/`) keeps the interface a Python user
//! reads: the `Model` class, keyword defaults, docstrings and the exception classes. No panic
//! crosses into the interpreter: every library call runs under `catch_unwind`
//! (`errors::guarded`), and inputs are checked before they reach the library.
//!
//! The crate is a member of the workspace, so `maturin develop` reuses what `cargo test
//! --workspace` compiled.

#![deny(missing_docs)]

mod arrays;
mod errors;
mod functions;
mod model;

use pyo3::prelude::*;

/// The native module, imported by the `dgstereo` package.
#[pymodule]
fn _dgstereo(m: &Bound<'_, PyModule>) -> PyResult<()> {
    m.add_class::<model::Engine>()?;
    m.add_function(wrap_pyfunction!(functions::metrics, m)?)?;
    m.add_function(wrap_pyfunction!(functions::depth, m)?)?;
    m.add_function(wrap_pyfunction!(functions::read_pfm, m)?)?;
    m.add_function(wrap_pyfunction!(functions::write_pfm, m)?)?;
    m.add_function(wrap_pyfunction!(functions::read_image, m)?)?;
    m.add("DEFAULT_MEMORY_BUDGET", dgstereo_inference::DEFAULT_MEMORY_BUDGET)?;
    Ok(())
}
