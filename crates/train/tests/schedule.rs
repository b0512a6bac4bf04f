//! The one-cycle schedule against PyTorch's `OneCycleLR` formula.

use dgstereo_train::OneCycleLr;

/// A line-by-line transcription of `torch.optim.lr_scheduler.OneCycleLR.get_lr` for
/// `three_phase=False`, `anneal_strategy='linear'`, `div_factor=25`, `final_div_factor=1e4`.
fn torch_one_cycle(max_lr: f64, total_steps: usize, pct_start: f64, step_num: usize) -> f64 {
    let initial_lr = max_lr / 25.0;
    let min_lr = initial_lr / 1e4;
    // self._schedule_phases
    let phases =
        [(pct_start * total_steps as f64 - 1.0, initial_lr, max_lr), (total_steps as f64 - 1.0, max_lr, min_lr)];
    let step_num = step_num as f64;
    let mut start_step = 0.0;
    let mut lr = f64::NAN;
    for (i, &(end_step, start_lr, end_lr)) in phases.iter().enumerate() {
        if step_num <= end_step || i == phases.len() - 1 {
            let pct = (step_num - start_step) / (end_step - start_step);
            // _annealing_linear
            lr = (end_lr - start_lr) * pct + start_lr;
            break;
        }
        start_step = end_step;
    }
    lr
}

#[test]
fn one_cycle_matches_pytorch_formula_for_raft_stereo_recipe() {
    // RAFT-Stereo: total_steps = num_steps + 100, pct_start = 0.01.
    for (steps, max_lr) in [(200_000usize, 2e-4), (1000, 1e-3), (4000, 2e-5)] {
        let total = steps + 100;
        let s = OneCycleLr::new(max_lr, total, 0.01).unwrap();
        let probes = [
            0,
            1,
            2,
            5,
            total / 200,
            total / 100 - 1,
            total / 100,
            total / 100 + 1,
            total / 2,
            steps - 1,
            total - 2,
            total - 1,
        ];
        for k in probes {
            let ours = s.lr(k);
            let torch = torch_one_cycle(max_lr, total, 0.01, k);
            assert!((ours - torch).abs() <= 1e-12 * max_lr.max(1.0), "steps {steps}, k {k}: {ours} vs {torch}");
        }
    }
}

#[test]
fn one_cycle_endpoints_are_pytorch_defaults() {
    let s = OneCycleLr::new(2e-4, 200_100, 0.01).unwrap();
    // Starts at max_lr / div_factor (25).
    assert!((s.lr(0) - 2e-4 / 25.0).abs() < 1e-15);
    // Peaks at step pct_start * total - 1 = 2000.
    assert!((s.lr(2000) - 2e-4).abs() < 1e-12, "{}", s.lr(2000));
    assert!(s.lr(1999) < s.lr(2000) && s.lr(2001) < s.lr(2000));
    // Ends at initial_lr / final_div_factor (1e4).
    assert!((s.lr(200_099) - 2e-4 / 25.0 / 1e4).abs() < 1e-18);
    // Linear: the fraction of the way from peak to floor is the fraction of the anneal phase.
    let (peak, floor) = (2e-4, 2e-4 / 25.0 / 1e4);
    for k in [2500usize, 101_050, 190_000] {
        let done = (s.lr(k) - peak) / (floor - peak);
        let expect = (k as f64 - 2000.0) / (200_099.0 - 2000.0);
        assert!((done - expect).abs() < 1e-9, "step {k}: {done} vs {expect}");
    }
    // Past the end it stays at the floor.
    assert_eq!(s.lr(10_000_000), s.lr(200_099));
}

#[test]
fn one_cycle_rejects_bad_parameters() {
    assert!(OneCycleLr::new(1e-3, 0, 0.01).is_err());
    assert!(OneCycleLr::new(1e-3, 100, 0.0).is_err());
    assert!(OneCycleLr::new(1e-3, 100, 1.0).is_err());
}
