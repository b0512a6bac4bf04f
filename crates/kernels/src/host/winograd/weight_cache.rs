//! Transformed Winograd weights kept between calls while an update loop runs, found again by
//! the weights' values.
//!
//! In inference the update loop transforms the same weights again at every iteration (the GRUs'
//! gates and candidates, the motion encoder's convolutions): about 4 % of a 384x448 x 32 pass on
//! the Xeon. The convolution API takes plain slices (the GRU's gate weight is a concatenation
//! made at each step), so there is no identity to key a cache on; the key is the value itself. An
//! entry holds a copy of the raw weight (`O x C x 9`, a quarter of the F(4x4) transform's size)
//! and is reused only where the new weight is bit-identical to it, so a changed weight (a
//! checkpoint loaded into the same model, a validation pass between training steps) never gets
//! a stale transform. Comparing is one read of the raw weight, a fraction of the transform's cost.
//!
//! Memory decides when entries live: the transforms of the default model's loop take ~65 MB, and
//! a forward pass's peak is in the encoders at full resolution, before the loop. So the cache
//! keeps entries only while a [`UpdateLoop`] guard is alive (the model holds one around its
//! update loop) and empties when the last guard drops; outside the loop (the encoders, whose
//! weights are used once per pass) nothing is kept. Within a scope the entries share a byte
//! budget ([`BUDGET_BYTES`]), the least recently used evicted first.
//!
//! For products in bf16 an entry also keeps its transform packed per position of the tile
//! ([`packed_positions`]: `α²` [`PackedWeights`] over a range of input channels, half the
//! transform's bytes), so the weights are converted once per loop, not at every call.

use std::ops::Range;
use std::sync::{Arc, Mutex};

use super::transforms::{Variant, transform_weights};
use crate::bf16_product::{Bf16Unit, PackedWeights};

/// Bytes of transformed and raw weights the process-wide cache keeps: the update loop of the
/// default RAFT-Stereo needs ~65 MB (the GRU pairs at 1/4 and 1/8 with F(4x4) 20 MB each and
/// their raw weights, the GRU at 1/16 and the motion encoder a few MB), ~100 MB with the bf16
/// packings beside; with less, the loop's cyclic use of its weights would miss at every call
/// under the LRU order.
pub(crate) const BUDGET_BYTES: usize = 160 << 20;

/// The transformed weights over a range of input channels, packed in bf16 per position.
struct Packing {
    channels: Range<usize>,
    unit: Bf16Unit,
    positions: Arc<Vec<PackedWeights>>,
}

/// One transformed weight and the raw weight it came from.
struct Entry {
    m: usize,
    o: usize,
    raw: Vec<f32>,
    u: Arc<Vec<f32>>,
    packings: Vec<Packing>,
    last_used: u64,
}

impl Entry {
    fn bytes(&self) -> usize {
        let packed: usize = self.packings.iter().flat_map(|p| p.positions.iter()).map(PackedWeights::bytes).sum();
        (self.raw.len() + self.u.len()) * size_of::<f32>() + packed
    }
}

/// Transformed weights by value, within a byte budget, while scopes are open.
pub(crate) struct WeightCache {
    entries: Vec<Entry>,
    budget: usize,
    clock: u64,
    /// Open [`UpdateLoop`] scopes: entries are kept only while there is one.
    scopes: usize,
}

impl WeightCache {
    /// An empty cache holding at most `budget` bytes, with no scope open.
    pub(crate) const fn new(budget: usize) -> Self {
        Self { entries: Vec::new(), budget, clock: 0, scopes: 0 }
    }

    /// `U = G g Gᵀ` of `wt` (`[O, C, 3, 3]`) for `variant`, laid out as [`transform_weights`]
    /// does: from the cache where a bit-identical weight was transformed for the same variant,
    /// else transformed now (without holding the lock) and kept.
    fn get(cache: &Mutex<Self>, variant: &Variant, wt: &[f32], o: usize, c: usize) -> Arc<Vec<f32>> {
        let same = |e: &Entry| e.m == variant.m && e.o == o && e.raw.len() == wt.len() && bits_equal(&e.raw, wt);
        {
            let mut guard = cache.lock().unwrap_or_else(|poisoned| poisoned.into_inner());
            let cache = &mut *guard;
            cache.clock += 1;
            if let Some(entry) = cache.entries.iter_mut().find(|e| same(e)) {
                entry.last_used = cache.clock;
                return entry.u.clone();
            }
        }
        let u = Arc::new(transform_weights(variant, wt, o, c));
        let mut cache = cache.lock().unwrap_or_else(|poisoned| poisoned.into_inner());
        if cache.scopes > 0 {
            cache.insert(Entry { m: variant.m, o, raw: wt.to_vec(), u: u.clone(), packings: Vec::new(), last_used: 0 });
        }
        u
    }

