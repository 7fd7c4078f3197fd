"""Halftoning: 8-bit ink amounts to 1-bit drop planes, band by band.

Interface::

    h = Halftoner(method, width, channels=4, seed=0)
    bits = h.process(band)   # band: uint8 (rows, width, channels), 0..255 ink (255 = full)
                             # bits: uint8 (rows, width, channels), 0/1 (1 = a drop)

``process`` keeps state between calls (the absolute row index and, for error
diffusion, the error rows still to be diffused), so an image halftoned in bands
of any heights gives exactly the same bits as in one call.  One ``Halftoner``
per image (or per page): it is not meant to be called from two threads at once.

Methods (``METHODS``)
---------------------
``vced`` (the default), ``vector``: variable-coefficient error diffusion with
threshold modulation (rip/diffusion.py: Zhou-Fang's weights, the next pixel's
weight x 1.15 for the 300 x 370.5 grid, a blue-noise modulation from
``bluenoise256.npy`` tuned per level to leave no periodic structure).  ``vced``
diffuses every ink on its own; ``vector`` decides C and M jointly (at most one
of the two dots where C + M <= 100 %, at least one beyond; the pair's dots form
one blue-noise pattern; which ink a single dot goes to is modulated too), Y and
K on their own.  ``joint`` (rip/joint.py) decides C, M and Y together: a cell gets the floor
or the ceiling of their local sum of coverages in dots (no cell stacked that the coverage
does not force), K as ``vced``.  Serpentine on the absolute row,
integer arithmetic, the error rows kept between bands as for ``fs``: identical
bits for any band split.  Ink 0 never gets a drop, ink 255 always one.

``fs``, ``jarvis``, ``stucki``: error diffusion (Floyd-Steinberg 1976,
Jarvis-Judice-Ninke 1976, Stucki 1981) with a serpentine scan: image rows with
an even *absolute* row index go left to right, odd ones right to left (the
absolute index counts rows since the ``Halftoner`` was made, so the direction
does not depend on the banding).  Arithmetic is integer fixed point, so the
result is bit-exact and platform independent:

* with D = the kernel's divisor (16, 48, 42), error is kept in units of 1/D
  level; a pixel's value is ``V = ink * D + acc`` where ``acc`` is the error
  diffused into it, clamped to ``[-127 D, +127 D]``;
* a drop is placed when ``V >= 128 D`` (i.e. ink + error >= 128), and then
  ``V -= 255 D``;
* the remaining error ``V`` is split as ``e = floor(V / D)`` whole levels
  (for D = 48, 42 computed as ``(V * M) >> 20`` with ``M = round(2**20 / D)``,
  an exact-enough stand-in, since what matters is that it is deterministic)
  and the neighbours get ``w_i * e`` each; the remainder ``V - D e`` goes to
  the next pixel in scan direction, so no error is lost or created except at
  the left/right image edges, where the share that would leave the image is
  dropped;
* because ``|acc| <= 127 D``, ink 0 never gets a drop and ink 255 always gets
  one, pixel by pixel, whatever the neighbourhood and including the edges.

The channels (planes) are independent error-diffusion processes (the same
input in two channels gives the same bits).  ``seed`` does not affect error
diffusion.

``bayer``, ``bluenoise``: ordered dither with a threshold mask of n x n ranks
(N = n*n): the 16x16 recursive Bayer index matrix, or the shipped 256x256
blue-noise screen mask ``resources/masks/screen256.npy`` (void-and-cluster on
the anisotropic device grid, its energy the eye model's coarse-scale filter, see
:mod:`wideprint.rip.bluenoise` and resources/masks/README.md; the 128x128
``bluenoise128.npy`` is the pass masks' tile, rip/swath.py; ``bluenoise256.npy``
the modulation of ``vced`` and ``vector``).  A pixel gets a drop when
``ink * N > rank * 255 + 127``, precomputed as an 8-bit threshold
``T = (rank * 255 + 127) // N`` with ``drop = ink > T``.  So ink 0 gives no
drops, 255 gives all, and a constant ink v gives ``ceil((v N - 127) / 255)``
drops per tile, i.e. round(v N / 255) (the floor or the ceiling of v N / 255).
The tile phase is the absolute row index (kept across bands) and the column
index within the band's width.

Channel layout, ``bluenoise`` (``screen_layout``): channel k reads the mask
shifted by ``(ox_k, oy_k)``, i.e. threshold at (row y, column x) is
``T_k[(y + oy_k) % n, (x + ox_k) % n]``, where ``T_k`` is the mask's threshold
tile for even k and the *inverted* mask's (rank N-1-r) for odd k.  So C and M
(and Y and K) are complementary: C's dots are the mask's lowest ranks, M's its
highest, and where C + M <= 100 % no C dot lands on an M dot (beyond, they
overlap as little as possible, C + M - 100 %).  The pairs are half a tile apart:
(ox, oy) = (0, 0) for C and M, (128, 128) for Y and K, so C and M are
uncorrelated with Y and K (no moire).  With ``seed != 0`` each pair's offset is
drawn from ``numpy.random.default_rng(seed)``.

Channel layout, ``bayer`` (``mask_offsets``): channel ``k`` reads the matrix
shifted by ``(ox_k, oy_k)``.  With ``seed=0`` (the default)::

    ox_k = (n * k // 4 + 17 * k) % n
    oy_k = (n * k // 2 + 17 * (k // 2)) % n

For the 16x16 Bayer tile it is (0,0), (5,8), (10,1), (15,9), whose phases mod 2
are the four different (0|1, 0|1): at 25 % ink the four channels' lattices are
disjoint (dot beside dot, not dot on dot); at exactly 50 % Bayer has only two
checkerboards, so channels 0 and 3 and channels 1 and 2 coincide there while 0
and 1 are complementary.  With ``seed != 0`` the offsets are drawn from
``numpy.random.default_rng(seed).integers(0, n, size=(channels, 2))`` as
``(ox_k, oy_k)`` rows.

Speed: the kernels are numba functions (rip/compiled.py: compiled at install, nogil), no Python
per pixel.  Work is split over a small shared ``ThreadPoolExecutor`` (2
workers, the machine has 2 cores): error diffusion of CMYK (``fs``, ``vced``) runs
the four planes in one loop on one thread (four dependency chains overlap: less
CPU than two loops of two planes on two threads, and no longer, as the RIP's
other stages run beside it); other error diffusions give each worker a group
of planes (one kernel call loops over its planes), ordered dither gives each
worker a block of rows.  Measured against numba ``prange`` over planes on
8000x2000x4 FS: about the same (medians within a few %; the machine is noisy).
Threads were kept because they do not depend on numba's threading layer
(the workqueue fallback aborts when two Python threads launch parallel
kernels at once, GNU OpenMP is not fork-safe); the pool is remade in a forked
child.  Bands below 64 k pixel-planes run in the calling thread.  See
``bench/halftone_bench.py`` for figures.
"""

