//! Winograd F(4x4, 3x3) and F(2x2, 3x3): the host convolution's path for 3x3, stride-1
//! convolutions.
//!
//! Design decision: most of a CPU forward pass is 3x3 stride-1 convolutions with many channels
//! (the ConvGRU gates, the encoders' residual blocks, the motion encoder), and the im2col path
//! of [`super::conv`] already runs the `gemm` crate near its speed on this machine, so the
//! remaining gain is fewer multiplications. F(m x m, 3 x 3) computes an m x m output tile from
//! an α x α input tile (α = m + 2) with α² products instead of 9·m²: F(2x2) 16 instead of 36
//! (2.25x fewer), F(4x4) 36 instead of 144 (4x fewer). With `U = G g Gᵀ` (weights),
//! `V = Bᵀ d B` (input tiles) and `Y = Aᵀ M A` (outputs), the products are α² matrix products
//! `M_k = U_k V_k`, one per position `k` of the transformed tile, `O x C` times `C x T` for `T`
//! tiles; the transforms are linear combinations with small constant coefficients.
//!
//! - The weights are transformed into `[O][α²][C]` (the product's left operand `U_k` has row
//!   stride `α²·C`), in parallel over output channels, and kept for the next call with the same
//!   weights while a [`UpdateLoop`] scope is open (`weight_cache`: the update loop would
//!   transform the GRUs' weights again at every iteration).
//! - The output is cut into bands of whole tile rows per image, processed in parallel with
//!   rayon; each band transforms its input tiles into the thread's reusable buffers (zeros where
//!   a tile reaches outside the input: the padding and the partial last tile row or column of
//!   sizes that are not multiples of m), runs the α² products with `gemm::Parallelism::None`
//!   (operands and results strided: the transformed inputs are laid out `[C][α²][T]` and the
//!   products `[O][α²][T]`, so that each transform reads or writes one contiguous run per
//!   channel; with `[α²][C][T]` its α² streams lay megabytes apart, 7 % slower on the whole pass),
//!   and transforms the result straight into its rows of the NCHW output, adding the bias and
//!   applying the epilogue. Input rows are split into column phases (column mod m) first, so
//!   every transform step is a combination of long contiguous vectors (see
//!   [`transform_inputs`]).
//! - Band size: [`Variant::band_tiles`] tiles, measured, but at least one band per rayon thread
//!   so every core has work on small grids, and a job count the threads share evenly where the
//!   tile rows allow (see [`Plan::new`], [`balanced_bands`]).
//! - Which variant ([`winograd_variant`]): F(4x4) where the grid has enough tiles, F(2x2) on
//!   smaller grids, im2col below [`MIN_CHANNELS`] channels or [`MIN_TILES`] tiles.
//! - F(4x4) with few channels (`C·O` up to 128·256: the encoders' 64- to 128-channel layers, the
//!   motion encoder, the flow head's and the mask head's first layers) runs in blocks of 48 tiles
//!   instead of bands where the processor has AVX-512 ([`blocks`]): the transforms and our own
//!   product kernel work on data that stay in the core's caches, a quarter to a third faster on
//!   the 64- and 96-channel layers (even at 128); the bands stay for the GRUs' 384 input
//!   channels, where the `gemm` crate's products over hundreds of tiles per read of the weights
//!   win.
//!
//! Numerics: F(2x2)'s transforms hold only 0, ±1 and ±½, so they are exact up to the rounding
//! of their additions: a max error of about 1e-6 of the output's magnitude against burn's
//! convolution at C=384, O=128. F(4x4)'s hold up to ±8 (`Aᵀ`), ±5 (`Bᵀ`) and 1/6, 1/24 (`G`,
//! not exact in f32), which grows the error about tenfold: about 1e-5 of the output's magnitude
//! at C=384, O=128. The RAFT-Stereo golden comparison with PyTorch passes with its tolerance
//! (1e-4 relative per tensor; largest 5.3e-5 as dispatched, 3.6e-5 with F(4x4) forced wherever
//! Winograd applies, 3.1e-5 with F(2x2) forced, 4.4e-5 with im2col alone: the differences are
//! rounding noise of the same size). The tests bound both variants.
//!
//! The settings' `no-winograd` turns the path off, so whole-pipeline runs can compare it with
//! the im2col path; `no-winograd-blocks` turns off the blocks only (bands everywhere).
//!
//! The products go through [`crate::product::matmul_strided_with`], the crate's one call of
//! the `gemm` crate's `unsafe` entry point.

