//! Operation counts taken from the operations as they run.
//!
//! Design decision: the number of multiply-accumulates (MACs) of a forward pass is counted by the
//! face operations themselves, not by a second description of the network that could drift from
//! it: each operation that multiplies and accumulates (the convolutions, the deformable
//! convolution, the ConvGRU step, the correlation's matrix product and its on-the-fly dot
//! products, the convex combination of the upsampling, the linear layers) opens an
//! [`Operation`] with its count as its first line. A count is the operation's defining arithmetic, the same on every path (a
//! direct convolution's `N·O·(C/groups)·kh·kw·H_out·W_out`, whether the host kernel computes it
//! by Winograd's algorithm or the GPU by a matrix product), so "achieved GFLOP/s" (2 FLOP per
//! MAC) compares directly with a machine's peak. Element-wise and memory-bound operations (norms,
//! activations, resizes, pooling, the lookups' interpolation, the deformable convolution's
//! sampling) count nothing.
//!
//! An operation that runs through another (the GRU step through its convolutions, a fused
//! convolution through the plain one, a caller's stock composition) is counted once, by the
//! outermost: inner operations see that one is open and count nothing. Counting is per thread
//! and off unless [`count_work`] is running on it; off, an operation costs one thread-local flag
//! read.

use std::cell::Cell;

use burn::nn::PaddingConfig2d;
use burn::nn::conv::{Conv2d, DeformConv2d};
use burn::tensor::ops::ConvOptions;

thread_local! {
    /// Whether [`count_work`] is running on this thread.
    static COUNTING: Cell<bool> = const { Cell::new(false) };
    /// Operations open on this thread while counting (only the outermost counts).
    static OPEN: Cell<u32> = const { Cell::new(0) };
    /// MACs counted on this thread so far.
    static MACS: Cell<u64> = const { Cell::new(0) };
}

/// The work of a span of code: its operations' multiply-accumulates.
#[derive(Debug, Clone, Copy, PartialEq, Eq, Default)]
pub struct WorkCount {
    /// Multiply-accumulates (one MAC = 2 FLOP).
    pub macs: u64,
}

/// Runs `f` with counting on for this thread and returns its result and the work its
/// operations did. Nested calls count their own span, which the enclosing one includes.
pub fn count_work<T>(f: impl FnOnce() -> T) -> (T, WorkCount) {
    /// Puts the counting flag back as it was, also when `f` panics.
    struct Restore(bool);
    impl Drop for Restore {
        fn drop(&mut self) {
            COUNTING.set(self.0);
        }
    }
    let _restore = Restore(COUNTING.replace(true));
    let start = macs_so_far();
    let out = f();
    (out, WorkCount { macs: macs_so_far().wrapping_sub(start) })
}

/// The MACs this thread has counted so far (it grows only under [`count_work`]): a meter to
/// read before and after a span, e.g. the stage clock's, to attribute work to that span.
pub fn macs_so_far() -> u64 {
    MACS.get()
}

/// An open operation (see [`operation`]); closing it (drop) lets the next one count.
#[must_use = "the operation counts as open only while this value lives"]
pub(crate) struct Operation {
    open: bool,
}

/// Opens an operation doing `macs()` multiply-accumulates: counted where [`count_work`] runs and
/// no other operation is open on this thread; `macs` is called only then.
#[inline]
pub(crate) fn operation(macs: impl FnOnce() -> u64) -> Operation {
    if !COUNTING.get() {
        return Operation { open: false };
    }
    if OPEN.get() == 0 {
        MACS.set(MACS.get().wrapping_add(macs()));
    }
    OPEN.set(OPEN.get() + 1);
    Operation { open: true }
}

impl Drop for Operation {
    #[inline]
    fn drop(&mut self) {
        if self.open {
            OPEN.set(OPEN.get() - 1);
        }
    }
}

/// Output side of a convolution: `n` input, `kernel` taps `dilation` apart, `pad` padding in all.
fn out_side(n: usize, kernel: usize, stride: usize, dilation: usize, pad: usize) -> usize {
    (n + pad).saturating_sub(dilation * (kernel.max(1) - 1) + 1) / stride.max(1) + 1
}