from __future__ import annotations

import functools

import numpy as np

from .compiled import kernel
# the masks (read once, checked) and the serpentine scan shared with rip/diffusion.py live
# in modules of their own; re-exported here, where they always were
from .masks import (BLUENOISE_PATH, MASKS, MODULATION_PATH, SCREEN_PATH,  # noqa: F401
                    load_bluenoise_mask, load_modulation_mask, load_screen_mask,
                    modulation_noise)
from .parallel import WORKERS, run_parallel
from .serpentine import _end_row, _rows4, _serpentine  # noqa: F401

__all__ = ["METHODS", "Halftoner", "bayer_matrix", "load_bluenoise_mask", "load_modulation_mask",
           "load_screen_mask", "mask_offsets", "screen_layout", "threshold_tile"]

from .settings import METHODS, ORDERED  # noqa: E402 - declared with the settings schema
ERROR_DIFFUSION = tuple(m for m in METHODS if m not in ORDERED)

#: error diffusion with variable coefficients (rip/diffusion.py): independent channels, and
#: colour-aware pairs (C with M, Y with K); ``dbs`` refines vced's dots (rip/dbs.py); ``joint``
#: decides C, M and Y together (rip/joint.py)
VARIABLE = ("vced", "vector", "dbs", "joint")

# 5-wide, 3-row diffusion kernels, scan direction left to right, "*" is the
# current pixel:             [*, x+1, x+2], row+1: [x-2..x+2], row+2: [x-2..x+2]
_KERNELS_5X3 = {
    "jarvis": (48, (7, 5), (3, 5, 7, 5, 3), (1, 3, 5, 3, 1)),
    "stucki": (42, (8, 4), (2, 4, 8, 4, 2), (1, 2, 4, 2, 1)),
}
_DIV_SHIFT = 20  # e = (V * M) >> 20, M = round(2**20 / D)

