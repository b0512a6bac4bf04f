//! Vectors of `f32` lanes for the blocked Winograd path: one type per instruction set, each
//! method a single instruction, inlined into a function compiled for that set.

#![allow(unsafe_code)]

/// A vector of [`Simd::WIDTH`] `f32` lanes.
pub(super) trait Simd: Copy {
    /// Lanes per vector.
    const WIDTH: usize;
    /// Every lane `value`.
    fn splat(value: f32) -> Self;
    /// The first `WIDTH` values of `src` (panics if shorter).
    fn load(src: &[f32]) -> Self;
    /// Writes the lanes to the first `WIDTH` values of `dst` (panics if shorter).
    fn store(self, dst: &mut [f32]);
    /// `self · b + c`, fused where the set has it.
    fn mul_add(self, b: Self, c: Self) -> Self;
    /// `self + b`.
    fn add(self, b: Self) -> Self;
    /// `self - b`.
    fn sub(self, b: Self) -> Self;
    /// The larger of `self` and `b`, lane by lane.
    fn max(self, b: Self) -> Self;
    /// The four phases of `4·WIDTH` values: `phases[j]` lane `l` is `src[4·l + j]`.
    fn deinterleave4(src: &[f32]) -> [Self; 4];
    /// The inverse of [`Simd::deinterleave4`]: `dst[4·l + j] = phases[j]` lane `l`.
    fn interleave4(phases: [Self; 4], dst: &mut [f32]);
}

/// Four lanes in plain Rust: what a baseline x86-64 (SSE2) or another architecture compiles.
#[derive(Clone, Copy)]
pub(super) struct Baseline([f32; 4]);

impl Simd for Baseline {
    const WIDTH: usize = 4;
    #[inline(always)]
    fn splat(value: f32) -> Self {
        Self([value; 4])
    }
    #[inline(always)]
    fn load(src: &[f32]) -> Self {
        Self(src[..4].try_into().expect("4 lanes"))
    }
    #[inline(always)]
    fn store(self, dst: &mut [f32]) {
        dst[..4].copy_from_slice(&self.0);
    }
    #[inline(always)]
    fn mul_add(self, b: Self, c: Self) -> Self {
        Self(std::array::from_fn(|l| self.0[l] * b.0[l] + c.0[l]))
    }
    #[inline(always)]
    fn add(self, b: Self) -> Self {
        Self(std::array::from_fn(|l| self.0[l] + b.0[l]))
    }
    #[inline(always)]
    fn sub(self, b: Self) -> Self {
        Self(std::array::from_fn(|l| self.0[l] - b.0[l]))
    }
    #[inline(always)]
    fn max(self, b: Self) -> Self {
        Self(std::array::from_fn(|l| self.0[l].max(b.0[l])))
    }
    #[inline(always)]
    fn deinterleave4(src: &[f32]) -> [Self; 4] {
        let src = &src[..16];
        std::array::from_fn(|j| Self(std::array::from_fn(|l| src[4 * l + j])))
    }
    #[inline(always)]
    fn interleave4(phases: [Self; 4], dst: &mut [f32]) {
        let dst = &mut dst[..16];
        for l in 0..4 {
            for (j, phase) in phases.iter().enumerate() {
                dst[4 * l + j] = phase.0[l];
            }
        }
    }
}

#[cfg(target_arch = "x86_64")]
pub(super) use x86::{Avx2, Avx512};

#[cfg(target_arch = "x86_64")]
mod x86 {
    use std::arch::x86_64::*;

    use super::Simd;

    /// Sixteen lanes of AVX-512; only for functions compiled with `avx512f` and `fma`.
    #[derive(Clone, Copy)]
    pub(in super::super) struct Avx512(__m512);