/// MACs of a convolution of `x` (`[N, C, H, W]`) with `weight` (`[O, C/groups, kh, kw]`).
pub(crate) fn conv_macs(x: [usize; 4], weight: [usize; 4], options: &ConvOptions<2>) -> u64 {
    let [(ph, ph_end), (pw, pw_end)] = options.padding;
    let h = out_side(x[2], weight[2], options.stride[0], options.dilation[0], ph + ph_end);
    let w = out_side(x[3], weight[3], options.stride[1], options.dilation[1], pw + pw_end);
    (x[0] * weight.iter().product::<usize>()) as u64 * (h * w) as u64
}

/// MACs of `conv.forward(x)` for `x` of dims `x`.
pub(crate) fn conv_module_macs(conv: &Conv2d, x: [usize; 4]) -> u64 {
    let weight = conv.weight.dims();
    let padding = match conv.padding {
        PaddingConfig2d::Explicit(top, left, bottom, right) => [(top, bottom), (left, right)],
        PaddingConfig2d::Valid => [(0, 0), (0, 0)],
        // The output keeps the input's size at stride 1 (`ceil(n / stride)` in general).
        PaddingConfig2d::Same => {
            let [h, w] = [0, 1].map(|i| x[2 + i].div_ceil(conv.stride[i].max(1)));
            return (x[0] * weight.iter().product::<usize>()) as u64 * (h * w) as u64;
        }
    };
    conv_macs(x, weight, &ConvOptions::new_with_padding(conv.stride, padding, conv.dilation, conv.groups))
}

/// MACs of a linear layer of weight `[d_in, d_out]` over `rows` rows.
pub(crate) fn linear_macs(rows: usize, [d_in, d_out]: [usize; 2]) -> u64 {
    (rows * d_in) as u64 * d_out as u64
}

/// MACs of a ConvGRU step on a state of dims `h`: its convolutions' (`[h, x]` in, the state's
/// size out).
pub(crate) fn gru_step_macs(convs: [&Conv2d; 3], h: [usize; 4]) -> u64 {
    convs.iter().map(|conv| conv_module_macs(conv, h)).sum()
}

/// MACs of a deformable convolution with offsets of dims `offset` (`[N, 2·kh·kw, H_out, W_out]`):
/// its weighted sum over the sampled taps (the bilinear sampling not counted).
pub(crate) fn deform_macs(conv: &DeformConv2d, offset: [usize; 4]) -> u64 {
    let [n, _, h, w] = offset;
    (n * conv.weight.dims().iter().product::<usize>()) as u64 * (h * w) as u64
}

/// MACs of the all-pairs correlation of `fmap1` (`[N, C, H, W1]`) with `fmap2` (`[.., W2]`).
pub(crate) fn all_pairs_macs([n, c, h, w1]: [usize; 4], fmap2: [usize; 4]) -> u64 {
    (n * c * h) as u64 * (w1 * fmap2[3]) as u64
}

/// MACs of one on-the-fly lookup of left features of dims `fmap1`: a `C`-long dot product at
/// `2·radius + 2` positions per pixel and level.
pub(crate) fn on_the_fly_macs([n, c, h, w1]: [usize; 4], levels: usize, radius: usize) -> u64 {
    (n * c * h * w1) as u64 * (levels * (2 * radius + 2)) as u64
}

/// MACs of convex upsampling of a `[N, D, H, W]` field by `factor`: 9 per output value.
pub(crate) fn convex_upsample_macs([n, d, h, w]: [usize; 4], factor: usize) -> u64 {
    (n * d * h * w) as u64 * (9 * factor * factor) as u64
}

#[cfg(test)]
mod tests {
    use super::*;

    /// An operation running inside another is counted once, by the outer one; operations one
    /// after the other add up, and a nested `count_work` counts its own span only.
    #[test]
    fn nested_operations_count_once() {
        let (_, work) = count_work(|| {
            let _outer = operation(|| 100);
            let _inner = operation(|| 40);
            drop(operation(|| 7));
        });
        assert_eq!(work.macs, 100);
        let (inner, outer) = count_work(|| {
            drop(operation(|| 3));
            count_work(|| drop(operation(|| 5))).1
        });
        assert_eq!((inner.macs, outer.macs), (5, 8));
    }
}