_PAD = 2  # error rows have 2 spare columns at each side for the shares that leave the image

# Parallel work is split only when there is at least this many pixels per call.
_MIN_PARALLEL_PIXELS = 1 << 16


# --------------------------------------------------------------------------
# numba kernels
# --------------------------------------------------------------------------

@kernel(inline="always")
def _fs_step(lvl, a):
    """One pixel of one ink of Floyd-Steinberg (the FS kernels below all take it from here):
    `lvl` the ink level, `a` the error diffused into it (1/16 level), clamped to +-127
    levels.  Returns (dot, the next pixel's share 7/16, e = the error's sixteenths): the
    row below gets 3 e, 5 e and e, the next pixel the rest, so no error is lost."""
    v = np.int64(lvl) * 16 + min(max(a, -2032), 2032)     # 127 * 16
    dot = ((v - 2048) >> 63) + 1                          # 1 if v >= 128*16 else 0, branch-free
    v -= dot * 4080
    e = v >> 4
    return dot, e * 7 + (v - (e << 4)), e


@kernel()
def _fs_plane(src, dst, err, row0):  # pragma: no cover - compiled
    """Floyd-Steinberg, serpentine, integer.  src/dst: (rows, width) uint8 views,
    err: (2, width + 4) int32 ring of error rows (units of 1/16 level) indexed by
    absolute row & 1; row0: absolute index of src[0]."""
    rows, width = src.shape
    for i in range(rows):
        r = row0 + i
        cur = err[r & 1]
        nxt = err[(r + 1) & 1]  # all zero here: it was cleared after its last use
        carry = 0  # share of the previous pixel's error for this pixel
        s1 = 0  # pending total for the row-below cell behind the current pixel
        s0 = 0  # pending total for the row-below cell under the current pixel
        if (r & 1) == 0:
            for x in range(width):
                p = x + 2
                dot, carry, e = _fs_step(src[i, x], cur[p] + carry)
                dst[i, x] = dot
                nxt[p - 1] = s1 + 3 * e
                s1 = s0 + 5 * e
                s0 = e
            nxt[width + 1] = s1
        else:
            for x in range(width - 1, -1, -1):
                p = x + 2
                dot, carry, e = _fs_step(src[i, x], cur[p] + carry)
                dst[i, x] = dot
                nxt[p + 1] = s1 + 3 * e
                s1 = s0 + 5 * e
                s0 = e
            nxt[2] = s1
        cur[:] = 0


@kernel()
def _fs_two(src3, dst3, err3, row0, c):  # pragma: no cover - compiled
    """`_fs_plane` on planes c and c + 1 of (rows, width, channels) src3/dst3 in one loop,
    err3 (channels, 2, width + 4): the same arithmetic for each plane, bit for bit, but the
    two planes' error chains are independent, so the CPU overlaps them (one plane's loop is
    bound by the latency of its carry): 1.25-1.3x the throughput of one plane after the
    other (8,000 x 1,000 x 4 on one core: 0.112-0.130 -> 0.086-0.106 s)."""
    rows, width = src3.shape[0], src3.shape[1]
    ea = err3[c]
    eb = err3[c + 1]
    for i in range(rows):
        r = row0 + i
        cura, nxta = ea[r & 1], ea[(r + 1) & 1]
        curb, nxtb = eb[r & 1], eb[(r + 1) & 1]
        carrya = carryb = 0
        s1a = s0a = s1b = s0b = 0
        back = r & 1                     # serpentine: odd rows right to left
        d = 1 - 2 * back                 # the scan's step; the row below gets shares at p - d
        for k in range(width):
            x = k + back * (width - 1 - 2 * k)
            p = x + 2
            dot, carrya, e = _fs_step(src3[i, x, c], cura[p] + carrya)
            dotb, carryb, f = _fs_step(src3[i, x, c + 1], curb[p] + carryb)
            dst3[i, x, c] = dot
            dst3[i, x, c + 1] = dotb
            nxta[p - d] = s1a + 3 * e
            nxtb[p - d] = s1b + 3 * f
            s1a = s0a + 5 * e
            s1b = s0b + 5 * f
            s0a = e
            s0b = f
        _end_row(cura, nxta, s1a, width, d == 1)
        _end_row(curb, nxtb, s1b, width, d == 1)


