//! Two Winograd convolutions that share a block of input channels, the shared block transformed
//! once: what the ConvGRU's gate and candidate convolutions need.
//!
//! The gates convolve `[h, x]`, the candidate `[r·h, x]`, where `r` comes out of the gates: the
//! candidate can only start once the gates are done, but its `x` channels are the gates' `x`
//! channels. The candidate's products are linear over its input channels, `M = U_h V_{r·h} +
//! U_x V_x`, so [`first`] computes the gates and, band by band from the transformed input it
//! already holds, the candidate's share `U_x V_x` of the shared channels; [`second`] transforms
//! only `r·h`, adds its products to that share and transforms the sum out. The input transform of
//! the shared channels (two thirds of the candidate's at the GRU's 128 + 256 channels) is saved,
//! at the memory of the pending share (`O x α² x tiles`, 35 MB for the GRU at 1/4 resolution of
//! a KITTI frame).

use super::*;
use crate::host_conv::matmul_strided_with;

/// The second convolution's products over the shared channels, band by band, waiting for the
/// rest of its input.
pub(crate) struct Pending {
    variant: &'static Variant,
    plan: Plan,
    /// The second convolution's transformed weights, `[O][α²][C]` over all its input channels.
    u: std::sync::Arc<Vec<f32>>,
    o: usize,
    /// Input channels the second convolution has in all (its own ones first, then the shared).
    c: usize,
    padding: [(usize, usize); 2],
    /// Per job: `[O][α²][T]`.
    sums: Vec<Vec<f32>>,
}

/// The first convolution (`wt_first`, all channels of `x`) with its bias and epilogue, and the
/// second convolution's products over the shared channels, the last `shared` channels of `x`.
/// The second convolution's weight `wt_second` covers `C2 = C2_own + shared` channels, its own
/// channels first.
///
/// # Shapes
/// - `x`: `x_dims = [N, C, H, W]`; `wt_first`: `[O1, C, 3, 3]`; `wt_second`: `[O2, C2, 3, 3]`
/// - output `[N, O1, H_out, W_out]` as [`winograd_conv`]
#[allow(clippy::too_many_arguments)]
pub(crate) fn first(
    variant: &'static Variant,
    x: &[f32],
    x_dims: [usize; 4],
    [wt_first, wt_second]: [&[f32]; 2],
    [o1, o2]: [usize; 2],
    c2: usize,
    shared: usize,
    bias: Option<&[f32]>,
    padding: [(usize, usize); 2],
    epilogue: Epilogue,
) -> ((Vec<f32>, [usize; 4]), Pending) {
    let c = x_dims[1];
    assert!(shared <= c && shared <= c2, "split winograd: {shared} shared channels of {c} and {c2}");
    assert_eq!(wt_first.len(), o1 * c * 9, "split winograd: the first weight is not [{o1}, {c}, 3, 3]");
    assert_eq!(wt_second.len(), o2 * c2 * 9, "split winograd: the second weight is not [{o2}, {c2}, 3, 3]");
    let plan = Plan::new(variant, x_dims, padding);
    let (u1, u2) = (transformed_weights(variant, wt_first, o1, c), transformed_weights(variant, wt_second, o2, c2));
    let k2 = plan.k2;
    // Every element of a job's sums is written by its first product (no accumulation), so the
    // buffers come from the calling thread's pool without being cleared.
    let mut sums: Vec<Vec<f32>> = SUMS.with_borrow_mut(|pool| {
        (0..plan.jobs())
            .map(|job| {
                let mut sum = pool.pop().unwrap_or_default();
                reuse_buffer(&mut sum, o2 * k2 * plan.tiles(job));
                sum
            })
            .collect()
    });
    let out = plan.run(x, o1, &mut sums, |job, image, planes, sum, [v, mm, scratch]| {
        let (tile_rows, t) = (plan.tile_rows(job), plan.tiles(job));
        let (v, mm) = (reuse_buffer(v, k2 * c * t), reuse_buffer(mm, k2 * o1 * t));
        transform_inputs(variant, v, image, plan.tiling, tile_rows.clone(), scratch);
        let (own1, own2) = (c - shared, c2 - shared);
        for k in 0..k2 {
            matmul_strided(&mut mm[k * t..], k2 * t, &u1[k * c..], k2 * c, &v[k * t..], k2 * t, [o1, t, c]);
            // The shared channels are the last `shared` of both inputs.
            let (lhs, rhs) = (&u2[k * c2 + own2..], &v[(own1 * k2 + k) * t..]);
            matmul_strided(&mut sum[k * t..], k2 * t, lhs, k2 * c2, rhs, k2 * t, [o2, t, shared]);
        }
        transform_outputs(variant, mm, planes, bias, epilogue, plan.tiling, tile_rows.len(), scratch);
    });
    (out, Pending { variant, plan, u: u2, o: o2, c: c2, padding, sums })
}

