#!/usr/bin/env bash
# Fetches the licence-clean photographs the synthetic generator's photo textures cut from
# (`photos = { dir = "data/photos", share = 0.5 }` in a synthetic source), from the scikit-image
# wheel on PyPI (its sample data), into DIR (default data/photos, which git ignores).
#
# Only images whose scikit-image documentation states CC0 or the public domain are taken (see
# docs/photo-textures.md for each one's licence and source). The Middlebury pair the wheel also
# ships (motorcycle_left/right) and the other test images are left out: the generator must never
# train on a benchmark's images.
set -euo pipefail
dir="${1:-data/photos}"
version="0.26.0"
images=(astronaut.png brick.png camera.png chelsea.png coffee.png grass.png gravel.png rocket.jpg)
tmp="$(mktemp -d)"
trap 'rm -rf "$tmp"' EXIT
python3 -m pip download --quiet --no-deps --dest "$tmp" "scikit-image==$version"
wheel="$(ls "$tmp"/scikit_image-*.whl)"
mkdir -p "$dir"
for image in "${images[@]}"; do
    python3 - "$wheel" "skimage/data/$image" "$dir/$image" <<'PY'
import sys, zipfile
with zipfile.ZipFile(sys.argv[1]) as wheel, open(sys.argv[3], "wb") as out:
    out.write(wheel.read(sys.argv[2]))
PY
done
cp "$(dirname "$0")/../docs/photo-textures.md" "$dir/LICENSES.md"
echo "${#images[@]} photographs in $dir (licences: $dir/LICENSES.md)"
