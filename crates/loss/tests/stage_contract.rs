//! Every loss through one body generic over the stage trait [`DisparityLoss`]: a finite,
//! non-negative loss that [`LossTerms`](dgstereo_loss::LossTerms) give back, zero for perfect
//! predictions, and the shape errors the trait promises.

use burn::tensor::{Distribution, Tensor};
use dgstereo_core::tensor::to_vec;
use dgstereo_core::{Error, default_device};
use dgstereo_loss::{
    DisparityLoss, EdgeAwareLoss, GammaAdjustment, InitialDisparityTerm, LossConfig, LossTarget, SequenceL1Loss,
};

const SHAPE: [usize; 4] = [2, 1, 6, 9];

fn value(t: Tensor<1>) -> f64 {
    f64::from(to_vec(t)[0])
}

/// What every loss promises, for three predictions against a target with invalid pixels.
fn conforms<L: DisparityLoss>(loss: &L, name: &str) {
    let device = default_device();
    let gt = Tensor::<4>::random(SHAPE, Distribution::Uniform(0.0, 60.0), &device);
    let valid = Tensor::<4>::random(SHAPE, Distribution::Uniform(0.0, 1.0), &device).greater_elem(0.25).float();
    let target = LossTarget { disparity_bilinear: gt.clone(), disparity_nearest: gt.clone(), valid };
    let predictions: Vec<Tensor<4>> =
        (0..3).map(|_| Tensor::random(SHAPE, Distribution::Uniform(0.0, 60.0), &device)).collect();
    let l = value(loss.loss(&predictions, &target).unwrap_or_else(|e| panic!("{name}: {e}")));
    assert!(l.is_finite() && l > 0.0, "{name}: loss {l}");
    let terms = loss.terms(&predictions, &target).unwrap_or_else(|e| panic!("{name}: {e}"));
    let from_terms = value(terms.sum) / terms.count.max(1.0);
    assert!((from_terms - l).abs() <= 1e-5 * l, "{name}: terms give {from_terms}, the loss is {l}");
    let perfect = vec![gt.clone(); 3];
    assert_eq!(value(loss.loss(&perfect, &target).unwrap()), 0.0, "{name}: perfect predictions");
    for (what, predictions) in [("no prediction", vec![]), ("a mis-shaped one", vec![gt.narrow(3, 0, 4)])] {
        assert!(matches!(loss.loss(&predictions, &target), Err(Error::Shape(_))), "{name}: {what}");
        assert!(matches!(loss.terms(&predictions, &target), Err(Error::Shape(_))), "{name}: {what}");
    }
}

#[test]
fn every_loss_keeps_the_stage_contract() {
    let sequence = SequenceL1Loss {
        gamma: 0.9,
        max_disparity: 700.0,
        adjustment: GammaAdjustment::default(),
        initial: InitialDisparityTerm::None,
    };
    conforms(&sequence, "sequence-l1");
    conforms(&EdgeAwareLoss { tau: 0.9, gamma: 0.9, max_disparity: 700.0 }, "edge-aware");
    for config in LossConfig::variants() {
        conforms(&config, config.kind());
    }
}
