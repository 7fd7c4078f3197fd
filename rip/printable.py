"""`PrintableJob`: what the driver prints, whatever made it - a file ripped (`RipJob`,
rip/pipeline.py), a layout of several (`LayoutJob`, rip/layout.py), a test pattern
(`PatternJob`, rip/testprints.py).  A module of its own so that those import the base and
not one another (tests/test_layers.py: no import circles inside a package)."""

from __future__ import annotations

from pathlib import Path
from typing import Iterator

import numpy as np

from .planes import PlanesWriter
from .profile import Profile
from .settings import RipSettings
from .swath import StrokeData, StrokePlanner, pack_dots, top_margin_rows


class PrintableJob:
    """What the driver prints: an image area of width x height device dots, its halftone
    bands, and the strokes planned from them.  Subclasses give `halftone_bands()` (dots,
    (h, W, 4) 0/1) and may give `packed_bands()` (the same as bits, (h, 4, W/8)) when they
    can make those more cheaply; the planner works on bits."""
    path: str
    settings: RipSettings
    profile: Profile
    width: int
    height: int

    @property
    def dpi_y(self) -> float:
        return 25.4e3 / self.profile.row_um

    def halftone_bands(self) -> Iterator[np.ndarray]:
        raise NotImplementedError

    def packed_bands(self) -> Iterator[np.ndarray]:
        for band in self.halftone_bands():
            yield pack_dots(band)

    def planner(self) -> StrokePlanner:
        s = self.settings
        return StrokePlanner(self.profile, self.width, self.height, s.dpi, s.passes, s.bidir,
                             s.pass_mask, top_rows=top_margin_rows(self.profile, s))

    def strokes(self, planner: StrokePlanner | None = None) -> Iterator[StrokeData]:
        planner = planner or self.planner()
        for bits in self.packed_bands():
            yield from planner.feed_packed(bits)
        yield from planner.finish()

    def packed_native(self) -> bool:
        """Whether `packed_bands()` is the cheaper way to this job's halftone (it is made as
        bits, not dots)."""
        return False

    def write_planes(self, out: str | Path, planes_format: str = "8bit") -> np.ndarray:
        """The halftone the RIP intends, as a planes TIFF (docs/formats.md; `planes_format`
        "8bit" or "packed"); returns dots per colour.  Deflating runs on worker threads
        while this thread makes the next bands."""
        with PlanesWriter(out, self.width, self.height, self.settings.dpi, self.dpi_y,
                          description=f"wideprint planes of {Path(self.path).name}",
                          planes_format=planes_format) as w:
            if self.packed_native():
                for bits in self.packed_bands():
                    w.write_bits(bits)
            else:
                for band in self.halftone_bands():
                    w.write(band)
        return w.dots

    def close(self) -> None:
        pass
