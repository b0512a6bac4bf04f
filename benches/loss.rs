//! Criterion benchmark of the paper's edge-aware loss (EALS) on a training batch.
#![allow(missing_docs)] // criterion_group! generates undocumented items.
//!
//! A 320x736 crop and 12 iterations' predictions, as in training; `sample_size(10)`.

use std::hint::black_box;

use burn::tensor::{Distribution, Tensor};
use criterion::{Criterion, criterion_group, criterion_main};
use dgstereo_core::default_device;
use dgstereo_loss::{DisparityLoss, EdgeAwareLoss, LossTarget};

fn edge_aware_loss(c: &mut Criterion) {
    let device = default_device();
    let shape = [1, 1, 320, 736];
    let gt = Tensor::<4>::random(shape, Distribution::Uniform(0.0, 100.0), &device);
    let target = LossTarget {
        disparity_bilinear: gt.clone(),
        disparity_nearest: gt.round(),
        valid: Tensor::ones(shape, &device),
    };
    let predictions: Vec<Tensor<4>> =
        (0..12).map(|_| Tensor::random(shape, Distribution::Uniform(0.0, 100.0), &device)).collect();
    let loss = EdgeAwareLoss { tau: 0.9, gamma: 0.9, max_disparity: 700.0 };
    let mut group = c.benchmark_group("loss");
    group.sample_size(10);
    group.bench_function("edge-aware 320x736 12 predictions", |b| {
        b.iter(|| black_box(loss.loss(&predictions, &target).expect("matching shapes").into_data()))
    });
    group.finish();
}

criterion_group!(benches, edge_aware_loss);
criterion_main!(benches);
