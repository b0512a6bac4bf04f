//! The gradients of a convolution on host buffers, for training on the CPU.
//!
//! Design decision: burn Flex computes a convolution's input gradient as a transposed
//! convolution and its weight gradient as a convolution of the input by the output gradient, whose
//! products have a depth of the batch and a few output channels: skinny shapes that ran the `gemm`
//! crate's narrowest micro-kernels for most of a training step. Here the input gradient of a
//! stride-1 convolution is the host convolution of the output gradient with the flipped,
//! transposed weight (Winograd where the layer suits it, as in inference; the dispatch may
//! keep the forward itself on plain products, see `crate::Numerics`). The weight gradient of a 3x3
//! stride-1 layer with enough channels runs by Winograd's transforms
//! ([`conv2d_weight_grad_winograd`], 4x fewer multiplications); elsewhere it is `G · Colsᵀ`, the
//! output gradient (`O x P`) by the forward's own column matrix, tiles of a thousand and more
//! pixels deep, summed over a fixed partition of the tiles. Both give the same sums on any
//! thread count, so training stays reproducible. burn's backward stays the reference and the
//! path for what these do not take (strided input gradients, groups).

use burn::tensor::ops::ConvOptions;
use dgstereo_core::tensor::reuse_buffer;
use rayon::prelude::*;

use super::columns::image_columns;
use super::conv::conv2d_host_slices;
use super::fresh::{CHUNK, collect_chunks};
use super::winograd::{WEIGHT_GRAD_BAND_ELEMENTS, variant, winograd_weight_grad};
use crate::algorithm::{ConvAlgorithm, WinogradTile};
use crate::geometry::{Epilogue, conv_output_size};
use crate::product::matmul_transposed_accumulate;

/// Column-matrix elements per weight-gradient tile: deep enough (pixels) for a well-shaped
/// product, small enough for a worker's buffer (16 MiB).
const WEIGHT_GRAD_COLUMNS: usize = 1 << 22;

/// Groups of tiles whose weight gradients are summed apart (in parallel), then in order; a
/// layer is cut into at least this many tiles where [`MIN_TILE_PIXELS`] allows, so that a batch
/// of one image still keeps every thread busy.
const GROUPS: usize = 8;

/// The fewest pixels a weight-gradient tile holds (the depth of its product), where the layer
/// has them: shallower products than this run below the `gemm` crate's good shapes.
const MIN_TILE_PIXELS: usize = 384;

/// The gradient of `conv2d(x, wt)` (stride 1, dilation 1, one group) with respect to `x`, given
/// the output gradient `g`: the convolution of `g` with the weight flipped in both axes and its
/// channels swapped, padded by `k - 1 - p`, by `algorithm` (the dispatch's choice for that
/// convolution). `None` for a stride, dilation, groups or padding of `k` or more, which burn's
/// transposed convolution takes (the dispatch gives no algorithm there).
///
/// # Shapes
/// - `g`: `g_dims = [N, O, H_out, W_out]`; `wt`: `w_dims = [O, C, kh, kw]`; output `x_dims = [N,
///   C, H, W]`
pub(crate) fn conv2d_input_grad(
    g: &[f32],
    g_dims: [usize; 4],
    wt: &[f32],
    w_dims: [usize; 4],
    x_dims: [usize; 4],
    options: &ConvOptions<2>,
    algorithm: ConvAlgorithm,
) -> Option<Vec<f32>> {
    let [o, c, kh, kw] = w_dims;
    let [(pt, pb), (pl, pr)] = options.padding;
    let plain = options.stride == [1, 1] && options.dilation == [1, 1] && options.groups == 1;
    if !plain || pt.max(pb) >= kh || pl.max(pr) >= kw {
        return None;
    }
    let taps = kh * kw;
    // `[C][O][taps]`, each tap mirrored; written in parallel into a fresh buffer (a zeroed one
    // was a `memset` on the calling thread).
    let flipped = collect_chunks(c * o * taps, o * taps, |ic| {
        (0..o).flat_map(move |oc| (0..taps).map(move |t| wt[(oc * c + ic) * taps + taps - 1 - t]))
    });
    let padding = [(kh - 1 - pt, kh - 1 - pb), (kw - 1 - pl, kw - 1 - pr)];
    let transposed = ConvOptions::new_with_padding([1, 1], padding, [1, 1], 1);
    let (out, dims) =
        conv2d_host_slices(g, g_dims, &flipped, [c, o, kh, kw], None, &transposed, algorithm, Epilogue::Linear);
    assert_eq!(dims, x_dims, "conv2d_input_grad: the output gradient does not match the input");
    Some(out)
}

