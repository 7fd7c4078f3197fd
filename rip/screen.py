"""Ordered screening fused with separation: the fast path for ``bayer`` and ``bluenoise``.

With an ordered method a pixel's drops depend only on its own ink and the threshold mask,
so the RIP need not make a band's CMYK and 0/1 planes at all.  Row by row, the kernel
separates into a scratch row that stays in cache (rip/color/kernels.py's LUT kernel, then ink limit
and curves), compares it with the mask's threshold row and writes packed bits straight in
the stroke planner's window layout: ``(rows, 4, ceil(width / 8))``, x = 0 in bit 7 of byte 0
(``np.packbits`` order).  The bits are exactly ``Halftoner.process(Separator.convert(band))``
packed: tests/test_screen.py checks it across modes, limits, curves and band splits.
docs/rip.md has the measurements.
"""

from __future__ import annotations

import numpy as np
from .compiled import kernel

from .color import Separator
from .color.kernels import _lut3_rows, _post_rows
from .halftone import ORDERED, Halftoner
from .parallel import run_parallel, split

__all__ = ["OrderedScreen"]


@kernel(inline="always")
def _drops4(ink, thr):
    """Bit 7 of each byte lane set where the ink byte > the threshold byte (unsigned):
    four inks compared at once (SWAR; H. Warren, Hacker's Delight, 2nd ed., 6-1)."""
    h = np.uint32(0x80808080)
    d = (thr | h) - (ink & ~h)                  # bit 7: thr's low 7 bits >= ink's
    ge = (thr & ~ink) | (~(ink ^ thr) & d)      # bit 7: thr >= ink
    return ~ge & h


@kernel()
def _screen_row(cmyk, thr_row, x_start, out):
    """One row (or a piece of one starting at column x_start, a multiple of 8): cmyk (w,)
    uint32 packed inks (C in the low byte), thr_row (n,) uint32 thresholds packed the same
    way (n a multiple of 8) -> out (4, ceil(w / 8)) bits.  Pixel i of a byte shifts its four
    drop bits (bit 7 of each lane) right by i, so each lane of the OR of eight pixels is that
    ink's byte, x = 0 in bit 7."""
    w = cmyk.shape[0]
    n = thr_row.shape[0]
    for xb in range((w + 7) >> 3):
        x0 = xb << 3
        t0 = (x_start + x0) % n
        acc = np.uint32(0)
        for i in range(min(8, w - x0)):
            acc |= _drops4(cmyk[x0 + i], thr_row[t0 + i]) >> np.uint32(i)
        out[0, xb] = acc & 0xFF
        out[1, xb] = (acc >> 8) & 0xFF
        out[2, xb] = (acc >> 16) & 0xFF
        out[3, xb] = acc >> 24


@kernel()
def _screen_cmyk(cmyk, thr, row0, out):
    """cmyk (h, w) uint32 packed (ink limit and curves applied) -> out (h, 4, wb) bits."""
    n = thr.shape[0]
    for i in range(cmyk.shape[0]):
        _screen_row(cmyk[i], thr[(row0 + i) % n], 0, out[i])


SCREEN_CHUNK = 512     # pixels per step: the chunk's source, CMYK and bits stay in L1 with the LUT


@kernel()
def _screen_lut3(src, lut, axes, d12, s3, limit, curves, use_curves, thr, row0, out):
    """src (h, w, 3) RGB -> out (h, 4, wb) bits: separation, ink limit, curves and the
    threshold compare, SCREEN_CHUNK pixels at a time through a small scratch buffer (a
    whole-row scratch streams ~84 KB a row through L1, evicting LUT lines: ~4 % slower)."""
    h, w = src.shape[0], src.shape[1]
    n = thr.shape[0]
    scratch = np.empty((SCREEN_CHUNK, 4), np.uint8)
    scratch32 = scratch.reshape(-1).view(np.uint32)
    for i in range(h):
        t = thr[(row0 + i) % n]
        for x0 in range(0, w, SCREEN_CHUNK):
            m = min(SCREEN_CHUNK, w - x0)
            if _lut3_rows(src[i, x0:x0 + m], lut, axes, d12, s3, limit, scratch32[:m]) or use_curves:
                _post_rows(scratch[:m], limit, curves, use_curves)
            _screen_row(scratch32[:m], t, x0, out[i, :, x0 >> 3:])


class OrderedScreen:
    """Separator + ordered Halftoner as one band step: ``process(band) -> packed bits``.
    Keeps the absolute row (the mask phase) across bands, like the Halftoner."""

    def __init__(self, separator: Separator, halftoner: Halftoner):
        if halftoner.method not in ORDERED or halftoner.channels != 4:
            raise ValueError("OrderedScreen needs a 4-channel ordered Halftoner")
        self.sep = separator
        self.width = halftoner.width
        self.wbytes = -(-self.width // 8)
        self.thr = halftoner.thresholds.view(np.uint32)      # (n, n): one uint32 per pixel
        self.row = halftoner.row

    def process(self, band: np.ndarray) -> np.ndarray:
        """band (h, width, channels) as from ImageSource.bands() -> (h, 4, wbytes) bits."""
        return self.job(band)()

    def job(self, band: np.ndarray):
        """The band's screening as a callable returning its bits, the mask phase taken now:
        bands' jobs may then run side by side in any order (rip/parallel.py `ordered`)."""
        sep = self.sep
        h = band.shape[0]
        if band.ndim < 2 or band.shape[1] != self.width:
            raise ValueError(f"band must be {self.width} px wide, got shape {band.shape}")
        row0 = self.row
        self.row = row0 + h

        def run() -> np.ndarray:
            out = np.empty((h, 4, self.wbytes), np.uint8)
            if sep.mode == "lut3":
                src = sep.check_band(band)
                kernel, args = _screen_lut3, sep.lut3_tables() + sep.post_tables()
            else:
                # other colour modes: CMYK first, then screen
                src = sep.convert(band).reshape(h, -1).view(np.uint32)
                kernel, args = _screen_cmyk, ()
            # rows split over the workers (at least 64 K pixels each), unless this runs on
            # a band worker
            run_parallel(
                (lambda a=a, b=b: kernel(src[a:b], *args, self.thr, row0 + a, out[a:b]))
                for a, b in split(h, minimum=-(-65536 // self.width)))
            return out
        return run