@kernel()
def _fs_four(src3, dst3, err3, row0):  # pragma: no cover - compiled
    """`_fs_plane` on the four planes of (rows, width, 4) src3/dst3 in one loop, bit for bit:
    four independent error chains for the CPU to overlap.  CMYK bands go through it on one
    thread rather than through `_fs_two` on two: less CPU and a shorter whole command, as the
    RIP's other stages run beside it (`rip -o --dither fs`, 12,000 x 4,000: RGB 0.89-1.04 ->
    0.84-0.88 s, 1.4-1.5 -> 1.2-1.25 CPU-s; CMYK 0.77-0.82 -> 0.64-0.68 s)."""
    rows, width = src3.shape[0], src3.shape[1]
    u1, u2, u3, u4 = np.uint64(1), np.uint64(2), np.uint64(3), np.uint64(4)
    for i in range(rows):
        r = row0 + i
        srow = src3[i].reshape(-1)
        drow = dst3[i].reshape(-1)
        c0, n0, c1, n1, c2, n2, c3, n3 = _rows4(err3, r)
        k0 = k1 = k2 = k3 = 0
        s10 = s11 = s12 = s13 = 0
        s00 = s01 = s02 = s03 = 0
        fwd = (r & 1) == 0
        for k in range(width):
            x, p, q = _serpentine(k, width, fwd)
            o = x * u4
            d0, k0, e0 = _fs_step(srow[o], c0[p] + k0)
            d1, k1, e1 = _fs_step(srow[o + u1], c1[p] + k1)
            d2, k2, e2 = _fs_step(srow[o + u2], c2[p] + k2)
            d3, k3, e3 = _fs_step(srow[o + u3], c3[p] + k3)
            drow[o] = d0
            drow[o + u1] = d1
            drow[o + u2] = d2
            drow[o + u3] = d3
            n0[q] = s10 + 3 * e0
            n1[q] = s11 + 3 * e1
            n2[q] = s12 + 3 * e2
            n3[q] = s13 + 3 * e3
            s10, s11, s12, s13 = s00 + 5 * e0, s01 + 5 * e1, s02 + 5 * e2, s03 + 5 * e3
            s00, s01, s02, s03 = e0, e1, e2, e3
        _end_row(c0, n0, s10, width, fwd)
        _end_row(c1, n1, s11, width, fwd)
        _end_row(c2, n2, s12, width, fwd)
        _end_row(c3, n3, s13, width, fwd)


@kernel()
def _fs_planes(src, dst, err, row0, c0, c1):  # pragma: no cover - compiled
    """Planes c0..c1-1 of (rows, width, channels) src/dst; err (channels, 2, width + 4):
    two at a time where it can (`_fs_two`), the last odd one alone."""
    c = c0
    while c + 1 < c1:
        _fs_two(src, dst, err, row0, c)
        c += 2
    if c < c1:
        _fs_plane(src[:, :, c], dst[:, :, c], err[c], row0)


