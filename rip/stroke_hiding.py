"""Nozzle-error hiding that follows each stroke (issue 36, docs/quality.md "Masks against the
machine"): pass shares per block of A rows, from the stroke errors the driver's whole-step
feeds leave, which are known before the job prints.

The driver feeds stroke i to `feed_steps_for_rows(i A + top)` (driver/job.py; rip/profile.py:
rounded from the absolute target), so stroke i lands `F_i = (round(x_i) - x_i) s` off, with
`x_i = (i A + top) µm_row / s` and `s` the step's travel (µm, with the calibrated travel
error).  Block b (image rows b A .. b A + A - 1) is printed by strokes b .. b + N - 1 (pass j
by stroke b + j: docs/geometry.md), so its passes land `F_{b+j} = (round(φ_b + j δ) - φ_b - j δ) s`
off, `φ_b` the fractional part of x_b and δ that of the advance in steps: the errors of a
block's passes depend on φ_b alone.  The blocks are put in classes by φ_b: the unit interval
cut at the N points where a pass's rounding jumps (so that inside a class the passes' errors
differ only by a common shift) and into `bins` equal parts (so that the common shift is known
to ± s / 2 bins).  Per class, colour and row phase the shares `w` (w >= 0, Σ w = 1) bring
the row's mean landing error `Σ w_j (dy_j + F_j)` and mean volume `Σ w_j v_j` nearest the
colour's mean (`rip.masks.hiding_weights` with the stroke errors inside the programme instead
of held off by it), so the rounding cancels with the nozzles' errors row by row.

The planner reads them per stroke through its `_stroke_mask` hook (rip/swath.py): stroke i's
rows are the blocks i - N + 1 .. i, each with its class's selection.  Same dots; only which
pass fires each changes.
"""

from __future__ import annotations

import copy
from dataclasses import dataclass, replace

import numpy as np

from .masks import (HIDE_DY_NOISE_UM, HIDE_DY_PER_UM, HIDE_FEED_NOISE_UM, HIDE_VOLUME_NOISE_PCT,
                    HIDE_VOLUME_PER_PCT, _simplex_qp, load_bluenoise_mask)

#: equal parts of a step the blocks' phase is cut into (besides the rounding's jumps): the
#: common shift of a class's strokes is then known to ± 23.56 / 32 µm on the default profile
STROKE_BINS = 16


@dataclass(frozen=True)
class StrokeClasses:
    """The blocks' classes by the phase of their first stroke's feed target (module doc)."""
    advance: int                # A, rows of paper advance a stroke
    passes: int                 # N
    row_steps: float            # feed steps a row (with the calibrated travel error)
    step_um: float              # a step's travel, µm
    top_rows: int               # the job's top margin, rows (driver/job.py `top_rows`)
    edges: np.ndarray           # (K,) ascending phases in [0, 1): class k is [edges[k], edges[k+1])

    @classmethod
    def of(cls, profile, passes: int, top_rows: int = 0, bins: int = STROKE_BINS) -> StrokeClasses:
        s0, s1 = profile.usable_slots()
        a = (s1 - s0) // passes
        ppm = 1.0 + profile.feed.travel_error_ppm * 1e-6
        row_steps = profile.row_um / profile.feed_um_per_step / ppm
        delta = (a * row_steps) % 1.0
        jumps = (0.5 - np.arange(passes) * delta) % 1.0
        edges = np.unique(np.round(np.concatenate([np.arange(bins) / bins, jumps]), 12))
        return cls(a, passes, row_steps, profile.feed_um_per_step * ppm, int(top_rows), edges)

    @property
    def count(self) -> int:
        return int(self.edges.size)

    def phase(self, blocks: np.ndarray) -> np.ndarray:
        """φ_b: the fractional feed step of block b's first stroke's target."""
        x = (np.asarray(blocks, np.int64) * self.advance + self.top_rows) * self.row_steps
        return x - np.floor(x)

    def of_blocks(self, blocks: np.ndarray) -> np.ndarray:
        """The class of each block."""
        return np.searchsorted(self.edges, self.phase(blocks), side="right") - 1

    def errors_um(self, phase: np.ndarray) -> np.ndarray:
        """(…, N) the landing error of a block's passes (µm, + = the paper fed further) for
        its phase: F_{b+j} = (round(φ + j δ) - φ - j δ) s."""
        x = np.asarray(phase, np.float64)[..., None] + np.arange(self.passes) * self.advance * self.row_steps
        return (np.floor(x + 0.5) - x) * self.step_um

    def class_errors_um(self) -> np.ndarray:
        """(K, N) each class's passes' errors at the middle of its phases."""
        hi = np.append(self.edges[1:], 1.0)
        return self.errors_um((self.edges + hi) / 2)

    def block_errors_um(self, blocks: np.ndarray) -> np.ndarray:
        """(…, N) the exact errors of the blocks' passes (what the classes approximate)."""
        return self.errors_um(self.phase(blocks))