mod blocks;
mod positions;
mod simd;
mod split;
mod transforms;
mod weight_cache;
mod weight_grad;

use dgstereo_core::tensor::reuse_buffer;

use crate::algorithm::{Bf16Unit, WinogradTile};
pub(crate) use blocks::available as blocks_available;
use positions::Positions;
pub(crate) use split::{Pending, first as split_first, second as split_second};
pub(crate) use transforms::{Conv3x3, Variant, split_row, variant};
use transforms::{Plan, transform_inputs, transform_outputs};
pub use weight_cache::UpdateLoop;
pub(crate) use weight_grad::{BAND_ELEMENTS as WEIGHT_GRAD_BAND_ELEMENTS, winograd_weight_grad};

/// `conv` by Winograd with `tile`: F(4x4) in blocks of tiles ([`blocks`]) where the dispatch
/// says `blocks` (and the processor runs them), otherwise in bands. Returns the output and its
/// dimensions.
pub(crate) fn winograd_conv(tile: WinogradTile, blocks: bool, conv: &Conv3x3) -> (Vec<f32>, [usize; 4]) {
    match blocks::Isa::detect().filter(|_| blocks && tile == WinogradTile::F4) {
        Some(isa) => blocks::blocked_conv(isa, conv),
        None => band_conv(variant(tile), conv, None),
    }
}

/// `conv` by Winograd with `tile` in bands, its products in bf16 with f32 sums on `unit`.
pub(crate) fn winograd_bf16_conv(tile: WinogradTile, unit: Bf16Unit, conv: &Conv3x3) -> (Vec<f32>, [usize; 4]) {
    band_conv(variant(tile), conv, Some(unit))
}

/// [`winograd_conv`] in bands of whole tile rows (the module's doc), the products in bf16 on
/// `unit` where it is given.
fn band_conv(variant: &Variant, conv: &Conv3x3, unit: Option<Bf16Unit>) -> (Vec<f32>, [usize; 4]) {
    let &Conv3x3 { x, x_dims, wt, o, bias, padding, epilogue } = conv;
    let c = conv.channels();
    let plan = Plan::new(variant, x_dims, padding);
    let u = Positions::new(variant, wt, [o, c], 0..c, unit);
    let k2 = plan.k2;
    plan.run(x, o, &mut vec![(); plan.jobs()], |job, image, planes, _, [v, mm, scratch]| {
        let (tile_rows, t) = (plan.tile_rows(job), plan.tiles(job));
        // Every element of `v` and `mm` is written before it is read (the transform fills all of
        // `v`, the products write all of `mm`), so stale values never leak.
        let (v, mm) = (reuse_buffer(v, k2 * c * t), reuse_buffer(mm, k2 * o * t));
        transform_inputs(variant, v, image, plan.tiling, tile_rows.clone(), scratch);
        for k in 0..k2 {
            u.product([k, k2], &mut mm[k * t..], k2 * t, &v[k * t..], k2 * t, t, false);
        }
        transform_outputs(variant, mm, planes, bias, epilogue, plan.tiling, tile_rows.len(), scratch);
    })
}

#[cfg(test)]
mod tests {
    use burn::tensor::module::conv2d;
    use burn::tensor::{Device, Distribution, Tensor};

    use super::transforms::*;
    use super::*;
    use burn::tensor::ops::ConvOptions;

    use crate::geometry::Epilogue;
    use dgstereo_core::tensor::to_vec;

    /// The largest error of F(2x2) with bf16 products, relative to the largest sum of absolute
    /// products: the inputs' rounding (2⁻⁹ each) grown by the transforms' coefficients (4e-4 at
    /// the GRU's size, 5e-3 seen with one channel, where nothing averages the rounding out).
    const BF16_F2_BOUND: f32 = 1.5e-2;
    /// The same for F(4x4), whose transforms hold larger coefficients: 6e-3 at the GRU's size
    /// (checked from 64 channels; 5-11 % with 2 to 4 channels).
    const BF16_F4_BOUND: f32 = 2e-2;