    // SAFETY (every method): the type is used only inside functions with `avx512f` enabled
    // (`blocks::band_avx512`, called where the processor has it), and the loads and stores
    // touch `WIDTH` values of a slice whose length was checked.
    impl Simd for Avx512 {
        const WIDTH: usize = 16;
        #[inline(always)]
        fn splat(value: f32) -> Self {
            Self(unsafe { _mm512_set1_ps(value) })
        }
        #[inline(always)]
        fn load(src: &[f32]) -> Self {
            let src = &src[..16];
            Self(unsafe { _mm512_loadu_ps(src.as_ptr()) })
        }
        #[inline(always)]
        fn store(self, dst: &mut [f32]) {
            let dst = &mut dst[..16];
            unsafe { _mm512_storeu_ps(dst.as_mut_ptr(), self.0) }
        }
        #[inline(always)]
        fn mul_add(self, b: Self, c: Self) -> Self {
            Self(unsafe { _mm512_fmadd_ps(self.0, b.0, c.0) })
        }
        #[inline(always)]
        fn add(self, b: Self) -> Self {
            Self(unsafe { _mm512_add_ps(self.0, b.0) })
        }
        #[inline(always)]
        fn sub(self, b: Self) -> Self {
            Self(unsafe { _mm512_sub_ps(self.0, b.0) })
        }
        #[inline(always)]
        fn max(self, b: Self) -> Self {
            Self(unsafe { _mm512_max_ps(self.0, b.0) })
        }
        // Two rounds of even/odd selection across vector pairs: [0, 2, .., 62] and [1, 3, ..,
        // 63], then the same again on those.
        #[inline(always)]
        fn deinterleave4(src: &[f32]) -> [Self; 4] {
            let (a, b, c, d) =
                (Self::load(src).0, Self::load(&src[16..]).0, Self::load(&src[32..]).0, Self::load(&src[48..]).0);
            unsafe {
                let (even, odd) = (index(&EVEN), index(&ODD));
                let (even_ab, odd_ab) = (_mm512_permutex2var_ps(a, even, b), _mm512_permutex2var_ps(a, odd, b));
                let (even_cd, odd_cd) = (_mm512_permutex2var_ps(c, even, d), _mm512_permutex2var_ps(c, odd, d));
                [
                    Self(_mm512_permutex2var_ps(even_ab, even, even_cd)),
                    Self(_mm512_permutex2var_ps(odd_ab, even, odd_cd)),
                    Self(_mm512_permutex2var_ps(even_ab, odd, even_cd)),
                    Self(_mm512_permutex2var_ps(odd_ab, odd, odd_cd)),
                ]
            }
        }
        #[inline(always)]
        fn interleave4([p0, p1, p2, p3]: [Self; 4], dst: &mut [f32]) {
            let (low, high) = (index(&LOW), index(&HIGH));
            let out = unsafe {
                let (even_ab, even_cd) =
                    (_mm512_permutex2var_ps(p0.0, low, p2.0), _mm512_permutex2var_ps(p0.0, high, p2.0));
                let (odd_ab, odd_cd) =
                    (_mm512_permutex2var_ps(p1.0, low, p3.0), _mm512_permutex2var_ps(p1.0, high, p3.0));
                [
                    _mm512_permutex2var_ps(even_ab, low, odd_ab),
                    _mm512_permutex2var_ps(even_ab, high, odd_ab),
                    _mm512_permutex2var_ps(even_cd, low, odd_cd),
                    _mm512_permutex2var_ps(even_cd, high, odd_cd),
                ]
            };
            let dst = &mut dst[..64];
            Self(out[0]).store(dst);
            Self(out[1]).store(&mut dst[16..]);
            Self(out[2]).store(&mut dst[32..]);
            Self(out[3]).store(&mut dst[48..]);
        }
    }

    /// Indices for `_mm512_permutex2var_ps` (0-15 the first operand, 16-31 the second): the
    /// even and odd elements of the pair, and the interleaving of the operands' low and high
    /// halves.
    const EVEN: [i32; 16] = [0, 2, 4, 6, 8, 10, 12, 14, 16, 18, 20, 22, 24, 26, 28, 30];
    const ODD: [i32; 16] = [1, 3, 5, 7, 9, 11, 13, 15, 17, 19, 21, 23, 25, 27, 29, 31];
    const LOW: [i32; 16] = [0, 16, 1, 17, 2, 18, 3, 19, 4, 20, 5, 21, 6, 22, 7, 23];
    const HIGH: [i32; 16] = [8, 24, 9, 25, 10, 26, 11, 27, 12, 28, 13, 29, 14, 30, 15, 31];

    #[inline(always)]
    fn index(values: &[i32; 16]) -> __m512i {
        unsafe { _mm512_loadu_si512(values.as_ptr().cast()) }
    }

    /// Eight lanes of AVX2 with FMA; only for functions compiled with `avx2` and `fma`.
    #[derive(Clone, Copy)]
    pub(in super::super) struct Avx2(__m256);

