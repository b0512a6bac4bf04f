//! The official preprocessing of `DepthAnythingV2.image2tensor`.
//!
//! Upstream: `Resize(width=input_size, height=input_size, keep_aspect_ratio=True,
//! ensure_multiple_of=14, resize_method='lower_bound', image_interpolation_method=cv2.INTER_CUBIC)`,
//! then `NormalizeImage(mean=[0.485, 0.456, 0.406], std=[0.229, 0.224, 0.225])` on the image in
//! 0..1. "Lower bound" scales both sides by the larger of the two factors `input_size / side`, so
//! the shorter side reaches `input_size`, then rounds each side to a multiple of 14 (half to even,
//! as `np.round`), rounding up instead when that would fall below `input_size`.

use burn::tensor::{Tensor, TensorData};
use dgstereo_core::{Error, Result};

use super::cubic::resize_bicubic;
use super::dinov2::PATCH_SIZE;

/// The input size of the official inference (`--input-size 518`).
pub const DEFAULT_INPUT_SIZE: usize = 518;
/// ImageNet channel means (RGB, 0..1).
pub const IMAGENET_MEAN: [f32; 3] = [0.485, 0.456, 0.406];
/// ImageNet channel standard deviations (RGB, 0..1).
pub const IMAGENET_STD: [f32; 3] = [0.229, 0.224, 0.225];

/// `constrain_to_multiple_of(x, min_val)` upstream: the nearest multiple of 14 (ties to even),
/// or the next one up when the nearest is below `min_val`.
fn constrain_to_multiple_of(x: f64, min_val: usize) -> usize {
    let m = PATCH_SIZE as f64;
    let mut y = (x / m).round_ties_even() * m;
    if y < min_val as f64 {
        y = (x / m).ceil() * m;
    }
    y as usize
}

/// The network input size `[height, width]` for an image of `height x width`.
///
/// Both sides are scaled by `max(input_size / height, input_size / width)` and constrained to
/// multiples of 14 no smaller than `input_size`.
///
/// # Errors
/// [`Error::Shape`] for an empty image; [`Error::config`]`("input_size", ..)` for an input size
/// of 0.
pub fn network_input_size(height: usize, width: usize, input_size: usize) -> Result<[usize; 2]> {
    if height == 0 || width == 0 {
        return Err(Error::Shape(format!("depth-anything-v2 prior: the image is empty ({height}x{width})")));
    }
    if input_size == 0 {
        return Err(Error::config("input_size", "must be at least 1 pixel (the official size is 518)"));
    }
    let scale = (input_size as f64 / height as f64).max(input_size as f64 / width as f64);
    Ok([
        constrain_to_multiple_of(scale * height as f64, input_size),
        constrain_to_multiple_of(scale * width as f64, input_size),
    ])
}

/// ImageNet normalisation of images in 0..1: `(x - mean) / std` per channel.
///
/// # Shapes
/// - `x`: `[B, 3, H, W]` -> `[B, 3, H, W]`
pub fn normalize_imagenet(x: Tensor<4>) -> Tensor<4> {
    let device = x.device();
    let mean = Tensor::<1>::from_data(TensorData::new(IMAGENET_MEAN.to_vec(), [3]), &device).reshape([1, 3, 1, 1]);
    let std = Tensor::<1>::from_data(TensorData::new(IMAGENET_STD.to_vec(), [3]), &device).reshape([1, 3, 1, 1]);
    (x - mean) / std
}

/// Images in 0..255 to the network input: `/255`, bicubic resize to [`network_input_size`]
/// (as `cv2.INTER_CUBIC`), ImageNet normalisation.
///
/// # Shapes
/// - `images`: `[B, 3, H, W]`, RGB in 0..255
/// - output: `[B, 3, H', W']` with `H'`, `W'` multiples of 14
///
/// # Errors
/// [`Error::Shape`] when the images do not have 3 channels or are empty (see
/// [`network_input_size`]).
pub fn preprocess(images: Tensor<4>, input_size: usize) -> Result<Tensor<4>> {
    let [_, c, h, w] = images.dims();
    if c != 3 {
        return Err(Error::Shape(format!(
            "depth-anything-v2 prior: takes RGB images [B, 3, H, W], got {c} channels ({:?})",
            images.dims()
        )));
    }
    let size = network_input_size(h, w, input_size)?;
    Ok(normalize_imagenet(resize_bicubic(images.div_scalar(255.0), size)))
}

