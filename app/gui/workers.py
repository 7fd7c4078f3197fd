"""Everything that runs off the UI thread (docs/gui.md, "Threading").

- ``Task``: a QRunnable for the preview pool (open, reduce, separate, halftone,
  estimate; re-render a preview with other separations).  Results come back through
  queued signals; the UI drops results it no longer wants (a newer request was made).
- ``PrinterWorker``: a QObject living in its own QThread that owns the printer: it opens
  the device, rips and prints tickets (one queue item, all its copies) with
  driver.job.PrintJob, runs test prints, clears faults.  Calls reach it as queued
  signals, so they run one after another; the only things the UI thread touches
  directly are thread-safe: ``JobControl`` (pause/resume/cancel/estop), the current
  job's ``Telemetry`` (read-only) and the live media canvas (under its own lock).
- On the emulator: ``LivePrinter`` (a device_sim Printer that hands every media row to
  the live view before it leaves the window) and the pacing wrappers that let the
  emulated machine run at real time or N x real time instead of as fast as possible.
"""

from __future__ import annotations

import logging
import threading
import time
import traceback
from dataclasses import dataclass, field
from pathlib import Path

import numpy as np
from PySide6.QtCore import QObject, QRunnable, Signal, Slot

from ...device_sim.printer import Printer
from ...driver.job import JobCancelled, JobControl, JobError, PrintJob
from ...rip.planes import render_rgb

log = logging.getLogger("wideprint.gui")

LIVE_MAX_PX = 1600


# --------------------------------------------------------------------------------------
# the preview pool

class TaskSignals(QObject):
    done = Signal(object, object)     # key, result
    failed = Signal(object, str)      # key, message


class Task(QRunnable):
    """Runs fn() in the pool; done(key, result) or failed(key, message)."""

    def __init__(self, key, fn):
        super().__init__()
        self.key, self.fn = key, fn
        self.signals = TaskSignals()
        self.setAutoDelete(True)

    def run(self) -> None:
        try:
            res = self.fn()
        except InterruptedError:
            return
        except Exception as exc:  # noqa: BLE001 - the operator sees the message in the queue
            msg = str(exc) or exc.__class__.__name__
            if not isinstance(exc, (ValueError, OSError)) and exc.__class__.__name__ != "ImageError":
                log.debug("preview task failed:\n%s", traceback.format_exc())
            self.signals.failed.emit(self.key, msg)
            return
        self.signals.done.emit(self.key, res)


# --------------------------------------------------------------------------------------
# the emulator: live media and pacing

