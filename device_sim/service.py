"""The service station and the ink's drying (docs/protocol.md 2.9, docs/emulator.md
"Head care"): capping, spitting, purging, and nozzles that misfire when left idle.

The drying clock counts uncapped time: the printer's own time (motions advance it) plus
the time it stood idle between host commands (wall time, scaled by the `idle-time-scale`
injection so a test can pause "for an hour" in a second).  A nozzle idle on that clock for
longer than the profile's `open_time_s` misfires its next `recovery_drops` fires (the
drops never leave it); idle longer than `clog_time_s` it misfires until a purge.  Firing
attempts, dropped or not, keep a nozzle wet: that is how spitting and printing recover it.
"""

from __future__ import annotations

import numpy as np

CLOGGED = np.iinfo(np.int32).max        # misfires left: until a purge
CAP_S = 0.5                             # raising or lowering the caps
WIPE_S = 2.0                            # the wiper pass after a purge


def fired_nozzles(words: np.ndarray) -> np.ndarray:
    """The nozzles (128 bools, docs/protocol.md 4.3 bit order) that fire at least once in
    these words (fires, 8) uint16."""
    any16 = np.bitwise_or.reduce(words, axis=0).astype("<u2") if words.size else \
        np.zeros(8, "<u2")
    return np.unpackbits(any16.view(np.uint8), bitorder="little").astype(bool)


class ServiceStation:
    def __init__(self, printer, n_heads: int, nozzles: int, maintenance, faults):
        self.printer = printer
        self.m = maintenance
        self.idle_scale = faults.idle_time_scale
        self.capped = False
        self._capped_since = 0.0             # device clock when the caps went up
        self._capped_total = 0.0             # device-clock seconds spent capped before that
        self.idle_s = 0.0                    # idle time added to the motion clock
        self.last_wet = np.zeros((n_heads, nozzles))                 # drying clock, s
        self.misfires_left = np.zeros((n_heads, nozzles), np.int64)
        self.last_spit = np.full(n_heads, -1.0)                       # drying clock, s (-1 never)
        self.misfired = np.zeros(n_heads, np.int64)                   # drops lost to drying
        self.spat_drops = 0                  # drops fired into the spittoon
        self.purge_ml = 0.0
        for attr, left in (("dry_nozzle", self.m.recovery_drops), ("clogged_nozzle", CLOGGED)):
            for name, nozzle in getattr(faults, attr):
                self.misfires_left[printer.head_index(name), nozzle] = left

    # -- clocks -----------------------------------------------------------------------------
    def clock(self) -> float:
        """The DSP's clock: motions plus idle time, seconds since power-up."""
        return self.printer.time + self.idle_s

    def wet_clock(self) -> float:
        """Seconds of uncapped time since power-up: the clock nozzles dry by."""
        t = self.clock()
        return t - self._capped_total - (t - self._capped_since if self.capped else 0.0)

    def idle(self, wall_s: float) -> None:
        """The printer stood idle this long (wall time) between two host commands."""
        self.idle_s += wall_s * self.idle_scale

    # -- drying ------------------------------------------------------------------------------
    def _dry(self, head: int, nozzles: np.ndarray, t: float) -> None:
        """Nozzles (bool mask) about to fire at drying-clock time t: those idle too long
        start misfiring."""
        age = t - self.last_wet[head]
        left = self.misfires_left[head]
        clog = nozzles & (age > self.m.clog_time_s)
        dry = nozzles & (age > self.m.open_time_s) & (left == 0) & ~clog
        left[clog] = CLOGGED
        left[dry] = self.m.recovery_drops

    def misfire(self, head: int, words: np.ndarray) -> np.ndarray:
        """The words of a head's fires with the drops its dried or clogged nozzles do not
        make (the input is not changed)."""
        fired = fired_nozzles(words)
        if not fired.any():
            return words
        t = self.wet_clock()
        self._dry(head, fired, t)
        self.last_wet[head, fired] = t
        left = self.misfires_left[head]
        bad = np.flatnonzero(fired & (left > 0))
        if bad.size == 0:
            return words
        words = words.copy()
        for z in bad:                        # few nozzles: each one's fires found vectorised
            w, bit = z >> 4, np.uint16(1 << (z & 15))
            fires = np.flatnonzero(words[:, w] & bit)
            lost = fires if left[z] == CLOGGED else fires[:left[z]]
            words[lost, w] &= ~bit
            if left[z] != CLOGGED:
                left[z] -= lost.size
            self.misfired[head] += lost.size
            self.printer.log("misfire", head=head, nozzle=int(z), drops=int(lost.size),
                             clogged=bool(left[z] == CLOGGED))
        return words

    # -- the station -------------------------------------------------------------------------
    def spit(self, heads: list[int], drops: int, printing: np.ndarray) -> None:
        """Every printing nozzle (bool mask of 128) of these heads fires `drops` times into
        the spittoon; the carriage is at the park position."""
        self.printer.time += drops / self.m.spit_hz
        t = self.wet_clock()
        for h in heads:
            self._dry(h, printing, t)
            left = self.misfires_left[h]
            open_ = printing & (left != CLOGGED)
            left[open_] = np.maximum(left[open_] - drops, 0)
            self.last_wet[h, printing] = t
            self.last_spit[h] = t
        self.spat_drops += drops * int(printing.sum()) * len(heads)
        self.printer.log("spit", heads=heads, drops=drops)

    def purge(self, heads: list[int], ms: int) -> None:
        self.cap(True)
        self.printer.time += ms / 1000
        self.cap(False)
        self.printer.time += WIPE_S
        t = self.wet_clock()
        for h in heads:
            self.misfires_left[h] = 0
            self.last_wet[h] = t
            self.last_spit[h] = t
        self.purge_ml += self.m.purge_ml * ms / 1000 * len(heads)
        self.printer.log("purge", heads=heads, ms=ms)

    def cap(self, on: bool) -> None:
        if on == self.capped:
            return
        if on:
            self.printer.time += CAP_S
            self._capped_since = self.clock()
        else:
            self._capped_total += self.clock() - self._capped_since
            self.printer.time += CAP_S
        self.capped = on
        self.printer.log("cap" if on else "uncap")

    def status(self, n: int = 8) -> dict:
        t = self.wet_clock()
        ages = [0xFFFFFFFF if s < 0 else min(int((t - s) * 1000), 0xFFFFFFFE)
                for s in self.last_spit]
        return dict(capped=int(self.capped), wet_clock_ms=int(t * 1000) & 0xFFFFFFFF,
                    spit_age_ms=tuple((ages + [0xFFFFFFFF] * n)[:n]))
