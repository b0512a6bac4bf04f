//! The materialised all-pairs pyramid ("reg").

use burn::tensor::{Device, Tensor, TensorData};

use dgstereo_core::tensor::host_values;

use crate::dispatch::{AllPairsCall, Path, Plan, plan};
use crate::gpu::gathered_lookup::GatheredLevels;
use crate::host::all_pairs::all_pairs_bf16;
use crate::host::pyramid_lookup::{self, HostLevel};
use crate::taps::{interpolate_taps, taps};

#[derive(Debug, Clone)]
enum Storage {
    Tensors(Vec<Tensor<2>>),
    /// The stock levels and, for the lookup, the looked-up ones side by side (GPU inference).
    Gathered(Vec<Tensor<2>>, Box<GatheredLevels>),
    Host {
        levels: Vec<HostLevel>,
        device: Device,
    },
}

/// All-pairs correlation per row and its average-pooled levels.
///
/// Level 0 is `corr[n,h,x1,x2] = <f1, f2> / sqrt(C)`, computed as one batched matrix product;
/// level `i` pools level `i-1` by 2 along `x2` (floor), as `avg_pool2d([1,2])` in the reference.
/// It keeps `levels + 1` entries, as the reference's `CorrBlock1D`, and looks up the first
/// `levels`.
///
/// # Shapes
/// - `levels()[i]`: `[N·H·W1, W2 / 2^i]`
#[derive(Debug, Clone)]
pub struct CorrelationPyramid {
    pyramid: Storage,
    dims: [usize; 3],
    levels: usize,
    radius: usize,
}

impl CorrelationPyramid {
    /// Builds the pyramid of `fmap1` (`[N, C, H, W1]`) against `fmap2` (`[N, C, H, W2]`), stored
    /// where the dispatch's path looks it up: host buffers, the GPU's gathered levels, or burn
    /// tensors.
    pub fn new(fmap1: Tensor<4>, fmap2: Tensor<4>, levels: usize, radius: usize) -> Self {
        let [n, _, h, w1] = fmap1.dims();
        let [_, _, _, w2] = fmap2.dims();
        let device = fmap1.device();
        let rows = n * h * w1;
        let pyramid = match plan(&device, &AllPairsCall) {
            plan @ (Plan::Gpu(()) | Plan::HostTraining(()) | Plan::Stock) => {
                let corr = all_pairs(fmap1, fmap2).reshape([n * h * w1, w2]);
                let mut pyramid = vec![corr];
                for _ in 0..levels {
                    let last = pyramid.last().expect("level 0").clone();
                    pyramid.push(pool_pairs(last));
                }
                if plan == Plan::Gpu(()) {
                    let gathered = Box::new(GatheredLevels::new(&pyramid[..levels], radius));
                    Storage::Gathered(pyramid, gathered)
                } else {
                    Storage::Tensors(pyramid)
                }
            }
            Plan::HostInference(unit) => {
                let values = match unit {
                    Some(unit) => {
                        let _work = crate::work::operation(|| crate::work::all_pairs_macs(fmap1.dims(), fmap2.dims()));
                        let dims = fmap1.dims();
                        all_pairs_bf16(&host_values(fmap1), &host_values(fmap2), dims, w2, unit)
                    }
                    None => {
                        let corr = all_pairs(fmap1, fmap2).reshape([n * h * w1, w2]);
                        corr.into_data().convert::<f32>().try_into_vec::<f32>().expect("float correlation")
                    }
                };
                let mut host = vec![HostLevel { values: values.into(), width: w2 }];
                for _ in 0..levels {
                    let next = pyramid_lookup::pool_rows(host.last().expect("level 0"), rows);
                    host.push(next);
                }
                Storage::Host { levels: host, device }
            }
        };
        Self { pyramid, dims: [n, h, w1], levels, radius }
    }

    /// The path this pyramid looks up on.
    pub fn path(&self) -> Path {
        match self.pyramid {
            Storage::Tensors(_) => Path::Stock,
            Storage::Gathered(..) => Path::Gpu,
            Storage::Host { .. } => Path::Host,
        }
    }

