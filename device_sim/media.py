"""The printed media: where drops landed, on the job's image raster (docs/formats.md).

Each dot counts the drops that landed on it (0 none, 1 one, 2 a doubled dot), so a media
file equal to the RIP's planes proves no dot was lost, moved or printed twice.  Rows are
held in a rolling window and streamed to the TIFF once the paper has carried them past
the heads: memory is bounded by the swath, not by the job's length.
"""

from __future__ import annotations

import ctypes
import threading
from concurrent.futures import ThreadPoolExecutor

import numpy as np
from ..rip.compiled import kernel

from ..rip.planes import INK_SHIFT, PlanesWriter


# A dot seen as one uint32 of its 4 inks (planes.INK_SHIFT): a row's drops of one ink are
# added with a contiguous walk (vectorised) instead of a 4-byte stride; the ink is a shift.
# No carry can cross into the next ink: a dot gets a drop per pass and head at most.
@kernel()
def _land_words(win32, base, height, width, words, cols, nozzle_rows, nozzle_dcols, ink_shift):
    """Scatter the drops of packed fire words: bit z of fire f lands at
    (nozzle_rows[z], cols[f] + nozzle_dcols[z]), in the ink `ink_shift` selects of the
    window's uint32 dots.  Returns (landed, stray, late).

    Nozzle by nozzle: each nozzle's drops go to one media row, so the writes walk along
    that row (the fires' columns are consecutive) instead of jumping between 128 rows."""
    landed = stray = late = 0
    nwin = win32.shape[0]
    n = words.shape[0]
    if n == 0:
        return 0, 0, 0
    cmin, cmax = cols.min(), cols.max()
    step = 0                                     # +1 / -1: the fires' columns are consecutive
    if n > 1 and cmax - cmin == n - 1 and abs(cols[1] - cols[0]) == 1:
        step = cols[1] - cols[0]
        for f in range(1, n):
            if cols[f] - cols[f - 1] != step:
                step = 0
                break
    nw = words.shape[1]
    by_word = np.empty((nw, n), np.uint32)      # each word's fires side by side, in column
    if step == -1:                               # order: a reverse stroke's too
        cols = cols[::-1]
        step = 1
        for w in range(nw):
            for f in range(n):
                by_word[w, n - 1 - f] = words[f, w]
    else:
        for w in range(nw):
            for f in range(n):
                by_word[w, f] = words[f, w]
    for z in range(nw * 16):
        fires = by_word[z >> 4]
        shift = np.uint32(z & 15)
        r = nozzle_rows[z]
        d = nozzle_dcols[z]
        if r < 0 or r >= height or r < base or r - base >= nwin:
            hits = 0
            for f in range(n):
                hits += (fires[f] >> shift) & np.uint32(1)
            if r < 0 or r >= height:
                stray += hits
            elif r < base:
                late += hits
            continue
        row = win32[r - base]
        if step == 1:                              # consecutive columns: a contiguous walk
            c0 = cols[0] + d                       # over the fires on the paper; those off
            lo = min(max(0, -c0), n)               # its edges (the heads' offsets make a
            hi = max(min(n, width - c0), lo)       # stroke fire past them) are only counted
            # both sides sliced to the same span and walked from 0, the count in 32 bits:
            # LLVM vectorises this form (2.8x the speed of indexing one side by f - lo)
            src = fires[lo:hi]
            row_f = row[c0 + lo:c0 + hi]
            hits = np.uint32(0)
            for f in range(hi - lo):
                v = (src[f] >> shift) & np.uint32(1)
                row_f[f] += v << ink_shift
                hits += v
            landed += hits
            for f in range(lo):
                stray += (fires[f] >> shift) & np.uint32(1)
            for f in range(hi, n):
                stray += (fires[f] >> shift) & np.uint32(1)
            continue
        if cmin + d >= 0 and cmax + d < width:      # every column on the paper: no branch
            hits = 0
            for f in range(n):
                v = (fires[f] >> shift) & np.uint32(1)
                row[cols[f] + d] += v << ink_shift
                hits += v
            landed += hits
            continue
        for f in range(n):
            if (fires[f] >> shift) & np.uint32(1):
                c = cols[f] + d
                if c < 0 or c >= width:
                    stray += 1
                else:
                    row[c] += np.uint32(1) << ink_shift
                    landed += 1
    return landed, stray, late


