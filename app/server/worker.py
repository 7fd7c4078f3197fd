"""The print worker: one per printer; prints that printer's queued jobs (and those for any
printer) one at a time, persisting each job's checkpoint after every stroke.  A printer
fault stops this printer's queue at the job, which waits with its checkpoint until the
operator clears the fault; the other printers go on (docs/server.md, "The worker",
"Printer faults")."""

from __future__ import annotations

import json
import logging
import os
import threading
import time
from typing import Any

from ...rip.swath import top_margin_rows
from . import archive, crashpoints, fsck, heap
from .ports import WorkerHost  # what it sees of the server (core.py composes it)
from .ripped import planes_job
from .rolls import ROLL_HELD
from .spool import COLORS, disk_full
from .validate import job_rip_settings

#: events an in-process emulator keeps (device_sim/printer.py): its deque of 200,000 took
#: ~100 MB per printer in the 30-minute GUI soak (it is polled while idle); 20,000 is ~10 MB
#: and still holds a long job's events
EMULATOR_EVENTS_KEPT = 20_000

log = logging.getLogger("wideprint.server")

# printer job ids of test prints: above every spool job id (docs/server.md, "Test prints")
TEST_PRINT_BASE = 0x8000_0000
CARE_RETRY_S = 30.0                  # idle head care on a printer that did not answer
DISK_RETRY_S = (0.5, 30.0)           # a full state disk: first wait, longest wait (doubling)


class DiskFull(Exception):
    """The server is stopping while a state change waits for disk space: nothing was
    recorded, and the next start recovers from what was (docs/server.md "Full disks")."""


