//! Criterion benchmarks of the pipeline's stages, of whole forward passes and of a training step.
#![allow(missing_docs)] // criterion_group! generates undocumented items.
//!
//! Sizes are the issue's: a 320x736 training crop and a KITTI frame (375x1242, padded to
//! 384x1248); the update stages run at their 1/4 grids (80x184 and 96x312). Whole forward passes
//! run at 320x736 with 12 and 32 iterations, and the training step (forward with every
//! iteration upsampled, backward, AdamW) at a small 128x256 crop. Every group uses
//! `sample_size(10)` so `cargo bench` (or `just bench`) stays within minutes per group; criterion
//! keeps the history in `target/criterion`, so `cargo bench -- --save-baseline main` on main and
//! `--baseline main` on a branch show a change's effect. Weights are random: costs do not depend
//! on their values.
//!
//! The edge-aware loss is in `benches/loss.rs` (it needs the loss crate).

use std::hint::black_box;

use burn::module::Module;
use burn::optim::{AdamWConfig, GradientsParams};
use burn::tensor::{Distribution, Int, Tensor};
use criterion::{BenchmarkId, Criterion, criterion_group};
use dgstereo_core::{Probe, default_device};
use dgstereo_costvolume::{CorrelationConfig, CorrelationImplementation, CorrelationPyramid, OnTheFlyCorrelation};
use dgstereo_kernels::{Path, UpdateLoop, with_path};
use dgstereo_model::fusion::{FusionConfig, ImageFusion};
use dgstereo_model::updater::{GateContext, convex_upsample};
use dgstereo_model::{ForwardOptions, ModelConfig, RaftStereo};

/// Full-resolution sizes (padded to a multiple of 32) and their names.
const SIZES: [([usize; 2], &str); 2] = [([320, 736], "320x736"), ([384, 1248], "kitti 384x1248")];

fn random(shape: [usize; 4]) -> Tensor<4> {
    Tensor::random(shape, Distribution::Normal(0.0, 1.0), &default_device())
}

fn image([h, w]: [usize; 2]) -> Tensor<4> {
    Tensor::random([1, 3, h, w], Distribution::Uniform(0.0, 255.0), &default_device())
}

fn model() -> RaftStereo {
    ModelConfig::default().init(&default_device()).expect("default config is valid")
}

/// x coordinates of a plausible match: the pixel's own column minus a smooth disparity.
fn coords(h: usize, w: usize) -> Tensor<4> {
    let x = Tensor::<1, Int>::arange(0..w as i64, &default_device()).float().reshape([1, 1, 1, w]).expand([1, 1, h, w]);
    x - random([1, 1, h, w]).abs().mul_scalar(8.0)
}

fn encoders(c: &mut Criterion) {
    let model = model();
    let dgstereo_model::encoder::Encoders::Separate(encoders) = &model.encoder else {
        panic!("RAFT-Stereo has separate encoders")
    };
    let fnet = &encoders.fnet;
    let mut group = c.benchmark_group("encoders");
    group.sample_size(10);
    for (size, name) in SIZES {
        let pair = Tensor::cat(vec![image(size), image(size)], 0).div_scalar(127.5).sub_scalar(1.0);
        let left = image(size).div_scalar(127.5).sub_scalar(1.0);
        group.bench_function(BenchmarkId::new("feature encoder (pair)", name), |b| {
            b.iter(|| black_box(fnet.features(pair.clone())))
        });
        group.bench_function(BenchmarkId::new("context encoder", name), |b| {
            b.iter(|| black_box(encoders.cnet.context(left.clone(), 3)))
        });
    }
    group.finish();
}