def stroke_hiding_weights(dy_um: np.ndarray, volume: np.ndarray, slots: np.ndarray,
                          errors_um: np.ndarray,
                          dy_noise_um: float = HIDE_DY_NOISE_UM,
                          volume_noise_pct: float = HIDE_VOLUME_NOISE_PCT,
                          feed_noise_um: float = HIDE_FEED_NOISE_UM) -> np.ndarray:
    """(K, 4, A, N) the shares per class of the blocks' stroke errors `errors_um` (K, N)
    (`StrokeClasses.class_errors_um`), colour and row phase: `dy_um`, `volume` (heads,
    nozzles) the nozzles' measured landing error and drop volume, `slots` (4, A, N, 2) the
    (head, nozzle) printing colour c's row phase r in pass j (-1: none), as for
    `rip.masks.hiding_weights`.  Per row: argmin (Σ w_j d_j - d̄)² + (Σ w_j v_j - v̄)² +
    λ Σ w² (+ the feed's random walk), d_j the banding of pass j's landing error dy + F_j,
    d̄ that of the colour's mean dy (the strokes' errors average to 0), v likewise for the
    volume, λ the measurement's uncertainty."""
    errors_um = np.atleast_2d(np.asarray(errors_um, np.float64))
    colours, a, n = slots.shape[:3]
    out = np.full((errors_um.shape[0], colours, a, n), 1.0 / n)
    lam = (dy_noise_um * HIDE_DY_PER_UM) ** 2 + (volume_noise_pct * HIDE_VOLUME_PER_PCT) ** 2
    for c in range(colours):
        h, z = slots[c, :, :, 0], slots[c, :, :, 1]
        live = h >= 0
        if not live.any():
            continue
        dy = np.where(live, dy_um[h, z], 0.0)
        v = np.where(live, (volume[h, z] - 1.0) * 100.0, 0.0) * HIDE_VOLUME_PER_PCT
        d_target = dy[live].mean() * HIDE_DY_PER_UM
        v_target = v[live].mean()
        for r in range(a):
            ok = np.flatnonzero(live[r])
            vv = v[r, ok]
            jj = ok.astype(np.float64)
            # the paper's random feed errors up to pass j (a random walk) are not known
            walk = np.minimum(jj[:, None], jj[None, :]) * (feed_noise_um * HIDE_DY_PER_UM) ** 2
            even = np.full(ok.size, 1.0 / ok.size)
            base = np.outer(vv, vv) + lam * np.eye(ok.size) + walk
            lin = v_target * vv + walk @ even
            for k, err in enumerate(errors_um):
                dd = (dy[r, ok] + err[ok]) * HIDE_DY_PER_UM
                w = _simplex_qp(base + np.outer(dd, dd), lin + d_target * dd)
                out[k, c, r] = 0.0
                out[k, c, r, ok] = w
    return out


MASK_LEVELS = 256           # as rip/swath.py's random mask: the blue-noise tile in 256 levels


class StrokeMasks:
    """The planner's selection per stroke from per-class shares: `__call__(i)` gives stroke
    i's (mask_rows, mask_index, sel) for rip/swath.py's packers, indexed by the image row
    modulo N A (a stroke's rows are N A consecutive rows, each block with its class's).
    `remap` (4, A, N) is the planner's dead-nozzle remap, `s0` its first used slot."""

    def __init__(self, passes: int, remap: np.ndarray, weights: np.ndarray,
                 classes: StrokeClasses, s0: int):
        n, a = passes, remap.shape[1]
        if weights.shape[1:] != (4, a, n) or classes.advance != a or classes.passes != n:
            raise ValueError(f"stroke shares {weights.shape} do not fit the planner's "
                             f"{n} passes of {a} rows")
        self.n, self.a, self.s0, self.classes = n, a, s0, classes
        ranks = load_bluenoise_mask()
        self.qmask = np.ascontiguousarray(
            (ranks.astype(np.int64) * MASK_LEVELS // ranks.size).astype(np.int16))
        u = (np.arange(MASK_LEVELS) + 0.5) / MASK_LEVELS
        k = weights.shape[0]
        sel = np.empty((k, 4, a, MASK_LEVELS), np.int16)
        for c in range(4):
            cum = np.cumsum(weights[:, c] / weights[:, c].sum(axis=2, keepdims=True), axis=2)
            jsel = np.minimum((u[None, None, :, None] > cum[:, :, None, :]).sum(axis=3), n - 1)
            rc = np.broadcast_to(remap[c], (k, a, n))
            sel[:, c] = np.take_along_axis(rc, jsel.astype(np.int64), axis=2)
        self.sel = sel
        # the packed bits of each distinct selection, as StrokePlanner._mask_bit_rows
        th, tw = self.qmask.shape
        unique, index = np.unique(sel.reshape(-1, MASK_LEVELS), axis=0, return_inverse=True)
        rows = np.empty((len(unique), th, n, tw // 8), np.uint8)
        j = np.arange(n, dtype=np.int16)[None, :, None]
        for i, srow in enumerate(unique):
            rows[i] = np.packbits(srow[self.qmask][:, None, :] == j, axis=-1)
        self.rows = rows
        self.index = index.reshape(k, 4, a).astype(np.int64)
        # shared by every planner from the cache (rip/hiding.py); `rows` goes to the packers
        # as the other masks' rows do (writable: the compiled kernels' signature)
        for arr in (self.sel, self.index):
            arr.setflags(write=False)

    def at_top(self, top_rows: int) -> StrokeMasks:
        """The same selections with the blocks' classes placed for a job whose top margin
        is `top_rows` (the planes are shared, not copied)."""
        out = copy.copy(self)
        out.classes = replace(self.classes, top_rows=int(top_rows))
        return out

    def __call__(self, i: int) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
        n, a = self.n, self.a
        rr = (i - n + 1) * a + np.arange(n * a)     # the image rows under the used run
        pos = rr % (n * a)
        cls = self.classes.of_blocks(rr // a)
        index = np.empty((4, n * a), np.int64)
        index[:, pos] = self.index[cls, :, rr % a].T
        sel = np.empty((4, n * a, MASK_LEVELS), np.int16)
        sel[:, pos] = self.sel[cls, :, rr % a].transpose(1, 0, 2)
        return self.rows, index, sel
