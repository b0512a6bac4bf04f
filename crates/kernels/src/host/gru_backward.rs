//! The ConvGRU step's element-wise parts, forward and backward on host buffers, for training
//! (`crate::autodiff::gru`): the gates `σ(a + b)` and the blend
//! `(1 − z)·h + z·tanh(q + c)`, each one parallel pass where burn's autodiff records four to
//! six serial operations and as many again backward.

use super::fresh::{map2, map3};

fn sigmoid(v: f32) -> f32 {
    1.0 / (1.0 + (-v).exp())
}

/// `σ(a + b)`.
pub fn gates_forward(a: &[f32], b: &[f32]) -> Vec<f32> {
    assert_eq!(a.len(), b.len(), "gates: shapes differ");
    map2(a, b, |a, b| sigmoid(a + b))
}

/// The gradient of [`gates_forward`] with respect to `a` (and `b`, the same) from its output `s`:
/// `g · s · (1 − s)`.
pub fn gates_backward(g: &[f32], s: &[f32]) -> Vec<f32> {
    assert_eq!(g.len(), s.len(), "gates backward: shapes differ");
    map2(g, s, |g, s| g * (s * (1.0 - s)))
}

/// `(1 − z)·h + z·t` with `t = tanh(q + c)`; returns the output and `t` (for the backward).
pub fn blend_forward(q: &[f32], c: &[f32], z: &[f32], h: &[f32]) -> (Vec<f32>, Vec<f32>) {
    let n = q.len();
    assert!(c.len() == n && z.len() == n && h.len() == n, "blend: shapes differ");
    let t = map2(q, c, |q, c| (q + c).tanh());
    let out = map3(&t, z, h, |t, z, h| (1.0 - z) * h + z * t);
    (out, t)
}

/// The gradients of [`blend_forward`] from the output gradient `g`: `[dq (= dc), dz, dh]`,
/// with `dq = g·z·(1 − t²)`, `dz = g·(t − h)`, `dh = g·(1 − z)`.
pub fn blend_backward(g: &[f32], t: &[f32], z: &[f32], h: &[f32]) -> [Vec<f32>; 3] {
    let n = g.len();
    assert!(t.len() == n && z.len() == n && h.len() == n, "blend backward: shapes differ");
    [
        map3(g, z, t, |g, z, t| g * z * (1.0 - t * t)),
        map3(g, t, h, |g, t, h| g * (t - h)),
        map2(g, z, |g, z| g * (1.0 - z)),
    ]
}
