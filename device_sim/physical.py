"""The physical media model (docs/physical.md): where each drop the emulator fires lands,
in micrometres of the image frame, from the encoder position at the fire, the firing
phase, the carriage's speed and direction, the drop's flight, the head's position and the
injected errors (bidirectional error, head offsets, feed error, misdirected nozzles).

The same static offsets decide the bit-exact media's cell (`JobGeometry.grid`), so the
media and the scan never disagree about where an injected error put a drop.
"""

from __future__ import annotations

import math
from dataclasses import dataclass

import numpy as np

from ..driver import protocol as P
from ..rip.profile import Profile
from .faults import HEAD_GAP_MM, Faults, Length
from .vcd import DSTB_PRINT_HZ

DROP_SPEED_M_S = 6.0       # the XJ128's nominal drop velocity
DOT_SPREAD = 2.4           # dot diameter on the paper / drop diameter in flight


def dot_diameter_um(profile: Profile, faults: Faults | None = None) -> float:
    """The diameter of one dot on the paper: injected, or spread from the drop volume."""
    gain = 1.0 + (faults.dot_gain if faults is not None else 0.0)    # drift (docs/media.md)
    if faults is not None and faults.dot_diameter is not None:
        return faults.dot_diameter.um(0.0, 0.0) * gain
    volume_um3 = profile.drop_volume_pl * 1000.0          # 1 pl = 1000 µm³
    return DOT_SPREAD * (6.0 * volume_um3 / math.pi) ** (1.0 / 3.0) * gain


def _length_um(v, col_um: float, row_um: float) -> float:
    """A Length, or a bare number of columns (Faults(bidir_error=2) in tests)."""
    return v.um(col_um, row_um) if isinstance(v, Length) else float(v) * col_um