    /// Both variants in bands, and F(4x4) in blocks compiled for each instruction set the
    /// processor has, against burn's convolution (the reference) and the im2col path on one
    /// shape, without and with ReLU; returns each variant's largest error relative to the
    /// largest sum of absolute products (F(2x2) within 1e-5, F(4x4) within 4e-5).
    fn case(n: usize, [c, o]: [usize; 2], [h, w]: [usize; 2], padding: [(usize, usize); 2], bias: bool) -> [f32; 4] {
        let device = Device::flex();
        let x = Tensor::<4>::random([n, c, h, w], Distribution::Normal(0.0, 1.0), &device);
        let wt = Tensor::<4>::random([o, c, 3, 3], Distribution::Normal(0.0, 1.0 / (3.0 * c as f64).sqrt()), &device);
        let b = bias.then(|| Tensor::<1>::random([o], Distribution::Normal(0.0, 1.0), &device));
        let options = ConvOptions::new_with_padding([1, 1], padding, [1, 1], 1);
        let reference = conv2d(x.clone(), wt.clone(), b.clone(), options.clone());
        let dims = reference.dims();
        // Errors are measured against the largest sum of absolute products (|x| convolved with
        // |w|, plus |b|), the scale of the rounding. Measured against the largest output, the
        // suite failed once in some 300 runs (the case was not recorded): in the one-channel,
        // few-pixel cases every output can be small after cancellation while the terms are not.
        let magnitude = conv2d(x.clone().abs(), wt.clone().abs(), b.clone().map(|b| b.abs()), options.clone());
        let scale = to_vec(magnitude).iter().fold(1e-6f32, |m, v| m.max(*v));
        let (x, wt, b, expected) = (to_vec(x), to_vec(wt), b.map(to_vec), to_vec(reference));
        let shape = format!("n {n} c {c} o {o} {h}x{w} padding {padding:?} bias {bias}");
        let mut worst = [0.0f32; 4];
        for epilogue in [Epilogue::Linear, Epilogue::Relu] {
            let finish = |v: f32| if epilogue == Epilogue::Relu { v.max(0.0) } else { v };
            let conv = Conv3x3 { x: &x, x_dims: [n, c, h, w], wt: &wt, o, bias: b.as_deref(), padding, epilogue };
            // F(2x2) and F(4x4) in bands, then F(4x4) in blocks for every instruction set here,
            // then both in bands with bf16 products on every bf16 unit here.
            let bands = [&F2, &F4].map(|variant| {
                let got = band_conv(variant, &conv, None);
                (format!("F({}) bands", variant.m), variant.m, None, got)
            });
            let blocks = blocks::Isa::available().into_iter().map(|isa| {
                let got = blocks::blocked_conv(isa, &conv);
                (format!("F(4) blocks {isa:?}"), 4, None, got)
            });
            let units = Bf16Unit::ALL.into_iter().filter(|u| u.available());
            // F(4x4) with bf16 products only from 64 input channels: below, its error is several
            // percent (11 % seen at 2 channels), and the dispatch gives it only layers of more.
            let bf16 = units.flat_map(|unit| {
                [&F2, &F4].into_iter().filter(|v| v.m == 2 || c >= 64).map(move |variant| {
                    let got = band_conv(variant, &conv, Some(unit));
                    (format!("F({}) bands {}", variant.m, unit.name()), variant.m, Some(unit), got)
                })
            });
            for (path, m, unit, (got, got_dims)) in bands.into_iter().chain(blocks).chain(bf16) {
                let (worst, bound) = match (m, unit) {
                    (2, None) => (&mut worst[0], 1e-5),
                    (_, None) => (&mut worst[1], 4e-5),
                    (2, Some(_)) => (&mut worst[2], BF16_F2_BOUND),
                    (_, Some(_)) => (&mut worst[3], BF16_F4_BOUND),
                };
                assert_eq!(got_dims, dims, "{shape} {path}");
                for (g, e) in got.iter().zip(&expected) {
                    let (e, err) = (finish(*e), (g - finish(*e)).abs() / scale);
                    assert!(err <= bound, "{shape} {path} {epilogue:?}: winograd {g}, burn {e} (scale {scale})");
                    *worst = worst.max(err);
                }
            }
        }
        worst
    }

