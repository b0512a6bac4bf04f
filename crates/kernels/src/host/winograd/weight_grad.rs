//! The weight gradient of a 3x3, stride-1 convolution by Winograd's transforms.
//!
//! Design decision: the im2col weight gradient (`conv_backward::conv2d_weight_grad`) was the
//! largest single part of a CPU training step (three tenths of the workers' samples), because the
//! forward and the input gradient of the GRUs' convolutions run by Winograd with 4x fewer
//! multiplications and it did not. The forward's transforms give the weight gradient too: with
//! `Y = Aᵀ[(G w Gᵀ) ⊙ (Bᵀ d B)]A` for one tile, the loss's derivative `Σ g·Y` is the trilinear
//! form `Σ (A g Aᵀ) ⊙ (G w Gᵀ) ⊙ (Bᵀ d B)`, so `∂/∂w = Gᵀ[Σ_tiles (A g Aᵀ) ⊙ (Bᵀ d B)]G`: the same
//! input transform as the forward's, the output transform's matrix applied to the output
//! gradient's m x m tiles, α² products `M_k += U_k · V_kᵀ` (`O x T` by `T x C`, `T` tiles deep)
//! summed over the tiles, and one transform by `G` at the end: α² products instead of 9·m² per
//! tile and channel pair (F(4x4): 36 instead of 144).
//!
//! Each stage runs in parallel over what it owns (input channels, output channels, the α²
//! products, output channels), and each `M_k` sums the bands of tile rows in order, so the
//! result is the same bit for bit on any thread count: training stays reproducible.

use dgstereo_core::tensor::{reuse_buffer, zeros_parallel};
use rayon::prelude::*;

use super::transforms::{Tiling, Variant, lincomb, split_row, transform_inputs};

/// Elements of a band's transformed inputs or output gradients (`α² x C x T`): the band's tile
/// rows are as many as this allows (16 MiB), the whole image on the 1/4 grids of training crops.
pub(crate) const BAND_ELEMENTS: usize = 1 << 22;

/// Output or input channels per transform job.
const CHANNELS_PER_JOB: usize = 8;

/// The gradient of a 3x3, stride-1, one-group convolution's weight (`[O, C, 3, 3]`), given its
/// input `x` and output gradient `g`, by Winograd `variant`, in bands of tile rows of at most
/// `band_elements` transformed values ([`BAND_ELEMENTS`] outside the tests).
///
/// # Shapes
/// - `x`: `x_dims = [N, C, H, W]`; `g`: `[N, O, H_out, W_out]` with `H_out = H + top + bottom - 2`
///   (`padding = [(top, bottom), (left, right)]`); output `[O, C, 3, 3]`
pub(crate) fn winograd_weight_grad(
    variant: &Variant,
    x: &[f32],
    x_dims: [usize; 4],
    g: &[f32],
    o: usize,
    padding: [(usize, usize); 2],
    band_elements: usize,
) -> Vec<f32> {
    let [n, c, h, w] = x_dims;
    let [(ph, ph_end), (pw, pw_end)] = padding;
    let (out_h, out_w) = ((h + ph + ph_end).saturating_sub(2), (w + pw + pw_end).saturating_sub(2));
    assert_eq!(x.len(), n * c * h * w, "winograd_weight_grad: the input is not {x_dims:?}");
    assert_eq!(
        g.len(),
        n * o * out_h * out_w,
        "winograd_weight_grad: the output gradient is not [{n}, {o}, {out_h}, {out_w}]"
    );
    let (m, alpha) = (variant.m, variant.m + 2);
    let k2 = alpha * alpha;
    let (tiles_h, tiles_w) = (out_h.div_ceil(m), out_w.div_ceil(m));
    let tws = tiles_w + 1;
    let tiling = Tiling { c, h, w, ph, pw, out_w, m, tiles_w };
    let band_rows = (band_elements / (k2 * c.max(o) * tws).max(1)).clamp(1, tiles_h.max(1));
    let mut sums = zeros_parallel(k2 * o * c);
    BAND_BUFFERS.with_borrow_mut(|[v_buffer, u_buffer]| {
        for b in 0..n {
            let image = &x[b * c * h * w..][..c * h * w];
            let grads = &g[b * o * out_h * out_w..][..o * out_h * out_w];
            for start in (0..tiles_h).step_by(band_rows) {
                let rows = start..(start + band_rows).min(tiles_h);
                let t = rows.len() * tws;
                // Every element of both is written by its transform before the products read it.
                let (v, u) = (reuse_buffer(v_buffer, k2 * c * t), reuse_buffer(u_buffer, k2 * o * t));
                v.par_chunks_mut(CHANNELS_PER_JOB * k2 * t).enumerate().for_each_init(
                    Vec::new,
                    |scratch, (job, dst)| {
                        let (c0, cc) = (job * CHANNELS_PER_JOB, dst.len() / (k2 * t));
                        let channels = &image[c0 * h * w..][..cc * h * w];
                        transform_inputs(variant, dst, channels, Tiling { c: cc, ..tiling }, rows.clone(), scratch);
                    },
                );
                u.par_chunks_mut(k2 * t).enumerate().for_each_init(Vec::new, |scratch, (oc, dst)| {
                    let plane = &grads[oc * out_h * out_w..][..out_h * out_w];
                    transform_grad_tiles(variant, dst, plane, [out_h, out_w], rows.clone(), tws, scratch);
                });
                let (u, v) = (&*u, &*v);
                sums.par_chunks_mut(o * c).enumerate().for_each(|(k, mk)| {
                    crate::product::matmul_transposed_accumulate(
                        mk,
                        c,
                        &u[k * t..],
                        k2 * t,
                        &v[k * t..],
                        k2 * t,
                        [o, c, t],
                    );
                });
            }
        }
    });
    transform_sums(variant, &sums, o, c)
}

