//! Small conversions between tensors and plain vectors.
//!
//! The host kernels read their operands through [`host_values`], which borrows the buffer of a
//! contiguous Flex tensor instead of copying it: [`to_vec`] on a tensor whose buffer is shared
//! (a parameter, or a value also used elsewhere) copies it twice (burn's `into_data` copies the
//! shared buffer, then copies it again to raise its alignment), and those copies ran on one
//! thread between the parallel kernels (8 % of a CPU forward pass's time).

use std::mem::MaybeUninit;
use std::ops::Deref;

use burn::backend::flex::{Flex, FlexTensor};
use burn::tensor::{DType, Device, FloatDType, Tensor, TensorData};
use rayon::prelude::*;

/// A float32 tensor's values on the host, read-only: the tensor's own buffer where it is a
/// contiguous float32 Flex tensor (held alive here, no copy), a copy otherwise.
pub struct HostValues(HostStorage);

enum HostStorage {
    Borrowed(FlexTensor),
    Owned(Vec<f32>),
}

impl Deref for HostValues {
    type Target = [f32];

    fn deref(&self) -> &[f32] {
        match &self.0 {
            HostStorage::Borrowed(t) => t.as_slice::<f32>().expect("checked contiguous float32 when made"),
            HostStorage::Owned(v) => v,
        }
    }
}

impl HostValues {
    /// Whether the values are the tensor's own buffer (no copy was made).
    pub fn is_borrowed(&self) -> bool {
        matches!(self.0, HostStorage::Borrowed(_))
    }
}

/// A tensor's values in row-major order as [`HostValues`]: borrowed from a contiguous float32
/// tensor on the Flex device (no autodiff), copied through [`to_vec`] otherwise.
pub fn host_values<const D: usize>(t: Tensor<D>) -> HostValues {
    let device = t.device();
    if device == Device::flex()
        && !device.is_autodiff()
        && t.dtype() == DType::F32
        && let Ok(flex) = t.clone().try_into_primitive::<Flex>()
        && flex.as_slice::<f32>().is_some()
    {
        return HostValues(HostStorage::Borrowed(flex));
    }
    HostValues(HostStorage::Owned(to_vec(t)))
}

/// A vector of `len` zeros, written by both cores: a large `vec![0.0; len]` is one `memset` on
/// the calling thread, which the host kernels' output buffers paid between their parallel
/// passes.
pub fn zeros_parallel(len: usize) -> Vec<f32> {
    let mut v = Vec::with_capacity(len);
    v.par_extend(rayon::iter::repeat_n(0.0f32, len));
    v
}

/// A buffer of `len` values not yet written, for an output that a parallel pass writes whole:
/// no zeros first. Zero-filling every host output before the kernel overwrote it was about 4 %
/// of a CPU pass's samples, mostly the Winograd convolutions' outputs. [`written`] turns it
/// into values once every element is written.
///
/// In tests and debug builds the buffer starts as NaN, so a value the pass failed to write shows
/// in the output (as stale memory from a buffer of the same size, freed a moment ago, might not).
pub fn unwritten(len: usize) -> Box<[MaybeUninit<f32>]> {
    let mut buffer = Box::new_uninit_slice(len);
    if cfg!(any(test, debug_assertions)) {
        buffer.iter_mut().for_each(|v| {
            v.write(f32::NAN);
        });
    }
    buffer
}

/// The values of a buffer from [`unwritten`], every element of which has been written.
///
/// # Safety
/// Every element of `buffer` must have been written (`MaybeUninit::write` or a copy into it).
#[allow(unsafe_code)]
pub unsafe fn written(buffer: Box<[MaybeUninit<f32>]>) -> Vec<f32> {
    // SAFETY: the caller guarantees that every element is initialised.
    unsafe { buffer.assume_init() }.into_vec()
}

/// `planes` planes of `plane` values each, plane `i` the first `plane` values of `values(i)`,
/// computed in parallel and written once: no zeros first (as with the crate's `unwritten` buffers).
///
/// # Panics
/// When `values(i)` yields fewer than `plane` values.
pub fn planes_from<I: Iterator<Item = f32>>(
    planes: usize,
    plane: usize,
    values: impl Fn(usize) -> I + Sync,
) -> Vec<f32> {
    let mut out = unwritten(planes * plane);
    out.par_chunks_mut(plane.max(1)).enumerate().for_each(|(i, dst)| {
        let count = dst.iter_mut().zip(values(i)).map(|(d, v)| d.write(v)).count();
        assert_eq!(count, dst.len(), "planes_from: plane {i} has {count} of {} values", dst.len());
    });
    // SAFETY: every plane's values were all written (asserted above; a failed assertion panics
    // out of the parallel loop before this line).
    #[allow(unsafe_code)]
    unsafe {
        written(out)
    }
}

