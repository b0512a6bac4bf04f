//! The correlation lookups of the cost volume: the materialised pyramid ("reg"), the
//! on-the-fly dot products ("alt") and IGEV-Stereo's geometry encoding volume, each stored and
//! sampled where the dispatch's path runs: host buffers and one hand-written loop for CPU
//! inference (`crate::host::pyramid_lookup`, `on_the_fly_lookup`, `geometry_lookup`), two
//! gathers over all levels for GPU inference (`crate::gpu::gathered_lookup`; the geometry
//! volume takes burn's operations there), burn's tensor operations (the reference and the
//! differentiable path) elsewhere.

mod geometry;
mod on_the_fly;
mod pyramid;

pub use geometry::GeometryPyramid;
pub use on_the_fly::OnTheFlyCorrelation;
pub use pyramid::{CorrelationPyramid, all_pairs};

#[cfg(test)]
mod geometry_tests;
#[cfg(test)]
mod tests;
