"""Row-causal direct binary search: ``dbs``, vced's dots refined row by row against the eye model.

Direct binary search (Analoui and Allebach 1992; Lieberman and Allebach 1997) toggles and
swaps dots while the eye-filtered error ``|p * (h - c)|^2`` falls.  Over a whole image it
is the quality bound of halftoning (bench/quality_bench.py's photographs: fine-scale error
0.01255 against vced's 0.01668), but it needs the whole image and many passes, every dot
may move until the end; the RIP works in bands of 16-64 rows and must give identical dots
for any banding (docs/rip.md).  ``dbs`` keeps DBS's objective and its O(1) trial of a
change, and makes it causal by rows:

* **One row at a time, the rows above final.**  Row r starts as vced's dots (rip/diffusion.py:
  tone-exact, blue noise, its error rows carried across bands as always).  With the rows
  above fixed and the rows below not known yet (the band may end here: they count as
  error-free), its dots are toggled, or swapped with the left or right neighbour, in
  serpentine passes (direction by absolute row and pass), a change taken when it lowers the
  objective, until a pass changes nothing (at most ``PASSES``; only pixels near a change are
  tried again).  A row depends only on the rows up to it and the carried state, so the same
  image in bands of any heights gives the same dots.
* **The objective**: the eye model of bench/hvs.py - a Gaussian of ``EYE_FINE`` px across,
  x ``SCREEN_ASPECT`` rows along (the 300 x 370.5 grid) - plus ``COARSE_WEIGHT`` x its
  ``EYE_COARSE`` px one (the fine filter alone leaves the low frequencies to chance: coarse
  error 0.0053, worse than vced's 0.0049).  The error counted is the filtered error at the
  rows down to ``BELOW`` = -1, the row above the current one: what the rows below cannot
  change any more.  Counting every row instead (the rows below taken as error-free) makes
  each row mend what the rows below will mend too: photographs 0.0141 fine / 0.0037 coarse,
  against 0.01346 / 0.0030 with -1 (0: 0.0135 / 0.0032, -2: 0.0156 / 0.0030).
  DBS tries a change through ``c_pe``, the error correlated with the filter's
  autocorrelation; for a separable Gaussian that is, across, the Gaussian of sqrt(2) sigma,
  and along, ``W_k = sum over the counted rows dy of g(dy) g(dy + k)``: ``c_pe`` of a row
  is the past rows' errors and its own weighted along (a ring of ``RING`` rows per ink),
  then filtered across, once for the fine and once for the coarse term (the same integers
  as filtering each row across first: 23 multiply-adds along, and across 18 multiplies, the
  kernels being symmetric and tap pairs summed first; 80 multiply-adds filtering first), and
  a change updates 23 cells of one row (24 for a swap), one add of a precomputed row
  (``update_table``).  Both cut at ``TRUNCATE`` sigma.
* **Tone**: the eye model cannot justify a lone dot in a very light tint (its gain within
  the filter's reach is below its own cost; full-image DBS drops tints below ~2 %, which
  the fine-scale score rewards and a print would not).  So dots are added or removed only
  where the ink is within (``TONE_GUARD``, 255 - ``TONE_GUARD``); nearer the ends vced's
  dots are only moved (a swap keeps the count).  Ink 0 and 255 are never swapped either:
  ink 0 gets no dot, 255 always one, pixel by pixel.
* **Jitter** (``JITTER_KEYS``): a change must lower the objective by more than a blue-noise
  threshold (vced's modulation mask at the ink's offsets, x a strength per ink level), which
  breaks up the lattices a greedy search settles into near the ends of the tone scale and
  the checkerboard domains around 50 %.  It only ever makes a change harder, so every
  change lowers the objective and the passes end.

Integer arithmetic throughout (weights in 1/1024, errors in ink levels, sums in int32 with
the bound checked), so the dots are bit-exact, platform independent and the same from the
compiled and the JIT kernel.  The trial of a pixel is branch-free (which neighbour differs is
a coin toss a branch predictor loses), and only pixels of ink 1..254 are tried (0 and 255
cannot change).  What the time goes to, and why half of vced's speed is out of reach for a
search of this kind: bench/README.md, "Halftone against DBS" (bench/dbs_sweeps.py; the
kernel counts its tries and changes in ``RowDBS.stats``).
"""

