//! Which bf16 units the processor has: CPUID for the instructions, and for AMX the operating
//! system's permission to use the tile registers (Linux grants it per process on request).

use std::sync::OnceLock;

/// A unit that multiplies bf16 values into f32 sums.
#[derive(Debug, Clone, Copy, PartialEq, Eq, Hash)]
pub(crate) enum Bf16Unit {
    /// AMX: 16x16 f32 tiles of sums, `tdpbf16ps` (Intel Sapphire Rapids and later).
    Tiles,
    /// AVX512-BF16: 16 f32 sums a vector, `vdpbf16ps` (Intel Cooper Lake and later, AMD Zen 4
    /// and later).
    DotProducts,
}

impl Bf16Unit {
    /// Both units, the faster first.
    pub(crate) const ALL: [Bf16Unit; 2] = [Self::Tiles, Self::DotProducts];

    /// The unit's name, as reports print it.
    pub(crate) fn name(self) -> &'static str {
        match self {
            Self::Tiles => "amx-bf16",
            Self::DotProducts => "avx512-bf16",
        }
    }

    /// Whether this process can run the unit (checked once per process; for the tiles this asks
    /// the operating system for their state once).
    pub(crate) fn available(self) -> bool {
        match self {
            Self::DotProducts => dot_products(),
            Self::Tiles => {
                static TILES: OnceLock<bool> = OnceLock::new();
                *TILES.get_or_init(|| dot_products() && tiles_in_cpuid() && tile_data_permitted())
            }
        }
    }
}

/// AVX512-BF16 with the AVX-512 subsets the packing uses.
fn dot_products() -> bool {
    #[cfg(target_arch = "x86_64")]
    {
        is_x86_feature_detected!("avx512f")
            && is_x86_feature_detected!("avx512bw")
            && is_x86_feature_detected!("avx512bf16")
    }
    #[cfg(not(target_arch = "x86_64"))]
    false
}

/// CPUID leaf 7, sub-leaf 0: EDX bit 22 (AMX-BF16) and bit 24 (AMX-TILE). `std`'s feature
/// detection of AMX is not stable yet, so the bits are read here.
fn tiles_in_cpuid() -> bool {
    #[cfg(target_arch = "x86_64")]
    {
        // Leaf 0 says whether leaf 7 exists.
        let max_leaf = std::arch::x86_64::__cpuid(0).eax;
        if max_leaf < 7 {
            return false;
        }
        let edx = std::arch::x86_64::__cpuid_count(7, 0).edx;
        edx & (1 << 22) != 0 && edx & (1 << 24) != 0
    }
    #[cfg(not(target_arch = "x86_64"))]
    false
}

/// Asks Linux for the AMX tile data state (`arch_prctl(ARCH_REQ_XCOMP_PERM, XFEATURE_XTILEDATA)`),
/// which a process must do once before its first tile instruction; false where it refuses or
/// on another system.
fn tile_data_permitted() -> bool {
    #[cfg(all(target_arch = "x86_64", target_os = "linux", target_env = "gnu"))]
    {
        const ARCH_REQ_XCOMP_PERM: libc::c_long = 0x1023;
        const XFEATURE_XTILEDATA: libc::c_long = 18;
        // SAFETY: the request only changes which register states the kernel saves for this
        // process; it reads and writes no memory of ours.
        unsafe { libc::syscall(libc::SYS_arch_prctl, ARCH_REQ_XCOMP_PERM, XFEATURE_XTILEDATA) == 0 }
    }
    #[cfg(not(all(target_arch = "x86_64", target_os = "linux", target_env = "gnu")))]
    false
}
