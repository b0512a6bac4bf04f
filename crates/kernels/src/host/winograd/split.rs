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

use dgstereo_core::tensor::reuse_buffer;

use super::positions::Positions;
use super::transforms::*;
use crate::bf16_product::Bf16Unit;
use crate::geometry::Epilogue;

/// The second convolution's products over the shared channels, band by band, waiting for the
/// rest of its input.
pub(crate) struct Pending {
    variant: &'static Variant,
    plan: Plan,
    /// The second convolution's transformed weights over its own input channels (the first of
    /// its input).
    u: Positions,
    o: usize,
    /// The second convolution's own input channels.
    own: usize,
    padding: [(usize, usize); 2],
    /// Per job: `[O][α²][T]`.
    sums: Vec<Vec<f32>>,
}

/// The first convolution (`wt_first`, all channels of `x`) with its bias and epilogue, and the
/// second convolution's products over the shared channels, the last `shared` channels of `x`.
/// The second convolution's weight `wt_second` covers `C2 = C2_own + shared` channels, its own
/// channels first. The products are in bf16 with f32 sums on `unit` where it is given.
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
    unit: Option<Bf16Unit>,
) -> ((Vec<f32>, [usize; 4]), Pending) {
    let c = x_dims[1];
    assert!(shared <= c && shared <= c2, "split winograd: {shared} shared channels of {c} and {c2}");
    assert_eq!(wt_first.len(), o1 * c * 9, "split winograd: the first weight is not [{o1}, {c}, 3, 3]");
    assert_eq!(wt_second.len(), o2 * c2 * 9, "split winograd: the second weight is not [{o2}, {c2}, 3, 3]");
    let plan = Plan::new(variant, x_dims, padding);
    let own2 = c2 - shared;
    let u1 = Positions::new(variant, wt_first, [o1, c], 0..c, unit);
    let u2_shared = Positions::new(variant, wt_second, [o2, c2], own2..c2, unit);
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
        let own1 = c - shared;
        for k in 0..k2 {
            u1.product([k, k2], &mut mm[k * t..], k2 * t, &v[k * t..], k2 * t, t, false);
            // The shared channels are the last `shared` of both inputs.
            u2_shared.product([k, k2], &mut sum[k * t..], k2 * t, &v[(own1 * k2 + k) * t..], k2 * t, t, false);
        }
        transform_outputs(variant, mm, planes, bias, epilogue, plan.tiling, tile_rows.len(), scratch);
    });
    let u = Positions::new(variant, wt_second, [o2, c2], 0..own2, unit);
    (out, Pending { variant, plan, u, o: o2, own: own2, padding, sums })
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
    let Pending { variant, plan: first_plan, u, o, own: c2_own, padding, mut sums } = pending;
    let own = x_dims[1];
    let plan = Plan::new(variant, x_dims, padding);
    let same = |p: &Plan| (p.n, p.out_h, p.tiling.out_w, p.tiling.h, p.tiling.w, p.bands, p.band_rows);
    assert!(same(&plan) == same(&first_plan), "split winograd: the second input's size differs from the first's");
    assert!(own == c2_own, "split winograd: {own} channels where the second convolution has {c2_own} of its own");
    let k2 = plan.k2;
    let out = plan.run(x, o, &mut sums, |job, image, planes, sum, [v, _, scratch]| {
        let (tile_rows, t) = (plan.tile_rows(job), plan.tiles(job));
        let v = reuse_buffer(v, k2 * own * t);
        transform_inputs(variant, v, image, plan.tiling, tile_rows.clone(), scratch);
        for k in 0..k2 {
            u.product([k, k2], &mut sum[k * t..], k2 * t, &v[k * t..], k2 * t, t, true);
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
