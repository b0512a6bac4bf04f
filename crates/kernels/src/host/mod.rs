//! Hand-written CPU kernels for inference on the Flex backend in f32, on host buffers.

pub mod conv;
pub mod conv_backward;
pub mod deform;
pub mod deform_backward;
pub mod few_outputs;
pub mod fresh;
pub mod gru;
pub mod gru_backward;
pub mod norm;
pub mod norm_backward;
pub mod on_the_fly_lookup;
pub mod pyramid_lookup;
pub mod upsample;
pub mod upsample_backward;
pub mod winograd;
