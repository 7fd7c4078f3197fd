"""Test images on the device grid: random 0/1 planes, a CMYK TIFF of them that prints 1 pixel =
1 dot, and reading an image source's bands back.  The tests compare the media the emulator
prints with these planes bit for bit."""

from __future__ import annotations

import io
from functools import lru_cache
from pathlib import Path

import numpy as np
import tifffile

from wideprint.rip.place import Placement

#: the repository root (the wideprint package)
ROOT = Path(__file__).resolve().parent.parent.parent

#: 1 image pixel = 1 device dot: the placement for tests that compare the media with the
#: planes they wrote (a physical-size placement resamples them)
PX = Placement(size="pixels")

#: the default profile's device grid at 300 dpi: 300 columns and 25400 / 68.55 rows per inch
DEVICE_PPI = (300.0, 25400 / 68.55)


def write_cmyk_tiff(path, planes01: np.ndarray) -> Path:
    """A CMYK TIFF whose channels hold only 0 and 255, from 0/1 planes (h, w, 4), tagged
    with the 300 dpi device grid's resolution, so that even a physical-size placement
    prints it 1 pixel = 1 dot."""
    tifffile.imwrite(path, (planes01 * 255).astype(np.uint8), photometric="separated",
                     resolution=DEVICE_PPI, resolutionunit="INCH")
    return Path(path)


def random_planes(h: int, w: int, density: float = 0.3, seed: int = 0) -> np.ndarray:
    rng = np.random.default_rng(seed)
    return (rng.random((h, w, 4)) < density).astype(np.uint8)


@lru_cache(maxsize=None)
def tiny_tiff() -> bytes:
    """An 8 x 16 CMYK TIFF's bytes (random dots, seed 5): the smallest job a server prints."""
    buf = io.BytesIO()
    tifffile.imwrite(buf, (random_planes(8, 16, seed=5) * 255).astype(np.uint8),
                     photometric="separated")
    return buf.getvalue()


def read_bands(src, rows: int = 37) -> np.ndarray:
    """All of an image source's bands, checking their heights, shape and dtype."""
    parts = list(src.bands(rows))
    for p in parts[:-1]:
        assert p.shape[0] == rows
    arr = np.concatenate(parts, axis=0)
    assert arr.shape == (src.height, src.width, src.channels)
    assert arr.dtype == (np.uint16 if src.depth == 16 else np.uint8)
    return arr
