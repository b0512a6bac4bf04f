//! Correlation computed at the sampled positions only ("alt").

use burn::tensor::module::avg_pool2d;
use burn::tensor::ops::AvgPoolOptions;
use burn::tensor::{Device, Tensor, TensorData};

use crate::dispatch::{Op, Path, PlainCall, Plan, plan};
use crate::host::on_the_fly_lookup::{self, ChannelLastFeatures};
use crate::taps::{interpolate_taps, taps};

#[derive(Debug, Clone)]
enum Storage {
    /// `fmap1` `[N, C, H, W1]`, `pooled[i]` `[N, C, H, W2 / 2^i]`.
    Tensors { fmap1: Tensor<4>, pooled: Vec<Tensor<4>> },
    /// The same, channel-last on the host (`[N, H, W, C]`).
    Host { fmap1: ChannelLastFeatures, pooled: Vec<ChannelLastFeatures>, device: Device },
}

/// Stores the left features and the pooled right features; each lookup takes the dot products
/// at the `2r + 2` integer positions around the match and interpolates between them.
///
/// Pooling the volume along `x2` equals correlating with right features pooled along `x`
/// (the dot product is linear), so the pyramid levels come from pooled `f2`. Memory is
/// `O(C·H·W)` instead of `O(H·W²)`; each lookup costs `O(levels·r·C·H·W)`. On the CPU without
/// autodiff the features live on the host and `crate::host::on_the_fly_lookup` looks them up
/// ([`Path::Host`]); elsewhere the tensor-op lookup below runs.
///
/// # Shapes
/// - `fmap1`: `[N, C, H, W1]`, `pooled[i]`: `[N, C, H, W2 / 2^i]`
#[derive(Debug, Clone)]
pub struct OnTheFlyCorrelation {
    storage: Storage,
    /// `[N, C, H, W1]` of `fmap1`.
    dims: [usize; 4],
    levels: usize,
    radius: usize,
}

impl OnTheFlyCorrelation {
    /// Prepares the lookup of `fmap1` (`[N, C, H, W1]`) against `fmap2` (`[N, C, H, W2]`), stored
    /// where the dispatch's path looks it up (host buffers or burn tensors).
    pub fn new(fmap1: Tensor<4>, fmap2: Tensor<4>, levels: usize, radius: usize) -> Self {
        let dims = fmap1.dims();
        let storage = match plan(&fmap1.device(), &PlainCall(Op::Lookup)) {
            Plan::Gpu(()) | Plan::HostTraining(()) | Plan::Stock => {
                let mut pooled = vec![fmap2];
                for _ in 1..levels {
                    let last = pooled.last().expect("level 0").clone();
                    let w = last.dims()[3];
                    pooled.push(if w >= 2 {
                        avg_pool2d(last, AvgPoolOptions::new([1, 2]))
                    } else {
                        let [n, c, h, _] = last.dims();
                        Tensor::zeros([n, c, h, 0], (&last.device(), last.dtype()))
                    });
                }
                Storage::Tensors { fmap1, pooled }
            }
            Plan::HostInference(()) => {
                let device = fmap1.device();
                let fmap2_dims = fmap2.dims();
                let mut pooled = vec![ChannelLastFeatures::from_channel_first(&host_values(fmap2), fmap2_dims)];
                for _ in 1..levels {
                    let next = pooled.last().expect("level 0").pool_columns();
                    pooled.push(next);
                }
                let fmap1 = ChannelLastFeatures::from_channel_first(&host_values(fmap1), dims);
                Storage::Host { fmap1, pooled, device }
            }
        };
        Self { storage, dims, levels, radius }
    }

    /// The path this volume looks up on.
    pub fn path(&self) -> Path {
        match self.storage {
            Storage::Tensors { .. } => Path::Stock,
            Storage::Host { .. } => Path::Host,
        }
    }
}

/// A float tensor's values on the host, row-major.
fn host_values<const D: usize>(t: Tensor<D>) -> Vec<f32> {
    t.into_data().convert::<f32>().try_into_vec::<f32>().expect("float tensor")
}

impl OnTheFlyCorrelation {
    /// Samples the levels around `coords_x`.
    ///
    /// # Shapes
    /// - `coords_x`: `[N, 1, H, W1]`; output `[N, levels · (2·radius + 1), H, W1]`, level-major
    pub fn lookup(&self, coords_x: Tensor<4>) -> Tensor<4> {
        self.lookup_levels(coords_x, self.levels, self.radius)
    }

    /// Samples the first `levels` levels (at most its own count) around `coords_x` with
    /// `radius`, which may differ from its own (DEFOM-Stereo's scale lookup).
    ///
    /// # Shapes
    /// - `coords_x`: `[N, 1, H, W1]`; output `[N, levels · (2·radius + 1), H, W1]`, level-major
    pub fn lookup_levels(&self, coords_x: Tensor<4>, levels: usize, radius: usize) -> Tensor<4> {
        assert!(levels <= self.levels, "{levels} levels looked up in a volume of {}", self.levels);
        let _work = crate::work::operation(|| crate::work::on_the_fly_macs(self.dims, levels, radius));
        let [n, c, h, w1] = self.dims;
        let k = 2 * radius + 1;
        let (fmap1, pooled) = match &self.storage {
            Storage::Tensors { fmap1, pooled } => (fmap1, pooled),
            Storage::Host { fmap1, pooled, device } => {
                assert_eq!(coords_x.dims(), [n, 1, h, w1], "coordinates must be [N, 1, H, W1] of the left features");
                let out = on_the_fly_lookup::lookup(fmap1, &pooled[..levels], &host_values(coords_x), radius);
                return Tensor::from_data(TensorData::new(out, [n, levels * k, h, w1]), device);
            }
        };
        let m = n * h * w1;
        let taps_n = 2 * radius + 2;
        let x = coords_x.reshape([m, 1]);
        let mut out = Vec::with_capacity(levels);
        for (i, f2) in pooled.iter().take(levels).enumerate() {
            let width = f2.dims()[3];
            let xi = x.clone().div_scalar((1u64 << i) as f64);
            let (idx, inside, w) = taps(xi, radius, width.max(1));
            let mut dots = Vec::with_capacity(taps_n);
            for t in 0..taps_n {
                if width == 0 {
                    dots.push(Tensor::<4>::zeros([n, 1, h, w1], (&x.device(), fmap1.dtype())));
                    continue;
                }
                let index = idx.clone().slice([0..m, t..t + 1]).reshape([n, 1, h, w1]).expand([n, c, h, w1]);
                let sampled = f2.clone().gather(3, index);
                dots.push((sampled * fmap1.clone()).sum_dim(1));
            }
            // [N, T, H, W1] -> [M, T]
            let values =
                Tensor::cat(dots, 1).permute([0, 2, 3, 1]).reshape([m, taps_n]).div_scalar((c as f64).sqrt()) * inside;
            out.push(interpolate_taps(values, w, radius));
        }
        Tensor::cat(out, 1).reshape([n, h, w1, levels * k]).permute([0, 3, 1, 2])
    }
}
