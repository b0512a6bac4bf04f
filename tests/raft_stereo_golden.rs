//! Conformance of RAFT-Stereo with the official PyTorch code.
//!
//! The numbers come from `../shared/golden/raft_stereo_random.activations.safetensors`: the
//! official RAFT-Stereo (princeton-vl/RAFT-Stereo, commit 6068c1a), default configuration, run
//! in float32 on CPU with the random-weight checkpoint `raft_stereo_random.pth` on a 64x128 crop
//! of the Cones pair for 4 iterations (see `../shared/golden/README.md`); and from
//! `raft_stereo_realtime_random.activations.safetensors`, the realtime architecture (shared
//! backbone, n_downsample 3, 2 GRU levels, slow-fast GRU) for 7 iterations, which the
//! checkpoint's tensors alone must select.

use std::path::PathBuf;

use dgstereo_core::default_device;
use dgstereo_core::tensor::{from_vec, max_abs_diff};
use dgstereo_costvolume::{CorrelationImplementation, CostVolume};
use dgstereo_model::{ModelConfig, checkpoint, verify};
use dgstereo_suite::shared_dir_for_test;

fn golden(name: &str) -> Option<(PathBuf, PathBuf)> {
    let shared = shared_dir_for_test(name, "golden/raft_stereo_random.pth")?;
    Some((
        shared.join("golden/raft_stereo_random.pth"),
        shared.join("golden/raft_stereo_random.activations.safetensors"),
    ))
}

#[test]
fn every_reference_tensor_matches() {
    let Some((weights, reference)) = golden("every_reference_tensor_matches") else { return };
    let report = verify::verify_raft_stereo(&weights, &reference, &default_device()).expect("verification runs");
    println!("{report}");
    assert!(report.unmatched.is_empty(), "keys not produced: {:?}", report.unmatched);
    assert!(report.lines.len() >= 40, "only {} tensors compared", report.lines.len());
    assert!(report.passed(), "some tensors are off:\n{report}");
    assert!(report.final_flow_error < verify::FLOW_TOLERANCE);
}

#[test]
fn every_realtime_reference_tensor_matches() {
    let weights = "golden/raft_stereo_realtime_random.pth";
    let Some(shared) = shared_dir_for_test("every_realtime_reference_tensor_matches", weights) else { return };
    let reference = shared.join("golden/raft_stereo_realtime_random.activations.safetensors");
    let report =
        verify::verify_raft_stereo(&shared.join(weights), &reference, &default_device()).expect("verification runs");
    println!("{report}");
    assert!(report.configuration.contains("shared backbone"), "{}", report.configuration);
    assert!(report.unmatched.is_empty(), "keys not produced: {:?}", report.unmatched);
    // fmap.{left,right}, context.hidden.{0,1}, 7 iterations' flow_up, final.{flow_lowres,flow_up}.
    assert_eq!(report.lines.len(), 13, "{report}");
    assert!(report.passed(), "some tensors are off:\n{report}");
    assert!(report.final_flow_error < verify::FLOW_TOLERANCE);
}

/// The realtime reference tells the slow-fast schedule from the plain one: without the extra
/// coarse updates, the final flow is off by far more than the tolerance.
#[test]
fn the_realtime_reference_needs_the_slow_fast_schedule() {
    let weights = "golden/raft_stereo_realtime_random.pth";
    let Some(shared) = shared_dir_for_test("the_realtime_reference_needs_the_slow_fast_schedule", weights) else {
        return;
    };
    let device = default_device();
    let refs =
        verify::read_reference(&shared.join("golden/raft_stereo_realtime_random.activations.safetensors")).unwrap();
    let (mut model, config) = dgstereo_model::checkpoint_config::load_detected(&shared.join(weights), &device).unwrap();
    assert!(model.update_block.slow_fast_gru && config.valid_iters == 7);
    model.update_block.slow_fast_gru = false;
    let f = |k: &str| {
        let (s, v) = &refs[k];
        from_vec(v.clone(), [s[0], s[1], s[2], s[3]], &device)
    };
    let out = model.forward_flow(f("input.left"), f("input.right"), None, 7, Default::default()).unwrap();
    let diff = max_abs_diff(out.flow_up.last().unwrap().clone(), f("final.flow_up"));
    assert!(diff > 10.0 * verify::FLOW_TOLERANCE, "plain schedule within {diff} of the slow-fast reference");
}

#[test]
fn on_the_fly_correlation_equals_materialised_pyramid() {
    let Some((weights, reference)) = golden("on_the_fly_correlation_equals_materialised_pyramid") else { return };
    let device = default_device();
    let refs = verify::read_reference(&reference).unwrap();
    let model = checkpoint::load_pytorch(ModelConfig::default().init(&device).unwrap(), &weights).unwrap();
    let f = |k: &str| {
        let (s, v) = &refs[k];
        from_vec(v.clone(), [s[0], s[1], s[2], s[3]], &device)
    };
    let (f1, f2) = (f("fnet.left"), f("fnet.right"));
    let reg = model.correlation.build_with(CorrelationImplementation::Reg, f1.clone(), f2.clone());
    let alt = model.correlation.build_with(CorrelationImplementation::Alt, f1, f2);
    // Correlation values reach ~66 here, where float32 values are 7.6e-6 apart: the bound is
    // 1e-5 relative to the volume's largest magnitude (a few ulps of summation order).
    let scale = refs["corr.pyramid.0"].1.iter().fold(1f32, |m, v| m.max(v.abs()));
    // Positions from the reference run's flows, plus fractional and out-of-row ones.
    let [n, _, h, w] = [1, 1, 16, 32];
    let base: Vec<f32> = (0..n * h * w).map(|i| (i % w) as f32).collect();
    for k in 0..4 {
        let flow = &refs[&format!("iter.{k}.flow_lowres")].1;
        let coords: Vec<f32> = base.iter().zip(flow).map(|(x, d)| x + d).collect();
        let c = from_vec(coords, [n, 1, h, w], &device);
        let diff = max_abs_diff(reg.lookup(c.clone()), alt.lookup(c));
        assert!(diff <= 1e-5 * scale, "iteration {k}: reg vs alt differ by {diff} (scale {scale})");
    }
    let odd: Vec<f32> = (0..n * h * w).map(|i| (i as f32 * 0.37).sin() * 40.0 + (i % w) as f32 - 3.3).collect();
    let c = from_vec(odd, [n, 1, h, w], &device);
    let diff = max_abs_diff(reg.lookup(c.clone()), alt.lookup(c));
    assert!(diff <= 1e-5 * scale, "arbitrary positions: reg vs alt differ by {diff} (scale {scale})");
}