/// The gradient of `conv2d(x, wt)` (one group) with respect to `wt`, given the output gradient
/// `g`: `Σ_images Σ_tiles G_tile · Cols_tileᵀ`.
///
/// # Shapes
/// - `x`: `x_dims = [N, C, H, W]`; `g`: `[N, O, H_out, W_out]`; output `w_dims = [O, C, kh, kw]`
pub(crate) fn conv2d_weight_grad(
    x: &[f32],
    x_dims: [usize; 4],
    g: &[f32],
    w_dims: [usize; 4],
    options: &ConvOptions<2>,
) -> Vec<f32> {
    let [n, c, h, w] = x_dims;
    let [o, cw, kh, kw] = w_dims;
    assert!(options.groups == 1 && c == cw, "conv2d_weight_grad: one group, {c} input channels, weight {w_dims:?}");
    let [out_h, out_w] = conv_output_size("conv2d_weight_grad", [h, w], [kh, kw], options);
    let (k, plane) = (c * kh * kw, out_h * out_w);
    assert_eq!(g.len(), n * o * plane, "conv2d_weight_grad: the output gradient is not [{n}, {o}, {out_h}, {out_w}]");
    let rows_per_tile = tile_rows([n, out_h, out_w], k);
    let tiles = out_h.div_ceil(rows_per_tile);
    // A fixed partition of the jobs into groups, each summed in order into its own accumulator,
    // and the groups summed in order: the same sums whatever the thread count or the work
    // stealing, so training stays reproducible bit for bit.
    let jobs = n * tiles;
    let groups = jobs.min(GROUPS);
    // Fewer groups than GROUPS (a small plane: one tile of one image) also split the output
    // channels into blocks, so that the layer still gives GROUPS tasks: one task ran the GRU
    // at 1/16's weight gradients on the calling thread while the workers waited. The rows of a
    // block are their own sums, so the split changes no value.
    let rows = o.div_ceil((GROUPS / groups).clamp(1, o.max(1)));
    let blocks = o.div_ceil(rows.max(1));
    let partials: Vec<Vec<f32>> = (0..groups * blocks)
        .into_par_iter()
        .map(|task| {
            let (group, block) = (task / blocks, task % blocks);
            let (o0, o1) = (block * rows, ((block + 1) * rows).min(o));
            let mut acc = vec![0.0f32; (o1 - o0) * k];
            for job in group * jobs / groups..(group + 1) * jobs / groups {
                let (b, tile) = (job / tiles, job % tiles);
                let (oy0, oy1) = (tile * rows_per_tile, ((tile + 1) * rows_per_tile).min(out_h));
                let p = (oy1 - oy0) * out_w;
                // The thread's column buffer, reused across tiles and calls: every element of
                // it that the product reads is written first.
                COLUMNS.with_borrow_mut(|buffer| {
                    let col = reuse_buffer(buffer, k * p);
                    let image = &x[b * c * h * w..][..c * h * w];
                    image_columns(col, image, [c, h, w], [kh, kw], options, out_w, oy0..oy1);
                    let g_tile = &g[(b * o + o0) * plane + oy0 * out_w..];
                    matmul_transposed_accumulate(&mut acc, k, g_tile, plane, col, p, [o1 - o0, k, p]);
                });
            }
            acc
        })
        .collect();
    // Each element sums the groups in order, chunks of elements in parallel.
    collect_chunks(o * k, CHUNK, |i| {
        let len = CHUNK.min(o * k - i * CHUNK);
        let partials = &partials;
        (i * CHUNK..i * CHUNK + len).map(move |e| {
            let (block, offset) = (e / (rows * k), e % (rows * k));
            (0..groups).fold(0.0f32, |t, group| t + partials[group * blocks + block][offset])
        })
    })
}

/// [`conv2d_weight_grad`] by Winograd's transforms (`winograd::weight_grad`) with `tile`, for a
/// layer the dispatch gives them (3x3, stride 1, enough channels and tiles).
///
/// # Shapes
/// As [`conv2d_weight_grad`].
pub(crate) fn conv2d_weight_grad_winograd(
    x: &[f32],
    x_dims: [usize; 4],
    g: &[f32],
    w_dims: [usize; 4],
    options: &ConvOptions<2>,
    tile: WinogradTile,
) -> Vec<f32> {
    winograd_weight_grad(variant(tile), x, x_dims, g, w_dims[0], options.padding, WEIGHT_GRAD_BAND_ELEMENTS)
}