class Media:
    """The rolling window of rows under the heads and the TIFF they go to.

    Landing drops and writing rows out run on a worker thread of their own (the landing
    kernel releases the GIL), one after the other in the order the emulator asked for them,
    while the emulator goes on decoding blocks and feeding paper: the line's state never
    depends on where drops land, only what is read back does.  Reading the window or the
    counts (`drops`, `stray`, `late`, `snapshot`, `close`) waits for the work in flight.
    A file that cannot be written (a full disk) stops the writing, not the landing: close()
    raises it once and removes the unfinished file."""

    def __init__(self, width: int, height: int, dpi_x: float, dpi_y: float, window_rows: int,
                 path: str | None = None):
        self.width, self.height = width, height
        self.path = path
        self._writer = PlanesWriter(path, width, height, dpi_x, dpi_y,
                                    description="wideprint emulator media") if path else None
        self._win = np.zeros((max(window_rows, 1), width, 4), np.uint8)
        self._win32 = self._win.view(np.uint32).reshape(self._win.shape[:2])   # the same bytes
        self._base = 0                       # image row of window row 0 (once the work queued is done)
        self._drops = np.zeros(4, np.int64)  # drops that landed in the image area
        self._stray = 0                      # drops outside the image area
        self._late = 0                       # drops on rows already written out (paper went back)
        # one thread: its jobs touch the same rows and must run in order
        self._worker = ThreadPoolExecutor(1, thread_name_prefix="media")
        self._queued: list = []              # (channel or None, future), oldest first
        self._books = threading.Lock()       # _queued and the counts: a live view reads too
        self.closed = False
        self.error: BaseException | None = None   # the file could not be written (close raises it)

    def _queue(self, channel, fn, *args) -> None:
        self._collect(wait=False)
        with self._books:
            self._queued.append((channel, self._worker.submit(fn, *args)))

    def _collect(self, wait: bool = True) -> None:
        """Take the results of the work done (all of it when `wait`), oldest first."""
        with self._books:
            q = self._queued
            while q and (wait or q[0][1].done()):
                channel, fut = q.pop(0)
                counts = fut.result()          # a failure is raised once, here
                if channel is not None:
                    landed, stray, late = counts
                    self._drops[channel] += landed
                    self._stray += stray
                    self._late += late

    def land_words(self, channel: int, words: np.ndarray, cols: np.ndarray,
                   nozzle_rows: np.ndarray, nozzle_dcols: np.ndarray | None = None) -> None:
        """Drops of one head: words (fires, 8) uint16, the media column of each fire, the
        media row of each of the 128 nozzles (docs/protocol.md 4.3 bit order) and each
        nozzle's column offset from its fire's column (misdirection; default none).  The
        caller does not change the arrays afterwards (they land later)."""
        if words.size == 0:
            return
        top = int(nozzle_rows.max())
        if top >= self._base + self._win.shape[0]:
            self.flush_below(top - self._win.shape[0] + 1)
        self._queue(channel, _land_words, self._win32, self._base, self.height, self.width,
                    np.ascontiguousarray(words), cols.astype(np.int64),
                    nozzle_rows.astype(np.int64),
                    np.zeros(nozzle_rows.size, np.int64) if nozzle_dcols is None
                    else nozzle_dcols.astype(np.int64), np.uint32(INK_SHIFT[channel]))

    @property
    def drops(self) -> np.ndarray:
        self._collect()
        return self._drops

    @property
    def stray(self) -> int:
        self._collect()
        return self._stray

    @property
    def late(self) -> int:
        self._collect()
        return self._late

    def snapshot(self, step: int = 1) -> tuple[int, np.ndarray]:
        """(first image row, copy of the rows still under or near the heads), every
        `step`-th row and column: a live view paints this over what it already has, since
        rows before it never change again."""
        self._collect()
        first = -(-self._base // step) * step
        return first, self._win[first - self._base::step, ::step].copy()

    def flush_below(self, row: int) -> None:
        """Rows < row can receive no more drops: write them out (queued behind the drops
        landing on them)."""
        row = min(row, self.height)
        if row > self._base:
            self._queue(None, self._write_out, row - self._base)
            self._base = row

    def _write_out(self, n: int) -> None:
        """The window's first n rows to the file (the worker thread)."""
        win = self._win
        n_win = min(n, win.shape[0])
        if self._writer and self.error is None:
            try:
                self._writer.write(win[:n_win])       # taken at once (rip/planes.py)
                blank = np.zeros((min(n - n_win, win.shape[0]), self.width, 4), np.uint8)
                for r in range(n_win, n, blank.shape[0] or 1):  # rows past the window: empty
                    self._writer.write(blank[:min(blank.shape[0], n - r)])
            except (OSError, ValueError, RuntimeError) as exc:
                # the file cannot be written (a full disk): the drops still land and are
                # counted, the rows are dropped, and close() says so once
                self.error = exc
        # shift the window up in place (one memmove, no copy of the job's width x a swath;
        # the writer keeps no view of it)
        keep = win.shape[0] - n_win
        if keep:
            row_bytes = win.strides[0]
            ctypes.memmove(win.ctypes.data, win.ctypes.data + n_win * row_bytes,
                           keep * row_bytes)
        win[keep:] = 0

    def close(self) -> None:
        """The rest of the rows written and the file completed.  A failure (a full disk)
        is raised once, the unfinished file removed, and the media is closed all the same:
        the printer takes its next job (docs/emulator.md "Media")."""
        if self.closed:
            return
        self.closed = True
        try:
            self.flush_below(self.height)
            self._collect()
        except BaseException:
            self._worker.shutdown(cancel_futures=True)
            if self._writer:
                self._writer.abort()
            raise
        self._worker.shutdown()
        if self._writer:
            if self.error is not None:
                self._writer.abort()
                raise self.error
            try:
                self._writer.close()
            except BaseException:
                self._writer.abort()
                raise
