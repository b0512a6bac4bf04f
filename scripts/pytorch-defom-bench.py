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
import argparse
import os
import resource
import statistics
import sys
import time
import warnings

sys.path.insert(0, os.environ.get("DEFOM_STEREO_DIR", os.getcwd()))
warnings.filterwarnings("ignore")

import torch  # noqa: E402

from core.defom_stereo import DEFOMStereo  # noqa: E402


def main():
    p = argparse.ArgumentParser(description=__doc__)
    p.add_argument("--size", default="384x448", help="HxW of the input images (padded up to multiples of 32)")
    p.add_argument("--iters", type=int, default=32, help="update iterations (valid_iters)")
    p.add_argument("--scale-iters", type=int, default=8, help="scale iterations among them (scale_iters)")
    p.add_argument("--encoder", default="vits", help="Depth Anything V2 size (dinov2_encoder)")
    p.add_argument("--runs", type=int, default=3, help="timed runs")
    p.add_argument("--warmup", type=int, default=1, help="untimed warm-up runs")
    p.add_argument("--threads", type=int, default=2, help="torch.set_num_threads")
    p.add_argument("--seed", type=int, default=0)
    a = p.parse_args()

    torch.set_num_threads(a.threads)
    torch.manual_seed(a.seed)
    # evaluate_stereo.py's default arguments, but the encoder
    margs = argparse.Namespace(
        dinov2_encoder=a.encoder, idepth_scale=0.5, hidden_dims=[128] * 3, corr_implementation="reg",
        shared_backbone=False, corr_levels=2, corr_radius=4,
        scale_list=[0.125, 0.25, 0.5, 0.75, 1.0, 1.25, 1.5, 2.0], scale_corr_radius=2, n_downsample=2,
        context_norm="batch", n_gru_layers=3, mixed_precision=False, slow_fast_gru=False)
    model = DEFOMStereo(margs).eval()

    h, w = (int(v) for v in a.size.lower().split("x"))
    hp, wp = (h + 31) // 32 * 32, (w + 31) // 32 * 32
    left = torch.rand(1, 3, hp, wp) * 255.0
    right = torch.rand(1, 3, hp, wp) * 255.0
    print(f"DEFOM-Stereo ({a.encoder}) CPU bench: input {h}x{w} -> padded {hp}x{wp}, iters={a.iters} "
          f"(scale {a.scale_iters}), threads={torch.get_num_threads()}, warmup={a.warmup}, runs={a.runs}", flush=True)
    times = []
    with torch.inference_mode():
        for _ in range(a.warmup):
            model(left, right, iters=a.iters, scale_iters=a.scale_iters, test_mode=True)
        for i in range(a.runs):
            t0 = time.perf_counter()
            disp = model(left, right, iters=a.iters, scale_iters=a.scale_iters, test_mode=True)
            dt = time.perf_counter() - t0
            times.append(dt)
            print(f"run {i + 1}: {dt:.3f} s  (output {tuple(disp.shape)})", flush=True)
    if times:
        print(f"median {statistics.median(times):.3f} s, min {min(times):.3f} s")
    print(f"peak RSS {resource.getrusage(resource.RUSAGE_SELF).ru_maxrss / 1024.0:.1f} MiB")
    print(f"torch {torch.__version__}, cpu capability {torch.backends.cpu.get_cpu_capability()}")


if __name__ == "__main__":
    main()
