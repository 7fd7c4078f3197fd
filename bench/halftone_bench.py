"""Throughput of wideprint.rip.halftone, per method, for 1 plane and for 4 planes.

    .venv/bin/python bench/halftone_bench.py [--width 8000] [--height 2000] [--band 256] [--repeat 3]

Input: a horizontal 0..255 gradient (each of the 4 planes shifted so that they
differ), halftoned in bands of --band rows (0 = the whole image in one call).
Prints Mpx/s, where one "px" is one pixel of one plane, so the 4-plane figure
is directly comparable with the 1-plane one.  No assertions: a measurement only.
"""

from __future__ import annotations

import argparse
import os
import sys
import time

import numpy as np

try:
    from wideprint.rip.halftone import METHODS, Halftoner
except ImportError:  # run from a checkout without the package installed
    sys.path.insert(0, os.path.dirname(os.path.dirname(os.path.dirname(os.path.abspath(__file__)))))
    from wideprint.rip.halftone import METHODS, Halftoner


def gradient(height: int, width: int, channels: int) -> np.ndarray:
    ramp = np.linspace(0, 255, width).round().astype(np.uint8)
    planes = [np.roll(ramp, k * width // max(channels, 1)) for k in range(channels)]
    row = np.stack(planes, axis=-1)  # (width, channels)
    return np.ascontiguousarray(np.broadcast_to(row, (height, width, channels)))


def run(method: str, img: np.ndarray, band: int) -> float:
    h = Halftoner(method, img.shape[1], img.shape[2])
    rows = img.shape[0]
    step = rows if band <= 0 else band
    t0 = time.perf_counter()
    for r in range(0, rows, step):
        h.process(img[r:r + step])
    return time.perf_counter() - t0


def main(argv=None) -> int:
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("--width", type=int, default=8000)
    ap.add_argument("--height", type=int, default=2000)
    ap.add_argument("--band", type=int, default=256, help="rows per process() call; 0 = one call")
    ap.add_argument("--repeat", type=int, default=3, help="best of N runs")
    args = ap.parse_args(argv)

    print(f"halftone throughput, {args.width}x{args.height} gradient, bands of "
          f"{args.band if args.band > 0 else args.height} rows, best of {args.repeat}, "
          f"{os.cpu_count()} CPUs")
    print(f"{'method':10s} {'1 plane Mpx/s':>14s} {'4 planes Mpx/s':>15s} {'4-plane speed-up':>17s}")
    images = {c: gradient(args.height, args.width, c) for c in (1, 4)}
    for method in METHODS:
        rates = {}
        for c, img in images.items():
            run(method, img[:16], 0)  # compile / load the numba cache
            best = min(run(method, img, args.band) for _ in range(args.repeat))
            rates[c] = img.shape[0] * img.shape[1] * c / best / 1e6
        print(f"{method:10s} {rates[1]:14.1f} {rates[4]:15.1f} {rates[4] / rates[1]:16.2f}x")
    return 0


if __name__ == "__main__":
    sys.exit(main())