/// The second convolution of [`first`]: its own input channels `x` (the first `C2 - shared` of
/// its input) added to the pending products of the shared ones, with its bias and epilogue.
///
/// # Shapes
/// - `x`: `x_dims = [N, C2 - shared, H, W]`, the size of the first convolution's input
/// - output `[N, O2, H_out, W_out]`
pub(crate) fn second(
    pending: Pending,
    x: &[f32],
    x_dims: [usize; 4],
    bias: Option<&[f32]>,
    epilogue: Epilogue,
) -> (Vec<f32>, [usize; 4]) {
    let Pending { variant, plan: first_plan, u, o, c: c2, padding, mut sums } = pending;
    let own = x_dims[1];
    let plan = Plan::new(variant, x_dims, padding);
    let same = |p: &Plan| (p.n, p.out_h, p.tiling.out_w, p.tiling.h, p.tiling.w, p.bands, p.band_rows);
    assert!(same(&plan) == same(&first_plan), "split winograd: the second input's size differs from the first's");
    assert!(own <= c2, "split winograd: {own} channels of the second convolution's {c2}");
    let k2 = plan.k2;
    let out = plan.run(x, o, &mut sums, |job, image, planes, sum, [v, _, scratch]| {
        let (tile_rows, t) = (plan.tile_rows(job), plan.tiles(job));
        let v = reuse_buffer(v, k2 * own * t);
        transform_inputs(variant, v, image, plan.tiling, tile_rows.clone(), scratch);
        for k in 0..k2 {
            let (lhs, rhs) = (&u[k * c2..], &v[k * t..]);
            matmul_strided_with(&mut sum[k * t..], k2 * t, lhs, k2 * c2, rhs, k2 * t, [o, t, own], true);
        }
        transform_outputs(variant, sum, planes, bias, epilogue, plan.tiling, tile_rows.len(), scratch);
    });
    SUMS.with_borrow_mut(|pool| pool.extend(sums));
    out
}

thread_local! {
    /// The calling thread's pending-sum buffers, returned by [`second`] for the next pair (a GRU
    /// step runs one pair per level per iteration; clearing fresh buffers each time cost a
    /// memory pass over them).
    static SUMS: std::cell::RefCell<Vec<Vec<f32>>> = const { std::cell::RefCell::new(Vec::new()) };
}

#[cfg(test)]
mod tests {
    use super::*;

    /// Both convolutions of a split pair against [`winograd_conv`] of the whole inputs, for both
    /// variants and a batch of two.
    #[test]
    fn a_split_pair_equals_the_two_whole_convolutions() {
        let random = |len: usize, seed: u32| -> Vec<f32> {
            (0..len).map(|i| (((i as u32).wrapping_mul(2_654_435_761) ^ seed) % 2001) as f32 / 1000.0 - 1.0).collect()
        };
        let (n, own1, own2, shared, o1, o2, h, w) = (2, 5, 4, 6, 7, 3, 13, 18);
        let c1 = own1 + shared;
        let c2 = own2 + shared;
        let x1 = random(n * c1 * h * w, 1);
        let own2_values = random(n * own2 * h * w, 2);
        let (wt1, wt2) = (random(o1 * c1 * 9, 3), random(o2 * c2 * 9, 4));
        let (b1, b2) = (random(o1, 5), random(o2, 6));
        // The second convolution's whole input: its own channels, then the first's shared ones.
        let plane = h * w;
        let mut x2 = Vec::with_capacity(n * c2 * plane);
        for b in 0..n {
            x2.extend_from_slice(&own2_values[b * own2 * plane..][..own2 * plane]);
            x2.extend_from_slice(&x1[(b * c1 + own1) * plane..][..shared * plane]);
        }
        let padding = [(1, 1), (1, 1)];
        for variant in [&F2, &F4] {
            let (got1, pending) = first(
                variant,
                &x1,
                [n, c1, h, w],
                [&wt1, &wt2],
                [o1, o2],
                c2,
                shared,
                Some(&b1),
                padding,
                Epilogue::Relu,
            );
            let got2 = second(pending, &own2_values, [n, own2, h, w], Some(&b2), Epilogue::Linear);
            let conv1 = Conv3x3 {
                x: &x1,
                x_dims: [n, c1, h, w],
                wt: &wt1,
                o: o1,
                bias: Some(&b1),
                padding,
                epilogue: Epilogue::Relu,
            };
            let want1 = winograd_conv(variant, &conv1);
            let conv2 = Conv3x3 {
                x: &x2,
                x_dims: [n, c2, h, w],
                wt: &wt2,
                o: o2,
                bias: Some(&b2),
                padding,
                epilogue: Epilogue::Linear,
            };
            let want2 = winograd_conv(variant, &conv2);
            for ((got, want), which) in [(got1, want1), (got2, want2)].into_iter().zip(["first", "second"]) {
                assert_eq!(got.1, want.1, "F({}) {which}", variant.m);
                let worst = got.0.iter().zip(&want.0).map(|(g, w)| (g - w).abs()).fold(0.0, f32::max);
                assert!(worst < 1e-4, "F({}) {which}: {worst}", variant.m);
            }
        }
    }
}
