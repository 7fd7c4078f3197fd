"""The serpentine scan the error-diffusion kernels share (rip/halftone.py's Floyd-Steinberg
and 5x3 kernels, rip/diffusion.py's variable-coefficient ones): which pixel comes next on a
row scanned left to right or right to left, the four inks' error rows of an image row, and
a row's end.  Inline helpers: numba compiles them into each kernel that calls them.

A module of its own so that both halftone modules import it and neither imports the other
(tests/test_layers.py: no import circles inside a package)."""

from __future__ import annotations

import numpy as np

from .compiled import kernel


@kernel(inline="always")
def _serpentine(k, width, fwd):
    """Pixel k of a serpentine row (left to right when `fwd`, else right to left) -> (x, p,
    q), unsigned: its column, its cell in the error rows (x + _PAD) and the row-below cell
    behind it, where the down-behind share goes.  The one-loop kernels here and in
    rip/diffusion.py scan through it (unsigned indices spare numba's wrap-around checks)."""
    if fwd:
        x = np.uint64(k)
        return x, x + np.uint64(2), x + np.uint64(1)
    x = np.uint64(width - 1 - k)
    return x, x + np.uint64(2), x + np.uint64(3)


@kernel(inline="always")
def _rows4(err, r):
    """The four inks' error rows (err (4, 2, width + 4)) for image row r: this row's and the
    next one's, ink after ink: (c0, n0, c1, n1, c2, n2, c3, n3)."""
    a, b = r & 1, (r + 1) & 1
    return err[0, a], err[0, b], err[1, a], err[1, b], err[2, a], err[2, b], err[3, a], err[3, b]


@kernel(inline="always")
def _end_row(cur, nxt, pending, width, fwd):
    """A serpentine row's end, one ink: the row-below cell under its last pixel takes what
    is pending for it, and the row's own error cells are cleared for the row two on."""
    nxt[width + 1 if fwd else 2] = pending
    cur[:] = 0
