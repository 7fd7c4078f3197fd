"""The print job state machine (docs/driver.md).

connect -> (head configuration) -> enable -> home -> measure paper -> place the job ->
per stroke: feed to the stroke's paper position, SET_LINE, DIR/DPI/WE_EN, preload the
FIFOs, START_LINE, stream on FIFO demand, wait for LINE_DONE, WE_EN off -> park -> report.
"""

from __future__ import annotations

import logging
import threading
import time
from dataclasses import dataclass, field

import numpy as np

from . import protocol as P
from .device import Device
from .headcare import HeadCare, nozzles_used
from .link import DeviceError, LineTooNoisy, LinkError
from .printer import Printer, PrinterFault, fault_message  # noqa: F401 - fault_message: re-exported
from .stream import StreamError, StrokeStreamer
from ..rip.load import ImageError
from ..rip.pipeline import RipJob, prefetch
from ..rip.profile import ProfileError
from ..rip.swath import StrokeData, top_margin_rows

log = logging.getLogger("wideprint.job")

HEAD_MASK_ALL = 0xFF
MAX_RECOVERIES = 5          # reconnections per stroke (or other step) before the job fails
STREAMING_POLL_S = 0.01     # status polls while a stroke's data streams (any device)


def resume_stroke(checkpoint: dict) -> int:
    """The first stroke a checkpoint's job has not printed: `next_stroke`, or `next_pass`
    in a checkpoint saved by an older version (it counted strokes under that name)."""
    if "next_stroke" in checkpoint:
        return int(checkpoint["next_stroke"])
    return int(checkpoint.get("next_pass", 0))


class JobCancelled(RuntimeError):
    """The operator cancelled the job."""


class JobControl:
    """Operator controls, safe to call from any thread (GUI, server, signal handler).
    Pause and cancel act at stroke boundaries (cancel also stops a running line);
    emergency stop acts at once."""

    def __init__(self) -> None:
        self._run = threading.Event()
        self._run.set()
        self.cancelled = threading.Event()
        self.estop_requested = threading.Event()

    def pause(self) -> None:
        self._run.clear()

    def resume(self) -> None:
        self._run.set()

    @property
    def paused(self) -> bool:
        return not self._run.is_set()

    def cancel(self) -> None:
        self.cancelled.set()
        self._run.set()

    def estop(self) -> None:
        self.estop_requested.set()
        self.cancel()

    def wait_while_paused(self, tick=None, every: float = 0.25) -> None:
        """Block while paused; `tick()` is called every `every` seconds meanwhile (head
        care keeps the nozzles wet)."""
        while not self._run.wait(every):
            if tick is not None:
                tick()


@dataclass
class Telemetry:
    """One snapshot of a job and its printer, for the GUI, the server and the CLI."""
    state: str = "queued"            # queued, connecting, printing, paused, done, failed, cancelled
    detail: str = ""
    stroke_index: int | None = None
    strokes_total: int = 0
    strokes_printed: int = 0
    carriage_counts: int = 0
    paper_steps: int = 0
    fires_done: int = 0
    fifo_words: tuple = ()
    head_temps_c: tuple = ()
    fault: str = ""
    retries: int = 0
    recoveries: int = 0


class JobError(RuntimeError):
    """A job that cannot be printed or was stopped by a device fault; the message says why
    and where (stroke, column, head)."""

    def __init__(self, message: str, fault: int = 0, stroke: int | None = None):
        super().__init__(message)
        self.fault, self.stroke = fault, stroke


class ResumeRefused(JobError):
    """The printer cannot confirm that the sheet holds what a checkpoint says (restarted,
    another job, or it cannot tell: docs/protocol.md 2.10), so the job must not go on
    from there.  `on_sheet` strokes of `total` were confirmed before; the caller holds the
    job or prints it again from its first stroke (docs/server.md "Crash recovery")."""

    def __init__(self, message: str, on_sheet: int, total: int):
        super().__init__(message)
        self.on_sheet, self.total = on_sheet, total


