//! F(4x4, 3x3) in blocks of [`LANES`] tiles whose transforms and products stay in the core's
//! caches: the path for convolutions with few channels on large grids.
//!
//! Design decision: the band path of the parent module writes a band's transformed inputs
//! (`C x 36 x T`, megabytes for the encoders' 64-channel layers at full resolution) before the
//! `gemm` crate packs them again for its products, and reads the products back from the same
//! distance; on those layers the transforms, the packing and their page faults took about three
//! quarters of the time and the products a quarter. Here a band is cut into blocks of [`LANES`]
//! consecutive tiles (across tile rows), and each block runs start to end while its data are
//! small: the input transform of all channels (`36 x C x LANES`), the 36 products by a kernel
//! of our own over weights packed once per call (`[36][O/8][C][8]`, so no packing per product),
//! and the output transform (`O x 36 x LANES`) straight into the output rows. Every step is
//! vectorised over the block's tiles.
//!
//! The kernel keeps 8 output channels by 48 tiles of sums in 24 vector registers and adds one input
//! channel's products per step (three vector loads and eight broadcasts for 24 fused multiply-adds;
//! see [`LANES`]). The transforms are the factored
//! F(4x4) formulas ([`input_1d`], [`output_1d`]); the tiles' input columns are split into their
//! four phases, and the output tiles' columns merged back into rows, by vector shuffles
//! ([`Simd::deinterleave4`]). The band body is compiled for AVX-512 and runs where the processor
//! has it ([`Isa`]; elsewhere the band path runs); the vectors are `std::arch` intrinsics behind
//! the small [`Simd`] trait. What it took, measured on a 64-channel layer: the same loops over
//! fixed-size arrays left to the autovectoriser ran about 10x slower (sums kept in memory, scalar
//! fused multiply-adds); a closure or an array `map` inside the body is compiled without the body's
//! instruction set, so the intrinsics in it become calls (20-30 % slower); prefetching the input
//! rows two channels ahead ([`PREFETCH_CHANNELS`]) took 8 % (64 channels) to 20 % (96 channels)
//! off.

// Elsewhere than on x86-64 only the tests run the blocks (with the portable vectors).
#![cfg_attr(not(target_arch = "x86_64"), allow(dead_code))]

use std::mem::MaybeUninit;
use std::ops::Range;

use dgstereo_core::tensor::{reuse_buffer, zeros_parallel};
use rayon::prelude::*;

use super::simd::{self, Simd};
use super::transforms::*;
use super::weight_cache::transformed_weights;
use crate::geometry::Epilogue;

/// Tiles per block: the vectors of the transforms and the kernel's columns, three AVX-512 vectors
/// a kernel step (48 beat 32 on the AMD EPYC; docs/performance.md).
const LANES: usize = 48;
/// Vectors of tiles per kernel step (of the widest set, 16 lanes); [`Band::products`] is
/// written out for three.
const VECS: usize = 3;
const _: () = assert!(VECS == 3 && LANES == VECS * WIDEST);
/// Lanes of the widest vector set (AVX-512).
const WIDEST: usize = 16;
/// Lanes a row of a block's transform buffers holds: [`LANES`] and room for one more vector of
/// the widest set, so a vector may be stored at any lane (see [`gather_row`]).
const ROW: usize = LANES + WIDEST;
/// Output channels per kernel step.
const ROWS: usize = 8;
/// Positions of the transformed tile, α² of F(4x4).
const K2: usize = 36;

/// Whether the processor runs the blocked path (AVX-512 with FMA).
pub(crate) fn available() -> bool {
    Isa::detect().is_some()
}

