"""Blue-noise threshold mask generator: void-and-cluster (Ulichney 1993).

The mask is an ``(n, n)`` array of *ranks*: a permutation of ``0 .. n*n-1``.
Thresholding it at any level ``k`` (taking the pixels whose rank is ``< k``)
gives a binary pattern of ``k`` dots that is spread evenly over the tile with
no low-frequency structure ("blue noise"), and the tile wraps seamlessly
(everything is computed on a torus).  :mod:`wideprint.rip.halftone` turns the
ranks into per-pixel thresholds.

Algorithm (all energies are the binary pattern convolved, circularly, with a
Gaussian of ``sigma`` = 1.5 pixels):

1. *Initial pattern*: ``n*n // 10`` ones at random positions (``seed`` picks
   them), then relaxed: repeatedly move the one in the tightest cluster
   (highest energy among ones) to the largest void (lowest energy among
   zeros) until the move would put it back where it came from.
2. *Phase 1*: from the relaxed pattern, repeatedly remove the tightest cluster;
   the ones get ranks ``ones-1`` down to ``0`` in removal order.
3. *Phases 2 and 3*: from the relaxed pattern, repeatedly fill the largest void
   with ranks ``ones .. n*n-1``.  (Ulichney's phase 3, "tightest cluster of
   zeros", is the same pixel as "largest void of ones" because the zeros'
   energy is ``sum(G) - energy``, so one rule serves both.)

The energy map is computed once with an FFT and then updated incrementally
with a pre-rolled copy of the periodic Gaussian kernel, so each of the ``n*n``
rank steps is a handful of vectorised numpy operations (under a second for
128x128 here).
Ties are broken by the lowest flat index (``argmax``/``argmin``), so the
result is deterministic for a given ``size``, ``sigma`` and ``seed``.

Usage::

    python -m wideprint.rip.bluenoise --size 128 --out resources/masks/bluenoise128.npy
    python -m wideprint.rip.bluenoise --screen --size 256 --out resources/masks/screen256.npy

``screen_mask`` is the same algorithm compiled, on the anisotropic device grid and with a
second, wide Gaussian in the energy (the screen); ``level_noise`` and ``nested_bound``
measure a mask against the eye model of bench/hvs.py and against what no threshold mask
can beat.
"""

from __future__ import annotations

import argparse
import math
import sys
import time
from pathlib import Path

import numpy as np

DEFAULT_SIZE = 128
DEFAULT_SIGMA = 1.5
DEFAULT_SEED = 0


def torus_gaussian(size: int, sigma: float) -> np.ndarray:
    """Periodic Gaussian kernel of shape (size, size) centred on (0, 0)."""
    d = np.arange(size)
    d = np.minimum(d, size - d).astype(np.float64)  # toroidal distance to 0
    g1 = np.exp(-(d * d) / (2.0 * sigma * sigma))
    return np.outer(g1, g1)


def _energy(pattern: np.ndarray, kernel_fft: np.ndarray) -> np.ndarray:
    """Circular convolution of a binary pattern with the kernel (via FFT)."""
    return np.fft.irfft2(np.fft.rfft2(pattern.astype(np.float64)) * kernel_fft, s=pattern.shape)


class _Field:
    """A binary pattern on a torus with its Gaussian energy kept up to date."""

    def __init__(self, pattern: np.ndarray, kernel: np.ndarray):
        self.size = pattern.shape[0]
        self.kernel = kernel
        self.pattern = pattern.copy()
        self.energy = _energy(pattern, np.fft.rfft2(kernel))
        # kernel rolled to every row (then rolled by column on demand): a
        # (size, size, size) cache would be 16 MB for 128; rolling per step is
        # cheap enough and keeps memory small.

    def _kernel_at(self, idx: int) -> np.ndarray:
        y, x = divmod(idx, self.size)
        return np.roll(self.kernel, (y, x), axis=(0, 1))

    def set(self, idx: int, value: bool) -> None:
        flat = self.pattern.reshape(-1)
        if bool(flat[idx]) == value:
            raise AssertionError("pixel already in that state")
        flat[idx] = value
        if value:
            self.energy += self._kernel_at(idx)
        else:
            self.energy -= self._kernel_at(idx)

    def tightest_cluster(self) -> int:
        e = np.where(self.pattern, self.energy, -np.inf)
        return int(np.argmax(e))

    def largest_void(self) -> int:
        e = np.where(self.pattern, np.inf, self.energy)
        return int(np.argmin(e))


