//! A convolution as one matrix product over shifted copies of the input, for GPU inference.
//!
//! Design decision: burn 0.22's convolution on wgpu/Vulkan tunes between a direct kernel and
//! implicit-GEMM kernels on the tensor cores (`simple_sync_cmma`). On the update loop's shapes
//! (3x3 with 256 to 384 input channels) the implicit-GEMM kernels ask for 90 KB of workgroup
//! memory where Vulkan allows 48 KB, so burn falls back to its direct kernel: about 2 TFLOP/s on
//! an H200 in f16 and f32 alike, 47 % of a KITTI pass in the GRU at 1/4 resolution (burn's tuning
//! database from the session 12 lease). burn's matrix product does run on the tensor cores at
//! those sizes (its tuning picked `matmul_simple_cyclic_cmma_multi_rows`). So on devices other
//! than the CPU a stride-1 convolution is built from burn's operations as an explicit im2col: the
//! input padded once, its `kh·kw` shifted windows concatenated along the channels (`[N, kh·kw·C,
//! H_out·W_out]`), and one product with the weight reordered to `[O, kh·kw·C]`. It costs the
//! column matrix's memory (`kh·kw` times the input's), which a GPU has, and it differentiates on
//! every backend, but autodiff would keep every column matrix for the backward pass, so training
//! keeps burn's convolution ([`matmul_conv_applies`]). The CPU never takes it: its host kernels
//! are faster there. burn's convolution stays the reference, and the tests check both agree,
//! gradients included.
//!
//! The environment variable `DGSTEREO_GPU_CONV=burn` (read once per process) turns the route
//! off, so a GPU run can measure what it gains.

use std::sync::OnceLock;

use burn::tensor::Tensor;
use burn::tensor::ops::{ConvOptions, PadMode};

use crate::host_conv::conv_output_size;

/// Whether `DGSTEREO_GPU_CONV` asks for burn's convolution on the GPU (read once).
fn route_disabled() -> bool {
    static DISABLED: OnceLock<bool> = OnceLock::new();
    *DISABLED.get_or_init(|| std::env::var("DGSTEREO_GPU_CONV").is_ok_and(|v| v.eq_ignore_ascii_case("burn")))
}

/// Whether a convolution with `options` and a `kh x kw` kernel on `device` takes
/// [`conv2d_by_matmul`]: inference (no autodiff) on a device other than the CPU, stride 1,
/// groups 1, a kernel larger than 1x1 (burn runs 1x1 convolutions as a product already).
pub fn matmul_conv_applies(device: &burn::tensor::Device, options: &ConvOptions<2>, kernel: [usize; 2]) -> bool {
    let on_cpu = *device == burn::tensor::Device::flex();
    !route_disabled() && suits(on_cpu, device.is_autodiff(), options, kernel)
}

/// The rule of [`matmul_conv_applies`] apart from the environment.
fn suits(on_cpu: bool, autodiff: bool, options: &ConvOptions<2>, [kh, kw]: [usize; 2]) -> bool {
    !on_cpu && !autodiff && options.stride == [1, 1] && options.groups == 1 && kh * kw > 1
}

/// `conv2d(x, weight, bias, options)` for stride 1 and groups 1 as one matrix product over
/// the input's shifted windows (explicit im2col from burn's operations).
///
/// # Shapes
/// - `x`: `[N, C, H, W]`; `weight`: `[O, C, kh, kw]`; `bias`: `[O]`
/// - output `[N, O, H_out, W_out]`, `H_out = H + top + bottom - dil·(kh - 1)` (likewise `W_out`)
///
/// # Panics
/// Where `options` has a stride other than 1 or groups, the channels do not match, or the padded
/// input is smaller than the (dilated) kernel.
pub fn conv2d_by_matmul(
    x: Tensor<4>,
    weight: Tensor<4>,
    bias: Option<Tensor<1>>,
    options: &ConvOptions<2>,
) -> Tensor<4> {
    assert!(options.stride == [1, 1] && options.groups == 1, "conv2d_by_matmul: stride 1 and groups 1 only");
    let [n, c, h, w] = x.dims();
    let [o, cw, kh, kw] = weight.dims();
    assert_eq!(c, cw, "conv2d_by_matmul: input has {c} channels, the weight expects {cw}");
    let [(top, bottom), (left, right)] = options.padding;
    let [dh, dw] = options.dilation;
    let [out_h, out_w] = conv_output_size("conv2d_by_matmul", [h, w], [kh, kw], options);
    let padded =
        if top + bottom + left + right > 0 { x.pad([(top, bottom), (left, right)], PadMode::Constant(0.0)) } else { x };
    // Windows in (ky, kx) order, each [N, C, H_out, W_out]: rows (ky, kx, c) of the columns.
    let windows: Vec<Tensor<4>> = (0..kh * kw)
        .map(|tap| {
            let (y, x) = (dh * (tap / kw), dw * (tap % kw));
            padded.clone().slice([0..n, 0..c, y..y + out_h, x..x + out_w])
        })
        .collect();
    let k = kh * kw * c;
    let columns = Tensor::cat(windows, 1).reshape([n, k, out_h * out_w]);
    let weight = weight.permute([0, 2, 3, 1]).reshape([1, o, k]);
    let weight = if n > 1 { weight.expand([n, o, k]) } else { weight };
    let mut out = weight.matmul(columns);
    if let Some(b) = bias {
        out = out + b.reshape([1, o, 1]);
    }
    out.reshape([n, o, out_h, out_w])
}