/// `conv` by F(4x4, 3x3) in cache-resident blocks of tiles, compiled for `isa`; the same
/// contract as `winograd_conv`.
pub(crate) fn blocked_conv(isa: Isa, conv: &Conv3x3) -> (Vec<f32>, [usize; 4]) {
    let &Conv3x3 { x, x_dims, wt, o, bias, padding, epilogue } = conv;
    let c = conv.channels();
    let plan = Plan::new(&F4, x_dims, padding);
    // `u` lives to the end, as in the band path: freed right after the packing, it left a hole
    // in glibc's heap that raised a KITTI frame's peak memory from the second pass on by one
    // full-resolution activation (690 -> 777 MiB; 669 MiB with this order).
    let u = transformed_weights(&F4, wt, o, c);
    let packed = pack_weights(&u, o, c);
    plan.run(x, o, &mut vec![(); plan.jobs()], |job, image, mut planes, _, [v, mm, _]| {
        let v = reuse_buffer(v, K2 * c * LANES);
        let mm = reuse_buffer(mm, o.next_multiple_of(ROWS) * K2 * LANES);
        let band = Band { g: plan.tiling, tile_rows: plan.tile_rows(job), packed: &packed, o, bias, epilogue };
        isa.run(&band, image, &mut planes, v, mm);
    })
}

/// `U` (`[O][36][C]`, [`transform_weights`]) repacked as `[36][O/8][C][8]`, the output channels
/// padded with zeros to a multiple of 8: the kernel's eight weights of one input channel are
/// adjacent.
fn pack_weights(u: &[f32], o: usize, c: usize) -> Vec<f32> {
    let groups = o.div_ceil(ROWS);
    // Zeros in parallel: the padding rows stay zero (a `vec![0.0; ..]` was a `memset` on the
    // calling thread at every training call).
    let mut packed = zeros_parallel(K2 * groups * c * ROWS);
    packed.par_chunks_mut(groups * c * ROWS).enumerate().for_each(|(k, dst)| {
        for oc in 0..o {
            let (group, r) = (oc / ROWS, oc % ROWS);
            for (ci, &value) in u[(oc * K2 + k) * c..][..c].iter().enumerate() {
                dst[(group * c + ci) * ROWS + r] = value;
            }
        }
    });
    packed
}

/// An instruction set the band body is compiled for.
///
/// Only AVX-512 is chosen: it is where the path was measured to beat the band path. The same
/// body compiled for AVX2 ran the 64-channel layer at 384x448 in 94-112 ms against the band
/// path's 84-98 ms (whose `gemm` products use AVX-512 on that machine), so on a processor
/// without AVX-512 the band path runs. `Isa::Portable` (four lanes of plain Rust) lets the
/// tests check the block logic on any processor.
#[derive(Clone, Copy, Debug)]
pub(crate) enum Isa {
    /// Sixteen lanes of AVX-512 with FMA.
    #[cfg(target_arch = "x86_64")]
    Avx512,
    /// Four lanes of plain Rust: for the tests only.
    #[cfg(test)]
    Portable,
}

impl Isa {
    /// The set the processor runs that the blocked path uses, if any.
    pub(crate) fn detect() -> Option<Self> {
        #[cfg(target_arch = "x86_64")]
        if is_x86_feature_detected!("avx512f") && is_x86_feature_detected!("fma") {
            return Some(Self::Avx512);
        }
        None
    }

    /// Every set the tests can run here.
    #[cfg(test)]
    pub(super) fn available() -> Vec<Self> {
        Self::detect().into_iter().chain([Self::Portable]).collect()
    }

    #[allow(unsafe_code)]
    fn run(self, band: &Band, image: &[f32], planes: &mut [&mut [MaybeUninit<f32>]], v: &mut [f32], mm: &mut [f32]) {
        match self {
            // SAFETY: `detect` returns `Avx512` only where the processor has AVX-512 and FMA.
            #[cfg(target_arch = "x86_64")]
            Self::Avx512 => unsafe { band_avx512(band, image, planes, v, mm) },
            #[cfg(test)]
            Self::Portable => band.run::<simd::Portable>(image, planes, v, mm),
        }
    }
}

#[cfg(target_arch = "x86_64")]
#[target_feature(enable = "avx512f,fma")]
fn band_avx512(band: &Band, image: &[f32], planes: &mut [&mut [MaybeUninit<f32>]], v: &mut [f32], mm: &mut [f32]) {
    band.run::<simd::Avx512>(image, planes, v, mm)
}

