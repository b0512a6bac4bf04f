//! Winograd's variants and transforms, and the plan that cuts a convolution into parallel bands
//! of tile rows: the parts every Winograd path (bands, blocks, the split GRU pair) shares.

use std::mem::MaybeUninit;
use std::ops::Range;

use burn::tensor::ops::ConvOptions;
use dgstereo_core::tensor::{reuse_buffer, unwritten, written, zeros_parallel};
use rayon::prelude::*;

use crate::algorithm::WinogradTile;
use crate::geometry::{Epilogue, band_jobs, conv_output_size};

/// The variant of a tile the dispatch chose.
pub(crate) fn variant(tile: WinogradTile) -> &'static Variant {
    match tile {
        WinogradTile::F2 => &F2,
        WinogradTile::F4 => &F4,
    }
}

/// A Winograd variant F(m x m, 3 x 3): m x m output tiles from α x α input tiles (α = m + 2)
/// with α² products, its transforms (rows of `Bᵀ` α x α, `G` α x 3 and `Aᵀ` m x α, in 6-wide
/// rows of which the first α entries are used) and its band size.
pub(crate) struct Variant {
    /// The output tile's side.
    pub(crate) m: usize,
    pub(crate) bt: &'static [[f32; 6]],
    pub(crate) g: &'static [[f32; 3]],
    pub(crate) at: &'static [[f32; 6]],
    /// Target tiles per band (rounded to whole tile rows): F(2x2) 128, F(4x4) 384, chosen on the
    /// GRU 1/4 convolution and the encoders' layers (docs/performance.md, "Winograd F(4x4, 3x3) and F(2x2, 3x3)").
    pub(crate) band_tiles: usize,
}

/// F(2x2, 3x3): interpolation points 0, ±1, ∞; 16 products per 4 outputs.
pub(crate) const F2: Variant = Variant {
    m: 2,
    bt: &[[1., 0., -1., 0., 0., 0.], [0., 1., 1., 0., 0., 0.], [0., -1., 1., 0., 0., 0.], [0., 1., 0., -1., 0., 0.]],
    g: &[[1., 0., 0.], [0.5, 0.5, 0.5], [0.5, -0.5, 0.5], [0., 0., 1.]],
    at: &[[1., 1., 1., 0., 0., 0.], [0., 1., -1., -1., 0., 0.]],
    band_tiles: 128,
};

/// F(4x4, 3x3): interpolation points 0, ±1, ±2, ∞; 36 products per 16 outputs.
#[rustfmt::skip]
pub(crate) const F4: Variant = Variant {
    m: 4,
    bt: &[[4., 0., -5., 0., 1., 0.], [0., -4., -4., 1., 1., 0.], [0., 4., -4., -1., 1., 0.],
          [0., -2., -1., 2., 1., 0.], [0., 2., -1., -2., 1., 0.], [0., 4., 0., -5., 0., 1.]],
    g: &[[1. / 4., 0., 0.], [-1. / 6., -1. / 6., -1. / 6.], [-1. / 6., 1. / 6., -1. / 6.],
         [1. / 24., 1. / 12., 1. / 6.], [1. / 24., -1. / 12., 1. / 6.], [0., 0., 1.]],
    at: &[[1., 1., 1., 1., 1., 0.], [0., 1., -1., 2., -2., 0.], [0., 1., 1., 4., 4., 0.], [0., 1., -1., 8., -8., 1.]],
    band_tiles: 384,
};

/// Tile grid of one convolution: channels, input size, leading padding, output width, tile
/// size and tiles per row.
#[derive(Clone, Copy)]
pub(crate) struct Tiling {
    pub(crate) c: usize,
    pub(crate) h: usize,
    pub(crate) w: usize,
    pub(crate) ph: usize,
    pub(crate) pw: usize,
    pub(crate) out_w: usize,
    pub(crate) m: usize,
    pub(crate) tiles_w: usize,
}

thread_local! {
    /// Each worker thread's band buffers, grown to the largest band it has run: transformed
    /// inputs (`C x α² x T`), products (`O x α² x T`) and row scratch.
    static BUFFERS: std::cell::RefCell<[Vec<f32>; 3]> = const { std::cell::RefCell::new([Vec::new(), Vec::new(), Vec::new()]) };
}