/// Output rows per weight-gradient tile of `n` images of `out_h x out_w` pixels with `k`
/// column-matrix rows: at most a worker buffer's worth ([`WEIGHT_GRAD_COLUMNS`]), and few enough
/// that the images give [`GROUPS`] tiles, halving that count (an even split over two or four
/// threads) while a tile would hold fewer than [`MIN_TILE_PIXELS`] pixels. A function of the
/// shapes only, so the partition, and with it the sums, do not depend on the thread count.
fn tile_rows([n, out_h, out_w]: [usize; 3], k: usize) -> usize {
    let out_h = out_h.max(1);
    let mut per_image = GROUPS.div_ceil(n.max(1));
    while per_image > 1 && out_h * out_w < per_image * MIN_TILE_PIXELS {
        per_image /= 2;
    }
    let by_memory = (WEIGHT_GRAD_COLUMNS / k.max(1) / out_w.max(1)).max(1);
    out_h.div_ceil(per_image).min(by_memory).clamp(1, out_h)
}

thread_local! {
    /// Each worker thread's column matrix for the weight gradient, grown to the largest tile.
    static COLUMNS: std::cell::RefCell<Vec<f32>> = const { std::cell::RefCell::new(Vec::new()) };
}

/// The gradient of a convolution's bias: the output gradient summed over images and pixels.
///
/// # Shapes
/// - `g`: `[N, O, H_out, W_out]` with `plane = H_out·W_out`; output `[O]`
pub(crate) fn conv2d_bias_grad(g: &[f32], [n, o, plane]: [usize; 3]) -> Vec<f32> {
    (0..o)
        .into_par_iter()
        .map(|oc| {
            (0..n).map(|b| g[(b * o + oc) * plane..][..plane].iter().map(|&v| v as f64).sum::<f64>()).sum::<f64>()
                as f32
        })
        .collect()
}

#[cfg(test)]
mod tests {
    use super::*;

    /// One image at a quarter of 192x320 (48x80) is cut into 8 tiles of 480 pixels, at an
    /// eighth (24x40) into 2 of 480 (4 of 240 would be shallower than `MIN_TILE_PIXELS`); a
    /// small plane stays one tile, eight images one tile each, and a deep column matrix is cut
    /// by the buffer's size.
    #[test]
    fn weight_gradient_tiles_keep_threads_busy_and_products_deep() {
        assert_eq!(tile_rows([1, 48, 80], 1152), 6);
        assert_eq!(tile_rows([1, 24, 40], 1152), 12);
        assert_eq!(tile_rows([1, 12, 20], 1152), 12);
        assert_eq!(tile_rows([2, 48, 80], 1152), 12, "two images, 4 tiles each");
        assert_eq!(tile_rows([8, 48, 80], 64), 48);
        assert_eq!(tile_rows([1, 480, 640], 1152), 5, "5 rows of 640 pixels fill the buffer");
    }

    /// The weight gradient is the same, bit for bit, on one thread and on three, and equals
    /// the plain sum `Σ g·x` of its definition.
    #[test]
    fn the_weight_gradient_is_reproducible_and_right() {
        let (n, c, o, h, w) = (2, 5, 4, 33, 29);
        let value = |i: usize, seed: usize| ((i * 2_654_435_761 + seed * 97) % 1999) as f32 / 999.0 - 1.0;
        let x: Vec<f32> = (0..n * c * h * w).map(|i| value(i, 1)).collect();
        let g: Vec<f32> = (0..n * o * h * w).map(|i| value(i, 2)).collect();
        let options = ConvOptions::new([1, 1], [1, 1], [1, 1], 1);
        let on = |threads: usize| {
            let pool = rayon::ThreadPoolBuilder::new().num_threads(threads).build().unwrap();
            pool.install(|| conv2d_weight_grad(&x, [n, c, h, w], &g, [o, c, 3, 3], &options))
        };
        let one = on(1);
        assert_eq!(one, on(3), "bit-identical on one and three threads");
        for (oc, ic, ky, kx) in [(0, 0, 0, 0), (3, 4, 2, 1), (1, 2, 1, 1)] {
            let mut want = 0.0f64;
            for b in 0..n {
                for y in 0..h {
                    for xx in 0..w {
                        let (iy, ix) = ((y + ky) as isize - 1, (xx + kx) as isize - 1);
                        if (0..h as isize).contains(&iy) && (0..w as isize).contains(&ix) {
                            let xv = x[((b * c + ic) * h + iy as usize) * w + ix as usize];
                            want += f64::from(g[((b * o + oc) * h + y) * w + xx] * xv);
                        }
                    }
                }
            }
            let got = one[((oc * c + ic) * 3 + ky) * 3 + kx];
            assert!((f64::from(got) - want).abs() < 1e-3, "({oc}, {ic}, {ky}, {kx}): {got} vs {want}");
        }
    }
}
