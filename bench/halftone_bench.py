"""Throughput of wideprint.rip.halftone, per method, for 1 plane and for 4 planes.

    .venv/bin/python bench/halftone_bench.py [--width 8000] [--height 2000] [--band 256] [--repeat 3]

Input: a horizontal 0..255 gradient (each of the 4 planes shifted so that they
differ), halftoned in bands of --band rows (0 = the whole image in one call).
Prints Mpx/s, where one "px" is one pixel of one plane, so the 4-plane figure
is directly comparable with the 1-plane one.  No assertions: a measurement only.

    .venv/bin/python bench/halftone_bench.py --cli vced,dbs [--width 6000 --height 2000]
                                             [--repeat 5] [--json bench/results/halftone_dbs.json]

Whole commands as users run them (issue 36's speed rule: a new method at no less than half
of vced's speed): rip_bench.py's generated photo-like RGB TIFF, then `wideprint rip IMG -o
PLANES.tif --size pixels --dither M` for each method in turn, round after round (so a busy
machine slows every method alike), each a fresh process: wall and CPU seconds (the process
and its children); the medians and each method's against the first.  `M@DIR` runs method M
from another checkout, the package DIR/wideprint (e.g. `git archive` of an earlier commit
with its kernels built: `PYTHONPATH=DIR python tools/build_kernels.py` there), for a
before / after in the same rounds.
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


def whole_commands(methods: list[str], width: int, height: int, repeat: int, out: str | None) -> int:
    """`wideprint rip` per method, interleaved rounds: medians of wall and CPU seconds."""
    import json
    import statistics
    import tempfile
    sys.path.insert(0, os.path.dirname(os.path.abspath(__file__)))
    from rip_bench import TestImage, cli_env, run_measured, wideprint_cmd, write_tiff
    env = cli_env()
    envs = {}
    for m in methods:                       # M@DIR: the package DIR/wideprint
        where = m.partition("@")[2]
        envs[m] = env if not where else dict(env, PYTHONPATH=os.path.abspath(where))
        if where and not os.path.isfile(os.path.join(where, "wideprint", "__init__.py")):
            print(f"halftone_bench: {m}: no package {where}/wideprint", file=sys.stderr)
            return 2
    runs: dict[str, list] = {m: [] for m in methods}

    def rip(m: str, out: str):
        return run_measured(wideprint_cmd("rip", img, "-o", out, "--size", "pixels", "--dither",
                                          m.partition("@")[0]), env=envs[m])
    with tempfile.TemporaryDirectory(prefix="halftone_bench_") as d:
        img = os.path.join(d, "in.tif")
        write_tiff(img, TestImage(width, height))
        for m in methods:                                  # warm the caches (not counted)
            rip(m, os.path.join(d, "p.tif"))
        for _ in range(repeat):
            for k, m in enumerate(methods):
                r = rip(m, os.path.join(d, f"{k}.tif"))
                if not r.ok:
                    print(r.err[-2000:], file=sys.stderr)
                    return 1
                runs[m].append((r.wall, r.cpu))
    first = methods[0]
    med = {m: (statistics.median(w for w, _ in v), statistics.median(c for _, c in v))
           for m, v in runs.items()}
    print(f"`wideprint rip IMG -o PLANES.tif --size pixels --dither M`, {width} x {height} RGB "
          f"(rip_bench's image), {repeat} interleaved rounds, {os.cpu_count()} CPUs, load "
          f"{os.getloadavg()[0]:.1f}")
    print(f"{'method':8s} {'wall s':>8s} {'CPU s':>8s} {'Mpx/s':>8s} {'speed vs ' + first:>14s} "
          f"{'CPU vs ' + first:>12s}")
    for m, (w, c) in med.items():
        print(f"{m:8s} {w:8.2f} {c:8.2f} {width * height / w / 1e6:8.1f} "
              f"{med[first][0] / w:13.2f}x {c / med[first][1]:11.2f}x")
    if out:
        with open(out, "w") as f:
            json.dump({"date": time.strftime("%Y-%m-%d %H:%M"), "command": "wideprint rip IMG -o "
                       "PLANES.tif --size pixels --dither M", "width": width, "height": height,
                       "cpus": os.cpu_count(), "load": os.getloadavg(),
                       "runs": {m: [{"wall": w, "cpu": c} for w, c in v] for m, v in runs.items()},
                       "median": {m: {"wall": w, "cpu": c} for m, (w, c) in med.items()}}, f, indent=1)
            f.write("\n")
    return 0


def main(argv=None) -> int:
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("--width", type=int, default=8000)
    ap.add_argument("--height", type=int, default=2000)
    ap.add_argument("--band", type=int, default=256, help="rows per process() call; 0 = one call")
    ap.add_argument("--repeat", type=int, default=3, help="best of N runs")
    ap.add_argument("--cli", metavar="M,M", help="whole `wideprint rip` commands for these methods")
    ap.add_argument("--json", metavar="PATH", help="--cli: also write the runs as JSON")
    args = ap.parse_args(argv)
    if args.cli:
        return whole_commands(args.cli.split(","), args.width, args.height, args.repeat, args.json)

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
