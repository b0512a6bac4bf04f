//! Random tensors drawn from a generator of their own.
//!
//! Design decision: burn's `Tensor::random` draws from the backend's generator, which is
//! process-wide on the CPU, and a seeded initialisation (`Device::seed`, then every parameter
//! drawn) only gives its weights when nothing else draws in between. Tensors
//! that are only inputs (the images `bench` times, the batch `bench --train` steps on) come from
//! [`RandomValues`] instead, a ChaCha8 generator owned by the caller, so timing one model while
//! another thread initialises a seeded run changes neither.

use burn::tensor::{Device, Tensor};
use rand::{Rng, SeedableRng};
use rand_chacha::ChaCha8Rng;

use crate::tensor::from_vec;

/// A ChaCha8 generator, seeded by the caller, that draws tensors.
pub struct RandomValues(ChaCha8Rng);

impl RandomValues {
    /// The generator seeded with `seed`: the same seed draws the same values on every run.
    pub fn new(seed: u64) -> Self {
        Self(ChaCha8Rng::seed_from_u64(seed))
    }

    /// A tensor of `shape` on `device`, uniform in `low..high`, in row-major order.
    pub fn uniform<const D: usize>(&mut self, shape: [usize; D], [low, high]: [f32; 2], device: &Device) -> Tensor<D> {
        let values = (0..shape.iter().product()).map(|_| low + self.0.r#gen::<f32>() * (high - low)).collect();
        from_vec(values, shape, device)
    }
}

#[cfg(test)]
mod tests {
    use super::*;
    use crate::tensor::to_vec;

    #[test]
    fn a_seed_draws_the_same_values_whatever_the_backend_generator_does() {
        let device = Device::default();
        let first = to_vec(RandomValues::new(3).uniform([2, 5], [0.1, 1.0], &device));
        let _ = Tensor::<2>::random([64, 64], burn::tensor::Distribution::Default, &device);
        let again = to_vec(RandomValues::new(3).uniform([2, 5], [0.1, 1.0], &device));
        assert_eq!(first, again);
        assert!(first.iter().all(|v| (0.1..1.0).contains(v)), "{first:?}");
        let other = to_vec(RandomValues::new(4).uniform([2, 5], [0.1, 1.0], &device));
        assert_ne!(first, other);
    }
}
