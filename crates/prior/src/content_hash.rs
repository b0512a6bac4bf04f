//! A content hash of byte streams: the cache's keys and the simulated prior's per-pair seeds.

/// A 128-bit FNV-1a hash (two independent 64-bit lanes) of a byte stream.
#[derive(Debug, Clone)]
pub struct ContentHasher {
    lanes: [u64; 2],
}

impl Default for ContentHasher {
    fn default() -> Self {
        Self { lanes: [0xcbf2_9ce4_8422_2325, 0x6c62_272e_07bb_0142] }
    }
}

impl ContentHasher {
    /// Feeds bytes; a length prefix keeps `("ab", "c")` and `("a", "bc")` apart.
    pub fn update(&mut self, bytes: &[u8]) {
        const PRIMES: [u64; 2] = [0x0000_0100_0000_01b3, 0x0000_0100_0000_0233];
        for (lane, prime) in self.lanes.iter_mut().zip(PRIMES) {
            for b in (bytes.len() as u64).to_le_bytes().iter().chain(bytes) {
                *lane = (*lane ^ u64::from(*b)).wrapping_mul(prime);
            }
        }
    }

    /// The hash as 32 hex digits.
    pub fn hex(&self) -> String {
        format!("{:016x}{:016x}", self.lanes[0], self.lanes[1])
    }
}
