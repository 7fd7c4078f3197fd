"""The host-side printer API (docs/driver.md, "The printer API").

One object per connected printer with the operations every front end needs: connect and
identify, status, paper, heads, FIFO levels, and the machine commands (home, park, feed,
measure the paper, clear a fault, configure the heads, stop).  The job engine
(driver/job.py), the GUI, the print server and `wideprint printer ...` all go through it,
so the order of commands, the waits and the fault words are written once.

Commands that move something return when the printer is idle again (`wait=True`), and
raise `PrinterFault` naming the fault in plain words when the printer latches one.
"""

from __future__ import annotations

import time
from dataclasses import dataclass
from typing import Callable

from . import protocol as P
from .device import Device
from .link import DeviceError, LinkError

MM_PER_INCH = 25.4

# HEAD_STATUS flags (docs/protocol.md 2.5)
HEAD_CONFIGURED = 1 << 0
HEAD_OVERTEMP = 1 << 1
HEAD_DEAD = 1 << 2

# faults whose place in the job (stroke, column) is worth saying
_LOCATED = (P.Fault.FIFO_UNDERRUN, P.Fault.HEAD_DATA, P.Fault.OVERSPEED, P.Fault.DATA_LINK_LOST,
            P.Fault.HEAD_OVERTEMP, P.Fault.LIMIT_RIGHT, P.Fault.LIMIT_LEFT, P.Fault.ENCODER,
            P.Fault.DATA_SEQUENCE, P.Fault.DATA_CRC)


def fault_message(st: P.Status, profile) -> str:
    """A latched fault in plain words, with the head, stroke and column where it happened."""
    text = P.FAULT_TEXT.get(P.Fault(st.fault), f"fault 0x{st.fault:02X}") \
        if st.fault in P.Fault._value2member_map_ else f"fault 0x{st.fault:02X}"
    where = []
    if st.fault_head != 0xFF and st.fault_head < len(profile.heads):
        where.append(f"head {profile.heads[st.fault_head].name}")
    if st.fault in _LOCATED:
        where.append(f"stroke {st.fault_stroke}")
        where.append(f"column {st.fault_column}")
    return text + (f" ({', '.join(where)})" if where else "")


class PrinterFault(RuntimeError):
    """The printer latched a fault (or did not finish in time); the message says which,
    in plain words, and where."""

    def __init__(self, message: str, fault: int = 0, stroke: int | None = None):
        super().__init__(message)
        self.fault, self.stroke = fault, stroke


@dataclass(frozen=True)
class Paper:
    present: bool
    left_counts: int
    right_counts: int
    counts_per_inch: int

    @property
    def width_mm(self) -> float:
        return (self.right_counts - self.left_counts) / self.counts_per_inch * MM_PER_INCH

    @property
    def left_mm(self) -> float:
        return self.left_counts / self.counts_per_inch * MM_PER_INCH


@dataclass(frozen=True)
class HeadState:
    name: str
    temperature_c: float
    piezo_v: float
    configured: bool
    overtemp: bool
    dead: bool


