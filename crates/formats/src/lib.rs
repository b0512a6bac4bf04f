//! The one reader and writer of the array files the workspace meets: NumPy `.npy` arrays and
//! PFM float maps.
//!
//! Design decision: data sets (disparity ground truth) and the prior stage (precomputed depth
//! maps) read the same formats, but a stage crate may not depend on the data crate; so the
//! codecs live below both, here, on nothing but `core`'s error type. They decode to plain
//! arrays (shape and `f32` samples); what shape a caller accepts (a disparity map, a depth map)
//! is the caller's rule. Headers can be read and checked against the file's length without
//! decoding the samples ([`npy::read_npy_header`], [`pfm::read_pfm_header`]).
#![deny(missing_docs)]

pub mod file_start;
pub mod npy;
pub mod pfm;

#[cfg(test)]
mod tests;
