//! The instance norm's and the ReLU's forward and backward on host buffers, for training
//! (`crate::autodiff::norm`).
//!
//! Design decision: burn's autodiff of an instance norm records six element-wise operations and
//! its ReLU a seventh, each a serial pass over the activation on burn Flex's calling thread, and
//! as many again in the backward, while the worker threads wait. Here each `(image, channel)`
//! plane is one rayon task in both directions: the forward keeps the normalised plane and its
//! inverse deviation, and the backward is the closed form
//! `dx = inv · (g − mean(g) − x̂ · mean(g · x̂))` (with `g` masked by the ReLU), its means in
//! `f64` over independent lanes as the inference kernel's statistics are.

use rayon::prelude::*;

use super::fresh::{chunk_of, collect_chunks, map1, map2};
use crate::host::norm::lane_sum;

/// What the forward of [`instance_norm_forward`] keeps for the backward.
#[derive(Debug, Clone)]
pub struct InstanceNormSaved {
    /// The normalised planes before the ReLU (`x̂`), row-major `[N, C, H, W]`.
    pub normalized: Vec<f32>,
    /// Per plane, `1 / sqrt(var + epsilon)`.
    pub inv_std: Vec<f32>,
}

/// Instance norm of every plane of `x` (planes of `plane` values; biased variance), then
/// `max(0, ·)` when `relu`. Returns the output and what the backward needs; without the ReLU
/// the output is `normalized` itself, so the caller may keep one copy.
pub fn instance_norm_forward(x: &[f32], plane: usize, epsilon: f64, relu: bool) -> (Vec<f32>, InstanceNormSaved) {
    let plane = plane.max(1);
    // Per plane the affine map `v · a + b` that normalises it; `a` is `1 / σ`.
    let affine: Vec<(f32, f32)> = x
        .par_chunks(plane)
        .map(|p| {
            let mean = lane_sum(p, |v| v) / plane as f64;
            let var = lane_sum(p, |v| (v - mean) * (v - mean)) / plane as f64;
            let inv = 1.0 / (var + epsilon).sqrt();
            (inv as f32, (-mean * inv) as f32)
        })
        .collect();
    let normalized = collect_chunks(x.len(), plane, |k| {
        let (a, b) = affine[k];
        chunk_of(x, plane, k).iter().map(move |&v| v * a + b)
    });
    let inv_std = affine.iter().map(|&(a, _)| a).collect();
    let out = if relu { relu_of(&normalized) } else { normalized.clone() };
    (out, InstanceNormSaved { normalized, inv_std })
}

/// The gradient of [`instance_norm_forward`] with respect to its input, given the output
/// gradient `g`.
pub fn instance_norm_backward(g: &[f32], saved: &InstanceNormSaved, relu: bool) -> Vec<f32> {
    let planes = saved.inv_std.len().max(1);
    let plane = (g.len() / planes).max(1);
    collect_chunks(g.len(), plane, |k| {
        let (g, xh, inv) = (chunk_of(g, plane, k), chunk_of(&saved.normalized, plane, k), saved.inv_std[k]);
        let masked = |i: usize| if relu && xh[i] <= 0.0 { 0.0 } else { g[i] };
        let gm: Vec<f32> = (0..g.len()).map(masked).collect();
        let mean_g = lane_sum(&gm, |v| v) / plane as f64;
        let gx: Vec<f32> = gm.iter().zip(xh).map(|(g, x)| g * x).collect();
        let mean_gx = lane_sum(&gx, |v| v) / plane as f64;
        let (mean_g, mean_gx) = (mean_g as f32, mean_gx as f32);
        gm.into_iter().zip(xh).map(move |(g, &x)| inv * (g - mean_g - x * mean_gx))
    })
}

/// `max(0, v)` of every value, in parallel chunks.
pub fn relu_of(x: &[f32]) -> Vec<f32> {
    map1(x, |v| v.max(0.0))
}

