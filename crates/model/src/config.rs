//! Configuration of the stereo network.

use dgstereo_core::{Error, Problem, Result};
use dgstereo_costvolume::CorrelationConfig;
pub use dgstereo_encoder::EncoderConfig;
use dgstereo_encoder::{DepthFeatureInput, EncoderLayout};
use dgstereo_fusion::FusionConfig;
use dgstereo_prior::MonocularConfig;
use dgstereo_updater::{GuidanceKind, UpdaterConfig, UpsamplingKind};
use serde::{Deserialize, Serialize};

use crate::initial_disparity::InitialDisparity;

/// The whole network: RAFT-Stereo's options plus the paper's fusion and guidance, and the
/// variants that make it DEFOM-Stereo (an embedded monocular network, encoders that add its
/// features, the disparity initialiser, the scale lookup and update).
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
    /// A monocular depth network inside the stereo network (DEFOM-Stereo's Depth Anything V2).
    #[serde(default)]
    pub monocular: MonocularConfig,
    /// The disparity the update loop starts from.
    #[serde(default)]
    pub initial_disparity: InitialDisparity,
}

impl ModelConfig {
    /// Everything wrong with the options, keys relative to the model table
    /// (`updater.n_gru_layers`, `fusion.features`): each stage's own
    /// [`problems`](UpdaterConfig::problems), gathered under its table, and the ones between
    /// stages ([`Self::stage_problems`]).
    pub fn problems(&self) -> Vec<Problem> {
        let stages = [
            ("updater", self.updater.problems()),
            ("correlation", self.correlation.problems()),
            ("encoder", self.encoder.problems()),
            ("fusion", self.fusion.problems()),
            ("monocular", self.monocular.problems()),
            ("initial_disparity", self.initial_disparity.problems()),
        ];
        let mut problems: Vec<Problem> = stages
            .into_iter()
            .flat_map(|(table, problems)| problems.into_iter().map(move |p| p.within(table)))
            .collect();
        problems.extend(self.stage_problems());
        problems
    }

    /// The problems between stages: a stage that reads what no other stage makes (the
    /// encoders' or the initialiser's monocular features without a monocular network, the scale
    /// update without the scale lookup), and a monocular network that nothing reads.
    pub fn stage_problems(&self) -> Vec<Problem> {
        let mut problems = Vec::new();
        let monocular = self.monocular != MonocularConfig::None {};
        if self.encoder.depth_features == DepthFeatureInput::Added && !monocular {
            problems.push(Problem::new(
                "encoder.depth_features",
                "\"added\" needs a monocular network's features: set model.monocular (kind = \"depth-anything-v2\")",
            ));
        }
        if self.initial_disparity.needs_monocular() && !monocular {
            problems.push(Problem::new(
                "initial_disparity.kind",
                format!(
                    "\"{}\" scales a monocular network's inverse depth: set model.monocular (kind = \"depth-anything-v2\")",
                    self.initial_disparity.kind()
                ),
            ));
        }
        if monocular
            && self.encoder.depth_features == DepthFeatureInput::None
            && !self.initial_disparity.needs_monocular()
        {
            problems.push(Problem::new(
                "monocular.kind",
                "nothing reads the monocular network: set encoder.depth_features = \"added\" or an initial_disparity \
                 that uses it",
            ));
        }
        if self.initial_disparity.needs_geometry() && self.correlation.geometry.is_none() {
            problems.push(Problem::new(
                "initial_disparity.kind",
                "\"soft-argmin\" reads the geometry encoding volume: set model.correlation.geometry",
            ));
        }
        let pyramid = self.encoder.layout == EncoderLayout::MobilenetPyramid;
        if self.correlation.geometry.is_some() && !pyramid {
            problems.push(Problem::new(
                "correlation.geometry",
                "the geometry volume reads the feature pyramid: set model.encoder.layout = \"mobilenet-pyramid\"",
            ));
        }
        if self.updater.upsampling == UpsamplingKind::Superpixel && !pyramid {
            problems.push(Problem::new(
                "updater.upsampling",
                "\"superpixel\" reads the feature pyramid's image stem: set model.encoder.layout = \
                 \"mobilenet-pyramid\"",
            ));
        }
        if self.updater.scale_update.is_some() && self.correlation.scale_lookup.is_none() {
            problems.push(Problem::new(
                "updater.scale_update",
                "the scale update reads the correlation's scale lookup: set model.correlation.scale_lookup",
            ));
        }
        problems
    }

    /// Checks the combination of options.
    ///
    /// # Errors
    /// [`Error::Config`] with the first of [`problems`](Self::problems).
    pub fn validate(&self) -> Result<()> {
        Problem::first(self.problems())
    }

    /// Whether the network consumes a depth prior (fusion or guidance).
    pub fn needs_prior(&self) -> bool {
        self.fusion.needs_prior() || self.updater.guidance != GuidanceKind::None
    }

    /// The one check that a network that consumes a depth prior gets one: `has_prior` says
    /// whether a prior will be there (a provider is configured, or the caller passes maps).
    ///
    /// # Errors
    /// [`Error::Config`] naming the consuming key relative to the model table (`fusion.kind`,
    /// else `updater.guidance`) when the network needs a prior and `has_prior` is false.
    pub fn check_prior(&self, has_prior: bool) -> Result<()> {
        if has_prior {
            return Ok(());
        }
        let missing = |key: &str, what: String| {
            Err(Error::config(
                key,
                format!(
                    "{what} needs a depth prior, but there is none: configure a prior provider (prior.kind) or \
                     give a prior with each pair"
                ),
            ))
        };
        if self.fusion.needs_prior() {
            return missing("fusion.kind", format!("{} fusion", self.fusion.kind()));
        }
        if self.updater.guidance != GuidanceKind::None {
            return missing("updater.guidance", format!("{} guidance", self.updater.guidance.name()));
        }
        Ok(())
    }

    /// Whether the feature network is IGEV-Stereo's MobileNetV2 pyramid, whose trunk takes
    /// timm's ImageNet weights (`train.feature_init`).
    pub fn has_mobilenet_features(&self) -> bool {
        self.encoder.layout == EncoderLayout::MobilenetPyramid
    }

    /// Whether a training pass returns the initial disparity at full resolution, for a loss to
    /// supervise ([`crate::TrainingDisparities::initial`]): IGEV-Stereo's soft-argmin start,
    /// which its superpixel heads upsample.
    pub fn outputs_initial_disparity(&self) -> bool {
        self.initial_disparity.needs_geometry() && self.updater.upsampling == UpsamplingKind::Superpixel
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
