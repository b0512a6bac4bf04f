//! Every provider through one body generic over the stage trait [`PriorProvider`]: no prior, or
//! one `[N, 1, H, W]` map per view, finite and non-negative (relative inverse depth).

use burn::tensor::{Distribution, Tensor};
use dgstereo_core::default_device;
use dgstereo_core::tensor::to_vec;
use dgstereo_prior::{
    CachedPrior, Prior, PriorConfig, PriorInput, PriorProvider, SimulatedPrior, SimulatedPriorConfig,
};

const N: usize = 2;
const H: usize = 16;
const W: usize = 24;

fn input() -> PriorInput {
    let device = default_device();
    let image = || Tensor::<4>::random([N, 3, H, W], Distribution::Uniform(0.0, 255.0), &device);
    let gt = Tensor::<4>::random([N, 1, H, W], Distribution::Uniform(1.0, 30.0), &device);
    PriorInput { left: image(), right: image(), gt_disparity: Some(gt), names: vec!["a".into(), "b".into()] }
}

/// What every provider promises: `None` where it gives no prior, else both views' maps.
fn conforms<P: PriorProvider>(provider: &P, gives_a_prior: bool, name: &str) {
    let prior = provider.provide(&input()).unwrap_or_else(|e| panic!("{name}: {e}"));
    assert_eq!(prior.is_some(), gives_a_prior, "{name}");
    if let Some(prior) = prior {
        for (side, map) in [("left", prior.left), ("right", prior.right)] {
            assert_eq!(map.dims(), [N, 1, H, W], "{name}, {side}");
            let values = to_vec(map);
            assert!(
                values.iter().all(|v| v.is_finite() && *v >= 0.0),
                "{name}, {side}: a value is negative or not finite"
            );
        }
    }
}

#[test]
fn every_provider_keeps_the_stage_contract() {
    let device = default_device();
    for config in [PriorConfig::default(), PriorConfig::Simulated(SimulatedPriorConfig::default())] {
        let gives = !matches!(config, PriorConfig::None { .. });
        conforms(&config.init(&device).unwrap(), gives, config.kind());
    }
    conforms(&Prior::None, false, "Prior::None");
    let simulated = SimulatedPrior::new(SimulatedPriorConfig::default()).unwrap();
    conforms(&simulated, true, "simulated");
    let dir = std::env::temp_dir().join(format!("dgstereo-prior-contract-{}", std::process::id()));
    let cached = CachedPrior::new(simulated.clone(), "simulated", &dir, true).unwrap();
    conforms(&cached, true, "cache, computed");
    conforms(&cached, true, "cache, read back");
    std::fs::remove_dir_all(&dir).unwrap();
    let boxed: Box<dyn PriorProvider> = Box::new(simulated);
    conforms(&boxed, true, "boxed");
}