from __future__ import annotations

import numpy as np

from .bluenoise import SCREEN_ASPECT
from .compiled import kernel

__all__ = ["EYE_FINE", "EYE_COARSE", "COARSE_WEIGHT", "TRUNCATE", "PASSES", "TONE_GUARD",
           "JITTER_KEYS", "BELOW", "jitter_table", "RowDBS", "filter_tables"]

EYE_FINE = 1.2          # px across: bench/hvs.py FINE (close inspection, ~0.1 mm)
EYE_COARSE = 2.5        # px across: bench/hvs.py COARSE (arm's length)
COARSE_WEIGHT = 1.5     # the coarse term's weight in the objective (see the module docstring)
TRUNCATE = 3.0          # the autocorrelation Gaussians are cut at 3 sigma
PASSES = 4              # at most this many passes a row (8: the same photo scores, 3: +0.7 %)
TONE_GUARD = 8          # dots are only moved, not added or removed, at ink <= 8 or >= 247
# the blue-noise threshold a change must beat, in the objective's units / 128, per ink level
# 0..127 (linear between the keys, mirrored above): breaks up the lattices a greedy search
# settles into at the ends of the tone scale and the checkerboard domains around 50 %
JITTER_KEYS = ((0, 36000), (44, 2000), (96, 2000), (127, 12000))
WEIGHT_BITS = 10        # the filter weights in 1/1024
RING = 16               # rows of past error kept per ink (> the coarse filter's reach)
BELOW = -1              # the rows whose filtered error counts: down to the one above (see below)
UPD = 32                # cells a change updates in c_pe (its 2 rx + 3 padded: one fixed-length add)


def _gauss(sigma: float, radius: int) -> np.ndarray:
    x = np.arange(-radius, radius + 1, dtype=np.float64)
    g = np.exp(-x * x / (2 * sigma * sigma))
    return g / g.sum()


def jitter_table(keys=JITTER_KEYS) -> np.ndarray:
    """(256,) int64: the jitter per ink level (``JITTER_KEYS``, mirrored above 127)."""
    lv, st = zip(*keys)
    half = np.interp(np.arange(128, dtype=np.float64), lv, st)
    return np.rint(np.concatenate([half, half[::-1]])).astype(np.int64)


