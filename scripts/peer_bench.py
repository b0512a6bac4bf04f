"""What the scripts timing the official PyTorch models on the CPU share: their flags, the random
padded inputs, the timing loop and its report (each run, the median and min, the peak memory).

Each `pytorch-*-bench.py` builds its model from the official code and passes `time_inference`
a function that runs one pass; this module holds no model code.
"""
import argparse
import resource
import statistics
import time

import torch


def timing_parser(description, iters=32, runs=3):
    """An argument parser with the flags every timing script takes."""
    p = argparse.ArgumentParser(description=description, formatter_class=argparse.RawDescriptionHelpFormatter)
    p.add_argument("--size", default="384x448", help="HxW of the input images (padded up to multiples of 32)")
    p.add_argument("--iters", type=int, default=iters, help="update iterations (valid_iters)")
    p.add_argument("--runs", type=int, default=runs, help="timed runs")
    p.add_argument("--warmup", type=int, default=1, help="untimed warm-up runs")
    p.add_argument("--threads", type=int, default=2, help="torch.set_num_threads")
    p.add_argument("--seed", type=int, default=0)
    return p


def raft_stereo_arguments(corr_levels=4):
    """demo.py's default model arguments of RAFT-Stereo (the base DEFOM-Stereo extends)."""
    return argparse.Namespace(
        hidden_dims=[128, 128, 128], corr_implementation="reg", shared_backbone=False, corr_levels=corr_levels,
        corr_radius=4, n_downsample=2, context_norm="batch", slow_fast_gru=False, n_gru_layers=3,
        mixed_precision=False)


def padded_inputs(size, batch=1):
    """Random left and right images of `size` ("HxW") padded up to multiples of 32, 0..255."""
    h, w = (int(v) for v in size.lower().split("x"))
    hp, wp = (h + 31) // 32 * 32, (w + 31) // 32 * 32
    return (h, w), (hp, wp), torch.rand(batch, 3, hp, wp) * 255.0, torch.rand(batch, 3, hp, wp) * 255.0


def setup(a):
    """Thread count and seed from the parsed flags."""
    torch.set_num_threads(a.threads)
    torch.manual_seed(a.seed)


def time_inference(a, label, run_once):
    """Runs `run_once()` (returning the output tensor) `a.warmup` times untimed and `a.runs`
    times timed under inference_mode, printing `label`, each run, the median and min, the peak
    RSS and torch's version."""
    print(f"{label}, threads={torch.get_num_threads()}, warmup={a.warmup}, runs={a.runs}", flush=True)
    times = []
    with torch.inference_mode():
        for _ in range(a.warmup):
            run_once()
        for i in range(a.runs):
            t0 = time.perf_counter()
            out = run_once()
            dt = time.perf_counter() - t0
            times.append(dt)
            print(f"run {i + 1}: {dt:.3f} s  (output {tuple(out.shape)})", flush=True)
    if times:
        print(f"median {statistics.median(times):.3f} s, min {min(times):.3f} s")
    report_memory()


def report_memory():
    """The process's peak RSS (ru_maxrss, KiB on Linux) and torch's version and CPU capability."""
    print(f"peak RSS {resource.getrusage(resource.RUSAGE_SELF).ru_maxrss / 1024.0:.1f} MiB")
    print(f"torch {torch.__version__}, cpu capability {torch.backends.cpu.get_cpu_capability()}")
