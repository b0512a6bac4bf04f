//! Any valid combination of the swappable stages builds, runs and trains.
//!
//! For random combinations of fusion (none / conv / deformable into both encoders or the context
//! encoder only), guidance (none / gradient / depth), GRU levels, n_downsample, context norm,
//! correlation implementation, levels and radius, hidden and feature widths, shared backbone,
//! slow-fast GRU and loss, at small random sizes: the configuration validates, the model builds,
//! every iteration's disparity is finite and of the input's size, and one training step under
//! autodiff gives a finite gradient to every parameter that takes part. Every combination
//! round-trips through our safetensors format (saved, loaded into a fresh model of the same
//! config: identical parameters), and one without fusion or guidance (an official architecture)
//! through detection: its official state dict reads back as its configuration (a second
//! property checks more such architectures, without the forward pass).

use burn::module::{Module, ModuleVisitor, Param};
use burn::tensor::{Device, Gradients, Tensor};
use dgstereo_core::tensor::to_vec;
use dgstereo_core::{DepthPrior, default_device};
use dgstereo_costvolume::CorrelationImplementation;
use dgstereo_experiment::smoke::synthetic_pair;
use dgstereo_experiment::{ExperimentConfig, smoke_test};
use dgstereo_fusion::{FusionConfig, FusionTarget};
use dgstereo_loss::{DisparityLoss, LossConfig, LossTarget};
use dgstereo_model::checkpoint_config::config_from_keys;
use dgstereo_model::encoder::{EncoderLayout, NormKind};
use dgstereo_model::official_keys::model_official_keys;
use dgstereo_model::{ModelConfig, RaftStereo, StereoModel, checkpoint};
use dgstereo_prior::{PriorConfig, SimulatedPriorConfig};
use dgstereo_updater::GuidanceKind;
use proptest::prelude::*;

#[derive(Debug, Clone)]
struct Combination {
    fusion: FusionConfig,
    guidance: GuidanceKind,
    n_gru_layers: usize,
    implementation: CorrelationImplementation,
    layout: EncoderLayout,
    slow_fast_gru: bool,
    n_downsample: usize,
    context_norm: NormKind,
    correlation: (usize, usize),
    loss: LossConfig,
    hidden: usize,
    feature_dim: usize,
    size: [usize; 2],
}

fn combination() -> impl Strategy<Value = Combination> {
    let target = prop_oneof![Just(FusionTarget::Both), Just(FusionTarget::ContextOnly)];
    // The kinds come from the stage crates' lists, so a new kind is swapped in here unasked.
    let fusion = (prop::sample::select(FusionConfig::variants()), target, 3usize..9)
        .prop_map(|(kind, target, features)| kind.with_parameters(target, features));
    let guidance = prop::sample::select(GuidanceKind::ALL.to_vec());
    let implementation = prop_oneof![Just(CorrelationImplementation::Reg), Just(CorrelationImplementation::Alt)];
    let loss = prop_oneof![
        (0.8f64..0.95).prop_map(|gamma| LossConfig::SequenceL1 {
            gamma,
            max_disparity: 700.0,
            gamma_adjustment: Default::default(),
            initial_disparity: Default::default(),
        }),
        (0.1f64..3.0).prop_map(|tau| LossConfig::EdgeAware { tau, gamma: 0.9, max_disparity: 700.0 }),
    ];
    let norm =
        prop_oneof![Just(NormKind::Batch), Just(NormKind::Group), Just(NormKind::Instance), Just(NormKind::None)];
    // (levels, radius) as detection splits their product: radius 4, or 4 levels, or a few others.
    let correlation =
        prop_oneof![(1usize..=4).prop_map(|l| (l, 4)), (1usize..=3).prop_map(|r| (4, r)), Just((2, 3)), Just((1, 2))];
    // RAFT-Stereo's two layouts (the MobileNetV2 pyramid has its own widths and stride).
    let layouts = prop::sample::select(vec![EncoderLayout::Separate, EncoderLayout::SharedBackbone]);
    let model = (fusion, guidance, 1usize..=3, implementation, layouts, any::<bool>());
    let architecture = (2usize..=3, norm, correlation);
    let sizes =
        (loss, prop_oneof![Just(8usize), Just(16)], prop_oneof![Just(16usize), Just(32)], 20usize..=32, 36usize..=64);
    (model, architecture, sizes).prop_map(
        |(
            (fusion, guidance, n_gru_layers, implementation, layout, slow_fast_gru),
            (n_downsample, context_norm, correlation),
            (loss, hidden, feature_dim, h, w),
        )| {
            Combination {
                fusion,
                guidance,
                n_gru_layers,
                implementation,
                layout,
                slow_fast_gru,
                n_downsample,
                context_norm,
                correlation,
                loss,
                hidden,
                feature_dim,
                size: [h, w],
            }
        },
    )
}

