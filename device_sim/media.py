"""The printed media: where drops landed, on the job's image raster (docs/formats.md).

Each dot counts the drops that landed on it (0 none, 1 one, 2 a doubled dot), so a media
file equal to the RIP's planes proves no dot was lost, moved or printed twice.  Rows are
held in a rolling window and streamed to the TIFF once the paper has carried them past
the heads: memory is bounded by the swath, not by the job's length.
"""

from __future__ import annotations

import numpy as np

from ..rip.planes import PlanesWriter


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

    def land(self, channel: int, rows: np.ndarray, cols: np.ndarray) -> None:
        """Drops of one colour at image rows/cols, equal-length arrays.  One call holds one
        head's fires of one block, so no (row, col) repeats inside a call and a buffered
        fancy-index increment counts every drop."""
        if rows.size == 0:
            return
        inside = (rows >= 0) & (rows < self.height) & (cols >= 0) & (cols < self.width)
        self.stray += int(rows.size - np.count_nonzero(inside))
        rows, cols = rows[inside], cols[inside]
        late = rows < self._base
        if late.any():
            self.late += int(np.count_nonzero(late))
            rows, cols = rows[~late], cols[~late]
        if rows.size == 0:
            return
        top = int(rows.max())
        if top >= self._base + self._win.shape[0]:
            self.flush_below(top - self._win.shape[0] + 1)
        self._win[rows - self._base, cols, channel] += 1
        self.drops[channel] += rows.size

    def flush_below(self, row: int) -> None:
        """Rows < row can receive no more drops: write them out."""
        row = min(row, self.height)
        n = row - self._base
        if n <= 0:
            return
        n_win = min(n, self._win.shape[0])
        if self._writer:
            self._writer.write(self._win[:n_win])
            if n > n_win:
                self._writer.write(np.zeros((n - n_win, self.width, 4), np.uint8))
        self._win = np.roll(self._win, -n_win, axis=0)
        self._win[-n_win:] = 0
        self._base = row

    def close(self) -> None:
        if self.closed:
            return
        self.flush_below(self.height)
        if self._writer:
            self._writer.close()
        self.closed = True
