//! The edge mask on ground truth that was actually resized: bilinear resizing at scale factor 1 is
//! the identity (all pixels kept, even at `tau = 0`), and a downsampled depth step is dropped
//! exactly where bilinear interpolation mixes the two surfaces.

use dgstereo_core::default_device;
use dgstereo_core::tensor::{from_vec, to_vec};
use dgstereo_kernels::resize_bilinear;
use dgstereo_loss::edge_mask;
use proptest::prelude::*;

proptest! {
    #![proptest_config(ProptestConfig::with_cases(16))]

    #[test]
    fn scale_factor_one_keeps_every_pixel(
        h in 1usize..12,
        w in 1usize..12,
        seed in any::<u64>(),
        tau in 0.0f64..2.0,
    ) {
        let device = default_device();
        let mut state = seed;
        let values: Vec<f32> = (0..h * w).map(|_| {
            state = state.wrapping_mul(6364136223846793005).wrapping_add(1442695040888963407);
            (state >> 40) as f32 / (1u64 << 24) as f32 * 300.0
        }).collect();
        let nearest = from_vec(values, [1, 1, h, w], &device);
        let bilinear = resize_bilinear(nearest.clone(), [h, w], false);
        let mask = to_vec(edge_mask(bilinear, nearest, tau));
        prop_assert!(mask.iter().all(|m| *m == 1.0), "{:?}", mask);
    }

    /// Halving the width of a map with a step between columns `2k` and `2k + 1`: bilinear gives
    /// output column `k` the mean of the two sides, nearest gives it the left side. The mask drops
    /// that column (every row) when `tau` is below half the step, and nothing else.
    #[test]
    fn a_halved_step_is_dropped_where_it_is_mixed(
        k in 0usize..6,
        extra in 1usize..6,
        h in 1usize..4,
        low in 0.0f32..100.0,
        step in 1.0f32..50.0,
    ) {
        let device = default_device();
        let w_out = k + extra;
        let w = 2 * w_out;
        let edge = 2 * k + 1;
        let full: Vec<f32> = (0..h * w).map(|i| if i % w < edge { low } else { low + step }).collect();
        // Nearest at scale 1/2 (PyTorch's `floor(x * 2)`): the even columns.
        let nearest: Vec<f32> = (0..h * w_out).map(|i| full[(i / w_out) * w + 2 * (i % w_out)]).collect();
        let bilinear = resize_bilinear(from_vec(full, [1, 1, h, w], &device), [h, w_out], false);
        let nearest = from_vec(nearest, [1, 1, h, w_out], &device);
        let below = to_vec(edge_mask(bilinear.clone(), nearest.clone(), 0.45 * step as f64));
        for (i, m) in below.iter().enumerate() {
            prop_assert_eq!(*m, if i % w_out == k { 0.0 } else { 1.0 }, "column {}", i % w_out);
        }
        let above = to_vec(edge_mask(bilinear, nearest, 0.55 * step as f64));
        prop_assert!(above.iter().all(|m| *m == 1.0));
    }
}
