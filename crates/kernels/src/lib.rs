//! The hand-written CPU kernels and GPU formulations of dgstereo, behind one dispatch.
//!
//! Design decision: a fast path exists only for a measured hot spot, and a stage should not need
//! to know it is there. So the stages call a small face of operations on burn tensors, re-exported
//! here (convolution with or without an epilogue, norms + ReLU, resize, pooling, lookups,
//! deformable sampling, the ConvGRU step, convex upsampling); each operation asks the one
//! dispatch ([`dispatch`]) for a plan, from the device, its dtype, autodiff, the operation's shape,
//! the process's [`settings`] and the [`Numerics`] its caller allows, and carries it out: a
//! hand-written host kernel with the algorithm the plan names (`host`), our training node
//! (`autodiff`), the GPU's launch-saving formulation (`gpu`) or burn's own operation, which stays
//! the reference every other path is tested against on every path ([`test_paths!`]). The layers
//! point one way: the face (`ops`) asks `dispatch` and calls `host`, `gpu` or `autodiff`, which
//! share `geometry`, `product` and `taps`; none of those three is visible outside this crate.
//! [`machine_line`] names the machine and the products it takes, for every timing to print.
#![deny(missing_docs)]

mod algorithm;
pub mod allocator;
mod autodiff;
#[cfg(test)]
mod bf16_paths;
mod bf16_product;
pub mod dispatch;
mod geometry;
mod gpu;
mod host;
mod machine;
mod ops;
mod product;
pub mod settings;
mod taps;
mod test_paths;
#[doc(hidden)]
pub mod testing;
mod work;

pub use dispatch::{
    Numerics, Op, Path, ProductPrecision, bf16_unit, path, product_precision, with_path, with_products,
};
pub use host::winograd::UpdateLoop;
pub use machine::machine_line;
pub use ops::conv::{
    conv_options, conv2d_affine, conv2d_forward, conv2d_forward_then, conv2d_op, conv2d_op_then, conv2d_relu_forward,
    flat_pixels,
};
pub use ops::deform::deform_conv2d_forward;
pub use ops::gru::conv_gru_step;
pub use ops::linear::linear_forward;
pub use ops::lookup::{CorrelationPyramid, GeometryPyramid, OnTheFlyCorrelation, all_pairs};
pub use ops::norm::{Normalization, add_relu, affine_planes, normalize_planes, rectify};
pub use ops::resample::{average_pool_half, linear_matrix, linear_weights, resize_bilinear};
pub use ops::upsample::convex_upsample;
pub use settings::{GpuRoute, Settings, configure};
pub use work::{WorkCount, count_work, macs_so_far};
