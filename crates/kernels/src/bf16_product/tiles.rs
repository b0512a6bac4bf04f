//! The AMX kernel: 32 rows by 32 columns of sums in four 16x16 f32 tiles, a step over 32 of the
//! depth loading two tiles of weights (16 rows of 32 bf16 values) and two of pairs (16 pair rows
//! of 16 columns) for four `tdpbf16ps` (32,768 multiply-adds).
//!
//! Rust has no stable AMX intrinsics, so the tile instructions are `asm!`. The tile
//! configuration (eight tiles of 16 rows of 64 bytes) is loaded at the start of each product on
//! its thread and released at its end; a block's loop, from zeroing its sums to storing them, is
//! one `asm!` statement, so no compiled code runs between tile instructions. The sums go through
//! a 32x32 buffer into `dst`, which takes the partial blocks at the edges (and the accumulation)
//! without another kernel.

use std::arch::asm;

use super::features::Bf16Unit;
use super::operands::{COL_STEP, DEPTH_STEP, Operands, ROW_STEP};

/// The 64-byte tile configuration `ldtilecfg` reads (palette 1).
#[repr(C, align(64))]
struct TileConfig {
    palette: u8,
    start_row: u8,
    reserved: [u8; 14],
    /// Bytes a row, per tile.
    colsb: [u16; 16],
    /// Rows, per tile.
    rows: [u8; 16],
}

/// The sums of one block, as the tiles store them: 32 rows of 32 f32.
#[repr(C, align(64))]
struct Sums([f32; ROW_STEP * COL_STEP]);

const _: () = assert!(ROW_STEP == 32 && COL_STEP == 32 && DEPTH_STEP == 32);

/// `dst (+)= lhs · rhs` from the packed operands on the calling thread.
pub(super) fn product(dst: &mut [f32], dst_stride: usize, operands: &Operands, accumulate: bool) {
    let Operands { lhs, pairs, cols, cols_pad } = *operands;
    let rows = lhs.rows;
    let rows_pad = rows.next_multiple_of(ROW_STEP);
    assert!(pairs.len() >= lhs.depth_pad * cols_pad && lhs.values.len() >= rows_pad * lhs.depth_pad);
    assert!(lhs.depth_pad.is_multiple_of(DEPTH_STEP) && cols_pad.is_multiple_of(COL_STEP));
    assert!(rows == 0 || cols == 0 || dst.len() >= (rows - 1) * dst_stride + cols);
    assert!(Bf16Unit::Tiles.available(), "the process may not use the AMX tiles");
    let config = TileConfig {
        palette: 1,
        start_row: 0,
        reserved: [0; 14],
        colsb: [64, 64, 64, 64, 64, 64, 64, 64, 0, 0, 0, 0, 0, 0, 0, 0],
        rows: [16, 16, 16, 16, 16, 16, 16, 16, 0, 0, 0, 0, 0, 0, 0, 0],
    };
    let mut sums = Sums([0.0; ROW_STEP * COL_STEP]);
    // SAFETY: the process has the tile state (asserted: CPUID and the operating system's
    // permission); `config` is a valid palette-1 configuration of 64 bytes.
    unsafe { asm!("ldtilecfg [{}]", in(reg) &config, options(nostack, readonly)) };
    let steps = lhs.depth_pad / DEPTH_STEP;
    for j in (0..cols).step_by(COL_STEP) {
        for r in (0..rows).step_by(ROW_STEP) {
            let a0 = lhs.values[r * lhs.depth_pad..].as_ptr();
            // SAFETY: the weights hold `rows_pad` padded rows, so rows `r..r + 32` exist; the
            // pairs hold `depth_pad / 2` pair rows of `cols_pad` columns, so columns `j..j + 32`
            // of them exist; each of the `steps` steps reads 32 values of the depth (64 bytes)
            // of the rows and 16 pair rows; the sums are stored into the 4 KiB of `sums`.
            unsafe {
                asm!(
                    "tilezero tmm0",
                    "tilezero tmm1",
                    "tilezero tmm2",
                    "tilezero tmm3",
                    "2:",
                    "tileloadd tmm4, [{a0} + {sa}*1]",
                    "tileloadd tmm5, [{a1} + {sa}*1]",
                    "tileloadd tmm6, [{b0} + {sb}*1]",
                    "tileloadd tmm7, [{b1} + {sb}*1]",
                    "tdpbf16ps tmm0, tmm4, tmm6",
                    "tdpbf16ps tmm1, tmm4, tmm7",
                    "tdpbf16ps tmm2, tmm5, tmm6",
                    "tdpbf16ps tmm3, tmm5, tmm7",
                    "add {a0}, 64",
                    "add {a1}, 64",
                    "add {b0}, {bstep}",
                    "add {b1}, {bstep}",
                    "dec {n}",
                    "jnz 2b",
                    "tilestored [{c} + {sc}*1], tmm0",
                    "lea {a0}, [{c} + 64]",
                    "tilestored [{a0} + {sc}*1], tmm1",
                    "lea {a0}, [{c} + 2048]",
                    "tilestored [{a0} + {sc}*1], tmm2",
                    "lea {a0}, [{c} + 2112]",
                    "tilestored [{a0} + {sc}*1], tmm3",
                    a0 = inout(reg) a0 => _,
                    a1 = inout(reg) a0.add(16 * lhs.depth_pad) => _,
                    b0 = inout(reg) pairs.as_ptr().add(j * 2) => _,
                    b1 = inout(reg) pairs.as_ptr().add(j * 2 + 32) => _,
                    n = inout(reg) steps => _,
                    sa = in(reg) lhs.depth_pad * 2,
                    sb = in(reg) cols_pad * 4,
                    bstep = in(reg) 16 * cols_pad * 4,
                    c = in(reg) sums.0.as_mut_ptr(),
                    sc = in(reg) COL_STEP * 4,
                    options(nostack),
                );
            }
            let (height, width) = ((rows - r).min(ROW_STEP), (cols - j).min(COL_STEP));
            for (i, sum) in sums.0.chunks_exact(COL_STEP).take(height).enumerate() {
                let out = &mut dst[(r + i) * dst_stride + j..][..width];
                if accumulate {
                    out.iter_mut().zip(sum).for_each(|(o, s)| *o += s);
                } else {
                    out.copy_from_slice(&sum[..width]);
                }
            }
        }
    }
    // SAFETY: releases the tile state this function configured.
    unsafe { asm!("tilerelease", options(nostack, nomem)) };
}
