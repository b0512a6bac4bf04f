//! Every cost volume through one body generic over the stage trait [`CostVolume`]: the shape
//! the trait promises, finite values, and the same samples for the same positions.

use burn::tensor::{Distribution, Tensor};
use dgstereo_core::default_device;
use dgstereo_core::tensor::{from_vec, to_vec};
use dgstereo_costvolume::{
    CombinedGeometryVolume, Correlation, CorrelationConfig, CorrelationImplementation, CorrelationPyramid, CostVolume,
    OnTheFlyCorrelation,
};

const N: usize = 1;
const C: usize = 8;
const H: usize = 3;
const W: usize = 20;
const LEVELS: usize = 2;
const RADIUS: usize = 3;

fn features() -> Tensor<4> {
    Tensor::random([N, C, H, W], Distribution::Uniform(-1.0, 1.0), &default_device())
}

/// Match positions in the row, between columns and past both ends.
fn positions() -> Tensor<4> {
    let x: Vec<f32> = (0..H * W).map(|i| (i % W) as f32 * 1.3 - 4.0 + (i / W) as f32 * 0.25).collect();
    from_vec(x, [N, 1, H, W], &default_device())
}

/// What every volume promises: `[N, channels, H, W]` samples, finite, equal for equal positions.
fn conforms<V: CostVolume>(volume: &V, channels: usize, name: &str) {
    let sampled = volume.lookup(positions());
    assert_eq!(sampled.dims(), [N, channels, H, W], "{name}");
    let values = to_vec(sampled);
    assert!(values.iter().all(|v| v.is_finite()), "{name}: a sample is not finite");
    assert!(values.iter().any(|v| *v != 0.0), "{name}: every sample is zero");
    let again = to_vec(volume.lookup(positions()));
    assert!(values.iter().zip(&again).all(|(a, b)| a.to_bits() == b.to_bits()), "{name}: differs between calls");
}

#[test]
fn every_volume_keeps_the_stage_contract() {
    let (left, right) = (features(), features());
    let config = CorrelationConfig { levels: LEVELS, radius: RADIUS, ..Default::default() };
    let channels = config.channels();
    conforms(&CorrelationPyramid::new(left.clone(), right.clone(), LEVELS, RADIUS), channels, "pyramid");
    conforms(&OnTheFlyCorrelation::new(left.clone(), right.clone(), LEVELS, RADIUS), channels, "on the fly");
    for implementation in [CorrelationImplementation::Reg, CorrelationImplementation::Alt] {
        let built = config.build_with(implementation, left.clone(), right.clone());
        conforms(&built, channels, &format!("{implementation:?}"));
    }
    // IGEV-Stereo's: 4 groups over 16 disparities, with either correlation.
    let volume = Tensor::<5>::random([N, 4, 16, H, W], Distribution::Uniform(-1.0, 1.0), &default_device());
    for implementation in [CorrelationImplementation::Reg, CorrelationImplementation::Alt] {
        let geometry =
            CombinedGeometryVolume::new(left.clone(), right.clone(), volume.clone(), LEVELS, RADIUS, implementation);
        let channels = geometry.channels();
        conforms(&geometry, channels, &format!("geometry, {implementation:?}"));
        conforms(&Correlation::Geometry(geometry), channels, &format!("Correlation::Geometry, {implementation:?}"));
    }
}
