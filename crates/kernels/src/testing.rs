//! Entry points for the workspace's benchmarks that compare one host algorithm with another;
//! not part of the face, and not for stages.

use burn::tensor::Tensor;
use burn::tensor::ops::ConvOptions;

use crate::algorithm::ConvAlgorithm;
use crate::dispatch::host_algorithm;
use crate::geometry::Epilogue;
use crate::host::conv::conv2d_host;
use crate::settings::settings;

/// `conv2d(x, weight, bias, options)` by the host convolution with the algorithm the dispatch
/// chooses for CPU inference (one group).
pub fn conv2d_host_dispatched(
    x: Tensor<4>,
    weight: Tensor<4>,
    bias: Option<Tensor<1>>,
    options: &ConvOptions<2>,
) -> Tensor<4> {
    let algorithm = host_algorithm(x.dims(), weight.dims(), options, true, settings());
    conv2d_host(x, weight, bias, options, algorithm, Epilogue::Linear)
}

/// The same by im2col tiles alone, never Winograd or the few-output kernel.
pub fn conv2d_host_im2col(
    x: Tensor<4>,
    weight: Tensor<4>,
    bias: Option<Tensor<1>>,
    options: &ConvOptions<2>,
) -> Tensor<4> {
    conv2d_host(x, weight, bias, options, ConvAlgorithm::Im2col, Epilogue::Linear)
}
