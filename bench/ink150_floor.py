"""Why 150 dpi needs more ink than 300 dpi for the same colour (docs/media.md "Every dpi
mode the same colour"): the same 27 C/M/Y mixes printed with the same ink per m² at 300 dpi
(drop budget 0.5) and at 150 dpi with every halftone, measured by the emulator's
spectrophotometer; and the share of drops that land on a cell another ink already took,
from the RIP's own planes.  Writes bench/results/ink150_floor.json.

    .venv/bin/python bench/ink150_floor.py
"""

from __future__ import annotations

import itertools
import json
import sys
import tempfile
from dataclasses import replace
from pathlib import Path

import numpy as np

HERE = Path(__file__).resolve().parent
CASES = ((300, "vced", 0.5), (150, "vced", 1.0), (150, "vector", 1.0), (150, "fs", 1.0),
         (150, "bluenoise", 1.0))


def stacked_share(profile, dpi: int, dither: str, value, tmp: Path) -> float:
    """Of all drops of a flat C/M/Y patch, the share on a cell that holds another ink too."""
    import tifffile
    from wideprint.rip.pipeline import RipJob
    from wideprint.rip.planes import read_planes
    from wideprint.rip.settings import Placement, RipSettings
    src = tmp / "flat.tif"
    tifffile.imwrite(src, np.full((200, 200, 4), value, np.uint8), photometric="separated")
    job = RipJob(str(src), RipSettings(dpi=dpi, dither=dither,
                                       placement=Placement(size="pixels")), profile)
    job.write_planes(str(tmp / "p.tif"))
    job.close()
    p = read_planes(tmp / "p.tif") > 0
    per_cell = p.sum(axis=2)
    drops = p.sum()
    return float((p & (per_cell[..., None] > 1)).sum() / max(drops, 1))


def main() -> int:
    from wideprint.app.mediacal import Printer
    from wideprint.device_sim.spectral import delta_e2000
    from wideprint.rip.profile import load_profile
    prof = load_profile(None)
    vals = np.array([[c, m, y, 0] for c, m, y in itertools.product((0, 90, 180), repeat=3)],
                    np.uint8)
    res, out = {}, {"chart": "27 C/M/Y mixes of 0, 35 %, 71 %", "cases": []}
    with tempfile.TemporaryDirectory() as t:
        tmp = Path(t)
        for dpi, dither, budget in CASES:
            col = replace(prof.color, drop_budget={**prof.color.drop_budget, dpi: budget})
            p2 = replace(prof, color=col)
            pr = Printer(p2, dpi=dpi, dither=dither)
            lab = pr.measure(vals, p2)
            res[(dpi, dither)] = lab
            stacked = stacked_share(p2, dpi, dither, (180, 180, 180, 0), tmp)
            out["cases"].append(dict(dpi=dpi, dither=dither, drop_budget=budget,
                                     ink_ml_m2=round(float(sum(pr.last_ink_ml_m2 or [])), 4),
                                     L_mean=round(float(lab[:, 0].mean()), 2),
                                     stacked_share_71pct_cmy=round(stacked, 3)))
    ref = res[(300, "vced")]
    for case in out["cases"]:
        de = delta_e2000(res[(case["dpi"], case["dither"])], ref)
        case.update(de2000_vs_300_mean=round(float(de.mean()), 2),
                    de2000_vs_300_max=round(float(de.max()), 2))
        print(case)
    path = HERE / "results" / "ink150_floor.json"
    path.write_text(json.dumps(out, indent=2) + "\n")
    print(f"written {path}")
    return 0


if __name__ == "__main__":
    sys.exit(main())
