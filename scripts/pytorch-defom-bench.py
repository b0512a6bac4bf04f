#!/usr/bin/env python3
"""Times the official PyTorch DEFOM-Stereo on the CPU, as docs/performance.md compares it.

The model code is not ours to commit: DEFOM_STEREO_DIR names a folder holding the official code
of Insta360-Research-Team/DEFOM-Stereo (`core/`, `depth_anything_v2/`), unchanged. Needs
`pip install torch timm opencv-python-headless numpy scipy opt_einsum` (imported by the
official code). evaluate_stereo.py's arguments for `--dinov2_encoder vits` (or `--encoder`),
eval(), inference_mode, test_mode=True, random weights (PyTorch's initialisation; no Depth
Anything checkpoint is read) and random images padded to multiples of 32 as its InputPadder
does; prints each run, the median and min, and the process's peak memory (ru_maxrss). Compare
with `dgstereo bench --config experiments/zoo/defom-vits.toml --size HxW --iters N --runs 3
--warmup 1`, alternating whole processes:

    DEFOM_STEREO_DIR=/path/to/DEFOM-Stereo python3 scripts/pytorch-defom-bench.py --size 384x448 --iters 32
"""
import os
import sys
import warnings

import peer_bench

sys.path.insert(0, os.environ.get("DEFOM_STEREO_DIR", os.getcwd()))
warnings.filterwarnings("ignore")

from core.defom_stereo import DEFOMStereo  # noqa: E402


def main():
    p = peer_bench.timing_parser(__doc__)
    p.add_argument("--scale-iters", type=int, default=8, help="scale iterations among them (scale_iters)")
    p.add_argument("--encoder", default="vits", help="Depth Anything V2 size (dinov2_encoder)")
    a = p.parse_args()
    peer_bench.setup(a)
    # evaluate_stereo.py's default arguments, but the encoder
    margs = peer_bench.raft_stereo_arguments(corr_levels=2)
    margs.dinov2_encoder, margs.idepth_scale = a.encoder, 0.5
    margs.scale_list, margs.scale_corr_radius = [0.125, 0.25, 0.5, 0.75, 1.0, 1.25, 1.5, 2.0], 2
    model = DEFOMStereo(margs).eval()
    (h, w), (hp, wp), left, right = peer_bench.padded_inputs(a.size)
    label = (f"DEFOM-Stereo ({a.encoder}) CPU bench: input {h}x{w} -> padded {hp}x{wp}, iters={a.iters} "
             f"(scale {a.scale_iters})")
    peer_bench.time_inference(
        a, label, lambda: model(left, right, iters=a.iters, scale_iters=a.scale_iters, test_mode=True))


if __name__ == "__main__":
    main()
