#!/usr/bin/env python3
"""Times the official PyTorch IGEV-Stereo on the CPU, as docs/performance.md compares it.

The model code is not ours to commit: IGEV_STEREO_DIR names the official code's `IGEV-Stereo/`
folder of gangweiX/IGEV (`core/`), unchanged. Needs `pip install torch numpy scipy opencv-python-headless`
and timm 0.5.4 (the MobileNetV2 layout the official `Feature` expects:
`pip install --target DIR --no-deps timm==0.5.4`, DIR on PYTHONPATH). demo_imgs.py's arguments
(max_disp 192, corr_levels 2, radius 4, hidden 128x3), eval(), inference_mode, test_mode=True,
random weights (timm's backbone built with pretrained=False; nothing is downloaded) and random
images padded to multiples of 32 as its InputPadder does; prints each run, the median and min,
and the process's peak memory (ru_maxrss). Compare with `dgstereo bench --config
experiments/zoo/igev.toml --size HxW --iters N --runs 3 --warmup 1`, alternating whole processes:

    IGEV_STEREO_DIR=/path/to/IGEV/IGEV-Stereo PYTHONPATH=DIR python3 scripts/pytorch-igev-bench.py --size 384x448 --iters 32
"""
import argparse
import os
import sys
import warnings

import peer_bench

sys.path.insert(0, os.environ.get("IGEV_STEREO_DIR", os.getcwd()))
warnings.filterwarnings("ignore")

import timm  # noqa: E402

# The official `Feature` asks timm for ImageNet weights; random ones are timed, so none is fetched.
_create = timm.create_model
timm.create_model = lambda name, pretrained=False, **kw: _create(name, pretrained=False, **kw)

from core.igev_stereo import IGEVStereo  # noqa: E402


def main():
    p = peer_bench.timing_parser(__doc__)
    p.add_argument("--max-disp", type=int, default=192, help="max_disp (the volume holds max_disp/4 disparities)")
    a = p.parse_args()
    peer_bench.setup(a)
    # demo_imgs.py's default arguments
    margs = argparse.Namespace(
        mixed_precision=False, precision_dtype="float32", hidden_dims=[128] * 3, corr_implementation="reg",
        shared_backbone=False, corr_levels=2, corr_radius=4, n_downsample=2, slow_fast_gru=False,
        n_gru_layers=3, max_disp=a.max_disp)
    model = IGEVStereo(margs).eval()
    (h, w), (hp, wp), left, right = peer_bench.padded_inputs(a.size)
    label = f"IGEV-Stereo (timm {timm.__version__}) CPU bench: input {h}x{w} -> padded {hp}x{wp}, iters={a.iters}, max_disp={a.max_disp}"
    peer_bench.time_inference(a, label, lambda: model(left, right, iters=a.iters, test_mode=True))


if __name__ == "__main__":
    main()
