//! The face: operations on burn tensors that stages call, each dispatched once
//! ([`crate::dispatch::path`]) to a host kernel, a GPU formulation or burn's operation.

pub mod conv;
pub mod gru;
pub mod norm;
pub mod resample;