def filter_tables(fine: float = EYE_FINE, coarse: float = EYE_COARSE,
                  coarse_weight: float = COARSE_WEIGHT, truncate: float = TRUNCATE,
                  aspect: float = SCREEN_ASPECT, below=BELOW):
    """The objective's autocorrelation as integer separable factors: (kf, yf, kc, yc, k0),
    int32.  kf, kc: the fine and coarse horizontal kernels (the autocorrelation of the
    Gaussian across: sigma sqrt(2), 2 rx + 1 taps, each summing to ~1024); yf, yc: their
    weights for the rows 0, 1, .. above (yc times the coarse weight): the error seen at the
    rows down to ``below`` rows under the current one (None: every row), i.e. ``W_k = sum
    over dy <= below of g(dy) g(dy + k)`` of the Gaussian along; k0: the row's own weights,
    yf[0] kf + yc[0] kc, centred on the wider one."""
    out = []
    for sigma, weight in ((fine, 1.0), (coarse, coarse_weight)):
        ax, ay = sigma * np.sqrt(2.0), sigma * aspect
        rx, ry = int(np.ceil(truncate * ax)), int(np.ceil(truncate * ay))
        gx = np.rint(_gauss(ax, rx) * (1 << WEIGHT_BITS)).astype(np.int32)
        nz = np.flatnonzero(gx)
        gx = gx[nz[0]:nz[-1] + 1]                   # (taps rounded to 0 cost time, not dots)
        g = _gauss(ay, ry)                          # the eye's Gaussian along, rows -ry..ry
        last = 2 * ry if below is None else min(2 * ry, ry + int(below))
        w = np.array([sum(g[i] * g[i + k] for i in range(0, min(2 * ry + 1 - k, last + 1)))
                      for k in range(0, 2 * ry + 1)])
        w = w[:np.flatnonzero(w > 0)[-1] + 1] / np.sum(np.convolve(g, g))
        gy = np.rint(w * weight * (1 << WEIGHT_BITS)).astype(np.int32)
        gy = gy[:np.flatnonzero(gy)[-1] + 1]
        out += [gx, gy]
    kf, yf, kc, yc = out
    if max(yf.size, yc.size) >= RING:
        raise ValueError("the filter reaches further than the ring of past rows")
    rx = max(kf.size, kc.size) // 2
    k0 = np.zeros(2 * rx + 1, np.int64)
    for k, y in ((kf, yf), (kc, yc)):
        r = k.size // 2
        k0[rx - r:rx + r + 1] += int(y[0]) * k.astype(np.int64)
    # the largest |c_pe|: every error at 255 levels, all weights summed; int32 must hold it
    bound = 255 * sum(int(k.sum()) * (int(y[0]) + 2 * int(y[1:].sum())) for k, y in ((kf, yf), (kc, yc)))
    if bound >= 1 << 30:
        raise ValueError("filter weights too large for 32-bit error sums")
    return kf, yf, kc, yc, k0.astype(np.int32)


def update_table(k0: np.ndarray) -> np.ndarray:
    """(6, UPD) int32: what a change adds to c_pe over the cells x - rx - 1 .., row
    2 (off + 1) + h for a toggle (off 0) or a swap with x + off (-1, 1) of the pixel x whose
    dot was h (0: one is added, +255 x k0 centred on x; 1: removed); a swap also takes the
    same, negated, centred on x + off."""
    rx = k0.size // 2
    if 2 * rx + 3 > UPD:
        raise ValueError("the filter is wider than a change's update")
    out = np.zeros((6, UPD), np.int32)
    for off in (-1, 0, 1):
        for h in (0, 1):
            d = 255 * (1 - 2 * h)
            row = out[2 * (off + 1) + h]
            row[1:2 * rx + 2] += d * k0
            if off:
                row[1 + off:2 * rx + 2 + off] -= d * k0
    return out


@kernel(inline="always")
def _filter_across(out, e, k, P, W, add):
    """out[P + x] (+)= sum over j of k[j] e[P + x + j - r] for x < W, k symmetric of 2 r + 1
    taps: the pairs of taps summed first (half the multiplies, the same integers); row
    slices, so numba sees non-negative indices and the loops vectorise."""
    r = k.shape[0] // 2
    os_ = out[P:P + W]
    es = e[P:P + W]
    kr = k[r]
    if add:
        for x in range(W):
            os_[x] += kr * es[x]
    else:
        for x in range(W):
            os_[x] = kr * es[x]
    for j in range(1, r + 1):
        kj = k[r + j]
        lo = e[P - j:P - j + W]
        hi = e[P + j:P + j + W]
        for x in range(W):
            os_[x] += kj * (lo[x] + hi[x])


