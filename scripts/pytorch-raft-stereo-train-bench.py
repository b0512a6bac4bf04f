#!/usr/bin/env python3
"""Times training steps of the official PyTorch RAFT-Stereo on the CPU, as `dgstereo bench --train`.

The model code is not ours to commit: RAFT_STEREO_DIR names a folder holding the official
`core/` of princeton-vl/RAFT-Stereo, unchanged (with empty `core/__init__.py` and
`core/utils/__init__.py` added), as for scripts/pytorch-raft-stereo-bench.py. Needs
`pip install torch numpy opt_einsum scipy`.

One step is the loop body of the official train_stereo.py: the model in train mode with frozen
batch norm (`model.module.freeze_bn()`), `model(left, right, iters=N)` returning every
iteration's upsampled flow, the sequence loss (gamma 0.9 adjusted to the prediction count,
`max_flow` 700, valid mask), `loss.backward()`, `clip_grad_norm_(1.0)`, AdamW (lr 2e-4, weight
decay 1e-5, eps 1e-8) and the one-cycle schedule (pct_start 0.01, linear, no momentum cycling).
Random images and a random ground truth of the requested size; prints each step, the median and
min after the warm-up, the forward / backward / optimiser split and the peak memory
(ru_maxrss). Compare with `dgstereo bench --train --size HxW --iters N --batch B`, alternating:

    RAFT_STEREO_DIR=/path/to/RAFT-Stereo python3 scripts/pytorch-raft-stereo-train-bench.py --size 192x320 --iters 12
"""
import argparse
import os
import resource
import statistics
import sys
import time
import warnings

import peer_bench

sys.path.insert(0, os.environ.get("RAFT_STEREO_DIR", os.path.dirname(os.path.abspath(__file__))))

import torch  # noqa: E402

warnings.filterwarnings("ignore", message=r".*torch\.cuda\.amp\.autocast.*")
warnings.filterwarnings("ignore", message=r".*torch\.meshgrid.*indexing.*")

from core.raft_stereo import RAFTStereo  # noqa: E402


def sequence_loss(flow_preds, flow_gt, valid, loss_gamma=0.9, max_flow=700):
    """train_stereo.py's loss, unchanged."""
    n_predictions = len(flow_preds)
    flow_loss = 0.0
    mag = torch.sum(flow_gt**2, dim=1).sqrt()
    valid = ((valid >= 0.5) & (mag < max_flow)).unsqueeze(1)
    for i in range(n_predictions):
        adjusted_loss_gamma = loss_gamma ** (15 / (n_predictions - 1)) if n_predictions > 1 else loss_gamma
        i_weight = adjusted_loss_gamma ** (n_predictions - i - 1)
        i_loss = (flow_preds[i] - flow_gt).abs()
        flow_loss += i_weight * i_loss[valid.bool()].mean()
    return flow_loss


def main():
    p = argparse.ArgumentParser(description=__doc__)
    p.add_argument("--size", default="192x320", help="HxW crop")
    p.add_argument("--iters", type=int, default=12, help="train_iters")
    p.add_argument("--batch", type=int, default=1)
    p.add_argument("--runs", type=int, default=5, help="timed steps")
    p.add_argument("--warmup", type=int, default=1, help="untimed steps first")
    p.add_argument("--threads", type=int, default=2, help="torch.set_num_threads")
    p.add_argument("--seed", type=int, default=0)
    a = p.parse_args()
    h, w = (int(v) for v in a.size.lower().split("x"))

    torch.set_num_threads(a.threads)
    torch.manual_seed(a.seed)
    margs = peer_bench.raft_stereo_arguments()
    model = torch.nn.DataParallel(RAFTStereo(margs))
    model.train()
    model.module.freeze_bn()
    steps = a.warmup + a.runs
    optimizer = torch.optim.AdamW(model.parameters(), lr=2e-4, weight_decay=1e-5, eps=1e-8)
    scheduler = torch.optim.lr_scheduler.OneCycleLR(
        optimizer, 2e-4, steps + 100, pct_start=0.01, cycle_momentum=False, anneal_strategy="linear"
    )
    left = torch.rand(a.batch, 3, h, w) * 255
    right = torch.rand(a.batch, 3, h, w) * 255
    flow = -torch.rand(a.batch, 1, h, w) * (w / 4)
    valid = torch.ones(a.batch, h, w)

    times = []
    for step in range(steps):
        start = time.perf_counter()
        optimizer.zero_grad()
        predictions = model(left, right, iters=a.iters)
        loss = sequence_loss(predictions, flow, valid)
        forward = time.perf_counter()
        loss.backward()
        backward = time.perf_counter()
        torch.nn.utils.clip_grad_norm_(model.parameters(), 1.0)
        optimizer.step()
        scheduler.step()
        end = time.perf_counter()
        split = (forward - start, backward - forward, end - backward)
        print(f"step {step}: {end - start:.3f} s (forward {split[0]:.3f}, backward {split[1]:.3f}, optimizer {split[2]:.3f})")
        if step >= a.warmup:
            times.append((end - start, split))
    total = [t for t, _ in times]
    med = lambda i: statistics.median(s[i] for _, s in times)  # noqa: E731
    print(f"torch {torch.__version__}, {a.threads} threads, batch {a.batch} of {h}x{w}, {a.iters} iterations")
    print(f"steps {a.runs} after {a.warmup} warm-up: median {statistics.median(total):.3f} s, min {min(total):.3f} s")
    print(f"median split: forward {med(0):.3f} s, backward {med(1):.3f} s, optimizer {med(2):.3f} s")
    print(f"peak memory (ru_maxrss) {resource.getrusage(resource.RUSAGE_SELF).ru_maxrss / 1024:.0f} MiB")


if __name__ == "__main__":
    main()
