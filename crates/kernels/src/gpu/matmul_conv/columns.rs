//! The pieces of the GPU's convolution product: the column matrix gathered by one `select`
//! of kept index tensors, and the bias and element-wise epilogue after the product.

use std::sync::{Mutex, PoisonError};

use burn::tensor::ops::ConvOptions;
use burn::tensor::{Device, Int, Tensor, TensorData};

use crate::geometry::conv_output_size;

/// The column matrix of `x` for the windows of `shape`: one `select` of the kept indices
/// ([`window_indices`]) from `x` with a zero column appended.
///
/// # Shapes
/// - `x`: `[N, C, H, W]`; output `[N, C·kh·kw, H_out·W_out]`, rows `(c, ky, kx)`
pub(super) fn gathered_columns(x: Tensor<4>, shape: WindowShape) -> Tensor<3> {
    let [n, c, h, w] = x.dims();
    let taps = shape.kernel[0] * shape.kernel[1];
    let indices = window_indices(shape, 1, &x.device());
    let pixels = indices.dims()[0] / taps;
    let zero = Tensor::zeros([n, c, 1], &x.device());
    let flat = Tensor::cat(vec![x.reshape([n, c, h * w]), zero], 2);
    flat.select(2, indices).reshape([n, c * taps, pixels])
}

/// The bias as [`finish`] adds it: as `[1, O, 1]`, reshaped before the product, or as it is.
pub(super) enum EpilogueBias {
    Flat(Tensor<3>),
    Vector(Tensor<1>),
}

/// `bias` prepared for [`finish`] before the product is issued: reshaped there where `fused`
/// (a convolution with an epilogue and the route on), else as it is. A convolution without an
/// epilogue (the encoders', each followed by a norm) keeps the bias after the product.
pub(super) fn epilogue_bias(bias: Option<Tensor<1>>, o: usize, fused: bool) -> Option<EpilogueBias> {
    bias.map(|b| if fused { EpilogueBias::Flat(b.reshape([1, o, 1])) } else { EpilogueBias::Vector(b) })
}

/// The product `out` (`[N, O, P]`) plus the bias, then `then`, as `[N, O, H_out, W_out]`. With the
/// bias reshaped before the product (`EpilogueBias::Flat`) burn's fusion takes both into the
/// product's epilogue; reshaped here, after the product (`Vector`, the composition before
/// [`GpuRoute::FusedEpilogue`]), the reshape ends the product's fusion block.
pub(super) fn finish(
    out: Tensor<3>,
    bias: Option<EpilogueBias>,
    then: impl FnOnce(Tensor<3>) -> Tensor<3>,
    [out_h, out_w]: [usize; 2],
) -> Tensor<4> {
    let [n, o, _] = out.dims();
    let out = match bias {
        None => out,
        Some(EpilogueBias::Flat(b)) => out + b,
        Some(EpilogueBias::Vector(b)) => out + b.reshape([1, o, 1]),
    };
    then(out).reshape([n, o, out_h, out_w])
}

/// What the gathered column indices depend on.
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
pub(super) struct WindowShape {
    pub(super) input: [usize; 2],
    pub(super) kernel: [usize; 2],
    pub(super) stride: [usize; 2],
    pub(super) padding: [(usize, usize); 2],
    pub(super) dilation: [usize; 2],
}

impl WindowShape {
    /// The windows of a `kh x kw` kernel over an `[h, w]` input with `options`.
    pub(super) fn new(input: [usize; 2], kernel: [usize; 2], options: &ConvOptions<2>) -> Self {
        let (stride, padding, dilation) = (options.stride, options.padding, options.dilation);
        Self { input, kernel, stride, padding, dilation }
    }

    /// For each row `(ky, kx)` of a channel and each output pixel, the input pixel it reads
    /// (`y·W + x`), or `H·W` (the appended zero) where the window lies in the padding.
    ///
    /// # Shapes
    /// - `kh·kw·H_out·W_out` indices, tap-major
    pub(super) fn indices(&self) -> Vec<i32> {
        let ([h, w], [kh, kw]) = (self.input, self.kernel);
        let [(top, _), (left, _)] = self.padding;
        let ([dh, dw], [sh, sw]) = (self.dilation, self.stride);
        let options = ConvOptions::new_with_padding(self.stride, self.padding, self.dilation, 1);
        let [out_h, out_w] = conv_output_size("window indices", self.input, self.kernel, &options);
        let zero = i32::try_from(h * w).expect("an input plane of fewer than 2^31 pixels");
        let mut indices = Vec::with_capacity(kh * kw * out_h * out_w);
        for ky in 0..kh {
            for kx in 0..kw {
                for oy in 0..out_h {
                    let y = (oy * sh + dh * ky).checked_sub(top).filter(|&y| y < h);
                    for ox in 0..out_w {
                        let x = (ox * sw + dw * kx).checked_sub(left).filter(|&x| x < w);
                        indices.push(match (y, x) {
                            (Some(y), Some(x)) => (y * w + x) as i32,
                            _ => zero,
                        });
                    }
                }
            }
        }
        indices
    }
}

/// The most index tensors kept: a pass uses a few shapes per resolution, and a folder of images
/// of many sizes must not grow the cache without bound.
pub(super) const KEPT_INDEX_TENSORS: usize = 32;

/// The indices of [`WindowShape::indices`], `repeat` times over, as a tensor on `device`, built
/// once per shape, repeat and device and kept (up to [`KEPT_INDEX_TENSORS`], the oldest dropped
/// first).
pub(super) fn window_indices(shape: WindowShape, repeat: usize, device: &Device) -> Tensor<1, Int> {
    type Kept = Vec<((WindowShape, usize), Device, Tensor<1, Int>)>;
    static KEPT: Mutex<Kept> = Mutex::new(Vec::new());
    let mut kept = KEPT.lock().unwrap_or_else(PoisonError::into_inner);
    let key = (shape, repeat);
    if let Some((_, _, t)) = kept.iter().find(|(k, d, _)| *k == key && d == device) {
        return t.clone();
    }
    let values = shape.indices().repeat(repeat);
    let len = values.len();
    let tensor = Tensor::<1, Int>::from_data(TensorData::new(values, [len]), device);
    if kept.len() == KEPT_INDEX_TENSORS {
        kept.remove(0);
    }
    kept.push((key, device.clone(), tensor.clone()));
    tensor
}
