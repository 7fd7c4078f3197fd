"""Banding, graininess and mottle of the banding chart on the emulated machines, per pass
mask and pass count (issue 36; docs/quality.md; results in bench/results/banding*.json).

    python -m wideprint.bench.banding_bench [--machines typical,tired] [--passes 1,2,4]
        [--masks checker,feather] [--out bench/results/banding.json] [--seeds 1,2]

Each run prints `wideprint test-print banding-scan` (300 dpi, 100 x 64 mm: ten flat tints
along the feed) on the in-process emulator with `--inject machine=NAME --inject seed=S`,
scans it at 600 dpi and measures the scan with `wideprint quality` (app/quality.py).  The
machine's errors are drawn from the seed, so every mask of a run prints on the same
machine: the same nozzles, the same feeds.  The figure per run is the mean over the ten
tints of the eye-weighted banding (RMS ΔL* at 500 mm), graininess and mottle; per mode
the mean over the seeds.
"""

from __future__ import annotations

import argparse
import contextlib
import io
import json
import os
import platform
import sys
import tempfile
import time
from pathlib import Path

from ..app.cli import main as wideprint
from ..app.quality import measure_scan
from ..rip.settings import PASS_MASKS

SCAN_DPI = 600
DPI = 300


def run(machine: str, passes: int, mask: str, seed: int, workdir: str, bidir: bool = False) -> dict:
    scan = os.path.join(workdir, f"{machine}-{passes}-{mask}-{seed}.tif")
    argv = ["test-print", "banding-scan", "--dpi", str(DPI), "--passes", str(passes),
            "--pass-mask", mask, "--scan-out", scan, "--scan-dpi", str(SCAN_DPI),
            "--inject", f"machine={machine}", "--inject", f"seed={seed}"] + (["--bidir"] if bidir else [])
    t0 = time.perf_counter()
    with contextlib.redirect_stdout(io.StringIO()):
        rc = wideprint(argv)
    if rc != 0:
        raise SystemExit(f"test-print failed ({rc}): {' '.join(argv)}")
    rep = measure_scan(scan, passes=passes)
    os.unlink(scan)
    return dict(machine=machine, passes=passes, mask=mask, seed=seed, bidir=bidir,
                seconds=round(time.perf_counter() - t0, 2), **rep.summary(),
                tints={q.name: dict(banding=q.banding, graininess=q.graininess, mottle=q.mottle,
                                    lightness=q.lightness) for q in rep.tints})


def main(argv: list[str] | None = None) -> int:
    ap = argparse.ArgumentParser(description=__doc__.split("\n\n")[0])
    ap.add_argument("--machines", default="typical,tired")
    ap.add_argument("--passes", default="1,2,3,4,6,8")
    ap.add_argument("--masks", default=",".join(PASS_MASKS))
    ap.add_argument("--seeds", default="1,2")
    ap.add_argument("--bidir", action="store_true")
    ap.add_argument("--out", default=None)
    args = ap.parse_args(argv)
    runs = []
    with tempfile.TemporaryDirectory(prefix="wideprint-banding-") as d:
        for machine in args.machines.split(","):
            for passes in (int(p) for p in args.passes.split(",")):
                for seed in (int(s) for s in args.seeds.split(",")):
                    for mask in args.masks.split(","):
                        r = run(machine, passes, mask, seed, d, args.bidir)
                        runs.append(r)
                        print(f"{machine:8} {passes} pass {mask:9} seed {seed}: banding "
                              f"{r['banding']:.3f} (worst {r['banding_max']:.3f}) grain "
                              f"{r['graininess']:.3f} mottle {r['mottle']:.3f}  {r['seconds']:.1f} s",
                              flush=True)
    modes: dict[str, dict] = {}
    for r in runs:
        m = modes.setdefault(f"{r['machine']} {r['passes']} pass{' bidir' if r['bidir'] else ''}", {})
        m.setdefault(r["mask"], []).append(r)
    table = {mode: {mask: {k: round(sum(r[k] for r in rs) / len(rs), 4)
                           for k in ("banding", "banding_max", "graininess", "mottle")}
                    for mask, rs in masks.items()} for mode, masks in modes.items()}
    for mode, masks in table.items():
        print(mode + ": " + ", ".join(f"{mask} {v['banding']:.3f}" for mask, v in masks.items()))
    if args.out:
        Path(args.out).write_text(json.dumps(dict(
            what="banding chart, 300 dpi, 600 dpi scan, eye at 500 mm (docs/quality.md)",
            machine=platform.machine(), python=sys.version.split()[0], modes=table, runs=runs),
            indent=1) + "\n")
    return 0


if __name__ == "__main__":
    sys.exit(main())
