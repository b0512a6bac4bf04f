//! Which cost volume a pair gets: the materialised pyramid ("reg", fast) unless its estimated
//! size at the padded feature resolution exceeds a memory budget, then the on-the-fly volume
//! ("alt", memory linear in the width).
//!
//! Design decision: the estimate pads the input exactly as the network does
//! ([`ModelConfig::pad_divisor`]: 32, or 64 for models at 1/8 resolution), so the size compared
//! with the budget is the size the network will allocate. IGEV-Stereo's geometry encoding volume
//! has no on-the-fly form: an input whose volume would exceed the budget is refused before the
//! pass ([`check_geometry_budget`]), with the `max_size` that fits, instead of running out of
//! memory inside it.

use dgstereo_core::{Error, Result};
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

/// Estimated bytes of the geometry encoding volume of a `width x height` input (padded as the
/// network pads it), `None` for models without one.
fn geometry_bytes(config: &ModelConfig, width: usize, height: usize) -> Option<u64> {
    let geometry = config.correlation.geometry.as_ref()?;
    let divisor = config.pad_divisor();
    let pad = |v: usize| v.div_ceil(divisor) * divisor;
    let f = config.factor();
    Some(geometry.volume_bytes(1, pad(height) / f, pad(width) / f) as u64)
}

/// Refuses a `width x height` network input of a model with a geometry encoding volume
/// (IGEV-Stereo) whose volume would take more than `budget` bytes
/// ([`dgstereo_costvolume::GeometryVolume::volume_bytes`]), naming the estimate, the budget and
/// the largest `max_size` (longer side, aspect kept) that fits; any other input or model passes.
///
/// # Errors
/// [`Error::Config`] keyed `memory_budget`.
pub fn check_geometry_budget(config: &ModelConfig, budget: u64, width: usize, height: usize) -> Result<()> {
    let Some(bytes) = geometry_bytes(config, width, height) else { return Ok(()) };
    if bytes <= budget {
        return Ok(());
    }
    let longer = width.max(height);
    let fits = (32..longer).rev().step_by(16).find(|&side| {
        let scale = side as f64 / longer as f64;
        let scaled = |v: usize| ((v as f64 * scale).round() as usize).max(1);
        geometry_bytes(config, scaled(width), scaled(height)).is_some_and(|b| b <= budget)
    });
    let gib = |b: u64| b as f64 / (1u64 << 30) as f64;
    let advice = match fits {
        Some(side) => format!("set `max_size` to {side} (or less) or raise `memory_budget`"),
        None => "raise `memory_budget`".to_string(),
    };
    Err(Error::config(
        "memory_budget",
        format!(
            "a {width}x{height} input needs about {:.2} GiB for IGEV-Stereo's geometry encoding volume, over the \
             budget of {:.2} GiB (the volume has no on-the-fly form): {advice}",
            gib(bytes),
            gib(budget)
        ),
    ))
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

    /// A geometry volume over the budget is refused with the estimate and a `max_size` whose
    /// input fits; models without one pass whatever the budget.
    #[test]
    fn inputs_over_the_budget_of_the_geometry_volume_are_refused_with_the_size_that_fits() {
        let mut config = ModelConfig::default();
        assert!(check_geometry_budget(&config, 0, 4096, 2160).is_ok(), "no geometry volume");
        config.updater.n_downsample = 2;
        config.correlation.geometry = Some(dgstereo_costvolume::GeometryVolume::default());
        let bytes = geometry_bytes(&config, 448, 384).expect("an estimate");
        assert_eq!(bytes, 4 * 96 * 112 * (48 * (3 * 8 + 22) + 112 + 56));
        assert!(check_geometry_budget(&config, bytes, 448, 384).is_ok());
        let refused = check_geometry_budget(&config, bytes, 900, 750).expect_err("over the budget");
        let text = refused.to_string();
        assert!(text.contains("memory_budget") && text.contains("900x750"), "{text}");
        let side: usize =
            text.split("max_size` to ").nth(1).and_then(|t| t.split(' ').next()).unwrap().parse().unwrap();
        let scale = side as f64 / 900.0;
        let (w, h) = ((900.0 * scale).round() as usize, (750.0 * scale).round() as usize);
        assert!(check_geometry_budget(&config, bytes, w, h).is_ok(), "the advised max_size {side} fits");
        // 435x363 pads to the budget's 448x384; 451 would pad to 480.
        assert!((400..900).contains(&side), "{side}");
    }

    #[test]
    fn names_are_those_of_experiment_files() {
        assert_eq!(corr_name(CorrelationImplementation::Reg), "reg");
        assert_eq!(corr_name(CorrelationImplementation::Alt), "alt");
    }
}