/// The operands of one 3x3, stride-1 convolution, as every Winograd path takes them, with the
/// bias and `epilogue` to apply.
///
/// # Shapes
/// - `x`: `x_dims = [N, C, H, W]` (NCHW); `wt`: `[O, C, 3, 3]` (OIHW); `bias`: `[O]`
/// - `padding`: `[(top, bottom), (left, right)]`; output `[N, O, H + top + bottom - 2,
///   W + left + right - 2]`
#[derive(Clone, Copy)]
pub(crate) struct Conv3x3<'a> {
    pub(crate) x: &'a [f32],
    pub(crate) x_dims: [usize; 4],
    pub(crate) wt: &'a [f32],
    pub(crate) o: usize,
    pub(crate) bias: Option<&'a [f32]>,
    pub(crate) padding: [(usize, usize); 2],
    pub(crate) epilogue: Epilogue,
}

impl Conv3x3<'_> {
    /// Input channels, after checking that the weight is `[O, C, 3, 3]`.
    pub(crate) fn channels(&self) -> usize {
        let (c, o) = (self.x_dims[1], self.o);
        assert_eq!(self.wt.len(), o * c * 9, "winograd_conv: the weight is not [{o}, {c}, 3, 3]");
        c
    }
}

/// The geometry of one Winograd convolution: its tile grid, output size and bands (whole tile
/// rows of one image, processed in parallel).
#[derive(Clone, Copy)]
pub(crate) struct Plan {
    pub(crate) tiling: Tiling,
    pub(crate) n: usize,
    pub(crate) k2: usize,
    pub(crate) out_h: usize,
    pub(crate) tiles_h: usize,
    pub(crate) bands: usize,
    pub(crate) band_rows: usize,
}

impl Plan {
    pub(crate) fn new(variant: &Variant, [n, c, h, w]: [usize; 4], padding: [(usize, usize); 2]) -> Self {
        let [(ph, _), (pw, _)] = padding;
        let options = ConvOptions { stride: [1, 1], padding, dilation: [1, 1], groups: 1 };
        let [out_h, out_w] = conv_output_size("winograd_conv", [h, w], [3, 3], &options);
        let m = variant.m;
        let (tiles_h, tiles_w) = (out_h.div_ceil(m), out_w.div_ceil(m));
        let by_size = (variant.band_tiles / tiles_w).max(1);
        // One band per thread at least, not two: every band streams the whole transformed weight
        // (`O x α² x C`, 14 MB for the GRU gates), which on the small grids of the GRUs at 1/8 and
        // 1/16 cost more than the balance two bands per thread bought. Measured in one process
        // alternating both rules, 25 rounds, min (median) ms: GRU 1/8 pair of 384x448 31.9 (45.8)
        // -> 25.2 (39.1), GRU 1/16 8.5 (13.7) -> 7.4 (11.7), GRU 1/8 of KITTI 59.2 (84.4) -> 47.5
        // (73.8); the 1/4 grids and the encoders' layers within the noise.
        let threads = rayon::current_num_threads();
        let min_bands = threads.div_ceil(n.max(1));
        // A count that `band_rows` realises exactly: every band `band_rows` rows, the last fewer.
        let bands = balanced_bands(tiles_h.div_ceil(by_size).max(min_bands), tiles_h, n, threads);
        let band_rows = tiles_h.div_ceil(bands);
        let tiling = Tiling { c, h, w, ph, pw, out_w, m, tiles_w };
        Self { tiling, n, k2: (m + 2) * (m + 2), out_h, tiles_h, bands, band_rows }
    }

    /// (Image, band) jobs.
    pub(crate) fn jobs(&self) -> usize {
        self.n * self.bands
    }

    /// The tile rows of `job`'s band.
    pub(crate) fn tile_rows(&self, job: usize) -> Range<usize> {
        let band = job % self.bands;
        band * self.band_rows..((band + 1) * self.band_rows).min(self.tiles_h)
    }

    /// Tiles of `job`'s band, one unused tile per row included ([`transform_inputs`]).
    pub(crate) fn tiles(&self, job: usize) -> usize {
        self.tile_rows(job).len() * (self.tiling.tiles_w + 1)
    }