    /// The stored levels (`levels + 1` of them), `[N·H·W1, W2 / 2^i]` each.
    pub fn levels(&self) -> Vec<Tensor<2>> {
        match &self.pyramid {
            Storage::Tensors(t) | Storage::Gathered(t, _) => t.clone(),
            Storage::Host { levels, device } => {
                let rows = self.dims.iter().product::<usize>();
                levels
                    .iter()
                    .map(|l| Tensor::from_data(TensorData::new(l.values.to_vec(), [rows, l.width]), device))
                    .collect()
            }
        }
    }
}

/// `[N, C, H, W1] x [N, C, H, W2] -> [N, H, W1, W2]`, scaled by `1/sqrt(C)`.
pub fn all_pairs(fmap1: Tensor<4>, fmap2: Tensor<4>) -> Tensor<4> {
    let _work = crate::work::operation(|| crate::work::all_pairs_macs(fmap1.dims(), fmap2.dims()));
    let c = fmap1.dims()[1];
    let a = fmap1.permute([0, 2, 3, 1]); // N H W1 C
    let b = fmap2.permute([0, 2, 1, 3]); // N H C W2
    a.matmul(b).div_scalar((c as f64).sqrt())
}

/// Averages neighbouring pairs along the last axis, dropping an odd last column.
fn pool_pairs(x: Tensor<2>) -> Tensor<2> {
    let [m, w] = x.dims();
    let half = w / 2;
    if half == 0 {
        return x.slice([0..m, 0..0]);
    }
    x.slice([0..m, 0..2 * half]).reshape([m, half, 2]).mean_dim(2).reshape([m, half])
}

impl CorrelationPyramid {
    /// Samples the levels around `coords_x`.
    ///
    /// # Shapes
    /// - `coords_x`: `[N, 1, H, W1]`; output `[N, levels · (2·radius + 1), H, W1]`, level-major
    pub fn lookup(&self, coords_x: Tensor<4>) -> Tensor<4> {
        self.lookup_levels(coords_x, self.levels, self.radius)
    }

    /// Samples the first `levels` levels (at most the pyramid's own count) around `coords_x`
    /// with `radius`, which may differ from the pyramid's own: DEFOM-Stereo's scale lookup reads
    /// level 0 with radius 2 from the same volume.
    ///
    /// # Shapes
    /// - `coords_x`: `[N, 1, H, W1]`; output `[N, levels · (2·radius + 1), H, W1]`, level-major
    pub fn lookup_levels(&self, coords_x: Tensor<4>, levels: usize, radius: usize) -> Tensor<4> {
        assert!(levels <= self.levels, "{levels} levels looked up in a pyramid of {}", self.levels);
        let [n, h, w1] = self.dims;
        let k = 2 * radius + 1;
        let pyramid = match &self.pyramid {
            Storage::Tensors(t) => t,
            Storage::Gathered(_, gathered) if (levels, radius) == (self.levels, self.radius) => {
                let out = gathered.lookup(coords_x.reshape([n * h * w1, 1]));
                return out.reshape([n, h, w1, levels * k]).permute([0, 3, 1, 2]);
            }
            Storage::Gathered(t, _) => t,
            Storage::Host { levels: host, device } => {
                let coords = coords_x.into_data().convert::<f32>().try_into_vec::<f32>().expect("float coordinates");
                let out = pyramid_lookup::lookup(&host[..levels], &coords, self.dims, radius);
                return Tensor::from_data(TensorData::new(out, [n, levels * k, h, w1]), device);
            }
        };
        let m = n * h * w1;
        let x = coords_x.reshape([m, 1]);
        let mut out = Vec::with_capacity(levels);
        for (i, level) in pyramid.iter().take(levels).enumerate() {
            let width = level.dims()[1];
            let xi = x.clone().div_scalar((1u64 << i) as f64);
            let (idx, inside, w) = taps(xi, radius, width.max(1));
            let values = if width == 0 { inside.zeros_like() } else { level.clone().gather(1, idx) * inside };
            out.push(interpolate_taps(values, w, radius));
        }
        Tensor::cat(out, 1).reshape([n, h, w1, levels * k]).permute([0, 3, 1, 2])
    }
}
