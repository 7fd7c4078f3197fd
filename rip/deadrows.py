"""Dead nozzles in one-pass printing (docs/geometry.md, "Dead nozzles with one pass"):
a row that only a dead nozzle prints gives its dots to the rows beside it, as industrial
printers compensate a nozzle out.

With N passes a dead nozzle's dots move to another pass of the weave (rip/swath.py).  With
one pass no other nozzle crosses the row, so the RIP moves the dots itself, on the
halftone, before the planes and the strokes are made (the media of a correct print still
equals the planes): each dot of a dead row goes to the same column of the row above or
below (alternating by column, so neither neighbour takes all), else to the other one,
else diagonally; a dot with no free cell near is lost (in dark tones the neighbours are
full: the deficit is then small against their ink).  Rows where a neighbour is dead too
are refused, with the nozzles named.  Bands stream through with two rows held back, so a
dead row at a band's edge sees both neighbours; memory stays one band.
"""

from __future__ import annotations

from collections.abc import Iterator

import numpy as np
from .compiled import kernel

from .profile import ProfileError


@kernel()
def _give_away(rows: np.ndarray, dead: np.ndarray, first: int, period: int, c: int) -> None:
    """rows (h, W, 4) 0/1 in place; rows[i] is image row first + i; for every row i with
    (first + i) mod period in `dead` and both neighbours inside, its colour c dots move to
    free cells of rows i - 1 / i + 1 (same column, then the column beside)."""
    h, w = rows.shape[0], rows.shape[1]
    is_dead = np.zeros(period, np.bool_)
    for d in dead:
        is_dead[d] = True
    for i in range(1, h - 1):
        if not is_dead[(first + i) % period]:
            continue
        for x in range(w):
            if rows[i, x, c] == 0:
                continue
            rows[i, x, c] = 0
            up = (x + i) & 1
            placed = False
            for step in range(2):
                t = i - 1 if (up ^ step) else i + 1
                if rows[t, x, c] == 0:
                    rows[t, x, c] = 1
                    placed = True
                    break
            if placed:
                continue
            for step in range(4):
                t = i - 1 if step < 2 else i + 1
                xx = x - 1 if (step & 1) == 0 else x + 1
                if 0 <= xx < w and rows[t, xx, c] == 0:
                    rows[t, xx, c] = 1
                    break


def compensate(bands: Iterator[np.ndarray], dead: list[np.ndarray],
               period: int) -> Iterator[np.ndarray]:
    """The halftone bands with the dots of dead rows (per colour, row phases mod `period`)
    given to their neighbours; the same rows come out, two held back until the next band
    (a dead row at a band's edge sees both neighbours).  Blank rows stand above and below
    the image (dots given there are lost: there is no image row to carry them)."""
    held: np.ndarray | None = None
    start = -1                                       # image row of rows[0] (-1: blank above)
    next_row = 0                                     # rows before it are compensated

    def run(rows: np.ndarray, start: int, next_row: int) -> None:
        lo = max(0, next_row - start - 1)
        for c, d in enumerate(dead):
            if d.size:
                _give_away(rows[lo:], d.astype(np.int64), start + lo + period, period, c)

    for band in bands:
        if held is None:
            held = np.zeros((1,) + band.shape[1:], band.dtype)
        rows = np.ascontiguousarray(np.concatenate([held, band]))
        run(rows, start, next_row)
        next_row = start + rows.shape[0] - 1
        keep = min(2, rows.shape[0])
        out = rows[max(0, -start):rows.shape[0] - keep]
        held = rows[rows.shape[0] - keep:].copy()
        start += rows.shape[0] - keep
        if out.shape[0]:
            yield out
    if held is not None:
        rows = np.concatenate([held, np.zeros((1,) + held.shape[1:], held.dtype)])
        run(rows, start, next_row)
        out = rows[max(0, -start):held.shape[0]]
        if out.shape[0]:
            yield out


def check_neighbours(dead: list[np.ndarray], period: int, names) -> None:
    """Refuse rows whose neighbour rows are dead too (nothing near can take their dots)."""
    for c, d in enumerate(dead):
        s = set(int(x) for x in d)
        bad = sorted(x for x in s if (x - 1) % period in s or (x + 1) % period in s)
        if bad:
            raise ProfileError(f"dead nozzles on neighbouring rows of colour {'CMYK'[c]} "
                             f"({', '.join(names(c, x) for x in bad)}): one pass cannot print "
                             f"around them; use 2 or more passes")