    /// Runs `body(job, image, planes, extra, buffers)` for every job in parallel and returns the
    /// output `[N, o, H_out, W_out]` and its dimensions: `image` is the job's input image (`[C,
    /// H, W]` of `x`), `planes` the band's rows of each of the `o` output planes of its image,
    /// `extra` the job's element of `extras`, `buffers` the worker thread's reusable band buffers.
    pub(crate) fn run<E: Send>(
        &self,
        x: &[f32],
        o: usize,
        extras: &mut [E],
        body: impl Fn(usize, &[f32], Vec<&mut [MaybeUninit<f32>]>, &mut E, &mut [Vec<f32>; 3]) + Sync,
    ) -> (Vec<f32>, [usize; 4]) {
        let (c, h, w) = (self.tiling.c, self.tiling.h, self.tiling.w);
        assert_eq!(x.len(), self.n * c * h * w, "winograd_conv: the input is not [{}, {c}, {h}, {w}]", self.n);
        assert_eq!(extras.len(), self.jobs());
        let plane = self.out_h * self.tiling.out_w;
        // Not zeroed first: the output transforms write every value (below).
        let mut out = unwritten(self.n * o * plane);
        // One job per (image, band) with its rows of every output plane: disjoint slices.
        let jobs = band_jobs(&mut out, o, plane, self.tiling.m * self.band_rows * self.tiling.out_w);
        debug_assert_eq!(jobs.len(), self.jobs());
        jobs.into_par_iter().zip(extras.par_iter_mut()).enumerate().for_each(|(job, (planes, extra))| {
            let image = &x[(job / self.bands) * c * h * w..][..c * h * w];
            BUFFERS.with_borrow_mut(|buffers| body(job, image, planes, extra, buffers));
        });
        // SAFETY: the jobs' band rows of every plane cover the whole output, and every body ends
        // with an output transform that writes each value of its band rows: `transform_outputs`
        // whole output rows, `blocks`' `scatter_row` every tile of every tile row, clipped to
        // the plane (tested on odd sizes, paddings and batches against burn's convolution).
        #[allow(unsafe_code)]
        let out = unsafe { written(out) };
        (out, [self.n, o, self.out_h, self.tiling.out_w])
    }
}

/// The band count, from `bands` up to `bands + threads` (at most `tiles_h`), whose `n · bands`
/// jobs the `threads` finish soonest ([`longest_thread`]); the fewest bands among equals, since
/// every band reads the whole transformed weight. Returned as the count its rows per band
/// realise (`tiles_h.div_ceil(rows)`), so `tiles_h.div_ceil(count)` gives those rows back. 3
/// bands of one image on 2 threads left one thread idle for a third of the convolution (the 1/4
/// grid of 320x736, 20 tile rows: 1.56 of 2 cores busy in the GRU 1/4, the motion encoder and
/// the flow head); 4 bands of 5 rows share evenly.
pub(crate) fn balanced_bands(bands: usize, tiles_h: usize, n: usize, threads: usize) -> usize {
    if tiles_h == 0 {
        return 0;
    }
    let first = bands.clamp(1, tiles_h);
    let mut best = (usize::MAX, first);
    for candidate in first..=(bands + threads).min(tiles_h) {
        let rows = tiles_h.div_ceil(candidate);
        let count = tiles_h.div_ceil(rows);
        let span = longest_thread(rows, tiles_h, count, n.max(1), threads.max(1));
        if span < best.0 {
            best = (span, count);
        }
    }
    best.1
}

/// Tile rows of the most loaded thread when `n` images' `count` bands of `rows` tile rows (the
/// last one shorter, `tiles_h` in all) go to `threads` threads, each job to the least loaded
/// thread, longest first: the work-stealing pool's schedule at best.
pub(crate) fn longest_thread(rows: usize, tiles_h: usize, count: usize, n: usize, threads: usize) -> usize {
    let mut loads = vec![0; threads];
    let last = tiles_h - rows * (count - 1);
    let jobs = std::iter::repeat_n(rows, n * (count - 1)).chain(std::iter::repeat_n(last, n));
    for job in jobs {
        let least = loads.iter_mut().min().expect("at least one thread");
        *least += job;
    }
    loads.into_iter().max().unwrap_or(0)
}

