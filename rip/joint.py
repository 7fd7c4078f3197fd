"""``joint``: variable-coefficient error diffusion with C, M and Y decided together, K counted -
dot-off-dot over every ink (docs/rip.md "The halftones", docs/media.md "Every dpi mode the same
colour").

Why: at 150 dpi a cell (one column, one row) takes at most one drop per ink and the columns
are 169 µm apart, wider than a dot (~102 µm), so two drops in one cell cover the paper of
one.  With each ink diffused on its own (``vced``) a C+M+Y tint stacks more than its coverage
forces (at 35 % each a third of the drops land on a cell already taken, where none need);
the print comes out lighter than 300 dpi's with the same ink, so 150 dpi's profile asks for
more ink (bench/ink150_floor.py).  ``vector`` keeps only C and M apart.

The decision, per pixel (``vced``'s arithmetic otherwise: ``rip/diffusion.py``):

* **How many dots** the cell gets is one error diffusion of the inks' sum.  With ``L = c + m
  + y + k`` (0..1020) the cell gets ``base = ceil(L / 255) - 1`` dots for certain (0 up to
  full coverage, 1 up to twice, ...) and one more when the four values' sum (ink + error
  each) minus ``base`` full dots reaches the threshold, modulated for the combined level ``L -
  255 base`` as ``vced`` modulates a level; C, M and Y get that count less K's dot.  So a
  cell holds ``floor`` or ``ceil`` of the local Σ coverage: no cell is left empty while
  another holds two, no cell holds three while another holds one - stacking only what the
  coverage forces.
* **Which inks**: those furthest above their own (modulated) thresholds, each with a split
  noise of its own (the mask a quarter tile along, ``SPLIT_BOOST`` x the ink's modulation,
  as ``vector``'s split), so the inks' dots interleave without line or checkerboard domains.
  An ink at 0 never gets a drop, at 255 always one (the count gives way: at least the inks
  at 255, at most the inks above 0).
* **Tone**: each ink keeps its own error, diffused with the combined level's weights
  (where the combined pattern is neither almost empty nor almost full, 16..239; else the
  ink's own level's), so each ink's mean coverage is its input; the error is clamped at
  ``PAIR_LIMIT`` (254 levels), as ``vector``'s pair.
* **K as vced's, counted in the cell**: K's dots are exactly ``vced``'s (K is the most
  visible ink and keeps its own best pattern), decided first in the same loop, and the cell's
  count above is of all four inks: C, M and Y fill the cells K left before stacking on K.
  Measured through the whole media loop (bench/ink150_media.py): with K left out of the count
  (``k_in_count=False``, K stacking on C, M and Y at random) 150 dpi needed 17 % more ink than
  300 dpi for the control chart; counted, 6 %.

Serpentine on the absolute row, integer arithmetic, the error rows carried between bands
(``err``, as ``vced``): the same dots for any band split, any thread split, every run.
Fewer than three channels: each on its own, as ``vced``.
"""

from __future__ import annotations

import numpy as np

from .compiled import kernel
from .diffusion import PAIR_LIMIT, UNIT, WEIGHT_BITS, VCDiffuser, _step, vc_planes
from .serpentine import _end_row, _serpentine

__all__ = ["JointDiffuser", "cmy_rows", "JOINT"]

#: the inks decided together (C, M, Y); K (the next) keeps vced's dots, counted in the cell
JOINT = 3

_U = UNIT
_T0 = 128 * UNIT
_FULL = 255 * UNIT
_LIM = 127 * UNIT       # vced's clamp (K's)
_SH = WEIGHT_BITS
_BIG = 1 << 40          # an ink at 255 ranks before, an ink at 0 after, every other


@kernel(inline="always")
def _rank(lvl, v, t, split):
    """An ink's claim to a dot: how far its value is above its own threshold (modulated by
    the split noise); 255 always first, 0 always last."""
    if lvl == 255:
        return _BIG
    if lvl == 0:
        return -_BIG
    return v - t + split


