"""The shipped threshold masks (resources/masks/, README there): the pass masks' 128x128
blue-noise tile, the ``bluenoise`` screen's 256x256 mask and the modulation mask of ``vced``
/ ``vector``; each read once, checked to be a permutation of its ranks, read-only.

Used by rip/halftone.py (the screens, the diffusion's modulation) and by rip/diffusion.py's
offline tuning; rip/halftone.py re-exports every name here."""

from __future__ import annotations

import functools
import os
from pathlib import Path

import numpy as np

MASKS = Path(__file__).resolve().parent.parent / "resources" / "masks"
BLUENOISE_PATH = MASKS / "bluenoise128.npy"       # the pass masks' tile (rip/swath.py)
SCREEN_PATH = MASKS / "screen256.npy"             # the bluenoise screen
MODULATION_PATH = MASKS / "bluenoise256.npy"      # vced's and vector's threshold modulation


@functools.lru_cache(maxsize=None)
def _bluenoise_cached(path: str) -> np.ndarray:
    mask = np.load(path, allow_pickle=False)
    if mask.ndim != 2 or mask.shape[0] != mask.shape[1]:
        raise ValueError(f"{path}: blue-noise mask must be square, got shape {mask.shape}")
    flat = mask.reshape(-1).astype(np.int64)
    if flat.min() < 0 or flat.max() >= flat.size or np.bincount(flat, minlength=flat.size).max() != 1:
        raise ValueError(f"{path}: blue-noise mask is not a permutation of 0..{flat.size - 1}")
    mask = mask.astype(np.uint16 if flat.size <= 1 << 16 else np.uint32)
    mask.setflags(write=False)
    return mask


def load_bluenoise_mask(path: str | os.PathLike | None = None) -> np.ndarray:
    """The shipped 128x128 blue-noise rank mask (read-only, cached): the pass masks' tile."""
    return _bluenoise_cached(str(BLUENOISE_PATH if path is None else path))


def load_screen_mask(path: str | os.PathLike | None = None) -> np.ndarray:
    """The shipped 256x256 screen rank mask (read-only, cached): the ``bluenoise`` screen
    (resources/masks/README.md)."""
    return _bluenoise_cached(str(SCREEN_PATH if path is None else path))


def load_modulation_mask() -> np.ndarray:
    """The shipped 256x256 rank mask of ``vced`` / ``vector``'s threshold modulation
    (read-only, cached; the screen mask before the coarse-scale one, kept because the
    modulation strength is tuned on it)."""
    return _bluenoise_cached(str(MODULATION_PATH))