#[cfg(test)]
mod tests {
    use super::*;

    /// The rule written out directly from upstream's `Resize.get_size`, in its own terms.
    fn upstream_get_size(width: usize, height: usize, target: usize) -> (usize, usize) {
        let mut scale_height = target as f64 / height as f64;
        let mut scale_width = target as f64 / width as f64;
        if scale_width > scale_height {
            scale_height = scale_width;
        } else {
            scale_width = scale_height;
        }
        let constrain = |x: f64| {
            let mut y = ((x / 14.0).round_ties_even() * 14.0) as i64;
            if y < target as i64 {
                y = ((x / 14.0).ceil() * 14.0) as i64;
            }
            y as usize
        };
        (constrain(scale_width * width as f64), constrain(scale_height * height as f64))
    }

    #[test]
    fn sizes_are_multiples_of_14_with_short_side_at_least_input_size() {
        for (h, w) in [(375, 1242), (480, 640), (1080, 1920), (518, 518), (100, 100), (2000, 300), (70, 98), (333, 334)]
        {
            for input_size in [518, 364, 700] {
                let [nh, nw] = network_input_size(h, w, input_size).unwrap();
                assert_eq!(nh % 14, 0, "{h}x{w}@{input_size} -> {nh}x{nw}");
                assert_eq!(nw % 14, 0, "{h}x{w}@{input_size} -> {nh}x{nw}");
                assert!(nh.min(nw) >= input_size, "{h}x{w}@{input_size} -> {nh}x{nw}");
                // The aspect ratio is kept up to the rounding to 14 px.
                let aspect = w as f64 / h as f64;
                let scale = nh.min(nw) as f64 / h.min(w) as f64;
                assert!((nw as f64 - aspect * nh as f64).abs() <= 14.0 * (1.0 + aspect) + 1e-9);
                assert!(scale > 0.0);
                assert_eq!((nw, nh), upstream_get_size(w, h, input_size));
            }
        }
    }

    #[test]
    fn known_sizes() {
        // 518 is already a multiple of 14 (37 patches): the short side stays 518.
        assert_eq!(network_input_size(480, 640, 518).unwrap(), [518, 686]); // 690.67 -> 49.33 -> 49 · 14
        assert_eq!(network_input_size(375, 1242, 518).unwrap(), [518, 1722]); // 1715.6 / 14 = 122.54 -> 123
        assert_eq!(network_input_size(518, 518, 518).unwrap(), [518, 518]);
        // Downscaling (SceneFlow 540x960): 960 · 518/540 = 920.9 -> 65.78 patches -> 66 · 14.
        assert_eq!(network_input_size(540, 960, 518).unwrap(), [518, 924]);
        // Portrait: the width is the shorter side. 450 · 518/375 = 621.6 -> 44.4 -> 44 · 14.
        assert_eq!(network_input_size(450, 375, 518).unwrap(), [616, 518]);
        // Upscaling a tiny image: the short side to 518.
        assert_eq!(network_input_size(100, 50, 518).unwrap(), [1036, 518]);
        // Rounding down would go below the minimum, so the side rounds up: 520 / 14 = 37.14 -> 38.
        assert_eq!(network_input_size(520, 1000, 520).unwrap(), [532, 994]);
    }

    #[test]
    fn empty_images_and_other_channel_counts_are_shape_errors() {
        for (h, w) in [(0, 10), (10, 0)] {
            let e = network_input_size(h, w, 518).unwrap_err();
            assert!(matches!(e, Error::Shape(_)) && e.to_string().contains(&format!("{h}x{w}")), "{e}");
        }
        let e = network_input_size(10, 10, 0).unwrap_err();
        assert!(matches!(&e, Error::Config(p) if p.key == "input_size"), "{e}");
        let device = dgstereo_core::default_device();
        let grey = Tensor::<4>::zeros([1, 1, 14, 14], &device);
        let e = preprocess(grey, 14).unwrap_err();
        assert!(matches!(e, Error::Shape(_)) && e.to_string().contains("1 channels"), "{e}");
        assert_eq!(preprocess(Tensor::<4>::zeros([1, 3, 14, 14], &device), 14).unwrap().dims(), [1, 3, 14, 14]);
    }
}
