"""What `dbs`'s sweeps cost and buy (issue 36: why half of vced's speed is out of reach).

    .venv/bin/python bench/dbs_sweeps.py [--sweeps 0,1,2,3,4] [--json bench/results/dbs_sweeps.json]

Per number of sweeps (rip/dbs.py `PASSES`, at most; 0: the filtered error only, vced's
dots kept): the photo fine and coarse error of quality_bench.py (the same photographs,
separation and eye model, in bands of 64 rows), the refinement's CPU time per ink-pixel
on one thread (vced's dots given; the photographs tiled to 1024 x 1536, per band the
least of 3 runs, summed: the least disturbed by other processes), and what the sweeps did
there (the kernel's counts): the pixels that may change (ink 1..254), and per sweep the
pixels tried and the changes made, per ink-pixel.  Last, "1 dry": one sweep with a jitter
threshold no change can beat, every pixel tried and none changed - the trials' own cost.
"""

from __future__ import annotations

import argparse
import json
import os
import sys
import time

import numpy as np

sys.path.insert(0, os.path.dirname(os.path.abspath(__file__)))
import hvs  # noqa: E402
import quality_bench  # noqa: E402

from wideprint.rip import dbs  # noqa: E402
from wideprint.rip.halftone import Halftoner  # noqa: E402

BAND = 64


def vced(cmyk: np.ndarray) -> np.ndarray:
    h = Halftoner("vced", cmyk.shape[1], 4)
    return np.concatenate([h.process(cmyk[y:y + BAND]) for y in range(0, cmyk.shape[0], BAND)])


DRY = (2 ** 31 - 1) // 255     # a jitter no change can beat (with the mask at 255 everywhere)


def refine(cmyk: np.ndarray, dots: np.ndarray, sweeps: int, dry: bool = False):
    """vced's dots refined in bands as the RIP does; (dots, CPU seconds per band, the
    kernel's counts summed over the inks).  dry: every pixel tried, none changed (the
    threshold out of reach): what the trials cost without the changes."""
    ref = Halftoner("dbs", 8, 4)._vc
    noise = np.full_like(ref.noise, 255) if dry else ref.noise
    r = dbs.RowDBS(cmyk.shape[1], 4, noise, ref.offsets, passes=sweeps,
                   jitter=((0, DRY), (127, DRY)) if dry else None)
    out = dots.copy()
    times = []
    for y in range(0, cmyk.shape[0], BAND):
        t = time.thread_time()
        for job in r.jobs(cmyk[y:y + BAND], out[y:y + BAND], y, 1):
            job()
        times.append(time.thread_time() - t)
    return out, np.array(times), r.stats.sum(axis=0)


def main(argv=None) -> int:
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("--sweeps", default="0,1,2,3,4")
    ap.add_argument("--json", metavar="PATH")
    args = ap.parse_args(argv)
    photos, source = quality_bench.photos()
    imgs = [(name, quality_bench.separate(rgb)) for name, rgb in photos]
    base = {name: vced(cmyk) for name, cmyk in imgs}
    big = np.concatenate([np.concatenate([imgs[0][1]] * 3, axis=1)] * 2, axis=0)
    big_dots = vced(big)
    refine(big[:BAND], big_dots[:BAND], 1)                  # compile / load the kernel
    rows = []
    print(f"photographs: {source}; CPU on one thread, {big.shape[1]} x {big.shape[0]} x 4")
    print(f"{'sweeps':>6} {'ns/ink-px':>10} {'photo fine':>11} {'photo coarse':>13}  "
          f"per ink-pixel: may change, then each sweep's tries / changes")
    configs = [(int(s), False) for s in args.sweeps.split(",")] + [(1, True)]
    times: dict = {cfg: [] for cfg in configs}
    counts: dict = {}
    for _ in range(3):              # interleaved rounds: a busy machine slows every row alike
        for cfg in configs:
            _, t, n = refine(big, big_dots, *cfg)
            times[cfg].append(t)
            counts[cfg] = n / big.size
    for sweeps, dry in configs:
        fine, coarse = [], []
        for name, cmyk in imgs if not dry else []:
            dots, _, _ = refine(cmyk, base[name], sweeps)
            for k in range(4):
                fine.append(hvs.rmse(dots[:, :, k], cmyk[:, :, k] / 255.0, hvs.FINE))
                coarse.append(hvs.rmse(dots[:, :, k], cmyk[:, :, k] / 255.0, hvs.COARSE))
        ns = np.min(times[sweeps, dry], axis=0).sum() / big.size * 1e9
        n = counts[sweeps, dry]
        active = float(n[0])
        per_sweep = [(round(float(t), 3), round(float(c), 4)) for t, c in zip(n[1::2], n[2::2])]
        row = dict(sweeps=sweeps, ns_per_ink_pixel=round(ns, 1), may_change=round(active, 3),
                   tries_changes=per_sweep)
        if dry:
            row["dry"] = True
        else:
            row.update(photo_fine=round(float(np.mean(fine)), 5),
                       photo_coarse=round(float(np.mean(coarse)), 5))
        rows.append(row)
        label = f"{sweeps} dry" if dry else f"{sweeps}"
        scores = "     (no change: vced's dots)" if dry else f"{np.mean(fine):11.5f} {np.mean(coarse):13.5f}"
        print(f"{label:>6} {ns:10.1f} {scores}  {active:.3f} "
              + " ".join(f"{t:.3f}/{c:.4f}" for t, c in per_sweep), flush=True)
    if args.json:
        with open(args.json, "w") as f:
            json.dump(dict(date=time.strftime("%Y-%m-%d %H:%M"), photos=source, cpus=os.cpu_count(),
                           load=os.getloadavg(), rows=rows), f, indent=1)
            f.write("\n")
    return 0


if __name__ == "__main__":
    sys.exit(main())
