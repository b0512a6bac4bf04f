#!/usr/bin/env python3
"""Times an exported model (`dgstereo export onnx`) in ONNX Runtime on the CPU, as `dgstereo
bench` times ours: random RGB pairs (0..255) of the file's size, whole `session.run` calls,
the median and min after the warm-up, and the peak memory of the process (ru_maxrss).
Needs `pip install onnxruntime numpy`. Compare with `dgstereo bench --size HxW --iters N`,
alternating whole processes:

    dgstereo export onnx --size 384x448 --iters 32 -o default.onnx
    python3 scripts/ort-bench.py default.onnx --threads 2
"""
import argparse
import platform
import resource
import statistics
import time

import numpy as np
import onnxruntime as ort


def main():
    p = argparse.ArgumentParser(description=__doc__, formatter_class=argparse.RawDescriptionHelpFormatter)
    p.add_argument("model")
    p.add_argument("--runs", type=int, default=3)
    p.add_argument("--warmup", type=int, default=1)
    p.add_argument("--threads", type=int, default=0, help="intra-op threads (0: ONNX Runtime's choice)")
    a = p.parse_args()
    options = ort.SessionOptions()
    options.intra_op_num_threads = a.threads
    options.inter_op_num_threads = 1
    start = time.perf_counter()
    session = ort.InferenceSession(a.model, options, providers=["CPUExecutionProvider"])
    load = time.perf_counter() - start
    rng = np.random.default_rng(0)
    feed = {}
    for i in session.get_inputs():
        shape = [int(d) for d in i.shape]
        scale = 255.0 if shape[1] == 3 else 1.0
        feed[i.name] = (rng.random(shape, dtype=np.float32) * scale).astype(np.float32)
    times = []
    for k in range(a.warmup + a.runs):
        t = time.perf_counter()
        session.run(None, feed)
        elapsed = time.perf_counter() - t
        print(f"run {k}: {elapsed:.3f} s{' (warm-up)' if k < a.warmup else ''}")
        if k >= a.warmup:
            times.append(elapsed)
    shapes = ", ".join(f"{i.name} {'x'.join(str(d) for d in i.shape)}" for i in session.get_inputs())
    print(f"onnxruntime {ort.__version__}, CPU, {a.threads or 'default'} threads, {shapes}; session made in {load:.1f} s")
    print(f"machine: {platform.processor() or platform.machine()}")
    print(f"runs {len(times)} after {a.warmup} warm-up: median {statistics.median(times):.3f} s, min {min(times):.3f} s")
    print(f"peak memory (ru_maxrss) {resource.getrusage(resource.RUSAGE_SELF).ru_maxrss // 1024} MiB")


if __name__ == "__main__":
    main()
