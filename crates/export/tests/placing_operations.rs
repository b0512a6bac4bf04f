//! An operation is placed in the forward pass by the named activations recorded with it (the
//! error of an operation the table lacks says where it comes): recorded on the golden default
//! checkpoint of `../shared/golden`, 2 iterations.

use burn::backend::ir::{BaseOperationIr, ModuleOperationIr, OperationIr};
use dgstereo_core::shared::shared_dir_for_test;
use dgstereo_export::capture::capture_disparity;
use dgstereo_export::lower::place;
use dgstereo_inference::{Engine, EngineConfig};

#[test]
fn operations_are_placed_after_the_activation_before_them() {
    let Some(shared) = shared_dir_for_test("placing", "golden/raft_stereo_random.pth") else { return };
    let weights = shared.join("golden/raft_stereo_random.pth");
    let engine = Engine::load(&EngineConfig { weights: Some(weights), ..EngineConfig::default() }).unwrap();
    let captured = capture_disparity(engine.stereo_model(), 64, 96, 2).unwrap();
    let ops = &captured.graph.graph.operations;
    let names: Vec<&str> = captured.landmarks.iter().map(|(_, n)| n.as_str()).collect();
    assert!(names.contains(&"fnet.left") && names.contains(&"iter.1.flow_lowres"), "{names:?}");
    let first_conv = ops.iter().position(|op| matches!(op, OperationIr::Module(ModuleOperationIr::Conv2d(_)))).unwrap();
    assert!(place(ops, &captured.landmarks, first_conv).starts_with("before `fnet.left`"));
    // The correlation lookup of the second iteration gathers after the first one's flow.
    let last_gather =
        ops.iter().rposition(|op| matches!(op, OperationIr::BaseFloat(BaseOperationIr::Gather(_)))).unwrap();
    let placed = place(ops, &captured.landmarks, last_gather);
    assert!(placed.starts_with("after `iter.0."), "{placed}");
}
