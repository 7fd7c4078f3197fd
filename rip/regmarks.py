"""Registration marks a contour cutter finds (docs/cut.md, "Registration marks").

Camera and sensor cutters (Summa OPOS, Graphtec ARMS, the vinyl cutters of every sign
shop) read black squares printed around the graphic: one at each corner, and along both
long sides every `spacing_mm` for a long print, so that the cutter measures the print's
scale, rotation and the feed's error section by section along a banner and bends the cut
path onto the print.  This module is the layout's geometry only (device dots of the sheet,
rounded to the grid); rip/layout.py draws the squares in K as part of a slot's frame, and
rip/cut.py writes their centres into the cut file in the same millimetres as the path.
"""

from __future__ import annotations

import math
from dataclasses import dataclass
from typing import Callable

#: the defaults (docs/cut.md): OPOS' standard 3 mm mark, 3 mm clear of the graphic,
#: a pair every 500 mm along the length at most
MARK_MM = 3.0
OFFSET_MM = 3.0
SPACING_MM = 500.0


@dataclass(frozen=True)
class MarkLayout:
    """Where the marks go around one graphic (docs/cut.md): squares of `size_mm`, their
    inner edges `offset_mm` clear of the graphic's box, pairs (left and right) at most
    `spacing_mm` apart along the feed, the first and last pair at the corners."""
    size_mm: float = MARK_MM
    offset_mm: float = OFFSET_MM
    spacing_mm: float = SPACING_MM

    def __post_init__(self) -> None:
        for name in ("size_mm", "offset_mm", "spacing_mm"):
            v = getattr(self, name)
            if not (math.isfinite(v) and v > 0):
                raise ValueError(f"registration marks: {name} must be a positive number, not {v!r}")
        if self.spacing_mm < 4 * self.size_mm:
            raise ValueError(f"registration marks: spacing {self.spacing_mm:g} mm is less than four "
                             f"marks ({4 * self.size_mm:g} mm)")

    def frame(self, cols: Callable[[float], int], rows: Callable[[float], int]) -> tuple[int, int]:
        """The frame (columns left and right, rows above and below) the marks need."""
        return cols(self.offset_mm) + cols(self.size_mm), rows(self.offset_mm) + rows(self.size_mm)

    def rects(self, x: int, y: int, w: int, h: int, cols: Callable[[float], int],
              rows: Callable[[float], int]) -> list[tuple[int, int, int, int, str]]:
        """The marks around the graphic at (x, y), w x h dots: (x, y, w, h, place) in dots,
        place 'L<i>' or 'R<i>' (left or right side, pair i from the top)."""
        sw, sh = cols(self.size_mm), rows(self.size_mm)
        ox, oy = cols(self.offset_mm), rows(self.offset_mm)
        left, right = x - ox - sw, x + w + ox
        top, bottom = y - oy - sh, y + h + oy          # the first and the last pair's top row
        run = bottom - top                              # rows between the first and last pair
        n = max(1, math.ceil(run / max(1, rows(self.spacing_mm))))
        out = []
        for i in range(n + 1):
            yy = top + int(math.floor(run * i / n + 0.5))
            out += [(left, yy, sw, sh, f"L{i}"), (right, yy, sw, sh, f"R{i}")]
        return out


def centres_mm(rects, mm_x: Callable[..., float], mm_y: Callable[..., float]
               ) -> list[tuple[str, float, float]]:
    """Each mark's centre in millimetres of the sheet (the cut file's frame): the middle of
    the dots it is printed with."""
    return [(place, mm_x(x + w / 2), mm_y(y + h / 2)) for x, y, w, h, place in rects]
