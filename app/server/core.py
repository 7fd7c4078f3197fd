"""`wideprint serve`: the print server (docs/server.md).

One process owns the printer (one Device, re-opened after link errors) and its queue
(spool.py).  Threads:

- the API: HTTP/JSON on 127.0.0.1 with a bearer token (`ApiHandler`);
- the worker: prints queued jobs one at a time in queue order, persisting the job's
  checkpoint after every stroke, so a server killed mid-job resumes it at its first
  unfinished stroke (or holds it, `--on-crash hold`);
- the hot-folder scanner: one folder per preset; a completely written file becomes a job,
  and moves to done/ or failed/ (with NAME.reason.txt) when the job ends.

The presets (`Presets`) are re-read when their file changes, without a restart; a broken
file keeps the presets in use.

`PrintServer` is the composition root: it builds every part and hands each a reference to
itself, which the part sees through a protocol of ports.py (`WorkerHost`, `HotFolderHost`,
`ApiHost`); no part imports this module.

Nothing here trusts its inputs: names, JSON, sizes and file types are checked (see
`validate_*`, `HotFolders`), and a file that cannot be ripped fails its own job only.
"""

from __future__ import annotations

import hashlib
import json
import logging
import os
import signal
import threading
import time
import uuid
from pathlib import Path

from . import archive, costs
from .accounting import prints_csv
from .api import ApiHandler, _HTTPServer
from .config import (CHUNK, IMAGE_SUFFIXES, MAX_COPIES, PRIORITY_RANGE, SERVER_FILE, ServerConfig,
                     _fsync_dir, ensure_token)
from .hotfolders import HotFolders
from .presets import Presets
from .previews import Previews
from .ripped import Ripper, clean as clean_planes
from .rolls import Rolls, paper_per_copy_mm, short_of_roll
from .sdnotify import notify
from . import crashpoints, fsck
from .spool import Spool
from .validate import Invalid, _check_int, validate_settings
from .worker import Worker

log = logging.getLogger("wideprint.server")

EDITABLE = {"priority", "copies", "settings", "printer"}