fn experiment(c: &Combination) -> ExperimentConfig {
    let mut model = ModelConfig { fusion: c.fusion.clone(), ..Default::default() };
    model.updater.guidance = c.guidance;
    model.updater.n_gru_layers = c.n_gru_layers;
    model.updater.hidden_dims = [c.hidden; 3];
    model.updater.slow_fast_gru = c.slow_fast_gru;
    model.correlation.implementation = c.implementation;
    model.encoder.layout = c.layout;
    model.encoder.feature_dim = c.feature_dim;
    model.encoder.context_norm = c.context_norm;
    model.updater.n_downsample = c.n_downsample;
    (model.correlation.levels, model.correlation.radius) = c.correlation;
    let prior = if model.needs_prior() {
        PriorConfig::Simulated(SimulatedPriorConfig::default())
    } else {
        PriorConfig::None {}
    };
    ExperimentConfig {
        name: "swap".into(),
        description: None,
        model,
        prior,
        loss: c.loss.clone(),
        train: Default::default(),
        data: Default::default(),
        benchmarks: Vec::new(),
        launcher: Default::default(),
    }
}

/// Module paths that do not take part in a forward pass with `n_gru_layers` levels: the coarser
/// GRUs and context heads are built (checkpoints hold them) but unused, and frozen BatchNorm
/// statistics never get gradients.
fn takes_part(path: &[String], n_gru_layers: usize) -> bool {
    let has = |name: &str| path.iter().any(|p| p == name);
    let unused_levels: &[&str] = match n_gru_layers {
        1 => &["gru16", "gru32", "layer4", "layer5", "outputs16", "outputs32"],
        2 => &["gru32", "layer5", "outputs32"],
        _ => &[],
    };
    !(has("running_mean") || has("running_var") || unused_levels.iter().any(|name| has(name)))
}

/// Checks every float parameter's gradient; returns how many took part.
struct GradientCheck<'a> {
    grads: &'a Gradients,
    n_gru_layers: usize,
    path: Vec<String>,
    checked: usize,
    problems: Vec<String>,
}

impl ModuleVisitor for GradientCheck<'_> {
    fn enter_module(&mut self, name: &str, _container_type: &str) {
        self.path.push(name.to_string());
    }
    fn exit_module(&mut self, _name: &str, _container_type: &str) {
        self.path.pop();
    }
    fn visit_float<const D: usize>(&mut self, param: &Param<Tensor<D>>) {
        let name = self.path.join(".");
        let grad = param.val().grad(self.grads);
        match grad {
            Some(grad) => {
                if to_vec(grad).iter().any(|g| !g.is_finite()) {
                    self.problems.push(format!("{name}: non-finite gradient"));
                }
                self.checked += 1;
            }
            None if takes_part(&self.path, self.n_gru_layers) => self.problems.push(format!("{name}: no gradient")),
            None => {}
        }
    }
}