class Printer:
    """A connected printer (a `Device`: command link + data channel + printer profile)."""

    def __init__(self, device: Device, on_status: Callable[[P.Status], None] | None = None):
        self.device = device
        self.link = device.link
        self.profile = device.profile
        self.on_status = on_status or (lambda st: None)   # every status read is reported
        self._config_held = 0          # head-configuration digits the printer acknowledged

    # -- identity and state -------------------------------------------------------------
    def connect(self) -> dict:
        """Handshake and IDENTIFY; the printer's identity (firmware, serial, heads, FIFO)."""
        return self.device.connect()

    @property
    def identity(self) -> dict | None:
        return self.device.info

    def status(self) -> P.Status:
        st = self.link.status()
        self.on_status(st)
        return st

    def fault_text(self, st: P.Status | None = None) -> str:
        st = st or self.status()
        return "" if st.fault == P.Fault.NONE else fault_message(st, self.profile)

    def paper(self) -> Paper:
        r = self.link.paper()
        return Paper(bool(r.present), r.left, r.right, self.profile.counts_per_inch)

    def heads(self) -> list[HeadState]:
        return [HeadState(h.name, r.temperature / 10, r.piezo / 10, bool(r.flags & HEAD_CONFIGURED),
                          bool(r.flags & HEAD_OVERTEMP), bool(r.flags & HEAD_DEAD))
                for h, r in zip(self.profile.heads, self.link.head_status())]

    def head_temperatures(self) -> tuple[float, ...]:
        return tuple(h.temperature_c for h in self.heads())

    def fifo_levels(self, st: P.Status | None = None) -> tuple[int, ...]:
        """Words in each head's FIFO, in profile head order."""
        st = st or self.status()
        return tuple(st.fifo[:len(self.profile.heads)])

    # -- waiting --------------------------------------------------------------------------
    def wait(self, done: Callable[[P.Status], bool], what: str, timeout: float = 120.0) -> P.Status:
        """Poll status until `done(status)`; PrinterFault if a fault latches or time runs out."""
        deadline = time.monotonic() + timeout
        while True:
            st = self.status()
            if st.fault != P.Fault.NONE:
                raise PrinterFault(f"{what}: {fault_message(st, self.profile)}", st.fault, st.fault_stroke)
            if done(st):
                return st
            if time.monotonic() > deadline:
                raise PrinterFault(f"{what}: the printer did not finish within {timeout:.0f} s")
            if self.device.timing.poll_interval_s:
                time.sleep(self.device.timing.poll_interval_s)

    def wait_idle(self, what: str, timeout: float = 120.0) -> P.Status:
        return self.wait(lambda s: s.motion == P.Motion.IDLE, what, timeout)

    def call(self, op: P.Op, **fields):
        """One command; a refusal because a fault is latched names that fault."""
        try:
            return self.link.call(op, **fields)
        except DeviceError as exc:
            if exc.result == P.Result.FAULT_ACTIVE:
                st = self.status()
                if st.fault != P.Fault.NONE:
                    raise PrinterFault(f"{P.op_name(op)} refused: {fault_message(st, self.profile)}",
                                       st.fault, st.fault_stroke) from None
            raise

    # -- machine commands -----------------------------------------------------------------
    def enable(self, on: bool = True) -> None:
        self.call(P.Op.ENABLE, on=int(on))

    def configure_heads(self, force: bool = False) -> bool:
        """Load the XJ128 configuration (docs/head-config.md) unless the heads have it;
        True when it was loaded."""
        if not force and self.status().flags & P.FLAG_HEADS_CONFIGURED:
            return False
        try:
            self.device.load_head_config(resume_from=self._config_held)
        except LinkError as exc:
            # a noisy line: the next call (after a reconnect) goes on from what was held
            self._config_held = getattr(exc, "config_held", 0)
            raise
        self._config_held = 0
        return True

    def home(self, wait: bool = True) -> None:
        self.call(P.Op.HOME)
        if wait:
            self.wait(lambda s: s.flags & P.FLAG_HOMED and s.motion == P.Motion.IDLE, "homing")

    def measure_paper(self, wait: bool = True) -> Paper | None:
        self.call(P.Op.MEASURE_PAPER)
        if not wait:
            return None
        self.wait(lambda s: s.flags & P.FLAG_PAPER_MEASURED and s.motion == P.Motion.IDLE,
                  "measuring the paper")
        return self.paper()

    def park(self, wait: bool = True) -> None:
        self.call(P.Op.PARK)
        if wait:
            self.wait_idle("parking")

    def feed_steps(self, steps: int, wait: bool = True) -> P.Status | None:
        """Feed the paper by `steps` stepper steps (negative: back), with the profile's
        feed ramp (docs/motion.md)."""
        f = self.profile.feed
        self.call(P.Op.FEED, steps=int(steps), profile=1 if f.profile == "sigmoid" else 0,
                  max_rate=int(f.max_steps_s), accel=int(f.accel_steps_s2))
        return self.wait_idle("feeding paper") if wait else None

    def feed_to(self, target_steps: int) -> P.Status:
        """Feed the paper to an absolute position (stepper steps since power-up).  Safe to
        repeat after a lost answer: the move is computed from where the paper is."""
        st = self.status()
        if st.paper_steps != target_steps:
            self.feed_steps(target_steps - st.paper_steps, wait=False)
            st = self.wait_idle("feeding paper")
        return st

    def feed(self, mm: float, wait: bool = True) -> int:
        """Feed the paper by `mm` millimetres; the steps made."""
        steps = int(round(mm * 1000 / self.profile.feed_um_per_step))
        if steps:
            self.feed_steps(steps, wait)
        return steps

    def clear_fault(self) -> int:
        """Clear a latched fault; the fault code that was cleared (0: there was none)."""
        return self.link.call(P.Op.CLEAR_FAULT).fault

    def job_status(self):
        """The printer's account of its job (docs/protocol.md 2.10: power-up number, job,
        its state, lines done, last stroke), or None from a printer before protocol 1.2,
        which cannot tell."""
        info = self.device.info or self.connect()
        if (info.get("proto_major"), info.get("proto_minor", 0)) < (1, 2):
            return None
        return self.link.call(P.Op.JOB_STATUS)

    def end_open_job(self, job_id: int) -> bool:
        """End the printer's open job `job_id`, if it holds it open (JOB_END); True if it
        did.  A printer before protocol 1.2 cannot say which job is open: any open job is
        ended.  Nothing is sent while a fault is latched (JOB_END would be refused; the job
        that follows meets the fault and stops there)."""
        st = self.status()
        if not st.flags & P.FLAG_JOB_OPEN or st.fault != P.Fault.NONE:
            return False
        js = self.job_status()
        if js is not None and (js.job != job_id or js.job_state != P.JobState.OPEN):
            return False
        self.link.call(P.Op.JOB_END, job=job_id)
        return True

    def stop(self) -> None:
        """End a running line at once (the carriage brakes); the job decides what next."""
        self.link.call(P.Op.STOP)

    def estop(self) -> None:
        """Emergency stop: everything stops, the DSP latches ESTOP and disables itself."""
        self.link.call(P.Op.ESTOP)

    def ready(self, on_step: Callable[[str], None] | None = None) -> P.Status:
        """Bring the printer to printing readiness: connect, refuse a latched fault, load
        the head configuration, enable, home and measure the paper, each only if needed.
        `on_step(words)` is told what is being done."""
        say = on_step or (lambda words: None)
        self.connect()
        st = self.status()
        if st.fault != P.Fault.NONE:
            raise PrinterFault(f"printer reports a fault: {fault_message(st, self.profile)}", st.fault)
        if st.motion not in (P.Motion.IDLE, P.Motion.PRINTING):
            # a motion an earlier host started (a park, a feed, a spit) before it went away:
            # every command that moves would be refused BUSY until it ends
            say("waiting for the printer's motion to end")
            st = self.wait(lambda s: s.motion in (P.Motion.IDLE, P.Motion.PRINTING),
                           "the printer's motion to end")
        if not st.flags & P.FLAG_HEADS_CONFIGURED:
            say("loading head configuration")
            self.configure_heads(force=True)
        if not st.flags & P.FLAG_ENABLED:
            self.enable()
        if st.flags & P.FLAG_CAPPED and not (st.flags & P.FLAG_HOMED and
                                            st.flags & P.FLAG_PAPER_MEASURED):
            say("uncapping")                 # the caps would be torn off (protocol 2.9)
            self.call(P.Op.CAP, on=0)
            self.wait_idle("uncapping")
        if not st.flags & P.FLAG_HOMED:
            say("homing")
            self.home()
        if not st.flags & P.FLAG_PAPER_MEASURED:
            say("measuring paper")
            self.measure_paper()
        return self.status()
