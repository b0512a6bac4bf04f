//! IGEV-Stereo's loss: the sequence L1 loss with the smooth-L1 term of the initial disparity
//! (`initial_disparity = "smooth-l1"`), against the official `sequence_loss` of
//! `IGEV-Stereo/train_stereo.py` and by hand.
//!
//! The official figure was computed by the official function itself, its text taken unchanged
//! from the file (torch 2.x, CPU) on the input of [`official_input`]:
//!
//! ```python
//! src = subprocess.check_output(["git", "--git-dir=IGEV", "show", "HEAD:IGEV-Stereo/train_stereo.py"]).decode()
//! exec(src[src.index("def sequence_loss"):src.index("def fetch_optimizer")])
//! loss, _ = sequence_loss(preds, init, gt, valid, loss_gamma=0.9, max_disp=192)  # float64 tensors
//! print(repr(loss.item()))  # 13.786855165679508 (float32: 13.78685474395752)
//! ```

use burn::tensor::{Device, Tensor};
use dgstereo_core::default_device;
use dgstereo_core::tensor::{from_vec, to_vec};
use dgstereo_loss::{
    DisparityLoss, GammaAdjustment, InitialDisparityTerm, LossConfig, LossTarget, Predictions, smooth_l1,
};

/// `sequence_loss(...)` of the official code on [`official_input`], in float64.
const OFFICIAL_LOSS: f64 = 13.786855165679508;

fn map(values: &[f32], device: &Device) -> Tensor<4> {
    from_vec(values.to_vec(), [2, 1, 2, 4], device)
}

fn plus(gt: &[f32], offsets: &[f32], device: &Device) -> Tensor<4> {
    map(&gt.iter().zip(offsets).map(|(g, o)| g + o).collect::<Vec<_>>(), device)
}

/// Two 2x4 images. Supervised: image 0's first five pixels (192 is `max_disp` itself, 250 above
/// it, the last pixel invalid), image 1's all but the third (invalid) and the last (200).
/// The initial disparity is off by 0.5, 0.99, -2.5, 4, -1.01 and 0.3, -1.7, 0, 2.2, -0.8, 1.5
/// there: both sides of |x| = 1. Three iterations: zero, off by a pixel or so, off by 0.25.
fn official_input(device: &Device) -> (Vec<Tensor<4>>, Tensor<4>, LossTarget) {
    let gt = [1.0, 2.0, 3.0, 10.0, 191.5, 192.0, 250.0, 5.0, 4.0, 8.0, 16.0, 32.0, 64.0, 128.0, 180.0, 200.0];
    let valid = [1.0, 1.0, 1.0, 1.0, 1.0, 1.0, 1.0, 0.0, 1.0, 1.0, 0.0, 1.0, 1.0, 1.0, 1.0, 1.0];
    let initial = [0.5, 0.99, -2.5, 4.0, -1.01, 7.0, 7.0, 95.0, 0.3, -1.7, 50.0, 0.0, 2.2, -0.8, 1.5, 9.0];
    let second = [1.0, -1.0, 2.0, -2.0, 0.5, 7.0, 7.0, 7.0, -3.0, 0.25, 9.0, 1.0, -0.5, 4.0, -6.0, 3.0];
    let iterations = vec![map(&[0.0; 16], device), plus(&gt, &second, device), plus(&gt, &[0.25; 16], device)];
    let target = LossTarget {
        disparity_bilinear: map(&gt, device),
        disparity_nearest: map(&gt, device),
        valid: map(&valid, device),
    };
    (iterations, plus(&gt, &initial, device), target)
}

fn scalar(t: Tensor<1>) -> f64 {
    f64::from(to_vec(t)[0])
}

