//! Support code shared by the workspace-level integration tests and benchmarks.
#![deny(missing_docs)]

pub use dgstereo_core::shared::{shared_dir, shared_dir_for_test};

pub mod import_graph;
