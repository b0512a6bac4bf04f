//! Behaviour of the disparity losses: edge mask, EALS by hand, sequence weights, configs.

use burn::tensor::{Device, Tensor};
use dgstereo_core::default_device;
use dgstereo_core::tensor::{from_vec, to_vec};
use dgstereo_loss::{
    DisparityLoss, EdgeAwareLoss, GammaAdjustment, InitialDisparityTerm, LossConfig, LossTarget, SequenceL1Loss,
    edge_mask, sequence_weights,
};
use proptest::prelude::*;

fn map(values: &[f32], shape: [usize; 4], device: &Device) -> Tensor<4> {
    from_vec(values.to_vec(), shape, device)
}

fn scalar(t: Tensor<1>) -> f32 {
    to_vec(t)[0]
}

fn count(mask: Tensor<4>) -> f32 {
    to_vec(mask).iter().sum()
}

/// The 2x3 example of the EALS hand computation.
///
/// ```text
/// bilinear  1  2    3        nearest  1  4    3.5      valid  1 1 1
///           4  5  800                 4  5  800               0 1 1
/// ```
/// Kept by EALS (tau 0.9, max 700): (0,0), (0,2), (1,1) with ground truth 1, 3, 5. Pixel (0,1)
/// is an edge (|2 - 4| > 0.9), (1,0) is invalid, (1,2) is beyond `max_disparity`.
/// The invalid pixel holds infinity to check that it cannot poison the loss.
fn example(device: &Device) -> LossTarget {
    let inf = f32::INFINITY;
    LossTarget {
        disparity_bilinear: map(&[1.0, 2.0, 3.0, inf, 5.0, 800.0], [1, 1, 2, 3], device),
        disparity_nearest: map(&[1.0, 4.0, 3.5, inf, 5.0, 800.0], [1, 1, 2, 3], device),
        valid: map(&[1.0, 1.0, 1.0, 0.0, 1.0, 1.0], [1, 1, 2, 3], device),
    }
}

/// Predictions: all zeros, then the (finite) ground truth plus one.
fn example_predictions(device: &Device) -> Vec<Tensor<4>> {
    vec![Tensor::zeros([1, 1, 2, 3], device), map(&[2.0, 3.0, 4.0, 5.0, 6.0, 801.0], [1, 1, 2, 3], device)]
}

#[test]
fn eals_matches_hand_computation() {
    let device = default_device();
    let loss = EdgeAwareLoss { tau: 0.9, gamma: 0.9, max_disparity: 700.0 };
    // L_1 = (1 + 3 + 5) / 6 = 1.5, L_2 = 3 * 1 / 6 = 0.5, L = 0.9 * 1.5 + 0.5 = 1.85.
    let value = scalar(loss.loss(&example_predictions(&device), &example(&device)).unwrap());
    assert!((value - 1.85).abs() < 1e-5, "{value}");
    // The single last prediction has weight 1.
    let value = scalar(loss.loss(&example_predictions(&device)[1..], &example(&device)).unwrap());
    assert!((value - 0.5).abs() < 1e-6, "{value}");
    assert_eq!(to_vec(loss.mask(&example(&device))), vec![1.0, 0.0, 1.0, 0.0, 1.0, 0.0]);
}

#[test]
fn eals_averages_over_the_batch_images() {
    let device = default_device();
    let one = example(&device);
    // A second image with nothing valid halves every term: sum / (B * H * W).
    let target = LossTarget {
        disparity_bilinear: Tensor::cat(vec![one.disparity_bilinear.clone(); 2], 0),
        disparity_nearest: Tensor::cat(vec![one.disparity_nearest.clone(); 2], 0),
        valid: Tensor::cat(vec![one.valid.clone(), Tensor::zeros([1, 1, 2, 3], &device)], 0),
    };
    let predictions: Vec<_> = example_predictions(&device).into_iter().map(|p| Tensor::cat(vec![p; 2], 0)).collect();
    let value = scalar(LossConfig::edge_aware().loss(&predictions, &target).unwrap());
    assert!((value - 0.925).abs() < 1e-5, "{value}");
}

