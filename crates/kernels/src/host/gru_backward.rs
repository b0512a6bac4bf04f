//! The ConvGRU step's element-wise parts, forward and backward on host buffers, for training
//! ([`crate::autodiff::gru`]): the gates `σ(a + b)` and the blend
//! `(1 − z)·h + z·tanh(q + c)`, each one parallel pass where burn's autodiff records four to
//! six serial operations and as many again backward.

use rayon::prelude::*;

/// Chunk of the passes (16 Ki values).
const CHUNK: usize = 1 << 14;

fn sigmoid(v: f32) -> f32 {
    1.0 / (1.0 + (-v).exp())
}

/// `σ(a + b)`.
pub fn gates_forward(a: &[f32], b: &[f32]) -> Vec<f32> {
    assert_eq!(a.len(), b.len(), "gates: shapes differ");
    let mut out = a.to_vec();
    out.par_chunks_mut(CHUNK).zip(b.par_chunks(CHUNK)).for_each(|(o, b)| {
        o.iter_mut().zip(b).for_each(|(o, b)| *o = sigmoid(*o + b));
    });
    out
}

/// The gradient of [`gates_forward`] with respect to `a` (and `b`, the same) from its output `s`:
/// `g · s · (1 − s)`.
pub fn gates_backward(g: &[f32], s: &[f32]) -> Vec<f32> {
    assert_eq!(g.len(), s.len(), "gates backward: shapes differ");
    let mut out = g.to_vec();
    out.par_chunks_mut(CHUNK).zip(s.par_chunks(CHUNK)).for_each(|(o, s)| {
        o.iter_mut().zip(s).for_each(|(o, &s)| *o *= s * (1.0 - s));
    });
    out
}

/// `(1 − z)·h + z·t` with `t = tanh(q + c)`; returns the output and `t` (for the backward).
pub fn blend_forward(q: &[f32], c: &[f32], z: &[f32], h: &[f32]) -> (Vec<f32>, Vec<f32>) {
    let n = q.len();
    assert!(c.len() == n && z.len() == n && h.len() == n, "blend: shapes differ");
    let mut t = q.to_vec();
    let mut out = vec![0.0f32; n];
    out.par_chunks_mut(CHUNK).zip(t.par_chunks_mut(CHUNK)).enumerate().for_each(|(k, (o, t))| {
        let at = k * CHUNK;
        for i in 0..o.len() {
            let j = at + i;
            t[i] = (t[i] + c[j]).tanh();
            o[i] = (1.0 - z[j]) * h[j] + z[j] * t[i];
        }
    });
    (out, t)
}

/// The gradients of [`blend_forward`] from the output gradient `g`: `[dq (= dc), dz, dh]`,
/// with `dq = g·z·(1 − t²)`, `dz = g·(t − h)`, `dh = g·(1 − z)`.
pub fn blend_backward(g: &[f32], t: &[f32], z: &[f32], h: &[f32]) -> [Vec<f32>; 3] {
    let n = g.len();
    assert!(t.len() == n && z.len() == n && h.len() == n, "blend backward: shapes differ");
    let (mut dq, mut dz, mut dh) = (vec![0.0f32; n], vec![0.0f32; n], vec![0.0f32; n]);
    dq.par_chunks_mut(CHUNK).zip(dz.par_chunks_mut(CHUNK)).zip(dh.par_chunks_mut(CHUNK)).enumerate().for_each(
        |(k, ((dq, dz), dh))| {
            let at = k * CHUNK;
            for i in 0..dq.len() {
                let j = at + i;
                dq[i] = g[j] * z[j] * (1.0 - t[j] * t[j]);
                dz[i] = g[j] * (t[j] - h[j]);
                dh[i] = g[j] * (1.0 - z[j]);
            }
        },
    );
    [dq, dz, dh]
}