#[cfg(test)]
mod tests {
    use burn::tensor::module::conv2d;
    use burn::tensor::{Device, Distribution};

    use super::*;
    use crate::tensor::max_abs_diff;

    fn options(padding: [(usize, usize); 2], dilation: usize) -> ConvOptions<2> {
        ConvOptions::new_with_padding([1, 1], padding, [dilation, dilation], 1)
    }

    /// Largest difference from burn's convolution relative to its output's largest magnitude.
    fn relative_error(n: usize, [c, o]: [usize; 2], [h, w]: [usize; 2], k: [usize; 2], opts: ConvOptions<2>) -> f32 {
        let device = Device::flex();
        let x = Tensor::<4>::random([n, c, h, w], Distribution::Normal(0.0, 1.0), &device);
        let wt = Tensor::<4>::random([o, c, k[0], k[1]], Distribution::Normal(0.0, 0.3), &device);
        let b = Tensor::<1>::random([o], Distribution::Normal(0.0, 1.0), &device);
        let reference = conv2d(x.clone(), wt.clone(), Some(b.clone()), opts.clone());
        let got = conv2d_by_matmul(x, wt, Some(b), &opts);
        assert_eq!(got.dims(), reference.dims());
        let scale = reference.clone().abs().max().into_scalar::<f32>().max(1e-6);
        max_abs_diff(got, reference) / scale
    }

    #[test]
    fn the_matmul_convolution_agrees_with_burn() {
        let same = [(1, 1), (1, 1)];
        for (n, co, hw, k, opts) in [
            (1, [16, 24], [9, 13], [3, 3], options(same, 1)),
            (2, [5, 7], [6, 5], [3, 3], options(same, 1)),
            (1, [2, 8], [11, 10], [7, 7], options([(3, 3), (3, 3)], 1)), // the motion encoder's flow conv
            (1, [3, 4], [8, 9], [3, 3], options([(0, 0), (0, 0)], 1)),   // no padding
            (1, [3, 4], [8, 9], [3, 3], options([(2, 1), (0, 3)], 1)),   // asymmetric
            (2, [4, 3], [10, 12], [3, 3], options([(2, 2), (2, 2)], 2)), // dilated
            (1, [6, 2], [7, 8], [1, 3], options([(0, 0), (1, 1)], 1)),   // not square
        ] {
            let err = relative_error(n, co, hw, k, opts);
            assert!(err < 1e-5, "n {n} {co:?} {hw:?} {k:?}: {err}");
        }
    }

    /// The route is exactly burn's convolution in value, so its gradients (through pad, slice,
    /// cat, reshape and matmul) must be burn's convolution's too.
    #[test]
    fn the_matmul_convolution_has_the_gradients_of_burns() {
        let device = Device::flex().autodiff();
        let opts = options([(1, 1), (1, 1)], 1);
        let x = Tensor::<4>::random([2, 4, 6, 7], Distribution::Normal(0.0, 1.0), &device).require_grad();
        let wt = Tensor::<4>::random([5, 4, 3, 3], Distribution::Normal(0.0, 0.3), &device).require_grad();
        let b = Tensor::<1>::random([5], Distribution::Normal(0.0, 1.0), &device).require_grad();
        let target = Tensor::<4>::random([2, 5, 6, 7], Distribution::Normal(0.0, 1.0), &device);
        let loss = |out: Tensor<4>| (out * target.clone()).sum();
        let g1 = loss(conv2d(x.clone(), wt.clone(), Some(b.clone()), opts.clone())).backward();
        let g2 = loss(conv2d_by_matmul(x.clone(), wt.clone(), Some(b.clone()), &opts)).backward();
        for (name, a, b) in [
            ("input", x.grad(&g1).unwrap(), x.grad(&g2).unwrap()),
            ("weight", wt.grad(&g1).unwrap(), wt.grad(&g2).unwrap()),
        ] {
            let scale = a.clone().abs().max().into_scalar::<f32>();
            let err = max_abs_diff(a, b) / scale;
            assert!(err < 1e-5, "{name} gradient: {err}");
        }
        let (gb1, gb2) = (b.grad(&g1).unwrap(), b.grad(&g2).unwrap());
        assert!(
            max_abs_diff(gb1.clone().unsqueeze::<4>(), gb2.unsqueeze()) <= 1e-4 * gb1.abs().max().into_scalar::<f32>()
        );
    }

    /// GPU inference takes the route for stride-1 kernels larger than 1x1; the CPU keeps its
    /// host kernels, training and strided or grouped convolutions keep burn's.
    #[test]
    fn only_gpu_inference_takes_the_route() {
        let opts = options([(1, 1), (1, 1)], 1);
        assert!(suits(false, false, &opts, [3, 3]) && suits(false, false, &opts, [7, 7]));
        assert!(!suits(false, false, &opts, [1, 1]));
        assert!(!suits(true, false, &opts, [3, 3]) && !suits(false, true, &opts, [3, 3]));
        let strided = ConvOptions::new_with_padding([2, 2], [(1, 1), (1, 1)], [1, 1], 1);
        let grouped = ConvOptions::new_with_padding([1, 1], [(1, 1), (1, 1)], [1, 1], 2);
        assert!(!suits(false, false, &strided, [3, 3]) && !suits(false, false, &grouped, [3, 3]));
        assert!(!matmul_conv_applies(&Device::flex(), &opts, [3, 3]));
        assert!(!matmul_conv_applies(&Device::flex().autodiff(), &opts, [3, 3]));
    }
}