    // SAFETY (every method): as for `Avx512`, inside `blocks::band_avx2` only.
    impl Simd for Avx2 {
        const WIDTH: usize = 8;
        #[inline(always)]
        fn splat(value: f32) -> Self {
            Self(unsafe { _mm256_set1_ps(value) })
        }
        #[inline(always)]
        fn load(src: &[f32]) -> Self {
            let src = &src[..8];
            Self(unsafe { _mm256_loadu_ps(src.as_ptr()) })
        }
        #[inline(always)]
        fn store(self, dst: &mut [f32]) {
            let dst = &mut dst[..8];
            unsafe { _mm256_storeu_ps(dst.as_mut_ptr(), self.0) }
        }
        #[inline(always)]
        fn mul_add(self, b: Self, c: Self) -> Self {
            Self(unsafe { _mm256_fmadd_ps(self.0, b.0, c.0) })
        }
        #[inline(always)]
        fn add(self, b: Self) -> Self {
            Self(unsafe { _mm256_add_ps(self.0, b.0) })
        }
        #[inline(always)]
        fn sub(self, b: Self) -> Self {
            Self(unsafe { _mm256_sub_ps(self.0, b.0) })
        }
        #[inline(always)]
        fn max(self, b: Self) -> Self {
            Self(unsafe { _mm256_max_ps(self.0, b.0) })
        }
        // Each 128-bit half holds one tile's four values: a 4x4 transpose within the halves
        // gives every phase with the tiles in the order 0, 2, 4, 6 | 1, 3, 5, 7, which one
        // permutation puts in order.
        #[inline(always)]
        fn deinterleave4(src: &[f32]) -> [Self; 4] {
            let rows = [Self::load(src).0, Self::load(&src[8..]).0, Self::load(&src[16..]).0, Self::load(&src[24..]).0];
            let [p0, p1, p2, p3] = transpose_halves(rows);
            unsafe {
                let order = _mm256_setr_epi32(0, 4, 1, 5, 2, 6, 3, 7);
                let put = |v| Self(_mm256_permutevar8x32_ps(v, order));
                [put(p0), put(p1), put(p2), put(p3)]
            }
        }
        #[inline(always)]
        fn interleave4(phases: [Self; 4], dst: &mut [f32]) {
            let [p0, p1, p2, p3] = phases;
            let rows = unsafe {
                let order = _mm256_setr_epi32(0, 2, 4, 6, 1, 3, 5, 7);
                let put = |p: Self| _mm256_permutevar8x32_ps(p.0, order);
                transpose_halves([put(p0), put(p1), put(p2), put(p3)])
            };
            let dst = &mut dst[..32];
            Self(rows[0]).store(dst);
            Self(rows[1]).store(&mut dst[8..]);
            Self(rows[2]).store(&mut dst[16..]);
            Self(rows[3]).store(&mut dst[24..]);
        }
    }

    /// The 4x4 transpose of the four vectors' low halves, and of their high halves.
    #[inline(always)]
    fn transpose_halves([a, b, c, d]: [__m256; 4]) -> [__m256; 4] {
        unsafe {
            let (ab_low, cd_low) = (_mm256_unpacklo_ps(a, b), _mm256_unpacklo_ps(c, d));
            let (ab_high, cd_high) = (_mm256_unpackhi_ps(a, b), _mm256_unpackhi_ps(c, d));
            [
                _mm256_shuffle_ps::<0x44>(ab_low, cd_low),
                _mm256_shuffle_ps::<0xEE>(ab_low, cd_low),
                _mm256_shuffle_ps::<0x44>(ab_high, cd_high),
                _mm256_shuffle_ps::<0xEE>(ab_high, cd_high),
            ]
        }
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    /// The shuffles put every value where their docs say and back, and the arithmetic works
    /// lane by lane.
    fn check<S: Simd>() {
        let w = S::WIDTH;
        let src: Vec<f32> = (0..4 * w).map(|i| i as f32 - 7.5).collect();
        let lanes = |v: S| {
            let mut out = vec![0.0; w];
            v.store(&mut out);
            out
        };
        let phases = S::deinterleave4(&src);
        for (j, &phase) in phases.iter().enumerate() {
            assert_eq!(lanes(phase), (0..w).map(|l| src[4 * l + j]).collect::<Vec<_>>(), "phase {j}, width {w}");
        }
        let mut back = vec![0.0; 4 * w];
        S::interleave4(phases, &mut back);
        assert_eq!(back, src, "width {w}");

        let (a, b) = (S::load(&src), S::load(&src[w..]));
        let expect = |f: &dyn Fn(f32, f32) -> f32| (0..w).map(|l| f(src[l], src[w + l])).collect::<Vec<_>>();
        assert_eq!(lanes(a.mul_add(b, S::splat(0.5))), expect(&|x, y| x * y + 0.5));
        assert_eq!(lanes(a.add(b)), expect(&|x, y| x + y));
        assert_eq!(lanes(a.sub(b)), expect(&|x, y| x - y));
        assert_eq!(lanes(a.max(S::splat(0.0))), expect(&|x, _| x.max(0.0)));
    }

    #[test]
    fn every_instruction_set_here_shuffles_and_computes_lane_by_lane() {
        check::<Baseline>();
        #[cfg(target_arch = "x86_64")]
        {
            if is_x86_feature_detected!("avx512f") && is_x86_feature_detected!("fma") {
                check::<Avx512>();
            }
            if is_x86_feature_detected!("avx2") && is_x86_feature_detected!("fma") {
                check::<Avx2>();
            }
        }
    }
}
