//! Configuration of the stereo network.

use dgstereo_costvolume::CorrelationConfig;
pub use dgstereo_encoder::EncoderConfig;
use dgstereo_fusion::FusionConfig;
use dgstereo_updater::{GuidanceKind, UpdaterConfig};
use serde::{Deserialize, Serialize};

/// The whole network: RAFT-Stereo's options plus the paper's fusion and guidance.
///
/// Every field has RAFT-Stereo's default, so an empty TOML table is the reference model.
#[derive(Debug, Clone, PartialEq, Serialize, Deserialize, Default)]
#[serde(deny_unknown_fields)]
pub struct ModelConfig {
    /// Encoders.
    #[serde(default)]
    pub encoder: EncoderConfig,
    /// Correlation volume.
    #[serde(default)]
    pub correlation: CorrelationConfig,
    /// Update operator (GRU levels, hidden widths, guidance).
    #[serde(default)]
    pub updater: UpdaterConfig,
    /// Image/depth fusion before the encoders.
    #[serde(default)]
    pub fusion: FusionConfig,
}

impl ModelConfig {
    /// Checks the combination of options; the message names the key.
    pub fn validate(&self) -> dgstereo_core::Result<()> {
        let err = |m: String| Err(dgstereo_core::Error::Config(m));
        let u = &self.updater;
        if !(1..=3).contains(&u.n_gru_layers) {
            return err(format!("updater.n_gru_layers = {} (must be 1, 2 or 3)", u.n_gru_layers));
        }
        if !(2..=3).contains(&u.n_downsample) {
            return err(format!("updater.n_downsample = {} (must be 2 or 3)", u.n_downsample));
        }
        if u.hidden_dims.contains(&0) {
            return err("updater.hidden_dims must be positive".into());
        }
        if self.correlation.levels == 0 {
            return err("correlation.levels must be at least 1".into());
        }
        self.encoder.validate()?;
        // `init` would panic on an invalid fusion (fewer than 3 feature channels).
        self.fusion.validate()?;
        Ok(())
    }

    /// Whether the network consumes a depth prior (fusion or guidance).
    pub fn needs_prior(&self) -> bool {
        self.fusion != FusionConfig::None || self.updater.guidance != GuidanceKind::None
    }

    /// The upsampling factor `2^n_downsample`.
    pub fn factor(&self) -> usize {
        1 << self.updater.n_downsample
    }

    /// Inputs are padded to a multiple of this: 32 as the reference's evaluation padder, more
    /// when the coarsest GRU level (`2^(n_downsample + 3)`) needs it.
    pub fn pad_divisor(&self) -> usize {
        32usize.max(1 << (self.updater.n_downsample + 3))
    }
}
