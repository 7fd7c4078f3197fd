"""Layouts on the roll (docs/layout.md): peak RSS and time of the RIP for step-and-repeat
sheets of growing length and a nest of many files, against the same sheet saved as one
TIFF and ripped as a plain job (the peer: what a RIP without layouts would print).

Each job is ``RipJob(...).strokes()`` (file -> every stroke's swath words) in a fresh
process; peak RSS is that process's ``RUSAGE_SELF`` maximum.  Memory must not grow with
the number of copies along the roll or the number of files nested.

    .venv/bin/python bench/layout_bench.py [--px 1000x750] [--dpi 300] [--dither vced]
"""

from __future__ import annotations

import argparse
import json
import os
import subprocess
import sys
import tempfile
import time
from pathlib import Path

ROOT = Path(__file__).resolve().parent.parent

JOB = r"""
import json, resource, sys, time
from wideprint.rip.pipeline import RipJob
from wideprint.rip.profile import load_profile
from wideprint.rip.settings import from_mapping
files, mapping = json.loads(sys.argv[1]), json.loads(sys.argv[2])
profile = load_profile()
t0 = time.perf_counter()
job = RipJob(files[0], from_mapping(mapping, profile), profile, more=tuple(files[1:]))
n = sum(1 for _ in job.strokes())
job.close()
print(json.dumps(dict(s=time.perf_counter() - t0, rss_mb=resource.getrusage(resource.RUSAGE_SELF).ru_maxrss / 1024,
                      w=job.width, h=job.height, strokes=n)))
"""


def run(files, mapping) -> dict:
    env = dict(os.environ, PYTHONPATH=str(ROOT.parent) + os.pathsep + os.environ.get("PYTHONPATH", ""))
    out = subprocess.run([sys.executable, "-c", JOB, json.dumps([str(f) for f in files]),
                          json.dumps(mapping)], capture_output=True, text=True, env=env, check=True)
    return json.loads(out.stdout)


def main() -> int:
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("--px", default="1000x750", help="the image, WxH pixels")
    ap.add_argument("--dpi", type=int, default=300)
    ap.add_argument("--dither", default="vced")
    ap.add_argument("--files", type=int, default=40, help="files in the nest")
    a = ap.parse_args()
    import numpy as np
    import tifffile
    w, h = (int(v) for v in a.px.split("x"))
    base = {"dpi": a.dpi, "dither": a.dither, "placement": {"size": "pixels"}}
    with tempfile.TemporaryDirectory(prefix="wideprint-layout-bench-") as d:
        rng = np.random.default_rng(1)
        img = (rng.random((h, w, 3)) * 255).astype(np.uint8)
        img = np.ascontiguousarray(np.clip(img.astype(np.int16) // 2 + np.linspace(0, 127, w)[None, :, None],
                                           0, 255).astype(np.uint8))
        one = Path(d) / "one.tif"
        tifffile.imwrite(one, img)
        nest = []
        for i in range(a.files):
            p = Path(d) / f"n{i}.tif"
            tifffile.imwrite(p, np.roll(img, i * 37, axis=1)[: h - (i % 5) * h // 10])
            nest.append(p)
        cases = [("single image", [one], {}),
                 ("repeat 4 x 1", [one], {"repeat_across": 4}),
                 ("repeat 4 x 10", [one], {"repeat_across": 4, "repeat_along": 10}),
                 ("repeat 4 x 40", [one], {"repeat_across": 4, "repeat_along": 40}),
                 (f"nest of {a.files} files", nest, {"nest": True, "nest_width_mm": 4.4 * w / a.dpi * 25.4})]
        rows = []
        for name, files, extra in cases:
            m = json.loads(json.dumps(base))
            m["placement"].update(extra)
            rows.append((name, run(files, m)))
            print(f"{name:22s} {rows[-1][1]}", file=sys.stderr)
        # the peer: the 4 x 10 sheet as one TIFF (the layout's own planes as contone), plain job
        from wideprint.rip.settings import from_mapping
        from wideprint.rip.profile import load_profile
        from wideprint.rip.layout import plan_layout
        prof = load_profile()
        m = json.loads(json.dumps(base))
        m["placement"].update(repeat_across=4, repeat_along=10)
        plan = plan_layout([one], from_mapping(m, prof), prof)
        sheet = np.full((plan.height, plan.width, 3), 255, np.uint8)
        for s in plan.slots:
            sheet[s.y:s.y + h, s.x:s.x + w] = img
        big = Path(d) / "sheet.tif"
        tifffile.imwrite(big, sheet, rowsperstrip=16)
        del sheet
        rows.append(("4 x 10 as one TIFF", run([big], base)))
    t0 = rows[2][1]["s"]
    print(f"\n{w} x {h} px RGB, {a.dpi} dpi, {a.dither}; RipJob(...).strokes() in a fresh process\n")
    print("| job | sheet (dots) | strokes | time | Mpx/s | peak RSS |")
    print("|---|---|---|---|---|---|")
    for name, r in rows:
        print(f"| {name} | {r['w']:,} x {r['h']:,} | {r['strokes']} | {r['s']:.1f} s | "
              f"{r['w'] * r['h'] / r['s'] / 1e6:.1f} | {r['rss_mb']:.0f} MB |")
    print(f"\nrepeat 4 x 10 against the same sheet as one TIFF: time {t0 / rows[-1][1]['s']:.2f}x")
    return 0


if __name__ == "__main__":
    sys.exit(main())