# -- the worker -------------------------------------------------------------------------------
class Worker(threading.Thread):
    """One printer: prints its queued jobs one at a time, in queue order."""

    def __init__(self, server: WorkerHost, printer=None, profile=None):
        from .config import PrinterConfig
        self.printer = printer or PrinterConfig("main", server.config.device,
                                                server.config.profile_path)
        self.name_ = self.printer.name
        super().__init__(name=f"wideprint-worker-{self.name_}", daemon=True)
        self.srv = server
        self.profile = profile if profile is not None else server.profile
        self.spool = server.spool
        self.fault = ""                    # the printer fault that stopped this printer
        self.disk_wait = ""                # a state change waiting for disk space (why)
        self.wake = threading.Condition()
        self.paused = server.config.start_paused
        self.pause_reason = "started paused" if self.paused else ""
        self.stopping = False
        self.dev = None
        self.printer_state = "idle"        # idle, printing, offline, fault
        self.printer_error = ""
        self.current: dict | None = None   # id, name, copy, state, detail, stroke, ...
        self.job = None                    # the PrintJob now running
        self._cancel: set[int] = set()
        self._backoff = server.config.reconnect_backoff[0]
        self._tests: list[dict] = []       # test prints asked for, run between jobs
        self._service: list[dict] = []     # head care asked for (spit, purge, cap), idem
        self.care = None                   # the printer's head-care schedule (HeadCare)
        self.capped: bool | None = None    # as last seen (None: not known yet)
        self._idle_since = time.monotonic()
        self._care_retry = 0.0             # idle head care paused until then (link down)
        self.live = None                   # an emulated printer's media as it lands (LiveMedia)
        self.paper_mm: float | None = None # the paper's width as last measured
        self._test_ids = 0
        self._profile_mtime = self._mtime(self.profile.path)
        self._next_expiry = time.monotonic() + 60   # the server expired them at start-up
        self._steps0: int | None = None    # the paper's position when this copy's run began
        self._fed_before = 0.0             # mm this copy fed before a crash (a resumed copy)
        self._fed_by = None                # the PrintJob whose telemetry tells where it is now

    # -- recording state changes on a disk that may be full ----------------------------------
    def _durable(self, write, what: str):
        """A state change the worker must record (claim, a copy's end, the job's end ...):
        retried with back-off while the state directory's disk is full — never given up
        for a job's failure, never a busy loop — until it commits (docs/server.md "Full
        disks").  Other errors pass.  Raises DiskFull when the server stops meanwhile."""
        delay = DISK_RETRY_S[0]
        warned = False
        while True:
            try:
                out = write()
            except Exception as exc:  # noqa: BLE001 - only a full disk is waited for
                if not disk_full(exc):
                    raise
                if not warned:
                    log.warning("printer %s: cannot record %s: the state directory's disk is "
                                "full (%s); waiting for space, retrying", self.name_, what, exc)
                    warned = True
                self.disk_wait = f"waiting for disk space to record {what}"
                if self.stopping:
                    raise DiskFull(f"{what} not recorded: the disk is full") from None
                with self.wake:
                    self.wake.wait(delay)
                delay = min(delay * 2, DISK_RETRY_S[1])
                continue
            if warned:
                log.info("printer %s: %s recorded: disk space is back", self.name_, what)
            self.disk_wait = ""
            return out

    # control from other threads
    def notify(self) -> None:
        with self.wake:
            self.wake.notify_all()

    def set_paused(self, paused: bool, reason: str = "") -> None:
        self.paused = paused
        self.pause_reason = reason if paused else ""
        self.notify()

    def clear_fault(self, then: str = "resume") -> dict:
        """The operator cleared the printer (loaded paper, let a head cool, freed the rail):
        CLEAR_FAULT on the printer, then the job the fault stopped goes back to the head of
        the queue to resume at its first unfinished stroke (`then="resume"`) or fails
        (`then="fail"`), and this printer's queue runs again."""
        from ...driver.link import LinkError
        from ...driver.printer import Printer
        if then not in ("resume", "fail"):
            raise ValueError("then must be 'resume' or 'fail'")
        if self.job is not None:
            raise RuntimeError(f"printer {self.name_} is printing: nothing to clear")
        cleared = ""
        try:
            printer = Printer(self._device())
            printer.connect()
            code = printer.clear_fault()
            cleared = printer.fault_text() or ("" if not code else f"fault 0x{code:02X} cleared")
        except (LinkError, OSError, ValueError) as exc:
            raise RuntimeError(f"printer {self.name_}: cannot clear the fault: {exc}") from None
        jobs = self.spool.fault_stopped(self.name_)
        for job in jobs:
            if then == "resume":
                self.spool.resume_after_fault(job["id"])
            else:
                self._finish(job, "failed", f"{job['fault']} (failed by the operator)")
        self.fault = ""
        self.printer_state, self.printer_error = "idle", ""
        self.set_paused(False)
        log.info("printer %s: fault cleared; job(s) %s %s", self.name_,
                 ", ".join(str(j["id"]) for j in jobs) or "-", "resumed" if then == "resume" else "failed")
        return dict(printer=self.name_, jobs=[j["id"] for j in jobs], then=then, still=cleared)

    @staticmethod
    def _mtime(path) -> int | None:
        try:
            return os.stat(path).st_mtime_ns if path else None
        except OSError:
            return None

    def _fresh_profile(self) -> None:
        """The printer profile re-read when its file changed (the GUI's calibration wrote
        it): the next job and test print use the new dead nozzles, offsets, ..."""
        from ...rip.profile import ProfileError, load_profile
        m = self._mtime(self.profile.path)
        if m is None or m == self._profile_mtime:
            return
        try:
            prof = load_profile(self.profile.path)
        except ProfileError as exc:
            log.error("printer %s: the changed profile is refused, the old one stays: %s",
                      self.name_, exc)
            self._profile_mtime = m
            return
        self.profile, self._profile_mtime = prof, m
        self.srv.profiles[self.name_] = prof
        if self.dev is not None:
            self.dev.profile = prof
        log.info("printer %s: profile %s re-read", self.name_, prof.path)

    def test_print(self, pattern: dict, timeout: float = 600.0) -> dict:
        """A test pattern (rip/testprints.py) printed between jobs, even with the queue
        paused, never on a printer with a fault: {state, message, media, report}."""
        if self.fault:
            raise RuntimeError(f"printer {self.name_} has a fault ({self.fault}): clear it first")
        req = dict(pattern=dict(pattern), done=threading.Event(), result=None)
        with self.wake:
            self._tests.append(req)
            self.wake.notify_all()
        if not req["done"].wait(timeout):
            raise RuntimeError(f"printer {self.name_}: the test print did not end within {timeout:.0f} s")
        return req["result"]

    def _run_test(self, req: dict) -> None:
        from ...driver.job import JobCancelled, JobError, PrintJob
        from ...driver.link import LinkError
        from ...rip.testprints import PatternJob
        p = req["pattern"]
        result = dict(state="failed", message="", media=None, report=None)
        try:
            self._fresh_profile()
            prof = self.profile
            dpi = int(p.get("dpi", 150))
            k = prof.k(dpi)
            width = int(round(float(p.get("width_mm", 100.0)) / 25.4 * prof.counts_per_inch / k))
            rip = PatternJob.for_pattern(p["kind"], prof, width, dpi,
                                         **{x: p[x] for x in ("head", "nozzle") if x in p})
            self._test_ids += 1
            job_id = TEST_PRINT_BASE + self._test_ids
            self.current = dict(id=None, name=f"test print: {p['kind']}", copy=1, copies=1,
                                state="printing", detail="", stroke_index=None,
                                strokes_total=0, strokes_printed=0, resumed=False)
            self.printer_state = "printing"
            pj = PrintJob(self._device(), rip, job_id=job_id, head_care=self._care())
            self.job = self._fed_by = pj
            self._steps0, self._fed_before = self._paper_steps(self._device()), 0.0
            try:
                rep = pj.run()
            finally:                         # a test print's paper comes off the roll too
                self.srv.rolls.used(self.name_, self._paper_fed_mm())
            media = self.srv.config.media_dir
            path = media / f"testprint-{self._test_ids}.tif" if media else None
            result.update(state="done", report=rep.as_dict(),
                          media=str(path) if path is not None and path.exists() else None)
        except (JobCancelled, JobError, LinkError, ValueError, OSError, KeyError) as exc:
            result["message"] = str(exc) or type(exc).__name__
        except Exception as exc:  # noqa: BLE001 - the worker must go on
            log.exception("test print")
            result["message"] = f"internal error: {exc}"
        finally:
            self.job, self.current = None, None
            if self.printer_state == "printing":
                self.printer_state = "idle"
            req["result"] = result
            req["done"].set()

    def cancel(self, job_id: int) -> bool:
        cur = self.current
        if cur is None or cur["id"] != job_id:
            return False
        self._cancel.add(job_id)
        job = self.job
        if job is not None:
            job.control.cancel()
        return True

    def forget_cancel(self, job_id: int) -> None:
        """A requeued job: a cancel meant for its earlier attempt must not stop this one."""
        self._cancel.discard(job_id)

    def interrupt(self, timeout: float) -> None:
        """Server shutdown: the running job pauses at its next stroke boundary (its
        checkpoint is saved), so a restart resumes it; the worker takes nothing new."""
        self.stopping = True
        self.notify()
        job = self.job
        if job is None:
            return
        job.control.pause()
        deadline = time.monotonic() + timeout
        while time.monotonic() < deadline and self.job is job and job.telemetry.state != "paused":
            time.sleep(0.05)

    # the loop
    def run(self) -> None:
        while not self.stopping:
            if time.monotonic() >= self._next_expiry:
                self._next_expiry = time.monotonic() + 60
                try:
                    self.srv.expire_spool()
                except Exception:  # noqa: BLE001 - housekeeping must not end the worker
                    log.exception("expiring spool copies")
            if self._tests and not self.fault:
                self._run_test(self._tests.pop(0))
                self._idle_since = time.monotonic()
                continue
            if self._service and not self.fault:
                self._run_service(self._service.pop(0))
                continue
            job = None
            if not self.paused:
                try:
                    job = self._next_job()
                except Exception:  # noqa: BLE001 - a database hiccup must not end the worker
                    log.exception("reading the queue")
            if job is None:
                self._keep_wet()
                heap.give_back_when_idle()   # the jobs' freed C heap back to the system
                with self.wake:
                    self.wake.wait(0.5)
                continue
            try:
                self._run_job(job["id"])
            except DiskFull as exc:
                log.warning("printer %s: job %s: %s; the next start goes on from what was "
                            "recorded", self.name_, job["id"], exc)
            except Exception as exc:  # noqa: BLE001 - never let one job end the server
                if disk_full(exc):           # not the job's failure: wait for space
                    log.warning("printer %s: job %s: the state directory's disk is full (%s); "
                                "waiting", self.name_, job["id"], exc)
                    with self.wake:
                        self.wake.wait(DISK_RETRY_S[1] / 4)
                    continue
                log.exception("job %s", job["id"])
                try:
                    self._finish(self.spool.get(job["id"]), "failed", f"internal error: {exc}")
                except Exception:  # noqa: BLE001
                    log.exception("failing job %s", job["id"])
            finally:
                self.current, self.job = None, None
                self._idle_since = time.monotonic()
                if self.printer_state == "printing":
                    self.printer_state = "idle"
                heap.job_ended()             # its freed C heap goes back once idle

    # -- head care (docs/server.md "Head care", docs/driver.md) ----------------------------------
    def _care(self):
        """The printer's head-care schedule, kept between jobs (it knows which nozzles
        fired when); a new one after the device was reopened."""
        from ...driver.headcare import HeadCare
        from ...driver.printer import Printer
        dev = self._device()
        if self.care is None or self.care.printer.device is not dev:
            printer = Printer(dev)
            if dev.info is None:
                printer.connect()
            self.care = HeadCare(printer)
        return self.care

    def _keep_wet(self) -> None:
        """Idle: spit every spit interval, park and cap after cap_after_s.  Only a printer
        this server has opened (an unopened one is left as it is), never one with a fault."""
        if self.dev is None or self.fault or time.monotonic() < self._care_retry:
            return
        from ...driver.link import DeviceError, LinkError
        from ...driver.printer import PrinterFault
        try:
            care = self._care()
            care.idle(self._idle_since)
            self.capped = bool(care.status().capped) if care.active else None
        except (LinkError, DeviceError, PrinterFault, OSError) as exc:
            # an unreachable printer is tried again in a while, not every half second
            log.warning("printer %s: head care while idle: %s (again in %.0f s)", self.name_,
                        exc, CARE_RETRY_S)
            self._care_retry = time.monotonic() + CARE_RETRY_S
            self.care, self.capped = None, None

    def service(self, action: str, mask: int, amount: int | None, timeout: float = 120.0) -> dict:
        """Spit, purge, cap or uncap between jobs (the printer's queue may be paused):
        answers when done."""
        if self.fault:
            raise RuntimeError(f"printer {self.name_} has a fault ({self.fault}): clear it first")
        if self.job is not None:
            raise RuntimeError(f"printer {self.name_} is printing: head care runs between jobs "
                               f"(a job spits for itself)")
        req = dict(action=action, mask=mask, amount=amount, done=threading.Event(), result=None)
        with self.wake:
            self._service.append(req)
            self.wake.notify_all()
        if not req["done"].wait(timeout):
            raise RuntimeError(f"printer {self.name_}: {action} did not end within {timeout:.0f} s")
        return req["result"]

    def _run_service(self, req: dict) -> None:
        from ...driver.link import DeviceError, LinkError
        from ...driver.printer import PrinterFault
        result = dict(action=req["action"], state="failed", message="")
        try:
            care = self._care()
            care.printer.ready()             # enabled and homed (uncapped first if need be)
            if req["action"] == "spit":
                care.spit(req["mask"], req["amount"])
            elif req["action"] == "purge":
                care.purge(req["mask"], req["amount"])
            else:
                care.cap(req["action"] == "cap")
            self.capped = bool(care.status().capped)
            result["state"] = "done"
        except (LinkError, DeviceError, PrinterFault, OSError, ValueError) as exc:
            result["message"] = str(exc)
        finally:
            self._idle_since = time.monotonic()
            req["result"] = result
            req["done"].set()

    def _next_job(self) -> dict | None:
        """The next job for this printer (`_pick_job`), unless the loaded roll cannot hold
        what is left of it: such a job is held, with the reason, before a stroke of it is
        printed, and the next is taken (docs/server.md "Rolls").  A job started already, a
        nested sheet and one the operator forced are not held."""
        while True:
            job = self._pick_job()
            if job is None or job["interrupted"] or job.get("force") or job.get("nest_members"):
                return job
            short = self.roll_short(job)
            if not short:
                return job
            msg = (f"{job['name']}: {short}: {ROLL_HELD} "
                   f"(wideprint printer roll load) and release it, or release it with --force")
            if self.spool.hold_for_roll(job["id"], msg) is not None:
                log.warning("printer %s: job %s %s", self.name_, job["id"], msg)

    ROLL_WARNING_EVERY_S = 1.0         # the warning is worked out at most once a second

    def roll_warnings(self) -> list[dict]:
        """This printer's warnings (not faults: nothing stops): the roll left is less than
        what the jobs it will print need, plus a metre to spare (docs/server.md "Rolls:
        the warning").  The jobs: the one printing (its copies left), then the queued
        ones for this printer (for any printer too when it is the only one), then those
        held because the roll could not hold them.  A new warning is logged once."""
        from .rolls import paper_per_copy_mm, roll_warning
        now = time.monotonic()
        roll = self.srv.rolls.get(self.name_)
        cached = getattr(self, "_roll_warned", None)
        if cached is not None and now - cached[0] < self.ROLL_WARNING_EVERY_S \
                and cached[2] == roll:                 # a roll loaded or set: at once
            return cached[1]
        warning = None
        if roll is not None and roll.get("remaining_mm") is not None:
            only = len(self.srv.workers) == 1
            cur = self.current
            jobs = [self.spool.get(cur["id"])] if cur and cur.get("id") else []
            jobs += [j for j in self.spool.next_jobs(self.name_, limit=200)
                     if j["printer"] == self.name_ or only]
            jobs += [j for j in self.spool.jobs(("held",))
                     if ROLL_HELD in (j["message"] or "")
                     and (j["printer"] == self.name_ or (only and j["printer"] is None))]
            waiting, seen = [], set()
            for job in jobs:
                if job is None or job["id"] in seen:
                    continue
                seen.add(job["id"])
                size = self.srv.job_size_mm(job, self.profile)
                if size is None:
                    continue
                n = max(1, job["copies"] - job["copies_done"])
                top = float((job["settings"].get("placement") or {}).get("top_mm") or 0.0)
                waiting.append((job, n * paper_per_copy_mm(self.profile, size[1], top)))
            warning = roll_warning(roll, waiting)
        out = [warning] if warning else []
        before = cached[1] if cached is not None else []
        if out and (not before or before[0]["job"] != out[0]["job"]):
            log.warning("printer %s: %s", self.name_, out[0]["message"])
        self._roll_warned = (now, out, roll)
        return out

    def roll_short(self, job: dict, copies: int | None = None) -> str:
        """Why this printer's roll cannot hold `copies` (default: the job's copies left) of
        `job`; '' when it can or nobody knows (no roll length, a file that cannot tell)."""
        from .rolls import paper_per_copy_mm, short_of_roll
        roll = self.srv.rolls.get(self.name_)
        if roll is None or roll.get("remaining_mm") is None:
            return ""
        size = self.srv.job_size_mm(job, self.profile)
        if size is None:
            return ""
        n = copies if copies is not None else max(1, job["copies"] - job["copies_done"])
        top = float((job["settings"].get("placement") or {}).get("top_mm") or 0.0)
        return short_of_roll(roll, n * paper_per_copy_mm(self.profile, size[1], top))

    def _pick_job(self) -> dict | None:
        """The next job for this printer: its own, or one for any printer whose width its
        paper holds.  An "any" job too wide for this paper is left for a printer whose
        paper is wide enough; when no printer's paper holds it, the first free printer
        takes it and the job fails with its own reason (docs/server.md, "Several printers")."""
        for job in self.spool.next_jobs(self.name_):
            if job["interrupted"]:
                return job
            if (job["settings"].get("placement") or {}).get("nest") and not job["nest_members"]:
                group = self._nest_group(job)
                if group is None:
                    continue                     # waiting for its rule: the next job goes first
                if not self.spool.nest(job["id"], [j["id"] for j in group[1:]]):
                    return None                  # the queue changed under us: look again
                return self.spool.get(job["id"])
            if job["printer"] is not None:
                return job
            need = self.srv.job_width_mm(job, self.profile)
            if need is None or self.fits(need):
                return job
            if not any(w.fits(need) for w in self.srv.workers.values() if w is not self):
                return job
        return None

    def _nest_group(self, first: dict) -> list[dict] | None:
        """The jobs to nest on one sheet with `first` (docs/server.md, "Nesting jobs"): the
        queued jobs asking to nest with the same settings and one copy each, for this
        printer or any, in queue order, once the nest's start rule holds — `nest_count`
        jobs, a sheet `nest_length_mm` long, or the first job waiting `nest_wait_s`; with
        no rule, whatever is queued now.  None: not yet."""
        pl = first["settings"].get("placement") or {}
        key = json.dumps(first["settings"], sort_keys=True)
        group = [j for j in self.spool.next_jobs(self.name_, limit=1000)
                 if not j["interrupted"] and not j["nest_members"] and j["copies"] == 1
                 and json.dumps(j["settings"], sort_keys=True) == key]
        if not group or group[0]["id"] != first["id"]:
            group = [first] + [j for j in group if j["id"] != first["id"]]
        count, length, wait = pl.get("nest_count"), pl.get("nest_length_mm"), pl.get("nest_wait_s")
        if count:
            group = group[:count]
            if len(group) >= count:
                return group
        if length:
            from ...rip.layout import plan_layout
            try:
                rs, media_profile = job_rip_settings(first["settings"], self.profile,
                                                     self.srv.state_dir)
                plan = plan_layout([j["spool_path"] for j in group], rs, media_profile,
                                   self.paper_mm)
                if plan.height_mm >= length:
                    return group
            except (ValueError, OSError):
                return group                     # the sheet's own problem: it fails printing
        if wait is not None:
            return group if time.time() - first["submitted"] >= wait else None
        return None if (count or length) else group

    def printable_mm(self) -> float:
        """This printer's paper (measured at its last job, else its profile's sheet) less
        the profile's side margins."""
        paper = self.paper_mm if self.paper_mm is not None else self.profile.paper.default_width_mm
        return paper - 2 * float(self.profile.paper.margin_mm)

    def fits(self, width_mm: float) -> bool:
        return width_mm <= self.printable_mm() + 1e-6

    def _measure_paper(self) -> None:
        """The paper's width, as the printer measured it (its edge sensors)."""
        from ...driver.printer import Printer
        try:
            p = Printer(self.dev).paper()
        except Exception:  # noqa: BLE001 - a reading for the queue's choice, never fatal
            return
        if p.present:
            self.paper_mm = (p.right_counts - p.left_counts) / self.profile.counts_per_inch * 25.4
            try:
                self.srv.rolls.measured(self.name_, self.paper_mm)
            except Exception:  # noqa: BLE001 - the roll's width is shown, never needed
                log.debug("printer %s: the roll's width not recorded", self.name_, exc_info=True)

    def _device(self):
        if self.dev is None:
            from ..devices import open_device
            media = self.srv.config.media_dir
            media_path = (lambda job: str(media / (f"job-{job}.tif" if job < TEST_PRINT_BASE else
                                                   f"testprint-{job - TEST_PRINT_BASE}.tif"))
                          ) if media else None
            from ..devices import is_emulator_spec
            emulated = is_emulator_spec(self.printer.device)
            inject = self.srv.config.inject if emulated else None
            if emulated and self.live is None:
                from ..livemedia import LiveMedia
                self.live = LiveMedia()
            self.dev = open_device(self.printer.device, self.profile, inject=inject,
                                   media_path=media_path, live=self.live if emulated else None,
                                   **({"keep_events": EMULATOR_EVENTS_KEPT} if emulated else {}))
        return self.dev

    def _drop_device(self) -> None:
        dev, self.dev = self.dev, None
        if dev is not None and dev.emulator is None:     # an in-process emulator keeps its state
            try:
                dev.close()
            except Exception:  # noqa: BLE001
                pass
        elif dev is not None:
            self.dev = dev

    def _offline(self, job_id: int, message: str) -> None:
        self.printer_state, self.printer_error = "offline", message
        self._durable(lambda: self.spool.wait_for_printer(job_id, f"waiting for the printer: {message}"),
                      f"job {job_id} waiting for the printer")
        log.warning("printer offline: %s (retrying in %.1f s)", message, self._backoff)
        with self.wake:
            self.wake.wait(self._backoff)
        self._backoff = min(self._backoff * 2, self.srv.config.reconnect_backoff[1])

    def _run_job(self, job_id: int) -> None:
        from ...rip.load import ImageError
        from ...rip.pipeline import RipJob
        from ...driver.job import JobCancelled, JobError, PrintJob, ResumeRefused
        from ...driver.link import DeviceError, LinkError
        from ...driver.stream import StreamError

        self._fresh_profile()
        job = self._durable(lambda: self.spool.claim(job_id, self.name_), f"job {job_id}'s start")
        if job is None:
            return
        crashpoints.reached("claim")
        resumed = job["checkpoint"] is not None
        self.current = dict(id=job_id, name=job["name"], copy=job["copies_done"] + 1,
                            copies=job["copies"], state="ripping", detail="", stroke_index=None,
                            strokes_total=job["strokes_total"], strokes_printed=job["strokes_done"],
                            resumed=resumed)
        self.printer_state = "printing"
        first = True
        layout = None
        while job["copies_done"] < job["copies"]:
            copy = job["copies_done"] + 1
            if not first:
                self._durable(lambda: self.spool.start_copy(job_id), f"job {job_id}'s next copy")
                job = self.spool.get(job_id)
                resumed = False
            self.current.update(copy=copy, state="ripping", stroke_index=None, strokes_printed=0)
            self._steps0, self._fed_by, self._fed_before = None, None, 0.0
            cp = job["checkpoint"] if first else None
            first = False
            started = job["copy_started"] or time.time()
            if job_id in self._cancel:
                self._finish(job, "cancelled", "cancelled by the operator",
                             self._print_row(job, copy, started, None, "cancelled",
                                             "cancelled by the operator", resumed))
                return
            members = self.spool.members(job)
            damaged = self._damaged_copy(job, members)
            if damaged:
                self._finish(job, "failed", damaged,
                             self._print_row(job, copy, started, None, "failed", damaged, resumed))
                return
            try:
                rs, media_profile = job_rip_settings(job["settings"], self.profile,
                                                     self.srv.state_dir)
                # ripped ahead (RIP and hold) and still the job's: printed from its planes
                rip: Any = None if members or rs.placement.marks == "cut" else \
                    planes_job(job, self.profile, rs, media_profile)
                if rip is not None:
                    log.info("job %s: printing its planes, ripped ahead", job_id)
                else:
                    rip = RipJob(job["spool_path"], rs, media_profile,
                                 more=tuple(m["spool_path"] for m in members),
                                 names=(job["name"], *(m["name"] for m in members)))
                    # its spot colours as this RIP resolved them, on the job's record
                    # before its first stroke (docs/spot.md "The job's report")
                    from ...rip.spot_render import job_spots
                    spots = job_spots(rip)
                    self._durable(lambda s=spots: self.spool.set_spots(job_id, s),
                                  f"job {job_id}'s spot colours")
                    job["spots"] = spots
                layout = rip.layout.report if rip.layout is not None else None
                if rs.placement.marks == "cut" and cp is None:     # print and cut (docs/cut.md)
                    from ...rip.cutfile import write_cut_files
                    write_cut_files(self.srv.state_dir, job_id, rip, rs, media_profile)
            except (ImageError, ValueError, OSError) as exc:
                msg = str(exc).replace(job["spool_path"] or "", job["name"])
                self._finish(job, "failed", msg,
                             self._print_row(job, copy, started, None, "failed", msg, resumed))
                return
            try:
                try:
                    dev = self._device()
                    if cp is None:
                        self._close_earlier_attempt(dev, job_id)
                except (LinkError, OSError, ValueError) as exc:
                    self._offline(job_id, str(exc))
                    return
                except DeviceError as exc:
                    msg = f"ending the earlier attempt on the printer: {exc}"
                    self._finish(job, "failed", msg,
                                 self._print_row(job, copy, started, None, "failed", msg, resumed))
                    return
                epoch = job.get("epoch") or self.spool.epoch(self.name_)
                self._steps0 = self._paper_steps(dev)
                if cp is not None:
                    # the copy was on the sheet when the server stopped: what it fed then
                    # is this copy's too, and comes off the roll with its row (docs/server.md
                    # "Rolls": resumed, restarted or counted done after a crash)
                    self._fed_before = self._fed_before_crash(dev, cp, rip, rs)

                def on_event(kind, **kw):
                    cur = self.current
                    if kind == "checkpoint":
                        self._save_checkpoint(job_id, dict(kw["checkpoint"], epoch=epoch,
                                                           copy=copy), pj.report.strokes_total)
                        crashpoints.reached("job_end" if kw["checkpoint"].get("ended")
                                            else "checkpoint")
                        cur["strokes_printed"] = kw["checkpoint"].get("next_stroke", 0)
                        cur["strokes_total"] = pj.report.strokes_total
                    elif kind == "state":
                        cur["state"], cur["detail"] = kw["state"], kw.get("detail", "")
                    elif kind == "stroke":
                        cur["stroke_index"], cur["strokes_total"] = kw["index"], kw["total"]

                pj = PrintJob(dev, rip, job_id=job_id, on_event=on_event, resume=cp,
                              head_care=self._care())
                self.job = self._fed_by = pj
                if job_id in self._cancel:
                    pj.control.cancel()
                if self.stopping:
                    pj.control.pause()
                try:
                    rep = pj.run()
                except JobCancelled as exc:
                    self._finish(job, "cancelled", f"cancelled by the operator ({exc})",
                                 self._print_row(job, copy, started, pj.report, "cancelled",
                                                 str(exc), resumed))
                    return
                except ResumeRefused as exc:
                    # the printer cannot confirm the sheet holds the checkpoint's strokes: never
                    # go on from there (docs/server.md "Crash recovery"); what is on the sheet
                    # is accounted, and the job starts again from its first stroke
                    # (nothing on the sheet yet: nothing to decide, it simply starts again)
                    hold = self.srv.config.on_crash != "reprint" and exc.on_sheet > 0
                    msg = (f"{exc}; held: release it to print it again from its first stroke, "
                           f"or cancel it" if hold else
                           f"{exc}; printing it again from its first stroke")
                    row = self._print_row(job, copy, started, pj.report, "interrupted",
                                          str(exc), resumed) if exc.on_sheet else None
                    self._durable(lambda: self.spool.restart(job_id, msg, row, hold),
                                  f"job {job_id}'s restart")
                    log.warning("job %s: %s", job_id, msg)
                    return
                except JobError as exc:
                    cause = exc.__cause__
                    if isinstance(cause, (LinkError, StreamError)) and not self.stopping:
                        self._drop_device()
                        self._offline(job_id, str(exc))
                        return
                    if exc.fault and not self.stopping:
                        # the printer's fault, not the job's: this printer stops at the job,
                        # which keeps its checkpoint until the operator clears the fault
                        why = str(exc)
                        row = self._print_row(job, copy, started, pj.report, "stopped", why,
                                              resumed)
                        self._durable(lambda: self.spool.stop_for_fault(job_id, why, row),
                                      f"job {job_id}'s stop")
                        self.fault = str(exc)
                        self.printer_state, self.printer_error = "fault", str(exc)
                        self.set_paused(True, f"printer fault: {exc}; clear it to resume or fail the job")
                        log.warning("printer %s: %s; job %s waits", self.name_, exc, job_id)
                        return
                    self._finish(job, "failed", str(exc), self._print_row(
                        job, copy, started, pj.report, "failed", str(exc), resumed))
                    return
                finally:
                    self.job = None
            finally:
                rip.close()
            self.printer_state, self.printer_error = "printing", ""
            self._backoff = self.srv.config.reconnect_backoff[0]
            self._measure_paper()
            row = self._print_row(job, copy, started, rep, "done", "", resumed)
            if copy < job["copies"]:
                job = self._durable(lambda: self.spool.copy_done(job_id, row),
                                    f"job {job_id}'s copy {copy}")
                crashpoints.reached("copy_done")
                continue
            from ...rip.layout import layout_line
            # the last copy: its row, its count and the job's end in one transaction; a
            # layout's figures (a nest: the media it saved) stay with the job
            self._finish(job, "done", layout_line(layout) if layout else "", row, copy_done=True)
            return
        self._finish(job, "done", "")          # every copy was done before a restart

    def _save_checkpoint(self, job_id: int, checkpoint: dict, strokes_total: int) -> None:
        """A stroke's checkpoint; on a full disk the print goes on without it (one warning a
        job): a restart then resumes from an older checkpoint, which the printer does not
        confirm (its lines are ahead), so the job is held, never printed twice or marked
        done (docs/server.md "Full disks")."""
        try:
            self.spool.save_checkpoint(job_id, checkpoint, strokes_total)
            self._checkpoint_warned = False
        except Exception as exc:  # noqa: BLE001 - only a full disk is let through
            if not disk_full(exc):
                raise
            if not getattr(self, "_checkpoint_warned", False):
                log.warning("printer %s: job %s: checkpoint not recorded, the state directory's "
                            "disk is full (%s); printing on", self.name_, job_id, exc)
                self._checkpoint_warned = True

    @staticmethod
    def _damaged_copy(job: dict, members: list[dict]) -> str:
        """The spool copies checked against the digests taken when they were queued
        (docs/server.md "Crash recovery"): a copy changed on disk since fails its job,
        naming the file, instead of printing something nobody sent."""
        for j in (job, *members):
            path = j.get("spool_path")
            if not path:
                return f"{j['name']}: its spooled copy is gone"
            try:
                digest = fsck.file_digest(path)
            except OSError as exc:
                return f"{j['name']}: its spooled copy {path} cannot be read ({exc.strerror})"
            if digest != j["sha256"]:
                return (f"{j['name']}: its spooled copy {path} is damaged (its SHA-256 is not "
                        f"the one taken when it was queued); submit the file again")
        return ""

    @staticmethod
    def _close_earlier_attempt(dev, job_id: int) -> None:
        """A job starting afresh (a requeued job, a checkpoint the printer could not
        confirm, a later copy) prints under the same printer job id.  An earlier run may
        have ended without JOB_END, so the printer may still hold it open, and would take
        the new JOB_BEGIN (same id, same image area) for the host reconnecting: keep the
        old placement's media and paper position.  End it first (docs/server.md,
        "Requeue")."""
        from ...driver.printer import Printer
        printer = Printer(dev)
        printer.connect()
        printer.end_open_job(job_id)

    def _finish(self, job: dict, state: str, message: str, row: dict | None = None,
                copy_done: bool = False) -> None:
        """The job ends: hot-folder originals moved first (a crash after the move resumes
        the job, which ends again and finds nothing to move; one after the commit would
        leave an original to be taken as a new job), then one transaction with its last
        copy's row and the jobs on its nested sheet, then the spool copies deleted."""
        if job.get("spool_path") and message and not message.startswith(f"{job['name']}:"):
            # the operator knows the file by its name, never by its spool copy's (a message
            # that names the file first may name its copy too: a damaged copy's)
            message = message.replace(job["spool_path"], job["name"])
            if row is not None:
                row = dict(row, message=row["message"].replace(job["spool_path"], job["name"]))
        members = [m for m in self.spool.members(job)
                   if m["state"] not in ("done", "failed", "cancelled")]
        words = {m["id"]: (f"on job {job['id']}'s nested sheet: {message}" if message
                           else f"printed on job {job['id']}'s nested sheet") for m in members}
        for m in members:                          # a nested sheet: its jobs end with it
            self.srv.hot_done(m, state, words[m["id"]])
        self.srv.hot_done(job, state, message)
        if job.get("hot_path"):
            crashpoints.reached("hot_done")
        keep = self.srv.keeps_copy(state)
        self._durable(lambda: self.spool.finish(job["id"], state, message, keep_copy=keep,
                                                row=row, copy_done=copy_done, members=words),
                      f"job {job['id']}'s end")
        crashpoints.reached("finish")
        self._cancel.discard(job["id"])
        planes = (job.get("ripped") or {}).get("path")
        if planes and not (state == "done" and keep and archive.keeps_planes(self.srv.config)):
            # RIP and hold: the kept planes go with it, unless the archive keeps them
            try:
                os.unlink(planes)
            except OSError:
                pass
        if not keep:
            for j in (*members, job):
                if j.get("spool_path"):
                    try:
                        fsck.remove_copy(j["spool_path"])
                    except OSError:
                        pass
        for m in members:
            log.info("job %s %s %s", m["id"], state, words[m["id"]])
        log.info("job %s %s %s", job["id"], state, message)

    @staticmethod
    def _paper_steps(dev) -> int | None:
        """Where the paper is (feed steps), or None when the printer does not say."""
        try:
            return int(dev.link.status().paper_steps)
        except Exception:  # noqa: BLE001 - the roll's count is kept when it can be
            return None

    def _paper_fed_mm(self) -> float:
        """The paper this copy fed (docs/server.md "Rolls"): the printer's paper position
        now (as last read by the job) less where it was when the run began, plus what the
        copy fed before a crash it was resumed from (`_fed_before_crash`)."""
        pj, s0 = self._fed_by, self._steps0
        if pj is None or s0 is None:
            return round(self._fed_before, 3)
        steps = int(pj.telemetry.paper_steps) - s0
        return round(self._fed_before + max(0, steps) * self.profile.feed_um_per_step / 1000.0, 3)

    def _fed_before_crash(self, dev, cp: dict, rip, rs) -> float:
        """The paper (mm) a copy fed before the server stopped in it, from its checkpoint
        (docs/server.md "Crash recovery"): on the same power-up of the printer (JOB_STATUS's
        boot is the checkpoint's) the paper's position now less where the copy began
        (`paper0`) - the printer's own count; after the printer was restarted (its count
        began again) the feed the stroke plan puts under the last stroke on the sheet
        (`next_stroke` - 1), top margin included.  0 when neither can be known."""
        from ...driver.printer import Printer
        prof = self.profile
        now, paper0 = self._paper_steps(dev), cp.get("paper0")
        try:
            js = Printer(dev).job_status()
        except Exception:  # noqa: BLE001 - the plan below still tells
            js = None
        if js is not None and cp.get("boot") is not None and js.boot == cp["boot"] \
                and now is not None and paper0 is not None:
            return max(0, now - int(paper0)) * prof.feed_um_per_step / 1000.0
        n = int(cp.get("next_stroke", 0))
        if n <= 0 or not hasattr(rip, "planner"):
            return 0.0
        try:
            planner = rip.planner()
            top = top_margin_rows(prof, rs)
            rows = planner.top_row(min(n, planner.total_strokes) - 1) - planner.top_row(0) + top
        except Exception:  # noqa: BLE001 - the count is kept when it can be
            log.debug("printer %s: the feed before the crash not known", self.name_, exc_info=True)
            return 0.0
        return max(0, prof.feed_steps_for_rows(rows)) * prof.feed_um_per_step / 1000.0

    def _print_row(self, job: dict, copy: int, started: float, rep, outcome: str, message: str,
                   resumed: bool) -> dict:
        """A copy's accounting row (docs/server.md "Accounting"), committed by the job's
        state change that ends the copy.  The area is what was printed: the image's area for
        a done copy, its strokes' share of it for one that stopped part-way - 0 m² when no
        stroke reached the sheet (a job refused by the printer is never billed media)."""
        prof = self.profile
        ended = time.time()
        r = rep.as_dict() if rep is not None else {}
        drops = [int(d) for d in r.get("drops", [0, 0, 0, 0])]
        pl = prof.drop_volume_pl
        total, printed = int(r.get("strokes_total", 0)), int(r.get("strokes_printed", 0))
        area = float(r.get("area_m2", 0.0))
        if outcome != "done":
            area = area * min(1.0, printed / total) if total and printed else 0.0
        roll = self.srv.rolls.get(self.name_)
        row = dict(job_id=job["id"], copy=copy, file=job["name"], source=job["source"],
                   preset=job["preset"], settings=json.dumps(job["settings"], sort_keys=True),
                   started=started, ended=ended, duration_s=round(ended - started, 3),
                   strokes_total=total, strokes_printed=printed,
                   width_dots=r.get("width_dots", 0), height_rows=r.get("height_rows", 0),
                   area_m2=round(area, 10), outcome=outcome, message=message,
                   resumed=int(bool(resumed)), recoveries=r.get("recoveries", 0),
                   retries=r.get("retries", 0), attempt=job["attempt"], printer=self.name_,
                   media=roll["media"] if roll else None,
                   paper_mm=self._paper_fed_mm() if rep is not None else 0.0,
                   spots=json.dumps(job["spots"]) if job.get("spots") else None)
        for c, d in zip(COLORS, drops):
            row[f"drops_{c}"] = d
            row[f"ink_{c}_ml"] = round(d * pl * 1e-9, 12)
        return row
