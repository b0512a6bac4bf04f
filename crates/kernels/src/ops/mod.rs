//! The face: operations on burn tensors that stages call (re-exported at the crate root), each
//! planned once by the dispatch (`crate::dispatch::plan`) and carried out: a host kernel with
//! its algorithm, a training node, a GPU formulation or burn's operation.

pub(crate) mod conv;
pub(crate) mod deform;
pub(crate) mod gru;
pub(crate) mod linear;
pub(crate) mod lookup;
pub(crate) mod norm;
pub(crate) mod resample;
pub(crate) mod upsample;
