#!/usr/bin/env bash
# The GPU measurements of issue #8 (and a check that the GPU path agrees with the CPU) in one
# call on a lent GPU machine, with room to spare in a 10-minute command.
#
# Prepare here (the GPU binary cannot be built on the device machine, which has no network):
#   cargo build --release -p dgstereo --features gpu --target-dir target/gpu      # ~27 min on 2 cores
#   mkdir -p .gpubin && strip -o .gpubin/dgstereo target/gpu/release/dgstereo && xz -T2 -6 -f .gpubin/dgstereo
#   and the Vulkan loader's packages in .gl/ (see the device tool's README). Both folders are
#   ignored by git; name them in the call's `carry`: [".gl", ".gpubin"].
# Run there:  bash scripts/gpu-check.sh
# A dry run of the plumbing on the CPU, with any release binary as .gpubin/dgstereo.xz:
#   DEVICE=cpu SIZE=64x128 ITERS=2 OUT=/tmp/gpu-check bash scripts/gpu-check.sh
# burn's kernel tuning is kept between leases: the database this script returns
# ($OUT/autotune-default.db) goes to .gpubin/autotune-default.db here, and the next lease starts
# from it (a fresh machine otherwise spends ~140 s tuning before the first timed pass).
set -uo pipefail
OUT=${OUT:-/tmp/gpu-check-out}
mkdir -p "$OUT"
for f in .gl/*.deb; do [ -e "$f" ] && dpkg -x "$f" /; done
ldconfig
xz -dc .gpubin/dgstereo.xz > /tmp/dgstereo && chmod +x /tmp/dgstereo || exit 1
export CUBECL_AUTOTUNE_LEVEL="${CUBECL_AUTOTUNE_LEVEL:-minimal}"
mkdir -p target/environment
if [ -f .gpubin/autotune-default.db ]; then cp .gpubin/autotune-default.db target/environment/default.db; fi
DEVICE="${DEVICE:-gpu}" SIZE="${SIZE:-375x1242}" ITERS="${ITERS:-32}"
if command -v nvidia-smi >/dev/null; then
    nvidia-smi --query-gpu=name,driver_version,memory.total --format=csv | tee "$OUT/gpu.txt"
fi

step() {
    echo "+ $*" | tee -a "$OUT/log.txt"
    timeout 170 "$@" 2>&1 | tee -a "$OUT/log.txt"
    # Keep the tuning after every step: a later step may be cut off by the command's limit.
    cp target/environment/default.db "$OUT/autotune-default.db" 2>/dev/null || true
}

kitti=(bench --device "$DEVICE" --size "$SIZE" --iters "$ITERS" --runs 3 --warmup 1)
step /tmp/dgstereo "${kitti[@]}" --precision f16
step /tmp/dgstereo "${kitti[@]}" --stages
step /tmp/dgstereo "${kitti[@]}" --precision f16 --stages
# The bundled default on Cones on the GPU in f32 and f16, scored against the ground truth: the
# metrics must match the CPU's (`dgstereo demo`: EPE 2.02 px, bad-2 23.7 %).
cones=(infer --left assets/cones/left_rgb.png --right assets/cones/right_rgb.png --device "$DEVICE" --iters "$ITERS" --save pfm)
for p in f32 f16; do
    step /tmp/dgstereo "${cones[@]}" --precision $p --out "$OUT/cones-$p"
    step /tmp/dgstereo metrics --pred "$OUT/cones-$p/rgb_disparity.pfm" --gt assets/cones/disp_left.pfm
done
