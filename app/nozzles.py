"""Every nozzle's landing error along the feed and drop volume, measured on a scan of the
nozzle check (`wideprint calibrate nozzles`, docs/calibration.md "nozzles", docs/quality.md
"Nozzle-error hiding as a setting"): what `--pass-mask hiding` plans with
(rip/hiding.py).

A dash's centroid is read through the frame bars' registration in a window 4 rows high each
side (the next dash of its staircase step is 16 rows away: a crooked nozzle's dash stays
whole); its landing error is the centroid's y less its cells'. Its ink (summed darkness
over that window) over its colour's median is the dot's area, volume^(2/3), so the volume is
that ratio to the power 3/2. A dead nozzle (calibrate nozzles' own test: under
`DEAD_FRACTION` of its head's median) is stored as error 0 and volume -100 %: no drop.
"""

from __future__ import annotations

from typing import TYPE_CHECKING

import numpy as np

if TYPE_CHECKING:
    from .calibrate import Scan

WINDOW_ROWS = 4           # rows of the dash's window each side (the staircase: 16 apart)
#: the coarsest scan the errors are measured on: at 1200 dpi (21 µm pixels) the typical
#: machine's errors come back within 0.26 µm and 0.55 %; at 600 dpi a row (68.55 µm) is
#: 1.6 pixels and the dash's centroid is the scanner's blur and pixel phase (docs/quality.md)
MIN_SCAN_DPI = 1200.0


def measure_nozzle_errors(scan: Scan, dead: set[tuple[str, int]] | frozenset = frozenset()
                          ) -> tuple[np.ndarray, np.ndarray]:
    """(landing error along the feed µm, drop volume relative to the colour's median) per
    (head index, nozzle); nozzles with no dash (0 and 127) and `dead` ones (head name,
    nozzle): error 0, volume 0."""
    prof = scan.profile
    shape = (len(prof.heads), prof.nozzles)
    dy, ink = np.zeros(shape), np.full(shape, np.nan)
    index = {h.name: h.index for h in prof.heads}
    for m in scan.layout.marks:
        wgt, _mx, my = scan.window(m, 0.0, WINDOW_ROWS * scan.row_um, scan.band(m.channel))
        total = float(wgt.sum()) if wgt.size else 0.0
        if total > 0 and (m.head, m.nozzle) not in dead:
            dy[index[m.head], m.nozzle] = (wgt * my).sum() / total - scan.model_centroid(m)[1]
            ink[index[m.head], m.nozzle] = total
    volume = np.zeros(shape)
    for ch in range(4):
        heads = [h.index for h in prof.heads if h.channel == ch]
        med = np.nanmedian(ink[heads])
        volume[heads] = np.nan_to_num((ink[heads] / med) ** 1.5, nan=0.0)
    return dy, volume


def summary(dy: np.ndarray, volume: np.ndarray) -> dict:
    """The spreads of the live nozzles' errors (µm, %), for the report."""
    live = volume > 0
    return dict(dy_spread_um=round(float(dy[live].std()), 2),
                volume_spread_pct=round(float(volume[live].std()) * 100, 2),
                nozzles=int(live.sum()))