fn correlation(c: &mut Criterion) {
    let mut group = c.benchmark_group("correlation");
    group.sample_size(10);
    let config = CorrelationConfig::default();
    for ([h, w], name) in SIZES {
        let (h, w) = (h / 4, w / 4);
        let (f1, f2) = (random([1, 256, h, w]), random([1, 256, h, w]));
        let x = coords(h, w);
        for implementation in [CorrelationImplementation::Reg, CorrelationImplementation::Alt] {
            group.bench_function(BenchmarkId::new(format!("build {implementation:?}"), name), |b| {
                b.iter(|| black_box(config.build_with(implementation, f1.clone(), f2.clone())))
            });
        }
        for kernel in [Path::Host, Path::Stock] {
            let pyramid =
                with_path(kernel, || CorrelationPyramid::new(f1.clone(), f2.clone(), config.levels, config.radius));
            group.bench_function(BenchmarkId::new(format!("lookup reg {kernel:?}"), name), |b| {
                b.iter(|| black_box(pyramid.lookup(x.clone())))
            });
        }
        for kernel in [Path::Host, Path::Stock] {
            let alt =
                with_path(kernel, || OnTheFlyCorrelation::new(f1.clone(), f2.clone(), config.levels, config.radius));
            group.bench_function(BenchmarkId::new(format!("lookup alt {kernel:?}"), name), |b| {
                b.iter(|| black_box(alt.lookup(x.clone())))
            });
        }
    }
    group.finish();
}

/// The host convolution kernel against burn's on the largest convolutions of a pass: the
/// GRU-1/4 candidate (384 -> 128 channels at the 1/4 grid, of 320x736 and of a 384x448 pair)
/// and a feature-encoder layer1 convolution (64 -> 64; the default model runs layer1 at full
/// resolution, here it runs at half of 320x736 to keep the bench short). `3x3 Host` is the
/// dispatching kernel (Winograd F(4x4, 3x3) at these sizes unless `DGSTEREO_KERNELS=no-winograd`; the
/// 64-channel layer in cache-resident blocks where the processor has AVX-512, in bands with
/// `DGSTEREO_KERNELS=no-winograd-blocks`), `3x3 Host im2col` its im2col path alone.
fn convolution(c: &mut Criterion) {
    use burn::tensor::module::conv2d;
    use burn::tensor::ops::ConvOptions;
    use dgstereo_kernels::testing::{conv2d_host_dispatched as conv2d_host, conv2d_host_im2col};
    let mut group = c.benchmark_group("convolution");
    group.sample_size(10);
    let [h, w] = SIZES[0].0;
    for (cin, cout, [ch, cw], name) in [
        (384, 128, [h / 4, w / 4], "GRU 1/4 384->128 80x184"),
        (384, 128, [96, 112], "GRU 1/4 384->128 96x112"),
        (64, 64, [h / 2, w / 2], "layer1 64->64 160x368"),
        (256, 2, [96, 112], "flow head 256->2 96x112"),
    ] {
        let x = random([1, cin, ch, cw]);
        let weight = random([cout, cin, 3, 3]).mul_scalar(0.05);
        let options = ConvOptions::new([1, 1], [1, 1], [1, 1], 1);
        group.bench_function(BenchmarkId::new("3x3 Stock", name), |b| {
            b.iter(|| dgstereo_core::tensor::to_vec(conv2d(x.clone(), weight.clone(), None, options.clone())))
        });
        group.bench_function(BenchmarkId::new("3x3 Host", name), |b| {
            b.iter(|| dgstereo_core::tensor::to_vec(conv2d_host(x.clone(), weight.clone(), None, &options)))
        });
        group.bench_function(BenchmarkId::new("3x3 Host im2col", name), |b| {
            b.iter(|| dgstereo_core::tensor::to_vec(conv2d_host_im2col(x.clone(), weight.clone(), None, &options)))
        });
    }
    group.finish();
}

