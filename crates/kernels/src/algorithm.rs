//! The algorithms a plan of the dispatch names, as the kernels that carry them out take them.
//!
//! The dispatch (`crate::dispatch`) chooses them; the host kernels and the training nodes only
//! read them. They live below both, so neither layer imports the other.

pub(crate) use crate::bf16_product::Bf16Unit;

/// Winograd's output tile.
#[derive(Debug, Clone, Copy, PartialEq, Eq, Hash)]
pub(crate) enum WinogradTile {
    /// F(2x2, 3x3).
    F2,
    /// F(4x4, 3x3).
    F4,
}

/// How the host convolution computes one convolution.
#[derive(Debug, Clone, Copy, PartialEq, Eq, Hash)]
pub(crate) enum ConvAlgorithm {
    /// Winograd with `tile`, in cache-resident blocks of tiles (AVX-512) when `blocks`, else in
    /// bands of tile rows.
    Winograd {
        /// The output tile.
        tile: WinogradTile,
        /// Blocks rather than bands.
        blocks: bool,
    },
    /// The product first over the unshifted input, then shifted sums (few outputs).
    FewOutputs,
    /// im2col tiles and the `gemm` crate.
    Im2col,
    /// im2col tiles and bf16 products with f32 sums on `unit` (inference in bf16).
    Im2colBf16(Bf16Unit),
    /// Winograd with `tile` in bands, its products in bf16 with f32 sums on `unit` (inference
    /// in bf16).
    WinogradBf16 {
        /// The output tile.
        tile: WinogradTile,
        /// The unit of the products.
        unit: Bf16Unit,
    },
}

/// The training node's algorithms: its forward's, its input gradient's (a host convolution of
/// the output gradient; `None`: burn's transposed convolution) and its weight gradient's
/// (Winograd's transforms with a tile, or `None`: the products with the forward's columns).
#[derive(Debug, Clone, Copy, PartialEq, Eq, Hash)]
pub(crate) struct ConvTraining {
    /// The forward.
    pub(crate) forward: ConvAlgorithm,
    /// The input gradient's host convolution.
    pub(crate) input_grad: Option<ConvAlgorithm>,
    /// The weight gradient's Winograd tile.
    pub(crate) weight_grad: Option<WinogradTile>,
}

/// The fused host ConvGRU step's convolutions: both by Winograd with the candidate's `x`
/// channels transformed once (`shared`), or each by its own algorithm.
#[derive(Debug, Clone, Copy, PartialEq, Eq, Hash)]
pub(crate) enum GruAlgorithm {
    /// Both convolutions by Winograd with this tile, sharing the `x` channels' transforms.
    Shared(WinogradTile),
    /// [`GruAlgorithm::Shared`] with the products in bf16 with f32 sums on the unit.
    SharedBf16(WinogradTile, Bf16Unit),
    /// The gates' and the candidate's convolutions each by its own algorithm.
    Separate {
        /// `[convz, convr]` fused.
        gates: ConvAlgorithm,
        /// `convq`.
        candidate: ConvAlgorithm,
    },
}

/// How the GPU's matrix product builds its column matrix.
#[derive(Debug, Clone, Copy, PartialEq, Eq, Hash)]
pub(crate) enum GpuColumns {
    /// One `select` of precomputed indices from the input with a zero column appended; rows
    /// `(c, ky, kx)`; any stride.
    Gathered,
    /// The input padded, its `kh·kw` shifted windows sliced and concatenated; rows `(ky, kx, c)`;
    /// stride 1 only.
    Windows,
}

/// How the GPU's matrix product carries out one convolution (or the ConvGRU step's two, over
/// shared columns): the column matrix, whether the product comes before the shift (few outputs
/// from many inputs) and whether the bias and the element-wise work after the convolution are
/// issued on the product's shape, so that burn's fusion takes them into its epilogue.
#[derive(Debug, Clone, Copy, PartialEq, Eq, Hash)]
pub(crate) struct GpuConvForm {
    /// How the column matrix is built.
    pub(crate) columns: GpuColumns,
    /// The product of the weight with the input as it lies, then the shifted planes summed.
    pub(crate) product_first: bool,
    /// The bias reshaped before the product where work follows the convolution.
    pub(crate) fused_epilogue: bool,
}