thread_local! {
    /// The calling thread's band buffers (transformed inputs and output gradients), kept between
    /// calls and grown to the largest band ([`BAND_ELEMENTS`] each at most): allocating and
    /// zeroing them at every call was a serial `memset` of up to 16 MiB each, 18 % of the main
    /// thread's samples in a training step.
    static BAND_BUFFERS: std::cell::RefCell<[Vec<f32>; 2]> = const { std::cell::RefCell::new([Vec::new(), Vec::new()]) };
}

/// Writes `A g Aᵀ` of every m x m tile of one output-gradient plane in `tile_rows` into `dst`,
/// laid out `[α²][T]` like the input transform's (tile-row-major, `tws` tiles a row, the last of
/// each row unused and zero), with `g` zero past the plane's last row and column.
///
/// As the input transform does, every row of the band is first split into its `m` column phases
/// (`phases[(r·m + s)·T + l·tws + tx] = g[m·ty + r][m·tx + s]`, `ty` the band's `l`-th tile row),
/// so both products with `A` are combinations of vectors over the whole band's tiles. One tile at
/// a time in scalar code cost 0.1 s of a 192x320 training step's backward.
fn transform_grad_tiles(
    variant: &Variant,
    dst: &mut [f32],
    plane: &[f32],
    [out_h, out_w]: [usize; 2],
    tile_rows: std::ops::Range<usize>,
    tws: usize,
    scratch: &mut Vec<f32>,
) {
    let (m, alpha) = (variant.m, variant.m + 2);
    let t = tile_rows.len() * tws;
    let (phases, columns) = reuse_buffer(scratch, (m * m + m * alpha) * t).split_at_mut(m * m * t);
    for (l, ty) in tile_rows.enumerate() {
        for r in 0..m {
            let y = m * ty + r;
            let line = if y < out_h { &plane[y * out_w..][..out_w] } else { &[][..] };
            let mut by_phase = phases.chunks_exact_mut(t).skip(r * m).map(|d| &mut d[l * tws..][..tws]);
            match m {
                2 => split_row::<2>(line, 0, std::array::from_fn(|_| by_phase.next().expect("2 phases"))),
                4 => split_row::<4>(line, 0, std::array::from_fn(|_| by_phase.next().expect("4 phases"))),
                _ => unreachable!("the Winograd variants are F(2x2) and F(4x4), not m = {m}"),
            }
        }
    }
    // `U[i][j] = Σ_r A[i][r]·(Σ_s g[r][s]·A[j][s])` with `A[i][r] = at[r][i]`: first the columns,
    // `columns[(r·α + j)·T ..] = Σ_s at[s][j]·phases[r][s]`, then the rows.
    let phases = &*phases;
    for (rj, dst) in columns.chunks_exact_mut(t).enumerate() {
        let (r, j) = (rj / alpha, rj % alpha);
        let coefs: [f32; 4] = std::array::from_fn(|s| if s < m { variant.at[s][j] } else { 0.0 });
        lincomb(dst, &coefs[..m], |s| &phases[(r * m + s) * t..][..t]);
    }
    let columns = &*columns;
    for (k, dst) in dst.chunks_exact_mut(t).enumerate() {
        let (i, j) = (k / alpha, k % alpha);
        let coefs: [f32; 4] = std::array::from_fn(|r| if r < m { variant.at[r][i] } else { 0.0 });
        lincomb(dst, &coefs[..m], |r| &columns[(r * alpha + j) * t..][..t]);
    }
}

