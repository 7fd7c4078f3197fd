"""Head care, the host's side (docs/driver.md "Head care", docs/protocol.md 2.9): when to
spit, cap and uncap, so that no nozzle fires after drying.

The printer cannot see a dried nozzle, but the host knows every nozzle it makes fire (its
own stroke words) and the printer tells its drying clock (SERVICE_STATUS).  So the host
keeps each nozzle's last fire on that clock and, before a stroke, spits the heads of
which a nozzle about to fire has been idle longer than `spit_interval_s` (the profile
guarantees that interval plus the longest stroke stays inside the ink's open time).  While
a job is paused or the printer idles it spits every `spit_interval_s`, and after
`cap_after_s` it parks and caps; the next stroke uncaps.
"""

from __future__ import annotations

import logging
import time

import numpy as np

from . import protocol as P

log = logging.getLogger(__name__)

NEVER = -(1 << 62)                       # "never fired" on the drying clock (ms)


def nozzles_used(words: np.ndarray) -> np.ndarray:
    """(heads, 128) bools: the nozzles that fire at least once in a stroke's words
    (heads, fires, 8) uint16 (docs/protocol.md 4.3 bit order)."""
    # OR-folded in halves, a fire's 8 words as two uint64: numpy's reduce along the fires
    # axis walks 16-byte strides (5 ms a full-width stroke; folded 0.7)
    x = np.ascontiguousarray(words, dtype=np.uint16).view(np.uint64)   # (heads, fires, 2)
    if x.shape[1] == 0:
        x = np.zeros((x.shape[0], 1, 2), np.uint64)
    while x.shape[1] > 1:
        half = x.shape[1] // 2
        odd = x[:, 2 * half:]
        x = x[:, :half] | x[:, half:2 * half]
        if odd.shape[1]:
            x[:, 0] |= odd[:, 0]
    any16 = x[:, 0].view(np.uint16).astype("<u2")                      # (heads, 8)
    return np.unpackbits(any16.view(np.uint8), axis=1, bitorder="little").astype(bool)


class HeadCare:
    """One printer's head-care schedule, kept for as long as the host holds the printer
    (a job, or a print server's printer between jobs)."""

    def __init__(self, printer):
        self.printer = printer
        self.m = printer.profile.maintenance
        self.n_heads = len(printer.profile.heads)
        self.all_heads = (1 << self.n_heads) - 1
        self.last_fire: np.ndarray | None = None      # (heads, 128) drying clock, ms
        self._clock_ms: int | None = None             # unwrapped drying clock
        self._raw: int | None = None
        self.spits = 0
        info = printer.identity or {}
        # a protocol 1.0 printer has no service station commands (docs/protocol.md)
        self.supported = (info.get("proto_major"), info.get("proto_minor", 0)) >= (1, 1) \
            if info else True
        self._warned = False

    @property
    def active(self) -> bool:
        if not self.supported and not self._warned:
            log.warning("the printer speaks protocol 1.0: no head care (spitting, capping)")
            self._warned = True
        return self.supported

    # -- the printer's drying clock ------------------------------------------------------------
    def status(self):
        """SERVICE_STATUS with the drying clock unwrapped (it is a u32 of ms)."""
        st = self.printer.call(P.Op.SERVICE_STATUS)
        if self._raw is None:
            self._clock_ms = st.wet_clock_ms
        else:
            self._clock_ms += (st.wet_clock_ms - self._raw) & 0xFFFFFFFF
        self._raw = st.wet_clock_ms
        if self.last_fire is None:
            # what the printer knows: each head's last spit or purge (firing since is not
            # counted: conservative)
            ages = np.array([NEVER if a == 0xFFFFFFFF else self._clock_ms - a
                             for a in st.spit_age_ms[:self.n_heads]], np.int64)
            self.last_fire = np.repeat(ages[:, None], self.printer.profile.nozzles, axis=1)
        return st

    def now_ms(self) -> int:
        self.status()
        return self._clock_ms

    # -- operations ----------------------------------------------------------------------------
    def spit(self, mask: int | None = None, drops: int | None = None) -> None:
        mask = self.all_heads if mask is None else mask
        if self.status().capped:
            self.cap(False)
        self._service(P.Op.SPIT, "spitting", mask, drops=drops or self.m.spit_drops)
        self.spits += 1

    def purge(self, mask: int | None = None, ms: int | None = None) -> None:
        mask = self.all_heads if mask is None else mask
        self._service(P.Op.PURGE, "purging", mask, ms=ms or self.m.purge_ms)

    def _service(self, op: P.Op, what: str, mask: int, **fields) -> None:
        """A spit or purge of the masked heads: every nozzle of theirs is wet afterwards."""
        self.printer.call(op, heads=mask, **fields)
        self.printer.wait_idle(what)
        now = self.now_ms()
        for h in range(self.n_heads):
            if mask >> h & 1:
                self.last_fire[h] = now

    def cap(self, on: bool) -> None:
        self.printer.call(P.Op.CAP, on=int(on))
        self.printer.wait_idle("capping" if on else "uncapping")

    # -- the schedule ----------------------------------------------------------------------------
    def before_stroke(self, used: np.ndarray) -> int:
        """Before a stroke whose nozzles `used` (heads, 128) will fire: uncap, and spit the
        heads with a nozzle about to fire that has been idle too long.  The stroke's start
        on the drying clock (ms), for `after_stroke`."""
        if not self.active:
            return 0
        st = self.status()
        if st.capped:
            self.cap(False)
        now = self._clock_ms
        if self.m.spit:
            stale = used & (now - self.last_fire > self.m.spit_interval_s * 1000)
            mask = sum(1 << h for h in np.flatnonzero(stale.any(axis=1)))
            if mask:
                log.info("spitting heads %s before the stroke (nozzles idle > %.0f s)",
                         [self.printer.profile.heads[h].name for h in range(self.n_heads)
                          if mask >> h & 1], self.m.spit_interval_s)
                self.spit(mask)
                now = self._clock_ms
        return now

    def after_stroke(self, used: np.ndarray, started_ms: int) -> None:
        """The stroke fired: its nozzles were wet at its start, at the latest."""
        if self.active and self.last_fire is not None:
            self.last_fire[used] = np.maximum(self.last_fire[used], started_ms)

    def idle(self, since: float) -> None:
        """Called now and then while a job is paused or the printer has nothing to print
        (`since`: time.monotonic() when that began): keep the heads wet, cap when it lasts."""
        if not self.active:
            return
        if self.status().capped:
            return
        if self.m.cap_after_s and time.monotonic() - since >= self.m.cap_after_s:
            self.printer.park()
            self.cap(True)
            log.info("idle for %.0f s: heads capped", self.m.cap_after_s)
            return
        if self.m.spit and (self._clock_ms - self.last_fire.min()) > self.m.spit_interval_s * 1000:
            self.spit()
