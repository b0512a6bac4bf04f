//! Vectors of `f32` lanes for the blocked Winograd path: AVX-512 (each method one or a few
//! instructions, inlined into a function compiled for AVX-512) and, for the tests on any
//! processor, four lanes of plain Rust.

#![allow(unsafe_code)]
// Elsewhere than on x86-64 only the tests use these vectors.
#![cfg_attr(not(target_arch = "x86_64"), allow(dead_code))]

use std::mem::MaybeUninit;

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
    /// The inverse of [`Simd::deinterleave4`]: writes `dst[4·l + j] = phases[j]` lane `l`, all
    /// `4·WIDTH` values (into an output not yet written, `dgstereo_core::tensor::unwritten`).
    fn interleave4(phases: [Self; 4], dst: &mut [MaybeUninit<f32>]);
}

/// Four lanes of plain Rust, for the tests of the block logic on any processor.
#[cfg(test)]
#[derive(Clone, Copy)]
pub(super) struct Portable([f32; 4]);

#[cfg(test)]
impl Simd for Portable {
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
    fn interleave4(phases: [Self; 4], dst: &mut [MaybeUninit<f32>]) {
        let dst = &mut dst[..16];
        for l in 0..4 {
            for (j, phase) in phases.iter().enumerate() {
                dst[4 * l + j].write(phase.0[l]);
            }
        }
    }
}

#[cfg(target_arch = "x86_64")]
pub(super) use x86::Avx512;

#[cfg(target_arch = "x86_64")]
mod x86 {
    use std::arch::x86_64::*;
    use std::mem::MaybeUninit;

    use super::Simd;

    /// Sixteen lanes of AVX-512; only for functions compiled with `avx512f` and `fma`.
    #[derive(Clone, Copy)]
    pub(crate) struct Avx512(__m512);

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
        fn interleave4([p0, p1, p2, p3]: [Self; 4], dst: &mut [MaybeUninit<f32>]) {
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
            // Stores into memory not yet written are fine through a raw pointer (`MaybeUninit`
            // has the layout of `f32`); the slice is 64 long.
            for (q, value) in out.into_iter().enumerate() {
                unsafe { _mm512_storeu_ps(dst[16 * q..].as_mut_ptr().cast::<f32>(), value) }
            }
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
        let mut back = vec![MaybeUninit::new(f32::NAN); 4 * w];
        S::interleave4(phases, &mut back);
        // SAFETY: every element was initialised (with NaN, then by `interleave4`).
        let back: Vec<f32> = back.into_iter().map(|v| unsafe { v.assume_init() }).collect();
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
        check::<Portable>();
        #[cfg(target_arch = "x86_64")]
        if is_x86_feature_detected!("avx512f") && is_x86_feature_detected!("fma") {
            check::<Avx512>();
        }
    }
}
