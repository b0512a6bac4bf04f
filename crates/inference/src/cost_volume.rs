//! Which cost volume a pair gets: the materialised pyramid ("reg", fast) unless its estimated
//! size at the padded feature resolution exceeds a memory budget, then the on-the-fly volume
//! ("alt", memory linear in the width).
//!
//! Design decision: the estimate pads the input exactly as the network does
//! ([`ModelConfig::pad_divisor`]: 32, or 64 for models at 1/8 resolution), so the size compared
//! with the budget is the size the network will allocate.

use dgstereo_costvolume::CorrelationImplementation;
use dgstereo_model::ModelConfig;

/// The memory the materialised volume may take by default (4 GiB).
pub const DEFAULT_MEMORY_BUDGET: u64 = 4 << 30;

/// Which cost volume to build.
#[derive(Clone, Copy, Debug, PartialEq, Eq)]
#[cfg_attr(feature = "clap", derive(clap::ValueEnum))]
pub enum CorrChoice {
    /// "reg" unless it would exceed the memory budget, then "alt".
    Auto,
    /// Always the materialised pyramid.
    Reg,
    /// Always on-the-fly correlation.
    Alt,
}

/// The cost volume `choice` gives for a `width x height` input of a model of `config`: with
/// [`CorrChoice::Auto`], "alt" when the materialised pyramid of the padded input's features
/// would take more than `budget` bytes.
pub fn corr_for(
    config: &ModelConfig,
    choice: CorrChoice,
    budget: u64,
    width: usize,
    height: usize,
) -> CorrelationImplementation {
    match choice {
        CorrChoice::Reg => CorrelationImplementation::Reg,
        CorrChoice::Alt => CorrelationImplementation::Alt,
        CorrChoice::Auto => {
            let divisor = config.pad_divisor();
            let pad = |v: usize| v.div_ceil(divisor) * divisor;
            let f = config.factor();
            let bytes = config.correlation.pyramid_bytes(1, pad(height) / f, pad(width) / f);
            if bytes as u64 > budget { CorrelationImplementation::Alt } else { CorrelationImplementation::Reg }
        }
    }
}

/// The short name of a cost volume, as experiment files write it (`reg`, `alt`).
pub fn corr_name(implementation: CorrelationImplementation) -> &'static str {
    match implementation {
        CorrelationImplementation::Reg => "reg",
        CorrelationImplementation::Alt => "alt",
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn large_inputs_switch_to_the_on_the_fly_volume() {
        let mut config = ModelConfig::default();
        config.updater.n_downsample = 2;
        // 1024 x 768 at 1/4: 256 x 192 features; rows of 256 + 128 + 64 + 32 + 16 floats each.
        let bytes = 4 * 192 * 256 * (256 + 128 + 64 + 32 + 16);
        assert_eq!(config.correlation.pyramid_bytes(1, 192, 256), bytes);
        let pick = |budget| corr_for(&config, CorrChoice::Auto, budget, 1000, 750);
        assert_eq!(pick(bytes as u64), CorrelationImplementation::Reg);
        assert_eq!(pick(bytes as u64 - 1), CorrelationImplementation::Alt);
        assert_eq!(corr_for(&config, CorrChoice::Reg, 0, 1000, 750), CorrelationImplementation::Reg);
        assert_eq!(corr_for(&config, CorrChoice::Alt, u64::MAX, 8, 8), CorrelationImplementation::Alt);
    }

    #[test]
    fn eighth_resolution_models_are_estimated_at_their_padding_of_64() {
        let mut config = ModelConfig::default();
        config.updater.n_downsample = 3;
        assert_eq!(config.pad_divisor(), 64);
        // 1024 x 720 pads to 1024 x 768 (not 736, a multiple of 32 only): 128 x 96 features.
        let bytes = config.correlation.pyramid_bytes(1, 96, 128) as u64;
        let pick = |budget| corr_for(&config, CorrChoice::Auto, budget, 1024, 720);
        assert_eq!(pick(bytes), CorrelationImplementation::Reg);
        assert_eq!(pick(bytes - 1), CorrelationImplementation::Alt);
    }

    #[test]
    fn names_are_those_of_experiment_files() {
        assert_eq!(corr_name(CorrelationImplementation::Reg), "reg");
        assert_eq!(corr_name(CorrelationImplementation::Alt), "alt");
    }
}