def void_and_cluster(size: int = DEFAULT_SIZE, sigma: float = DEFAULT_SIGMA,
                     seed: int = DEFAULT_SEED, initial_fraction: float = 0.1) -> np.ndarray:
    """Return a (size, size) uint16/uint32 rank mask, a permutation of 0..size*size-1."""
    if size < 2:
        raise ValueError("size must be >= 2")
    n_pix = size * size
    kernel = torus_gaussian(size, sigma)
    rng = np.random.default_rng(seed)

    ones = max(1, int(n_pix * initial_fraction))
    pattern = np.zeros((size, size), dtype=bool)
    pattern.reshape(-1)[rng.choice(n_pix, size=ones, replace=False)] = True

    # 1. relax the initial pattern
    field = _Field(pattern, kernel)
    for _ in range(100 * n_pix):  # converges in far fewer; a guard, not a tuning knob
        c = field.tightest_cluster()
        field.set(c, False)
        v = field.largest_void()
        if v == c:
            field.set(c, True)
            break
        field.set(v, True)
    else:  # pragma: no cover - would mean the relaxation cycles
        raise RuntimeError("void-and-cluster initial pattern did not converge")
    prototype = field.pattern.copy()

    dtype = np.uint16 if n_pix <= 1 << 16 else np.uint32
    ranks = np.full(n_pix, n_pix, dtype=np.int64)  # n_pix = "not yet ranked"

    # 2. phase 1: remove tightest clusters, ranks ones-1 .. 0
    field = _Field(prototype, kernel)
    for rank in range(ones - 1, -1, -1):
        c = field.tightest_cluster()
        field.set(c, False)
        ranks[c] = rank

    # 3. phases 2+3: fill largest voids, ranks ones .. n_pix-1
    field = _Field(prototype, kernel)
    for rank in range(ones, n_pix):
        v = field.largest_void()
        field.set(v, True)
        ranks[v] = rank

    check_permutation(ranks)
    return ranks.reshape(size, size).astype(dtype)


# --------------------------------------------------------------------------
# the screen mask: void-and-cluster on the anisotropic device grid, compiled
# --------------------------------------------------------------------------

SCREEN_SIZE = 256
SCREEN_SIGMA = 1.5
SCREEN_ASPECT = 370.5 / 300.0   # rows per inch / columns per inch of the device grid
SCREEN_SEED = 0
# plus 0.9 x a Gaussian of 2.5 sqrt(2) px: the autocorrelation of the eye model's coarse blur
# (bench/hvs.py, 2.5 px), so "largest void" is where the pattern's coarse-scale error is most
# negative - the energy the coarse HVS score measures (resources/masks/README.md)
SCREEN_WIDE = 2.5 * np.sqrt(2.0)
SCREEN_WIDE_WEIGHT = 0.9
# the threshold modulation of vced / vector (resources/masks/bluenoise256.npy, the screen
# before): 1.5 px plus 0.3 x a Gaussian of 4 px
MODULATION_WIDE = 4.0
MODULATION_WIDE_WEIGHT = 0.3


def _local_kernel(sigma: float, aspect: float, wide: float = 0.0, wide_weight: float = 0.0) -> np.ndarray:
    """The Gaussian of the energy, truncated where it is below 1e-9 of its peak: sigma
    columns across, sigma * aspect rows along (isotropic in physical units), (2ry+1, 2rx+1);
    plus ``wide_weight`` times a second Gaussian of sigma ``wide`` (if given)."""
    big = max(sigma, wide if wide_weight else 0.0)
    rx = int(np.ceil(big * np.sqrt(2 * np.log(1e9))))
    ry = int(np.ceil(big * aspect * np.sqrt(2 * np.log(1e9))))
    dy = np.arange(-ry, ry + 1, dtype=np.float64)[:, None]
    dx = np.arange(-rx, rx + 1, dtype=np.float64)[None, :]

    # math.exp (the C library's), not np.exp: numpy's SIMD exp differs by an ulp between
    # CPUs (AVX-512 against AVX2), the energies' ties fall the other way, and the shipped
    # masks would no longer be reproducible on every machine.  A few thousand values.
    exp = np.vectorize(math.exp, otypes=[np.float64])

    def g(s):
        return exp(-(dx * dx) / (2 * s * s) - (dy * dy) / (2 * (s * aspect) ** 2))
    k = g(sigma)
    if wide and wide_weight:
        k = k + wide_weight * g(wide)
    return k