/// `Bᵀ d` of F(4x4) (the rows of [`F4`]'s `bt`) on six vectors, in the factored form: 6
/// additions and 8 fused multiply-adds instead of one multiply-add per nonzero entry (22).
#[inline(always)]
fn input_1d<S: Simd>([d0, d1, d2, d3, d4, d5]: [S; 6]) -> [S; 6] {
    let k = S::splat;
    let (sum12, diff12) = (d1.add(d2), d1.sub(d2));
    let (a, b) = (d4.sub(d2), d3.sub(d1));
    [
        k(4.0).mul_add(d0, k(-5.0).mul_add(d2, d4)),
        k(-4.0).mul_add(sum12, d3.add(d4)),
        k(4.0).mul_add(diff12, d4.sub(d3)),
        k(2.0).mul_add(b, a),
        k(-2.0).mul_add(b, a),
        k(4.0).mul_add(d1, k(-5.0).mul_add(d3, d5)),
    ]
}

/// Six vectors `stride` values apart from the start of `src`.
#[inline(always)]
fn load6<S: Simd>(src: &[f32], stride: usize) -> [S; 6] {
    [
        S::load(src),
        S::load(&src[stride..]),
        S::load(&src[2 * stride..]),
        S::load(&src[3 * stride..]),
        S::load(&src[4 * stride..]),
        S::load(&src[5 * stride..]),
    ]
}

/// `Aᵀ m` of F(4x4) (the rows of [`F4`]'s `at`) on six vectors, factored likewise.
#[inline(always)]
fn output_1d<S: Simd>([m0, m1, m2, m3, m4, m5]: [S; 6]) -> [S; 4] {
    let k = S::splat;
    let (sum12, diff12, sum34, diff34) = (m1.add(m2), m1.sub(m2), m3.add(m4), m3.sub(m4));
    [
        m0.add(sum12).add(sum34),
        k(2.0).mul_add(diff34, diff12),
        k(4.0).mul_add(sum34, sum12),
        k(8.0).mul_add(diff34, diff12).add(m5),
    ]
}

/// Channels ahead whose input rows [`Band::transform_inputs`] prefetches: a block's rows of one
/// channel are hundreds of separate lines, too many streams for the hardware prefetcher.
const PREFETCH_CHANNELS: usize = 2;

/// Prefetches the cache line holding `value` (a hint: no effect on results).
#[inline(always)]
fn prefetch(value: &f32) {
    #[cfg(target_arch = "x86_64")]
    // SAFETY: prefetching is a hint that never faults; `value` is a valid reference anyway.
    #[allow(unsafe_code)]
    unsafe {
        std::arch::x86_64::_mm_prefetch::<{ std::arch::x86_64::_MM_HINT_T0 }>(std::ptr::from_ref(value).cast());
    }
    #[cfg(not(target_arch = "x86_64"))]
    let _ = value;
}

/// One band's work: its tile rows, the packed weights and the output's finishing.
struct Band<'a> {
    g: Tiling,
    tile_rows: Range<usize>,
    packed: &'a [f32],
    o: usize,
    bias: Option<&'a [f32]>,
    epilogue: Epilogue,
}

