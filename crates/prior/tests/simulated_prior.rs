//! The documented properties of the `simulated` prior.

use burn::tensor::Tensor;
use dgstereo_core::tensor::{from_vec, to_vec};
use dgstereo_prior::{PriorInput, PriorProvider, SimulatedPrior, SimulatedPriorConfig};

const H: usize = 24;
const W: usize = 48;

/// Background disparity 5 with a foreground square of disparity 20 at rows 6..18, cols 24..36.
fn square_scene() -> Vec<f32> {
    let mut d = vec![5.0f32; H * W];
    for y in 6..18 {
        for x in 24..36 {
            d[y * W + x] = 20.0;
        }
    }
    d
}

/// A smooth slanted scene with disparities 2..30.
fn slanted_scene() -> Vec<f32> {
    (0..H * W).map(|i| 2.0 + 28.0 * ((i % W) as f32 / W as f32) * (0.5 + 0.5 * (i / W) as f32 / H as f32)).collect()
}

fn input(gt: &[f32]) -> PriorInput {
    let device = dgstereo_core::default_device();
    PriorInput {
        left: Tensor::zeros([1, 3, H, W], &device),
        right: Tensor::zeros([1, 3, H, W], &device),
        gt_disparity: Some(from_vec(gt.to_vec(), [1, 1, H, W], &device)),
        names: vec!["scene".into()],
    }
}

fn run(config: SimulatedPriorConfig, gt: &[f32]) -> (Vec<f32>, Vec<f32>) {
    let prior = SimulatedPrior::new(config).unwrap().provide(&input(gt)).unwrap().unwrap();
    assert_eq!(prior.left.dims(), [1, 1, H, W]);
    (to_vec(prior.left), to_vec(prior.right))
}

/// Least-squares fit `y = a x + b`; returns `(a, b, rms residual)`.
fn affine_fit(x: &[f32], y: &[f32]) -> (f64, f64, f64) {
    let n = x.len() as f64;
    let (mx, my) = (x.iter().map(|&v| v as f64).sum::<f64>() / n, y.iter().map(|&v| v as f64).sum::<f64>() / n);
    let sxy: f64 = x.iter().zip(y).map(|(&a, &b)| (a as f64 - mx) * (b as f64 - my)).sum();
    let sxx: f64 = x.iter().map(|&a| (a as f64 - mx).powi(2)).sum();
    let a = sxy / sxx;
    let b = my - a * mx;
    let rms = (x.iter().zip(y).map(|(&u, &v)| (v as f64 - a * u as f64 - b).powi(2)).sum::<f64>() / n).sqrt();
    (a, b, rms)
}

#[test]
fn deterministic_per_seed() {
    let gt = slanted_scene();
    let config = |seed| SimulatedPriorConfig { seed, ..Default::default() };
    assert_eq!(run(config(1), &gt), run(config(1), &gt));
    assert_ne!(run(config(1), &gt).0, run(config(2), &gt).0);
}

#[test]
fn without_distortion_blur_and_noise_the_prior_is_an_unknown_affine_map_of_disparity() {
    let gt = slanted_scene();
    let max = gt.iter().copied().fold(0.0, f32::max) as f64;
    let mut scales = Vec::new();
    for seed in 0..6 {
        let config =
            SimulatedPriorConfig { seed, gamma: [1.0, 1.0], blur_sigma: 0.0, noise_std: 0.0, ..Default::default() };
        let (left, _) = run(config.clone(), &gt);
        let (a, b, rms) = affine_fit(&gt, &left);
        assert!(rms < 1e-5, "seed {seed}: not affine, rms {rms}");
        let (scale, shift) = (a * max, b);
        assert!(scale >= config.scale[0] as f64 - 1e-5 && scale <= config.scale[1] as f64 + 1e-5, "scale {scale}");
        assert!(shift >= config.shift[0] as f64 - 1e-5 && shift <= config.shift[1] as f64 + 1e-5, "shift {shift}");
        scales.push(scale);
    }
    let spread =
        scales.iter().copied().fold(f64::NEG_INFINITY, f64::max) - scales.iter().copied().fold(f64::INFINITY, f64::min);
    assert!(spread > 0.1, "the scale must vary with the seed: {scales:?}");
}

#[test]
fn gamma_keeps_the_depth_order_but_is_not_affine() {
    let gt = slanted_scene();
    let config = SimulatedPriorConfig { gamma: [2.5, 2.5], ..SimulatedPriorConfig::exact(0) };
    let (left, _) = run(config, &gt);
    let mut order: Vec<usize> = (0..gt.len()).collect();
    order.sort_by(|&i, &j| gt[i].total_cmp(&gt[j]));
    assert!(order.windows(2).all(|p| left[p[0]] <= left[p[1]] + 1e-7), "order not kept");
    let (_, _, rms) = affine_fit(&gt, &left);
    assert!(rms > 0.01, "gamma 2.5 should bend the relation, rms {rms}");
}

#[test]
fn blur_rounds_depth_edges() {
    let gt = square_scene();
    let row = 12;
    let distinct_in_row = |values: &[f32]| {
        let mut v: Vec<f32> = values[row * W..(row + 1) * W].to_vec();
        v.sort_by(f32::total_cmp);
        v.dedup_by(|a, b| (*a - *b).abs() < 1e-6);
        v.len()
    };
    let (sharp, _) = run(SimulatedPriorConfig::exact(0), &gt);
    assert_eq!(distinct_in_row(&sharp), 2);
    let (blurred, _) = run(SimulatedPriorConfig { blur_sigma: 1.0, ..SimulatedPriorConfig::exact(0) }, &gt);
    assert!(distinct_in_row(&blurred) >= 5, "the edge must become a ramp");
    let edge = &blurred[row * W + 16..row * W + 30];
    assert!(edge.windows(2).all(|p| p[0] <= p[1] + 1e-6), "ramp rises monotonically: {edge:?}");
    // Farther than the blur radius (3 px) from any edge the plateaus keep their values.
    assert!((blurred[row * W + 2] - sharp[row * W + 2]).abs() < 1e-5);
    assert!((blurred[row * W + 30] - sharp[row * W + 30]).abs() < 1e-5);
}