    #[test]
    fn winograd_agrees_with_burn_on_small_and_odd_shapes() {
        let same = [(1, 1), (1, 1)];
        for [c, o] in [[1, 1], [2, 3], [3, 2]] {
            for hw in [[1, 1], [2, 2], [3, 5], [5, 3], [6, 8], [7, 9], [10, 13]] {
                case(1, [c, o], hw, same, true);
            }
        }
        case(2, [3, 4], [9, 10], same, false);
        case(1, [2, 2], [3, 3], [(0, 0), (0, 0)], true); // a single output
        case(1, [3, 5], [8, 11], [(0, 0), (0, 0)], true);
        case(2, [4, 3], [7, 6], [(1, 0), (0, 2)], true); // asymmetric
        case(1, [3, 3], [5, 4], [(2, 1), (0, 3)], false);
        case(1, [2, 3], [1, 2], [(2, 2), (1, 2)], true);
    }

    #[test]
    fn winograd_agrees_with_burn_with_many_channels_and_bands() {
        case(2, [64, 96], [9, 14], [(1, 1), (1, 1)], true);
        case(1, [96, 64], [10, 7], [(1, 1), (1, 1)], false);
        case(1, [130, 17], [5, 6], [(0, 1), (1, 0)], true);
        // Several bands per image: one tile row per band (150 to 300 tiles a row), narrow rows.
        case(1, [4, 5], [11, 600], [(1, 1), (1, 1)], true);
        case(2, [3, 4], [71, 9], [(1, 1), (1, 1)], true);
        // Rows of whole vectors of tiles and a partial last tile (the blocked path's shuffles at
        // both row ends, blocks and vectors that cross tile rows), unpadded and asymmetric.
        case(1, [3, 4], [13, 141], [(1, 1), (1, 1)], true);
        case(1, [2, 3], [10, 133], [(0, 0), (0, 0)], false);
        case(2, [3, 2], [9, 150], [(2, 1), (0, 3)], true);
        // A block that starts at tiles wholly in a wide right padding (33 tiles a row, the
        // 33rd past the input's last column).
        case(1, [3, 2], [6, 128], [(1, 1), (0, 4)], true);
        // Smaller again after the large bands: the threads' reused buffers hold stale values.
        case(1, [2, 2], [4, 4], [(1, 1), (1, 1)], true);
    }

    #[test]
    fn winograd_error_at_the_gru_size_is_small() {
        let [f2, f4, f2_bf16, f4_bf16] = case(1, [384, 128], [12, 14], [(1, 1), (1, 1)], true);
        println!("C=384, O=128, 12x14: max error F(2x2) {f2:e}, F(4x4) {f4:e} of the largest sum of |products|");
        println!("with bf16 products: F(2x2) {f2_bf16:e}, F(4x4) {f4_bf16:e}");
        assert!(f2 <= 1e-5 && f4 <= 4e-5, "{f2} {f4}");
    }

