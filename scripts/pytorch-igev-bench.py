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
import resource
import statistics
import sys
import time
import warnings

sys.path.insert(0, os.environ.get("IGEV_STEREO_DIR", os.getcwd()))
warnings.filterwarnings("ignore")

import timm  # noqa: E402
import torch  # noqa: E402

# The official `Feature` asks timm for ImageNet weights; random ones are timed, so none is fetched.
_create = timm.create_model
timm.create_model = lambda name, pretrained=False, **kw: _create(name, pretrained=False, **kw)

from core.igev_stereo import IGEVStereo  # noqa: E402


def main():
    p = argparse.ArgumentParser(description=__doc__)
    p.add_argument("--size", default="384x448", help="HxW of the input images (padded up to multiples of 32)")
    p.add_argument("--iters", type=int, default=32, help="update iterations (valid_iters)")
    p.add_argument("--max-disp", type=int, default=192, help="max_disp (the volume holds max_disp/4 disparities)")
    p.add_argument("--runs", type=int, default=3, help="timed runs")
    p.add_argument("--warmup", type=int, default=1, help="untimed warm-up runs")
    p.add_argument("--threads", type=int, default=2, help="torch.set_num_threads")
    p.add_argument("--seed", type=int, default=0)
    a = p.parse_args()

    torch.set_num_threads(a.threads)
    torch.manual_seed(a.seed)
    # demo_imgs.py's default arguments
    margs = argparse.Namespace(
        mixed_precision=False, precision_dtype="float32", hidden_dims=[128] * 3, corr_implementation="reg",
        shared_backbone=False, corr_levels=2, corr_radius=4, n_downsample=2, slow_fast_gru=False,
        n_gru_layers=3, max_disp=a.max_disp)
    model = IGEVStereo(margs).eval()

    h, w = (int(v) for v in a.size.lower().split("x"))
    hp, wp = (h + 31) // 32 * 32, (w + 31) // 32 * 32
    left = torch.rand(1, 3, hp, wp) * 255.0
    right = torch.rand(1, 3, hp, wp) * 255.0
    print(f"IGEV-Stereo CPU bench: input {h}x{w} -> padded {hp}x{wp}, iters={a.iters}, max_disp={a.max_disp}, "
          f"threads={torch.get_num_threads()}, warmup={a.warmup}, runs={a.runs}", flush=True)
    times = []
    with torch.inference_mode():
        for _ in range(a.warmup):
            model(left, right, iters=a.iters, test_mode=True)
        for i in range(a.runs):
            t0 = time.perf_counter()
            disp = model(left, right, iters=a.iters, test_mode=True)
            dt = time.perf_counter() - t0
            times.append(dt)
            print(f"run {i + 1}: {dt:.3f} s  (output {tuple(disp.shape)})", flush=True)
    if times:
        print(f"median {statistics.median(times):.3f} s, min {min(times):.3f} s")
    print(f"peak RSS {resource.getrusage(resource.RUSAGE_SELF).ru_maxrss / 1024.0:.1f} MiB")
    print(f"torch {torch.__version__}, timm {timm.__version__}, cpu capability {torch.backends.cpu.get_cpu_capability()}")


if __name__ == "__main__":
    main()
