//! Hand-written CPU kernels on host buffers, for the Flex backend in f32: inference, and the
//! gradients of the training nodes (`crate::autodiff`). Each runs the algorithm the dispatch
//! chose; none decides a path.

pub(crate) mod all_pairs;
pub(crate) mod columns;
pub(crate) mod conv;
pub(crate) mod conv_backward;
pub(crate) mod deform;
pub(crate) mod deform_backward;
pub(crate) mod few_outputs;
pub(crate) mod fresh;
pub(crate) mod geometry_lookup;
pub(crate) mod gru;
pub(crate) mod gru_backward;
pub(crate) mod linear;
pub(crate) mod norm;
pub(crate) mod norm_backward;
pub(crate) mod on_the_fly_lookup;
pub(crate) mod pyramid_lookup;
pub(crate) mod resample;
pub(crate) mod upsample;
pub(crate) mod upsample_backward;
pub(crate) mod winograd;
