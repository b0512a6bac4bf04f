//! IGEV-Stereo's geometry encoding volume, pooled into levels and sampled around a disparity.

use burn::tensor::{Device, Int, Tensor, TensorData};
use dgstereo_core::tensor::{host_values, to_vec};

use crate::dispatch::{Op, Path, PlainCall, Plan, plan};
use crate::host::geometry_lookup;
use crate::host::pyramid_lookup::{self, HostLevel};

#[derive(Debug, Clone)]
enum Storage {
    /// burn tensors `[N·H·W, G, D / 2^i]`: the reference, the differentiable path and the GPU's.
    Tensors(Vec<Tensor<3>>),
    /// Host rows `[N·H·W·G, D / 2^i]` for the hand-written lookup (CPU inference).
    Host { levels: Vec<HostLevel>, device: Device },
}

/// The geometry encoding volume of each pixel and its levels: level `i` averages level `i - 1`
/// by 2 along the disparities (dropping an odd last one), as IGEV-Stereo's
/// `Combined_Geo_Encoding_Volume` pools with `avg_pool2d([1, 2])`. Level `i` is sampled at
/// `d / 2^i + dx`, `dx = -r..=r`, by linear interpolation with zeros outside, as `grid_sample`
/// with `align_corners=True` samples. Stored where the dispatch's path samples it.
#[derive(Debug, Clone)]
pub struct GeometryPyramid {
    storage: Storage,
    /// `[N, H, W]` of the grid.
    grid: [usize; 3],
    groups: usize,
}

impl GeometryPyramid {
    /// The `levels` levels of `volume`.
    ///
    /// # Shapes
    /// - `volume`: `[N, G, D, H, W]`
    pub fn new(volume: Tensor<5>, levels: usize) -> Self {
        let [n, g, d, h, w] = volume.dims();
        let device = volume.device();
        let rows = volume.permute([0, 3, 4, 1, 2]).reshape([n * h * w, g, d]);
        let storage = match plan(&device, &PlainCall(Op::Lookup)) {
            Plan::HostInference(()) => {
                // The permuted volume in its logical order (one copy, once a pass).
                let mut host = vec![HostLevel { values: to_vec(rows).into(), width: d }];
                for _ in 1..levels {
                    let next = pyramid_lookup::pool_rows(host.last().expect("level 0"), n * h * w * g);
                    host.push(next);
                }
                Storage::Host { levels: host, device }
            }
            Plan::HostTraining(()) | Plan::Gpu(()) | Plan::Stock => {
                let mut level = rows;
                let mut stored = Vec::with_capacity(levels);
                for _ in 1..levels {
                    let half = level.dims()[2] / 2;
                    let pooled = level.clone().narrow(2, 0, 2 * half).reshape([n * h * w, g, half, 2]).mean_dim(3);
                    stored.push(level);
                    level = pooled.squeeze_dim::<3>(3);
                }
                stored.push(level);
                Storage::Tensors(stored)
            }
        };
        Self { storage, grid: [n, h, w], groups: g }
    }

    /// The path this pyramid samples on.
    pub fn path(&self) -> Path {
        match self.storage {
            Storage::Tensors(_) => Path::Stock,
            Storage::Host { .. } => Path::Host,
        }
    }

    /// The groups (channels) of the volume.
    pub fn groups(&self) -> usize {
        self.groups
    }

    /// The number of levels.
    pub fn levels(&self) -> usize {
        match &self.storage {
            Storage::Tensors(t) => t.len(),
            Storage::Host { levels, .. } => levels.len(),
        }
    }

    /// Each level sampled around `disparity` with `radius`.
    ///
    /// # Shapes
    /// - `disparity`: `[N, 1, H, W]`; each output `[N, G·(2r+1), H, W]`, group-major then offset
    pub fn lookup(&self, disparity: Tensor<4>, radius: usize) -> Vec<Tensor<4>> {
        let [n, h, w] = self.grid;
        let (g, taps) = (self.groups, 2 * radius + 1);
        match &self.storage {
            Storage::Tensors(levels) => {
                let flat = disparity.reshape([n * h * w, 1]);
                let sampled = levels.iter().enumerate().map(|(i, volume)| {
                    let at = flat.clone().div_scalar((1u32 << i) as f32);
                    sample_linear(volume, at, radius).reshape([n, h, w, g * taps]).permute([0, 3, 1, 2])
                });
                sampled.collect()
            }
            Storage::Host { levels, device } => {
                let disparity = host_values(disparity);
                let sampled = levels.iter().enumerate().map(|(i, level)| {
                    let scale = (1u32 << i) as f32;
                    let out = geometry_lookup::lookup_level(level, &disparity, scale, self.grid, g, radius);
                    Tensor::from_data(TensorData::new(out, [n, g * taps, h, w]), device)
                });
                sampled.collect()
            }
        }
    }
}

/// Linear interpolation of each row of `volume` at `at + dx`, `dx = -radius..=radius`, zero
/// outside the row (burn's operations).
///
/// # Shapes
/// - `volume`: `[M, G, D]`; `at`: `[M, 1]`; output `[M, G, 2·radius + 1]`
fn sample_linear(volume: &Tensor<3>, at: Tensor<2>, radius: usize) -> Tensor<3> {
    let [m, g, d] = volume.dims();
    let taps = 2 * radius + 1;
    let device = volume.device();
    let offsets = Tensor::<1, Int>::arange(0..taps as i64, &device).float().sub_scalar(radius as f32);
    let x = at + offsets.reshape([1, taps]);
    let x0 = x.clone().floor();
    let w1 = x - x0.clone();
    let w0 = w1.clone().neg().add_scalar(1.0);
    let tap = |corner: Tensor<2>, weight: Tensor<2>| {
        let inside = corner.clone().greater_equal_elem(0.0).bool_and(corner.clone().lower_equal_elem((d - 1) as f32));
        let weight = weight * inside.float();
        let index = corner.clamp(0.0, (d - 1) as f32).int().reshape([m, 1, taps]).expand([m, g, taps]);
        volume.clone().gather(2, index) * weight.reshape([m, 1, taps])
    };
    tap(x0.clone(), w0) + tap(x0.add_scalar(1.0), w1)
}
