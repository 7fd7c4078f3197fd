"""Ink amounts to coverages (docs/physical.md "Ink limit"), for both instruments that
render the print - the scanner (scanner.py) and the spectrophotometer (spectro.py).  A
module of its own so that neither instrument imports the other (tests/test_layers.py: no
import circles inside a package)."""

from __future__ import annotations

import cv2
import numpy as np

from ..rip.compiled import kernel
from .spectral import SpectralMedia


@kernel()
def _coverage(amounts, unit, cov, volume):
    """cov = min(1, amounts), volume = the amounts' sum x unit; returns the largest volume."""
    top = np.float32(0.0)
    for r in range(amounts.shape[0]):
        for c in range(amounts.shape[1]):
            v = np.float32(0.0)
            for i in range(4):
                a = amounts[r, c, i]
                v += a
                cov[r, c, i] = a if a < 1.0 else 1.0
            v *= unit
            volume[r, c] = v
            if v > top:
                top = v
    return top


def coverage_rows(amounts: np.ndarray, media: SpectralMedia, unit_ml_m2: float,
                  bleed_px: float) -> np.ndarray:
    """Ink amounts (rows, cols, 4: discs summed) -> coverages (docs/physical.md "Ink
    limit"): each ink's coverage is min(1, amount); where the ink volume, smoothed over
    the bleed reach, is beyond what the media takes, the wet ink coalesces: every ink's
    coverage shrinks by limit / volume (the ink pools, the colour gets no darker)."""
    cov = np.empty_like(amounts)
    volume = np.empty(amounts.shape[:2], np.float32)
    limit = np.float32(media.ink_limit_ml_m2)
    if _coverage(amounts, np.float32(unit_ml_m2), cov, volume) <= limit:
        return cov                             # (smoothing never raises the maximum)
    if bleed_px > 0:
        volume = cv2.GaussianBlur(volume, (0, 0), bleed_px, borderType=cv2.BORDER_REPLICATE)
    scale = np.minimum(np.float32(1.0), limit / np.maximum(volume, np.float32(1e-6)))
    cov *= scale[:, :, None]
    return cov
