//! The im2col column matrix of a tile of output rows, built from NCHW rows: a shifted copy per
//! `(c, ky, kx)` row of the matrix, the stride-2 rows from the input's even and odd columns.

use burn::tensor::ops::ConvOptions;

use super::winograd::split_row;

/// Writes the column matrix (`K x P` row-major: row `(c, ky, kx)`, column the output pixel) of
/// output rows `rows` of one image `x` (`[C, H, W]`) for a `kh x kw` kernel with `options`, whose
/// output is `out_w` wide: the im2col path's columns, for the weight gradient.
pub(crate) fn image_columns(
    col: &mut [f32],
    x: &[f32],
    [c, h, w]: [usize; 3],
    [kh, kw]: [usize; 2],
    options: &ConvOptions<2>,
    out_w: usize,
    rows: std::ops::Range<usize>,
) {
    let [sh, sw] = options.stride;
    let [(ph, _), (pw, _)] = options.padding;
    let [dh, dw] = options.dilation;
    fill_columns(col, x, Geometry { c, h, w, kh, kw, sh, sw, ph, pw, dh, dw, out_w }, rows);
}

/// Sizes of one convolution: input channels and size, kernel, stride, leading padding,
/// dilation, output width.
#[derive(Clone, Copy)]
struct Geometry {
    c: usize,
    h: usize,
    w: usize,
    kh: usize,
    kw: usize,
    sh: usize,
    sw: usize,
    ph: usize,
    pw: usize,
    dh: usize,
    dw: usize,
    out_w: usize,
}

/// Writes every element of the column matrix of output rows `rows` of one image (`src`, NCHW).
fn fill_columns(col: &mut [f32], src: &[f32], g: Geometry, rows: std::ops::Range<usize>) {
    if g.sw == 2 {
        return fill_columns_stride2(col, src, g, rows);
    }
    let p = rows.len() * g.out_w;
    for ci in 0..g.c {
        let channel = &src[ci * g.h * g.w..(ci + 1) * g.h * g.w];
        for ky in 0..g.kh {
            for kx in 0..g.kw {
                let row = &mut col[((ci * g.kh + ky) * g.kw + kx) * p..][..p];
                let offset = (kx * g.dw) as isize - g.pw as isize;
                for (r, oy) in rows.clone().enumerate() {
                    let dst = &mut row[r * g.out_w..][..g.out_w];
                    let iy = (oy * g.sh + ky * g.dh) as isize - g.ph as isize;
                    if iy < 0 || iy >= g.h as isize {
                        dst.fill(0.0);
                        continue;
                    }
                    let line = &channel[iy as usize * g.w..][..g.w];
                    if g.sw == 1 {
                        // ix = ox + offset: one shifted copy, zeros outside the input.
                        shifted_copy(dst, line, offset);
                    } else {
                        for (ox, v) in dst.iter_mut().enumerate() {
                            let ix = (ox * g.sw) as isize + offset;
                            *v = if ix >= 0 && ix < g.w as isize { line[ix as usize] } else { 0.0 };
                        }
                    }
                }
            }
        }
    }
}

/// [`fill_columns`] for a horizontal stride of 2: each input row a kernel row reads is split
/// into its even and odd columns (module `host_winograd`'s row split), and every kernel column's
/// row of the matrix is then one shifted copy from one of them (column `2·ox + offset` is phase
/// `offset mod 2`, index `ox + offset div 2`). The general path gathered element by element,
/// once per kernel column: the encoders' stride-2 convolutions spent most of their
/// column-building time there.
fn fill_columns_stride2(col: &mut [f32], src: &[f32], g: Geometry, rows: std::ops::Range<usize>) {
    let p = rows.len() * g.out_w;
    // Both phases `ceil(w / 2)` long: for an odd width the odd phase's last value lies outside
    // the row, a zero like the padding.
    let half = g.w.div_ceil(2);
    let mut phases = vec![0.0f32; 2 * half];
    for ci in 0..g.c {
        let channel = &src[ci * g.h * g.w..(ci + 1) * g.h * g.w];
        for ky in 0..g.kh {
            for (r, oy) in rows.clone().enumerate() {
                let iy = (oy * g.sh + ky * g.dh) as isize - g.ph as isize;
                let inside = iy >= 0 && iy < g.h as isize;
                if inside {
                    let (even, odd) = phases.split_at_mut(half);
                    split_row::<2>(&channel[iy as usize * g.w..][..g.w], 0, [even, odd]);
                }
                for kx in 0..g.kw {
                    let dst = &mut col[((ci * g.kh + ky) * g.kw + kx) * p + r * g.out_w..][..g.out_w];
                    if !inside {
                        dst.fill(0.0);
                        continue;
                    }
                    let offset = (kx * g.dw) as isize - g.pw as isize;
                    let (phase, shift) = (offset.rem_euclid(2) as usize, offset.div_euclid(2));
                    shifted_copy(dst, &phases[phase * half..][..half], shift);
                }
            }
        }
    }
}

/// `dst[i] = source[i + shift]` where that index lies inside `source`, zeros elsewhere.
fn shifted_copy(dst: &mut [f32], source: &[f32], shift: isize) {
    let n = dst.len() as isize;
    let lo = (-shift).clamp(0, n) as usize;
    let hi = (source.len() as isize - shift).clamp(lo as isize, n) as usize;
    let start = (lo as isize + shift) as usize;
    dst[..lo].fill(0.0);
    dst[lo..hi].copy_from_slice(&source[start..start + (hi - lo)]);
    dst[hi..].fill(0.0);
}
