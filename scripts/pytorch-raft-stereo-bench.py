#!/usr/bin/env python3
"""Times the official PyTorch RAFT-Stereo on the CPU, as docs/performance.md compares it.

The model code is not ours to commit: RAFT_STEREO_DIR names a folder holding the official
`core/` of princeton-vl/RAFT-Stereo, unchanged (the comparisons used raft_stereo.py of fa8ed9d,
corr.py of ca57ab2, the rest of 5c13878, with empty `core/__init__.py` and
`core/utils/__init__.py` added). Needs `pip install torch numpy opt_einsum scipy` (the last two
are imported by the official code). demo.py's default arguments, eval(), inference_mode,
test_mode=True, random weights and images padded to multiples of 32; prints each run, the
median and min, and the process's peak memory (ru_maxrss). Compare with
`dgstereo bench --size HxW --iters N --runs 3 --warmup 1`, alternating size by size:

    RAFT_STEREO_DIR=/path/to/RAFT-Stereo python3 scripts/pytorch-raft-stereo-bench.py --size 384x448 --iters 32
"""
import argparse
import os
import resource
import statistics
import sys
import time
import warnings

sys.path.insert(0, os.environ.get("RAFT_STEREO_DIR", os.path.dirname(os.path.abspath(__file__))))

import torch  # noqa: E402

# Silence two harmless deprecation warnings emitted by the unmodified official code
# (torch.cuda.amp.autocast(enabled=False) is a no-op on CPU; meshgrid default indexing='ij').
warnings.filterwarnings("ignore", message=r".*torch\.cuda\.amp\.autocast.*")
warnings.filterwarnings("ignore", message=r".*torch\.meshgrid.*indexing.*")

from core.raft_stereo import RAFTStereo  # noqa: E402


def parse_size(s):
    h, w = s.lower().split("x")
    return int(h), int(w)


def pad_up(x, m=32):
    return ((x + m - 1) // m) * m


def main():
    p = argparse.ArgumentParser(description=__doc__)
    p.add_argument("--size", default="384x448", help="HxW of the input images (padded up to multiples of 32)")
    p.add_argument("--iters", type=int, default=32, help="GRU update iterations (demo.py valid_iters)")
    p.add_argument("--runs", type=int, default=3, help="timed runs")
    p.add_argument("--warmup", type=int, default=1, help="untimed warm-up runs")
    p.add_argument("--threads", type=int, default=2, help="torch.set_num_threads")
    p.add_argument("--seed", type=int, default=0)
    a = p.parse_args()

    torch.set_num_threads(a.threads)
    torch.manual_seed(a.seed)

    # demo.py default arguments
    margs = argparse.Namespace(
        hidden_dims=[128, 128, 128],
        corr_implementation="reg",
        shared_backbone=False,
        corr_levels=4,
        corr_radius=4,
        n_downsample=2,
        context_norm="batch",
        slow_fast_gru=False,
        n_gru_layers=3,
        mixed_precision=False,
    )
    model = RAFTStereo(margs)
    model.eval()

    h, w = parse_size(a.size)
    hp, wp = pad_up(h), pad_up(w)
    left = torch.rand(1, 3, hp, wp) * 255.0
    right = torch.rand(1, 3, hp, wp) * 255.0

    print(f"RAFT-Stereo CPU bench: input {h}x{w} -> padded {hp}x{wp}, iters={a.iters}, "
          f"threads={torch.get_num_threads()}, warmup={a.warmup}, runs={a.runs}", flush=True)

    times = []
    with torch.inference_mode():
        for _ in range(a.warmup):
            model(left, right, iters=a.iters, test_mode=True)
        for i in range(a.runs):
            t0 = time.perf_counter()
            _, flow_up = model(left, right, iters=a.iters, test_mode=True)
            dt = time.perf_counter() - t0
            times.append(dt)
            print(f"run {i + 1}: {dt:.3f} s  (output {tuple(flow_up.shape)})", flush=True)

    if times:
        print(f"median {statistics.median(times):.3f} s, min {min(times):.3f} s")
    maxrss_kib = resource.getrusage(resource.RUSAGE_SELF).ru_maxrss  # KiB on Linux
    print(f"peak RSS {maxrss_kib / 1024.0:.1f} MiB")
    print(f"torch {torch.__version__}, cpu capability {torch.backends.cpu.get_cpu_capability()}")


if __name__ == "__main__":
    main()