impl Band<'_> {
    /// Runs every block of the band: `v` holds a block's transformed inputs (`[36][C][LANES]`),
    /// `mm` its products (`[O][36][LANES]`).
    #[inline(always)]
    fn run<S: Simd>(&self, image: &[f32], planes: &mut [&mut [MaybeUninit<f32>]], v: &mut [f32], mm: &mut [f32]) {
        let total = self.tile_rows.len() * self.g.tiles_w;
        for start in (0..total).step_by(LANES) {
            let lanes = (total - start).min(LANES);
            self.transform_inputs::<S>(image, start, lanes, v);
            self.products::<S>(v, mm);
            self.transform_outputs::<S>(mm, start, lanes, planes);
        }
    }

    /// The tiles of the block starting at band tile `start`, by tile row: `(tile row within the
    /// band, first tile column, tiles, first lane)`.
    #[inline(always)]
    fn segments(&self, start: usize, lanes: usize) -> impl Iterator<Item = (usize, usize, usize, usize)> {
        let tw = self.g.tiles_w;
        let mut lane = 0;
        std::iter::from_fn(move || {
            (lane < lanes).then(|| {
                let t = start + lane;
                let (row, tx) = (t / tw, t % tw);
                let count = (tw - tx).min(lanes - lane);
                let segment = (row, tx, count, lane);
                lane += count;
                segment
            })
        })
    }

    /// `V = Bᵀ d B` of the block's first `lanes` tiles, all channels, into `v`
    /// (`[36][C][LANES]`); lanes past `lanes` hold leftovers of earlier rows (finite or not,
    /// every operation is lane by lane and their outputs are never written).
    #[inline(always)]
    fn transform_inputs<S: Simd>(&self, image: &[f32], start: usize, lanes: usize, v: &mut [f32]) {
        let g = self.g;
        // d[j][lane] of one input row, then its row transform rows[i][jj][lane].
        let mut d = [[0.0f32; ROW]; 6];
        let mut rows = [[[0.0f32; LANES]; 6]; 6];
        for ci in 0..g.c {
            let channel = &image[ci * g.h * g.w..][..g.h * g.w];
            if let Some(ahead) =
                image.get((ci + PREFETCH_CHANNELS) * g.h * g.w..).filter(|_| ci + PREFETCH_CHANNELS < g.c)
            {
                self.prefetch_rows(&ahead[..g.h * g.w], start, lanes);
            }
            for (i, row_t) in rows.iter_mut().enumerate() {
                for (row, tx0, count, lane0) in self.segments(start, lanes) {
                    let ty = self.tile_rows.start + row;
                    match (4 * ty + i).checked_sub(g.ph).filter(|&iy| iy < g.h) {
                        Some(iy) => gather_row::<S>(&channel[iy * g.w..][..g.w], g.pw, tx0, count, lane0, &mut d),
                        None => d.iter_mut().for_each(|dj| dj[lane0..lane0 + count].iter_mut().for_each(|v| *v = 0.0)),
                    }
                }
                for l in (0..LANES).step_by(S::WIDTH) {
                    let t = input_1d(load6::<S>(&d.as_flattened()[l..], ROW));
                    for (jj, t) in t.into_iter().enumerate() {
                        t.store(&mut row_t[jj][l..]);
                    }
                }
            }
            for jj in 0..6 {
                for l in (0..LANES).step_by(S::WIDTH) {
                    let column = load6::<S>(&rows.as_flattened().as_flattened()[jj * LANES + l..], 6 * LANES);
                    for (ii, value) in input_1d(column).into_iter().enumerate() {
                        value.store(&mut v[((6 * ii + jj) * g.c + ci) * LANES + l..]);
                    }
                }
            }
        }
    }

    /// Asks the processor to fetch the block's input rows of `channel` into its caches.
    #[inline(always)]
    fn prefetch_rows(&self, channel: &[f32], start: usize, lanes: usize) {
        let g = self.g;
        for (row, tx0, count, _) in self.segments(start, lanes) {
            let first = (4 * (self.tile_rows.start + row)).saturating_sub(g.ph);
            let x0 = (4 * tx0).saturating_sub(g.pw);
            let len = (4 * count + 2).min(g.w.saturating_sub(x0));
            if len == 0 {
                // Tiles wholly in the right padding.
                continue;
            }
            for iy in first..(first + 6).min(g.h) {
                let span = &channel[iy * g.w + x0..][..len];
                for at in (0..len).step_by(16) {
                    prefetch(&span[at]);
                }
                prefetch(&span[len - 1]);
            }
        }
    }

    /// `M_k = U_k V_k` for the 36 positions: `mm[o][k][lane]`, [`VECS`] vectors of lanes by
    /// [`ROWS`] output channels of sums at a time.
    #[inline(always)]
    fn products<S: Simd>(&self, v: &[f32], mm: &mut [f32]) {
        let c = self.g.c;
        let groups = self.o.div_ceil(ROWS);
        let w = S::WIDTH;
        for k in 0..K2 {
            let vk = &v[k * c * LANES..][..c * LANES].as_chunks::<LANES>().0[..c];
            for group in 0..groups {
                let uk = &self.packed[(k * groups + group) * c * ROWS..][..c * ROWS].as_chunks::<ROWS>().0[..c];
                for half in (0..LANES).step_by(VECS * w) {
                    let mut acc = [[S::splat(0.0); VECS]; ROWS];
                    for ci in 0..c {
                        let (u, vv) = (&uk[ci], &vk[ci]);
                        // Written out for the three vectors (`VECS`): `array::from_fn` or a
                        // closure here would be compiled without the body's instruction set.
                        let x = [S::load(&vv[half..]), S::load(&vv[half + w..]), S::load(&vv[half + 2 * w..])];
                        for r in 0..ROWS {
                            let b = S::splat(u[r]);
                            acc[r][0] = b.mul_add(x[0], acc[r][0]);
                            acc[r][1] = b.mul_add(x[1], acc[r][1]);
                            acc[r][2] = b.mul_add(x[2], acc[r][2]);
                        }
                    }
                    for (r, sums) in acc.iter().enumerate() {
                        let dst = &mut mm[((group * ROWS + r) * K2 + k) * LANES + half..];
                        sums[0].store(dst);
                        sums[1].store(&mut dst[w..]);
                        sums[2].store(&mut dst[2 * w..]);
                    }
                }
            }
        }
    }

    /// `Y = Aᵀ M A` of the block's first `lanes` tiles, plus the bias and the epilogue, into the
    /// band's output rows.
    #[inline(always)]
    fn transform_outputs<S: Simd>(
        &self,
        mm: &[f32],
        start: usize,
        lanes: usize,
        planes: &mut [&mut [MaybeUninit<f32>]],
    ) {
        let g = self.g;
        let relu = self.epilogue == Epilogue::Relu;
        let mut y = [[[0.0f32; ROW]; 4]; 4];
        for (oc, plane) in planes.iter_mut().enumerate() {
            let m = &mm[oc * K2 * LANES..][..K2 * LANES];
            let add = S::splat(self.bias.map_or(0.0, |b| b[oc]));
            for l in (0..LANES).step_by(S::WIDTH) {
                // Column j of `Aᵀ M`: tmp[j][r] = Σ_i Aᵀ[r][i] M[i][j]; then row r of Y from
                // tmp[.][r].
                // (No closure here: it would be compiled without the caller's instruction set.)
                let m = &m[l..];
                let tmp = [
                    output_1d(load6::<S>(m, 6 * LANES)),
                    output_1d(load6::<S>(&m[LANES..], 6 * LANES)),
                    output_1d(load6::<S>(&m[2 * LANES..], 6 * LANES)),
                    output_1d(load6::<S>(&m[3 * LANES..], 6 * LANES)),
                    output_1d(load6::<S>(&m[4 * LANES..], 6 * LANES)),
                    output_1d(load6::<S>(&m[5 * LANES..], 6 * LANES)),
                ];
                for (r, y_r) in y.iter_mut().enumerate() {
                    let row = output_1d([tmp[0][r], tmp[1][r], tmp[2][r], tmp[3][r], tmp[4][r], tmp[5][r]]);
                    for (s, value) in row.into_iter().enumerate() {
                        let value = value.add(add);
                        let value = if relu { value.max(S::splat(0.0)) } else { value };
                        value.store(&mut y_r[s][l..]);
                    }
                }
            }
            for (row, tx0, count, lane0) in self.segments(start, lanes) {
                for (r, y_r) in y.iter().enumerate() {
                    let oy = 4 * row + r;
                    let Some(line) = plane.get_mut(oy * g.out_w..(oy + 1) * g.out_w) else { break };
                    scatter_row::<S>(y_r, tx0, count, lane0, line);
                }
            }
        }
    }
}

