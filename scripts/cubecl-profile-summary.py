#!/usr/bin/env python3
"""Summarises cubecl's per-kernel profile log (`[profiling.logger] level = "basic"` in
cubecl.toml): kernels grouped by name, with count, total and mean GPU time, for the last
forward pass in the log: everything after the last kernel whose name contains `--start-after`
(default: the last random-number kernel, which `dgstereo bench` runs to make its inputs).

Usage: cubecl-profile-summary.py LOG [--start-after NAME]
"""
import argparse
import collections
import re
import sys

UNITS = {"ns": 1e-9, "µs": 1e-6, "us": 1e-6, "ms": 1e-3, "s": 1.0}


def parse(lines):
    rows = []
    for line in lines:
        m = re.match(r"\| ([0-9.]+)(ns|µs|us|ms|s)\s*\| (.*)", line)
        if not m:
            continue
        name = m.group(3)
        # A kernel's name without its hash; the matrix products' names spell out their whole
        # configuration, so they are grouped as one.
        short = "Matmul" if name.startswith("MatmulEntry") else re.sub(r"_[0-9a-f]{8}$", "", name)
        rows.append((float(m.group(1)) * UNITS[m.group(2)], short, name))
    return rows


def main():
    p = argparse.ArgumentParser()
    p.add_argument("log")
    p.add_argument("--start-after", default="PrngKernel", help="the last pass starts after the last kernel whose name contains this")
    a = p.parse_args()
    rows = parse(open(a.log, encoding="utf-8").read().splitlines())
    start = max((i for i, r in enumerate(rows) if a.start_after in r[2]), default=-1) + 1
    rows = rows[start:]
    total = sum(r[0] for r in rows)
    print(f"{len(rows)} kernels, {total * 1e3:.1f} ms of GPU time (each kernel timed alone)")
    groups = collections.defaultdict(lambda: [0, 0.0])
    for t, short, _ in rows:
        groups[short][0] += 1
        groups[short][1] += t
    print("| kernel | count | total (ms) | mean (µs) | share |")
    print("|---|---:|---:|---:|---:|")
    for name, (n, t) in sorted(groups.items(), key=lambda kv: -kv[1][1])[:30]:
        print(f"| {name[:80].replace(' | ', ' / ')} | {n} | {t * 1e3:.2f} | {t / n * 1e6:.1f} | {100 * t / max(total, 1e-12):.1f} % |")


if __name__ == "__main__":
    sys.exit(main())