@dataclass
class JobReport:
    file: str
    state: str = "queued"
    strokes_total: int = 0
    strokes_printed: int = 0
    strokes_skipped: int = 0
    drops: list = field(default_factory=lambda: [0, 0, 0, 0])
    ink_ml: list = field(default_factory=lambda: [0.0] * 4)
    width_dots: int = 0
    height_rows: int = 0
    area_m2: float = 0.0
    retries: int = 0
    recoveries: int = 0
    min_fifo_words: int | None = None
    spits: int = 0                   # head care: spits during the job (docs/driver.md)
    wall_s: float = 0.0
    message: str = ""

    def as_dict(self) -> dict:
        return dict(self.__dict__)


class PrintJob:
    def __init__(self, device: Device, rip: RipJob, job_id: int = 1, on_event=None,
                 speed_mm_s: float | None = None, allow_overspeed: bool = False,
                 resume: dict | None = None, head_care: HeadCare | None = None):
        """resume: a checkpoint from an earlier run of the same job on the same printer
        (the `checkpoint` event / attribute): placement, paper origin and the next stroke;
        strokes before it are not printed again.  A checkpoint from an older version names
        the next stroke `next_pass`; it is read the same.  head_care: the printer's
        schedule kept by whoever holds the printer between jobs (a print server's worker);
        default: one for this job."""
        self.dev = device
        self.resume = resume
        self.checkpoint: dict = {}
        self._started: set[int] = set()      # strokes this run sent SET_LINE for
        self.speed_mm_s = speed_mm_s
        self.allow_overspeed = allow_overspeed
        self.rip = rip
        self.job_id = job_id
        self.profile = device.profile
        self.report = JobReport(file=rip.path)
        self.on_event = on_event or (lambda kind, **kw: None)
        self.poll_interval = device.timing.poll_interval_s
        self.control = JobControl()
        self.telemetry = Telemetry()
        self.printer = Printer(device, on_status=self._seen)   # every status read feeds the telemetry
        self.care = head_care
        self._state("queued")

    # -- telemetry --------------------------------------------------------------------------
    def _state(self, state: str, detail: str = "") -> None:
        self.telemetry.state, self.telemetry.detail = state, detail
        log.info("job %s: %s %s", self.job_id, state, detail)
        self.on_event("state", state=state, detail=detail)

    def _seen(self, st: P.Status) -> P.Status:
        """Every status the job reads updates the telemetry (no extra traffic)."""
        t = self.telemetry
        t.carriage_counts, t.paper_steps, t.fires_done = st.carriage, st.paper_steps, st.fires_done
        t.fifo_words = st.fifo[:len(self.profile.heads)]
        t.fault = "" if st.fault == P.Fault.NONE else fault_message(st, self.profile)
        t.retries = self.dev.link.retries
        self.on_event("status", telemetry=t)
        return st

    def _read_head_temps(self) -> None:
        try:
            self.telemetry.head_temps_c = self.printer.head_temperatures()
        except (LinkError, DeviceError):
            pass

    # -- device steps ---------------------------------------------------------------------
    def _wait(self, done, what: str, timeout: float = 120.0) -> P.Status:
        return self._command(lambda: self.printer.wait(done, what, timeout))

    def prepare(self) -> P.Status:
        """The printer brought to readiness (driver/printer.py `ready`).  A job starting
        afresh finds no line of an earlier run still going: a line left running or starved
        by a host that went away is stopped (its job, if resumed later, is refused by the
        printer's account: docs/protocol.md 2.10)."""
        st = self._command(lambda: self.printer.ready(
            on_step=lambda words: self._state("connecting", words)))
        if self.resume is None and st.motion == P.Motion.PRINTING:
            log.warning("job %s: the printer is still in a line of an earlier run (stroke %d); "
                        "stopping it", self.job_id, st.stroke)
            self._command(self.printer.stop)
            st = self._wait(lambda s: s.motion == P.Motion.IDLE, "the earlier line to stop")
        return st

    def place(self) -> int:
        """x0: encoder count of image column 0 on the measured paper, from the placement's
        side margins, alignment and offset (docs/placement.md, "Position on the paper");
        refuses a job that does not fit, before anything prints."""
        paper = self.printer.paper()
        present, left, right = paper.present, paper.left_counts, paper.right_counts
        if not present:
            raise JobError("no paper loaded", P.Fault.PAPER_OUT)
        prof = self.profile
        pl = self.rip.settings.placement
        cpi = prof.counts_per_inch
        k = prof.k(self.rip.settings.dpi)
        kmax = max(prof.k(d) for d in prof.dpi_modes)   # x0 on every dpi mode's column grid
        margin_mm = float(prof.paper.margin_mm if pl.margin_mm is None else pl.margin_mm)
        margin = int(round(margin_mm / 25.4 * cpi))
        lo, hi = left + margin, right - margin           # the printable span, counts
        width_counts = self.rip.width * k
        paper_mm = (right - left) / cpi * 25.4
        job_mm = width_counts / cpi * 25.4
        if width_counts > hi - lo:
            raise JobError(f"{self.rip.path}: image is {job_mm:.0f} mm wide at "
                           f"{self.rip.settings.dpi} dpi but the paper is {paper_mm:.0f} mm "
                           f"(with {margin_mm:g} mm margins)")
        offset = float(pl.x_mm) / 25.4 * cpi
        want = {"left": lo, "center": (lo + hi - width_counts) / 2,
                "right": hi - width_counts}[pl.align] + offset
        x0 = int(round(want / kmax)) * kmax
        if x0 < lo:                                      # rounding to the grid: stay inside
            x0 += kmax * -(-(lo - x0) // kmax)
        if x0 + width_counts > hi:
            x0 -= kmax * -(-(x0 + width_counts - hi) // kmax)
        if want < lo - kmax or want + width_counts > hi + kmax:
            where = (f"start {(lo - want) / cpi * 25.4:.1f} mm left of the left margin"
                     if want < lo else
                     f"end {(want + width_counts - hi) / cpi * 25.4:.1f} mm right of the right margin")
            raise JobError(f"{self.rip.path}: the image ({job_mm:.0f} mm wide, {pl.align} "
                           f"aligned, x offset {float(pl.x_mm):g} mm) would {where}; the paper "
                           f"is {paper_mm:.0f} mm with {margin_mm:g} mm margins")
        if x0 < lo:          # fits by less than one column of the coarsest grid
            raise JobError(f"{self.rip.path}: image is {job_mm:.1f} mm wide: it does not fit "
                           f"the {paper_mm:.0f} mm paper's printable width on the column grid "
                           f"(with {margin_mm:g} mm margins)")
        return x0

    def top_rows(self) -> int:
        """Blank rows of paper before the image's first row (placement top_mm)."""
        return top_margin_rows(self.profile, self.rip.settings)

    def feed_to(self, target_steps: int) -> None:
        st = self.printer.status()
        delta = target_steps - st.paper_steps
        if delta:
            self._command(lambda: self.printer.feed_steps(delta, wait=False))
            st = self._wait(lambda s: s.motion == P.Motion.IDLE, "feeding paper")
        if st.paper_steps != target_steps:
            raise JobError(f"paper is at step {st.paper_steps}, expected {target_steps}: "
                           f"feed error", P.Fault.PAPER_OUT)

    def line_speed(self) -> int:
        """Carriage speed in counts/s: the profile's for the dpi mode, or the job's own
        (--speed), which must not fire the heads faster than they can."""
        prof, dpi = self.profile, self.rip.settings.dpi
        if self.speed_mm_s is None:
            return prof.speed_counts_s(dpi)
        limit = prof.max_fire_hz * 25.4 / dpi
        if self.speed_mm_s > limit and not self.allow_overspeed:
            raise JobError(f"{self.speed_mm_s:.0f} mm/s at {dpi} dpi fires the heads at "
                           f"{self.speed_mm_s / 25.4 * dpi:.0f} Hz, above their "
                           f"{prof.max_fire_hz:.0f} Hz (limit {limit:.0f} mm/s)")
        return int(self.speed_mm_s / 25.4 * prof.counts_per_inch)

    def _fire_delays(self) -> None:
        """The calibration's fine shift per head and direction (docs/calibration.md) as
        FIRE_DELAY ticks at this job's line speed; JOB_BEGIN cleared them, so a profile
        without one writes nothing."""
        prof = self.profile
        _, fine_um = prof.fire_shift(self.rip.settings.dpi)
        if not fine_um.any():
            return
        v_um_s = self.line_speed() * 25_400.0 / prof.counts_per_inch
        ticks = np.minimum(np.rint(fine_um / v_um_s * P.FIRE_DELAY_HZ), 0xFFFF).astype(int)
        for d, base in enumerate((P.REG_FIRE_DELAY_FWD0, P.REG_FIRE_DELAY_REV0)):
            for h in range(len(prof.heads)):
                if ticks[d, h]:
                    self.dev.link.write_reg(base + h, int(ticks[d, h]))

    def _command(self, step):
        """A printer API call; a fault it meets (latched, or refusing the command) becomes
        this job's JobError, in the printer's words."""
        try:
            return step()
        except PrinterFault as exc:
            raise JobError(str(exc), exc.fault, exc.stroke) from None

    def _recovering(self, step, what: str):
        """Run a step; on a lost link reconnect and run it again (each step is written to
        pick up from the device's status, so nothing is done twice).  Reconnecting goes on
        while the link makes progress (commands are answered between the losses); it
        stops after MAX_RECOVERIES losses in a row with nothing answered, or at once when
        the measured bit error rate leaves the protocol no chance (LineTooNoisy)
        (docs/driver.md, "A noisy serial line")."""
        barren = 0
        while True:
            answered = self.dev.link.frames_ok
            try:
                return step()
            except (LinkError, StreamError) as exc:
                if isinstance(exc, LineTooNoisy):
                    raise
                self.dev.link.check_line()
                barren = barren + 1 if self.dev.link.frames_ok == answered else 1
                if barren > MAX_RECOVERIES:
                    raise
                self.report.recoveries += 1
                log.warning("%s: %s; reconnecting (%d without progress, of %d)", what, exc,
                            barren, MAX_RECOVERIES)
                self.on_event("recover", what=what, error=str(exc), attempt=barren)
                self._reconnect(data=isinstance(exc, StreamError))

    def _reconnect(self, data: bool) -> None:
        last = None
        for attempt in range(MAX_RECOVERIES):
            try:
                if data or not getattr(self.dev.data, "open", True):
                    self.dev.data.reconnect()
                self.dev.connect()
                self._same_printer()
                return
            except (LinkError, OSError) as exc:
                if isinstance(exc, LineTooNoisy):
                    raise
                last = exc
                self.dev.link.check_line()
                time.sleep(self.dev.timing.reconnect_backoff_s * (attempt + 1))
        ber = self.dev.link.quality.bit_error_rate()
        raise LinkError(f"cannot reconnect to the printer: {last}"
                        + (f" (the serial line's measured bit error rate is {ber:.1e})" if ber else ""))

    def print_stroke(self, stroke: StrokeData, x0: int) -> None:
        self._recovering(lambda: self._print_stroke_once(stroke, x0), f"stroke {stroke.index}")

    def _print_stroke_once(self, stroke: StrokeData, x0: int) -> None:
        link, prof = self.dev.link, self.profile
        dpi = self.rip.settings.dpi
        k = prof.k(dpi)
        first = x0 // k + stroke.first_column
        info = self.dev.info or {}
        st = link.status()
        # The stroke registers may still describe another job's (or copy's) last line with
        # the same number and length: only a line this job started (before a lost link),
        # or the one a resumed job stopped in, may be taken as its own.
        ours = stroke.index in self._started or (
            self.resume is not None and stroke.index == resume_stroke(self.resume))
        if ours and st.stroke == stroke.index and st.motion == P.Motion.IDLE and \
                st.flags & P.FLAG_LINE_DONE and st.fires_done == stroke.fires:
            link.write_reg(P.REG_WE_EN, 0)          # it finished while we were away
            return
        # A resumed job whose stroke a printer fault stopped part-way (the fault cleared
        # since): the columns fired stay printed, the line goes on from the next one
        # (docs/driver.md, "Resuming after a fault").
        done = st.fires_done if (ours and st.stroke == stroke.index and st.motion == P.Motion.IDLE
                                 and 0 < st.fires_done < stroke.fires) else 0
        fires = stroke.fires - done
        streamer = StrokeStreamer(self.dev.data, stroke.index, stroke.words[:, done:],
                                  info.get("block_fires", prof.block_fires),
                                  info.get("ring_blocks", prof.ring_blocks), HEAD_MASK_ALL)
        if ours and st.stroke == stroke.index and st.motion == P.Motion.PRINTING:
            streamer.resume()                       # the line is running or starved: feed it
        else:
            self._started.add(stroke.index)
            if done:
                log.info("stroke %d: resuming after column %d of %d", stroke.index, done, stroke.fires)
                self.on_event("stroke_resumed", index=stroke.index, fires_done=done)
            # forward strokes fire their columns upwards, reverse ones downwards: the columns
            # left are the top ones going forward and the bottom ones going back
            start = first + done if stroke.direction == 0 else first
            speed, accel = self.line_speed(), prof.accel_counts_s2()
            streamer.discard_stale()                # earlier lines' reports (protocol 3.2)
            link.call(P.Op.SET_LINE, stroke=stroke.index, direction=stroke.direction, dpi=dpi,
                      fire_start=start, fire_count=fires, speed=speed, accel=accel)
            link.write_reg(P.REG_DIR, 1 if stroke.direction == 0 else 0)
            link.write_reg(P.REG_DPI, P.DPI_CODE[dpi])
            link.write_reg(P.REG_WE_EN, 1)
            streamer.preload()
            link.command(P.Op.START_LINE)
        streamer.start()
        try:
            st = self._watch_line(stroke, streamer)
        finally:
            streamer.stop()
        if streamer.error is not None:
            raise StreamError(str(streamer.error))
        if st.fires_done != fires:
            raise JobError(f"stroke {stroke.index}: {st.fires_done} of {fires} columns fired")
        link.write_reg(P.REG_WE_EN, 0)
        if streamer.min_fifo_words is not None:
            m = self.report.min_fifo_words
            self.report.min_fifo_words = streamer.min_fifo_words if m is None else min(m, streamer.min_fifo_words)

    def _watch_line(self, stroke: StrokeData, streamer: StrokeStreamer) -> P.Status:
        link, prof = self.dev.link, self.profile
        deadline = time.monotonic() + 60 + stroke.fires / 1000
        while True:
            if self.control.estop_requested.is_set():
                self._estop()
            elif self.control.cancelled.is_set():
                link.command(P.Op.STOP)
                raise JobCancelled(f"cancelled during stroke {stroke.index}")
            st = self.printer.status()
            if st.fault != P.Fault.NONE:
                raise JobError(f"stroke {stroke.index}: {fault_message(st, prof)}", st.fault,
                               stroke.index)
            if streamer.error is not None:      # the device's own report (above) comes first
                raise StreamError(str(streamer.error))
            if streamer.done and st.flags & P.FLAG_LINE_DONE and st.motion == P.Motion.IDLE:
                return st
            if time.monotonic() > deadline:
                raise JobError(f"stroke {stroke.index}: the line did not finish")
            if streamer.done:
                time.sleep(self.poll_interval or 0.001)
            else:
                # while the data streams, status every 10 ms is enough (a real printer's
                # pace); an in-process device polled every millisecond takes the
                # interpreter from the streaming thread that drives it
                streamer.wait(max(self.poll_interval, STREAMING_POLL_S))

    # -- resuming: what the printer must confirm (docs/protocol.md 2.10) -------------------------
    def confirm_resume(self, total: int) -> str:
        """Whether this job may go on from its checkpoint: "open" (the printer holds the
        job, on the sheet as the checkpoint says, or one stroke further) or "ended" (the
        printer ended it after every stroke: the copy is complete).  Raises ResumeRefused
        otherwise, saying how many strokes the sheet holds."""
        cp = self.resume
        n, lines = resume_stroke(cp), int(cp.get("lines", -1))
        on_sheet = f"{n} of {total} strokes are on the sheet"

        def refuse(why: str):
            raise ResumeRefused(f"{why}: {on_sheet}", n, total)

        js = self.printer.job_status()
        if js is None:
            info = self.dev.info or {}
            refuse(f"the printer cannot confirm its job (protocol {info.get('proto_major')}."
                   f"{info.get('proto_minor')} has no JOB_STATUS)")
        if cp.get("boot") is None or lines < 0:
            refuse("the checkpoint does not say which power-up of the printer it was made on")
        if js.boot != cp["boot"]:
            refuse("the printer was restarted")
        if js.job != self.job_id or js.job_state == P.JobState.NONE:
            refuse(f"the printer holds another job ({'none' if js.job == P.NO_JOB else js.job})")
        last = n - 1 if n > 0 else P.NO_STROKE
        if js.job_state == P.JobState.ENDED:
            if n >= total and js.lines_done == lines:
                return "ended"
            refuse(f"the printer ended the job after {js.lines_done} lines")
        if js.lines_done == lines and (js.last_stroke == last or lines == 0):
            return "open"
        if js.lines_done == lines + 1 and js.last_stroke != P.NO_STROKE and \
                (js.last_stroke >= n or n == 0):
            return "open"                 # the stroke in flight finished after the checkpoint
        refuse(f"the printer has {js.lines_done} lines of the job (last stroke "
               f"{'none' if js.last_stroke == P.NO_STROKE else js.last_stroke}), the checkpoint "
               f"{lines}")

    def _same_printer(self) -> None:
        """After a reconnection inside the job: the printer must be the one that has the
        job's beginning (same power-up, docs/protocol.md 2.10); printing the rest onto a
        restarted printer's sheet would be a print without its beginning."""
        boot = self.checkpoint.get("boot")
        if boot is None:
            return
        js = self.printer.job_status()
        if js is not None and js.boot != boot:
            n = int(self.checkpoint.get("next_stroke", 0))
            total = self.report.strokes_total
            raise ResumeRefused(f"the printer was restarted during the job: {n} of {total} "
                                f"strokes are on the sheet", n, total)

    # -- the whole job -------------------------------------------------------------------------
    def run(self) -> JobReport:
        t0 = time.monotonic()
        rep, prof, rip = self.report, self.profile, self.rip
        rep.state = "printing"
        rep.width_dots, rep.height_rows = rip.width, rip.height
        strokes = None
        try:
            try:                                 # planned first: a refusal moves nothing
                planner = rip.planner()
            except ProfileError as exc:          # e.g. dead nozzles a single pass cannot avoid
                raise JobError(f"{rip.path}: {exc}") from None
            self.line_speed()
            # the RIP starts now, on its own thread: the first strokes are made while the
            # printer is connected, homed and the job placed (a full-width job's first stroke
            # takes ~0.2 s to RIP; the printer's readiness as long again)
            strokes = prefetch(rip.strokes(planner), depth=2)
            rep.strokes_total = self.telemetry.strokes_total = planner.total_strokes
            resumed = None
            if self.resume and self.resume.get("ended"):
                resumed = "ended"                # JOB_END was confirmed: the copy is complete
            elif self.resume:
                self._state("connecting", "confirming the printer's job")
                self._recovering(self.printer.connect, "connecting")
                try:
                    resumed = self._recovering(
                        lambda: self.confirm_resume(planner.total_strokes),
                        "confirming the printer's job")
                except ResumeRefused as exc:
                    self._count_on_sheet(strokes, exc.on_sheet)
                    raise
            if resumed == "ended":
                return self._counted_only(strokes)
            self._state("connecting")
            self._recovering(self.prepare, "connecting")
            if self.care is None:
                self.care = HeadCare(self.printer)
            spits0 = self.care.spits
            self._read_head_temps()
            self._state("printing")
            x0 = self.resume["x0"] if self.resume else self._recovering(self.place, "placing the job")
            link = self.dev.link
            top = self.top_rows()                # the top margin: image row 0 that much later
            begin = dict(job=self.job_id, x0=x0, width=rip.width, height=rip.height,
                         dpi=rip.settings.dpi, row_nm=prof.row_nm, y0=planner.y0_rows + top)
            self._recovering(lambda: link.call(P.Op.JOB_BEGIN, **begin), "starting the job")
            self._recovering(self._fire_delays, "setting the fire delays")
            paper0 = self.resume["paper0"] if self.resume else self._recovering(
                lambda: link.status().paper_steps, "reading the paper position")
            next_stroke = resume_stroke(self.resume) if self.resume else 0
            # the printer's power-up this job's strokes land in (docs/protocol.md 2.10)
            js = self._recovering(self.printer.job_status, "reading the printer's job")
            self._checkpoint(x0=x0, paper0=paper0, next_stroke=next_stroke,
                             boot=None if js is None else js.boot,
                             lines=int(self.resume.get("lines", 0)) if self.resume else 0)
            top0 = planner.top_row(0) - top
            for stroke in strokes:
                if stroke.index < next_stroke:       # printed before the interruption
                    rep.strokes_printed += 1
                    for c in range(4):
                        rep.drops[c] += int(stroke.dots[c])
                    continue
                self._between_strokes(stroke.index)
                self.telemetry.stroke_index = stroke.index
                target = paper0 + prof.feed_steps_for_rows(stroke.top_row - top0)
                self._recovering(lambda: self.feed_to(target), f"feed before stroke {stroke.index}")
                self.on_event("stroke", index=stroke.index, total=planner.total_strokes,
                              direction=stroke.direction, fires=stroke.fires)
                used = nozzles_used(stroke.words)
                if self._in_line(stroke):
                    # the resumed stroke's line is still going (starved when the host went
                    # away): the heads are mid-line, a spit would be refused BUSY
                    wet = (self._recovering(self.care.now_ms, "the drying clock")
                           if self.care.active else 0)
                else:
                    wet = self._recovering(lambda: self.care.before_stroke(used),
                                           f"head care before stroke {stroke.index}")
                rep.spits = self.care.spits - spits0
                self.print_stroke(stroke, x0)
                self.care.after_stroke(used, wet)
                rep.strokes_printed += 1
                self.telemetry.strokes_printed = rep.strokes_printed
                self._checkpoint(next_stroke=stroke.index + 1, lines=rep.strokes_printed)
                self._read_head_temps()
                for c in range(4):
                    rep.drops[c] += int(stroke.dots[c])
            # feed the last rows out past the heads, then park
            out = paper0 + prof.feed_steps_for_rows(
                planner.top_row(planner.total_strokes - 1) - top0 + prof.swath_rows)
            self._recovering(lambda: self.feed_to(out), "feeding the job out")
            self._recovering(lambda: link.call(P.Op.JOB_END, job=self.job_id),
                             "ending the job")
            self._checkpoint(ended=True)         # the copy is complete on the sheet
            self._recovering(lambda: self._command(lambda: self.printer.park(wait=False)), "parking")
            rep.strokes_skipped = rep.strokes_total - rep.strokes_printed
            rep.state = "done"
            self._state("done")
        except ResumeRefused as exc:
            rep.state, rep.message = "failed", str(exc)
            self._state("failed", rep.message)
            raise
        except JobCancelled as exc:
            rep.state, rep.message = "cancelled", str(exc)
            self._safe_stop()
            self._state("cancelled", str(exc))
            raise
        except (JobError, LinkError, DeviceError, StreamError, ImageError) as exc:
            # ImageError: the file broke while streaming (a corrupt strip far down)
            rep.state = "failed"
            rep.message = self._failure_words(exc)
            self._safe_stop()
            self._state("failed", rep.message)
            raise JobError(rep.message, getattr(exc, "fault", 0), getattr(exc, "stroke", None)) from exc
        finally:
            if strokes is not None:
                strokes.close()                  # a job that ended early stops its RIP
            rep.retries = self.dev.link.retries
            self.telemetry.recoveries = rep.recoveries
            rep.wall_s = time.monotonic() - t0
            pl = prof.drop_volume_pl
            rep.ink_ml = [round(d * pl * 1e-9, 6) for d in rep.drops]
            k = prof.k(rip.settings.dpi)
            rep.area_m2 = (rip.width * k / prof.counts_per_inch * 0.0254) * \
                (rip.height * prof.row_um * 1e-6)
        return rep

    def _in_line(self, stroke: StrokeData) -> bool:
        """Whether the printer is in this stroke's line already: only the stroke a resumed
        job stopped in can be (docs/driver.md, recovery)."""
        if self.resume is None or stroke.index != resume_stroke(self.resume):
            return False
        st = self._recovering(self.dev.link.status, f"status before stroke {stroke.index}")
        return st.motion == P.Motion.PRINTING and st.stroke == stroke.index

    def _count_on_sheet(self, strokes, n: int) -> None:
        """The report of a job that stops before printing: the strokes before `n` (those
        the checkpoint says are on the sheet) and their drops, for the accounting."""
        rep = self.report
        for stroke in strokes:
            if stroke.index >= n:
                break
            rep.strokes_printed += 1
            for c in range(4):
                rep.drops[c] += int(stroke.dots[c])

    def _counted_only(self, strokes) -> JobReport:
        """A copy the printer completed before the host lost it (its JOB_END confirmed):
        nothing is printed again; the report counts its strokes and drops."""
        rep = self.report
        for stroke in strokes:
            rep.strokes_printed += 1
            for c in range(4):
                rep.drops[c] += int(stroke.dots[c])
        rep.strokes_skipped = rep.strokes_total - rep.strokes_printed
        rep.state = "done"
        self._state("done", "completed before the interruption")
        return rep

    def _failure_words(self, exc: Exception) -> str:
        """What went wrong in plain words: a command refused because the printer latched a
        fault names that fault, not the refusal."""
        if isinstance(exc, DeviceError) and exc.result == P.Result.FAULT_ACTIVE:
            try:
                fault = self.printer.fault_text()
            except Exception:  # noqa: BLE001 - the refusal is all we know
                fault = ""
            if fault:
                return f"{P.op_name(exc.op)} refused: {fault}"
        return str(exc)

    def _checkpoint(self, **values) -> None:
        self.checkpoint.update(values)
        self.on_event("checkpoint", checkpoint=dict(self.checkpoint))

    def _estop(self) -> None:
        try:
            self.printer.estop()
        finally:
            raise JobError("emergency stop by the operator", P.Fault.ESTOP)

    def _between_strokes(self, next_index: int) -> None:
        c = self.control
        if c.estop_requested.is_set():
            self._estop()
        if c.paused and not c.cancelled.is_set():
            self._state("paused", f"before stroke {next_index}")
            since = time.monotonic()
            c.wait_while_paused(lambda: self._keep_wet(since))
            self._state("printing")
        if c.estop_requested.is_set():
            self._estop()
        if c.cancelled.is_set():
            raise JobCancelled(f"cancelled before stroke {next_index}")

    def _keep_wet(self, since: float) -> None:
        """While paused: head care (spit, cap); a failure here waits for the resume."""
        try:
            self.care.idle(since)
        except (LinkError, DeviceError, PrinterFault) as exc:
            log.warning("job %s: head care while paused: %s", self.job_id, exc)

    def _safe_stop(self) -> None:
        """After a failure: heads off, carriage stopped; errors here are secondary."""
        try:
            self.dev.link.write_reg(P.REG_WE_EN, 0)
        except Exception:  # noqa: BLE001 - the original error is what the operator needs
            pass
        try:
            self.printer.stop()
        except Exception:  # noqa: BLE001
            pass
