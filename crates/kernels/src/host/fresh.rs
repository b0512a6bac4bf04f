//! New buffers written in parallel: the training kernels' element-wise passes create their
//! outputs here instead of copying an input (`to_vec`) or zeroing a buffer first.
//!
//! Design decision: an output made by `x.to_vec()` or `vec![0.0; n]` and then overwritten in
//! parallel is first written whole on the calling thread (a copy or glibc's `memset` in
//! `calloc`) while the workers wait: in a profile of a training step those serial writes held a
//! fifth of the main thread's samples. [`collect_chunks`] reserves the buffer uninitialised and
//! lets each rayon task write its own chunk once, from an iterator of exactly the chunk's values,
//! checked by count: safe code cannot leave a value unwritten. The buffer is the host kernels'
//! usual unwritten one (`dgstereo_core::tensor::unwritten`).
#![allow(unsafe_code)]

use dgstereo_core::tensor::{unwritten, written};
use rayon::prelude::*;

/// Chunk of the element-wise passes (16 Ki values: large enough to amortise a task).
pub const CHUNK: usize = 1 << 14;

/// A vector of `n` values whose chunk `k` (values `k·chunk ..`, the last one shorter) holds
/// what `values(k)` yields, every chunk written by one rayon task into a buffer from
/// [`unwritten`] (NaN in tests and debug builds, uninitialised otherwise).
///
/// # Panics
/// If an iterator yields fewer values than its chunk holds (extra values are ignored).
pub fn collect_chunks<I, F>(n: usize, chunk: usize, values: F) -> Vec<f32>
where
    I: Iterator<Item = f32>,
    F: Fn(usize) -> I + Sync,
{
    let mut out = unwritten(n);
    out.par_chunks_mut(chunk.max(1)).enumerate().for_each(|(k, slots)| {
        let mut count = 0;
        for (slot, v) in slots.iter_mut().zip(values(k)) {
            slot.write(v);
            count += 1;
        }
        assert_eq!(count, slots.len(), "collect_chunks: chunk {k} got {count} of {} values", slots.len());
    });
    // SAFETY: every element was written: each chunk's task counted its writes against the
    // chunk's length, and a task that panicked propagates out of `for_each` before this line.
    unsafe { written(out) }
}

/// Chunk `k` of `x` in chunks of `chunk` values.
pub fn chunk_of(x: &[f32], chunk: usize, k: usize) -> &[f32] {
    &x[(k * chunk).min(x.len())..((k + 1) * chunk).min(x.len())]
}

/// `f(a)` of every value, as a new vector written in parallel.
pub fn map1(a: &[f32], f: impl Fn(f32) -> f32 + Sync) -> Vec<f32> {
    collect_chunks(a.len(), CHUNK, |k| chunk_of(a, CHUNK, k).iter().map(|&v| f(v)))
}

/// `f(a, b)` of every pair of values, as a new vector written in parallel.
///
/// # Panics
/// If the lengths differ.
pub fn map2(a: &[f32], b: &[f32], f: impl Fn(f32, f32) -> f32 + Sync) -> Vec<f32> {
    assert_eq!(a.len(), b.len(), "map2: lengths differ");
    collect_chunks(a.len(), CHUNK, |k| chunk_of(a, CHUNK, k).iter().zip(chunk_of(b, CHUNK, k)).map(|(&a, &b)| f(a, b)))
}

/// `f(a, b, c)` of every triple of values, as a new vector written in parallel.
///
/// # Panics
/// If the lengths differ.
pub fn map3(a: &[f32], b: &[f32], c: &[f32], f: impl Fn(f32, f32, f32) -> f32 + Sync) -> Vec<f32> {
    assert!(a.len() == b.len() && a.len() == c.len(), "map3: lengths differ");
    collect_chunks(a.len(), CHUNK, |k| {
        let (a, b, c) = (chunk_of(a, CHUNK, k), chunk_of(b, CHUNK, k), chunk_of(c, CHUNK, k));
        a.iter().zip(b).zip(c).map(|((&a, &b), &c)| f(a, b, c))
    })
}

#[cfg(test)]
mod tests {
    use super::*;

    /// Chunks of every size, a short last chunk and an empty vector come out in order.
    #[test]
    fn chunks_land_in_order() {
        for (n, chunk) in [(0, 4), (1, 4), (10, 4), (12, 4), (100_003, CHUNK)] {
            let got = collect_chunks(n, chunk, |k| (k * chunk..((k + 1) * chunk).min(n)).map(|i| i as f32));
            assert_eq!(got, (0..n).map(|i| i as f32).collect::<Vec<_>>(), "n {n} chunk {chunk}");
        }
        let (a, b, c): (Vec<f32>, Vec<f32>, Vec<f32>) =
            ((0..40_000).map(|i| i as f32).collect(), vec![2.0; 40_000], vec![1.0; 40_000]);
        assert_eq!(map3(&a, &b, &c, |a, b, c| a * b - c)[39_999], 79_997.0);
        assert_eq!(map1(&a, |v| -v)[17_000], -17_000.0);
    }

    /// A chunk whose iterator runs short is refused, not left unwritten.
    #[test]
    #[should_panic(expected = "got 3 of 4 values")]
    fn a_short_chunk_panics() {
        collect_chunks(8, 4, |k| (0..if k == 1 { 3 } else { 4 }).map(|i| i as f32));
    }
}
