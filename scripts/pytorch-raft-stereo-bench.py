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
import os
import sys
import warnings

import peer_bench

sys.path.insert(0, os.environ.get("RAFT_STEREO_DIR", os.path.dirname(os.path.abspath(__file__))))

# Silence two harmless deprecation warnings emitted by the unmodified official code
# (torch.cuda.amp.autocast(enabled=False) is a no-op on CPU; meshgrid default indexing='ij').
warnings.filterwarnings("ignore", message=r".*torch\.cuda\.amp\.autocast.*")
warnings.filterwarnings("ignore", message=r".*torch\.meshgrid.*indexing.*")

from core.raft_stereo import RAFTStereo  # noqa: E402


def main():
    a = peer_bench.timing_parser(__doc__).parse_args()
    peer_bench.setup(a)
    model = RAFTStereo(peer_bench.raft_stereo_arguments()).eval()
    (h, w), (hp, wp), left, right = peer_bench.padded_inputs(a.size)
    label = f"RAFT-Stereo CPU bench: input {h}x{w} -> padded {hp}x{wp}, iters={a.iters}"
    peer_bench.time_inference(a, label, lambda: model(left, right, iters=a.iters, test_mode=True)[1])


if __name__ == "__main__":
    main()
