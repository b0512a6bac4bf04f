//! Shapes shared by the dispatch and the kernels: a convolution's options and output size, the cut of an output into
//! parallel band jobs, and the element-wise epilogue a kernel applies as it writes.

use burn::nn::PaddingConfig2d;
use burn::nn::conv::Conv2d;
use burn::tensor::ops::ConvOptions;

/// The options of `conv` as the host kernel takes them; `None` for what it does not do (groups,
/// `Same` padding, which depends on the input size).
pub fn conv_options(conv: &Conv2d) -> Option<ConvOptions<2>> {
    let padding = match conv.padding {
        PaddingConfig2d::Explicit(top, left, bottom, right) => [(top, bottom), (left, right)],
        PaddingConfig2d::Valid => [(0, 0), (0, 0)],
        PaddingConfig2d::Same => return None,
    };
    (conv.groups == 1).then(|| ConvOptions::new_with_padding(conv.stride, padding, conv.dilation, 1))
}

/// What the host convolution does to each output value after adding the bias.
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
pub enum Epilogue {
    /// Nothing.
    Linear,
    /// `max(0, ·)`.
    Relu,
}

/// The `[H_out, W_out]` of a convolution of an `[h, w]` input with a `[kh, kw]` kernel and
/// `options`; panics, naming `caller`, where the padded input is smaller than the dilated kernel.
pub fn conv_output_size(
    caller: &str,
    [h, w]: [usize; 2],
    [kh, kw]: [usize; 2],
    options: &ConvOptions<2>,
) -> [usize; 2] {
    let [(ph, ph_end), (pw, pw_end)] = options.padding;
    let [dh, dw] = options.dilation;
    let (reach_h, reach_w) = (dh * (kh - 1) + 1, dw * (kw - 1) + 1);
    assert!(
        h + ph + ph_end >= reach_h && w + pw + pw_end >= reach_w,
        "{caller}: a {h}x{w} input with padding {:?} is smaller than the {reach_h}x{reach_w} kernel",
        options.padding
    );
    let [sh, sw] = options.stride;
    [(h + ph + ph_end - reach_h) / sh + 1, (w + pw + pw_end - reach_w) / sw + 1]
}

/// `out` (images of `o` output planes of `plane` values each) cut into parallel jobs of one image
/// and one band of `band_len` values of every plane: job `image·bands + band` holds that band's
/// slice of each of the image's planes, in plane order (the last band may be shorter).
pub fn band_jobs<T>(out: &mut [T], o: usize, plane: usize, band_len: usize) -> Vec<Vec<&mut [T]>> {
    let bands = plane.div_ceil(band_len);
    let images = out.len() / (o * plane).max(1);
    let mut jobs: Vec<Vec<&mut [T]>> = (0..images * bands).map(|_| Vec::with_capacity(o)).collect();
    for (i, dst) in out.chunks_mut(plane).enumerate() {
        for (band, rows) in dst.chunks_mut(band_len).enumerate() {
            jobs[(i / o) * bands + band].push(rows);
        }
    }
    jobs
}