#[test]
fn the_loss_is_the_official_sequence_loss() {
    let device = default_device();
    let (iterations, initial, target) = official_input(&device);
    let predictions = Predictions { iterations: &iterations, initial: Some(&initial) };
    let loss = LossConfig::igev_stereo();
    let value = scalar(loss.loss(predictions, &target).unwrap());
    assert!((value - OFFICIAL_LOSS).abs() < 2e-6 * OFFICIAL_LOSS, "{value} vs the official {OFFICIAL_LOSS}");

    // By hand over the 11 supervised pixels: the smooth-L1 mean (0.125 + 0.49005 + 2 + 3.5 +
    // 0.51 and 0.045 + 1.2 + 0 + 1.7 + 0.32 + 1) / 11, then RAFT-Stereo's weights 0.9^15,
    // 0.9^7.5, 1 on the iterations' means 623.5 / 11, 21.25 / 11 and 0.25.
    let initial_term = (0.125 + 0.49005 + 2.0 + 3.5 + 0.51 + 0.045 + 1.2 + 0.0 + 1.7 + 0.32 + 1.0) / 11.0;
    let sequence = 0.9f64.powi(15) * 623.5 / 11.0 + 0.9f64.powf(7.5) * 21.25 / 11.0 + 0.25;
    assert!((value - (initial_term + sequence)).abs() < 1e-5 * value, "{value}");
    // Without the term (or without an initial disparity to read) it is the sequence alone.
    let without = LossConfig::SequenceL1 {
        gamma: 0.9,
        max_disparity: 192.0,
        gamma_adjustment: GammaAdjustment::RaftStereo,
        initial_disparity: InitialDisparityTerm::None,
    };
    let value = scalar(without.loss(predictions, &target).unwrap());
    assert!((value - sequence).abs() < 1e-5 * sequence, "{value} vs {sequence}");

    // The split form adds the same term: sum / count over the two images, and over shards.
    let terms = loss.terms(predictions, &target).unwrap();
    assert_eq!(terms.count, 11.0);
    let split = scalar(terms.sum) / terms.count;
    assert!((split - OFFICIAL_LOSS).abs() < 2e-6 * OFFICIAL_LOSS, "{split}");
    let image = |t: &Tensor<4>, i: usize| t.clone().narrow(0, i, 1);
    let (mut sum, mut count) = (0.0, 0.0);
    for i in 0..2 {
        let shard: Vec<_> = iterations.iter().map(|p| image(p, i)).collect();
        let target = LossTarget {
            disparity_bilinear: image(&target.disparity_bilinear, i),
            disparity_nearest: image(&target.disparity_nearest, i),
            valid: image(&target.valid, i),
        };
        let part = loss.terms(Predictions { iterations: &shard, initial: Some(&image(&initial, i)) }, &target).unwrap();
        sum += scalar(part.sum);
        count += part.count;
    }
    assert_eq!(count, 11.0);
    assert!((sum / count - OFFICIAL_LOSS).abs() < 2e-6 * OFFICIAL_LOSS, "{}", sum / count);
}

/// `max_disp` bounds the supervised pixels: the ground truth at exactly 192 or above gets no
/// gradient, from the initial term or the iterations, and neither does an invalid pixel.
#[test]
fn max_disp_and_validity_mask_both_terms() {
    let device = default_device().autodiff();
    let (iterations, initial, target) = official_input(&device);
    let initial = initial.require_grad();
    let last = iterations[2].clone().require_grad();
    let iterations = [iterations[0].clone(), iterations[1].clone(), last.clone()];
    let loss =
        LossConfig::igev_stereo().loss(Predictions { iterations: &iterations, initial: Some(&initial) }, &target);
    let grads = loss.unwrap().backward();
    let initial_grad = to_vec(initial.grad(&grads).unwrap());
    let last_grad = to_vec(last.grad(&grads).unwrap());
    for pixel in [5, 6, 7, 10, 15] {
        assert_eq!((initial_grad[pixel], last_grad[pixel]), (0.0, 0.0), "pixel {pixel} is not supervised");
    }
    // 191.5 < 192 is supervised: off by -1.01, the gradient of the mean is sign(x) / 11.
    assert!((initial_grad[4] + 1.0 / 11.0).abs() < 1e-6, "{}", initial_grad[4]);
    // The same ground truth with max_disparity 700 supervises 192 and 250 as well.
    let wide = LossConfig::SequenceL1 {
        gamma: 0.9,
        max_disparity: 700.0,
        gamma_adjustment: GammaAdjustment::RaftStereo,
        initial_disparity: InitialDisparityTerm::SmoothL1,
    };
    let terms = wide.terms(Predictions { iterations: &iterations, initial: Some(&initial) }, &target).unwrap();
    assert_eq!(terms.count, 14.0);
}

