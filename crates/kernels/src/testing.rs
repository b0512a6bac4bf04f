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

/// The bf16 units this process can run, by name (`amx-bf16`, `avx512-bf16`), the faster first.
pub fn bf16_units() -> Vec<&'static str> {
    crate::bf16_product::Bf16Unit::ALL.into_iter().filter(|u| u.available()).map(|u| u.name()).collect()
}

/// A product of fixed weights (`rows x depth`, packed in bf16 once) with `depth x cols` f32
/// columns on one bf16 unit, for the products' benchmark.
pub struct Bf16Product {
    unit: crate::bf16_product::Bf16Unit,
    weights: crate::bf16_product::PackedWeights,
    cols: usize,
    out: Vec<f32>,
}

impl Bf16Product {
    /// The product on the unit named `unit` ([`bf16_units`]), `None` where the process lacks it.
    pub fn new(unit: &str, lhs: &[f32], [rows, cols, depth]: [usize; 3]) -> Option<Self> {
        let unit = crate::bf16_product::Bf16Unit::ALL.into_iter().find(|u| u.name() == unit && u.available())?;
        let weights = crate::bf16_product::PackedWeights::new(lhs, depth, [rows, depth]);
        Some(Self { unit, weights, cols, out: vec![0.0; rows * cols] })
    }

    /// `out = lhs · rhs` (the columns converted to bf16 pairs first), returning `out`.
    pub fn run(&mut self, rhs: &[f32]) -> &[f32] {
        crate::bf16_product::matmul_bf16(
            self.unit,
            &mut self.out,
            self.cols,
            &self.weights,
            rhs,
            self.cols,
            self.cols,
            false,
        );
        &self.out
    }
}

/// `dst = lhs · rhs` in f32 by the `gemm` crate on the calling thread (`rows x depth` times
/// `depth x cols`), the host kernels' f32 product.
pub fn f32_product(dst: &mut [f32], lhs: &[f32], rhs: &[f32], [rows, cols, depth]: [usize; 3]) {
    crate::product::matmul_into(dst, lhs, depth, rhs, [rows, cols, depth]);
}
