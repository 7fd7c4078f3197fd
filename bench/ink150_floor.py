"""Why 150 dpi needs more ink than 300 dpi for the same colour (docs/media.md "Every dpi
mode the same colour"): the same 27 C/M/Y mixes printed with the same ink per m² at 300 dpi
(drop budget 0.5) and at 150 dpi with every halftone (`joint`: C, M and Y decided together,
rip/joint.py), measured by the emulator's spectrophotometer; and how the drops stack, from the
RIP's own planes: the share on a cell that holds another ink too, and the share that land on a
cell another drop already took, against its floor.  Writes bench/results/ink150_floor.json.

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
         (150, "bluenoise", 1.0), (150, "joint", 1.0))


def stacked_share(profile, dpi: int, dither: str, value, tmp: Path) -> tuple[float, float, float]:
    """Of all drops of a flat C/M/Y patch: the share on a cell that holds another ink too;
    the share that land on a cell another drop already took (1 - taken cells / drops: its
    floor is max(0, 1 - 1/s) at Σ coverage s of a cell, where every cell is taken and only
    the rest stacks); and the share of cells whose drops are neither floor(s) nor ceil(s)
    (a cell of three beside a cell of one: stacked more than the coverage forces)."""
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
    mean = per_cell.mean()
    uneven = (per_cell < np.floor(mean - 0.01)) | (per_cell > np.ceil(mean + 0.01))
    return (float((p & (per_cell[..., None] > 1)).sum() / max(drops, 1)),
            float(1 - (per_cell > 0).sum() / max(drops, 1)), float(uneven.mean()))


WEDGE = (0, 30, 60, 90, 120, 150, 180, 210, 240, 255)


def single_ink_floor(Printer, prof) -> dict:
    """Each ink alone (nothing to stack on): the ink 150 dpi needs for the ΔE from paper
    (CIE76) that 300 dpi at budget 0.5 prints at each step, over that step's ink (x1.00:
    the same ink), per halftone; None where 150 dpi's solid does not reach it."""
    vals = np.zeros((4 * len(WEDGE), 4), np.uint8)
    for k in range(4):
        vals[k * len(WEDGE):(k + 1) * len(WEDGE), k] = WEDGE
    lab = {}
    for dpi, dither, budget in ((300, "vced", 0.5), (150, "vced", 1.0), (150, "joint", 1.0)):
        col = replace(prof.color, drop_budget={**prof.color.drop_budget, dpi: budget})
        p2 = replace(prof, color=col)
        lab[(dpi, dither)] = Printer(p2, dpi=dpi, dither=dither).measure(vals, p2)
    out: dict = {"steps": list(WEDGE[1:])}
    for dither in ("vced", "joint"):
        out[dither] = {}
        for k, ink in enumerate("CMYK"):
            part = slice(k * len(WEDGE), (k + 1) * len(WEDGE))
            a, b = lab[(300, "vced")][part], lab[(150, dither)][part]
            e300 = np.linalg.norm(a - a[0], axis=1)
            e150 = np.linalg.norm(b - b[0], axis=1)
            need = np.interp(e300, e150, np.asarray(WEDGE, float), right=np.nan)
            out[dither][ink] = [None if np.isnan(r) else round(float(r), 3)
                                for r in need[1:] / np.asarray(WEDGE[1:])]
            out[dither][f"{ink}_solid_de_from_paper_150_300"] = [round(float(e150[-1]), 1),
                                                                 round(float(e300[-1]), 1)]
    return out


def main() -> int:
    from wideprint.app.mediacal import Printer
    from wideprint.device_sim.spectral import delta_e2000
    from wideprint.rip.profile import load_profile
    prof = load_profile(None)
    vals = np.array([[c, m, y, 0] for c, m, y in itertools.product((0, 90, 180), repeat=3)],
                    np.uint8)

    def floor(level: float) -> float:        # Σ coverage s = 3 level / 255 of a cell
        return round(max(0.0, 1 - 255 / (3 * level)), 3)

    res, out = {}, {"chart": "27 C/M/Y mixes of 0, 35 %, 71 %", "cases": [],
                    "on_taken_cell_floor": {"150dpi_35pct_cmy": floor(90), "150dpi_71pct_cmy": floor(180),
                                            "300dpi_budget_0.5_35pct_cmy": floor(45),
                                            "300dpi_budget_0.5_71pct_cmy": floor(90)}}
    with tempfile.TemporaryDirectory() as t:
        tmp = Path(t)
        for dpi, dither, budget in CASES:
            col = replace(prof.color, drop_budget={**prof.color.drop_budget, dpi: budget})
            p2 = replace(prof, color=col)
            pr = Printer(p2, dpi=dpi, dither=dither)
            lab = pr.measure(vals, p2)
            res[(dpi, dither)] = lab
            stacked, excess, uneven = stacked_share(p2, dpi, dither, (180, 180, 180, 0), tmp)
            _, light_excess, light_uneven = stacked_share(p2, dpi, dither, (90, 90, 90, 0), tmp)
            out["cases"].append(dict(dpi=dpi, dither=dither, drop_budget=budget,
                                     ink_ml_m2=round(float(sum(pr.last_ink_ml_m2 or [])), 4),
                                     L_mean=round(float(lab[:, 0].mean()), 2),
                                     stacked_share_71pct_cmy=round(stacked, 3),
                                     on_taken_cell_71pct_cmy=round(excess, 3),
                                     on_taken_cell_35pct_cmy=round(light_excess, 3),
                                     uneven_cells_71pct_cmy=round(uneven, 3),
                                     uneven_cells_35pct_cmy=round(light_uneven, 3)))
    out["single_ink_150_over_300"] = single_ink_floor(Printer, prof)
    print("each ink alone, 150 dpi's ink over 300 dpi's for the same ΔE from paper:",
          out["single_ink_150_over_300"])
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
