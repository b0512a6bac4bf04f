//! A small model overfits one synthetic pair: the whole training step works end to end.

mod common;

use std::time::Instant;

use dgstereo_core::default_device;
use dgstereo_train::Trainer;
use dgstereo_train::batch::to_tensors;
use dgstereo_train::trainer::{batch_metrics, forward_disparities};

#[test]
fn tiny_model_overfits_one_synthetic_pair() {
    // 32x64 pair, 3 iterations, a schedule that ends at the last step (no extra 100 steps), so the
    // rate anneals to ~0 and the weights settle.
    let (steps, iters) = (50, 3);
    let mut parts = common::tiny_parts(steps, iters, 2e-3, Some(1), 1);
    parts.train.schedule_extra_steps = 0;
    let device = default_device();
    let mut trainer = Trainer::new(parts, &device).unwrap();
    let bn_before = dgstereo_core::tensor::to_vec(match &trainer.inference_model().encoder.context_encoder().norm1 {
        dgstereo_encoder::norm::Norm::Batch(bn) => bn.running_var.val(),
        _ => panic!("the context encoder uses batch norm"),
    });
    let started = Instant::now();
    let mut first = None;
    let mut last = None;
    for _ in 0..steps {
        let r = trainer.step().unwrap();
        first.get_or_insert(r);
        last = Some(r);
    }
    let (first, last) = (first.unwrap(), last.unwrap());
    // Evaluate the trained weights (no autodiff) on the pair it saw.
    let model = trainer.inference_model();
    let pair = dgstereo_train::batch::TrainingData::new(&trainer.parts().data, &trainer.parts().train)
        .unwrap()
        .pair(0, 0)
        .unwrap();
    let batch = to_tensors(&[pair], &device).unwrap();
    let out = forward_disparities(&model, &trainer.parts().model, batch.left, batch.right, None, iters, false).unwrap();
    let m = batch_metrics(out[0].clone(), batch.target.disparity_bilinear, batch.target.valid).unwrap().metrics();
    eprintln!(
        "overfit: {steps} steps in {:.1} s; loss {:.3} -> {:.3}, train EPE {:.3} -> {:.3}; final EPE {:.3} px, bad-3 {:.2} %",
        started.elapsed().as_secs_f64(),
        first.loss,
        last.loss,
        first.epe,
        last.epe,
        m.epe,
        m.bad_3
    );
    assert!(first.epe > 1.0, "the untrained model should be far off (EPE {})", first.epe);
    assert!(m.epe < 0.5, "EPE after overfitting is {} px", m.epe);
    let bn_after = dgstereo_core::tensor::to_vec(match &model.encoder.context_encoder().norm1 {
        dgstereo_encoder::norm::Norm::Batch(bn) => bn.running_var.val(),
        _ => unreachable!(),
    });
    assert_eq!(bn_before, bn_after, "frozen BatchNorm statistics changed during training");
}

#[test]
fn timed_steps_report_each_step_and_the_forwards_work() {
    let device = default_device();
    let mut trainer = Trainer::new(common::tiny_parts(10, 2, 2e-3, Some(1), 1), &device).unwrap();
    let batch = dgstereo_train::step_timing::random_batch(1, [32, 64], 8.0, trainer.autodiff_device());
    let single = dgstereo_collective::SingleProcess;
    let timing = dgstereo_train::timed_steps::time_steps(&mut trainer, &batch, &single, 1, 2).unwrap();
    assert_eq!(timing.steps.len(), 2);
    for (wall, parts) in &timing.steps {
        assert!(*wall > 0.0 && parts.forward > 0.0 && parts.backward > 0.0, "{timing:?}");
        assert!(parts.total() <= *wall, "{timing:?}");
    }
    assert!(timing.macs > 0);
    assert_eq!(trainer.completed_steps(), 3, "the warm-up steps too");
}
