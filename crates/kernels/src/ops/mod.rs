//! The face: operations on burn tensors that stages call, each dispatched once
//! ([`crate::dispatch::path`]) to a host kernel, a GPU formulation or burn's operation.

pub mod conv;
pub mod deform;
pub mod gru;
pub mod lookup;
pub mod norm;
pub mod resample;
pub mod upsample;
