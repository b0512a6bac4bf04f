//! The split form of every loss ([`DisparityLoss::terms`]): it gives the loss, and it adds over
//! the images of a batch, which is what lets data-parallel ranks share one batch's loss.

use burn::tensor::{Device, Distribution, Tensor};
use dgstereo_core::default_device;
use dgstereo_core::tensor::to_vec;
use dgstereo_loss::{DisparityLoss, LossConfig, LossTarget};

/// A batch of `n` images with a third of the pixels invalid and some ground truth beyond
/// `max_disparity`, and three predictions.
fn batch(n: usize, device: &Device) -> (Vec<Tensor<4>>, LossTarget) {
    let shape = [n, 1, 6, 7];
    let gt = Tensor::<4>::random(shape, Distribution::Uniform(0.0, 900.0), device);
    let nearest = gt.clone() + Tensor::random(shape, Distribution::Uniform(-1.5, 1.5), device);
    let valid = Tensor::<4>::random(shape, Distribution::Uniform(0.0, 1.0), device).greater_elem(0.33).float();
    let predictions = (0..3).map(|_| Tensor::random(shape, Distribution::Uniform(0.0, 900.0), device)).collect();
    (predictions, LossTarget { disparity_bilinear: gt, disparity_nearest: nearest, valid })
}

fn images(t: &Tensor<4>, range: std::ops::Range<usize>) -> Tensor<4> {
    t.clone().narrow(0, range.start, range.len())
}

fn shard(
    predictions: &[Tensor<4>],
    target: &LossTarget,
    range: std::ops::Range<usize>,
) -> (Vec<Tensor<4>>, LossTarget) {
    (
        predictions.iter().map(|p| images(p, range.clone())).collect(),
        LossTarget {
            disparity_bilinear: images(&target.disparity_bilinear, range.clone()),
            disparity_nearest: images(&target.disparity_nearest, range.clone()),
            valid: images(&target.valid, range),
        },
    )
}

fn value(t: Tensor<1>) -> f64 {
    f64::from(to_vec(t)[0])
}

#[test]
fn terms_give_the_loss_and_add_over_the_images_of_a_batch() {
    let device = default_device();
    let (predictions, target) = batch(4, &device);
    for config in LossConfig::variants() {
        let loss = value(config.loss(&predictions, &target).unwrap());
        let whole = config.terms(&predictions, &target).unwrap();
        let from_terms = value(whole.sum.clone()) / whole.count.max(1.0);
        assert!((from_terms - loss).abs() <= 1e-5 * loss.abs(), "{}: {from_terms} vs {loss}", config.kind());
        // Images 0 and 2 on one shard, 1 and 3 on the other, as two ranks hold them.
        let parts: Vec<_> = [0..1, 2..3, 1..2, 3..4]
            .into_iter()
            .map(|r| {
                let (p, t) = shard(&predictions, &target, r);
                config.terms(&p, &t).unwrap()
            })
            .collect();
        let count: f64 = parts.iter().map(|t| t.count).sum();
        let sum: f64 = parts.iter().map(|t| value(t.sum.clone())).sum();
        assert_eq!(count, whole.count, "{}", config.kind());
        assert!((sum / count - loss).abs() <= 1e-5 * loss.abs(), "{}: {} vs {loss}", config.kind(), sum / count);
    }
}

#[test]
fn a_shard_without_supervised_pixels_adds_nothing() {
    let device = default_device();
    let (predictions, mut target) = batch(1, &device);
    target.valid = target.valid.zeros_like();
    let terms = LossConfig::default().terms(&predictions, &target).unwrap();
    assert_eq!(terms.count, 0.0);
    assert_eq!(value(terms.sum), 0.0);
}
