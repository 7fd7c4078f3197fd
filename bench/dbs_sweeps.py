"""What `dbs`'s sweeps cost and buy (issue 36: why half of vced's speed is out of reach).

    .venv/bin/python bench/dbs_sweeps.py [--sweeps 0,1,2,3,4] [--json bench/results/dbs_sweeps.json]

Per number of sweeps (rip/dbs.py `PASSES`, at most; 0: the filtered error only, vced's
dots kept): the photo fine and coarse error of quality_bench.py (the same photographs,
separation and eye model, in bands of 64 rows) and the refinement's CPU time per ink-pixel
on one thread (vced's dots given; the photographs tiled to 1024 x 1536, best of 3).
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


def refine(cmyk: np.ndarray, dots: np.ndarray, sweeps: int) -> tuple[np.ndarray, float]:
    """vced's dots refined in bands as the RIP does; (dots, CPU seconds)."""
    ref = Halftoner("dbs", 8, 4)._vc
    r = dbs.RowDBS(cmyk.shape[1], 4, ref.noise, ref.offsets, passes=sweeps)
    out = dots.copy()
    t = time.process_time()
    for y in range(0, cmyk.shape[0], BAND):
        for job in r.jobs(cmyk[y:y + BAND], out[y:y + BAND], y, 1):
            job()
    return out, time.process_time() - t


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
    print(f"{'sweeps':>6} {'ns/ink-px':>10} {'photo fine':>11} {'photo coarse':>13}")
    for sweeps in (int(s) for s in args.sweeps.split(",")):
        fine, coarse = [], []
        for name, cmyk in imgs:
            dots, _ = refine(cmyk, base[name], sweeps)
            for k in range(4):
                fine.append(hvs.rmse(dots[:, :, k], cmyk[:, :, k] / 255.0, hvs.FINE))
                coarse.append(hvs.rmse(dots[:, :, k], cmyk[:, :, k] / 255.0, hvs.COARSE))
        ns = min(refine(big, big_dots, sweeps)[1] for _ in range(3)) / big.size * 1e9
        rows.append(dict(sweeps=sweeps, ns_per_ink_pixel=round(ns, 1),
                         photo_fine=round(float(np.mean(fine)), 5),
                         photo_coarse=round(float(np.mean(coarse)), 5)))
        print(f"{sweeps:6d} {ns:10.1f} {np.mean(fine):11.5f} {np.mean(coarse):13.5f}", flush=True)
    if args.json:
        with open(args.json, "w") as f:
            json.dump(dict(date=time.strftime("%Y-%m-%d %H:%M"), photos=source, cpus=os.cpu_count(),
                           load=os.getloadavg(), rows=rows), f, indent=1)
            f.write("\n")
    return 0


if __name__ == "__main__":
    sys.exit(main())