/// Fills `d[j][lane0 + n] = line[4·(tx0 + n) + j - pw]` (zero outside the row) for the `count`
/// tiles of one segment, a whole vector of lanes at a time by [`Simd::deinterleave4`]: from the
/// row where the vector's values lie inside it, else from a zero-padded copy of the part that
/// does. A segment's last vector may reach past its `count` tiles: the lanes it fills there
/// belong to the block's next segments, which are filled after it, or lie past the block's
/// lanes (`d`'s rows have room for a vector at any lane, [`ROW`]).
///
/// Before, a vector ran only where it fitted the segment and single lanes did the rest: at the
/// 1/4 grid of 384x448 (28 tiles a row) 12 of every 28 lanes. Whole vectors, one image, min ms
/// of 15, two processes alternating in four rounds: 64 -> 64 at 96x112 3.49-3.57 -> 3.12, 96 ->
/// 96 6.58 -> 5.89-6.00, 128 -> 128 9.92-9.98 -> 9.13-9.37, 128 -> 126 10.20-10.37 -> 9.56-10.04,
/// 64 -> 64 at 192x224 11.30-11.75 -> 10.92-11.07; KITTI's 1/4 grid (78 tiles a row) unchanged.
#[inline(always)]
fn gather_row<S: Simd>(line: &[f32], pw: usize, tx0: usize, count: usize, lane0: usize, d: &mut [[f32; ROW]; 6]) {
    let w = S::WIDTH;
    // Values x0 - pw .. x0 - pw + 4w + 4 of the row (the last two unused).
    let span = 4 * w + 4;
    // One vector's span (at most the widest's), zero-filled where it is used.
    let mut stage = [0.0f32; 4 * WIDEST + 4];
    for n in (0..count).step_by(w) {
        let (lane, x0) = (lane0 + n, 4 * (tx0 + n));
        let src = if x0 >= pw && x0 - pw + span <= line.len() {
            &line[x0 - pw..][..span]
        } else {
            let stage = &mut stage[..span];
            stage.fill(0.0);
            // Row positions start - pw .. end - pw lie inside the span and the row.
            let (start, end) = (x0.max(pw), (x0 + span).min(pw + line.len()));
            if start < end {
                stage[start - x0..end - x0].copy_from_slice(&line[start - pw..end - pw]);
            }
            &*stage
        };
        let [p0, p1, p2, p3] = S::deinterleave4(src);
        let [q0, q1, _, _] = S::deinterleave4(&src[4..]);
        for (j, phase) in [p0, p1, p2, p3, q0, q1].into_iter().enumerate() {
            phase.store(&mut d[j][lane..]);
        }
    }
}

