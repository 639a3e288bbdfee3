#!/usr/bin/env python3
"""Compares terrain-core's exact nearest-seed transform with scipy's
distance_transform_edt(return_indices=True) on the same masks.

Runs `cargo run --release -p terrain-core --example edt_masks`, which writes masks, the squared
Euclidean distance to the seed terrain-core returned, and its best-of-R timings. With python3,
numpy and scipy present, times scipy on each mask (best of R), checks that the squared distances
are equal texel for texel (the seeds may differ where several are equally near), and prints the
ratio scipy / terrain-core. Without scipy it says so and prints terrain-core's timings only.

    python3 scripts/compare_edt.py [--size N] [--repeat R]
"""

import argparse
import json
import os
import subprocess
import sys
import tempfile
import time


def main() -> int:
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("--size", type=int, default=492)
    ap.add_argument("--repeat", type=int, default=20)
    args = ap.parse_args()
    root = os.path.dirname(os.path.dirname(os.path.abspath(__file__)))
    out = tempfile.mkdtemp(prefix="compare_edt_")
    cmd = ["cargo", "run", "--release", "--quiet", "-p", "terrain-core", "--example", "edt_masks",
           "--", "--size", str(args.size), "--repeat", str(args.repeat), "--out", out]
    print("running:", " ".join(cmd), flush=True)
    subprocess.run(cmd, cwd=root, check=True)
    with open(os.path.join(out, "edt_timings.json")) as f:
        timings = json.load(f)
    try:
        import numpy as np
        from scipy import ndimage
    except ImportError as e:
        print(f"scipy comparison skipped: {e} (pip install scipy to run it)")
        return 0
    n = args.size
    print(f"\nterrain-core on {timings['threads']} threads; scipy {__import__('scipy').__version__}, "
          f"one thread; best of {args.repeat}; {n} x {n} masks")
    print(f"{'mask':<20} {'scipy (ms)':>11} {'exact (ms)':>11} {'ratio':>7}  distances")
    ok = True
    for name, t in timings["masks"].items():
        mask = np.fromfile(os.path.join(out, f"{name}.mask.u8"), dtype=np.uint8).reshape(n, n)
        ours = np.fromfile(os.path.join(out, f"{name}.dist2.u32"), dtype="<u4").reshape(n, n)
        # scipy measures from non-zero texels to the nearest zero: seeds are the zeros.
        feature = mask == 0
        best = float("inf")
        for _ in range(args.repeat):
            t0 = time.perf_counter()
            _, idx = ndimage.distance_transform_edt(feature, return_indices=True)
            best = min(best, (time.perf_counter() - t0) * 1e3)
        ys, xs = np.indices((n, n))
        d2 = (idx[0] - ys).astype(np.int64) ** 2 + (idx[1] - xs).astype(np.int64) ** 2
        if not mask.any():
            equal = True  # no seed: scipy's indices are meaningless, ours are NO_SEED
        else:
            equal = bool(np.array_equal(d2, ours.astype(np.int64)))
        ok &= equal
        ratio = best / t["exact_ms"]
        print(f"{name:<20} {best:>11.3f} {t['exact_ms']:>11.3f} {ratio:>6.1f}x  "
              f"{'equal' if equal else 'DIFFER'}")
    return 0 if ok else 1


if __name__ == "__main__":
    sys.exit(main())
