# Common tasks. `just --list` shows them.

# The main job: disparity of the bundled Cones pair.
demo:
    cargo run --release -p dgstereo -- demo

# The test suite, as CI runs it.
test:
    scripts/test

# CI exactly.
ci:
    .ci/run

# Criterion benchmarks (history in target/criterion).
bench:
    cargo bench -p dgstereo-suite

# Conformance with the official RAFT-Stereo code on the reference activations.
verify:
    cargo run --release -p dgstereo -- verify raft-stereo --weights ../shared/golden/raft_stereo_random.pth --reference ../shared/golden/raft_stereo_random.activations.safetensors
    cargo run --release -p dgstereo -- verify train-step --weights ../shared/golden/raft_stereo_random.pth --reference ../shared/golden/raft_stereo_random.train_step.safetensors

# Resolve, validate and smoke-test every experiment file.
check-experiments:
    cargo run --release -p dgstereo -- experiment check experiments/*.toml experiments/smoke/*.toml

# Build the GPU (wgpu/Vulkan) binary.
build-gpu:
    cargo build --release -p dgstereo --features gpu --target-dir target/gpu

# Lints.
lint:
    cargo clippy --workspace --all-targets -- -D warnings
    cargo fmt --all -- --check

# Whole-inference timing with and without the host kernels (the issue's 384x448, 32 iterations).
bench-kernels size="384x448" iters="32":
    cargo build --release -p dgstereo
    target/release/dgstereo bench --size {{size}} --iters {{iters}} --kernels stock
    target/release/dgstereo bench --size {{size}} --iters {{iters}} --kernels host

# Look at the training pairs an experiment draws (augmented, as the trainer sees them).
samples experiment:
    cargo run --release -p dgstereo -- experiment samples {{experiment}} --out out/samples