/// The weight gradient `[O, C, 3, 3]` from the summed products `sums` (`[α²][O][C]`):
/// `dw[a][b] = Σ_i Σ_j G[i][a]·M[αi + j]·G[j][b]`, per output channel over vectors of the `C`
/// input channels.
fn transform_sums(variant: &Variant, sums: &[f32], o: usize, c: usize) -> Vec<f32> {
    let alpha = variant.m + 2;
    let mut dw = zeros_parallel(o * c * 9);
    dw.par_chunks_mut(c * 9).enumerate().for_each_init(Vec::new, |scratch: &mut Vec<f32>, (oc, dst)| {
        let scratch = reuse_buffer(scratch, (3 * alpha + 9) * c);
        let (left, taps) = scratch.split_at_mut(3 * alpha * c);
        let sum = |k: usize| &sums[(k * o + oc) * c..][..c];
        // left[(α·a + j)·C ..] = Σ_i G[i][a]·M[αi + j], then taps[(3a + b)·C ..] = Σ_j left[a][j]·G[j][b].
        let column = |a: usize| -> [f32; 6] { std::array::from_fn(|i| if i < alpha { variant.g[i][a] } else { 0.0 }) };
        for a in 0..3 {
            let coefs = column(a);
            for j in 0..alpha {
                lincomb(&mut left[(alpha * a + j) * c..][..c], &coefs[..alpha], |i| sum(alpha * i + j));
            }
        }
        let left = &*left;
        for a in 0..3 {
            for b in 0..3 {
                let coefs = column(b);
                lincomb(&mut taps[(3 * a + b) * c..][..c], &coefs[..alpha], |j| &left[(alpha * a + j) * c..][..c]);
            }
        }
        for (ci, out) in dst.chunks_exact_mut(9).enumerate() {
            for (tap, value) in out.iter_mut().enumerate() {
                *value = taps[tap * c + ci];
            }
        }
    });
    dw
}

#[cfg(test)]
mod tests {
    use super::super::transforms::{F2, F4};
    use super::*;

    /// `Σ_images Σ_pixels g·x` of a 3x3 stride-1 convolution's definition, in f64: the
    /// weight gradient `[O, C, 3, 3]`.
    fn plain_weight_grad(
        x: &[f32],
        [n, c, h, w]: [usize; 4],
        g: &[f32],
        o: usize,
        padding: [(usize, usize); 2],
    ) -> Vec<f32> {
        let [(pt, pb), (pl, pr)] = padding;
        let (out_h, out_w) = (h + pt + pb - 2, w + pl + pr - 2);
        let mut dw = vec![0.0f64; o * c * 9];
        for b in 0..n {
            for oc in 0..o {
                for y in 0..out_h {
                    for xx in 0..out_w {
                        let gv = f64::from(g[((b * o + oc) * out_h + y) * out_w + xx]);
                        for ic in 0..c {
                            for tap in 0..9 {
                                let (iy, ix) = ((y + tap / 3).checked_sub(pt), (xx + tap % 3).checked_sub(pl));
                                if let (Some(iy), Some(ix)) = (iy, ix)
                                    && iy < h
                                    && ix < w
                                {
                                    dw[(oc * c + ic) * 9 + tap] += gv * f64::from(x[((b * c + ic) * h + iy) * w + ix]);
                                }
                            }
                        }
                    }
                }
            }
        }
        dw.into_iter().map(|v| v as f32).collect()
    }

