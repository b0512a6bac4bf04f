//! The hand-written CPU kernels and GPU formulations of dgstereo, behind one dispatch.
//!
//! Design decision: a fast path exists only for a measured hot spot, and a stage should not need
//! to know it is there. So the stages call a small face of operations on burn tensors
//! ([`ops`]: convolution with or without an epilogue, norm + ReLU, resize, pooling, lookups,
//! deformable sampling, the ConvGRU step, convex upsampling); each operation asks the one
//! dispatch ([`dispatch::path`]) where to run, from the device, its dtype, autodiff and the
//! process's [`settings`], and runs the hand-written host kernel ([`host`]), the GPU's
//! launch-saving formulation ([`gpu`]) or burn's own operation, which stays the reference every
//! other path is tested against on every path ([`test_paths!`]).
#![deny(missing_docs)]

pub mod allocator;
pub mod autodiff;
pub mod dispatch;
pub mod geometry;
pub mod gpu;
pub mod host;
pub mod ops;
pub mod product;
pub mod settings;
mod test_paths;
mod work;

pub use autodiff::WinogradForward;
pub use dispatch::{Op, Path, path, with_path};
pub use host::winograd::UpdateLoop;
pub use ops::conv::{
    conv_options, conv2d_affine_or, conv2d_forward, conv2d_forward_then, conv2d_op, conv2d_op_then,
    conv2d_relu_forward, flat_pixels,
};
pub use ops::deform::deform_conv2d_forward;
pub use ops::gru::{conv_gru_step_or, gru_blend, gru_gates};
pub use ops::norm::{PlaneNorm, add_relu, affine_planes_or, normalize_planes_or, rectify};
pub use ops::resample::{average_pool_half, resize_bilinear};
pub use ops::upsample::convex_upsample;
pub use settings::{GpuRoute, Settings, configure};
pub use work::{WorkCount, count_work, macs_so_far};
