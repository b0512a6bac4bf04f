//! Formulations of burn's operations with fewer kernel launches, for GPU inference.

pub mod matmul_conv;
