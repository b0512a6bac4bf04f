//! Conversions between the data crate's images and tensors.

use burn::tensor::{Device, Tensor, TensorData};
use dgstereo_data::{DisparityMap, RgbImage};

/// A `[1, 3, H, W]` tensor of an image (its CHW layout is the tensor's).
pub fn image_tensor(img: &RgbImage, device: &Device) -> Tensor<4> {
    Tensor::from_data(TensorData::new(img.data.clone(), [1, 3, img.height, img.width]), device)
}

/// The first map of a `[N, 1, H, W]` tensor.
pub fn disparity_map(t: Tensor<4>) -> DisparityMap {
    let [_, _, h, w] = t.dims();
    let values = dgstereo_core::tensor::to_vec(t);
    DisparityMap { width: w, height: h, data: values[..w * h].to_vec() }
}
