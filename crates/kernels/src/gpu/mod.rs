//! Formulations of burn's operations with fewer kernel launches, for GPU inference.

pub mod gathered_lookup;
pub mod matmul_conv;