/// Writes `line[4·(tx0 + n) + s] = y[s][lane0 + n]` for the `count` tiles of one segment,
/// clipped to the row, a whole vector of lanes at a time by [`Simd::interleave4`]: straight into
/// the row where the vector's values fit it, else through a copy. A vector that reaches past the
/// segment's tiles inside the row writes tiles of the same row that a later block writes again
/// (a segment ends at the row's end or at the block's).
#[inline(always)]
fn scatter_row<S: Simd>(y: &[[f32; ROW]; 4], tx0: usize, count: usize, lane0: usize, line: &mut [MaybeUninit<f32>]) {
    let w = S::WIDTH;
    // One vector's values (at most the widest's), written by `interleave4` before they are read.
    let mut stage = [MaybeUninit::<f32>::uninit(); 4 * WIDEST];
    for n in (0..count).step_by(w) {
        let (lane, x0) = (lane0 + n, 4 * (tx0 + n));
        let phases = [S::load(&y[0][lane..]), S::load(&y[1][lane..]), S::load(&y[2][lane..]), S::load(&y[3][lane..])];
        if x0 + 4 * w <= line.len() {
            S::interleave4(phases, &mut line[x0..]);
        } else {
            let len = (4 * (count - n)).min(line.len() - x0);
            S::interleave4(phases, &mut stage);
            line[x0..x0 + len].copy_from_slice(&stage[..len]);
        }
    }
}
