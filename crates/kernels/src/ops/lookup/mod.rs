//! The correlation lookups of the cost volume: the materialised pyramid ("reg") and the
//! on-the-fly dot products ("alt"), each stored and sampled where the dispatch's path runs:
//! host buffers and one hand-written loop for CPU inference (`crate::host::pyramid_lookup`,
//! `crate::host::on_the_fly_lookup`), two gathers over all levels for GPU inference
//! (`crate::gpu::gathered_lookup`), burn's tensor operations (the reference and the
//! differentiable path) elsewhere.

mod on_the_fly;
mod pyramid;

pub use on_the_fly::OnTheFlyCorrelation;
pub use pyramid::{CorrelationPyramid, all_pairs};

#[cfg(test)]
mod tests;
