//! One module per subcommand.

pub mod ablate;
pub mod bench;
pub mod bench_train;
pub mod demo;
pub mod eval;
pub mod experiment;
pub mod export;
pub mod infer;
pub mod metrics;
pub mod train;
pub mod verify;
pub mod weights;
