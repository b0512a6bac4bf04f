//! Criterion benchmarks of the pipeline's stages and of one whole forward pass.
//!
//! Sizes are those of a quarter-resolution Middlebury pair padded to a multiple of 32
//! (384x448 for the network; its 1/4 grid 96x112 for the stages), the size at which the
//! reference PyTorch timing of the issue tracker was taken. Run with `cargo bench` (or
//! `just bench`); criterion keeps the history in `target/criterion` and reports changes.

use std::hint::black_box;

use burn::tensor::{Distribution, Tensor};
use criterion::{Criterion, criterion_group, criterion_main};
use dgstereo_core::default_device;
use dgstereo_costvolume::{CorrelationConfig, CorrelationImplementation, CostVolume};
use dgstereo_model::ModelConfig;

fn random(shape: [usize; 4]) -> Tensor<4> {
    Tensor::random(shape, Distribution::Normal(0.0, 1.0), &default_device())
}

/// Building the correlation volume and one radius-4 lookup, both implementations.
fn correlation(c: &mut Criterion) {
    let (h, w) = (96, 112);
    let f1 = random([1, 256, h, w]);
    let f2 = random([1, 256, h, w]);
    let coords = Tensor::<1, burn::tensor::Int>::arange(0..w as i64, &default_device())
        .float()
        .reshape([1, 1, 1, w])
        .expand([1, 1, h, w]);
    let mut group = c.benchmark_group("correlation");
    group.sample_size(10);
    for implementation in [CorrelationImplementation::Reg, CorrelationImplementation::Alt] {
        let config = CorrelationConfig { implementation, ..CorrelationConfig::default() };
        group.bench_function(format!("{implementation:?}/build+lookup 96x112"), |b| {
            b.iter(|| {
                let volume = config.build(f1.clone(), f2.clone());
                let out = volume.lookup(coords.clone());
                black_box(out.into_data())
            })
        });
    }
    group.finish();
}

/// One whole forward pass of RAFT-Stereo (default configuration) at 384x448.
fn forward(c: &mut Criterion) {
    let device = default_device();
    let model = ModelConfig::default().init(&device).expect("default config is valid");
    let left = random([1, 3, 384, 448]).mul_scalar(60.0).add_scalar(128.0);
    let right = random([1, 3, 384, 448]).mul_scalar(60.0).add_scalar(128.0);
    let mut group = c.benchmark_group("raft-stereo");
    group.sample_size(10);
    for iters in [1usize, 8] {
        group.bench_function(format!("forward 384x448 {iters} iterations"), |b| {
            b.iter(|| {
                let out = model.forward_flow(left.clone(), right.clone(), None, iters, None, None, false, None);
                black_box(out.flow_up.last().cloned().map(|t| t.into_data()))
            })
        });
    }
    group.finish();
}

criterion_group!(benches, correlation, forward);
criterion_main!(benches);