#[test]
fn noise_has_the_configured_standard_deviation() {
    let gt = slanted_scene();
    let (left, _) =
        run(SimulatedPriorConfig { noise_std: 0.05, shift: [0.5, 0.5], ..SimulatedPriorConfig::exact(3) }, &gt);
    let (_, _, rms) = affine_fit(&gt, &left);
    assert!((rms - 0.05).abs() < 0.01, "residual std {rms}");
}

#[test]
fn holes_are_filled_from_the_background_and_output_is_dense() {
    let mut gt = square_scene();
    // An occlusion-like hole just right of the square, and a non-finite sample.
    for y in 6..18 {
        for x in 36..40 {
            gt[y * W + x] = 0.0;
        }
    }
    gt[3] = f32::NAN;
    let (left, right) = run(SimulatedPriorConfig::exact(0), &gt);
    assert!(left.iter().chain(&right).all(|v| v.is_finite() && *v >= 0.0));
    let background = left[0];
    for x in 36..40 {
        assert_eq!(left[10 * W + x], background, "hole at x={x} should continue the background");
    }
    assert_eq!(left[3], background);
}

#[test]
fn right_view_is_the_left_disparity_warped() {
    let gt = square_scene();
    let (left, right) = run(SimulatedPriorConfig::exact(0), &gt);
    let row = 10;
    // In the right image the square (disparity 20) spans columns 4..16, the left's 24..36.
    for x in 0..W {
        let expected = if (4..16).contains(&x) { left[row * W + 30] } else { left[row * W] };
        assert_eq!(right[row * W + x], expected, "column {x}");
    }
    // Rows without the square are the background everywhere, including the border strip.
    assert!(right[..W].iter().all(|&v| v == left[0]));
}

#[test]
fn shifts_below_zero_are_clamped_and_missing_ground_truth_is_an_error() {
    let gt = slanted_scene();
    let (left, _) = run(SimulatedPriorConfig { shift: [-0.5, -0.5], ..SimulatedPriorConfig::exact(0) }, &gt);
    assert!(left.iter().all(|&v| v >= 0.0));
    assert!(left.contains(&0.0));
    let mut no_gt = input(&gt);
    no_gt.gt_disparity = None;
    let err = SimulatedPrior::new(SimulatedPriorConfig::default()).unwrap().provide(&no_gt).unwrap_err().to_string();
    assert!(err.contains("simulated") && err.contains("ground-truth"), "{err}");
    let bad = SimulatedPriorConfig { gamma: [0.0, 1.0], ..Default::default() };
    assert!(SimulatedPrior::new(bad).unwrap_err().to_string().contains("prior.gamma"));
}

/// Spearman's rank correlation (ties broken by index; the scenes have few ties).
fn rank_correlation(x: &[f32], y: &[f32]) -> f64 {
    let ranks = |v: &[f32]| {
        let mut order: Vec<usize> = (0..v.len()).collect();
        order.sort_by(|&i, &j| v[i].total_cmp(&v[j]));
        let mut rank = vec![0f64; v.len()];
        for (r, &i) in order.iter().enumerate() {
            rank[i] = r as f64;
        }
        rank
    };
    let (rx, ry) = (ranks(x), ranks(y));
    let n = x.len() as f64;
    let d2: f64 = rx.iter().zip(&ry).map(|(a, b)| (a - b).powi(2)).sum();
    1.0 - 6.0 * d2 / (n * (n * n - 1.0))
}

#[test]
fn with_default_errors_the_prior_still_orders_depths_like_the_ground_truth() {
    let gt = slanted_scene();
    for seed in 0..4 {
        let (left, right) = run(SimulatedPriorConfig { seed, ..Default::default() }, &gt);
        assert!(left.iter().chain(&right).all(|v| v.is_finite() && *v >= 0.0), "seed {seed}");
        let rho = rank_correlation(&gt, &left);
        assert!(rho > 0.95, "seed {seed}: rank correlation {rho}");
        // ...but it is not the ground truth up to one fixed affine map: the errors are real.
        let (_, _, rms) = affine_fit(&gt, &left);
        assert!(rms > 1e-3, "seed {seed}: no error left, rms {rms}");
    }
}

#[test]
fn batching_does_not_change_an_elements_prior() {
    let (square, slanted) = (square_scene(), slanted_scene());
    let device = dgstereo_core::default_device();
    let both: Vec<f32> = square.iter().chain(&slanted).copied().collect();
    let batch = PriorInput {
        left: Tensor::zeros([2, 3, H, W], &device),
        right: Tensor::zeros([2, 3, H, W], &device),
        gt_disparity: Some(from_vec(both, [2, 1, H, W], &device)),
        names: vec!["a".into(), "b".into()],
    };
    let config = SimulatedPriorConfig { seed: 11, ..Default::default() };
    let prior = SimulatedPrior::new(config.clone()).unwrap().provide(&batch).unwrap().unwrap();
    let (left, right) = (to_vec(prior.left), to_vec(prior.right));
    let (alone_left, alone_right) = run(config, &slanted);
    assert_eq!(&left[H * W..], alone_left.as_slice());
    assert_eq!(&right[H * W..], alone_right.as_slice());
}
