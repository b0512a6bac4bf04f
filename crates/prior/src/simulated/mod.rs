//! The `simulated` prior provider: a monocular-like prior made from ground-truth disparity.
//!
//! It lets the fusion and the rest of the model be trained and ablated without running a
//! network, with errors whose size is known. Each view goes through, in this order:
//!
//! 1. **Holes filled as a monocular network would**: invalid ground truth (non-finite or ≤ 0:
//!    occlusions, sky, sensor gaps) is dense in a network's output, continuing the surface
//!    behind; each invalid run of a row takes the smaller (background) disparity bordering it
//!    ([`map_ops::fill_holes_background`]).
//! 2. **Normalisation** by the view's largest disparity, so values lie in `(0, 1]` (ground-truth
//!    disparity is already proportional to inverse depth, the prior's quantity).
//! 3. **Smooth non-linear distortion**: `x^γ`, `γ` log-uniform in `gamma`. Monotone, so the
//!    ordering of depths is kept while ratios are not, as for real relative-depth networks.
//! 4. **Rounded edges**: a Gaussian blur of `blur_sigma` pixels, so depth discontinuities become
//!    ramps, as in upsampled network output.
//! 5. **Noise**: i.i.d. Gaussian with standard deviation `noise_std` (in the normalised units).
//! 6. **Unknown scale and shift**: `s·x + t`, `s` log-uniform in `scale`, `t` uniform in `shift`,
//!    then clamped at 0 (the network ends in a ReLU).
//!
//! The right view: [`PriorInput`] carries only the left ground truth, so the right view's
//! disparity is the left one forward-warped (`x_r = round(x_l - d)`, nearest surface wins) and
//! its disocclusions are holes filled by step 1 — the right view's own ground truth, where a
//! dataset has it, is not used. Each view draws its own `γ`, `s`, `t` and noise, as a monocular
//! network sees each image alone.
//!
//! Determinism: the draws of a batch element come from ChaCha8 seeded by `seed` and a hash of
//! that element's ground truth, so equal seeds and inputs give identical priors and batching
//! does not change them.

pub mod map_ops;

use burn::tensor::{Tensor, TensorData};
use dgstereo_core::tensor::to_vec;
use dgstereo_core::{Error, Problem, Result};
use rand::{Rng, SeedableRng};
use rand_chacha::ChaCha8Rng;
use serde::{Deserialize, Serialize};

use crate::content_hash::ContentHasher;
use crate::{DepthPrior, PriorInput, PriorProvider};
use map_ops::{fill_holes_background, gaussian_blur, warp_left_to_right};

fn default_scale() -> [f32; 2] {
    [0.5, 2.0]
}
fn default_shift() -> [f32; 2] {
    [0.0, 0.3]
}
fn default_gamma() -> [f32; 2] {
    [0.7, 1.4]
}
fn default_blur_sigma() -> f32 {
    1.5
}
fn default_noise_std() -> f32 {
    0.01
}

/// Parameters of the simulated prior's errors (the `[prior]` table with `kind = "simulated"`).
#[derive(Debug, Clone, PartialEq, Serialize, Deserialize)]
#[serde(deny_unknown_fields)]
pub struct SimulatedPriorConfig {
    /// Seed of the random draws.
    #[serde(default)]
    pub seed: u64,
    /// Range `[min, max]` of the unknown scale `s` (log-uniform, positive).
    #[serde(default = "default_scale")]
    pub scale: [f32; 2],
    /// Range `[min, max]` of the unknown shift `t`, in units of the normalised prior (uniform).
    #[serde(default = "default_shift")]
    pub shift: [f32; 2],
    /// Range `[min, max]` of the exponent `γ` (log-uniform, positive); `[1, 1]` is linear.
    #[serde(default = "default_gamma")]
    pub gamma: [f32; 2],
    /// Standard deviation of the edge-rounding blur, in pixels (0: none).
    #[serde(default = "default_blur_sigma")]
    pub blur_sigma: f32,
    /// Standard deviation of the per-pixel noise, in normalised units (0: none).
    #[serde(default = "default_noise_std")]
    pub noise_std: f32,
}

impl Default for SimulatedPriorConfig {
    fn default() -> Self {
        Self {
            seed: 0,
            scale: default_scale(),
            shift: default_shift(),
            gamma: default_gamma(),
            blur_sigma: default_blur_sigma(),
            noise_std: default_noise_std(),
        }
    }
}

impl SimulatedPriorConfig {
    /// An error-free prior: the normalised ground truth itself (no distortion, blur, noise,
    /// scale or shift). A baseline, and a base for tests that switch on one error at a time.
    pub fn exact(seed: u64) -> Self {
        Self { seed, scale: [1.0, 1.0], shift: [0.0, 0.0], gamma: [1.0, 1.0], blur_sigma: 0.0, noise_std: 0.0 }
    }

    /// Everything wrong with the ranges, keys relative to the prior table (`scale`, `gamma`).
    pub fn problems(&self) -> Vec<Problem> {
        let mut problems = Vec::new();
        for (key, [lo, hi], positive) in
            [("scale", self.scale, true), ("shift", self.shift, false), ("gamma", self.gamma, true)]
        {
            if !(lo.is_finite() && hi.is_finite() && lo <= hi) || (positive && lo <= 0.0) {
                let floor = if positive { " and min > 0" } else { "" };
                problems.push(Problem::new(
                    key,
                    format!("[{lo}, {hi}]: expected finite [min, max] with min <= max{floor}"),
                ));
            }
        }
        for (key, v) in [("blur_sigma", self.blur_sigma), ("noise_std", self.noise_std)] {
            if !(v.is_finite() && v >= 0.0) {
                problems.push(Problem::new(key, format!("{v}: expected a finite value >= 0")));
            }
        }
        problems
    }

