//! `dgstereo bench --train`: whole training steps timed, with their split, on both paths of the
//! convolution's backward.

use std::process::{Command, Output};

fn dgstereo(args: &[&str]) -> Output {
    Command::new(env!("CARGO_BIN_EXE_dgstereo")).args(args).output().expect("run dgstereo")
}

fn text(o: &Output) -> String {
    format!("{}{}", String::from_utf8_lossy(&o.stdout), String::from_utf8_lossy(&o.stderr))
}

#[test]
fn bench_train_times_steps_and_names_the_backward() {
    let bench = |kernels: &str| {
        let args = [
            "bench",
            "--train",
            "--size",
            "32x64",
            "--iters",
            "1",
            "--runs",
            "1",
            "--warmup",
            "0",
            "--kernels",
            kernels,
        ];
        dgstereo(&args)
    };
    let host = bench("host");
    assert!(host.status.success(), "{}", text(&host));
    let out = text(&host);
    for line in [
        "training step: batch 1 of 32x64, 1 iterations",
        "host convolution backward",
        "median split: forward",
        "machine: ",
    ] {
        assert!(out.contains(line), "missing '{line}' in:\n{out}");
    }
    let stock = bench("stock-training");
    assert!(stock.status.success() && text(&stock).contains(", stock, "), "{}", text(&stock));
    let bad = dgstereo(&["bench", "--train", "--batch", "0", "--size", "32x64"]);
    assert!(!bad.status.success() && text(&bad).contains("--batch must be at least 1"), "{}", text(&bad));
}