#[test]
fn sequence_l1_matches_hand_computation() {
    let device = default_device();
    let loss = SequenceL1Loss {
        gamma: 0.9,
        max_disparity: 700.0,
        adjustment: GammaAdjustment::RaftStereo,
        initial: InitialDisparityTerm::None,
    };
    // Supervised: (0,0), (0,1), (0,2), (1,1) with ground truth 1, 2, 3, 5.
    // L_1 = 11 / 4, L_2 = 1; weights 0.9^15 and 1.
    let value = scalar(loss.loss(&example_predictions(&device), &example(&device)).unwrap());
    let expected = 0.9f32.powi(15) * 2.75 + 1.0;
    assert!((value - expected).abs() < 1e-5, "{value} vs {expected}");
    // N = 1: weight 1, no division by zero.
    let value = scalar(loss.loss(&example_predictions(&device)[..1], &example(&device)).unwrap());
    assert!((value - 2.75).abs() < 1e-5, "{value}");
}

/// DEFOM-Stereo's `sequence_loss` (`utils/utils.py`) transcribed: for `i in range(n)`,
/// `adjusted = gamma ** (15 / n)`, `i_weight = adjusted ** (n - i)`.
fn defom_official_weights(n: usize, gamma: f64) -> Vec<f64> {
    (0..n).map(|i| (gamma.powf(15.0 / n as f64)).powf((n - i) as f64)).collect()
}

#[test]
fn defom_weights_are_the_official_ones() {
    for n in [1, 2, 3, 18, 26, 32] {
        let ours = GammaAdjustment::DefomStereo.weights(n, 0.9);
        let official = defom_official_weights(n, 0.9);
        assert_eq!(ours.len(), n);
        for (k, (a, b)) in ours.iter().zip(&official).enumerate() {
            assert!((a - b).abs() < 1e-12, "n = {n}, prediction {k}: {a} vs {b}");
        }
        // Unlike RAFT-Stereo's, the last prediction weighs gamma^(15/N), not 1, and the first
        // gamma^15.
        assert!((ours[n - 1] - 0.9f64.powf(15.0 / n as f64)).abs() < 1e-12);
        assert!((ours[0] - 0.9f64.powi(15)).abs() < 1e-9);
    }
    // DEFOM's 18 training iterations: the two adjustments differ.
    let raft = GammaAdjustment::RaftStereo.weights(18, 0.9);
    let defom = GammaAdjustment::DefomStereo.weights(18, 0.9);
    assert_eq!(raft[17], 1.0);
    assert!((defom[17] - 0.9f64.powf(15.0 / 18.0)).abs() < 1e-12 && defom[17] < 0.92);
}

#[test]
fn sequence_l1_with_defom_adjustment_matches_hand_computation() {
    let device = default_device();
    let loss = SequenceL1Loss {
        gamma: 0.9,
        max_disparity: 700.0,
        adjustment: GammaAdjustment::DefomStereo,
        initial: InitialDisparityTerm::None,
    };
    // L_1 = 11 / 4, L_2 = 1 (as above); N = 2: gamma' = 0.9^7.5, weights 0.9^15 and 0.9^7.5.
    let value = scalar(loss.loss(&example_predictions(&device), &example(&device)).unwrap());
    let expected = 0.9f64.powi(15) * 2.75 + 0.9f64.powf(7.5);
    assert!((f64::from(value) - expected).abs() < 1e-5, "{value} vs {expected}");
    // The split form agrees: sum / count.
    let terms = loss.terms(&example_predictions(&device), &example(&device)).unwrap();
    let split = f64::from(scalar(terms.sum)) / terms.count;
    assert!((split - expected).abs() < 1e-5, "{split} vs {expected}");
    // Through the configuration.
    let config: LossConfig = toml::from_str("kind = \"sequence-l1\"\ngamma_adjustment = \"defom-stereo\"").unwrap();
    let value = scalar(config.loss(&example_predictions(&device), &example(&device)).unwrap());
    assert!((f64::from(value) - expected).abs() < 1e-5, "{value} vs {expected}");
    assert!(toml::from_str::<LossConfig>("kind = \"sequence-l1\"\ngamma_adjustment = \"igev\"").is_err());
    assert!(toml::from_str::<LossConfig>("kind = \"edge-aware\"\ngamma_adjustment = \"defom-stereo\"").is_err());
    for adjustment in GammaAdjustment::ALL {
        let text = format!("kind = \"sequence-l1\"\ngamma_adjustment = \"{}\"", adjustment.name());
        let LossConfig::SequenceL1 { gamma_adjustment, .. } = toml::from_str(&text).unwrap() else {
            panic!("{text} is not a sequence-l1 loss");
        };
        assert_eq!(gamma_adjustment, adjustment);
    }
}