    /// Checks the ranges.
    ///
    /// # Errors
    /// [`Error::Config`] with the first of [`problems`](Self::problems), its key relative to the
    /// prior table.
    pub fn validate(&self) -> Result<()> {
        Problem::first(self.problems())
    }
}

/// The random draws of one view.
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct ViewDraw {
    /// The exponent `γ`.
    pub gamma: f32,
    /// The scale `s`.
    pub scale: f32,
    /// The shift `t`.
    pub shift: f32,
}

fn log_uniform(rng: &mut ChaCha8Rng, [lo, hi]: [f32; 2]) -> f32 {
    if lo == hi { lo } else { (rng.gen_range(lo.ln()..hi.ln())).exp() }
}

fn uniform(rng: &mut ChaCha8Rng, [lo, hi]: [f32; 2]) -> f32 {
    if lo == hi { lo } else { rng.gen_range(lo..hi) }
}

/// A standard normal sample (Box-Muller).
fn standard_normal(rng: &mut ChaCha8Rng) -> f32 {
    let u1: f32 = rng.gen_range(f32::EPSILON..1.0);
    let u2: f32 = rng.r#gen();
    (-2.0 * u1.ln()).sqrt() * (2.0 * std::f32::consts::PI * u2).cos()
}

/// Steps 1-6 of the module documentation on one view's disparity (holes as NaN or ≤ 0).
///
/// # Shapes
/// - `disparity`, output: `height · width`, row-major
pub fn simulate_view(
    disparity: &[f32],
    height: usize,
    width: usize,
    config: &SimulatedPriorConfig,
    rng: &mut ChaCha8Rng,
) -> (Vec<f32>, ViewDraw) {
    let draw = ViewDraw {
        gamma: log_uniform(rng, config.gamma),
        scale: log_uniform(rng, config.scale),
        shift: uniform(rng, config.shift),
    };
    let mut x = disparity.to_vec();
    fill_holes_background(&mut x, height, width);
    let max = x.iter().copied().fold(0.0, f32::max);
    if max > 0.0 {
        x.iter_mut().for_each(|v| *v = (*v / max).powf(draw.gamma));
    }
    let mut x = gaussian_blur(&x, height, width, config.blur_sigma);
    if config.noise_std > 0.0 {
        x.iter_mut().for_each(|v| *v += config.noise_std * standard_normal(rng));
    }
    x.iter_mut().for_each(|v| *v = (draw.scale * *v + draw.shift).max(0.0));
    (x, draw)
}

/// The simulated prior provider.
#[derive(Debug, Clone)]
pub struct SimulatedPrior {
    config: SimulatedPriorConfig,
}

impl SimulatedPrior {
    /// A provider with these error parameters (checked).
    pub fn new(config: SimulatedPriorConfig) -> Result<Self> {
        // A built provider's errors name keys under `prior`, as the other providers' do.
        config.validate().map_err(|e| e.within("prior"))?;
        Ok(Self { config })
    }

    /// The generator of one batch element: the seed mixed with a hash of its ground truth.
    pub fn element_rng(&self, disparity: &[f32]) -> ChaCha8Rng {
        let mut hasher = ContentHasher::default();
        hasher.update(&self.config.seed.to_le_bytes());
        hasher.update(&disparity.iter().flat_map(|v| v.to_le_bytes()).collect::<Vec<u8>>());
        let hex = hasher.hex();
        ChaCha8Rng::seed_from_u64(u64::from_str_radix(&hex[..16], 16).expect("hex") ^ self.config.seed)
    }

    /// Both views' priors and draws of one element's left disparity.
    ///
    /// # Shapes
    /// - `disparity`: `height · width`; outputs likewise
    pub fn simulate_pair(&self, disparity: &[f32], height: usize, width: usize) -> [(Vec<f32>, ViewDraw); 2] {
        let mut rng = self.element_rng(disparity);
        let left = simulate_view(disparity, height, width, &self.config, &mut rng);
        let right_disparity = warp_left_to_right(disparity, height, width);
        let right = simulate_view(&right_disparity, height, width, &self.config, &mut rng);
        [left, right]
    }
}

impl PriorProvider for SimulatedPrior {
    fn provide(&self, input: &PriorInput) -> Result<Option<DepthPrior>> {
        let gt = input.gt_disparity.as_ref().ok_or_else(|| {
            Error::config(
                "prior.kind",
                "'simulated' needs ground-truth disparity (PriorInput.gt_disparity), which this input lacks",
            )
        })?;
        let [n, c, h, w] = gt.dims();
        let [ni, _, hi, wi] = input.left.dims();
        if c != 1 || [n, h, w] != [ni, hi, wi] {
            return Err(Error::Shape(format!(
                "simulated prior: ground truth {:?} does not fit images {:?}",
                gt.dims(),
                input.left.dims()
            )));
        }
        let values = to_vec(gt.clone());
        let (mut left, mut right) = (Vec::with_capacity(n * h * w), Vec::with_capacity(n * h * w));
        for element in values.chunks_exact(h * w) {
            let [(l, _), (r, _)] = self.simulate_pair(element, h, w);
            left.extend(l);
            right.extend(r);
        }
        let device = gt.device();
        let tensor = |v: Vec<f32>| Tensor::<4>::from_data(TensorData::new(v, [n, 1, h, w]), &device);
        Ok(Some(DepthPrior { left: tensor(left), right: tensor(right) }))
    }
}
