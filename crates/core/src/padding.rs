//! Padding inputs to a multiple of 32, as RAFT-Stereo's evaluation does.

use burn::tensor::Tensor;
use burn::tensor::ops::PadMode;

/// Pads images so both sides are multiples of `divisor`, and removes the padding from results.
///
/// This is RAFT-Stereo's `InputPadder(divis_by=32)` in its `sintel` mode: the padding is split
/// evenly (the extra pixel goes after), in both dimensions, and filled by replicating the border.
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
pub struct InputPadder {
    /// Height and width before padding.
    pub original: [usize; 2],
    /// Padding as `[left, right, top, bottom]`.
    pub pad: [usize; 4],
}

impl InputPadder {
    /// A padder for images of `height` x `width`.
    pub fn new(height: usize, width: usize, divisor: usize) -> Self {
        let pad_h = (height.div_ceil(divisor) * divisor) - height;
        let pad_w = (width.div_ceil(divisor) * divisor) - width;
        Self { original: [height, width], pad: [pad_w / 2, pad_w - pad_w / 2, pad_h / 2, pad_h - pad_h / 2] }
    }

    /// Height and width after padding.
    pub fn padded(&self) -> [usize; 2] {
        [self.original[0] + self.pad[2] + self.pad[3], self.original[1] + self.pad[0] + self.pad[1]]
    }

    /// Pads an `[N, C, H, W]` tensor by replicating its border.
    pub fn pad(&self, x: Tensor<4>) -> Tensor<4> {
        if self.pad.iter().all(|&p| p == 0) {
            return x;
        }
        let [l, r, t, b] = self.pad;
        x.pad([(0, 0), (0, 0), (t, b), (l, r)], PadMode::Edge)
    }

    /// Crops an `[N, C, H, W]` tensor of the padded size back to the original size.
    pub fn unpad(&self, x: Tensor<4>) -> Tensor<4> {
        let [n, c, h, w] = x.dims();
        let [l, r, t, b] = self.pad;
        x.slice([0..n, 0..c, t..h - b, l..w - r])
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn padding_matches_reference_rule() {
        // The reference: pad_ht = (((ht // 32) + 1) * 32 - ht) % 32, split ht//2, ht - ht//2.
        for (h, w) in [(375usize, 1242usize), (64, 128), (1, 1), (33, 95)] {
            let p = InputPadder::new(h, w, 32);
            let ref_h = (((h / 32) + 1) * 32 - h) % 32;
            let ref_w = (((w / 32) + 1) * 32 - w) % 32;
            assert_eq!(p.pad, [ref_w / 2, ref_w - ref_w / 2, ref_h / 2, ref_h - ref_h / 2]);
            assert_eq!(p.padded()[0] % 32, 0);
            assert_eq!(p.padded()[1] % 32, 0);
        }
    }

    #[test]
    fn pad_then_unpad_is_identity_and_replicates_border() {
        let device = crate::default_device();
        let x = Tensor::<1, burn::tensor::Int>::arange(0..15, &device).float().reshape([1, 1, 3, 5]);
        let p = InputPadder::new(3, 5, 4);
        let y = p.pad(x.clone());
        assert_eq!(y.dims(), [1, 1, 4, 8]);
        let yv = y.clone().into_data().try_to_vec::<f32>().unwrap();
        // pad = [l=1, r=2, t=0, b=1]: the first column replicates column 0 of row 0 (value 0).
        assert_eq!(yv[0], 0.0);
        assert_eq!(yv[7], 4.0); // right border replicated
        let back = p.unpad(y).into_data().try_to_vec::<f32>().unwrap();
        assert_eq!(back, x.into_data().try_to_vec::<f32>().unwrap());
    }
}