    /// The band count is the one the threads finish soonest, fewest bands among equals.
    #[test]
    fn bands_split_evenly_over_the_threads() {
        // One image on 2 threads: 3 bands become 4 (the 1/4 grid of 320x736, 20 tile rows).
        assert_eq!(balanced_bands(3, 20, 1, 2), 4);
        assert_eq!(balanced_bands(2, 24, 1, 2), 2);
        // Two images: 3 bands give 6 jobs already.
        assert_eq!(balanced_bands(3, 20, 2, 2), 3);
        // Never more bands than tile rows.
        assert_eq!(balanced_bands(3, 3, 1, 2), 3);
        assert_eq!(balanced_bands(5, 4, 1, 2), 4);
        // 4 threads, 2 images: 4 bands of 5 rows, 8 jobs.
        assert_eq!(balanced_bands(3, 20, 2, 4), 4);
        // 17 rows on 4 threads: 5 bands (4, 4, 4, 4, 1) finish after 5 rows; a multiple of the
        // threads (8 asked, 6 of 3 rows) after 6.
        assert_eq!(balanced_bands(5, 17, 1, 4), 5);
        assert_eq!(longest_thread(4, 17, 5, 1, 4), 5);
        assert_eq!(longest_thread(3, 17, 6, 1, 4), 6);
        // One thread: the bands asked for.
        assert_eq!(balanced_bands(3, 20, 1, 1), 3);
        // Plan on the 320x736 1/4 grid (384 -> 128 at 80x184, F(4x4)): an even number of jobs
        // on 2 threads, every tile row in one band.
        let pool = rayon::ThreadPoolBuilder::new().num_threads(2).build().unwrap();
        let plan = pool.install(|| Plan::new(&F4, [1, 384, 80, 184], [(1, 1), (1, 1)]));
        assert_eq!(plan.jobs() % 2, 0, "{} jobs", plan.jobs());
        let rows: usize = (0..plan.jobs()).map(|job| plan.tile_rows(job).len()).sum();
        assert_eq!(rows, plan.tiles_h);
    }

    /// Both convolutions of a split pair against [`winograd_conv`] of the whole inputs, for both
    /// variants and a batch of two.
    #[test]
    fn a_split_pair_equals_the_two_whole_convolutions() {
        let random = |len: usize, seed: u32| -> Vec<f32> {
            (0..len).map(|i| (((i as u32).wrapping_mul(2_654_435_761) ^ seed) % 2001) as f32 / 1000.0 - 1.0).collect()
        };
        let (n, own1, own2, shared, o1, o2, h, w) = (2, 5, 4, 6, 7, 3, 13, 18);
        let c1 = own1 + shared;
        let c2 = own2 + shared;
        let x1 = random(n * c1 * h * w, 1);
        let own2_values = random(n * own2 * h * w, 2);
        let (wt1, wt2) = (random(o1 * c1 * 9, 3), random(o2 * c2 * 9, 4));
        let (b1, b2) = (random(o1, 5), random(o2, 6));
        // The second convolution's whole input: its own channels, then the first's shared ones.
        let plane = h * w;
        let mut x2 = Vec::with_capacity(n * c2 * plane);
        for b in 0..n {
            x2.extend_from_slice(&own2_values[b * own2 * plane..][..own2 * plane]);
            x2.extend_from_slice(&x1[(b * c1 + own1) * plane..][..shared * plane]);
        }
        let padding = [(1, 1), (1, 1)];
        let units = [None].into_iter().chain(Bf16Unit::ALL.into_iter().filter(|u| u.available()).map(Some));
        for (variant, unit) in units.flat_map(|unit| [(&F2, unit), (&F4, unit)]) {
            let (got1, pending) = split_first(
                variant,
                &x1,
                [n, c1, h, w],
                [&wt1, &wt2],
                [o1, o2],
                c2,
                shared,
                Some(&b1),
                padding,
                Epilogue::Relu,
                unit,
            );
            let got2 = split_second(pending, &own2_values, [n, own2, h, w], Some(&b2), Epilogue::Linear);
            let conv1 = Conv3x3 {
                x: &x1,
                x_dims: [n, c1, h, w],
                wt: &wt1,
                o: o1,
                bias: Some(&b1),
                padding,
                epilogue: Epilogue::Relu,
            };
            let want1 = band_conv(variant, &conv1, unit);
            let conv2 = Conv3x3 {
                x: &x2,
                x_dims: [n, c2, h, w],
                wt: &wt2,
                o: o2,
                bias: Some(&b2),
                padding,
                epilogue: Epilogue::Linear,
            };
            let want2 = band_conv(variant, &conv2, unit);
            for ((got, want), which) in [(got1, want1), (got2, want2)].into_iter().zip(["first", "second"]) {
                assert_eq!(got.1, want.1, "F({}) {which} {unit:?}", variant.m);
                let worst = got.0.iter().zip(&want.0).map(|(g, w)| (g - w).abs()).fold(0.0, f32::max);
                assert!(worst < 1e-4, "F({}) {which} {unit:?}: {worst}", variant.m);
            }
        }
    }
}