# -- the server ---------------------------------------------------------------------------------
class PrintServer:
    def __init__(self, config: ServerConfig):
        from ...rip.profile import load_profile
        self.config = config
        self.state_dir = Path(config.state_dir)
        self.state_dir.mkdir(parents=True, exist_ok=True)
        os.chmod(self.state_dir, 0o700) if self.state_dir.stat().st_uid == os.geteuid() else None
        self._lock_state_dir()
        (self.state_dir / "icc").mkdir(exist_ok=True)
        if config.media_dir:
            Path(config.media_dir).mkdir(parents=True, exist_ok=True)
        self.printer_configs = config.printer_configs()
        # each printer its own profile; settings and presets are checked against the first
        self.profiles = {p.name: load_profile(p.profile_path or self._own_profile(p.name))
                         for p in self.printer_configs}
        self.profile = self.profiles[self.printer_configs[0].name]
        self.preset_source = Presets(self.state_dir, self.profile)
        self.token = ensure_token(self.state_dir)
        fsck.check_at_start(self.state_dir)        # a lost queue is never "cleaned" away
        self.spool = Spool(self.state_dir)
        self.rolls = Rolls(self.spool, self.state_dir / "media")
        self.started = time.time()
        self.recovered = self.spool.recover(config.on_crash)
        for job in self.recovered:
            log.warning("job %s: %s", job["id"], job["message"])
        self._clean_spool()
        self.expire_spool()
        self.workers = {p.name: Worker(self, p, self.profiles[p.name]) for p in self.printer_configs}
        self.worker = next(iter(self.workers.values()))     # the first printer
        self.hot = HotFolders(self, Path(config.hot_folder_root)) if config.hot_folder_root else None
        self.ripper = Ripper(self)              # RIP and hold (docs/server.md)
        self.previews = Previews(self)
        self._widths: dict = {}                 # job_width_mm's cache
        handler = type("Handler", (ApiHandler,), {"srv": self})
        if config.host not in ("127.0.0.1", "localhost", "::1"):
            log.warning("the API listens on %s, beyond this machine: anyone with the token "
                        "can print", config.host)
        self.http = _HTTPServer((config.host, config.port), handler, config.api_max_connections)
        self.port = self.http.server_address[1]
        self.url = f"http://{config.host}:{self.port}"
        self._http_thread = threading.Thread(target=self.http.serve_forever, name="wideprint-api",
                                             daemon=True)
        self._stopped = threading.Event()
        self.stop_requested = threading.Event()     # POST /v1/shutdown: serve() stops

    def _lock_state_dir(self) -> None:
        """One server per state directory: a second one (a GUI starting its own while
        another starts, a second `serve`) would fight the first over the printers and the
        queue.  The lock is the kernel's (flock), so it dies with its process, kill -9
        included."""
        import fcntl
        fd = os.open(self.state_dir / "server.lock", os.O_RDWR | os.O_CREAT | os.O_CLOEXEC, 0o600)
        try:
            fcntl.flock(fd, fcntl.LOCK_EX | fcntl.LOCK_NB)
        except BlockingIOError:
            try:
                pid = os.read(fd, 32).decode().strip() or "?"
            finally:
                os.close(fd)
            raise ValueError(f"another wideprint server (pid {pid}) already serves "
                             f"{self.state_dir}") from None
        os.ftruncate(fd, 0)
        os.write(fd, f"{os.getpid()}\n".encode())
        self._lock_fd: int | None = fd

    def _own_profile(self, name: str) -> Path:
        """A printer configured without a profile gets its own in the state directory
        (profiles/NAME.toml, first a copy of the built-in one), where calibration writes
        its results (docs/server.md, "Printer profiles")."""
        from ...rip.profile import DEFAULT_PROFILE
        d = self.state_dir / "profiles"
        d.mkdir(exist_ok=True)
        path = d / f"{name}.toml"
        if not path.exists():
            tmp = path.with_suffix(".tmp")
            tmp.write_bytes(Path(DEFAULT_PROFILE).read_bytes())
            os.replace(tmp, path)
        return path

    def _clean_spool(self) -> None:
        """Private copies nobody references (a crash between copy and commit, or after a
        job's end) go, with their descriptions; only ever after the database was found
        whole (fsck.check_at_start)."""
        used = self.spool.spool_files_in_use()
        gone = []
        for p in self.spool.spool_dir.iterdir():
            if str(p) not in used:
                try:
                    fsck.remove_copy(p)
                    gone.append(p.name)
                except OSError:
                    pass
        info = self.state_dir / fsck.INFO_DIR
        for p in info.iterdir() if info.is_dir() else ():
            if str(self.spool.spool_dir / p.name[:-len(".json")]) not in used:
                try:
                    p.unlink()
                except OSError:
                    pass
        if gone:
            log.info("spool: %d file(s) no job owns deleted: %s", len(gone), ", ".join(gone[:10]))

    def expire_spool(self) -> None:
        """Spool copies of failed and cancelled jobs older than --keep-failed go (those
        jobs can no longer be requeued)."""
        now = time.time()
        gone = self.spool.expire_copies(now - self.config.keep_failed_s)
        # the archive of done jobs (docs/server.md "Archive and reprint")
        gone += self.spool.expire_archive(now - self.config.archive_days * 86400,
                                          archive.max_bytes(self.config))
        for path in gone:
            try:
                fsck.remove_copy(path)
            except OSError:
                pass
        clean_planes(self.state_dir, self.spool.planes_in_use(archive.keeps_planes(self.config)))

    def request_stop(self) -> None:
        """An authorised client asked the server to stop (the GUI that started it, when it
        closes with nothing to print): as SIGTERM, the job printing pauses at its next
        stroke boundary and the next start resumes it."""
        log.info("stop requested through the API")
        self.stop_requested.set()

    def stopping(self) -> bool:
        return self._stopped.is_set()

    def keeps_copy(self, state: str) -> bool:
        """Whether a job ending in `state` keeps its spool copy: failed and cancelled jobs
        do, for requeue (docs/server.md, "Requeue"), unless --keep-failed is 0; done jobs
        do, for reprints ("Archive and reprint"), unless --archive-days is 0."""
        if state == "done":
            return archive.keeps_done(self.config)     # the archive, for reprints
        return state in ("failed", "cancelled") and self.config.keep_failed_s > 0

    @property
    def presets(self) -> dict:
        """The presets now (re-read first when their file changed)."""
        return self.preset_source.get()

    def reload_presets(self) -> dict:
        """Re-read the presets file (API `POST /v1/presets/reload`): the presets, what
        changed, and the hot folders of new presets made at once.  A broken file raises
        Invalid naming the file and the problem; the presets in use stay."""
        try:
            diff = self.preset_source.reload()
        except ValueError as exc:
            raise Invalid(str(exc)) from None
        presets = self.preset_source.current
        if self.hot:
            with self.hot.lock:
                self.hot.make_folders(presets)
        return dict(self.preset_source.info(), presets=presets, **diff)

    def start(self) -> None:
        for w in self.workers.values():
            w.start()
        self.ripper.start()
        self._http_thread.start()
        if self.hot:
            self.hot.start()
        self.publish()

    def publish(self, **extra) -> None:
        """(Re)write server.json: the URL clients find the server at, plus what front ends
        started beside it add (`ipp`: each printer's IPP URI, docs/ipp.md)."""
        self._published = dict(getattr(self, "_published", {}), **extra)
        info = dict(url=self.url, pid=os.getpid(), started=self.started,
                    device=self.config.device, state_dir=str(self.state_dir), **self._published)
        tmp = self.state_dir / (SERVER_FILE + ".tmp")
        tmp.write_text(json.dumps(info) + "\n")
        os.replace(tmp, self.state_dir / SERVER_FILE)

    def stop(self, timeout: float = 30.0) -> None:
        if self._stopped.is_set():
            return
        self._stopped.set()
        self.ripper.stop()
        if self.hot:
            self.hot.stopping.set()
        for w in self.workers.values():
            w.interrupt(timeout)
        self.http.shutdown()
        self.http.server_close()
        if self.hot:
            self.hot.close()
        try:
            (self.state_dir / SERVER_FILE).unlink()
        except OSError:
            pass
        fd, self._lock_fd = getattr(self, "_lock_fd", None), None
        if fd is not None:
            os.close(fd)                    # the lock goes with the descriptor

    # -- intake -------------------------------------------------------------------------------
    def queue_file(self, src, name: str, size: int, *, exact: bool = False, check=None,
                   fit: bool | str = False, **fields) -> tuple[dict, bool]:
        """Copy a file into the spool and queue it as a job: (job, created).  The copy is
        owned by the job, or deleted before this returns or raises — whatever fails (the
        copy, `check()` after it, the database), no spool file is left without a job.
        A duplicate key returns the job already queued, and its copy is deleted too.
        fit: refuse a job that does not fit the loaded paper unless `force` (Invalid 422
        naming the file: docs/server.md "Fit before it fails"); "width": only one too wide
        (a hot folder's file the roll left cannot hold is queued, and held before
        printing).  hold None: the preset's default ("Presets")."""
        if fields.get("hold") is None:
            fields["hold"] = self.preset_source.holds(fields.get("preset"))
        spool_path, n, digest = self.spool_copy(src, name, size, exact=exact)
        try:
            if check is not None:
                check()
            if fit:
                self.check_fit(dict(fields, id=None, name=name, spool_path=spool_path,
                                    sha256=digest, copies_done=0), width_only=fit == "width")
            # its description beside it, so a lost database can be rebuilt (fsck.py)
            fsck.write_description(spool_path, dict(fields, name=name, size=n, sha256=digest))
            job, created = self.spool.add_job(name=name, spool_path=spool_path, size=n,
                                              sha256=digest, **fields)
        except BaseException:
            fsck.remove_copy(spool_path)
            raise
        if not created:
            fsck.remove_copy(spool_path)
        else:
            crashpoints.reached("upload")
        return job, created

    def spool_copy(self, src, name: str, size: int, exact: bool = False) -> tuple[str, int, str]:
        """Copy a submitted file into the spool (fsync'd): returns (path, size, sha256).
        exact: read exactly `size` bytes (an upload); otherwise to EOF, refusing more than
        the size limit."""
        suffix = Path(name).suffix.lower()
        suffix = suffix if suffix in IMAGE_SUFFIXES else ""
        final = self.spool.spool_dir / f"{uuid.uuid4().hex}{suffix}"
        tmp = self.spool.spool_dir / f".{final.name}.part"
        h = hashlib.sha256()
        n = 0
        limit = self.config.max_file_bytes
        try:
            with open(tmp, "wb") as out:
                while True:
                    want = min(CHUNK, size - n) if exact else CHUNK
                    if exact and want <= 0:
                        break
                    buf = src.read(want)
                    if not buf:
                        break
                    n += len(buf)
                    if n > limit:
                        raise Invalid(f"{name} is more than {limit} bytes, the limit", 413)
                    h.update(buf)
                    out.write(buf)
                if exact and n != size:
                    raise Invalid(f"upload ended after {n} of {size} bytes")
                out.flush()
                os.fsync(out.fileno())
            os.rename(tmp, final)
            _fsync_dir(self.spool.spool_dir)
        except BaseException:
            try:
                tmp.unlink()
            except OSError:
                pass
            raise
        return str(final), n, h.hexdigest()

    # -- operations (API) -----------------------------------------------------------------------
    def public(self, job: dict, positions: dict | None = None) -> dict:
        d = {k: v for k, v in job.items() if k not in ("spool_path", "checkpoint", "key")}
        info = job.get("ripped")
        if info:                                   # RIP and hold: ready or why not, no paths
            d["ripped"] = dict(ready=bool(info.get("path")) and not info.get("error"),
                               error=info.get("error"), rip_s=info.get("rip_s"),
                               bytes=info.get("bytes"))
        cp = job.get("checkpoint")
        d["next_stroke"] = cp.get("next_stroke") if cp else None
        if positions is not None:
            d["position"] = positions.get(job["id"])
        return d

    def jobs(self, states=None, limit=None, after=0, newest=False) -> list[dict]:
        pos = self.spool.queue_position()
        return [self.public(j, pos) for j in self.spool.jobs(states, limit, after, newest)]

    CANCEL_WAIT_S = 5.0               # a printing job's cancel waits this long for it to stop

    def cancel(self, job_id: int, _again: bool = True) -> dict:
        """Cancel a job: a waiting one at once; a printing one is stopped at the printer and
        waited for (CANCEL_WAIT_S).  Returns the job: `cancelled`, or still `printing` when
        it has not stopped yet (the API answers 202: the client follows it).  A job that
        ended otherwise meanwhile (done, failed) raises Invalid (409): the cancel did not
        happen, and the caller is told so."""
        before = self.spool.get(job_id)
        keep = self.keeps_copy("cancelled")
        job = self.spool.cancel_waiting(job_id, keep_copy=keep)
        if job is None:                                # printing: stop it at the printer
            if not any(w.cancel(job_id) for w in self.workers.values()):
                # claimed but not started yet, or between copies: the workers check this set
                for w in self.workers.values():
                    w._cancel.add(job_id)
            deadline = time.monotonic() + self.CANCEL_WAIT_S
            while True:
                job = self.spool.get(job_id)
                if job["state"] != "printing" or time.monotonic() >= deadline:
                    break
                time.sleep(0.05)
            if job["state"] in ("queued", "held") and _again:
                # it stopped for another reason meanwhile (the link, a fault): cancel it waiting
                return self.cancel(job_id, _again=False)
            if job["state"] in ("done", "failed"):
                raise Invalid(f"job {job_id} is {job['state']}: it ended before the cancel "
                              f"reached the printer" + (f" ({job['message']})"
                                                        if job["message"] else ""), 409)
            return job
        self.hot_done(job, "cancelled", "cancelled by the operator")
        for m in self.spool.members(job):        # a nested sheet not started: its jobs too
            if m["state"] not in ("done", "failed", "cancelled"):
                self.spool.finish(m["id"], "cancelled", f"job {job_id}'s nested sheet was "
                                  "cancelled", keep_copy=keep)
                self.hot_done(m, "cancelled", "cancelled with its nested sheet")
        if before and before.get("spool_path") and not keep:
            try:
                os.unlink(before["spool_path"])
            except OSError:
                pass
        self.notify()
        return job

    def hold(self, job_id: int) -> dict:
        return self.spool.hold(job_id)

    def edit(self, job_id: int, change: dict) -> dict:
        """PATCH /v1/jobs/ID (docs/server.md, "Editing a job"): only the fields given change.
        `settings` is a partial settings mapping checked by the one schema and laid over the
        job's own (placement field by field; null puts a setting back to automatic), so an
        operator editing one setting of several jobs changes only that setting of each."""
        if not isinstance(change, dict) or not change or set(change) - EDITABLE:
            raise Invalid(f"expected an object with some of {', '.join(sorted(EDITABLE))}")
        job = self.spool.get(job_id)
        if job is None:
            raise Invalid(f"no job {job_id}", 404)
        kw = {}
        if "priority" in change:
            kw["priority"] = _check_int("priority", change["priority"], *PRIORITY_RANGE)
        if "copies" in change:
            kw["copies"] = _check_int("copies", change["copies"], 1, MAX_COPIES)
        if "settings" in change:
            profile = self.profiles.get(job["printer"] or "") or self.profile
            # null: the setting goes back to its default (the key is dropped)
            kw["settings"] = self._merged_settings(job["settings"], change["settings"], profile)
        job = self.spool.edit(job_id, **kw)
        if "printer" in change:
            job = self.move(job_id, change["printer"])
        self.previews.forget(job_id)
        self.notify()
        return job

    def release(self, job_id: int, force: bool = False) -> dict:
        """A held job to the queue; force: past the fit checks (a roll that holds more than
        the server knows; docs/server.md "Fit before it fails")."""
        job = self.spool.release(job_id, force=force)
        self.notify()
        return job

    REPRINT_KEYS = {"settings", "copies", "priority", "hold", "printer", "force", "client"}

    def reprint(self, job_id: int, change: dict | None = None) -> dict:
        """POST /v1/jobs/ID/reprint (docs/server.md "Archive and reprint"): a finished job's
        archived file as a new job - its settings, copies, priority, preset and printer, or
        the ones `change` gives (settings laid over the job's as for an edit; null drops
        one).  The new job checks the fit like a submission and names the one it reprints
        (`reprint_of`)."""
        change = change or {}
        if not isinstance(change, dict) or set(change) - self.REPRINT_KEYS:
            raise Invalid(f"expected an object with some of {', '.join(sorted(self.REPRINT_KEYS))}")
        job = self.spool.get(job_id)
        if job is None:
            raise Invalid(f"no job {job_id}", 404)
        if job["state"] not in ("done", "failed", "cancelled"):
            raise Invalid(f"job {job_id} is {job['state']}: only a finished job is reprinted "
                          f"(a waiting one prints as it is)", 409)
        try:
            src = archive.check_archived(job)
        except FileNotFoundError as exc:
            raise Invalid(str(exc), 410) from None
        except ValueError as exc:
            raise Invalid(str(exc), 409) from None
        printer = change.get("printer", job["printer"])
        if printer in ("", "any"):
            printer = None
        if printer is not None:
            self.printer_worker(printer)
        settings = job["settings"]
        if change.get("settings") is not None:
            profile = self.profiles.get(printer or "") or self.profile
            settings = self._merged_settings(settings, change["settings"], profile)
        for k in ("hold", "force"):
            if not isinstance(change.get(k, False), bool):
                raise Invalid(f"{k} must be true or false")
        client = change.get("client", job["client"])
        if client is not None and (not isinstance(client, str) or not 0 < len(client) <= 100):
            raise Invalid("client must be a string of 1..100 characters")
        fields = dict(source="reprint", settings=settings, preset=job["preset"],
                      copies=_check_int("copies", change.get("copies", job["copies"]), 1, MAX_COPIES),
                      priority=_check_int("priority", change.get("priority", job["priority"]),
                                          *PRIORITY_RANGE),
                      hold=change.get("hold"), client=client, printer=printer,
                      force=bool(change.get("force", False)), reprint_of=job_id)
        if fields["hold"] is None:
            fields["hold"] = self.preset_source.holds(job["preset"])
        path = archive.link_copy(self.spool.spool_dir, src)
        try:
            self.check_fit(dict(fields, id=None, name=job["name"], spool_path=path,
                                sha256=job["sha256"], copies_done=0))
            fsck.write_description(path, dict(fields, name=job["name"], size=job["size"],
                                              sha256=job["sha256"]))
            new, _ = self.spool.add_job(name=job["name"], spool_path=path, size=job["size"],
                                        sha256=job["sha256"], **fields)
        except BaseException:
            fsck.remove_copy(path)
            raise
        self._reuse_planes(job, new)
        log.info("job %s reprints job %s (%s)", new["id"], job_id, job["name"])
        self.notify()
        return new

    def _reuse_planes(self, old: dict, new: dict) -> None:
        """A reprint of a job whose ripped planes the archive kept (--archive-planes) gets
        them (a hard link) when they are still its halftone: same file, settings, profile."""
        from .ripped import RIPPED_DIR, planes_key
        info = old.get("ripped") or {}
        path = info.get("path")
        profile = self.profiles.get(new.get("printer") or "") or self.profile
        if not path or not os.path.exists(path) or info.get("key") != planes_key(new, profile):
            return
        link = self.state_dir / RIPPED_DIR / f"{new['id']}-{info['key']}.tif"
        try:
            os.link(path, link)
        except OSError as exc:
            log.warning("job %s: the archived planes of job %s not reused: %s", new["id"],
                        old["id"], exc)
            return
        self.spool.set_ripped(new["id"], dict(info, path=str(link)), old.get("spots"))
        new["ripped"] = dict(info, path=str(link))

    def _merged_settings(self, old: dict, raw, profile) -> dict:
        """A partial settings mapping checked by the one schema and laid over `old`
        (placement field by field; null puts a setting back to automatic)."""
        from ...rip.settings import merge
        if not isinstance(raw, dict) or not isinstance(raw.get("placement", {}), dict):
            raise Invalid("settings must be a JSON object (placement a nested one)")
        dropped = {k for k, v in raw.items() if v is None}
        place = raw.get("placement", {})
        dropped_place = {k for k, v in place.items() if v is None}
        part = dict({k: v for k, v in raw.items() if v is not None and k != "placement"},
                    placement={k: v for k, v in place.items() if v is not None})
        merged = merge(old, validate_settings(part, profile, self.state_dir / "icc"))
        merged = {k: v for k, v in merged.items() if k not in dropped}
        merged["placement"] = {k: v for k, v in merged.get("placement", {}).items()
                               if k not in dropped_place}
        if not merged["placement"]:
            del merged["placement"]
        return validate_settings(merged, profile, self.state_dir / "icc")

    # -- rolls, prices and costs (docs/server.md "Rolls", "Prices and costs") -------------------
    def roll(self, name: str, body: dict | None = None) -> dict:
        """A printer's roll: as it is (body None), or a new one loaded (`load`), what is
        left measured (`remaining_m`) and/or its warning's spare (`spare_m`), or taken off
        (`unload`)."""
        w = self.printer_worker(name)
        if body is not None:
            if not isinstance(body, dict):
                raise Invalid("expected a JSON object")
            if body.get("unload") is True and len(body) == 1:
                self.rolls.unload(name)
            elif body and set(body) <= {"remaining_m", "spare_m"}:     # the roll loaded
                self.rolls.set_remaining(name, body.get("remaining_m"), body.get("spare_m"))
            else:
                self.rolls.load(name, body, w.paper_mm)
            log.info("printer %s: roll %s", name, self.rolls.get(name))
            self.notify()
        return dict(printer=name, roll=self.rolls.get(name), paper_mm=w.paper_mm)

    def prices(self, new=None) -> dict:
        if new is not None:
            return costs.write(self.state_dir, new)
        return costs.read(self.state_dir)

    def report_costs(self, job_id: int | None = None) -> dict:
        """Every accounting row with its cost, and the totals (`GET /v1/report?costs=1`)."""
        prices = costs.read(self.state_dir)
        rows = self.spool.prints(job_id)
        out = [dict(r, cost=costs.print_cost(prices, r)) for r in rows]
        return dict(prices=prices, prints=out, totals=costs.totals(prices, rows))

    def quote(self, job: dict, info: dict) -> dict:
        """An estimate's quote: the preview's figures for all copies at the price list, with
        the media of the roll on the job's printer."""
        name = job.get("printed_on") or job.get("printer") or next(iter(self.workers))
        roll = self.rolls.get(name)
        return costs.quote(costs.read(self.state_dir), info["all_copies"],
                           roll["media"] if roll else None)

    def requeue(self, job_id: int) -> dict:
        """A failed or cancelled job back in the queue, to print afresh (docs/server.md,
        "Requeue"); refused, with the reason, for other states or a spool copy gone."""
        before = self.spool.get(job_id)
        if before is not None and before["state"] in ("failed", "cancelled"):
            for w in self.workers.values():
                w.forget_cancel(job_id)            # a late cancel of the ended attempt
        job = self.spool.requeue(job_id)
        log.info("job %s requeued (attempt %s)", job_id, job["attempt"])
        self.notify()
        return job

    def notify(self) -> None:
        """Wake every printer's worker (a job was queued or released), and the ripper."""
        for w in self.workers.values():
            w.notify()
        ripper = getattr(self, "ripper", None)
        if ripper is not None:
            ripper.notify()

    def rip_hold(self, job_id: int) -> dict:
        """POST /v1/jobs/ID/rip-hold: held, and ripped ahead (docs/server.md "RIP and hold")."""
        job = self.spool.rip_hold(job_id)
        self.notify()
        return job

    def printer_worker(self, name: str) -> Worker:
        w = self.workers.get(name)
        if w is None:
            raise Invalid(f"no printer {name!r} (printers: {', '.join(self.workers)})", 404)
        return w

    def clear_fault(self, name: str, then: str = "resume") -> dict:
        """Printer `name`'s fault cleared by the operator: its stopped job resumes at its
        first unfinished stroke (or fails), its queue runs again (docs/server.md,
        "Printer faults")."""
        w = self.printer_worker(name)
        try:
            return w.clear_fault(then)
        except ValueError as exc:
            raise Invalid(str(exc)) from None
        except RuntimeError as exc:
            raise Invalid(str(exc), 409) from None

    def test_print(self, name: str, pattern) -> dict:
        """POST /v1/printers/NAME/test-print: a test pattern printed on that printer between
        jobs; answers when it has printed (docs/server.md, "Test prints")."""
        from ...rip.settings import TEST_PATTERNS
        w = self.printer_worker(name)
        if not isinstance(pattern, dict) or set(pattern) - {"kind", "dpi", "width_mm", "head", "nozzle"}:
            raise Invalid('expected {"kind": PATTERN, "dpi": N, "width_mm": MM, "head": H, "nozzle": N}')
        if pattern.get("kind") not in TEST_PATTERNS:
            raise Invalid(f"kind must be one of {', '.join(TEST_PATTERNS)}")
        dpi = pattern.get("dpi", 150)
        if dpi not in w.profile.dpi_modes:
            raise Invalid(f"dpi must be one of {', '.join(map(str, w.profile.dpi_modes))}")
        width = pattern.get("width_mm", 100.0)
        if isinstance(width, bool) or not isinstance(width, (int, float)) or not 5 <= width <= 3400:
            raise Invalid("width_mm must be a number of 5..3400")
        if "head" in pattern and pattern["head"] not in {h.name for h in w.profile.heads}:
            raise Invalid(f"no head {pattern['head']!r} in printer {name}'s profile")
        if "nozzle" in pattern:
            _check_int("nozzle", pattern["nozzle"], 1, w.profile.nozzles)
        try:
            return dict(w.test_print(pattern), printer=name, profile=str(w.profile.path))
        except RuntimeError as exc:
            raise Invalid(str(exc), 409) from None

    def service(self, name: str, body) -> dict:
        """POST /v1/printers/NAME/head-care: spit, purge, cap or uncap between jobs
        (docs/server.md, "Head care"); answers when done."""
        w = self.printer_worker(name)
        if not isinstance(body, dict) or set(body) - {"action", "heads", "drops", "ms"}:
            raise Invalid('expected {"action": "spit"|"purge"|"cap"|"uncap", "heads": [NAME, ...], '
                          '"drops": N, "ms": N}')
        action = body.get("action")
        if action not in ("spit", "purge", "cap", "uncap"):
            raise Invalid("action must be one of spit, purge, cap, uncap")
        heads = body.get("heads")
        names = [h.name for h in w.profile.heads]
        if heads is None:
            mask = (1 << len(names)) - 1
        elif not isinstance(heads, list) or not heads or \
                any(not isinstance(h, str) or h not in names for h in heads):
            raise Invalid(f"heads must be a list of head names ({', '.join(names)})")
        else:
            mask = sum(1 << names.index(h) for h in heads)
        amount = None
        if "drops" in body:
            if action != "spit":
                raise Invalid("drops is for spit")
            amount = _check_int("drops", body["drops"], 1, 10000)
        if "ms" in body:
            if action != "purge":
                raise Invalid("ms is for purge")
            amount = _check_int("ms", body["ms"], 100, 10000)
        try:
            return dict(w.service(action, mask, amount), printer=name)
        except RuntimeError as exc:
            raise Invalid(str(exc), 409) from None

    def move(self, job_id: int, printer: str | None) -> dict:
        """A job not yet started goes to another printer (None or "any": the first free)."""
        if printer in (None, "", "any"):
            printer = None
        else:
            self.printer_worker(printer)
        job = self.spool.set_printer(job_id, printer)
        self.notify()
        return job

    def estop(self) -> list[str]:
        """Emergency stop: every printer that is printing stops at once (its job is held
        with the ESTOP fault until cleared); the others are paused."""
        stopped: list[str] = []
        for name, w in self.workers.items():
            job = w.job
            if job is not None:
                job.control.estop()
                stopped.append(name)
            w.set_paused(True, "emergency stop by the operator")
        log.warning("emergency stop: %s", ", ".join(stopped) or "nothing was printing")
        return stopped

    def job_width_mm(self, job: dict, profile) -> float | None:
        """How wide a job prints (its placed image or layout, mm) with `profile`; None when
        the file cannot tell (it fails on its own)."""
        size = self.job_size_mm(job, profile)
        return None if size is None else size[0]

    def job_size_mm(self, job: dict, profile) -> tuple[float, float] | None:
        """How wide and long a job prints (its placed image or layout, mm) with `profile`;
        cached per file, settings and profile; None when the file cannot tell."""
        key = (job.get("sha256") or job["id"], job.get("spool_path"),
               json.dumps(job["settings"], sort_keys=True), str(profile.path))
        if key in self._widths:
            return self._widths[key]
        from ...rip.load import ImageError
        from ...rip.pipeline import RipJob
        from .validate import rip_settings
        size = None
        try:
            settings = {k: v for k, v in job["settings"].items()       # colour: no size
                        if k not in ("input_icc", "output_icc")}
            rip = RipJob(job["spool_path"], rip_settings(settings), profile)
            try:
                size = (rip.width * profile.k(rip.settings.dpi) / profile.counts_per_inch * 25.4,
                        rip.height * profile.row_um / 1000.0)
            finally:
                rip.close()
        except (ImageError, ValueError, OSError, TypeError):
            pass
        if len(self._widths) > 1000:
            self._widths.clear()
        self._widths[key] = size
        return size

    # -- fit before it fails (docs/server.md "Fit before it fails") ----------------------------
    def fit(self, job: dict) -> dict:
        """Whether `job` fits the paper loaded: {fits, problems, width_mm, height_mm,
        printable_mm, roll, offers}.  The printer it asks for, or for "any" the printer
        that fits it best.  offers: the settings changes that make it fit (fit to the
        width, turned 90 degrees), each with the size it then prints at."""
        names = [job["printer"]] if job.get("printer") in self.workers else list(self.workers)
        best: dict | None = None
        for name in names:
            w = self.workers[name]
            size = self.job_size_mm(job, w.profile)
            if size is None:
                return dict(fits=True, problems=[], printer=name, width_mm=None,
                            height_mm=None, printable_mm=round(w.printable_mm(), 1),
                            roll=self.rolls.get(name), offers=[])
            width, height = size
            printable = w.printable_mm()
            problems = []
            if width > printable + 1e-6:
                problems.append(f"{job['name']} is {width:,.0f} mm wide: printer {name}'s "
                                f"paper takes {printable:,.0f} mm (its width less the margins)")
            n = max(1, int(job.get("copies", 1)) - int(job.get("copies_done", 0)))
            top = float((job["settings"].get("placement") or {}).get("top_mm") or 0.0)
            short = short_of_roll(self.rolls.get(name),
                                  n * paper_per_copy_mm(w.profile, height, top))
            if short:
                problems.append(f"{job['name']} {short} on printer {name}")
            out = dict(fits=not problems, problems=problems, printer=name,
                       width_mm=round(width, 1), height_mm=round(height, 1),
                       printable_mm=round(printable, 1), roll=self.rolls.get(name), offers=[])
            if width > printable + 1e-6:
                out["offers"] = self._fit_offers(job, w, printable)
            if best is None or (out["fits"] and not best["fits"]):
                best = out
        return best  # type: ignore[return-value]

    def _fit_offers(self, job: dict, w, printable: float) -> list[dict]:
        """Settings that make a too wide job fit: scaled to the printable width; turned 90
        degrees when its length fits across."""
        place = dict(job["settings"].get("placement") or {})
        offers = []
        sizes = ("width_mm", "height_mm", "scale", "fit_width_mm")
        turned: dict = dict(rotate=(int(place.get("rotate", 0)) + 90) % 360)
        # a size given across the paper goes along it once turned
        if place.get("width_mm") is not None or place.get("height_mm") is not None:
            turned.update(width_mm=place.get("height_mm"), height_mm=place.get("width_mm"))
        for kind, change in (("fit-to-width", dict(fit_width_mm=round(printable - 0.5, 1))),
                             ("rotate", turned)):
            kept = {k: v for k, v in place.items() if k not in sizes or kind == "rotate"}
            new = dict(job["settings"], placement={k: v for k, v in dict(kept, **change).items()
                                                   if v is not None})
            size = self.job_size_mm(dict(job, settings=new), w.profile)
            if size is not None and size[0] <= printable + 1e-6:
                offers.append(dict(kind=kind, settings={"placement": change},
                                   width_mm=round(size[0], 1), height_mm=round(size[1], 1)))
        return offers

    def check_fit(self, job: dict, width_only: bool = False) -> None:
        """Refuse a job that does not fit the loaded paper (Invalid 422 naming the file and
        what would make it fit), unless it is forced; width_only: only a job too wide."""
        if job.get("force"):
            return
        fit = self.fit(job)
        if width_only:                  # the width's problem, in fit()'s words
            fit = dict(fit, problems=[p for p in fit["problems"] if " mm wide: " in p])
        if not fit["problems"]:
            return
        offers = "; ".join(f"{o['kind']} ({o['width_mm']:,.0f} x {o['height_mm']:,.0f} mm, "
                           f"settings {json.dumps(o['settings'])})" for o in fit["offers"])
        raise Invalid("; ".join(fit["problems"]) + (f". It fits with: {offers}" if offers else "")
                      + ". Refused: change it, load other paper, or submit it with force "
                      "(wideprint submit --force)", 422)

    def printers(self) -> list[dict]:
        out = []
        for name, w in self.workers.items():
            cur = dict(w.current) if w.current else None
            if cur is not None and w.job is not None:
                t = w.job.telemetry
                cur["telemetry"] = dict(carriage_counts=t.carriage_counts, paper_steps=t.paper_steps,
                                        fires_done=t.fires_done, head_temps_c=list(t.head_temps_c),
                                        fifo_words=list(t.fifo_words), fault=t.fault, retries=t.retries)
            live = w.live
            out.append(dict(name=name, device=w.printer.device, profile=w.profile.path,
                            paper_mm=w.paper_mm, printable_mm=round(w.printable_mm(), 1),
                            media=None if live is None or live.job is None else
                            dict(job=live.job, version=live.version),
                            state=w.printer_state, error=w.disk_wait or w.printer_error, fault=w.fault or None,
                            paused=w.paused, reason=w.pause_reason, capped=w.capped,
                            current=cur, roll=self.rolls.get(name),
                            warnings=w.roll_warnings()))      # docs/server.md "Rolls: the warning"
        return out

    def hot_done(self, job: dict, state: str, message: str) -> None:
        """A hot-folder job ended: its original goes to done/ or failed/ (with reason),
        reached from the hot-folder root's descriptor only (HotFolders.finish)."""
        hot = job.get("hot_path")
        if not hot or not self.hot:
            return
        self.hot.finish(hot, state, None if state == "done"
                        else f"job {job['id']} {state}: {message}")

    def status(self) -> dict:
        """The server, its queue and its printers.  `printer`, `current` and `queue.paused`
        describe the first printer, as with one printer (older clients)."""
        self.preset_source.get()                     # the status reports the file as it is now
        printers = self.printers()
        first = printers[0]
        return dict(server=dict(version=_version(), pid=os.getpid(), url=self.url,
                                started=self.started, device=self.config.printer_configs()[0].device,
                                on_crash=self.config.on_crash,
                                hot_folder_root=str(self.config.hot_folder_root or "") or None),
                    queue=dict(paused=first["paused"], reason=first["reason"],
                               counts=self.spool.counts()),
                    presets=self.preset_source.info(),
                    printer=dict(state=first["state"], error=first["error"], fault=first["fault"]),
                    printers=printers,
                    current=first["current"])

    def report_csv(self, job_id: int | None = None, with_costs: bool = False) -> str:
        return prints_csv(self.spool.prints(job_id),
                          costs.read(self.state_dir) if with_costs else None)


