"""The printed media: where drops landed, on the job's image raster (docs/formats.md).

Each dot counts the drops that landed on it (0 none, 1 one, 2 a doubled dot), so a media
file equal to the RIP's planes proves no dot was lost, moved or printed twice.  Rows are
held in a rolling window and streamed to the TIFF once the paper has carried them past
the heads: memory is bounded by the swath, not by the job's length.
"""

from __future__ import annotations

import numpy as np
from numba import njit

from ..rip.planes import PlanesWriter


@njit(cache=True, nogil=True)
def _land_words(win, base, height, width, words, cols, nozzle_rows, nozzle_dcols, channel):
    """Scatter the drops of packed fire words: bit z of fire f lands at
    (nozzle_rows[z], cols[f] + nozzle_dcols[z]).  Returns (landed, stray, late)."""
    landed = stray = late = 0
    nwin = win.shape[0]
    for f in range(words.shape[0]):
        for w in range(8):
            v = words[f, w]
            if v == 0:
                continue
            for b in range(16):
                if v & (1 << b):
                    r = nozzle_rows[w * 16 + b]
                    c = cols[f] + nozzle_dcols[w * 16 + b]
                    if r < 0 or r >= height or c < 0 or c >= width:
                        stray += 1
                    elif r < base:
                        late += 1
                    elif r - base < nwin:
                        win[r - base, c, channel] += 1
                        landed += 1
    return landed, stray, late


class Media:
    def __init__(self, width: int, height: int, dpi_x: float, dpi_y: float, window_rows: int,
                 path: str | None = None):
        self.width, self.height = width, height
        self.path = path
        self._writer = PlanesWriter(path, width, height, dpi_x, dpi_y,
                                    description="wideprint emulator media") if path else None
        self._win = np.zeros((max(window_rows, 1), width, 4), np.uint8)
        self._base = 0                       # image row of window row 0
        self.drops = np.zeros(4, np.int64)   # drops that landed in the image area
        self.stray = 0                       # drops outside the image area
        self.late = 0                        # drops on rows already written out (paper went back)
        self.closed = False

    def land_words(self, channel: int, words: np.ndarray, cols: np.ndarray,
                   nozzle_rows: np.ndarray, nozzle_dcols: np.ndarray | None = None) -> None:
        """Drops of one head: words (fires, 8) uint16, the media column of each fire, the
        media row of each of the 128 nozzles (docs/protocol.md 4.3 bit order) and each
        nozzle's column offset from its fire's column (misdirection; default none)."""
        if words.size == 0:
            return
        top = int(nozzle_rows.max())
        if top >= self._base + self._win.shape[0]:
            self.flush_below(top - self._win.shape[0] + 1)
        landed, stray, late = _land_words(self._win, self._base, self.height, self.width,
                                          np.ascontiguousarray(words), cols.astype(np.int64),
                                          nozzle_rows.astype(np.int64),
                                          np.zeros(nozzle_rows.size, np.int64)
                                          if nozzle_dcols is None else nozzle_dcols.astype(np.int64),
                                          channel)
        self.drops[channel] += landed
        self.stray += stray
        self.late += late

    def snapshot(self, step: int = 1) -> tuple[int, np.ndarray]:
        """(first image row, copy of the rows still under or near the heads), every
        `step`-th row and column: a live view paints this over what it already has, since
        rows before it never change again."""
        first = -(-self._base // step) * step
        return first, self._win[first - self._base::step, ::step].copy()

    def flush_below(self, row: int) -> None:
        """Rows < row can receive no more drops: write them out."""
        row = min(row, self.height)
        n = row - self._base
        if n <= 0:
            return
        win = self._win
        n_win = min(n, win.shape[0])
        if self._writer:
            self._writer.write(win[:n_win])       # taken at once (rip/planes.py)
            blank = np.zeros((min(n - n_win, win.shape[0]), self.width, 4), np.uint8)
            for r in range(n_win, n, blank.shape[0] or 1):      # rows past the window: empty
                self._writer.write(blank[:min(blank.shape[0], n - r)])
        # the rows left move up in place, a block of n_win rows at a time (blocks that do
        # not overlap: no temporary copy of the window, which is the job's width x a swath)
        for r in range(0, win.shape[0] - n_win, n_win):
            m = min(n_win, win.shape[0] - n_win - r)
            win[r:r + m] = win[r + n_win:r + n_win + m]
        win[-n_win:] = 0
        self._base = row

    def close(self) -> None:
        if self.closed:
            return
        self.flush_below(self.height)
        if self._writer:
            self._writer.close()
        self.closed = True