@kernel()
def dbs_rows(src, dst, c0, c1, row0, ring, kf, yf, kc, yc, k0, upd, passes, guard, noise,
             offs, jit, stats):  # pragma: no cover - compiled
    """Refine channels c0..c1-1 of dst ((rows, W, ch) uint8 0/1, vced's dots on entry) in
    place against src ((rows, W, ch) uint8 ink); row0 the absolute row of src[0]; ring
    (ch, RING, W + 2 pad) int32: per ink the past rows' final error (255 dot - ink, zero in
    the pad), row r in r & (RING - 1); the tables of ``filter_tables`` and ``update_table``;
    ``guard`` the tone guard; noise (n, n) uint8, offs (ch, 2) int64: the jitter's mask and
    the inks' offsets in it, jit (256,) int32 its strength per ink level (``jitter_table``);
    stats (ch, 1 + 2 passes) int64, added to: per ink the pixels that may change, then per
    pass the pixels tried and the changes made."""
    rows, W = src.shape[0], src.shape[1]
    ryf, ryc = yf.shape[0] - 1, yc.shape[0] - 1
    rx = k0.shape[0] // 2
    P = rx + 2
    L = W + 2 * P
    m = ring.shape[1] - 1
    nm = noise.shape[0] - 1
    cpe = np.zeros(L + UPD, np.int32)  # (the tail: a change's fixed-length update)
    ef = np.zeros(L, np.int32)
    ec = np.zeros(L, np.int32)
    e = np.zeros(L, np.int32)
    hp = np.zeros(L, np.uint8)
    dirty = np.zeros(L, np.uint8)
    tog = np.zeros(L, np.uint8)         # a dot may be added or removed here
    mov = np.zeros(L, np.uint8)         # a dot may be moved here or from here
    lims = np.zeros(L, np.int32)        # the jitter: a change must beat this
    act = np.zeros(W, np.int64)         # the pixels that may change (0 < ink < 255), in order
    BIG = np.int64(1) << 40
    t0 = np.int64(255) * k0[rx]         # a toggle's own cost (c_pp(0), x 255)
    sw = 2 * (t0 - np.int64(255) * k0[rx + 1])   # a swap's with the next pixel
    for c in range(c0, c1):
        rc = ring[c]
        ox, oy = offs[c, 0], offs[c, 1]
        for i in range(rows):
            r = row0 + i
            hr = dst[i, :, c]
            sr = src[i, :, c]
            nrow = noise[(r + oy) & nm]
            wf = yf[0]
            wc = yc[0]
            for x in range(W):                  # (no loop-carried state: vectorises)
                v = np.int32(sr[x])
                h = hr[x]
                hp[x + P] = h
                ex = 255 * np.int32(h) - v
                e[x + P] = ex
                ef[x + P] = wf * ex
                ec[x + P] = wc * ex
                tog[x + P] = 1 if guard < v < 255 - guard else 0
                mov[x + P] = 1 if 0 < v < 255 else 0
                lims[x + P] = -((jit[v] * np.int32(nrow[(x + ox) & nm])) >> 1)
            na = 0
            for x in range(P, P + W):
                act[na] = x
                na += mov[x]
            if na > 0:                          # (a row of inks 0 and 255 only: nothing to try)
                # c_pe = kf * (sum over dy of yf[dy] e[r - dy]) + the same with kc, yc: the
                # past rows' errors weighted along, then filtered across (exact in integers)
                for dy in range(1, max(ryf, ryc) + 1):
                    er = rc[(r - dy) & m]
                    if dy <= min(ryf, ryc):     # both terms: the past row read once
                        wy = yf[dy]
                        wz = yc[dy]
                        for x in range(L):
                            ex = er[x]
                            ef[x] += wy * ex
                            ec[x] += wz * ex
                    elif dy <= ryf:
                        wy = yf[dy]
                        for x in range(L):
                            ef[x] += wy * er[x]
                    else:
                        wy = yc[dy]
                        for x in range(L):
                            ec[x] += wy * er[x]
                cpe[:P] = 0
                cpe[P + W:] = 0
                _filter_across(cpe, ef, kf, P, W, False)
                _filter_across(cpe, ec, kc, P, W, True)
                dirty[P:P + W] = 1
            stats[c, 0] += na
            for it in range(passes if na > 0 else 0):
                changes = 0
                tries = 0
                fwd = ((r + it) & 1) == 0
                for k in range(na):
                    x = act[k] if fwd else act[na - 1 - k]
                    if dirty[x] == 0:
                        continue
                    dirty[x] = 0
                    tries += 1
                    hx = np.int64(hp[x])
                    a = 1 - 2 * hx                  # +1: a dot is added, -1: removed
                    cx = np.int64(cpe[x])
                    # the change of the error (x 1 / 255): a toggle, a swap to the left or
                    # right; selects, not branches (which neighbour differs is a coin toss)
                    best = t0 + 2 * a * cx
                    best = best if tog[x] else BIG
                    ok = mov[x - 1] & (hp[x - 1] ^ hp[x])
                    v = sw + 2 * a * (cx - cpe[x - 1])
                    v = v if ok else BIG
                    sel = v < best
                    best = v if sel else best
                    off = -1 if sel else 0
                    ok = mov[x + 1] & (hp[x + 1] ^ hp[x])
                    v = sw + 2 * a * (cx - cpe[x + 1])
                    v = v if ok else BIG
                    sel = v < best
                    best = v if sel else best
                    off = 1 if sel else off
                    if best < lims[x]:
                        changes += 1
                        hp[x] = 1 - hp[x]
                        e[x] += 255 * a
                        if off != 0:
                            bx = x + off
                            hp[bx] = 1 - hp[bx]
                            e[bx] -= 255 * a
                        # c_pe over the window x - rx - 1 .. : the change's row of upd,
                        # one fixed-length add (vectorises fully: no remainder loop)
                        u = upd[(off + 1) * 2 + hx]
                        cv = cpe[x - rx - 1:x - rx - 1 + UPD]
                        for j in range(UPD):
                            cv[j] += u[j]
                        lo = x - rx - 1 + min(off, 0)
                        dirty[lo:lo + 2 * rx + 3 + (off & 1)] = 1
                stats[c, 1 + 2 * it] += tries
                stats[c, 2 + 2 * it] += changes
                if changes == 0:
                    break
            if na > 0:
                for x in range(W):
                    hr[x] = hp[x + P]
                dirty[:] = 0
            # this row's final error, for the rows below
            rc[r & m, :] = e