#[test]
fn losses_without_supervised_pixels_are_zero() {
    let device = default_device();
    let mut target = example(&device);
    target.valid = Tensor::zeros([1, 1, 2, 3], &device);
    for config in [LossConfig::default(), LossConfig::edge_aware()] {
        let value = scalar(config.loss(&example_predictions(&device), &target).unwrap());
        assert_eq!(value, 0.0, "{config:?}");
    }
}

#[test]
fn eals_equals_sequence_l1_without_resize_edges_or_invalid_pixels() {
    let device = default_device();
    let gt = map(&[1.0, 2.0, 3.0, 4.0, 5.0, 6.0], [1, 1, 2, 3], &device);
    let target = LossTarget {
        disparity_bilinear: gt.clone(),
        disparity_nearest: gt,
        valid: Tensor::ones([1, 1, 2, 3], &device),
    };
    let predictions = [Tensor::zeros([1, 1, 2, 3], &device)];
    let eals = scalar(LossConfig::edge_aware().loss(&predictions, &target).unwrap());
    let l1 = scalar(LossConfig::default().loss(&predictions, &target).unwrap());
    assert!((eals - 3.5).abs() < 1e-6 && (l1 - 3.5).abs() < 1e-6, "{eals} {l1}");
}

#[test]
fn gradients_stay_finite_next_to_infinite_ground_truth() {
    let device = default_device().autodiff();
    let target = example(&device);
    let prediction = map(&[0.5, 0.5, 0.5, 0.5, 0.5, 0.5], [1, 1, 2, 3], &device).require_grad();
    for config in [LossConfig::default(), LossConfig::edge_aware()] {
        let loss = config.loss(std::slice::from_ref(&prediction), &target).unwrap();
        let grads = loss.backward();
        let grad = to_vec(prediction.grad(&grads).expect("gradient"));
        assert!(grad.iter().all(|g| g.is_finite()), "{config:?}: {grad:?}");
        // Only supervised pixels get a gradient.
        assert_eq!(grad[3], 0.0);
        assert_eq!(grad[5], 0.0);
    }
}

#[test]
fn sequence_weights_follow_raft_stereo() {
    assert_eq!(sequence_weights(1, 0.9, true), vec![1.0]);
    assert_eq!(sequence_weights(1, 0.9, false), vec![1.0]);
    let plain = sequence_weights(3, 0.9, false);
    assert!((plain[0] - 0.81).abs() < 1e-12 && (plain[1] - 0.9).abs() < 1e-12 && plain[2] == 1.0);
    for n in 2..=32 {
        let w = sequence_weights(n, 0.9, true);
        assert_eq!(w.len(), n);
        assert_eq!(w[n - 1], 1.0);
        // The first prediction always weighs 0.9^15, whatever the iteration count.
        assert!((w[0] - 0.9f64.powi(15)).abs() < 1e-9, "n = {n}: {}", w[0]);
        let ratio = w[0] / w[1];
        assert!(w.windows(2).all(|p| (p[0] / p[1] - ratio).abs() < 1e-9));
    }
}

#[test]
fn configs_read_from_toml() {
    let config: LossConfig = toml::from_str("kind = \"edge-aware\"").unwrap();
    assert_eq!(config, LossConfig::edge_aware());
    assert!(config.needs_nearest());
    let config: LossConfig = toml::from_str("kind = \"edge-aware\"\ntau = 0.5").unwrap();
    assert_eq!(config, LossConfig::EdgeAware { tau: 0.5, gamma: 0.9, max_disparity: 700.0 });
    let config: LossConfig = toml::from_str("kind = \"sequence-l1\"\ngamma = 0.8\nmax_disparity = 192.0").unwrap();
    assert_eq!(
        config,
        LossConfig::SequenceL1 {
            gamma: 0.8,
            max_disparity: 192.0,
            gamma_adjustment: GammaAdjustment::RaftStereo,
            initial_disparity: InitialDisparityTerm::None,
        }
    );
    assert!(!config.needs_nearest());
    assert!(toml::from_str::<LossConfig>("kind = \"sequence-l1\"\ntau = 0.5").is_err());
    let text = toml::to_string(&LossConfig::edge_aware()).unwrap();
    assert_eq!(toml::from_str::<LossConfig>(&text).unwrap(), LossConfig::edge_aware());
}

/// Random small disparity maps: `(values, shape)`.
fn disparity_map() -> impl Strategy<Value = (Vec<f32>, [usize; 4])> {
    (1usize..3, 1usize..5, 1usize..6)
        .prop_flat_map(|(n, h, w)| (proptest::collection::vec(0.0f32..200.0, n * h * w), Just([n, 1, h, w])))
}