    fn values(len: usize, seed: u32) -> Vec<f32> {
        (0..len).map(|i| (((i as u32).wrapping_mul(2_654_435_761) ^ seed) % 2001) as f32 / 1000.0 - 1.0).collect()
    }

    /// Both variants against the definition's plain sum of products on odd sizes,
    /// paddings and batches, bounded relative to the largest sum of absolute products (the scale
    /// of the rounding): F(2x2) within 1e-5, F(4x4) within 4e-5, as the forward's tests.
    #[test]
    fn the_winograd_weight_gradient_equals_the_plain_sum() {
        type Case = (usize, [usize; 2], [usize; 2], [(usize, usize); 2]);
        let cases: [Case; 7] = [
            (1, [3, 2], [9, 10], [(1, 1), (1, 1)]),
            (2, [5, 4], [13, 18], [(1, 1), (1, 1)]),
            (1, [4, 3], [7, 6], [(1, 0), (0, 2)]),
            (2, [2, 3], [3, 3], [(0, 0), (0, 0)]),
            (1, [3, 5], [1, 2], [(2, 2), (1, 2)]),
            (1, [40, 33], [21, 27], [(1, 1), (1, 1)]),
            (2, [17, 9], [30, 11], [(1, 1), (1, 1)]),
        ];
        for (n, [c, o], [h, w], padding) in cases {
            let [(pt, pb), (pl, pr)] = padding;
            let (out_h, out_w) = (h + pt + pb - 2, w + pl + pr - 2);
            let (x, g) = (values(n * c * h * w, 1), values(n * o * out_h * out_w, 2));
            let want = plain_weight_grad(&x, [n, c, h, w], &g, o, padding);
            let abs = |v: &[f32]| v.iter().map(|v| v.abs()).collect::<Vec<_>>();
            let magnitude = plain_weight_grad(&abs(&x), [n, c, h, w], &abs(&g), o, padding);
            let scale = magnitude.iter().fold(1e-6f32, |s, v| s.max(*v));
            for (variant, bound) in [(&F2, 1e-5), (&F4, 4e-5)] {
                let got = winograd_weight_grad(variant, &x, [n, c, h, w], &g, o, padding, BAND_ELEMENTS);
                let worst = got.iter().zip(&want).map(|(a, b)| (a - b).abs()).fold(0.0, f32::max) / scale;
                let case = format!("F({}) n {n} c {c} o {o} {h}x{w} padding {padding:?}", variant.m);
                assert!(worst <= bound, "{case}: {worst:e} of the largest sum of |products|");
            }
        }
    }

    /// Bands of one and of two tile rows give the gradient of one band within rounding, and the
    /// same gradient on one thread and on three, bit for bit.
    #[test]
    fn the_winograd_weight_gradient_is_reproducible_in_bands() {
        let (n, c, o, h, w) = (2, 20, 12, 23, 30);
        let (x, g) = (values(n * c * h * w, 3), values(n * o * h * w, 4));
        let padding = [(1, 1), (1, 1)];
        let in_bands = |rows: usize, threads: usize| {
            let pool = rayon::ThreadPoolBuilder::new().num_threads(threads).build().unwrap();
            let elements = 36 * c * (w.div_ceil(4) + 1) * rows;
            pool.install(|| winograd_weight_grad(&F4, &x, [n, c, h, w], &g, o, padding, elements))
        };
        let whole = winograd_weight_grad(&F4, &x, [n, c, h, w], &g, o, padding, BAND_ELEMENTS);
        for rows in [1, 2] {
            let banded = in_bands(rows, 1);
            assert_eq!(banded, in_bands(rows, 3), "{rows} rows a band: one and three threads");
            let worst = banded.iter().zip(&whole).map(|(a, b)| (a - b).abs()).fold(0.0, f32::max);
            assert!(worst < 1e-3, "{rows} rows a band against one band: {worst}");
        }
    }
}
