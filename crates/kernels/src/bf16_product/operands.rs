//! The operands' layouts that both kernels read: the packed weights, the pairs' padding, and
//! the rounding to bf16 (see the parent module's doc). A module of its own so that the kernels
//! and the dispatching parent share it without importing each other.

/// The weights' depth is padded to a multiple of this: one tile's 32 bf16 values a row.
pub(crate) const DEPTH_STEP: usize = 32;
/// The weights' rows are padded to a multiple of this: the tile kernel's two tiles of 16 rows.
pub(crate) const ROW_STEP: usize = 32;
/// The pairs' columns are padded to a multiple of this: two tiles (or vectors) of 16 columns.
pub(crate) const COL_STEP: usize = 32;

/// A `rows x depth` left operand in bf16, row-major with the padding of the module's doc.
#[derive(Debug, Clone)]
pub(crate) struct PackedWeights {
    /// The operand's rows (without padding).
    pub(crate) rows: usize,
    /// The operand's depth (without padding).
    pub(crate) depth: usize,
    /// The padded depth: the row stride of `values`.
    pub(super) depth_pad: usize,
    /// `rows_pad x depth_pad` bf16 bit patterns.
    pub(super) values: Vec<u16>,
}

impl PackedWeights {
    /// `lhs` (`rows x depth`, row stride `stride`) rounded to bf16 and padded.
    pub(crate) fn new(lhs: &[f32], stride: usize, [rows, depth]: [usize; 2]) -> Self {
        assert!(depth <= stride || rows == 0, "a row of {depth} values in a stride of {stride}");
        assert!(rows == 0 || lhs.len() >= (rows - 1) * stride + depth, "the weights end before row {rows}");
        let depth_pad = depth.next_multiple_of(DEPTH_STEP).max(DEPTH_STEP);
        let rows_pad = rows.next_multiple_of(ROW_STEP).max(ROW_STEP);
        let mut values = vec![0u16; rows_pad * depth_pad];
        for (r, row) in values.chunks_exact_mut(depth_pad).take(rows).enumerate() {
            for (v, &x) in row.iter_mut().zip(&lhs[r * stride..][..depth]) {
                *v = to_bf16(x);
            }
        }
        Self { rows, depth, depth_pad, values }
    }

    /// The `rows x depth` operand whose element `(r, k)` is `columns[k · stride + r]` (stored
    /// column by column: a feature map's `C x W` row read as `W x C`), rounded to bf16 and padded.
    pub(crate) fn from_columns(columns: &[f32], stride: usize, [rows, depth]: [usize; 2]) -> Self {
        assert!(rows <= stride || depth <= 1, "a column of {rows} values in a stride of {stride}");
        assert!(depth == 0 || columns.len() >= (depth - 1) * stride + rows, "the columns end before column {depth}");
        let depth_pad = depth.next_multiple_of(DEPTH_STEP).max(DEPTH_STEP);
        let rows_pad = rows.next_multiple_of(ROW_STEP).max(ROW_STEP);
        let mut values = vec![0u16; rows_pad * depth_pad];
        for k in 0..depth {
            for (r, &x) in columns[k * stride..][..rows].iter().enumerate() {
                values[r * depth_pad + k] = to_bf16(x);
            }
        }
        Self { rows, depth, depth_pad, values }
    }

    /// Bytes held.
    pub(crate) fn bytes(&self) -> usize {
        self.values.len() * size_of::<u16>()
    }
}

/// The two packed operands of one product, as the kernels read them.
pub(super) struct Operands<'a> {
    /// The packed left operand.
    pub(super) lhs: &'a PackedWeights,
    /// The right operand in pairs.
    pub(super) pairs: &'a [u16],
    /// Columns of the product.
    pub(super) cols: usize,
    /// The pairs' padded columns: their row stride in pairs.
    pub(super) cols_pad: usize,
}

/// `x` rounded to the nearest bf16 (ties to even), as its bit pattern; NaN stays NaN.
pub(crate) fn to_bf16(x: f32) -> u16 {
    let bits = x.to_bits();
    if x.is_nan() {
        return ((bits >> 16) | 0x40) as u16;
    }
    ((bits + 0x7fff + ((bits >> 16) & 1)) >> 16) as u16
}