proptest! {
    #![proptest_config(ProptestConfig::with_cases(32))]

    #[test]
    fn edge_mask_is_all_ones_without_resize((values, shape) in disparity_map(), tau in 0.0f64..5.0) {
        let device = default_device();
        let d = map(&values, shape, &device);
        let total = values.len() as f32;
        prop_assert_eq!(count(edge_mask(d.clone(), d, tau)), total);
    }

    #[test]
    fn edge_mask_is_all_ones_when_tau_exceeds_the_range(
        (a, shape) in disparity_map(),
        seed in any::<u64>(),
    ) {
        let device = default_device();
        // A second map in the same range, shuffled by a cheap LCG.
        let mut state = seed;
        let b: Vec<f32> = a.iter().map(|_| {
            state = state.wrapping_mul(6364136223846793005).wrapping_add(1442695040888963407);
            (state >> 40) as f32 / (1u64 << 24) as f32 * 200.0
        }).collect();
        let mask = edge_mask(map(&a, shape, &device), map(&b, shape, &device), 200.0);
        prop_assert_eq!(count(mask), a.len() as f32);
    }

    #[test]
    fn edge_mask_shrinks_as_tau_falls(
        (a, shape) in disparity_map(),
        offsets in proptest::collection::vec(-3.0f32..3.0, 30),
        taus in proptest::collection::vec(0.0f64..4.0, 2..6),
    ) {
        let device = default_device();
        let b: Vec<f32> = a.iter().zip(offsets.iter().cycle()).map(|(x, o)| x + o).collect();
        let (a, b) = (map(&a, shape, &device), map(&b, shape, &device));
        let mut taus = taus;
        taus.sort_by(f64::total_cmp);
        let counts: Vec<f32> =
            taus.iter().map(|&tau| count(edge_mask(a.clone(), b.clone(), tau))).collect();
        prop_assert!(counts.windows(2).all(|c| c[0] <= c[1]), "{:?} at {:?}", counts, taus);
    }
}

/// `LossConfig::variants` lists every kind serde accepts, once, in the enum's order, each valid
/// and named as TOML names it.
#[test]
fn every_kind_is_listed() {
    let accepted = dgstereo_core::serde_names::accepted_kinds::<LossConfig>("kind").unwrap();
    let variants = LossConfig::variants();
    let listed: Vec<&str> = variants.iter().map(LossConfig::kind).collect();
    assert_eq!(listed, accepted);
    for variant in variants {
        assert!(variant.validate().is_ok(), "{variant:?}");
        assert_eq!(toml::from_str::<LossConfig>(&toml::to_string(&variant).unwrap()).unwrap(), variant);
    }
}

/// Invalid values are problems keyed relative to the loss table.
#[test]
fn invalid_values_are_keyed_problems() {
    let keys = |config: LossConfig| config.problems().into_iter().map(|p| p.key).collect::<Vec<_>>();
    assert_eq!(keys(LossConfig::EdgeAware { tau: -1.0, gamma: 0.9, max_disparity: 700.0 }), ["tau"]);
    assert_eq!(
        keys(LossConfig::SequenceL1 {
            gamma: 0.0,
            max_disparity: f64::NAN,
            gamma_adjustment: GammaAdjustment::RaftStereo,
            initial_disparity: InitialDisparityTerm::SmoothL1,
        }),
        ["gamma", "max_disparity"]
    );
    assert!(LossConfig::edge_aware().problems().is_empty());
}

#[test]
fn no_prediction_or_a_prediction_of_another_shape_is_a_shape_error() {
    let device = default_device();
    for config in LossConfig::variants() {
        let e = config.loss(&[], &example(&device)).unwrap_err();
        assert!(
            matches!(e, dgstereo_core::Error::Shape(_)) && e.to_string().contains("at least one prediction"),
            "{e}"
        );
        let e = config.terms(&[], &example(&device)).unwrap_err();
        assert!(matches!(e, dgstereo_core::Error::Shape(_)), "{e}");
        let wrong = [Tensor::zeros([1, 1, 3, 2], &device)];
        let e = config.loss(&wrong, &example(&device)).unwrap_err();
        assert!(e.to_string().contains("[1, 1, 3, 2]") && e.to_string().contains("[1, 1, 2, 3]"), "{e}");
    }
}