/// `dst = Σ coefs[q]·src(q)` over the nonzero coefficients (each `src(q)` at least as long as
/// `dst`), in one pass for up to 4 terms.
pub(crate) fn lincomb<'a>(dst: &mut [f32], coefs: &[f32], src: impl Fn(usize) -> &'a [f32]) {
    let n = dst.len();
    let mut terms: [(f32, &[f32]); 6] = [(0.0, &[]); 6];
    let mut len = 0;
    for (q, &k) in coefs.iter().enumerate().filter(|(_, k)| **k != 0.0) {
        terms[len] = (k, &src(q)[..n]);
        len += 1;
    }
    let (head, rest) = terms[..len].split_at(len.min(4));
    let src = |i: usize| head[i];
    match head.len() {
        0 => dst.fill(0.0),
        1 => {
            let (k0, s0) = src(0);
            for i in 0..n {
                dst[i] = k0 * s0[i];
            }
        }
        2 => {
            let ((k0, s0), (k1, s1)) = (src(0), src(1));
            for i in 0..n {
                dst[i] = k0 * s0[i] + k1 * s1[i];
            }
        }
        3 => {
            let ((k0, s0), (k1, s1), (k2, s2)) = (src(0), src(1), src(2));
            for i in 0..n {
                dst[i] = k0 * s0[i] + k1 * s1[i] + k2 * s2[i];
            }
        }
        _ => {
            let ((k0, s0), (k1, s1), (k2, s2), (k3, s3)) = (src(0), src(1), src(2), src(3));
            for i in 0..n {
                dst[i] = k0 * s0[i] + k1 * s1[i] + k2 * s2[i] + k3 * s3[i];
            }
        }
    }
    for &(k, s) in rest {
        for (d, s) in dst.iter_mut().zip(&s[..n]) {
            *d += k * s;
        }
    }
}

/// `U = G g Gᵀ` for every `(o, c)`, laid out `[O][α²][C]` (position `k = α·i + j` of the
/// transformed kernel). Per output channel the 9 taps are first gathered into vectors over `C`,
/// so both products with `G` are vector operations.
pub(crate) fn transform_weights(variant: &Variant, wt: &[f32], o: usize, c: usize) -> Vec<f32> {
    let alpha = variant.m + 2;
    let mut u = zeros_parallel(o * alpha * alpha * c);
    u.par_chunks_mut(alpha * alpha * c).enumerate().for_each_init(Vec::new, |scratch, (oc, dst)| {
        // taps[(3·ky + kx)·C + ci], then G g as gg[(α·kx + i)·C + ci].
        scratch.resize((9 + 3 * alpha) * c, 0.0);
        let (taps, gg) = scratch.split_at_mut(9 * c);
        for (ci, g) in wt[oc * c * 9..][..c * 9].chunks_exact(9).enumerate() {
            for (tap, &value) in g.iter().enumerate() {
                taps[tap * c + ci] = value;
            }
        }
        for (kx, column) in gg.chunks_exact_mut(alpha * c).enumerate() {
            for (i, dst) in column.chunks_exact_mut(c).enumerate() {
                lincomb(dst, &variant.g[i], |ky| &taps[(3 * ky + kx) * c..][..c]);
            }
        }
        let gg = &*gg;
        for (k, dst) in dst.chunks_exact_mut(c).enumerate() {
            let (i, j) = (k / alpha, k % alpha);
            lincomb(dst, &variant.g[j], |kx| &gg[(alpha * kx + i) * c..][..c]);
        }
    });
    u
}

