//! `dgstereo verify train-step` on the golden reference of two official training steps: the
//! trainer's defaults reproduce them (exit status 0, the summary line last).

mod common;

use common::{dgstereo, text};
use dgstereo_core::shared::shared_dir_for_test;

#[test]
fn verify_train_step_passes_on_the_golden_steps() {
    let reference = "golden/raft_stereo_random.train_step.safetensors";
    let Some(shared) = shared_dir_for_test("verify_train_step_passes_on_the_golden_steps", reference) else { return };
    let weights = shared.join("golden/raft_stereo_random.pth");
    let reference = shared.join(reference);
    let out = dgstereo(&[
        "verify",
        "train-step",
        "--weights",
        weights.to_str().unwrap(),
        "--reference",
        reference.to_str().unwrap(),
    ]);
    let all = text(&out);
    println!("{all}");
    assert!(out.status.success(), "the trainer deviates from the reference:\n{all}");
    let stdout = String::from_utf8_lossy(&out.stdout);
    let lines: Vec<&str> = stdout.lines().collect();
    let count = |prefix: &str| lines.iter().filter(|l| l.starts_with(prefix)).count();
    assert_eq!(count("step1.flow_up."), 4, "one line per iteration");
    assert_eq!(count("step1.grad."), 30, "every reference gradient");
    assert_eq!(count("step2.param."), 23, "every reference parameter's update");
    for key in ["step1.loss", "step2.loss", "step1.grad_norm", "step2.grad_norm", "step1.lr", "step2.lr"] {
        assert_eq!(count(&format!("{key} ")), 1, "{key}");
    }
    assert!(lines.iter().all(|l| !l.ends_with("FAIL")), "{stdout}");
    let last = lines.last().copied().unwrap_or_default();
    assert!(
        last.starts_with("train step: loss rel err ") && last.contains(" (worst: ") && last.ends_with(" %: PASSED"),
        "last line: {last}"
    );
}