def _make_ed5x3(D, row0, row1, row2):
    """Compile-on-demand 5x3 error-diffusion kernel (Jarvis-Judice-Ninke, Stucki)
    with the weights baked in as constants (numba freezes closure variables;
    that measured ~1.4x faster than passing the weights as arguments, and the
    on-disk cache keys closures by their cell values, so each kernel caches).

    Kernel (src3, dst3, err3, row0, cfirst, cend) processes planes cfirst..cend-1:
    src3/dst3 (rows, width, channels) uint8; err3 (channels, 3, width + 4)
    int32, per plane a ring of error rows in units of 1/D level, indexed by
    absolute row % 3; row0 the absolute index of src3[0].  Weights are given
    for a left-to-right scan: current row x+1, x+2 = row0; next row x-2..x+2 =
    row1; the row after that x-2..x+2 = row2.  Right-to-left rows mirror them.
    """
    w01, w02 = row0
    w1a, w1b, w1c, w1d, w1e = row1
    w2a, w2b, w2c, w2d, w2e = row2
    if w01 + w02 + sum(row1) + sum(row2) != D:
        raise ValueError("diffusion weights must sum to the divisor")
    M = int(round((1 << _DIV_SHIFT) / D))  # e = (V * M) >> 20 ~ floor(V / D)
    lim = 127 * D
    thr = 128 * D
    full = 255 * D

    @kernel(variant=f"{D}:{row0}:{row1}:{row2}")
    def ed5x3(src3, dst3, err3, row0, cfirst, cend):  # pragma: no cover - compiled
        rows, width = src3.shape[0], src3.shape[1]
        for c in range(cfirst, cend):
            src = src3[:, :, c]
            dst = dst3[:, :, c]
            err = err3[c]
            for i in range(rows):
                r = row0 + i
                cur = err[r % 3]
                n1 = err[(r + 1) % 3]
                n2 = err[(r + 2) % 3]  # all zero here: it was cleared after its last use
                q1 = 0  # pending share for the next pixel
                q2 = 0  # pending share for the pixel after next
                if (r & 1) == 0:
                    for x in range(width):
                        p = x + 2
                        a = cur[p] + q1
                        a = min(max(a, -lim), lim)
                        v = np.int64(src[i, x]) * D + a
                        dot = ((v - thr) >> 63) + 1  # 1 if v >= 128*D else 0, branch-free
                        dst[i, x] = dot
                        v -= dot * full
                        e = (v * M) >> 20
                        q1 = q2 + w01 * e + (v - e * D)  # the remainder goes to the next pixel
                        q2 = w02 * e
                        n1[p - 2] += w1a * e
                        n1[p - 1] += w1b * e
                        n1[p] += w1c * e
                        n1[p + 1] += w1d * e
                        n1[p + 2] += w1e * e
                        n2[p - 2] += w2a * e
                        n2[p - 1] += w2b * e
                        n2[p] += w2c * e
                        n2[p + 1] += w2d * e
                        n2[p + 2] += w2e * e
                else:
                    for x in range(width - 1, -1, -1):
                        p = x + 2
                        a = cur[p] + q1
                        a = min(max(a, -lim), lim)
                        v = np.int64(src[i, x]) * D + a
                        dot = ((v - thr) >> 63) + 1
                        dst[i, x] = dot
                        v -= dot * full
                        e = (v * M) >> 20
                        q1 = q2 + w01 * e + (v - e * D)
                        q2 = w02 * e
                        n1[p + 2] += w1a * e
                        n1[p + 1] += w1b * e
                        n1[p] += w1c * e
                        n1[p - 1] += w1d * e
                        n1[p - 2] += w1e * e
                        n2[p + 2] += w2a * e
                        n2[p + 1] += w2b * e
                        n2[p] += w2c * e
                        n2[p - 1] += w2d * e
                        n2[p - 2] += w2e * e
                cur[:] = 0

    return ed5x3


_ED5X3_PLANES = {name: _make_ed5x3(*k) for name, k in _KERNELS_5X3.items()}


@kernel()
def _ordered_rows(src, dst, thr, row0):  # pragma: no cover - compiled
    """Ordered dither.  src/dst: (rows, width * channels) C-contiguous uint8;
    thr: (n, n * channels) uint8 thresholds, channel-interleaved, per-channel
    offsets already applied; row0: absolute row of src[0].  drop = ink > thr."""
    rows, length = src.shape
    n, period = thr.shape
    for i in range(rows):
        t = thr[(row0 + i) % n]
        s = src[i]
        d = dst[i]
        for x0 in range(0, length, period):
            m = min(period, length - x0)
            for j in range(m):
                d[x0 + j] = np.uint8(s[x0 + j] > t[j])


# --------------------------------------------------------------------------
# masks
# --------------------------------------------------------------------------

def bayer_matrix(n: int = 16) -> np.ndarray:
    """Recursive Bayer index matrix of side n (a power of two): ranks 0..n*n-1."""
    if n < 1 or n & (n - 1):
        raise ValueError("Bayer matrix size must be a power of two")
    m = np.zeros((1, 1), dtype=np.int64)
    while m.shape[0] < n:
        m = np.block([[4 * m, 4 * m + 2], [4 * m + 3, 4 * m + 1]])
    return m.astype(np.uint16)


