#!/usr/bin/env python3
"""Times an exported model (`dgstereo export onnx`) in ONNX Runtime or OpenVINO on the CPU, as
`dgstereo bench` times ours: random RGB pairs (0..255) of the file's size, whole inference
calls, the median and min after the warm-up, and the peak memory of the process (ru_maxrss).
Needs `pip install onnxruntime numpy` (or `openvino`). OpenVINO runs its default precision
for the CPU (bf16 where the processor has AMX or AVX512-BF16) unless `--precision f32`.
Compare with `dgstereo bench --size HxW --iters N [--precision bf16]`, alternating whole
processes:

    dgstereo export onnx --size 384x448 --iters 32 -o default.onnx
    python3 scripts/ort-bench.py default.onnx --threads 2
    python3 scripts/ort-bench.py default.onnx --threads 2 --runtime openvino
"""
import argparse
import platform
import resource
import statistics
import time

import numpy as np


def ort_session(a):
    """ONNX Runtime's CPU session: a run function, the inputs' names and shapes, its name."""
    import onnxruntime as ort

    options = ort.SessionOptions()
    options.intra_op_num_threads = a.threads
    options.inter_op_num_threads = 1
    session = ort.InferenceSession(a.model, options, providers=["CPUExecutionProvider"])
    inputs = [(i.name, [int(d) for d in i.shape]) for i in session.get_inputs()]
    return (lambda feed: session.run(None, feed)), inputs, f"onnxruntime {ort.__version__}"


def openvino_session(a):
    """OpenVINO's CPU plugin, compiled for latency, in its default precision unless asked."""
    import openvino as ov

    core = ov.Core()
    config = {"PERFORMANCE_HINT": "LATENCY"}
    if a.threads:
        config["INFERENCE_NUM_THREADS"] = a.threads
    if a.precision != "default":
        config["INFERENCE_PRECISION_HINT"] = a.precision
    compiled = core.compile_model(core.read_model(a.model), "CPU", config)
    request = compiled.create_infer_request()
    inputs = [(i.get_any_name(), [int(d) for d in i.get_shape()]) for i in compiled.inputs]
    precision = compiled.get_property("INFERENCE_PRECISION_HINT")
    return (lambda feed: request.infer(feed)), inputs, f"openvino {ov.__version__} ({precision} inference precision)"


def main():
    p = argparse.ArgumentParser(description=__doc__, formatter_class=argparse.RawDescriptionHelpFormatter)
    p.add_argument("model")
    p.add_argument("--runs", type=int, default=3)
    p.add_argument("--warmup", type=int, default=1)
    p.add_argument("--threads", type=int, default=0, help="intra-op threads (0: ONNX Runtime's choice)")
    p.add_argument("--runtime", choices=["onnxruntime", "openvino"], default="onnxruntime")
    p.add_argument(
        "--precision",
        choices=["default", "f32", "bf16"],
        default="default",
        help="OpenVINO's inference precision (default: its choice for the CPU, bf16 where it has a bf16 unit)",
    )
    a = p.parse_args()
    start = time.perf_counter()
    run, inputs, name = (openvino_session if a.runtime == "openvino" else ort_session)(a)
    load = time.perf_counter() - start
    rng = np.random.default_rng(0)
    feed = {}
    for input_name, shape in inputs:
        scale = 255.0 if shape[1] == 3 else 1.0
        feed[input_name] = (rng.random(shape, dtype=np.float32) * scale).astype(np.float32)
    times = []
    for k in range(a.warmup + a.runs):
        t = time.perf_counter()
        run(feed)
        elapsed = time.perf_counter() - t
        print(f"run {k}: {elapsed:.3f} s{' (warm-up)' if k < a.warmup else ''}")
        if k >= a.warmup:
            times.append(elapsed)
    shapes = ", ".join(f"{n} {'x'.join(str(d) for d in s)}" for n, s in inputs)
    print(f"{name}, CPU, {a.threads or 'default'} threads, {shapes}; session made in {load:.1f} s")
    print(f"machine: {platform.processor() or platform.machine()}")
    print(f"runs {len(times)} after {a.warmup} warm-up: median {statistics.median(times):.3f} s, min {min(times):.3f} s")
    print(f"peak memory (ru_maxrss) {resource.getrusage(resource.RUSAGE_SELF).ru_maxrss // 1024} MiB")


if __name__ == "__main__":
    main()