/// A ground truth of constant disparity with a step, the nearest-resized copy differing at the
/// step (as after a resize), every pixel valid.
fn target(size: [usize; 2], device: &Device) -> LossTarget {
    let [h, w] = size;
    let bilinear: Vec<f32> = (0..h * w).map(|i| if i % w < w / 2 { 2.0 } else { 3.5 }).collect();
    let nearest: Vec<f32> = (0..h * w).map(|i| if i % w < w / 2 + 1 { 2.0 } else { 3.5 }).collect();
    LossTarget {
        disparity_bilinear: dgstereo_core::tensor::from_vec(bilinear, [1, 1, h, w], device),
        disparity_nearest: dgstereo_core::tensor::from_vec(nearest, [1, 1, h, w], device),
        valid: Tensor::ones([1, 1, h, w], device),
    }
}

/// Every parameter of `a` equals `b`'s of the same name; the problems otherwise.
fn parameter_differences(a: &RaftStereo, b: &RaftStereo) -> Vec<String> {
    use burn::store::ModuleSnapshot;
    let values = |m: &RaftStereo| -> Vec<(String, Vec<f32>)> {
        m.collect(None, None, false)
            .iter()
            .map(|t| {
                let data = burn::store::bridge::to_data(t).expect("parameter data");
                (t.name.clone(), data.convert::<f32>().try_to_vec::<f32>().expect("float parameter"))
            })
            .collect()
    };
    let (va, vb) = (values(a), values(b));
    if va.len() != vb.len() {
        return vec![format!("{} parameters saved, {} loaded", va.len(), vb.len())];
    }
    va.iter().zip(&vb).filter(|(x, y)| x != y).map(|(x, y)| format!("{} vs {}", x.0, y.0)).collect()
}

/// Saves `config`'s fresh model as safetensors, loads it into another fresh model of `config`,
/// and compares their parameters; without fusion or guidance, detects the configuration from the
/// model's official state dict.
fn round_trips(config: &ModelConfig, case: usize) -> Result<(), String> {
    let device = default_device();
    let saved = config.init(&device).map_err(|e| e.to_string())?;
    let dir = tempfile::tempdir().map_err(|e| e.to_string())?;
    let path = dir.path().join(format!("swap-{case}.safetensors"));
    let json = serde_json::to_string(config).map_err(|e| e.to_string())?;
    checkpoint::save_safetensors(&saved, &path, &[("model_config", &json)]).map_err(|e| e.to_string())?;
    let loaded = checkpoint::load_safetensors(config.init(&device).map_err(|e| e.to_string())?, &path)
        .map_err(|e| e.to_string())?;
    let differences = parameter_differences(&saved, &loaded);
    if !differences.is_empty() {
        return Err(format!("save/load changed parameters: {differences:?}"));
    }
    if config.needs_prior() {
        return Ok(());
    }
    let detected = config_from_keys(&model_official_keys(&saved), &device).map_err(|p| p.to_string())?;
    let mut expected = config.clone();
    // What the tensors cannot show: the implementation, the schedule (from the preset), and a
    // parameterless norm (instance, as the official checkpoints).
    expected.correlation.implementation = detected.model.correlation.implementation;
    expected.updater.slow_fast_gru = detected.model.updater.slow_fast_gru;
    if expected.encoder.context_norm == NormKind::None {
        expected.encoder.context_norm = NormKind::Instance;
    }
    if detected.model != expected {
        return Err(format!("detected {detected} for {expected:?}"));
    }
    Ok(())
}

