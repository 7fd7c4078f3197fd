"""Banding, graininess and mottle of the banding chart on the emulated machines, per pass
mask and pass count (issue 36; docs/quality.md; results in bench/results/banding*.json).

    .venv/bin/python bench/banding_bench.py [--machines typical,tired] [--passes 1,2,4]
        [--masks checker,feather] [--out bench/results/banding.json] [--seeds 1,2]

A machine is a named one (perfect, typical, tired: docs/physical.md "The machine") or
kinds of error by themselves joined by '+' (`feed-noise=8um`).  One pass has no mask
to choose: it runs the checkerboard only.

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

from wideprint.app.cli import main as wideprint
from wideprint.app.quality import measure_scan
from wideprint.rip.settings import PASS_MASKS

SCAN_DPI = 600
DPI = 300
WIDTH_MM = 100


def run(machine: str, passes: int, mask: str, seed: int, workdir: str, bidir: bool = False) -> dict:
    scan = os.path.join(workdir, f"{machine}-{passes}-{mask}-{seed}.tif")
    argv = ["test-print", "banding-scan", "--dpi", str(DPI), "--passes", str(passes),
            "--pass-mask", mask, "--scan-out", scan, "--scan-dpi", str(SCAN_DPI),
            "--width-mm", str(WIDTH_MM), "--inject", f"seed={seed}"] + (["--bidir"] if bidir else [])
    # a named machine, or kinds of error by themselves: feed-noise=8um+volume-spread=3%
    for item in (machine.split("+") if "=" in machine else [f"machine={machine}"]):
        argv += ["--inject", item]
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
    ap.add_argument("--merge", nargs="+", metavar="JSON",
                    help="no runs: the runs of these result files, tabled together into --out")
    args = ap.parse_args(argv)
    runs: list[dict] = []
    if args.merge:
        for path in args.merge:
            runs += json.loads(Path(path).read_text())["runs"]
        return summarise(runs, args.out)
    with tempfile.TemporaryDirectory(prefix="wideprint-banding-") as d:
        for machine in args.machines.split(","):
            for passes in (int(p) for p in args.passes.split(",")):
                for seed in (int(s) for s in args.seeds.split(",")):
                    for mask in (args.masks.split(",") if passes > 1 else ["checker"]):
                        r = run(machine, passes, mask, seed, d, args.bidir)
                        runs.append(r)
                        if args.out:            # as it goes: a long bench keeps what it ran
                            Path(args.out).write_text(json.dumps(dict(runs=runs), indent=1) + "\n")
                        print(f"{machine:8} {passes} pass {mask:9} seed {seed}: banding "
                              f"{r['banding']:.3f} (worst {r['banding_max']:.3f}) grain "
                              f"{r['graininess']:.3f} mottle {r['mottle']:.3f}  {r['seconds']:.1f} s",
                              flush=True)
    return summarise(runs, args.out)


def summarise(runs: list[dict], out: str | None) -> int:
    """Per mode (machine, passes, direction) and mask: the mean of the runs' figures."""
    modes: dict[str, dict] = {}
    for r in runs:
        m = modes.setdefault(f"{r['machine']} {r['passes']} pass{' bidir' if r['bidir'] else ''}", {})
        m.setdefault(r["mask"], []).append(r)
    table = {mode: {mask: {k: round(sum(r[k] for r in rs) / len(rs), 4)
                           for k in ("banding", "banding_max", "graininess", "mottle")}
                    for mask, rs in masks.items()} for mode, masks in modes.items()}
    for masks in table.values():           # against today's default mask in the same mode
        if "checker" in masks and masks["checker"]["banding"] > 0:
            for v in masks.values():
                v["banding_vs_checker"] = round(v["banding"] / masks["checker"]["banding"], 3)
    for mode, masks in table.items():
        print(mode + ": " + ", ".join(f"{mask} {v['banding']:.3f}" for mask, v in masks.items()))
    if out:
        Path(out).write_text(json.dumps(dict(
            what="banding chart, 300 dpi, 600 dpi scan, eye at 500 mm (docs/quality.md)",
            machine=platform.machine(), python=sys.version.split()[0], modes=table, runs=runs),
            indent=1) + "\n")
    return 0


if __name__ == "__main__":
    sys.exit(main())
