//! The integer hashes behind the procedural textures: deterministic per lattice point and seed.

/// A 64-bit hash of the lattice point `(ix, iy)` (splitmix64's finaliser).
pub(super) fn hash_cell(ix: i64, iy: i64, seed: u64) -> u64 {
    let z = seed ^ (ix as u64).wrapping_mul(0x9E37_79B9_7F4A_7C15) ^ (iy as u64).wrapping_mul(0xC2B2_AE3D_27D4_EB4F);
    mix64(z)
}

/// splitmix64's finaliser: a bijective scramble of `z`.
pub(super) fn mix64(mut z: u64) -> u64 {
    z = (z ^ (z >> 30)).wrapping_mul(0xBF58_476D_1CE4_E5B9);
    z = (z ^ (z >> 27)).wrapping_mul(0x94D0_49BB_1331_11EB);
    z ^ (z >> 31)
}