@functools.lru_cache(maxsize=None)
def modulation_noise() -> np.ndarray:
    """The modulation mask as uint8 noise 0..255 (each value on n*n/256 pixels): the threshold
    modulation of the variable-coefficient error diffusion."""
    ranks = load_modulation_mask().astype(np.int64)
    noise = (ranks * 256 // ranks.size).astype(np.uint8)
    noise.setflags(write=False)
    return noise


# -- pass masks that hide a measured machine's nozzles (issue 36, docs/quality.md) ------------
#: the banding one unit of a row's error makes on the typical machine at 4 passes (ΔL*, eye-
#: weighted; bench/README.md "Banding and grain"): per µm of the row's mean landing error
#: along the feed and per 1 % of its mean drop volume
HIDE_DY_PER_UM = 0.053
HIDE_VOLUME_PER_PCT = 0.038
#: what a nozzle's measured error is uncertain by (the nozzle check's noise and the errors it
#: does not see): µm along the feed, % of volume; it keeps the shares from leaning on one nozzle
HIDE_DY_NOISE_UM = 1.0
HIDE_VOLUME_NOISE_PCT = 1.0
#: the feed's random error per feed (µm) the shares are made robust to: 0, the best measured
#: on the typical machine (3 µm: 0.057 against 0.050, bench/README.md)
HIDE_FEED_NOISE_UM = 0.0


def _supports(n: int) -> list[tuple[int, np.ndarray, np.ndarray]]:
    """Every non-empty subset of n passes, by size k: (k, their bit masks, their members)."""
    if n not in _SUPPORTS:
        by_k: dict[int, list[tuple[int, tuple[int, ...]]]] = {}
        for support in range(1, 1 << n):
            members = tuple(i for i in range(n) if (support >> i) & 1)
            by_k.setdefault(len(members), []).append((support, members))
        _SUPPORTS[n] = [(k, np.array([b for b, _ in v]), np.array([m for _, m in v]))
                        for k, v in sorted(by_k.items())]
    return _SUPPORTS[n]


_SUPPORTS: dict[int, list[tuple[int, np.ndarray, np.ndarray]]] = {}


def _simplex_qp(q: np.ndarray, c: np.ndarray) -> np.ndarray:
    """argmin w'Qw - 2c'w over w >= 0, sum w = 1 (N <= 8: every support tried, KKT on each;
    the supports of one size solved in one batch, 7x faster at 8 passes, the same shares:
    the candidates are compared in the order of their bit masks, as one by one)."""
    n = c.size
    found: list[tuple[int, np.ndarray]] = []
    for k, bits, members in _supports(n):
        m = len(bits)
        kkt = np.zeros((m, k + 1, k + 1))
        kkt[:, :k, :k] = 2 * q[members[:, :, None], members[:, None, :]]
        kkt[:, :k, k] = kkt[:, k, :k] = 1.0
        rhs = np.concatenate([2 * c[members], np.ones((m, 1))], axis=1)
        ok = np.ones(m, bool)
        try:
            sol = np.linalg.solve(kkt, rhs[..., None])[..., 0]
        except np.linalg.LinAlgError:          # a singular system: solve the others alone
            sol = np.zeros((m, k + 1))
            for t in range(m):
                try:
                    sol[t] = np.linalg.solve(kkt[t], rhs[t])
                except np.linalg.LinAlgError:
                    ok[t] = False
        ok &= ~(sol[:, :k] < -1e-12).any(axis=1)
        for good in np.flatnonzero(ok):
            w = np.zeros(n)
            w[members[good]] = np.clip(sol[good, :k], 0.0, None)
            w /= w.sum()
            found.append((int(bits[good]), w))
    best, best_w = np.inf, np.full(n, 1.0 / n)
    for _, w in sorted(found, key=lambda f: f[0]):
        val = float(w @ q @ w - 2 * c @ w)
        if val < best - 1e-15:
            best, best_w = val, w
    return best_w


def hiding_weights(dy_um: np.ndarray, volume: np.ndarray, slots: np.ndarray,
                   dy_noise_um: float = HIDE_DY_NOISE_UM,
                   volume_noise_pct: float = HIDE_VOLUME_NOISE_PCT,
                   feed_noise_um: float = HIDE_FEED_NOISE_UM,
                   stroke_error_um: float = 0.0) -> np.ndarray:
    """The shares of a row's dots each pass prints, so that the nozzles' measured errors
    cancel row by row instead of averaging ("nozzle-error hiding"): `dy_um` (the nozzles'
    landing error along the feed, µm) and `volume` (drop volume, 1 nominal), both (heads,
    nozzles) as a calibration measures them; `slots` (4, A, N, 2) the (head, nozzle) printing
    colour c's row phase r in pass j (-1: none).  Per colour and row phase: the shares
    w >= 0, sum 1, that bring the row's mean error, sum w e, nearest the colour's mean over
    its nozzles, weighted by the banding each makes, plus the measurement's uncertainty
    times sum w² (which alone gives equal shares, what no knowledge of the errors allows),
    plus `stroke_error_um` (the paper's error at each stroke that the shares cannot follow:
    the driver's whole-step rounding, `stroke_error_um()`) times |w - equal|²: a row that
    leans on other passes than its neighbours is shifted by it.  Returns (4, A, N) float64
    (docs/quality.md "Masks against the machine")."""
    colours, a, n = slots.shape[:3]
    out = np.full((colours, a, n), 1.0 / n)
    for c in range(colours):
        h, z = slots[c, :, :, 0], slots[c, :, :, 1]
        live = h >= 0
        if not live.any():
            continue
        d = np.where(live, dy_um[h, z], 0.0) * HIDE_DY_PER_UM
        v = np.where(live, (volume[h, z] - 1.0) * 100.0, 0.0) * HIDE_VOLUME_PER_PCT
        d_target, v_target = d[live].mean(), v[live].mean()
        lam = (dy_noise_um * HIDE_DY_PER_UM) ** 2 + (volume_noise_pct * HIDE_VOLUME_PER_PCT) ** 2
        for r in range(a):
            ok = np.flatnonzero(live[r])
            dd, vv = d[r, ok], v[r, ok]
            # the paper's position at pass j carries the feeds' random errors up to it (a
            # random walk): rows that lean on other passes than their neighbours see it as
            # a shift.  The driver's whole-step rounding differs from stroke to stroke, which
            # shares fixed per row phase cannot follow: it pulls them towards equal shares
            jj = ok.astype(np.float64)
            walk = np.minimum(jj[:, None], jj[None, :]) * (feed_noise_um * HIDE_DY_PER_UM) ** 2
            even = np.full(ok.size, 1.0 / ok.size)
            st = (stroke_error_um * HIDE_DY_PER_UM) ** 2
            q = np.outer(dd, dd) + np.outer(vv, vv) + (lam + st) * np.eye(ok.size) + walk
            w = _simplex_qp(q, d_target * dd + v_target * vv + walk @ even + st * even)
            out[c, r] = 0.0
            out[c, r, ok] = w
    return out


def stroke_error_um(profile, passes: int, strokes: int = 2000) -> float:
    """The RMS error of the paper's position at a stroke that the driver's whole-step feeds
    leave (rip/profile.py `feed_steps_for_rows`: each feed rounded from the absolute target,
    up to half a step off), against the mean of the strokes that print a row: 6.5 µm at 4
    passes on the default profile, 0 where the weave's advance is a whole number of steps."""
    s0, s1 = profile.usable_slots()
    a = (s1 - s0) // passes
    rows = np.arange(strokes) * a
    steps = np.array([profile.feed_steps_for_rows(int(r)) for r in rows], np.float64)
    err = steps * profile.feed_um_per_step - rows * profile.row_um
    # what a row's passes see: each stroke's error against the mean of the N strokes that
    # print the row (a slow drift moves them together and is harmless)
    win = np.lib.stride_tricks.sliding_window_view(err, passes)
    return float(np.sqrt(np.mean((win - win.mean(axis=1, keepdims=True)) ** 2)))
