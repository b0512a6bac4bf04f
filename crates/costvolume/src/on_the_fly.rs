//! Correlation computed at the sampled positions only ("alt").

use burn::tensor::Tensor;
use burn::tensor::module::avg_pool2d;
use burn::tensor::ops::AvgPoolOptions;

use crate::CostVolume;
use crate::lookup::{interpolate_taps, taps};

/// Stores the left features and the pooled right features; each lookup takes the dot products
/// at the `2r + 2` integer positions around the match and interpolates between them.
///
/// Pooling the volume along `x2` equals correlating with right features pooled along `x`
/// (the dot product is linear), so the pyramid levels come from pooled `f2`. Memory is
/// `O(C·H·W)` instead of `O(H·W²)`; each lookup costs `O(levels·r·C·H·W)`.
///
/// # Shapes
/// - `fmap1`: `[N, C, H, W1]`, `pooled[i]`: `[N, C, H, W2 / 2^i]`
#[derive(Debug, Clone)]
pub struct OnTheFlyCorrelation {
    fmap1: Tensor<4>,
    pooled: Vec<Tensor<4>>,
    levels: usize,
    radius: usize,
}

impl OnTheFlyCorrelation {
    /// Prepares the lookup of `fmap1` against `fmap2`.
    pub fn new(fmap1: Tensor<4>, fmap2: Tensor<4>, levels: usize, radius: usize) -> Self {
        let mut pooled = vec![fmap2];
        for _ in 1..levels {
            let last = pooled.last().expect("level 0").clone();
            let w = last.dims()[3];
            pooled.push(if w >= 2 {
                avg_pool2d(last, AvgPoolOptions::new([1, 2]))
            } else {
                let [n, c, h, _] = last.dims();
                Tensor::zeros([n, c, h, 0], &last.device())
            });
        }
        Self { fmap1, pooled, levels, radius }
    }
}

impl CostVolume for OnTheFlyCorrelation {
    fn lookup(&self, coords_x: Tensor<4>) -> Tensor<4> {
        let [n, c, h, w1] = self.fmap1.dims();
        let m = n * h * w1;
        let taps_n = 2 * self.radius + 2;
        let x = coords_x.reshape([m, 1]);
        let mut out = Vec::with_capacity(self.levels);
        for (i, f2) in self.pooled.iter().enumerate() {
            let width = f2.dims()[3];
            let xi = x.clone().div_scalar((1u64 << i) as f64);
            let (idx, inside, w) = taps(xi, self.radius, width.max(1));
            let mut dots = Vec::with_capacity(taps_n);
            for t in 0..taps_n {
                if width == 0 {
                    dots.push(Tensor::<4>::zeros([n, 1, h, w1], &x.device()));
                    continue;
                }
                let index = idx.clone().slice([0..m, t..t + 1]).reshape([n, 1, h, w1]).expand([n, c, h, w1]);
                let sampled = f2.clone().gather(3, index);
                dots.push((sampled * self.fmap1.clone()).sum_dim(1));
            }
            // [N, T, H, W1] -> [M, T]
            let values =
                Tensor::cat(dots, 1).permute([0, 2, 3, 1]).reshape([m, taps_n]).div_scalar((c as f64).sqrt()) * inside;
            out.push(interpolate_taps(values, w, self.radius));
        }
        let k = 2 * self.radius + 1;
        Tensor::cat(out, 1).reshape([n, h, w1, self.levels * k]).permute([0, 3, 1, 2])
    }
}