    /// [`packed_positions`] on `cache`: from the entry of these weights where it holds the
    /// packing, else packed now from [`WeightCache::get`]'s transform and kept with its entry
    /// where the budget allows.
    fn get_packed(
        cache: &Mutex<Self>,
        variant: &Variant,
        wt: &[f32],
        [o, c]: [usize; 2],
        channels: Range<usize>,
        unit: Bf16Unit,
    ) -> Arc<Vec<PackedWeights>> {
        let same = |e: &Entry| e.m == variant.m && e.o == o && e.raw.len() == wt.len() && bits_equal(&e.raw, wt);
        let kept = |e: &Entry| {
            e.packings.iter().find(|p| p.channels == channels && p.unit == unit).map(|p| p.positions.clone())
        };
        if let Some(positions) =
            cache.lock().unwrap_or_else(|p| p.into_inner()).entries.iter().find(|e| same(e)).and_then(kept)
        {
            return positions;
        }
        let u = Self::get(cache, variant, wt, o, c);
        let k2 = (variant.m + 2) * (variant.m + 2);
        let positions: Vec<PackedWeights> =
            (0..k2).map(|k| PackedWeights::new(&u[k * c + channels.start..], k2 * c, [o, channels.len()])).collect();
        let positions = Arc::new(positions);
        let mut guard = cache.lock().unwrap_or_else(|p| p.into_inner());
        let cache = &mut *guard;
        let room = cache.budget.saturating_sub(cache.bytes());
        let bytes: usize = positions.iter().map(PackedWeights::bytes).sum();
        if let Some(entry) = cache.entries.iter_mut().find(|e| same(e)).filter(|_| bytes <= room) {
            entry.packings.push(Packing { channels, unit, positions: positions.clone() });
        }
        positions
    }

    /// Opens a scope.
    fn open(cache: &Mutex<Self>) {
        cache.lock().unwrap_or_else(|poisoned| poisoned.into_inner()).scopes += 1;
    }

    /// Closes a scope; the last one empties the cache.
    fn close(cache: &Mutex<Self>) {
        let mut cache = cache.lock().unwrap_or_else(|poisoned| poisoned.into_inner());
        cache.scopes -= 1;
        if cache.scopes == 0 {
            cache.entries = Vec::new();
        }
    }

    /// Keeps `entry`, evicting the least recently used entries until the budget holds it; an
    /// entry larger than the whole budget is not kept.
    fn insert(&mut self, mut entry: Entry) {
        let bytes = entry.bytes();
        if bytes > self.budget {
            return;
        }
        while self.bytes() + bytes > self.budget {
            let oldest = (0..self.entries.len()).min_by_key(|&i| self.entries[i].last_used);
            self.entries.swap_remove(oldest.expect("a cache over its budget has entries"));
        }
        self.clock += 1;
        entry.last_used = self.clock;
        self.entries.push(entry);
    }

    fn bytes(&self) -> usize {
        self.entries.iter().map(Entry::bytes).sum()
    }
}

/// Whether two equally long slices hold the same bits (`-0.0` differs from `0.0`, a NaN equals
/// itself), in blocks folded without branches so the comparison vectorises.
fn bits_equal(a: &[f32], b: &[f32]) -> bool {
    let lanes = |a: &[f32], b: &[f32]| a.iter().zip(b).fold(0u32, |acc, (x, y)| acc | (x.to_bits() ^ y.to_bits()));
    a.chunks(1024).zip(b.chunks(1024)).all(|(a, b)| lanes(a, b) == 0)
}

/// The process-wide cache [`transformed_weights`] uses.
static CACHE: Mutex<WeightCache> = Mutex::new(WeightCache::new(BUDGET_BYTES));

/// [`transform_weights`] of `wt` (`[O, C, 3, 3]`) for `variant`, from the process-wide cache
/// where these exact weights were transformed before in an open scope.
pub(crate) fn transformed_weights(variant: &Variant, wt: &[f32], o: usize, c: usize) -> Arc<Vec<f32>> {
    WeightCache::get(&CACHE, variant, wt, o, c)
}

/// The transform of `wt` (`[O, C, 3, 3]`) for `variant` over input channels `channels`, packed in
/// bf16 for `unit` per position of the tile (position `k`'s left operand `U_k`, `O x
/// channels.len()`), from the process-wide cache where these exact weights were packed before in
/// an open scope.
pub(crate) fn packed_positions(
    variant: &Variant,
    wt: &[f32],
    o: usize,
    c: usize,
    channels: Range<usize>,
    unit: Bf16Unit,
) -> Arc<Vec<PackedWeights>> {
    WeightCache::get_packed(&CACHE, variant, wt, [o, c], channels, unit)
}

/// A running update loop, held by the model around its iterations: while alive, the host
/// Winograd convolutions keep the weights they transform for the next call with the same weights
/// (see the module's doc), freed when the last guard drops. This never changes results (the
/// numerics of the loop's convolutions are their calls' [`crate::Numerics`]).
#[must_use = "the loop's weights are kept only while the guard is alive"]
pub struct UpdateLoop {
    _scope: (),
}

impl UpdateLoop {
    /// Opens a scope of the process-wide cache: the loop begins.
    pub fn new() -> Self {
        WeightCache::open(&CACHE);
        Self { _scope: () }
    }
}

