#!/usr/bin/env bash
# Runs a command with Mesa's software Vulkan driver (lavapipe) as the only Vulkan device, so the
# GPU composition of a pass (burn's wgpu backend, the `dgstereo_core::gpu_routes`) runs on a
# machine without a GPU: which kernels it launches (cubecl's profiler) and what it computes, not
# how fast (lavapipe runs the kernels on the CPU).
#
# Build the WGSL variant first (lavapipe's compiler crashes on the `gpu` build's SPIR-V
# matrix-product kernels; autotune is off in it, since tuning on lavapipe takes many minutes):
#   cargo build --release -p dgstereo --features gpu-wgsl --target-dir target/gpu-wgsl
# Then, for example:
#   scripts/lavapipe.sh target/gpu-wgsl/release/dgstereo bench --device gpu --size 64x128 --iters 2
# With a `cubecl.toml` holding `[profiling.logger] level = "basic"` in the working directory, every
# kernel is logged (`scripts/cubecl-profile-summary.py` groups the log by kernel).
#
# The driver comes from the system's package archive on first use (`apt-get download`, Debian
# and Ubuntu), unpacked into LAVAPIPE_DIR (default ~/.cache/dgstereo-lavapipe); nothing is
# installed system-wide. LAVAPIPE_DEB names a driver package to unpack instead.
set -euo pipefail
dir=${LAVAPIPE_DIR:-$HOME/.cache/dgstereo-lavapipe}
if [ ! -f "$dir/lvp.json" ]; then
    mkdir -p "$dir/debs" "$dir/root"
    (
        cd "$dir/debs"
        if [ -n "${LAVAPIPE_DEB:-}" ]; then cp "$LAVAPIPE_DEB" .; else apt-get download mesa-vulkan-drivers; fi
        apt-get download libvulkan1
    ) >&2 || { echo "lavapipe.sh: could not fetch the driver packages (apt-get download)" >&2; exit 1; }
    for deb in "$dir"/debs/*.deb; do dpkg -x "$deb" "$dir/root"; done
    icd=$(find "$dir/root" -name 'lvp_icd*.json' | head -n 1)
    lib=$(find "$dir/root" -name libvulkan_lvp.so | head -n 1)
    if [ -z "$icd" ] || [ -z "$lib" ]; then echo "lavapipe.sh: no lavapipe driver in the packages" >&2; exit 1; fi
    sed "s#\"library_path\": *\"[^\"]*\"#\"library_path\": \"$lib\"#" "$icd" > "$dir/lvp.json"
fi
loader=$(dirname "$(find "$dir/root" -name 'libvulkan.so.1' | head -n 1)")
export VK_ICD_FILENAMES="$dir/lvp.json"
export LD_LIBRARY_PATH="$loader${LD_LIBRARY_PATH:+:$LD_LIBRARY_PATH}"
exec "$@"
