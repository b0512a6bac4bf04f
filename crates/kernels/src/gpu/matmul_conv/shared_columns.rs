//! One input's column matrix shared by several convolutions, for GPU inference.
//!
//! The ConvGRU convolves `[h, x]` for its gates and `[r·h, x]` for its candidate: the same `x`
//! (the motion features and the neighbouring levels' states, two thirds of the channels at 1/4
//! resolution) gathered into a column matrix twice an iteration, 0.26 ms each on an H200 at the
//! KITTI frame's 1/4 level. A convolution over channels concatenated is
//! the sum of the convolutions over each part with the weight's matching input channels, so `x`'s
//! columns are gathered once ([`SharedColumns::gather`]) and each convolution adds the product
//! with its own first part's columns to the shared part's product
//! ([`SharedColumns::conv_then`]); the sum, the bias and the epilogue join the second product's
//! epilogue (`super::finish`). It costs a second product per convolution (9 to 12 more kernels an
//! iteration on lavapipe) for a third less gather traffic at 1/4.

use burn::tensor::Tensor;
use burn::tensor::ops::ConvOptions;

use super::columns::{WindowShape, epilogue_bias, finish, gathered_columns};
use crate::algorithm::GpuConvForm;
use crate::geometry::conv_output_size;

/// The gathered column matrix of the part of a convolution's input that several convolutions
/// share, with the geometry they all use.
#[derive(Debug, Clone)]
pub struct SharedColumns {
    /// `[N, C_shared·kh·kw, H_out·W_out]`, rows `(c, ky, kx)`.
    columns: Tensor<3>,
    channels: usize,
    input: [usize; 2],
    kernel: [usize; 2],
    options: ConvOptions<2>,
    /// The bias reshaped before the products (the dispatch's form).
    fused_epilogue: bool,
}

impl SharedColumns {
    /// The columns of `shared` for a `kh x kw` kernel with `options` (groups 1), for
    /// convolutions in the dispatch's `form` (its columns are gathered; its epilogue fused or not).
    ///
    /// # Shapes
    /// - `shared`: `[N, C_shared, H, W]`
    pub(crate) fn gather(shared: Tensor<4>, kernel: [usize; 2], options: &ConvOptions<2>, form: GpuConvForm) -> Self {
        assert!(options.groups == 1, "SharedColumns: groups 1 only");
        let [_, channels, h, w] = shared.dims();
        let columns = gathered_columns(shared, WindowShape::new([h, w], kernel, options));
        Self { columns, channels, input: [h, w], kernel, options: options.clone(), fused_epilogue: form.fused_epilogue }
    }

    /// `then(conv2d(cat([first, shared], 1), weight, bias, options))` with the shared part's
    /// columns as gathered, `then` working on `[N, O, H_out·W_out]` as in
    /// `super::conv2d_by_matmul_then`.
    ///
    /// # Shapes
    /// - `first`: `[N, C_first, H, W]`; `weight`: `[O, C_first + C_shared, kh, kw]`; `bias`: `[O]`
    /// - output `[N, O, H_out, W_out]`
    ///
    /// # Panics
    /// Where `first` differs from the shared input in batch or size, or the weight does not fit.
    pub fn conv_then(
        &self,
        first: Tensor<4>,
        weight: Tensor<4>,
        bias: Option<Tensor<1>>,
        then: impl FnOnce(Tensor<3>) -> Tensor<3>,
    ) -> Tensor<4> {
        let [n, c_first, h, w] = first.dims();
        let [o, c, kh, kw] = weight.dims();
        let [n_shared, _, pixels] = self.columns.dims();
        assert!(n == n_shared && [h, w] == self.input, "SharedColumns: the first part's batch or size differs");
        assert!(c == c_first + self.channels && [kh, kw] == self.kernel, "SharedColumns: the weight does not fit");
        let out_size = conv_output_size("SharedColumns", [h, w], self.kernel, &self.options);
        let taps = kh * kw;
        let bias = epilogue_bias(bias, o, self.fused_epilogue);
        // Rows `(c, ky, kx)`: a part's input channels are one run of columns of the flattened
        // weight, a strided view (narrowing the 4-D weight first would make the reshape a copy).
        let flat = weight.reshape([1, o, c * taps]);
        let weight_of = |start: usize, channels: usize| {
            let part = flat.clone().narrow(2, start * taps, channels * taps);
            if n > 1 { part.expand([n, o, channels * taps]) } else { part }
        };
        // The shared part's product first, so that it is ready before the second product and its
        // addition joins that product's epilogue.
        let shared = weight_of(c_first, self.channels).matmul(self.columns.clone());
        let columns = gathered_columns(first, WindowShape::new(self.input, self.kernel, &self.options));
        let own = weight_of(0, c_first).matmul(columns);
        debug_assert_eq!(own.dims(), [n, o, pixels]);
        finish(own, bias, |out| then(out + shared), out_size)
    }
}

#[cfg(test)]
mod tests {
    use burn::tensor::module::conv2d;
    use burn::tensor::{Device, Distribution};

    use super::*;
    use crate::algorithm::GpuColumns;
    use dgstereo_core::tensor::max_abs_diff;

    /// Against burn's convolution of the concatenated input: two convolutions sharing one
    /// part's columns (as the ConvGRU's gates and candidate do), a batch of two, padded and
    /// unpadded, a dilated kernel.
    #[test]
    fn shared_columns_give_the_convolution_of_the_concatenation() {
        let device = Device::flex();
        let normal = |shape: [usize; 4], std| Tensor::<4>::random(shape, Distribution::Normal(0.0, std), &device);
        for (n, [c_first, c_shared, o], [kh, kw], options) in [
            (1, [4, 6, 5], [3, 3], ConvOptions::new([1, 1], [1, 1], [1, 1], 1)),
            (2, [3, 5, 4], [3, 3], ConvOptions::new([1, 1], [0, 0], [1, 1], 1)),
            (1, [2, 3, 6], [3, 3], ConvOptions::new([1, 1], [2, 2], [2, 2], 1)),
        ] {
            let [h, w] = [6, 9];
            let shared = normal([n, c_shared, h, w], 1.0);
            let form = GpuConvForm { columns: GpuColumns::Gathered, product_first: false, fused_epilogue: n == 1 };
            let columns = SharedColumns::gather(shared.clone(), [kh, kw], &options, form);
            for _ in 0..2 {
                let first = normal([n, c_first, h, w], 1.0);
                let weight = normal([o, c_first + c_shared, kh, kw], 0.3);
                let bias = Tensor::<1>::random([o], Distribution::Normal(0.0, 1.0), &device);
                let whole = Tensor::cat(vec![first.clone(), shared.clone()], 1);
                let expected = conv2d(whole, weight.clone(), Some(bias.clone()), options.clone()).tanh();
                let got = columns.conv_then(first, weight, Some(bias), |t| t.tanh());
                assert_eq!(got.dims(), expected.dims());
                let err = max_abs_diff(got, expected);
                assert!(err < 1e-5, "n {n} c {c_first}+{c_shared} o {o}: {err}");
            }
        }
    }
}