/// Smooth L1 with `beta = 1` on both sides of `|x| = 1`: `0.5 x^2` inside, `|x| - 0.5` outside,
/// continuous at 1; its gradient is `x` inside and `sign(x)` outside.
#[test]
fn smooth_l1_is_quadratic_inside_one_and_linear_outside() {
    let device = default_device().autodiff();
    let x =
        from_vec(vec![-3.0, -1.01, -0.99, -0.5, 0.0, 0.5, 0.99, 1.0, 1.01, 3.0], [1, 1, 1, 10], &device).require_grad();
    let y = smooth_l1(x.clone());
    let values = to_vec(y.clone());
    let expected = [2.5, 0.51, 0.49005, 0.125, 0.0, 0.125, 0.49005, 0.5, 0.51, 2.5];
    for (k, (v, e)) in values.iter().zip(expected).enumerate() {
        assert!((v - e).abs() < 1e-6, "element {k}: {v} vs {e}");
    }
    let grad = to_vec(x.grad(&y.sum().backward()).unwrap());
    let expected = [-1.0, -1.0, -0.99, -0.5, 0.0, 0.5, 0.99, 1.0, 1.0, 1.0];
    for (k, (g, e)) in grad.iter().zip(expected).enumerate() {
        assert!((g - e).abs() < 1e-6, "gradient {k}: {g} vs {e}");
    }
}

/// The term reads the network's initial disparity: none is an error naming the key, another
/// shape a shape error; the other losses ignore it.
#[test]
fn the_initial_disparity_must_be_there_and_of_the_ground_truths_shape() {
    let device = default_device();
    let (iterations, initial, target) = official_input(&device);
    let message = LossConfig::igev_stereo().loss(&iterations, &target).unwrap_err().to_string();
    assert!(message.contains("loss.initial_disparity") && message.contains("soft-argmin"), "{message}");
    assert!(LossConfig::igev_stereo().terms(&iterations, &target).is_err());
    let small = initial.clone().narrow(3, 0, 2);
    let wrong = Predictions { iterations: &iterations, initial: Some(&small) };
    assert!(matches!(LossConfig::igev_stereo().loss(wrong, &target), Err(dgstereo_core::Error::Shape(_))));
    let with_initial = Predictions { iterations: &iterations, initial: Some(&initial) };
    for config in [LossConfig::default(), LossConfig::edge_aware()] {
        let a = scalar(config.loss(with_initial, &target).unwrap());
        let b = scalar(config.loss(&iterations, &target).unwrap());
        assert_eq!(a, b, "{config:?}");
        assert!(!config.needs_initial_disparity());
    }
    assert!(LossConfig::igev_stereo().needs_initial_disparity());
}

#[test]
fn the_term_is_read_from_toml() {
    let text = "kind = \"sequence-l1\"\nmax_disparity = 192.0\ninitial_disparity = \"smooth-l1\"";
    assert_eq!(toml::from_str::<LossConfig>(text).unwrap(), LossConfig::igev_stereo());
    for term in InitialDisparityTerm::ALL {
        let text = format!("kind = \"sequence-l1\"\ninitial_disparity = \"{}\"", term.name());
        let LossConfig::SequenceL1 { initial_disparity, .. } = toml::from_str(&text).unwrap() else {
            panic!("{text} is not a sequence-l1 loss");
        };
        assert_eq!(initial_disparity, term);
    }
    let default: LossConfig = toml::from_str("kind = \"sequence-l1\"").unwrap();
    assert_eq!(default, LossConfig::default());
    assert!(toml::from_str::<LossConfig>("kind = \"sequence-l1\"\ninitial_disparity = \"l1\"").is_err());
    assert!(toml::from_str::<LossConfig>("kind = \"edge-aware\"\ninitial_disparity = \"smooth-l1\"").is_err());
    let written = toml::to_string(&LossConfig::igev_stereo()).unwrap();
    assert_eq!(toml::from_str::<LossConfig>(&written).unwrap(), LossConfig::igev_stereo());
}
