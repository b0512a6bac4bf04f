//! Formulations of burn's operations with fewer kernel launches, for GPU inference.

pub(crate) mod gathered_lookup;
pub(crate) mod matmul_conv;