@kernel()
def cmy_rows(src, dst, err, row0, wn, wdl, mod, smod, noise, offs, lim, kc, tab):  # pragma: no cover
    """Channels 0, 1, 2 of (rows, width, channels) C-contiguous uint8 src/dst decided
    jointly (the module docstring); err (channels, 2, width + 4) int32 error rows by
    absolute row & 1; row0 the absolute row of src[0]; wn, wdl, mod, smod (256,) int64; noise
    (n, n) uint8; offs (channels, 2) int64 noise offsets; lim the error clamp; kc >= 0: K's
    channel, diffused here as vced does (``tab``: vced's per-level table) and counted in the
    cell's dots, so C, M and Y fill the cells K left; kc < 0: C, M, Y alone."""
    rows, width = src.shape[0], src.shape[1]
    ch = np.uint64(src.shape[2])
    nm = np.uint64(noise.shape[0] - 1)
    m = noise.shape[0] - 1
    q4 = noise.shape[0] // 4
    u1, u2 = np.uint64(1), np.uint64(2)
    x0, x1, x2 = np.uint64(offs[0, 0]), np.uint64(offs[1, 0]), np.uint64(offs[2, 0])
    s0, s1, s2 = np.uint64(offs[0, 0] + q4), np.uint64(offs[1, 0] + q4), np.uint64(offs[2, 0] + q4)
    kk = max(kc, 0)
    ku = np.uint64(kk)
    xk = np.uint64(offs[kk, 0])
    for i in range(rows):
        r = row0 + i
        srow = src[i].reshape(-1)
        drow = dst[i].reshape(-1)
        a, b = r & 1, (r + 1) & 1
        c0, n0, c1, n1, c2, n2 = err[0, a], err[0, b], err[1, a], err[1, b], err[2, a], err[2, b]
        z0 = noise[(r + offs[0, 1]) & m]
        z1 = noise[(r + offs[1, 1]) & m]
        z2 = noise[(r + offs[2, 1]) & m]
        ck, nk = err[kk, a], err[kk, b]
        zk = noise[(r + offs[kk, 1]) & m]
        k0 = k1 = k2 = k3 = 0   # the next pixel's shares
        p0 = p1 = p2 = p3 = 0   # the row below: the cell under this pixel, so far
        fwd = (r & 1) == 0
        for k in range(width):
            x, p, q = _serpentine(k, width, fwd)
            o = x * ch
            l0 = np.int64(srow[o])
            l1 = np.int64(srow[o + u1])
            l2 = np.int64(srow[o + u2])
            v0 = l0 * _U + min(max(c0[p] + k0, -lim), lim)
            v1 = l1 * _U + min(max(c1[p] + k1, -lim), lim)
            v2 = l2 * _U + min(max(c2[p] + k2, -lim), lim)
            tot = l0 + l1 + l2
            lo = (tot - 1) // 255 if tot > 0 else 0     # C, M and Y's own floor of dots
            vs = v0 + v1 + v2
            dk = 0
            if kc >= 0:         # K as vced diffuses it, and counted in the cell
                lk = srow[o + ku]
                vs += np.int64(lk) * _U + min(max(ck[p] + k3, -_LIM), _LIM)
                tot += np.int64(lk)
                dk, ek, lk_, wk = _step(lk, ck[p] + k3, zk[(x + xk) & nm], tab)
                drow[o + ku] = dk
                k3 = ek
                nk[q] = p3 + lk_
                p3 = wk
            # how many dots: the sum's own diffusion at the combined level
            base = (tot - 1) // 255 if tot > 0 else 0
            lev = tot - 255 * base
            t = _T0 + mod[lev] * (np.int64(z0[(x + x1) & nm]) - 128)
            n = base + (1 if vs - base * _FULL >= t else 0) - dk
            # never beyond C, M and Y's own floor or ceiling: K lands where it will, and
            # a light ink must not be forced into a cell more often than its tone allows
            n = min(max(n, lo), lo + 1)
            # which: the inks furthest above their own thresholds
            r0 = _rank(l0, v0, _T0 + mod[l0] * (np.int64(z0[(x + x0) & nm]) - 128),
                       smod[l0] * (np.int64(z0[(x + s0) & nm]) - 128))
            r1 = _rank(l1, v1, _T0 + mod[l1] * (np.int64(z1[(x + x1) & nm]) - 128),
                       smod[l1] * (np.int64(z1[(x + s1) & nm]) - 128))
            r2 = _rank(l2, v2, _T0 + mod[l2] * (np.int64(z2[(x + x2) & nm]) - 128),
                       smod[l2] * (np.int64(z2[(x + s2) & nm]) - 128))
            full = (1 if l0 == 255 else 0) + (1 if l1 == 255 else 0) + (1 if l2 == 255 else 0)
            some = (1 if l0 > 0 else 0) + (1 if l1 > 0 else 0) + (1 if l2 > 0 else 0)
            n = min(max(n, full), some)
            o0 = o1 = o2 = 0
            if n == 3:
                o0 = o1 = o2 = 1
            elif n == 2:        # all but the last
                o0 = o1 = o2 = 1
                if r0 < r1 and r0 < r2:
                    o0 = 0
                elif r1 < r2:
                    o1 = 0
                else:
                    o2 = 0
            elif n == 1:        # the first
                if r0 >= r1 and r0 >= r2:
                    o0 = 1
                elif r1 >= r2:
                    o1 = 1
                else:
                    o2 = 1
            drow[o] = o0
            drow[o + u1] = o1
            drow[o + u2] = o2
            v0 -= o0 * _FULL
            v1 -= o1 * _FULL
            v2 -= o2 * _FULL
            # the error with the combined pattern's weights (each ink's own near the extremes)
            mid = 16 <= lev <= 239
            w0 = lev if mid else l0
            w1 = lev if mid else l1
            w2 = lev if mid else l2
            e0 = (v0 * wn[w0]) >> _SH
            d0 = (v0 * wdl[w0]) >> _SH
            e1 = (v1 * wn[w1]) >> _SH
            d1 = (v1 * wdl[w1]) >> _SH
            e2 = (v2 * wn[w2]) >> _SH
            d2 = (v2 * wdl[w2]) >> _SH
            k0, k1, k2 = e0, e1, e2
            n0[q] = p0 + d0
            n1[q] = p1 + d1
            n2[q] = p2 + d2
            p0, p1, p2 = v0 - e0 - d0, v1 - e1 - d1, v2 - e2 - d2
        _end_row(c0, n0, p0, width, fwd)
        _end_row(c1, n1, p1, width, fwd)
        _end_row(c2, n2, p2, width, fwd)
        if kc >= 0:
            _end_row(ck, nk, p3, width, fwd)