class LiveSink:
    """The live view's canvas: rendered media rows, every `step`-th row and column.
    Written by the printer thread (and by the UI's mid-stroke polls), read by the UI."""

    def __init__(self, width: int, height: int, max_px: int = LIVE_MAX_PX):
        self.width, self.height = width, height
        self.step = max(1, -(-max(width, height) // max_px))
        self.canvas = np.full((-(-height // self.step), -(-width // self.step), 3), 255, np.uint8)
        self.lock = threading.Lock()
        self.version = 0
        self.rows_done = 0           # image rows written out for good
        self.media = None            # the emulator Media this sink follows

    def push(self, first: int, rows: np.ndarray, done_below: int | None = None) -> None:
        r0 = first // self.step
        n = min(rows.shape[0], self.canvas.shape[0] - r0) if rows.size else 0
        rgb = render_rgb(rows[:n, :self.canvas.shape[1]]) if n > 0 else None
        with self.lock:
            if rgb is not None:
                self.canvas[r0:r0 + n, :rgb.shape[1]] = rgb
            if done_below is not None:
                self.rows_done = max(self.rows_done, min(done_below, self.height))
            self.version += 1

    def image(self) -> tuple[np.ndarray, int]:
        with self.lock:
            return self.canvas.copy(), self.version


class LivePrinter(Printer):
    """The emulated printer, plus: every media row reaches the live view before it is
    written out (rows leave the media window when the paper carries them past the heads;
    a 200 ms poll alone would miss rows printed and fed out between two polls)."""

    live: LiveSink | None = None

    def _capture(self, flushing_to: int | None = None) -> None:
        sink, media = self.live, self.media
        if sink is None or media is None or media is not sink.media:
            return
        first, rows = media.snapshot(sink.step)
        sink.push(first, rows, first if flushing_to is None else flushing_to)

    def capture_now(self) -> None:
        self._capture()

    def before_media_flush(self) -> None:
        if self.live is not None:
            self._capture()

    def job_begin(self, job, x0, width, height, dpi, row_nm, y0) -> None:
        super().job_begin(job, x0, width, height, dpi, row_nm, y0)
        sink = self.live
        if sink is not None and self.media is not None and \
                (self.media.width, self.media.height) == (sink.width, sink.height):
            sink.media = self.media

    def before_job_end(self) -> None:
        if self.live is not None:
            self._capture(self.live.height)


class Pace:
    """Let the emulated machine run at `speed` x real time (0 = as fast as it can).
    Called after every exchange with the emulator: sleeps while simulated time is ahead
    of wall-clock time.  Never lends credit for idle periods; sleeps in slices of at most
    50 ms so cancel and emergency stop stay prompt."""

    def __init__(self, speed: float = 0.0):
        self.speed = float(speed)
        self._sim0 = self._wall0 = None

    def __call__(self, printer: Printer) -> None:
        speed = self.speed
        if speed <= 0:
            self._sim0 = None
            return
        now, sim = time.monotonic(), printer.time
        if self._sim0 is None:
            self._sim0, self._wall0, self._speed0 = sim, now, speed
        if speed != self._speed0:
            self._sim0, self._wall0, self._speed0 = sim, now, speed
        ahead = (sim - self._sim0) / speed - (now - self._wall0)
        if ahead > 0:
            time.sleep(min(ahead, 0.05))
        elif ahead < -0.25:                  # the host was slow or idle: no catching up
            self._sim0, self._wall0 = sim, now


class InProcessPacedSerial:
    """The in-process serial port with pacing; still synchronous (the `synchronous`
    attribute comes from the wrapped port)."""

    def __init__(self, port, printer: Printer, pace: Pace):
        self._port, self._printer, self._pace = port, printer, pace

    def write(self, data: bytes) -> int:
        n = self._port.write(data)
        self._pace(self._printer)
        return n

    def __getattr__(self, name):
        return getattr(self._port, name)

    def __setattr__(self, name, value):
        if name.startswith("_"):
            object.__setattr__(self, name, value)
        else:
            setattr(self._port, name, value)


class PacedData:
    def __init__(self, data, printer: Printer, pace: Pace):
        self._data, self._printer, self._pace = data, printer, pace

    def send(self, data: bytes) -> None:
        self._data.send(data)
        self._pace(self._printer)

    def __getattr__(self, name):
        return getattr(self._data, name)


def parse_faults(text: str):
    from ...device_sim.faults import Faults
    items = [t for t in text.replace(",", " ").split() if t]
    return Faults.parse(items)


# --------------------------------------------------------------------------------------
# the printer thread

@dataclass
class DeviceConfig:
    spec: str = "emulator"
    faults: str = ""
    profile_path: str = ""


@dataclass
class Ticket:
    """A print request: one queue item with all its copies, or one test print."""
    item_id: int
    path: str
    settings: object                    # JobSettings
    profile_path: str
    copies: int = 1
    kind: str = "image"                 # "image" | "pattern"
    pattern: dict = field(default_factory=dict)   # kind, width_mm, dpi, head, nozzle
    media_dir: str = ""
    media_file: str = ""                # test prints: write the media exactly here
    media_width_mm: float | None = None
    control: JobControl = field(default_factory=JobControl)
    device: "DeviceConfig | None" = None


class PrinterWorker(QObject):
    deviceChanged = Signal(object)           # connected, spec, paper_mm, info, temps, fault ...
    jobStarted = Signal(int, object)         # item id, {copy, copies, width, height, dpi, media, sink}
    jobState = Signal(int, str, str)        # item id, state, detail
    jobStroke = Signal(int, int, int, int, int)   # item id, copy, copies, stroke index, total
    jobFinished = Signal(int, object)        # item id, {state, message, media, reports}

    def __init__(self, pace: Pace):
        super().__init__()
        self.pace = pace
        self.dev = None
        self.cfg: DeviceConfig | None = None
        self.current_job: PrintJob | None = None
        self.live: LiveSink | None = None
        self.busy = False
        self._job_ids = 0
        self._media_paths: dict[int, str | None] = {}
        self.paper_mm: float | None = None

    # -- device -------------------------------------------------------------------------
    def _media_for(self, job_id: int):
        return self._media_paths.get(job_id)

    def _open(self, cfg: DeviceConfig) -> None:
        from ...rip.profile import load_profile
        from ..devices import open_device
        from .config import builtin_profile_path
        self._close()
        profile = load_profile(cfg.profile_path or None)
        spec = (cfg.spec or "emulator").strip()
        if spec == "emulator":
            # the live view's printer, paced to the machine's real speed
            dev = open_device(spec, profile, parse_faults(cfg.faults), media_path=self._media_for,
                              machine_profile=load_profile(builtin_profile_path()),
                              printer_class=LivePrinter,
                              wrap=lambda port, data, printer: (
                                  InProcessPacedSerial(port, printer, self.pace),
                                  PacedData(data, printer, self.pace)))
        else:
            if cfg.faults.strip():
                raise ValueError("emulator faults only apply to the emulator")
            dev = open_device(spec, profile)
        self.dev, self.cfg = dev, cfg
        try:
            self._prepare()
        except BaseException:
            self._close()
            raise

    @property
    def printer(self):
        """The printer API (driver/printer.py) on the open device."""
        from ...driver.printer import Printer
        return Printer(self.dev)

    def _prepare(self) -> None:
        from ...driver.printer import PrinterFault
        printer = self.printer
        try:
            printer.ready()                       # connect, configure, enable, home, measure
        except PrinterFault:
            st = printer.status()
            if st.fault == 0:
                raise
            # reachable but in a fault (e.g. after an emergency stop): stay connected, so
            # the operator can read the fault and clear it
            self._emit_device(st, self._head_temps())
            return
        paper = printer.paper()
        self.paper_mm = paper.width_mm if paper.present else None
        self._emit_device(printer.status(), self._head_temps())

    def _head_temps(self) -> tuple:
        """Head temperatures in °C (as PrintJob reads them)."""
        return self.printer.head_temperatures()

    def _emit_device(self, st=None, temps=(), error: str = "") -> None:
        from ...driver.printer import fault_message
        d = dict(connected=self.dev is not None, spec=self.cfg.spec if self.cfg else "",
                 paper_mm=self.paper_mm, error=error, temps=tuple(temps), fault="",
                 info=dict(self.dev.info or {}) if self.dev is not None else {},
                 emulator=self.dev is not None and self.dev.emulator is not None)
        if st is not None:
            d.update(carriage=st.carriage, paper_steps=st.paper_steps,
                     fifo=tuple(st.fifo[:len(self.dev.profile.heads)]), motion=int(st.motion),
                     fault="" if st.fault == 0 else fault_message(st, self.dev.profile))
        self.deviceChanged.emit(d)

    def _close(self) -> None:
        dev, self.dev = self.dev, None
        self.paper_mm = None
        if dev is not None:
            try:
                if dev.emulator is not None:
                    dev.emulator.close()
            finally:
                try:
                    dev.close()
                except Exception:  # noqa: BLE001 - closing a dead link
                    pass

    def _ensure(self, cfg: DeviceConfig) -> None:
        if self.dev is None or self.cfg is None or (self.cfg.spec, self.cfg.faults) != (cfg.spec, cfg.faults):
            self._open(cfg)

    @Slot(object)
    def connect_device(self, cfg: DeviceConfig) -> None:
        try:
            self._open(cfg)
            log.info("connected to %s (paper %s mm)", cfg.spec,
                     f"{self.paper_mm:.0f}" if self.paper_mm else "not measured")
        except Exception as exc:  # noqa: BLE001
            log.error("cannot connect to %s: %s", cfg.spec, exc)
            self._emit_device(error=str(exc))

    @Slot()
    def disconnect_device(self) -> None:
        self._close()
        self.cfg = None
        self._emit_device()
        log.info("disconnected")

    @Slot()
    def refresh(self) -> None:
        if self.dev is None or self.busy:
            return
        try:
            st = self.printer.status()
            self._emit_device(st, self._head_temps())
        except Exception as exc:  # noqa: BLE001
            self._emit_device(error=f"status: {exc}")

    @Slot()
    def clear_fault(self) -> None:
        if self.dev is None:
            return
        from ...driver import protocol as P
        try:
            self.printer.clear_fault()
            log.info("fault cleared")
            st = self.printer.status()
            if not st.flags & P.FLAG_HOMED or not st.flags & P.FLAG_PAPER_MEASURED:
                self._prepare()
            else:
                self._emit_device(st)
        except Exception as exc:  # noqa: BLE001
            log.error("clear fault: %s", exc)
            self._emit_device(error=str(exc))

    @Slot()
    def estop_idle(self) -> None:
        if self.dev is None:
            return
        try:
            self.printer.estop()
            log.warning("emergency stop")
            self._emit_device(self.printer.status())
        except Exception as exc:  # noqa: BLE001
            self._emit_device(error=str(exc))

    @Slot()
    def shutdown(self) -> None:
        self._close()

    # -- printing -----------------------------------------------------------------------
    def capture_live(self) -> None:
        """Called from the UI thread: bring the live canvas up to the running stroke, if the
        emulator is free this instant (never waits)."""
        dev = self.dev
        if dev is None or dev.emulator is None or self.live is None:
            return
        lock = getattr(dev.link.port, "lock", None)
        if lock is None or not lock.acquire(blocking=False):
            return
        try:
            dev.emulator.capture_now()
        finally:
            lock.release()

    @Slot(object)
    def run_ticket(self, t: Ticket) -> None:
        self.busy = True
        try:
            result = self._run_ticket(t)
        except Exception as exc:  # noqa: BLE001 - never let the printer thread die
            log.exception("printing %s", t.path)
            result = dict(state="failed", message=str(exc) or exc.__class__.__name__)
        finally:
            self.busy = False
            self.current_job = None
        self.jobFinished.emit(t.item_id, result)
        if self.dev is not None:
            self.refresh()

    def _rip_job(self, t: Ticket, profile):
        if t.kind == "pattern":
            from ...rip.testprints import PatternJob
            p = t.pattern
            k = profile.k(int(p.get("dpi", 150)))
            width = int(round(float(p.get("width_mm", 100.0)) / 25.4 * profile.counts_per_inch / k))
            return PatternJob.for_pattern(p["kind"], profile, width, int(p.get("dpi", 150)),
                                          **{x: p[x] for x in ("head", "nozzle") if x in p})
        from ...rip.pipeline import RipJob
        return RipJob(t.path, t.settings.rip_settings(
            t.media_width_mm or self._printable_mm(profile, t.settings.margin_mm)), profile)

    def _printable_mm(self, profile, margin_mm: float | None = None) -> float:
        from .jobsettings import printable_width_mm
        return printable_width_mm(profile, self.paper_mm, margin_mm)

    def _run_ticket(self, t: Ticket) -> dict:
        from ...rip.load import ImageError
        from ...rip.profile import ProfileError, load_profile
        if t.control.cancelled.is_set():
            return dict(state="cancelled", message="cancelled before it started")
        try:
            profile = load_profile(t.profile_path or None)
        except ProfileError as exc:
            return dict(state="failed", message=str(exc))
        base = t.device or self.cfg or DeviceConfig()
        cfg = DeviceConfig(base.spec, base.faults, t.profile_path)
        try:
            self._ensure(cfg)
        except Exception as exc:  # noqa: BLE001
            self._emit_device(error=str(exc))
            return dict(state="failed", message=f"cannot reach the printer: {exc}")
        self.dev.profile = profile
        reports, media = [], []
        state, message = "done", ""
        for copy in range(max(1, t.copies)):
            if t.control.cancelled.is_set():
                state, message = "cancelled", "cancelled"
                break
            try:
                rip = self._rip_job(t, profile)
            except (ImageError, ValueError, OSError) as exc:
                return dict(state="failed", message=str(exc), reports=reports, media=media)
            try:
                total_strokes = rip.planner().total_strokes
            except ValueError as exc:       # e.g. dead nozzles with 1 pass: refused, with why
                rip.close()
                return dict(state="failed", message=str(exc), reports=reports, media=media)
            self._job_ids += 1
            job_id = self._job_ids
            mpath = None
            if self.dev.emulator is not None:
                if t.media_file:
                    mpath = t.media_file
                elif t.media_dir:
                    stem = Path(t.path).stem if t.kind == "image" else t.pattern.get("kind", "test")
                    suffix = f"-copy{copy + 1}" if t.copies > 1 else ""
                    mpath = str(Path(t.media_dir) / f"{t.item_id:03d}-{stem}{suffix}.tif")
                    Path(t.media_dir).mkdir(parents=True, exist_ok=True)
            self._media_paths[job_id] = mpath
            live = None
            if self.dev.emulator is not None:
                live = LiveSink(rip.width, rip.height)
                self.dev.emulator.live = live
            self.live = live

            def on_event(kind, _id=t.item_id, _copy=copy, **kw):
                if kind == "state":
                    self.jobState.emit(_id, kw.get("state", ""), kw.get("detail", ""))
                elif kind == "stroke":
                    self.jobStroke.emit(_id, _copy, max(1, t.copies), int(kw["index"]), int(kw["total"]))
                elif kind == "recover":
                    log.warning("%s: %s (reconnecting, attempt %s)", kw.get("what"), kw.get("error"),
                                kw.get("attempt"))

            job = PrintJob(self.dev, rip, job_id=job_id, on_event=on_event)
            job.control = t.control
            self.current_job = job
            self.jobStarted.emit(t.item_id, dict(copy=copy, copies=max(1, t.copies), width=rip.width,
                                                 height=rip.height, dpi=rip.settings.dpi,
                                                 row_um=profile.row_um, media=mpath, sink=live,
                                                 strokes=total_strokes))
            try:
                rep = job.run()
                reports.append(rep.as_dict())
                if mpath:
                    media.append(mpath)
            except JobCancelled as exc:
                state, message = "cancelled", str(exc)
                reports.append(job.report.as_dict())
                break
            except JobError as exc:
                state, message = "failed", str(exc)
                reports.append(job.report.as_dict())
                break
            except (ImageError, ValueError, OSError) as exc:
                # a file that fails while it is being read: the job stops like any failure
                job._safe_stop()
                job._state("failed", str(exc))
                state, message = "failed", str(exc)
                reports.append(job.report.as_dict())
                break
            finally:
                self.current_job = None
                rip.close()
                if self.dev is not None and self.dev.emulator is not None:
                    self.dev.emulator.live = None
        return dict(state=state, message=message, reports=reports, media=media)

