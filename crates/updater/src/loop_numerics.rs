//! The numerics the update loop's convolutions allow.

use dgstereo_kernels::Numerics;

/// The numerics of the update loop's convolutions: no norm after them divides by the
/// activations' statistics, so a change of rounding is not magnified and the training forward
/// may take Winograd wherever it suits.
pub(crate) const UPDATE_LOOP: Numerics = Numerics::Tolerant;