class JointDiffuser(VCDiffuser):
    """Band-by-band ``joint`` diffusion of (rows, width, channels) uint8 ink: channels 0-2 (C,
    M, Y) decided together by ``cmy_rows``, with K (channel 3) diffused in the same loop as
    ``vced`` diffuses it and counted in the cell (``k_in_count``; else K on its own,
    ``vc_planes``, as any further channel).  ``rip.diffusion.VCDiffuser``'s tables, state
    (``err``, ``row``) and ``process``, which rip/halftone.py drives; only ``jobs`` differs."""

    def __init__(self, width: int, channels: int, noise: np.ndarray, *, k_in_count: bool = True):
        super().__init__(width, channels, noise)        # vced's weights, modulation, tab
        self.inks = JOINT if self.channels >= JOINT else 0
        self.kc = JOINT if k_in_count and self.channels > JOINT else -1
        self.lim = int(PAIR_LIMIT)

    def jobs(self, band: np.ndarray, out: np.ndarray, groups: int):
        """Callables that together diffuse ``band`` into ``out``: C, M and Y (and K, counted)
        in one, the other channels in another (on two threads when ``groups`` > 1)."""
        row0 = self.row
        rest = (self.inks + (self.kc >= 0), self.channels)

        def cmy():
            cmy_rows(band, out, self.err, row0, self.wn, self.wdl, self.mod, self.smod,
                     self.noise, self.offsets, self.lim, self.kc, self.tab)

        def others():
            if rest[1] > rest[0]:
                vc_planes(band, out, self.err, row0, rest[0], rest[1], self.wn, self.wdl,
                          self.mod, self.noise, self.offsets)

        if not self.inks:
            return [others]
        if groups > 1 and rest[1] > rest[0]:
            return [cmy, others]
        return [lambda: (cmy(), others())]
