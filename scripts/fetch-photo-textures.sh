#!/usr/bin/env bash
# Fetches the licence-clean photographs the synthetic generator's photo textures cut from, into
# DIR (default data/photos, which git ignores):
#   DIR/train     scikit-image 0.26's CC0 / public-domain sample images (the wheel on PyPI) and nine
#                 of the MATE desktop's nature photographs (Debian's mate-backgrounds, GPL-2+);
#   DIR/held-out  three more MATE nature photographs, for a validation set whose textures the
#                 training never saw (`[data.validation] photos = { dir = "data/photos/held-out" }`).
# docs/photo-textures.md lists each image's author and licence. None is bundled in the repository,
# and no stereo benchmark's image is taken: the Middlebury pair that the scikit-image wheel also
# ships (motorcycle_left/right) is left out, so the generator never trains on a benchmark.
set -euo pipefail
dir="${1:-data/photos}"
skimage_version="0.26.0"
skimage=(astronaut.png brick.png camera.png chelsea.png coffee.png grass.png gravel.png rocket.jpg)
mate_version="1.26.0-1"
mate_train=(Aqua.jpg Blinds.jpg FreshFlower.jpg Garden.jpg LadyBird.jpg RainDrops.jpg TwoWings.jpg Wood.jpg YellowFlower.jpg)
mate_held_out=(Dune.jpg GreenMeadow.jpg Storm.jpg)
tmp="$(mktemp -d)"
trap 'rm -rf "$tmp"' EXIT
mkdir -p "$dir/train" "$dir/held-out"

python3 -m pip download --quiet --no-deps --dest "$tmp" "scikit-image==$skimage_version"
wheel="$(ls "$tmp"/scikit_image-*.whl)"
for image in "${skimage[@]}"; do
    python3 - "$wheel" "skimage/data/$image" "$dir/train/$image" <<'PY'
import sys, zipfile
with zipfile.ZipFile(sys.argv[1]) as wheel, open(sys.argv[3], "wb") as out:
    out.write(wheel.read(sys.argv[2]))
PY
done

# apt-get download needs no root and installs nothing; the package is unpacked in the temporary folder.
(cd "$tmp" && apt-get download --quiet "mate-backgrounds=$mate_version" >/dev/null)
dpkg-deb -x "$tmp"/mate-backgrounds_*.deb "$tmp/mate"
nature="$tmp/mate/usr/share/backgrounds/mate/nature"
for image in "${mate_train[@]}"; do cp "$nature/$image" "$dir/train/"; done
for image in "${mate_held_out[@]}"; do cp "$nature/$image" "$dir/held-out/"; done

cp "$(dirname "$0")/../docs/photo-textures.md" "$dir/LICENSES.md"
echo "$(ls "$dir/train" | wc -l) training and $(ls "$dir/held-out" | wc -l) held-out photographs in $dir (licences: $dir/LICENSES.md)"