def _vac_compiled():
    from numba import njit

    @njit(cache=True)
    def add(energy, k, y, x, sign):  # pragma: no cover - compiled
        h, w = energy.shape
        ky, kx = k.shape
        ry, rx = ky // 2, kx // 2
        for j in range(ky):
            yy = (y + j - ry) % h
            for i in range(kx):
                energy[yy, (x + i - rx) % w] += sign * k[j, i]

    @njit(cache=True)
    def extreme(energy, pattern, want_one):  # pragma: no cover - compiled
        """Tightest cluster (max energy among ones) or largest void (min among zeros);
        ties: the lowest flat index."""
        best = -1
        bv = 0.0
        flat_e = energy.reshape(-1)
        flat_p = pattern.reshape(-1)
        for idx in range(flat_e.size):
            if flat_p[idx] == want_one:
                v = flat_e[idx]
                if best < 0 or (want_one and v > bv) or ((not want_one) and v < bv):
                    best = idx
                    bv = v
        return best

    @njit(cache=True)
    def run(pattern, k, ones):  # pragma: no cover - compiled
        h, w = pattern.shape
        n = h * w
        energy = np.zeros((h, w))
        for idx in range(n):
            if pattern.reshape(-1)[idx]:
                add(energy, k, idx // w, idx % w, 1.0)
        # 1. relax: move the tightest cluster to the largest void until it stays
        for _ in range(100 * n):
            c = extreme(energy, pattern, True)
            pattern.reshape(-1)[c] = False
            add(energy, k, c // w, c % w, -1.0)
            v = extreme(energy, pattern, False)
            pattern.reshape(-1)[v] = True
            add(energy, k, v // w, v % w, 1.0)
            if v == c:
                break
        ranks = np.full(n, n, np.int64)
        proto = pattern.copy()
        e0 = energy.copy()
        # 2. phase 1: remove tightest clusters, ranks ones-1 .. 0
        for rank in range(ones - 1, -1, -1):
            c = extreme(energy, pattern, True)
            pattern.reshape(-1)[c] = False
            add(energy, k, c // w, c % w, -1.0)
            ranks[c] = rank
        # 3. phases 2 and 3: fill largest voids, ranks ones .. n-1
        pattern[:, :] = proto
        energy[:, :] = e0
        for rank in range(ones, n):
            v = extreme(energy, pattern, False)
            pattern.reshape(-1)[v] = True
            add(energy, k, v // w, v % w, 1.0)
            ranks[v] = rank
        return ranks

    return run


def screen_mask(size: int = SCREEN_SIZE, sigma: float = SCREEN_SIGMA,
                aspect: float = SCREEN_ASPECT, seed: int = SCREEN_SEED,
                initial_fraction: float = 0.1, wide: float = SCREEN_WIDE,
                wide_weight: float = SCREEN_WIDE_WEIGHT) -> np.ndarray:
    """Void-and-cluster rank mask for the device grid: the energy's Gaussian is sigma
    columns across and sigma * aspect rows along, so the dots are evenly spread in
    *physical* distance on the 300 x 370.5 dpi grid (a square-pixel mask is squeezed along
    the feed there), plus ``wide_weight`` x a Gaussian of ``wide`` (both peak 1).  Otherwise
    as ``void_and_cluster`` (compiled: 15-60 s for 256)."""
    if size < 2:
        raise ValueError("size must be >= 2")
    n = size * size
    rng = np.random.default_rng(seed)
    ones = max(1, int(n * initial_fraction))
    pattern = np.zeros((size, size), dtype=np.bool_)
    pattern.reshape(-1)[rng.choice(n, size=ones, replace=False)] = True
    k = _local_kernel(sigma, aspect, wide, wide_weight)
    if k.shape[0] > size or k.shape[1] > size:
        raise ValueError("sigma too large for the mask size")
    ranks = _vac_compiled()(pattern, k, ones)
    check_permutation(ranks)
    return ranks.reshape(size, size).astype(np.uint16 if n <= 1 << 16 else np.uint32)


def modulation_mask() -> np.ndarray:
    """The rank mask vced / vector read as their threshold modulation
    (resources/masks/bluenoise256.npy): ``screen_mask`` with the 4 px wide term."""
    return screen_mask(wide=MODULATION_WIDE, wide_weight=MODULATION_WIDE_WEIGHT)


# --------------------------------------------------------------------------
# how good a threshold mask can be: every level's coarse noise, and the bound
# --------------------------------------------------------------------------

def _blur_response(shape: tuple[int, int], sigma: float, aspect: float) -> np.ndarray:
    """Frequency response of the eye model's Gaussian (bench/hvs.py) on a periodic tile."""
    fy = np.fft.fftfreq(shape[0])[:, None]
    fx = np.fft.fftfreq(shape[1])[None, :]
    return np.exp(-2 * np.pi ** 2 * ((sigma * fx) ** 2 + (sigma * aspect * fy) ** 2))


def level_noise(ranks: np.ndarray, sigma: float, aspect: float = SCREEN_ASPECT) -> np.ndarray:
    """(254,) RMS of the blurred error (dots - ink) of the tile's flat tint at every ink level
    1..254 as the screen thresholds it (``rank * 255 + 127 < ink * N``), on the torus: the
    noise a viewer sees at that blur (sigma columns across, sigma * aspect rows along)."""
    r = np.asarray(ranks, np.int64)
    n_pix = r.size
    thr = (r * 255 + 127) // n_pix
    g = _blur_response(r.shape, sigma, aspect)
    out = np.empty(254)
    for v in range(1, 255):
        e = (thr < v).astype(np.float64)
        e -= e.mean()
        b = np.fft.ifft2(np.fft.fft2(e) * g).real
        out[v - 1] = np.sqrt(np.mean(b * b))
    return out


def nested_bound(sigma: float, aspect: float = SCREEN_ASPECT, size: int = SCREEN_SIZE) -> float:
    """Lower bound on the RMS over ink levels of ``level_noise`` for *any* threshold mask.

    A threshold mask's patterns are nested: raising the ink only adds dots.  Follow one
    pixel x through the levels: its blurred error s(x) falls steadily (the tint's mean
    rises by 1 per unit of ink; the blur sums to 1) and jumps up by g(x - y) whenever a
    pixel y turns on, and every pixel turns on exactly once.  A path that falls at slope 1
    must fall back through every value a jump passed over, so the time spent at |s| = u
    is at least the number of jumps across u, and the mean of s^2 over the levels is at
    least sum_k h_k^3 / 12 (each jump of h best centred on 0: the integral of u^2 over
    [-h/2, h/2]).  Hence mean_levels(noise^2) >= sum_y g(y)^3 / 12 at every pixel, whatever
    the order - the price of the stacking constraint.  (Continuous levels; the 255 steps
    only add.)  A single pattern, free of it, can go far below (direct binary search,
    error diffusion); resources/masks/README.md has the figures."""
    g = np.fft.ifft2(_blur_response((size, size), sigma, aspect)).real
    return float(np.sqrt(np.sum(g ** 3) / 12.0))


def check_permutation(ranks: np.ndarray) -> None:
    """Raise ValueError unless ``ranks`` holds every value 0..ranks.size-1 exactly once."""
    flat = np.asarray(ranks).reshape(-1).astype(np.int64)
    if flat.size == 0 or flat.min() < 0 or flat.max() >= flat.size:
        raise ValueError("mask values out of range 0..N-1")
    if np.bincount(flat, minlength=flat.size).max() != 1:
        raise ValueError("mask is not a permutation of 0..N-1")


def main(argv: list[str] | None = None) -> int:
    ap = argparse.ArgumentParser(prog="python -m wideprint.rip.bluenoise",
                                 description="Generate a void-and-cluster blue-noise rank mask (.npy).")
    ap.add_argument("--size", type=int, default=DEFAULT_SIZE, help="tile side in pixels (default 128)")
    ap.add_argument("--sigma", type=float, default=DEFAULT_SIGMA, help="Gaussian filter sigma (default 1.5)")
    ap.add_argument("--seed", type=int, default=DEFAULT_SEED, help="seed of the initial random pattern (default 0)")
    ap.add_argument("--screen", action="store_true",
                    help="the screen mask: compiled void-and-cluster on the device grid "
                         "(--aspect, default 370.5/300; resources/masks/screen256.npy is "
                         "--screen --size 256 --sigma 1.5 --seed 0, bluenoise256.npy the same "
                         "with --wide 4 --wide-weight 0.3)")
    ap.add_argument("--aspect", type=float, default=SCREEN_ASPECT,
                    help="with --screen: rows per column of equal physical length")
    ap.add_argument("--wide", type=float, default=SCREEN_WIDE,
                    help="with --screen: sigma of the second, wide Gaussian (default 2.5 x sqrt 2)")
    ap.add_argument("--wide-weight", type=float, default=SCREEN_WIDE_WEIGHT,
                    help="with --screen: its weight (default 0.9; 0: a single Gaussian)")
    ap.add_argument("--out", type=Path, required=True, help="output .npy path")
    args = ap.parse_args(argv)

    t0 = time.perf_counter()
    if args.screen:
        mask = screen_mask(args.size, args.sigma, args.aspect, args.seed, wide=args.wide,
                           wide_weight=args.wide_weight)
    else:
        mask = void_and_cluster(args.size, args.sigma, args.seed)
    dt = time.perf_counter() - t0
    args.out.parent.mkdir(parents=True, exist_ok=True)
    np.save(args.out, mask)
    print(f"wrote {args.out}: {mask.shape} {mask.dtype}, ranks 0..{mask.size - 1}, "
          f"sigma={args.sigma}, seed={args.seed}"
          f"{f', aspect={args.aspect:.6g}, wide={args.wide:g} x {args.wide_weight:g}' if args.screen else ''}"
          f", {dt:.1f} s")
    return 0


if __name__ == "__main__":
    sys.exit(main())
