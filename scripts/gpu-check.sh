#!/usr/bin/env bash
# The GPU measurements of issue #8 (and a check that the GPU path agrees with the CPU) in one
# call on a lent GPU machine, with room to spare in a 10-minute command.
#
# Prepare here (the GPU binary cannot be built on the device machine, which has no network):
#   cargo build --release -p dgstereo --features gpu --target-dir target/gpu      # ~27 min on 2 cores
#   mkdir -p .gpubin && strip -o .gpubin/dgstereo target/gpu/release/dgstereo && xz -T2 -6 -f .gpubin/dgstereo
#   and the Vulkan loader's packages in .gl/ (see the device tool's README). Both folders are
#   ignored by git; name them in the call's `carry`: [".gl", ".gpubin"].
# Run there:  bash scripts/gpu-check.sh    (call with timeout_s 600)
# A dry run of the plumbing on the CPU, with any release binary as .gpubin/dgstereo.xz:
#   DEVICE=cpu SIZE=64x128 ITERS=2 OUT=/tmp/gpu-check bash scripts/gpu-check.sh
# burn's kernel tuning is kept between leases: the database this script returns
# ($OUT/autotune-default.db and its write-ahead log, $OUT/autotune-default.db-wal) goes to
# .gpubin/ here, and the next lease starts from it (a fresh machine otherwise spends ~140 s tuning
# before the first timed pass). The log holds the newest tunings; a stale log left beside a
# replaced database (a warm machine's second call) corrupts it, so both are replaced together.
set -uo pipefail
OUT=${OUT:-/tmp/gpu-check-out}
mkdir -p "$OUT"
for f in .gl/*.deb; do [ -e "$f" ] && dpkg -x "$f" /; done
ldconfig
xz -dc .gpubin/dgstereo.xz > /tmp/dgstereo && chmod +x /tmp/dgstereo || exit 1
export CUBECL_AUTOTUNE_LEVEL="${CUBECL_AUTOTUNE_LEVEL:-minimal}"
mkdir -p target/environment
if [ -f .gpubin/autotune-default.db ]; then
    rm -f target/environment/default.db target/environment/default.db-*
    cp .gpubin/autotune-default.db target/environment/default.db
    if [ -f .gpubin/autotune-default.db-wal ]; then cp .gpubin/autotune-default.db-wal target/environment/default.db-wal; fi
fi
DEVICE="${DEVICE:-gpu}" SIZE="${SIZE:-375x1242}" ITERS="${ITERS:-32}"
if command -v nvidia-smi >/dev/null; then
    nvidia-smi --query-gpu=name,driver_version,memory.total --format=csv | tee "$OUT/gpu.txt"
fi

# Steps in order of importance, each with its own time limit, and none started once the whole
# script has run DEADLINE seconds (what a 600-second call leaves for the copy back), so a cut-off
# call still returns the first figures. The first step pays for burn's tuning (~140 s on a fresh
# machine without the database).
DEADLINE=${DEADLINE:-540}
step() {
    local limit=$1; shift
    local left=$((DEADLINE - SECONDS))
    if [ "$left" -lt 20 ]; then echo "- skipped (${SECONDS} s gone): $*" | tee -a "$OUT/log.txt"; return; fi
    [ "$limit" -gt "$left" ] && limit=$left
    echo "+ [${SECONDS} s, limit ${limit} s] ${DGSTEREO_KERNELS:+DGSTEREO_KERNELS=$DGSTEREO_KERNELS }$*" | tee -a "$OUT/log.txt"
    timeout "$limit" "$@" 2>&1 | tee -a "$OUT/log.txt"
    # Keep the tuning after every step: a later step may be cut off by the command's limit.
    cp target/environment/default.db "$OUT/autotune-default.db" 2>/dev/null || true
    cp target/environment/default.db-wal "$OUT/autotune-default.db-wal" 2>/dev/null || true
}

kitti=(bench --device "$DEVICE" --size "$SIZE" --iters "$ITERS" --runs 3 --warmup 1)
# The bundled default on Cones on the GPU, scored against the ground truth: the metrics must match
# the CPU's (`dgstereo demo`: EPE 2.02 px, bad-2 23.7 %).
cones=(infer --left assets/cones/left_rgb.png --right assets/cones/right_rgb.png --device "$DEVICE" --iters "$ITERS" --save pfm)
cones_scored() {
    step 120 /tmp/dgstereo "${cones[@]}" --precision "$1" --out "$OUT/cones-$1"
    step 30 /tmp/dgstereo metrics --pred "$OUT/cones-$1/rgb_disparity.pfm" --gt assets/cones/disp_left.pfm
}
step 280 /tmp/dgstereo "${kitti[@]}" --precision f16 --stages
cones_scored f16
# What each GPU inference route gains (`dgstereo_kernels::gpu`; DGSTEREO_KERNELS=stock-route=NAME turns the
# named ones off): one process each, all routes on between them.
for routes in epilogue "" shared-columns "" strided few-outputs "" epilogue,shared-columns,strided,few-outputs; do
    DGSTEREO_KERNELS=$(echo "$routes" | sed -E 's/([^,]+)/stock-route=\1/g') step 60 /tmp/dgstereo "${kitti[@]}" --precision f16
done
# The paper's stereo model (DGIA fusion + Gradient-GRU; its prior's time is not included).
step 60 /tmp/dgstereo "${kitti[@]}" --precision f16 --config scripts/paper-model.toml
# cubecl's per-kernel profile of one f16 pass (every kernel timed alone on the GPU, so the pass
# runs slower), summarised by kernel name ($OUT/profile.txt) and kept whole (gzipped).
printf '[profiling.logger]\nlevel = "basic"\nfile = "/tmp/cubecl-profile.log"\n' > cubecl.toml
step 90 /tmp/dgstereo bench --device "$DEVICE" --size "$SIZE" --iters "$ITERS" --runs 1 --warmup 1 --precision f16
rm -f cubecl.toml
if [ -s /tmp/cubecl-profile.log ]; then
    python3 scripts/cubecl-profile-summary.py /tmp/cubecl-profile.log > "$OUT/profile.txt" 2>&1
    gzip -c /tmp/cubecl-profile.log > "$OUT/cubecl-profile.log.gz"
fi
step 120 /tmp/dgstereo "${kitti[@]}" --precision f32
cones_scored f32
echo "done after ${SECONDS} s" | tee -a "$OUT/log.txt"