def _version() -> str:
    try:
        from ... import __version__
        return __version__
    except ImportError:
        return "?"


def serve(config: ServerConfig, ready=None) -> int:
    """Run the server until SIGTERM/SIGINT: a job printing then is paused at its next stroke
    boundary and resumed by the next start."""
    # the colour transforms' cache (rip/color/lutcache.py) in the state directory: what clients send
    # (embedded profiles) makes files there, never in the service user's home
    os.environ.setdefault("WIDEPRINT_CACHE_DIR", str(Path(config.state_dir) / "cache"))
    server = PrintServer(config)
    server.start()

    done = server.stop_requested

    def on_signal(signum, frame):
        done.set()
    signal.signal(signal.SIGTERM, on_signal)
    signal.signal(signal.SIGINT, on_signal)
    print(f"wideprint serve: {server.url} (state {server.state_dir}, device {config.device}"
          + (f", hot folders {config.hot_folder_root}" if config.hot_folder_root else "")
          + ")", flush=True)
    for job in server.recovered:
        print(f"wideprint serve: job {job['id']}: {job['message']}", flush=True)
    if ready:
        ready(server)
    notify(READY=1, STATUS=f"serving {server.url}")       # systemd Type=notify
    while not done.wait(1.0):
        pass
    notify(STOPPING=1, STATUS="stopping: the printing job pauses at its next boundary")
    server.stop()
    return 0
