//! `np.random.seed(seed); np.random.permutation(n)` of NumPy's legacy `RandomState`, bit for bit.
//!
//! RAFT-Stereo picks its FlyingThings3D validation pairs with that call, so reproducing its subset
//! needs NumPy's generator, not any shuffle: MT19937 seeded by Knuth's initialisation
//! (`init_genrand`, what `RandomState.seed(int)` does), and the legacy shuffle, a Fisher-Yates pass
//! from the last element down whose index `j <= i` is drawn by masked rejection (the smallest
//! all-ones mask covering `i`, 32-bit draws while `i` fits in 32 bits). NumPy keeps this stream
//! fixed across versions for `RandomState`.

/// The Mersenne Twister MT19937, as NumPy's `RandomState` runs it.
pub(crate) struct Mt19937 {
    state: [u32; 624],
    index: usize,
}

impl Mt19937 {
    const N: usize = 624;
    const M: usize = 397;

    /// The generator after `np.random.seed(seed)` (a seed that fits in 32 bits).
    pub(crate) fn new(seed: u32) -> Self {
        let mut state = [0u32; Self::N];
        state[0] = seed;
        for i in 1..Self::N {
            let previous = state[i - 1];
            state[i] = 1_812_433_253u32.wrapping_mul(previous ^ (previous >> 30)).wrapping_add(i as u32);
        }
        Self { state, index: Self::N }
    }

    /// The next 32-bit output (`genrand_int32`).
    pub(crate) fn next_u32(&mut self) -> u32 {
        if self.index >= Self::N {
            self.twist();
        }
        let mut y = self.state[self.index];
        self.index += 1;
        y ^= y >> 11;
        y ^= (y << 7) & 0x9d2c_5680;
        y ^= (y << 15) & 0xefc6_0000;
        y ^ (y >> 18)
    }

    /// Two 32-bit outputs, the first in the high half (NumPy's `next_uint64` for MT19937).
    fn next_u64(&mut self) -> u64 {
        let high = u64::from(self.next_u32());
        (high << 32) | u64::from(self.next_u32())
    }

    fn twist(&mut self) {
        for i in 0..Self::N {
            let y = (self.state[i] & 0x8000_0000) | (self.state[(i + 1) % Self::N] & 0x7fff_ffff);
            let mut value = self.state[(i + Self::M) % Self::N] ^ (y >> 1);
            if y & 1 != 0 {
                value ^= 0x9908_b0df;
            }
            self.state[i] = value;
        }
        self.index = 0;
    }

    /// A uniform value in `0..=max` (NumPy's `random_interval`).
    fn interval(&mut self, max: u64) -> u64 {
        if max == 0 {
            return 0;
        }
        let mut mask = max;
        for shift in [1, 2, 4, 8, 16, 32] {
            mask |= mask >> shift;
        }
        loop {
            let value =
                if max <= u64::from(u32::MAX) { u64::from(self.next_u32()) & mask } else { self.next_u64() & mask };
            if value <= max {
                return value;
            }
        }
    }
}

/// `np.random.seed(seed); np.random.permutation(n)`: the numbers `0..n` in NumPy's shuffled order.
pub fn numpy_permutation(seed: u32, n: usize) -> Vec<usize> {
    let mut rng = Mt19937::new(seed);
    let mut order: Vec<usize> = (0..n).collect();
    for i in (1..n).rev() {
        let j = rng.interval(i as u64) as usize;
        order.swap(i, j);
    }
    order
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn the_generator_matches_the_reference_and_numpy() {
        // The reference implementation's first output for its default seed 5489.
        assert_eq!(Mt19937::new(5489).next_u32(), 3_499_211_612);
        // NumPy: RandomState(1000).randint(0, 2**32, dtype=np.uint32), twice.
        let mut rng = Mt19937::new(1000);
        assert_eq!([rng.next_u32(), rng.next_u32()], [2_807_145_907, 882_709_079]);
    }

    #[test]
    fn permutations_match_numpy() {
        // np.random.seed(1000); np.random.permutation(20) and permutation(10).
        assert_eq!(numpy_permutation(1000, 20), [5, 18, 3, 6, 14, 16, 2, 12, 10, 11, 4, 15, 8, 9, 17, 13, 1, 0, 7, 19]);
        assert_eq!(numpy_permutation(1000, 10), [2, 6, 5, 1, 4, 9, 0, 8, 7, 3]);
        let p = numpy_permutation(1000, 4370);
        assert_eq!(p[..8], [1182, 2430, 2205, 1501, 808, 126, 134, 2759]);
        let mut first: Vec<usize> = p[..400].to_vec();
        first.sort_unstable();
        // sorted(np.random.permutation(4370)[:400]) after seed 1000: its sum and ends.
        assert_eq!(first.iter().sum::<usize>(), 868_495);
        assert_eq!(first[..6], [5, 17, 23, 31, 58, 85]);
        assert_eq!(first[394..], [4338, 4342, 4349, 4353, 4354, 4366]);
        assert!(numpy_permutation(3, 0).is_empty());
        assert_eq!(numpy_permutation(3, 1), [0]);
    }
}