impl Default for UpdateLoop {
    fn default() -> Self {
        Self::new()
    }
}

impl Drop for UpdateLoop {
    fn drop(&mut self) {
        WeightCache::close(&CACHE);
    }
}

#[cfg(test)]
mod tests {
    use super::super::transforms::{F2, F4};
    use super::*;

    fn weight(o: usize, c: usize, seed: u32) -> Vec<f32> {
        let hash = |i: usize| (i as u32 + 7919 * seed).wrapping_mul(2_654_435_761);
        (0..o * c * 9).map(|i| hash(i) as f32 / u32::MAX as f32 - 0.5).collect()
    }

    /// A cached transform is the fresh one; a weight that differs in one value, or the same
    /// weight for the other variant, gets its own fresh transform, never the cached one.
    #[test]
    fn the_cache_returns_the_transform_of_exactly_these_weights() {
        let cache = Mutex::new(WeightCache::new(64 << 20));
        WeightCache::open(&cache);
        let (o, c) = (8, 5);
        let wt = weight(o, c, 1);
        let first = WeightCache::get(&cache, &F4, &wt, o, c);
        assert_eq!(*first, transform_weights(&F4, &wt, o, c));
        let again = WeightCache::get(&cache, &F4, &wt, o, c);
        assert!(Arc::ptr_eq(&first, &again), "the second call did not reuse the cached transform");

        let mut changed = wt.clone();
        changed[o * c * 9 - 1] += 0.25;
        let fresh = WeightCache::get(&cache, &F4, &changed, o, c);
        assert_eq!(*fresh, transform_weights(&F4, &changed, o, c));
        assert_ne!(*fresh, *first);

        let mut signed_zero = wt.clone();
        signed_zero[3] = 0.0;
        let zero = WeightCache::get(&cache, &F4, &signed_zero, o, c);
        signed_zero[3] = -0.0;
        let negative_zero = WeightCache::get(&cache, &F4, &signed_zero, o, c);
        assert!(!Arc::ptr_eq(&zero, &negative_zero), "-0.0 matched a cached 0.0");

        let other_variant = WeightCache::get(&cache, &F2, &wt, o, c);
        assert_eq!(*other_variant, transform_weights(&F2, &wt, o, c));
    }

    /// The cache stays within its budget by evicting the least recently used entry, and does not
    /// keep an entry larger than the whole budget.
    #[test]
    fn the_cache_evicts_the_least_recently_used_within_its_budget() {
        let (o, c) = (4, 4);
        // Raw 144 + F(4x4) transform 576 floats: 2880 bytes per entry; room for two.
        let cache = Mutex::new(WeightCache::new(2 * 2880 + 100));
        WeightCache::open(&cache);
        let [a, b, d] = [1, 2, 3].map(|seed| weight(o, c, seed));
        assert!(a != b && b != d && a != d);
        let a1 = WeightCache::get(&cache, &F4, &a, o, c);
        let _b1 = WeightCache::get(&cache, &F4, &b, o, c);
        // Touch `a`, so `b` is the least recently used when `d` comes in.
        assert!(Arc::ptr_eq(&a1, &WeightCache::get(&cache, &F4, &a, o, c)));
        let _d1 = WeightCache::get(&cache, &F4, &d, o, c);
        let guard = cache.lock().unwrap();
        assert!(guard.bytes() <= guard.budget);
        let kept: Vec<&Vec<f32>> = guard.entries.iter().map(|e| &e.raw).collect();
        assert!(kept.contains(&&a) && kept.contains(&&d) && !kept.contains(&&b), "evicted the wrong entry");
        drop(guard);

        let tiny = Mutex::new(WeightCache::new(1000));
        WeightCache::open(&tiny);
        let u = WeightCache::get(&tiny, &F4, &a, o, c);
        assert_eq!(*u, transform_weights(&F4, &a, o, c));
        assert!(tiny.lock().unwrap().entries.is_empty());
    }

    /// Nothing is kept outside a scope, and closing the last scope empties the cache.
    #[test]
    fn the_cache_keeps_weights_only_while_a_scope_is_open() {
        let cache = Mutex::new(WeightCache::new(64 << 20));
        let (o, c) = (4, 4);
        let wt = weight(o, c, 4);
        let first = WeightCache::get(&cache, &F4, &wt, o, c);
        assert!(!Arc::ptr_eq(&first, &WeightCache::get(&cache, &F4, &wt, o, c)), "kept without a scope");
        WeightCache::open(&cache);
        WeightCache::open(&cache);
        let kept = WeightCache::get(&cache, &F4, &wt, o, c);
        assert!(Arc::ptr_eq(&kept, &WeightCache::get(&cache, &F4, &wt, o, c)));
        WeightCache::close(&cache);
        assert!(Arc::ptr_eq(&kept, &WeightCache::get(&cache, &F4, &wt, o, c)), "an inner scope emptied the cache");
        WeightCache::close(&cache);
        assert!(cache.lock().unwrap().entries.is_empty());
        assert_eq!(*WeightCache::get(&cache, &F4, &wt, o, c), transform_weights(&F4, &wt, o, c));
    }
}
