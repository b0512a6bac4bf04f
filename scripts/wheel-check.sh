#!/usr/bin/env bash
# Checks that the Python wheel stands on its own, as a user receives it: builds the wheel from a
# temporary clone of HEAD, deletes the clone, installs the wheel into a fresh venv and, from
# another folder, predicts the Cones pair with `Model()` (the weights the wheel carries) and
# compares it with `dgstereo infer`'s disparity (the CLI given, default target/release/dgstereo);
# then removes the weights from the installed package and checks that `Model()` raises an error
# naming them. Needs maturin (pip) and a Rust toolchain; ~6 min cold on 2 cores.
#
#     scripts/wheel-check.sh [path/to/dgstereo]
set -euo pipefail
repo="$(cd "$(dirname "$0")/.." && pwd)"
cli="$(realpath "${1:-$repo/target/release/dgstereo}")"
work="$(mktemp -d)"
trap 'rm -rf "$work"' EXIT
git clone -q "$repo" "$work/clone"
python3 -m venv "$work/build-venv"
"$work/build-venv/bin/pip" install -q maturin
(cd "$work/clone/bindings/python" && CARGO_TARGET_DIR="${CARGO_TARGET_DIR:-$repo/target/wheel}" \
    "$work/build-venv/bin/maturin" build --release --out "$work/dist" -q)
rm -rf "$work/clone"
wheel="$(ls "$work"/dist/dgstereo-*.whl)"
echo "wheel: $(basename "$wheel"), $(du -h "$wheel" | cut -f1)"
unzip -l "$wheel" | grep -E "assets/weights/" || { echo "error: the wheel carries no weights" >&2; exit 1; }
python3 -m venv "$work/venv"
"$work/venv/bin/pip" install -q "$wheel"
mkdir -p "$work/elsewhere" && cd "$work/elsewhere"
"$cli" infer -l "$repo/assets/cones/left_rgb.png" -r "$repo/assets/cones/right_rgb.png" --out cli --save pfm > /dev/null 2>&1
"$work/venv/bin/python" - "$repo/assets/cones" cli <<'PY'
import pathlib, sys
import numpy as np
import dgstereo
cones, out = pathlib.Path(sys.argv[1]), pathlib.Path(sys.argv[2])
model = dgstereo.Model()
print("weights:", model.weights)
assert "site-packages" in model.weights, model.weights
disp = model.predict(dgstereo.read_image(cones / "left_rgb.png"), dgstereo.read_image(cones / "right_rgb.png"), iters=32)
cli = dgstereo.read_pfm(next(out.glob("*.pfm")))
print("max |Model() - infer| =", float(np.abs(disp - cli).max()), "px")
assert np.array_equal(disp, cli)
PY
rm -rf "$work"/venv/lib/python3*/site-packages/dgstereo/assets/weights
"$work/venv/bin/python" -c "
import dgstereo
try:
    dgstereo.Model()
except dgstereo.Error as e:
    print('without its weights:', e)
    assert 'raft-stereo-default.safetensors' in str(e)
else:
    raise SystemExit('Model() loaded without weights')
"
echo "wheel check passed"