def mask_offsets(size: int, channels: int, seed: int = 0) -> np.ndarray:
    """(channels, 2) array of per-channel mask offsets (ox, oy); see module docstring."""
    if seed == 0:
        k = np.arange(channels, dtype=np.int64)
        ox = (size * k // 4 + 17 * k) % size
        oy = (size * k // 2 + 17 * (k // 2)) % size
        return np.stack([ox, oy], axis=1)
    return np.random.default_rng(seed).integers(0, size, size=(channels, 2)).astype(np.int64)


def screen_layout(size: int, channels: int, seed: int = 0) -> tuple[np.ndarray, np.ndarray]:
    """The blue-noise screen's channel layout: (channels, 2) offsets (ox, oy) and (channels,)
    inversion flags.  Channels come in pairs (C with M, Y with K, ...): the second of a pair
    reads the *inverted* mask (rank N-1-r) at the same offset, so where the pair's inks sum to
    at most full coverage their dots never coincide (C's dots are the mask's lowest ranks, M's
    its highest), and beyond that they overlap as little as possible; pair j reads the mask
    shifted by (ox, oy) = (j n/2 + 37 (j//2), j n/2 + 53 (j//2)) mod n, so C and M are
    uncorrelated with Y and K (half a tile apart).  ``seed != 0``: the pairs' offsets are drawn
    from ``numpy.random.default_rng(seed)`` instead."""
    k = np.arange(channels, dtype=np.int64)
    pair = k // 2
    if seed == 0:
        ox = (size // 2 * pair + 37 * (pair // 2)) % size
        oy = (size // 2 * pair + 53 * (pair // 2)) % size
        offsets = np.stack([ox, oy], axis=1)
    else:
        drawn = np.random.default_rng(seed).integers(0, size, size=((channels + 1) // 2, 2))
        offsets = drawn[pair].astype(np.int64)
    invert = k % 2 == 1
    return offsets, invert


def threshold_tile(ranks: np.ndarray) -> np.ndarray:
    """8-bit thresholds T for a rank mask: drop iff ink > T  <=>  ink*N > rank*255 + 127."""
    n_ranks = ranks.size
    return ((ranks.astype(np.int64) * 255 + 127) // n_ranks).astype(np.uint8)


# --------------------------------------------------------------------------
# thread pool
# --------------------------------------------------------------------------

# The shared pool lives in rip/parallel.py.  (Submitting every job, rather than running one
# in the calling thread, measured ~15 % faster for 4-plane error diffusion.)
_run_parallel = run_parallel


# --------------------------------------------------------------------------
# Halftoner
# --------------------------------------------------------------------------

class Halftoner:
    """Stateful band halftoner; see the module docstring for the algorithms."""

    def __init__(self, method: str, width: int, channels: int = 4, seed: int = 0):
        if method not in METHODS:
            raise ValueError(f"unknown halftone method {method!r}; valid methods: {', '.join(METHODS)}")
        width = int(width)
        channels = int(channels)
        if width < 1:
            raise ValueError(f"width must be >= 1, got {width}")
        if channels < 1:
            raise ValueError(f"channels must be >= 1, got {channels}")
        self.method = method
        self.width = width
        self.channels = channels
        self.seed = int(seed)
        self.row = 0  # absolute index of the next row to be processed

        if method == "fs":
            self._err = np.zeros((channels, 2, width + 2 * _PAD), dtype=np.int32)
        elif method in _KERNELS_5X3:
            self._err = np.zeros((channels, 3, width + 2 * _PAD), dtype=np.int32)
        elif method in VARIABLE:
            from .diffusion import VCDiffuser
            from .joint import JointDiffuser
            vc: VCDiffuser | JointDiffuser = (
                JointDiffuser(width, channels, modulation_noise()) if method == "joint" else
                VCDiffuser(width, channels, modulation_noise(), joint=method == "vector"))
            self._vc = vc
            self._err = self._vc.err
            if method == "dbs":
                from .dbs import RowDBS
                self._dbs = RowDBS(width, channels, self._vc.noise, self._vc.offsets)
        else:
            if method == "bayer":
                ranks = bayer_matrix(16)
                n = ranks.shape[0]
                self.offsets = mask_offsets(n, channels, self.seed)
                self.inverted = np.zeros(channels, dtype=bool)
            else:
                ranks = load_screen_mask()
                n = ranks.shape[0]
                self.offsets, self.inverted = screen_layout(n, channels, self.seed)
            self.mask_size = n
            t = threshold_tile(ranks)
            t_inv = threshold_tile((ranks.size - 1 - ranks.astype(np.int64)))
            tile = np.empty((n, n, channels), dtype=np.uint8)
            for k, (ox, oy) in enumerate(self.offsets):
                tk = t_inv if self.inverted[k] else t
                tile[:, :, k] = np.roll(tk, (-int(oy), -int(ox)), axis=(0, 1))  # tile[y, x] = t[y+oy, x+ox]
            self._thr = np.ascontiguousarray(tile.reshape(n, n * channels))

    @property
    def thresholds(self) -> np.ndarray:
        """Ordered methods: (n, n * channels) uint8 thresholds, channel-interleaved, the
        per-channel offsets applied; row y of the image uses row y mod n (drop = ink > T)."""
        return self._thr

    def __repr__(self) -> str:
        return (f"Halftoner(method={self.method!r}, width={self.width}, channels={self.channels}, "
                f"seed={self.seed}, row={self.row})")

    def _check(self, band: np.ndarray) -> np.ndarray:
        if not isinstance(band, np.ndarray):
            raise ValueError(f"band must be a numpy array, got {type(band).__name__}")
        if band.dtype != np.uint8:
            raise ValueError(f"band must be uint8, got {band.dtype}")
        if band.ndim != 3 or band.shape[1] != self.width or band.shape[2] != self.channels:
            raise ValueError(f"band must have shape (rows, {self.width}, {self.channels}), got {band.shape}")
        return band

    def process(self, band: np.ndarray) -> np.ndarray:
        """band: uint8 (rows, width, channels), C-contiguous or not, ink amount 0..255 (255 = full ink).
        Returns uint8 (rows, width, channels) with values 0/1 (1 = a drop). State carries across calls,
        so halftoning an image in bands of ANY heights gives exactly the same bits as in one call."""
        band = self._check(band)
        rows = band.shape[0]
        out = np.empty((rows, self.width, self.channels), dtype=np.uint8)
        if rows == 0:
            return out
        row0 = self.row
        parallel = rows * self.width * self.channels >= _MIN_PARALLEL_PIXELS

        if self.method in ORDERED:
            src = np.ascontiguousarray(band).reshape(rows, self.width * self.channels)
            dst = out.reshape(rows, self.width * self.channels)
            thr = self._thr
            parts = min(WORKERS, rows) if parallel else 1
            bounds = np.linspace(0, rows, parts + 1).astype(int)
            _run_parallel(
                functools.partial(_ordered_rows, src[a:b], dst[a:b], thr, row0 + a)
                for a, b in zip(bounds[:-1], bounds[1:]) if b > a
            )
        elif self.method in VARIABLE:
            groups = WORKERS if parallel else 1
            if groups > 1:
                out.reshape(-1)[::4096] = 0   # fault the pages in here (see below)
            src = band if band.flags.c_contiguous else np.ascontiguousarray(band)
            self._vc.row = row0
            _run_parallel(self._vc.jobs(src, out, groups))
            self._vc.row = row0 + rows
            if self.method == "dbs":        # vced's dots refined row by row (rip/dbs.py)
                _run_parallel(self._dbs.jobs(src, out, row0, groups))
        elif self.method == "fs" and self.channels == 4:
            # one loop of four inks on one thread (see `_fs_four`)
            _fs_four(band if band.flags.c_contiguous else np.ascontiguousarray(band), out, self._err, row0)
        else:
            kernel = _fs_planes if self.method == "fs" else _ED5X3_PLANES[self.method]
            groups = min(WORKERS, self.channels) if parallel else 1
            if groups > 1:
                # Fault the fresh output pages in here: otherwise both workers,
                # writing interleaved planes, fault the same pages at once
                # (measured ~7 % slower for 8000x2000x4).
                out.reshape(-1)[::4096] = 0
            bounds = np.linspace(0, self.channels, groups + 1).astype(int)
            _run_parallel(
                functools.partial(kernel, band, out, self._err, row0, int(a), int(b))
                for a, b in zip(bounds[:-1], bounds[1:]) if b > a
            )
        self.row = row0 + rows
        return out