proptest! {
    #![proptest_config(ProptestConfig::with_cases(6))]

    #[test]
    fn any_valid_combination_builds_runs_and_trains(c in combination()) {
        let config = experiment(&c);
        prop_assert!(config.validate().is_ok(), "{:?}", config.validate());
        let trip = round_trips(&config.model, c.size[0] * 100 + c.size[1]);
        prop_assert!(trip.is_ok(), "{:?}: {:?}", c, trip);

        // Forward: every iteration's disparity is finite and of the input's size.
        let device = default_device();
        let report = smoke_test(&config, c.size, 2, &device);
        prop_assert!(report.is_ok(), "{:?}: {:?}", c, report);
        prop_assert_eq!(report.unwrap().iterations, 2);

        // One training step under autodiff.
        let ad = device.clone().autodiff();
        let network = config.model.init(&device).unwrap().fork(&ad).train();
        let model = StereoModel::new(network, config.model.clone(), ad.clone());
        let (left, right, prior) = synthetic_pair(c.size, 3, &ad);
        let prior: Option<DepthPrior> = config.model.needs_prior().then_some(prior);
        let prediction = model.predict(left, right, prior.as_ref(), 2, true, None).unwrap();
        prop_assert_eq!(prediction.disparities.len(), 2);
        for disparity in &prediction.disparities {
            prop_assert_eq!(disparity.dims(), [1, 1, c.size[0], c.size[1]]);
        }
        let loss = config.loss.loss(&prediction.disparities, &target(c.size, &ad)).unwrap();
        let value = to_vec(loss.clone())[0];
        prop_assert!(value.is_finite() && value > 0.0, "loss {}", value);
        let grads = loss.backward();
        let mut check = GradientCheck { grads: &grads, n_gru_layers: c.n_gru_layers, path: Vec::new(), checked: 0, problems: Vec::new() };
        model.network.visit(&mut check);
        prop_assert!(check.problems.is_empty(), "{:?}: {:?}", c, check.problems);
        prop_assert!(check.checked > 20, "only {} parameters took part", check.checked);
    }
}

proptest! {
    #![proptest_config(ProptestConfig::with_cases(16))]

    /// The architectures an official checkpoint can have (no fusion, no guidance), more of them
    /// than the full test above trains: each round-trips through save and load and detection.
    #[test]
    fn every_official_architecture_round_trips(
        c in combination(),
        hidden in prop_oneof![Just(8usize), Just(16), Just(24)],
    ) {
        let mut config = experiment(&c).model;
        config.fusion = FusionConfig::None {};
        config.updater.guidance = GuidanceKind::None;
        config.updater.hidden_dims = [hidden; 3];
        prop_assert!(config.validate().is_ok(), "{:?}", config.validate());
        let trip = round_trips(&config, c.size[0] * 100 + c.size[1]);
        prop_assert!(trip.is_ok(), "{:?}: {:?}", config, trip);
    }
}

/// Every fusion and guidance kind the stage crates list is checked against the prior: without
/// a provider a kind that consumes the prior is refused naming its key, with one a kind that
/// consumes nothing is refused naming `prior.kind`, and the other combinations validate.
#[test]
fn every_kind_is_checked_against_the_prior() {
    for fusion in FusionConfig::variants() {
        for guidance in GuidanceKind::ALL {
            let mut model = ModelConfig { fusion: fusion.clone(), ..Default::default() };
            model.updater.guidance = guidance;
            let label = format!("{} fusion, {} guidance", fusion.kind(), guidance.name());
            for prior in [PriorConfig::None {}, PriorConfig::Simulated(SimulatedPriorConfig::default())] {
                let config = ExperimentConfig {
                    name: "kinds".into(),
                    description: None,
                    model: model.clone(),
                    prior,
                    loss: LossConfig::default(),
                    train: Default::default(),
                    data: Default::default(),
                    benchmarks: Vec::new(),
                    launcher: Default::default(),
                };
                let keys: Vec<String> = config.problems().into_iter().map(|p| p.key).collect();
                let expected: &[&str] = match (model.needs_prior(), config.prior.gives_prior()) {
                    (true, false) if fusion.needs_prior() => &["model.fusion.kind"],
                    (true, false) => &["model.updater.guidance"],
                    (false, true) => &["prior.kind"],
                    _ => &[],
                };
                assert_eq!(keys, expected, "{label}, prior {}", config.prior.kind());
            }
        }
    }
}
