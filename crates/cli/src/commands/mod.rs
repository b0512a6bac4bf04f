//! One module per subcommand.

pub mod demo;
pub mod infer;
pub mod metrics;
pub mod verify;