class RowDBS:
    """The state of ``dbs`` for one image: per ink the ring of past rows' error;
    ``jobs`` refines a band of vced's dots in place (rows in order, band after band)."""

    def __init__(self, width: int, channels: int, noise: np.ndarray, offsets: np.ndarray, *,
                 passes: int = PASSES, guard: int = TONE_GUARD, jitter=None, **filt):
        self.width, self.channels = int(width), int(channels)
        self.kf, self.yf, self.kc, self.yc, self.k0 = filter_tables(**filt)
        self.upd = update_table(self.k0)
        # per ink: the pixels that may change (0 < ink < 255), then per pass the pixels tried
        # and the changes made (what a pass costs: bench/dbs_sweeps.py)
        self.stats = np.zeros((self.channels, 1 + 2 * max(int(passes), 0)), np.int64)
        pad = self.k0.size // 2 + 2
        self.ring = np.zeros((self.channels, RING, self.width + 2 * pad), np.int32)
        self.noise = np.ascontiguousarray(noise)
        self.offsets = np.ascontiguousarray(offsets, np.int64)
        self.passes, self.guard = int(passes), int(guard)
        jit = jitter_table(JITTER_KEYS if jitter is None else jitter)
        if jit.min() < 0 or jit.max() * 255 >= 1 << 31:
            raise ValueError("jitter strengths out of range (0 .. 2^31 / 255)")
        self.jitter = jit.astype(np.int32)          # (int32 in the kernel: times 0..255)

    def jobs(self, band: np.ndarray, dots: np.ndarray, row0: int, groups: int):
        """Callables refining ``dots`` (vced's, for ``band`` at absolute row ``row0``) in
        place, the inks split into ``groups`` independent parts."""
        groups = max(1, min(groups, self.channels))
        bounds = np.linspace(0, self.channels, groups + 1).astype(int)
        return [lambda a=int(a), b=int(b): dbs_rows(
                    band, dots, a, b, int(row0), self.ring, self.kf, self.yf, self.kc,
                    self.yc, self.k0, self.upd, self.passes, self.guard, self.noise, self.offsets,
                    self.jitter, self.stats)
                for a, b in zip(bounds[:-1], bounds[1:]) if b > a]