@dataclass
class JobGeometry:
    """One job's frame (JOB_BEGIN) with the injected static errors resolved to micrometres."""
    x0: int                   # encoder count of image column 0
    k: int                    # counts per column
    y0: int                   # paper row of image row 0
    row_nm: int
    width: int
    height: int
    count_um: float           # µm per encoder count
    col_um: float
    row_um: float
    head_dx_um: np.ndarray    # (heads,) head-error + head-offset along x
    head_dy_um: np.ndarray    # (heads,) head-offset along y
    bidir_um: float           # reverse drops land this far left
    nozzle_dx_um: np.ndarray  # (heads, nozzles) misdirection
    nozzle_dy_um: np.ndarray
    skew_rad: float = 0.0     # the paper travels at this angle (--inject skew)

    def skewed(self, x: np.ndarray, y: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
        """Drops on paper that travels at an angle to the feed axis (docs/physical.md,
        "Skew"): the paper walks sideways as it feeds, so on the sheet the print is turned
        about its first dot, `y tan` further right at `y` down the sheet."""
        if not self.skew_rad:
            return x, y
        c, s = math.cos(self.skew_rad), math.sin(self.skew_rad)
        return x * c + y * s, y * c - x * s

    def static_dx_um(self, head: int, forward: bool) -> np.ndarray:
        """(nozzles,) the static x error of each nozzle of a head in this direction."""
        return self.head_dx_um[head] - (0.0 if forward else self.bidir_um) + self.nozzle_dx_um[head]

    def static_dy_um(self, head: int) -> np.ndarray:
        return self.head_dy_um[head] + self.nozzle_dy_um[head]

    def grid(self, head: int, x_counts: int, slots: np.ndarray, forward: bool,
             paper_nm: float, delay_counts: float = 0.0) -> tuple[np.ndarray, np.ndarray]:
        """Bit-exact media cell of each nozzle's drops: (column offset from the trigger
        column, media row), per nozzle.  The cell holds the drop's static position
        (docs/physical.md): col = c + floor((X - x0 + k/2 + dx) / k); a fire delay moves
        it by its nominal `delay_counts` (s V t, docs/calibration.md)."""
        dx_counts = self.static_dx_um(head, forward) / self.count_um + delay_counts
        dcol = np.floor((x_counts - self.x0 + self.k / 2 + dx_counts) / self.k).astype(np.int64)
        dy_nm = self.static_dy_um(head) * 1000.0
        rows = np.rint((paper_nm + slots * self.row_nm + dy_nm) / self.row_nm).astype(np.int64) - self.y0
        return dcol, rows


class PhysicalModel:
    """Landing positions of the drops of one emulated machine (profile + injected faults)."""

    def __init__(self, profile: Profile, faults: Faults):
        self.profile, self.faults = profile, faults
        prof = profile
        self.n_heads, self.nozzles = len(prof.heads), prof.nozzles
        z = np.arange(prof.nozzles)
        self.phase = (z - 1) % 3                               # A = 0 (3n+1), B = 1, C = 2
        self.t_shift = prof.nozzles / DSTB_PRINT_HZ             # 128 DSTB clocks of data
        self.t_gap = 1.0 / (3.0 * prof.max_fire_hz)            # a third of the minimum fire period
        self.t_flight = HEAD_GAP_MM * 1e-3 / DROP_SPEED_M_S
        self.v_design = prof.carriage.max_speed_mm_s / 25.4 * prof.counts_per_inch   # counts/s
        self.slots = np.array([[h.y_rows + prof.heads_per_color * n for n in z] for h in prof.heads],
                              np.int64)
        names = [h.name for h in prof.heads]
        for name, *_ in [*faults.head_offset, *faults.misdirect]:
            if name not in names:
                raise ValueError(f"--inject: no head named {name!r} (heads: {', '.join(names)})")
        for _, nozzle, *_ in faults.misdirect:
            if not 0 <= nozzle < prof.nozzles:
                raise ValueError(f"--inject misdirect: nozzle {nozzle} is not 0..{prof.nozzles - 1}")
        for name, _ in faults.head_density:
            if name not in names:
                raise ValueError(f"--inject head-density: no head named {name!r} (heads: {', '.join(names)})")
        self._machine()

    # -- the machine's own errors (docs/physical.md "The machine") ---------------------------
    def _machine(self) -> None:
        """Draw the machine's fixed errors once, from the seed: each nozzle's direction
        (x, y at the paper) and drop volume, each head's volume; and the feed's random
        stream.  Each draw has its own stream, so adding one kind leaves the others'."""
        f, seed = self.faults, int(self.faults.seed)
        shape = (self.n_heads, self.nozzles)
        sd = f.direction_spread.um(0.0, 0.0) if f.direction_spread is not None else 0.0
        rng = np.random.default_rng([seed, 36, 1])
        self.spread_dx_um = rng.normal(0.0, 1.0, shape) * sd
        self.spread_dy_um = rng.normal(0.0, 1.0, shape) * sd
        volume = 1.0 + np.random.default_rng([seed, 36, 2]).normal(0.0, 1.0, shape) * f.volume_spread
        head = 1.0 + np.random.default_rng([seed, 36, 3]).normal(0.0, 1.0, self.n_heads) * f.head_density_spread
        index = {h.name: h.index for h in self.profile.heads}
        for name, frac in f.head_density:
            head[index[name]] *= 1.0 + frac
        # a dot's diameter grows as the cube root of its drop's volume (docs/physical.md)
        self.volume = np.clip(volume * head[:, None], 0.05, None)
        self.diameter_dev = self.volume ** (1.0 / 3.0) - 1.0
        self.has_sizes = bool(np.any(self.diameter_dev != 0.0))
        self._feed_rng = np.random.default_rng([seed, 36, 4])

    # -- per job -------------------------------------------------------------------------
    def job_geometry(self, x0: int, k: int, y0: int, row_nm: int, width: int,
                     height: int) -> JobGeometry:
        prof, f = self.profile, self.faults
        count_um = 25_400.0 / prof.counts_per_inch
        col_um, row_um = k * count_um, row_nm / 1000.0
        index = {h.name: h.index for h in prof.heads}
        hdx, hdy = np.zeros(self.n_heads), np.zeros(self.n_heads)
        for name, counts in f.head_error:
            hdx[index[name]] += counts * count_um
        for name, dx, dy in f.head_offset:
            hdx[index[name]] += dx.um(col_um, row_um)
            hdy[index[name]] += dy.um(col_um, row_um)
        ndx, ndy = self.spread_dx_um.copy(), self.spread_dy_um.copy()     # the machine's spread
        for name, nozzle, dx, dy in f.misdirect:
            ndx[index[name], nozzle] += dx.um(col_um, row_um)
            ndy[index[name], nozzle] += dy.um(col_um, row_um)
        return JobGeometry(x0, k, y0, row_nm, width, height, count_um, col_um, row_um, hdx, hdy,
                           _length_um(f.bidir_error, col_um, row_um), ndx, ndy, math.radians(f.skew))

    def feed_error_um(self, travel_um: float, row_um: float) -> float:
        """The paper's extra travel on a feed of `travel_um` (docs/physical.md)."""
        f = self.faults
        extra = travel_um * f.feed_error_fraction
        if f.feed_error is not None and travel_um:
            extra += f.feed_error.um(0.0, row_um)
        if f.feed_noise is not None and f.feed_noise.value and travel_um:
            # the random part, new on every feed (the roller's runout, the stepper's step
            # angle error, the media slipping on the grit): it accumulates, as on paper
            extra += float(self._feed_rng.normal()) * f.feed_noise.um(0.0, row_um)
        return extra

    # -- the drops ------------------------------------------------------------------------
    def land(self, geo: JobGeometry, head: int, columns: np.ndarray, words: np.ndarray,
             forward: bool, velocity: np.ndarray, line_speed: float,
             paper_um: float, delay_s: float = 0.0, sizes: bool = False):
        """Positions (x µm, y µm) in the image frame of every drop of one head's fires:
        `columns` the trigger columns, `words` (fires, 8) what the nozzles latched (dead
        nozzles already cleared), `velocity` the carriage's signed speed at each fire
        (counts/s), `line_speed` the line's commanded speed, `paper_um` the paper's travel
        since JOB_BEGIN, `delay_s` the head's fire delay (FIRE_DELAY registers): the strobes
        come that much later, the carriage has moved v t further.  With `sizes`, also each
        drop's relative dot diameter error (None on a machine without volume errors)."""
        fire, z = np.nonzero(P.words_to_nozzles(words))
        if fire.size == 0:
            return (np.zeros(0), np.zeros(0), None) if sizes else (np.zeros(0), np.zeros(0))
        h = self.profile.heads[head]
        s = 1.0 if forward else -1.0
        p = self.phase[z]
        q = p if forward else 2 - p
        t_q = self.t_shift + q * self.t_gap + delay_s
        v = np.asarray(velocity, np.float64)[fire]
        dyn_counts = (v * (t_q + self.t_flight) - (p - 1) * self.v_design * self.t_gap
                      - s * line_speed * (self.t_shift + self.t_gap + self.t_flight))
        base = columns[fire].astype(np.float64) * geo.k + (h.x_counts - geo.x0 + geo.k / 2)
        x = (base + dyn_counts) * geo.count_um + geo.static_dx_um(head, forward)[z]
        y = (paper_um + (self.slots[head, z] + 0.5 - geo.y0) * geo.row_um
             + geo.static_dy_um(head)[z])
        x, y = geo.skewed(x, y)                     # the paper's own travel, not in the media
        if sizes:
            return x, y, (self.diameter_dev[head, z] if self.has_sizes else None)
        return x, y