/// The first `len` elements of a reused scratch buffer, grown (with zeros) only when shorter.
/// Resizing a thread's buffer down for a small convolution and up again for the next large one
/// wrote zeros over the regrown part every time (1-1.5 % of a CPU forward pass); the callers
/// write every element they read, so what the buffer held before never matters.
pub fn reuse_buffer(buffer: &mut Vec<f32>, len: usize) -> &mut [f32] {
    if buffer.len() < len {
        buffer.resize(len, 0.0);
    }
    &mut buffer[..len]
}

/// A tensor's values as a flat `Vec<f32>` in row-major order.
pub fn to_vec<const D: usize>(t: Tensor<D>) -> Vec<f32> {
    // `try_into_vec` takes the buffer over when the tensor owned it alone (no copy), where
    // `try_to_vec` would always copy it.
    t.into_data().convert::<f32>().try_into_vec::<f32>().expect("float tensor data")
}

/// A float tensor of `shape` from row-major `values`.
///
/// # Panics
/// When `values.len()` is not the product of `shape`.
pub fn from_vec<const D: usize>(values: Vec<f32>, shape: [usize; D], device: &Device) -> Tensor<D> {
    Tensor::from_data(TensorData::new(values, shape), device)
}

/// The largest absolute difference between two tensors of the same shape.
pub fn max_abs_diff<const D: usize>(a: Tensor<D>, b: Tensor<D>) -> f32 {
    let a = to_vec(a);
    let b = to_vec(b);
    a.iter().zip(&b).map(|(x, y)| (x - y).abs()).fold(0.0, f32::max)
}

/// Instance normalisation of `[N, C, H, W]` over `H, W` (biased variance, no affine).
pub fn instance_norm(x: Tensor<4>, epsilon: f64) -> Tensor<4> {
    let [n, c, h, w] = x.dims();
    let flat = x.reshape([n, c, h * w]);
    let mean = flat.clone().mean_dim(2);
    let centred = flat - mean;
    let var = centred.clone().square().mean_dim(2);
    (centred / var.add_scalar(epsilon).sqrt()).reshape([n, c, h, w])
}

/// `t` in the float dtype `dtype`: itself when it is already, else a cast.
pub fn cast_float<const D: usize>(t: Tensor<D>, dtype: FloatDType) -> Tensor<D> {
    if t.dtype() == DType::from(dtype) { t } else { t.cast(dtype) }
}

#[cfg(test)]
mod tests {
    use burn::tensor::Distribution;

    use super::*;

    /// Every plane gets its values in order; a plane short of values is refused (a panic, not
    /// a buffer with unwritten values).
    #[test]
    fn planes_from_writes_every_plane_and_refuses_short_ones() {
        let out = planes_from(3, 4, |i| (0..4).map(move |j| (10 * i + j) as f32));
        assert_eq!(out, [0., 1., 2., 3., 10., 11., 12., 13., 20., 21., 22., 23.]);
        assert!(planes_from(0, 4, |_| std::iter::empty()).is_empty());
        let short = std::panic::catch_unwind(|| planes_from(2, 4, |i| (0..4 - i).map(|j| j as f32)));
        assert!(short.is_err());
    }

    #[test]
    fn host_values_borrow_a_shared_flex_buffer_and_copy_otherwise() {
        let device = Device::flex();
        let t = Tensor::<3>::random([2, 3, 5], Distribution::Normal(0.0, 1.0), &device);
        let expected = to_vec(t.clone());
        // Shared (the clone stays alive), as a parameter's value is: borrowed, same values.
        let shared = host_values(t.clone());
        assert!(shared.is_borrowed());
        assert_eq!(&*shared, expected.as_slice());
        // A permuted view is not contiguous: copied, in row-major order of the view.
        let permuted = t.clone().permute([2, 0, 1]);
        let view = host_values(permuted.clone());
        assert!(!view.is_borrowed());
        assert_eq!(&*view, to_vec(permuted).as_slice());
        // On the autodiff device: copied.
        let ad = device.clone().autodiff();
        let on_ad = host_values(Tensor::<3>::from_data(t.to_data(), &ad));
        assert!(!on_ad.is_borrowed());
        assert_eq!(&*on_ad, expected.as_slice());
    }

    #[test]
    fn zeros_parallel_is_zeros_of_the_length() {
        for len in [0, 1, 1000, 1 << 20] {
            let v = zeros_parallel(len);
            assert_eq!(v.len(), len);
            assert!(v.iter().all(|&x| x == 0.0));
        }
    }
}