/// Writes `V = Bᵀ d B` of every tile of `tile_rows` of one image (`image`, CHW) into `v`, laid
/// out `[C][α²][T]` with `T = tile_rows.len() · (tiles_w + 1)` (tile-row-major, one unused tile
/// per row), where `d` is the α x α input at rows `m·ty - ph ..`, columns `m·tx - pw ..`, zero
/// outside the input.
///
/// Per channel, every input row of the band is split into its `m` column phases (column
/// `m·tx + q` is phase `q mod m`, index `tx + q / m`), rows ordered by row phase (row `m·l + p`
/// at `(p, l)`), so that `d B` of all rows and `Bᵀ` over the rows (tile row `l` has rows
/// `m·l + r`: phase `r mod m`, index `l + r / m`) are each one combination of long contiguous
/// vectors. The extra tile per row (`tx = tiles_w`) absorbs the shifted reads across rows; its
/// values are never written out.
pub(crate) fn transform_inputs(
    variant: &Variant,
    v: &mut [f32],
    image: &[f32],
    g: Tiling,
    tile_rows: Range<usize>,
    scratch: &mut Vec<f32>,
) {
    let (m, alpha) = (g.m, g.m + 2);
    let (tws, rows) = (g.tiles_w + 1, tile_rows.len());
    let t = rows * tws;
    // Column phases [p][row phase][l][tws] (+1 slack for the last shifted read), then `d B`
    // [j][row phase][l][tws].
    let per_phase = m * (rows + 1) * tws;
    let (phases, rows_b) = reuse_buffer(scratch, m * per_phase + 1 + alpha * per_phase).split_at_mut(m * per_phase + 1);
    for ci in 0..g.c {
        let channel = &image[ci * g.h * g.w..][..g.h * g.w];
        // Input rows in memory order (row `m·l + rp` of the band goes to slot `(rp, l)`): reading
        // them by row phase instead (every m-th row first) cost 3-4 % of CPU inference.
        for r in 0..m * (rows + 1) {
            let slot = (r % m) * (rows + 1) + r / m;
            let row = (m * tile_rows.start + r).checked_sub(g.ph).filter(|&iy| iy < g.h);
            let line = row.map_or(&[][..], |iy| &channel[iy * g.w..][..g.w]);
            let mut by_phase = phases.chunks_exact_mut(per_phase).map(|dst| &mut dst[slot * tws..][..tws]);
            match m {
                2 => split_row::<2>(line, g.pw, std::array::from_fn(|_| by_phase.next().expect("2 phases"))),
                4 => split_row::<4>(line, g.pw, std::array::from_fn(|_| by_phase.next().expect("4 phases"))),
                _ => unreachable!("the Winograd variants are F(2x2) and F(4x4), not m = {m}"),
            }
        }
        let phases = &*phases;
        for (j, dst) in rows_b.chunks_exact_mut(per_phase).enumerate() {
            lincomb(dst, &variant.bt[j][..alpha], |q| &phases[(q % m) * per_phase + q / m..][..per_phase]);
        }
        let rows_b = &*rows_b;
        for k in 0..alpha * alpha {
            let (i, j) = (k / alpha, k % alpha);
            let lane = |r: usize| &rows_b[j * per_phase + ((r % m) * (rows + 1) + r / m) * tws..][..t];
            lincomb(&mut v[(ci * alpha * alpha + k) * t..][..t], &variant.bt[i][..alpha], lane);
        }
    }
}

/// Column `x` of a row padded with `pw` zeros on the left (and zeros past its end): `line[x - pw]`
/// where that lies inside the row, else 0 (an empty `line` is a row outside the input).
#[inline(always)]
pub(crate) fn padded_value(line: &[f32], pw: usize, x: usize) -> f32 {
    x.checked_sub(pw).and_then(|x| line.get(x)).copied().unwrap_or(0.0)
}

/// The `M` column phases of one input row shifted by the left padding `pw`: `dst[p][i] =
/// line[M·i + p - pw]`, zeros outside the row (an empty `line` is a row outside the input).
///
/// All phases in one pass over the row: where every phase of a tile column lies inside the row,
/// `M` consecutive values go to the `M` phases, which the compiler turns into vector loads and
/// shuffles. One strided pass per phase was a scalar gather, about 30 % of the input transform's
/// samples in a profile of the encoders' 64-channel layer; in one process alternating both, 15
/// rounds, median ms: layer1 64->64 at 384x448 115.4 -> 113.6, GRU 384->128 at 96x112 42.0 ->
/// 40.3 (the loads of the input rows now take the time the gather took).
pub(crate) fn split_row<const M: usize>(line: &[f32], pw: usize, mut dst: [&mut [f32]; M]) {
    let n = dst[0].len();
    let value = |i: usize, p: usize| padded_value(line, pw, M * i + p);
    // Columns i in lo..hi hold all M phases inside the row: pw ≤ M·i and M·i + M - 1 < len + pw.
    let lo = pw.div_ceil(M).min(n);
    let hi = ((line.len() + pw) / M).clamp(lo, n);
    for i in (0..lo).chain(hi..n) {
        for (p, d) in dst.iter_mut().enumerate() {
            d[i] = value(i, p);
        }
    }
    if lo == hi {
        return;
    }
    let (body, _) = line[M * lo - pw..].as_chunks::<M>();
    let inner: [&mut [f32]; M] = dst.map(|d| &mut d[lo..hi]);
    for (i, values) in body[..hi - lo].iter().enumerate() {
        for p in 0..M {
            inner[p][i] = values[p];
        }
    }
}

