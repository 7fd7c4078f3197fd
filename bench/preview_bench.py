"""`print --preview` memory: peak RSS of whole `wideprint print` commands on a 0.25 m2 print
(50 x 50 cm RGB at 300 dpi, the in-process emulator) with and without `--preview`, as the
command's own rusage (bench/rip_bench.py's launcher).  Results to bench/results/preview.json,
one entry per --label (e.g. a checkout before and after a change).

    .venv/bin/python bench/preview_bench.py                               # this checkout
    .venv/bin/python bench/preview_bench.py --pythonpath DIR --label before  # DIR/wideprint

Target (issue 32): the preview within ~50 MB of the print without it."""

from __future__ import annotations

import argparse
import json
import os
import statistics
import sys
import tempfile
import time
from pathlib import Path

import numpy as np
import tifffile

HERE = Path(__file__).resolve().parent
sys.path.insert(0, str(HERE))
from rip_bench import cli_env, cpu_model, run_measured  # noqa: E402


def image(path: str, side: int) -> None:
    y, x = np.mgrid[0:side, 0:side]
    img = np.empty((side, side, 3), np.uint8)
    img[..., 0] = x * 255 // side
    img[..., 1] = y * 255 // side
    img[..., 2] = (x + y) % 256
    tifffile.imwrite(path, img, resolution=(300, 300), resolutionunit="INCH", compression="deflate")


def main() -> int:
    ap = argparse.ArgumentParser(description=__doc__.split("\n\n")[0])
    ap.add_argument("--side-mm", type=float, default=500.0)
    ap.add_argument("--repeat", type=int, default=3)
    ap.add_argument("--pythonpath", help="a folder holding the `wideprint` package to measure")
    ap.add_argument("--label", default="this checkout")
    ap.add_argument("--out", default=str(HERE / "results" / "preview.json"))
    args = ap.parse_args()
    env = cli_env()
    if args.pythonpath:
        env["PYTHONPATH"] = args.pythonpath
    side = round(args.side_mm / 25.4 * 300)
    rows = {}
    with tempfile.TemporaryDirectory(prefix="wideprint-preview-") as d:
        src = os.path.join(d, "quarter.tif")
        image(src, side)
        runs: dict[str, list] = {"print": [], "print --preview": []}
        for i in range(args.repeat):
            for name in (runs if i % 2 == 0 else list(runs)[::-1]):
                extra = ["--preview", os.path.join(d, "p.png")] if "preview" in name else []
                r = run_measured([sys.executable, "-m", "wideprint.app.cli", "print", *extra, src],
                                 env=env)
                if not r.ok:
                    print(r.err, file=sys.stderr)
                    return 1
                runs[name].append(r)
        for name, rs in runs.items():
            rows[name] = dict(rss_mb_max=round(max(r.rss_mb for r in rs), 1),
                              rss_mb=[round(r.rss_mb, 1) for r in rs],
                              wall_s_median=round(statistics.median(r.wall for r in rs), 2))
    added = rows["print --preview"]["rss_mb_max"] - rows["print"]["rss_mb_max"]
    for name, row in rows.items():
        print(f"{args.label:14} {name:18} peak RSS {row['rss_mb_max']:6.1f} MB  "
              f"wall {row['wall_s_median']:5.2f} s")
    print(f"{args.label:14} the preview adds {added:.1f} MB (target <= ~50 MB)")
    out = Path(args.out)
    doc = json.loads(out.read_text()) if out.exists() else dict(
        bench="preview_bench.py", machine=dict(cpu=cpu_model(), cores=os.cpu_count()),
        image=f"{side} x {side} RGB at 300 dpi ({args.side_mm:g} mm square, "
              f"{(args.side_mm / 1000) ** 2:g} m2), print on the in-process emulator",
        entries={})
    doc["entries"][args.label] = dict(date=time.strftime("%Y-%m-%d %H:%M"), repeat=args.repeat,
                                      added_mb=round(added, 1), **rows)
    out.parent.mkdir(parents=True, exist_ok=True)
    out.write_text(json.dumps(doc, indent=1) + "\n")
    print(f"-> {out}")
    return 0


if __name__ == "__main__":
    sys.exit(main())
