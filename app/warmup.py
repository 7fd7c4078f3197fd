"""Run every kernel once on numba's JIT, filling its on-disk cache (app/aot.py runs it
before compiling the kernels ahead of time; docs/rip.md "Compiled kernels").

A kernel the ahead-of-time build does not cover runs on numba's JIT (`cache=True`: compiled
once, then loaded from the cache beside its module); with the cache filled here, such a
kernel's first call after set-up loads instead of compiling.
Every kernel is reached by ripping and printing a small generated image on the in-process
emulator with every halftone method, pass count and pass mask, 8 and 16 bits, RGB and CMYK.

    python -m wideprint.app.warmup
"""

from __future__ import annotations

import sys
import tempfile
import time
from pathlib import Path


def warm(verbose: bool = True) -> float:
    import numpy as np
    import tifffile

    from ..driver.job import PrintJob
    from ..rip.pipeline import RipJob
    from ..rip.profile import load_profile
    from ..rip.settings import METHODS, PASS_MASKS, Placement, RipSettings
    from .devices import close_device, open_device

    t0 = time.monotonic()
    profile = load_profile()
    rng = np.random.default_rng(0)
    with tempfile.TemporaryDirectory(prefix="wideprint-warmup-") as d:
        rgb = Path(d) / "rgb.tif"
        tifffile.imwrite(rgb, rng.integers(0, 256, (48, 64, 3), dtype=np.uint8))
        cmyk16 = Path(d) / "cmyk16.tif"
        tifffile.imwrite(cmyk16, rng.integers(0, 65536, (48, 64, 4), dtype=np.uint16),
                         photometric="separated")
        runs = [(rgb, m, 1, "checker") for m in METHODS]
        runs += [(rgb, "fs", n, mask) for n in (2, 4) for mask in PASS_MASKS]
        runs += [(cmyk16, "bayer", 2, "checker")]
        for path, method, passes, mask in runs:
            settings = RipSettings(dither=method, passes=passes, pass_mask=mask, bidir=passes > 1,
                                   placement=Placement(size="pixels"))
            dev = open_device("emulator", profile, media_path=str(Path(d) / "m.tif"))
            try:
                PrintJob(dev, RipJob(str(path), settings, profile)).run()
            finally:
                close_device(dev)
    took = time.monotonic() - t0
    if verbose:
        print(f"wideprint: numba kernels compiled and cached in {took:.1f} s")
    return took


if __name__ == "__main__":
    warm()
    sys.exit(0)