/// Writes `Y = Aᵀ M A` (plus the bias, through `epilogue`) of every tile of a band of
/// `band_rows` tile rows into the band's rows of each output plane (`planes[o]`, whole output
/// rows, the last tile row and column clipped to the output), with `mm` laid out `[O][α²][T]`.
/// Both steps run over the whole band's tiles.
#[allow(clippy::too_many_arguments)]
pub(crate) fn transform_outputs(
    variant: &Variant,
    mm: &[f32],
    planes: Vec<&mut [MaybeUninit<f32>]>,
    bias: Option<&[f32]>,
    epilogue: Epilogue,
    g: Tiling,
    band_rows: usize,
    scratch: &mut Vec<f32>,
) {
    let (m, alpha, tw) = (g.m, g.m + 2, g.tiles_w);
    let t = band_rows * (tw + 1);
    // `M A` per row i of the tile: q[m·i + s] (s = output column), then Y[m·r + s] (r = row).
    let (q, y) = reuse_buffer(scratch, (alpha + m) * m * t).split_at_mut(alpha * m * t);
    for (oc, dst) in planes.into_iter().enumerate() {
        let add = bias.map_or(0.0, |b| b[oc]);
        for (k, q) in q.chunks_exact_mut(t).enumerate() {
            lincomb(q, &variant.at[k % m][..alpha], |j| &mm[(oc * alpha * alpha + alpha * (k / m) + j) * t..][..t]);
        }
        let q = &*q;
        for (k, y) in y.chunks_exact_mut(t).enumerate() {
            lincomb(y, &variant.at[k / m][..alpha], |i| &q[(m * i + k % m) * t..][..t]);
        }
        // Output row m·l + r, column m·tx + s is y[(m·r + s)·T + l·(tw + 1) + tx].
        for (oy, row) in dst.chunks_exact_mut(g.out_w).enumerate() {
            let stream = |s: usize| &y[(m * (oy % m) + s) * t + (oy / m) * (tw + 1)..][..tw];
            match (m, epilogue) {
                (2, Epilogue::Linear) => interleave::<2, false>(row, [0, 1].map(stream), add),
                (2, Epilogue::Relu) => interleave::<2, true>(row, [0, 1].map(stream), add),
                (4, Epilogue::Linear) => interleave::<4, false>(row, [0, 1, 2, 3].map(stream), add),
                (4, Epilogue::Relu) => interleave::<4, true>(row, [0, 1, 2, 3].map(stream), add),
                _ => unreachable!("the Winograd variants are F(2x2) and F(4x4), not m = {m}"),
            }
        }
    }
}

/// Writes one output row, every value of it, from its `M` column streams (`row[M·tx + s] =
/// streams[s][tx] + add`, then ReLU when `RELU`), in row order: with `M` known at compile time
/// the stores are contiguous, where `M` strided scalar passes over the row were the output
/// transform's hot spot.
#[inline(always)]
pub(crate) fn interleave<const M: usize, const RELU: bool>(
    row: &mut [MaybeUninit<f32>],
    streams: [&[f32]; M],
    add: f32,
) {
    let finish = |v: f32| if RELU { (v + add).max(0.0) } else { v + add };
    let whole = row.len() / M;
    let streams = streams.map(|s| &s[..row.len().div_ceil(M)]);
    let (body, tail) = row.split_at_mut(whole * M);
    for (tx, out) in body.chunks_exact_mut(M).enumerate() {
        for s in 0..M {
            out[s].write(finish(streams[s][tx]));
        }
    }
    for (s, d) in tail.iter_mut().enumerate() {
        d.write(finish(streams[s][whole]));
    }
}
