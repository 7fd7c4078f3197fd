"""The pictures of docs/media.md: the default media's profiling chart as measured
(docs/media-chart.png, from resources/media/vinyl-300/profiling.ti3) and a verify report
with and without an injected drift (docs/media-verify.png, docs/media-verify-drift.png).

    .venv/bin/python tools/media_pictures.py
"""

from __future__ import annotations

import sys
from pathlib import Path

import numpy as np

ROOT = Path(__file__).resolve().parent.parent


def main() -> int:
    import cv2
    from wideprint.app import argyll, mediacal, medialib
    from wideprint.rip.profile import load_profile
    m = medialib.load(medialib.SHIPPED / medialib.DEFAULT_MEDIA, shipped=True)
    t = argyll.read_cgats(m.folder / "profiling.ti3")
    lab = t.columns("LAB_L", "LAB_A", "LAB_B")
    rgb = mediacal.lab_to_srgb8(lab)
    cell, across = 16, mediacal.ACROSS
    down = -(-len(rgb) // across)
    img = np.full((down * cell, across * cell, 3), 255, np.uint8)
    for i, c in enumerate(rgb):
        r, k = divmod(i, across)
        img[r * cell:(r + 1) * cell - 1, k * cell:(k + 1) * cell - 1] = c
    cv2.imwrite(str(ROOT / "docs" / "media-chart.png"), cv2.cvtColor(img, cv2.COLOR_RGB2BGR))
    profile = load_profile()
    for name, inject in (("media-verify.png", ()), ("media-verify-drift.png", ("dot-gain=+8%",))):
        kept: dict = {}
        r = mediacal.verify(m, profile, inject=inject, keep=kept)
        mediacal.verify_picture(kept, ROOT / "docs" / name)
        print(name, r["mean"], r["p95"], r["max"], "pass" if r["pass"] else "FAIL")
    return 0


if __name__ == "__main__":
    sys.exit(main())
