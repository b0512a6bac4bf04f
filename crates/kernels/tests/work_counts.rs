//! The operations' own multiply-accumulate counts, on every path (`count_work`).

use burn::nn::PaddingConfig2d;
use burn::nn::conv::{Conv2d, Conv2dConfig};
use burn::tensor::{Device, Distribution, Tensor};
use dgstereo_kernels::{
    Numerics, Path, conv_gru_step, conv2d_forward, conv2d_relu_forward, count_work, macs_so_far, with_path,
};

fn conv(c: usize, o: usize, k: usize, stride: usize, device: &Device) -> Conv2d {
    Conv2dConfig::new([c, o], [k, k])
        .with_stride([stride, stride])
        .with_padding(PaddingConfig2d::Explicit(k / 2, k / 2, k / 2, k / 2))
        .init(device)
}

/// A convolution counts `N·C·O·k·k·H_out·W_out` on every path, whichever fused form runs;
/// nothing is counted outside `count_work`.
#[test]
fn a_convolution_counts_its_direct_products() {
    let device = Device::flex();
    let x = Tensor::<4>::random([2, 5, 12, 10], Distribution::Normal(0.0, 1.0), &device);
    let (three, strided) = (conv(5, 7, 3, 1, &device), conv(5, 4, 3, 2, &device));
    for pinned in [Path::Host, Path::Gpu, Path::Stock] {
        let before = macs_so_far();
        let _ = with_path(pinned, || conv2d_forward(&three, x.clone(), Numerics::Sensitive));
        assert_eq!(macs_so_far(), before, "counting is off outside count_work");
        let (_, work) = count_work(|| with_path(pinned, || conv2d_forward(&three, x.clone(), Numerics::Sensitive)));
        assert_eq!(work.macs, 2 * 5 * 7 * 9 * 12 * 10, "{pinned:?}");
        let (_, work) =
            count_work(|| with_path(pinned, || conv2d_relu_forward(&strided, x.clone(), Numerics::Sensitive)));
        assert_eq!(work.macs, 2 * 5 * 4 * 9 * 6 * 5, "{pinned:?} stride 2");
    }
}

/// The ConvGRU step counts its three convolutions whether the fused host step or the
/// tensor-op step runs.
#[test]
fn the_gru_step_counts_its_three_convolutions() {
    let device = Device::flex();
    let (hidden, input) = (6, 4);
    let convs: Vec<Conv2d> = (0..3).map(|_| conv(hidden + input, hidden, 3, 1, &device)).collect();
    let h = Tensor::<4>::random([1, hidden, 8, 9], Distribution::Normal(0.0, 1.0), &device);
    let x = Tensor::<4>::random([1, input, 8, 9], Distribution::Normal(0.0, 1.0), &device);
    let ctx = Tensor::<4>::zeros([1, 2 * hidden, 8, 9], &device);
    let q = Tensor::<4>::zeros([1, hidden, 8, 9], &device);
    for pinned in [Path::Host, Path::Stock] {
        let step = || {
            let convs = [&convs[0], &convs[1], &convs[2]];
            conv_gru_step(convs, h.clone(), [&ctx, &q], std::slice::from_ref(&x), Numerics::Tolerant)
        };
        let (_, work) = count_work(|| with_path(pinned, step));
        assert_eq!(work.macs, (3 * (hidden + input) * hidden * 9 * 8 * 9) as u64, "{pinned:?}");
    }
}