/// `max(0, a + b)`, in parallel chunks.
pub fn add_relu_of(a: &[f32], b: &[f32]) -> Vec<f32> {
    assert_eq!(a.len(), b.len(), "add_relu: shapes differ");
    map2(a, b, |a, b| (a + b).max(0.0))
}

/// The gradient through a ReLU whose output was `y`: `g` where `y > 0`, else 0.
pub fn relu_backward(g: &[f32], y: &[f32]) -> Vec<f32> {
    assert_eq!(g.len(), y.len(), "relu_backward: shapes differ");
    map2(g, y, |g, y| if y <= 0.0 { 0.0 } else { g })
}

/// `x · scale[c] + shift[c]` on every plane of channel `c` (`x` row-major `[N, C, plane]` with
/// `scale.len()` channels), then `max(0, ·)` when `relu`: a frozen batch norm in training.
pub fn channel_affine_forward(x: &[f32], plane: usize, scale: &[f32], shift: &[f32], relu: bool) -> Vec<f32> {
    let channels = scale.len().max(1);
    assert_eq!(shift.len(), scale.len(), "channel affine: scale and shift differ in length");
    let plane = checked_plane(x.len(), plane, channels);
    collect_chunks(x.len(), plane, |k| {
        let (a, b) = (scale[k % channels], shift[k % channels]);
        chunk_of(x, plane, k).iter().map(move |&v| if relu { (v * a + b).max(0.0) } else { v * a + b })
    })
}

/// The gradients of [`channel_affine_forward`] from the output gradient `g`: `(dx, dscale,
/// dshift)`, with `g` masked where the output `y` is not positive when `y` is given (the ReLU's
/// output): `dx = g·scale[c]`, `dscale[c] = Σ g·x`, `dshift[c] = Σ g` over the channel's planes
/// (sums in `f64`).
pub fn channel_affine_backward(
    g: &[f32],
    x: &[f32],
    y: Option<&[f32]>,
    plane: usize,
    scale: &[f32],
) -> (Vec<f32>, Vec<f32>, Vec<f32>) {
    let channels = scale.len().max(1);
    assert!(g.len() == x.len() && y.is_none_or(|y| y.len() == g.len()), "channel affine backward: shapes differ");
    let plane = checked_plane(g.len(), plane, channels);
    let masked = |k: usize| {
        let (g, y) = (chunk_of(g, plane, k), y.map(|y| chunk_of(y, plane, k)));
        g.iter().enumerate().map(move |(i, &g)| if y.is_some_and(|y| y[i] <= 0.0) { 0.0 } else { g })
    };
    let dx = collect_chunks(g.len(), plane, |k| masked(k).map(move |g| g * scale[k % channels]));
    let sums: Vec<(f64, f64)> = (0..g.len() / plane)
        .into_par_iter()
        .map(|k| {
            let gm: Vec<f32> = masked(k).collect();
            let gx: Vec<f32> = gm.iter().zip(chunk_of(x, plane, k)).map(|(g, x)| g * x).collect();
            (lane_sum(&gx, |v| v), lane_sum(&gm, |v| v))
        })
        .collect();
    let (mut dscale, mut dshift) = (vec![0.0f64; channels], vec![0.0f64; channels]);
    for (k, (gx, gs)) in sums.into_iter().enumerate() {
        dscale[k % channels] += gx;
        dshift[k % channels] += gs;
    }
    let narrow = |v: Vec<f64>| v.into_iter().map(|v| v as f32).collect();
    (dx, narrow(dscale), narrow(dshift))
}

/// `plane` (at least 1), checked to divide `len` values into whole images of `channels` planes.
fn checked_plane(len: usize, plane: usize, channels: usize) -> usize {
    let plane = plane.max(1);
    assert_eq!(
        len % (plane * channels),
        0,
        "channel affine: {len} values are not images of {channels} planes of {plane}"
    );
    plane
}