fn update(c: &mut Criterion) {
    let model = model();
    let block = &model.update_block;
    let mut group = c.benchmark_group("update");
    group.sample_size(10);
    for ([h, w], name) in SIZES {
        let (h, w) = (h / 4, w / 4);
        let hidden: Vec<Tensor<4>> = (0..3).map(|l| random([1, 128, h >> l, w >> l]).tanh()).collect();
        let gates: Vec<_> = (0..3).map(|l| GateContext::from_zqr(random([1, 384, h >> l, w >> l]))).collect();
        let corr = random([1, 36, h, w]);
        let flow = Tensor::cat(vec![random([1, 1, h, w]), Tensor::zeros([1, 1, h, w], &default_device())], 1);
        group.bench_function(BenchmarkId::new("one iteration (3 GRU levels, flow head)", name), |b| {
            // As inside the model's loop: the transformed convolution weights kept between steps.
            let _update_loop = UpdateLoop::new();
            b.iter(|| {
                let mut state = hidden.clone();
                black_box(block.step(&mut state, &gates, corr.clone(), flow.clone(), None, &mut Probe::none()))
            })
        });
        group.bench_function(BenchmarkId::new("mask head + convex upsample", name), |b| {
            b.iter(|| {
                let mask = block.upsample_mask(&hidden);
                black_box(convex_upsample(flow.clone().narrow(1, 0, 1), mask, 4))
            })
        });
        let depth = random([1, 1, 4 * h, 4 * w]).abs().add_scalar(0.1);
        let guidance: ModelConfig = toml::from_str("[updater]\nguidance = \"gradient\"").expect("valid TOML");
        group.bench_function(BenchmarkId::new("gradient feature", name), |b| {
            b.iter(|| black_box(guidance.updater.guidance.feature(depth.clone(), [h, w])))
        });
        let fusion = FusionConfig::deformable().init(&default_device()).expect("the paper's fusion builds");
        let img = image([4 * h, 4 * w]);
        group.bench_function(BenchmarkId::new("DGIA fusion (full resolution)", name), |b| {
            b.iter(|| black_box(fusion.fuse(img.clone(), Some(depth.clone())).expect("a prior is given")))
        });
    }
    group.finish();
}

fn forward(c: &mut Criterion) {
    let model = model();
    let size = [320, 736];
    let (left, right) = (image(size), image(size));
    let mut group = c.benchmark_group("raft-stereo");
    group.sample_size(10);
    for iters in [12usize, 32] {
        group.bench_function(BenchmarkId::new("forward 320x736", format!("{iters} iterations")), |b| {
            b.iter(|| {
                let out = model
                    .forward_flow(left.clone(), right.clone(), None, iters, ForwardOptions::default())
                    .expect("the model needs no prior");
                black_box(out.flow_up.last().cloned().map(|t| t.into_data()))
            })
        });
    }
    group.finish();
}

/// One optimiser step at 128x256, 4 iterations: forward with every iteration upsampled,
/// sequence L1 loss (gamma 0.9), backward, AdamW.
fn training_step(c: &mut Criterion) {
    let device = default_device().autodiff();
    let (h, w, iters) = (128, 256, 4);
    let left = Tensor::<4>::random([1, 3, h, w], Distribution::Uniform(0.0, 255.0), &device);
    let right = Tensor::<4>::random([1, 3, h, w], Distribution::Uniform(0.0, 255.0), &device);
    let target = Tensor::<4>::random([1, 1, h, w], Distribution::Uniform(0.0, 20.0), &device);
    let mut group = c.benchmark_group("training");
    group.sample_size(10);
    group.bench_function("step 128x256 4 iterations (forward+backward+AdamW)", |b| {
        let mut model = Some(model().fork(&device).train());
        let mut optim = AdamWConfig::new().with_weight_decay(1e-5).init();
        b.iter(|| {
            let m = model.take().expect("model");
            let out = m
                .forward_flow(
                    left.clone(),
                    right.clone(),
                    None,
                    iters,
                    ForwardOptions { all_iterations: true, ..ForwardOptions::default() },
                )
                .expect("the model needs no prior");
            let n = out.flow_up.len();
            let loss = out
                .flow_up
                .iter()
                .enumerate()
                .map(|(k, f)| {
                    (f.clone().neg() - target.clone()).abs().mean().mul_scalar(0.9f64.powi((n - k - 1) as i32))
                })
                .reduce(|a, b| a + b)
                .expect("at least one iteration");
            let grads = GradientsParams::from_grads(loss.backward(), &m);
            model = Some(optim.step(2e-4, m, grads));
        })
    });
    group.finish();
}

criterion_group!(benches, encoders, convolution, correlation, update, forward, training_step);
/// `criterion_main!` with the allocator setting the `dgstereo` binary makes, so the stages are
/// timed as the binary runs them.
fn main() {
    dgstereo_kernels::allocator::retain_freed_memory();
    benches();
    Criterion::default().configure_from_args().final_summary();
}
