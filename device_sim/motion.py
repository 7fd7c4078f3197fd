"""Carriage and feed kinematics of the emulated DSP.

A carriage move is a trapezoidal (or triangular) velocity profile in encoder counts; the
times at which the carriage crosses given positions are computed in closed form, vectorised,
so a 40,000-column line costs a few array operations, not a loop per encoder edge.
"""

from __future__ import annotations

import math
from dataclasses import dataclass

import numpy as np


@dataclass(frozen=True)
class Trapezoid:
    """A move from `start` to `end` (counts) at cruise `v` (counts/s) and acceleration `a`
    (counts/s²), starting and ending at rest."""
    start: float
    end: float
    v: float
    a: float

    @property
    def distance(self) -> float:
        return abs(self.end - self.start)

    @property
    def sign(self) -> int:
        return 1 if self.end >= self.start else -1

    @property
    def v_peak(self) -> float:
        return min(self.v, math.sqrt(self.a * self.distance))

    @property
    def t_ramp(self) -> float:
        return self.v_peak / self.a

    @property
    def d_ramp(self) -> float:
        return self.v_peak ** 2 / (2 * self.a)

    @property
    def duration(self) -> float:
        if self.distance == 0:
            return 0.0
        cruise = (self.distance - 2 * self.d_ramp) / self.v_peak
        return 2 * self.t_ramp + cruise

    def time_at(self, positions: np.ndarray) -> np.ndarray:
        """Time (s from the move's start) at which the carriage reaches each position."""
        d = np.abs(np.asarray(positions, dtype=np.float64) - self.start)
        if np.any(d > self.distance + 1e-9):
            raise ValueError("position outside the move")
        vp, a, dr = self.v_peak, self.a, self.d_ramp
        t = np.empty_like(d)
        acc = d <= dr
        dec = d >= self.distance - dr
        cru = ~acc & ~dec
        t[acc] = np.sqrt(2 * d[acc] / a)
        t[cru] = self.t_ramp + (d[cru] - dr) / vp
        rem = self.distance - d[dec]
        t[dec] = self.duration - np.sqrt(np.maximum(2 * rem / a, 0.0))
        return t

    def position_at(self, t: float) -> float:
        t = min(max(t, 0.0), self.duration)
        vp, a, tr = self.v_peak, self.a, self.t_ramp
        if t <= tr:
            d = 0.5 * a * t * t
        elif t <= self.duration - tr:
            d = self.d_ramp + vp * (t - tr)
        else:
            rem = self.duration - t
            d = self.distance - 0.5 * a * rem * rem
        return self.start + self.sign * d

    def speed_at(self, t: float) -> float:
        if t <= 0 or t >= self.duration:
            return 0.0
        vp, a, tr = self.v_peak, self.a, self.t_ramp
        if t <= tr:
            s = a * t
        elif t <= self.duration - tr:
            s = vp
        else:
            s = a * (self.duration - t)
        return self.sign * s


def ramp_counts(v: float, a: float, k: int) -> int:
    """Ramp length before the first fire (docs/protocol.md 2.7): v²/2a plus a 2-column guard."""
    return int(math.ceil(v * v / (2 * a))) + 2 * k
