"""`wideprint serve`: the print server (docs/server.md).

One process owns the printer (one Device, re-opened after link errors) and its queue
(driver/spool.py).  Threads:

- the API: HTTP/JSON on 127.0.0.1 with a bearer token (`ApiHandler`);
- the worker: prints queued jobs one at a time in queue order, persisting the job's
  checkpoint after every pass, so a server killed mid-job resumes it at its first
  unfinished pass (or holds it, `--on-crash hold`);
- the hot-folder scanner: one folder per preset; a completely written file becomes a job,
  and moves to done/ or failed/ (with NAME.reason.txt) when the job ends.

The presets (`Presets`) are re-read when their file changes, without a restart; a broken
file keeps the presets in use.

Nothing here trusts its inputs: names, JSON, sizes and file types are checked (see
`validate_*`, `HotFolders`), and a file that cannot be ripped fails its own job only.
"""

from __future__ import annotations

import csv
import hashlib
import hmac
import io
import json
import logging
import math
import os
import secrets
import signal
import stat
import threading
import time
import uuid
from dataclasses import dataclass, field
from http.server import BaseHTTPRequestHandler, ThreadingHTTPServer
from pathlib import Path
from urllib.parse import parse_qs, urlsplit

from .spool import COLORS, Spool, SpoolError

log = logging.getLogger("wideprint.server")

DEFAULT_PORT = 8631
DEFAULT_MAX_FILE = 4 * 1024 ** 3          # 4 GiB
TOKEN_FILE = "token"
SERVER_FILE = "server.json"
PRESET_FILES = ("presets.toml", "presets.json")
DEFAULT_PRESETS = {
    "default": {},
    "photo": {"passes": 4, "bidir": False, "dither": "fs", "dpi": 300},
    "banner": {"passes": 2, "bidir": True, "dither": "bayer", "dpi": 300},
}
IMAGE_SUFFIXES = (".tif", ".tiff", ".jpg", ".jpeg", ".bmp", ".png")
IGNORED_SUFFIXES = (".part", ".tmp", ".temp", ".crdownload", ".partial", ".download", "~",
                    ".swp", ".reason.txt")
PASS_MODES = (1, 2, 3, 4, 6, 8)
INTENTS = ("perceptual", "relative", "saturation", "absolute")
MAX_COPIES = 100
PRIORITY_RANGE = (-100, 100)
CHUNK = 1 << 20


def default_state_dir() -> Path:
    """WIDEPRINT_STATE_DIR, else /var/lib/wideprint for root, else the user's state dir."""
    env = os.environ.get("WIDEPRINT_STATE_DIR")
    if env:
        return Path(env)
    if os.geteuid() == 0:
        return Path("/var/lib/wideprint")
    try:
        from platformdirs import user_state_dir
        return Path(user_state_dir("wideprint"))
    except ImportError:
        return Path.home() / ".local" / "state" / "wideprint"


# -- validation ----------------------------------------------------------------------------
class Invalid(ValueError):
    """A request or file that is refused; the message says why."""

    def __init__(self, message: str, status: int = 400):
        super().__init__(message)
        self.status = status


def validate_name(name) -> str:
    """A submitted file name: a plain name, never a path."""
    if not isinstance(name, str):
        raise Invalid("name must be a string")
    if not name or len(name.encode("utf-8", "surrogateescape")) > 255:
        raise Invalid("name must be 1 to 255 bytes")
    if "/" in name or "\\" in name:
        raise Invalid(f"name {name!r} is a path: give a plain file name (no / or \\)")
    if name in (".", "..") or name.startswith("."):
        raise Invalid(f"name {name!r}: names starting with '.' are refused")
    if any(ord(ch) < 32 or ord(ch) == 127 for ch in name):
        raise Invalid(f"name {name!r} contains control characters")
    return name


def _is_int(v) -> bool:
    return isinstance(v, int) and not isinstance(v, bool)


def _check_int(key: str, v, lo: int, hi: int) -> int:
    if not _is_int(v):
        raise Invalid(f"{key} must be an integer, not {type(v).__name__}")
    if not lo <= v <= hi:
        raise Invalid(f"{key} {v} is out of range ({lo}..{hi})")
    return v


def validate_placement(raw) -> dict:
    """A placement object (rip/place.py Placement fields), types checked, then the
    placement's own consistency check."""
    import dataclasses
    from ..rip.place import Placement
    if not isinstance(raw, dict):
        raise Invalid("placement must be a JSON object")
    fields = {f.name: f for f in dataclasses.fields(Placement)}
    for key, v in raw.items():
        if key not in fields:
            raise Invalid(f"unknown placement field {key!r} (known: {', '.join(fields)})")
        if key in ("size", "filter", "align") and not isinstance(v, str):
            raise Invalid(f"placement {key} must be a string")
        if key in ("width_mm", "height_mm", "scale", "fit_width_mm", "margin_mm") and v is not None and (
                isinstance(v, bool) or not isinstance(v, (int, float)) or not math.isfinite(v)):
            raise Invalid(f"placement {key} must be a number or null")
        if key in ("x_mm", "top_mm") and (
                isinstance(v, bool) or not isinstance(v, (int, float)) or not math.isfinite(v)):
            raise Invalid(f"placement {key} must be a number")
        if key == "rotate" and not _is_int(v):
            raise Invalid("placement rotate must be an integer (0, 90, 180, 270)")
        if key == "mirror" and not isinstance(v, bool):
            raise Invalid("placement mirror must be true or false")
    try:
        Placement(**raw).check()
    except ValueError as exc:
        raise Invalid(str(exc)) from None
    return dict(raw)


def rip_settings(settings: dict):
    """RipSettings from validated settings (placement given as a JSON object)."""
    from ..rip.pipeline import RipSettings
    from ..rip.place import Placement
    s = dict(settings)
    if "placement" in s:
        s["placement"] = Placement(**s["placement"])
    return RipSettings(**s)


def validate_settings(raw, profile, icc_dir: Path | None = None) -> dict:
    """RIP settings from a request or a preset: known keys only, right types, in range."""
    from ..rip.halftone import METHODS
    if not isinstance(raw, dict):
        raise Invalid("settings must be a JSON object")
    out = {}
    for key, v in raw.items():
        if key == "dpi":
            if not _is_int(v) or v not in profile.dpi_modes:
                raise Invalid(f"dpi must be one of {list(profile.dpi_modes)}, not {v!r}")
        elif key == "passes":
            if not _is_int(v) or v not in PASS_MODES:
                raise Invalid(f"passes must be one of {list(PASS_MODES)}, not {v!r}")
        elif key == "bidir":
            if not isinstance(v, bool):
                raise Invalid(f"bidir must be true or false, not {v!r}")
        elif key == "dither":
            if v not in METHODS:
                raise Invalid(f"dither must be one of {', '.join(METHODS)}, not {v!r}")
        elif key == "intent":
            if v not in INTENTS:
                raise Invalid(f"intent must be one of {', '.join(INTENTS)}, not {v!r}")
        elif key == "ink_limit":
            if v is not None:
                if isinstance(v, bool) or not isinstance(v, (int, float)) or not math.isfinite(v):
                    raise Invalid(f"ink_limit must be a number (percent) or null, not {v!r}")
                if not 1 <= v <= 400:
                    raise Invalid(f"ink_limit {v} is out of range (1..400 %)")
                v = float(v)
        elif key == "pass_mask":
            from ..rip.swath import PASS_MASKS
            if v not in PASS_MASKS:
                raise Invalid(f"pass_mask must be one of {', '.join(PASS_MASKS)}, not {v!r}")
        elif key == "placement":
            v = validate_placement(v)
        elif key in ("input_icc", "output_icc"):
            if v is not None:
                try:
                    validate_name(v)
                except Invalid as exc:
                    raise Invalid(f"{key}: {exc} (ICC profiles are named from the server's "
                                  f"icc/ folder)") from None
                if icc_dir is not None and not (icc_dir / v).is_file():
                    raise Invalid(f"{key} {v!r}: no such profile in {icc_dir}")
        else:
            raise Invalid(f"unknown setting {key!r} (known: dpi, passes, bidir, dither, "
                          f"pass_mask, placement, intent, ink_limit, input_icc, output_icc)")
        out[key] = v
    return out


JOB_KEYS = {"name", "preset", "copies", "priority", "hold", "key", "client", "settings"}


def validate_job_request(raw, presets: dict, profile, icc_dir: Path | None) -> dict:
    """The X-Wideprint-Job header of an upload: returns the checked request with the
    effective settings (preset overlaid by explicit settings)."""
    if not isinstance(raw, dict):
        raise Invalid("the job description must be a JSON object")
    unknown = set(raw) - JOB_KEYS
    if unknown:
        raise Invalid(f"unknown field {sorted(unknown)[0]!r} (known: {', '.join(sorted(JOB_KEYS))})")
    if "name" not in raw:
        raise Invalid("name is required")
    req = {"name": validate_name(raw["name"])}
    preset = raw.get("preset")
    if preset is not None:
        if not isinstance(preset, str) or preset not in presets:
            raise Invalid(f"unknown preset {preset!r} (presets: {', '.join(sorted(presets))})")
    req["preset"] = preset
    req["copies"] = _check_int("copies", raw.get("copies", 1), 1, MAX_COPIES)
    req["priority"] = _check_int("priority", raw.get("priority", 0), *PRIORITY_RANGE)
    hold = raw.get("hold", False)
    if not isinstance(hold, bool):
        raise Invalid("hold must be true or false")
    req["hold"] = hold
    for k, limit in (("key", 200), ("client", 100)):
        v = raw.get(k)
        if v is not None and (not isinstance(v, str) or not 0 < len(v) <= limit or
                              any(ord(ch) < 32 for ch in v)):
            raise Invalid(f"{k} must be a printable string of 1..{limit} characters")
        req[k] = v
    settings = dict(presets.get(preset, {})) if preset else {}
    settings.update(validate_settings(raw.get("settings", {}), profile, icc_dir))
    req["settings"] = settings
    return req


def preset_file(state_dir: Path) -> Path | None:
    """The presets file in use: presets.toml, else presets.json (None: neither exists)."""
    for fname in PRESET_FILES:
        p = state_dir / fname
        if p.exists():
            return p
    return None


def read_presets(path: Path, profile, icc_dir: Path) -> dict:
    """One presets file ({name: settings}), every preset checked like the API's settings;
    ValueError naming the file and the problem."""
    try:
        text = path.read_text()
        if path.suffix == ".toml":
            import tomllib
            raw = tomllib.loads(text)
        else:
            raw = json.loads(text)
    except OSError as exc:
        raise ValueError(f"{path}: {exc.strerror}") from None
    except ValueError as exc:                  # TOML / JSON syntax, bad UTF-8
        raise ValueError(f"{path}: {exc}") from None
    if not isinstance(raw, dict):
        raise ValueError(f"{path}: expected a table of presets")
    presets = {}
    for name, settings in raw.items():
        try:
            validate_name(name)
            if name in ("done", "failed"):
                raise Invalid("reserved for the hot folders' done/ and failed/")
            presets[name] = validate_settings(settings, profile, icc_dir)
        except Invalid as exc:
            raise ValueError(f"{path}: preset {name!r}: {exc}") from None
    return presets


def load_presets(state_dir: Path, profile) -> dict:
    """presets.toml or presets.json in the state dir ({name: settings}); written with
    the defaults on first start."""
    path = preset_file(state_dir)
    if path is None:
        path = state_dir / "presets.json"
        path.write_text(json.dumps(DEFAULT_PRESETS, indent=2) + "\n")
    return read_presets(path, profile, state_dir / "icc")


class Presets:
    """The server's presets, kept in step with their file without a restart (docs/server.md,
    "Presets are re-read without a restart"): `get()` compares the file's stat signature
    with the one last read (one stat: cheap enough for every request and scan) and
    re-reads it when it changed; `reload()` re-reads on demand.  A file that cannot be read or has an invalid preset is
    logged and reported (`error`) and the presets in use are kept — a typo in the file
    never stops the server or the jobs that use the other presets.  At start-up there is
    nothing to keep, so there a broken file is fatal (as before)."""

    def __init__(self, state_dir: Path, profile):
        self.state_dir, self.profile = state_dir, profile
        self._lock = threading.Lock()
        self._sig = self._signature()          # before reading: a later write is seen
        self.current = load_presets(state_dir, profile)
        self.path = preset_file(state_dir)
        self.loaded = time.time()
        self.error = ""

    def _signature(self):
        # mtime alone misses two writes within the clock's granularity; size and inode
        # (editors that write a new file and rename it) catch most of those
        path = preset_file(self.state_dir)
        try:
            st = path.stat() if path else None
        except OSError:
            st = None
        return None if st is None else (path.name, st.st_mtime_ns, st.st_size, st.st_ino)

    def get(self) -> dict:
        """The presets now, re-read first if the file changed since it was last read."""
        if self._signature() != self._sig:
            try:
                self.reload(only_if_changed=True)
            except ValueError:
                pass                           # logged, kept in `error`; the old ones stay
        return self.current

    def reload(self, only_if_changed: bool = False) -> dict:
        """Re-read the file: returns {added, removed, changed} preset names, or raises
        ValueError naming the file and the problem (the presets in use are kept, and the
        broken file is not read again until it changes or `reload` is asked for)."""
        with self._lock:
            sig = self._signature()            # before reading: a later write is seen next time
            if only_if_changed and sig == self._sig:
                return dict(added=[], removed=[], changed=[])   # another thread just did it
            path = preset_file(self.state_dir)
            try:
                if path is None:
                    raise ValueError(f"{self.state_dir}: no presets file "
                                     f"({' or '.join(PRESET_FILES)})")
                new = read_presets(path, self.profile, self.state_dir / "icc")
            except ValueError as exc:
                self._sig, self.error = sig, f"{exc}; the presets in use are kept"
                log.error("presets: %s", self.error)
                raise ValueError(self.error) from None
            old, self.current = self.current, new
            self._sig, self.path, self.error = sig, path, ""
            diff = dict(added=sorted(set(new) - set(old)), removed=sorted(set(old) - set(new)),
                        changed=sorted(n for n in set(new) & set(old) if new[n] != old[n]))
            if any(diff.values()):
                self.loaded = time.time()      # when the presets in use took effect
        if any(diff.values()):
            log.info("presets re-read from %s: %s", path,
                     "; ".join(f"{k} {', '.join(v)}" for k, v in diff.items() if v))
        return diff

    def info(self) -> dict:
        return dict(file=str(self.path) if self.path else None, names=sorted(self.current),
                    loaded=self.loaded, error=self.error or None)


def ensure_token(state_dir: Path) -> str:
    """The API token: created 0600 on first start, read by clients."""
    path = state_dir / TOKEN_FILE
    try:
        fd = os.open(path, os.O_WRONLY | os.O_CREAT | os.O_EXCL, 0o600)
    except FileExistsError:
        return path.read_text().strip()
    token = secrets.token_urlsafe(32)
    with os.fdopen(fd, "w") as f:
        f.write(token + "\n")
    return token


def _fsync_dir(path: Path) -> None:
    fd = os.open(path, os.O_RDONLY | os.O_DIRECTORY)
    try:
        os.fsync(fd)
    finally:
        os.close(fd)


def _unique(path: Path) -> Path:
    if not path.exists() and not path.is_symlink():
        return path
    stem, suffix = path.name, ""
    for s in IMAGE_SUFFIXES:
        if path.name.lower().endswith(s):
            stem, suffix = path.name[:-len(s)], path.name[-len(s):]
    i = 1
    while True:
        cand = path.with_name(f"{stem}-{i}{suffix}")
        if not cand.exists() and not cand.is_symlink():
            return cand
        i += 1


@dataclass
class ServerConfig:
    device: str = "emulator"
    state_dir: Path = field(default_factory=default_state_dir)
    media_dir: Path | None = None
    hot_folder_root: Path | None = None
    host: str = "127.0.0.1"
    port: int = DEFAULT_PORT
    on_crash: str = "resume"               # resume | hold
    max_file_bytes: int = DEFAULT_MAX_FILE
    scan_interval: float = 1.0
    start_paused: bool = False
    profile_path: str | None = None
    reconnect_backoff: tuple = (0.5, 30.0)
    keep_failed_s: float = 7 * 86400       # spool copies of failed/cancelled jobs (requeue)


# -- the worker -------------------------------------------------------------------------------
class Worker(threading.Thread):
    """Prints queued jobs one at a time, in queue order."""

    def __init__(self, server: "PrintServer"):
        super().__init__(name="wideprint-worker", daemon=True)
        self.srv = server
        self.spool = server.spool
        self.wake = threading.Condition()
        self.paused = server.config.start_paused
        self.pause_reason = "started paused" if self.paused else ""
        self.stopping = False
        self.dev = None
        self.printer_state = "idle"        # idle, printing, offline
        self.printer_error = ""
        self.current: dict | None = None   # id, name, copy, state, detail, pass, ...
        self.job = None                    # the PrintJob now running
        self._cancel: set[int] = set()
        self._backoff = server.config.reconnect_backoff[0]
        self._next_expiry = time.monotonic() + 60   # the server expired them at start-up

    # control from other threads
    def notify(self) -> None:
        with self.wake:
            self.wake.notify_all()

    def set_paused(self, paused: bool, reason: str = "") -> None:
        self.paused = paused
        self.pause_reason = reason if paused else ""
        self.notify()

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
        """Server shutdown: the running job pauses at its next pass boundary (its
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
            job = None
            if not self.paused:
                try:
                    job = self.spool.next_job()
                except Exception:  # noqa: BLE001 - a database hiccup must not end the worker
                    log.exception("reading the queue")
            if job is None:
                with self.wake:
                    self.wake.wait(0.5)
                continue
            try:
                self._run_job(job["id"])
            except Exception as exc:  # noqa: BLE001 - never let one job end the server
                log.exception("job %s", job["id"])
                try:
                    self._finish(self.spool.get(job["id"]), "failed", f"internal error: {exc}")
                except Exception:  # noqa: BLE001
                    log.exception("failing job %s", job["id"])
            finally:
                self.current, self.job = None, None
                if self.printer_state == "printing":
                    self.printer_state = "idle"

    def _device(self):
        if self.dev is None:
            from .device import open_device
            media = self.srv.config.media_dir
            media_path = (lambda job: str(media / f"job-{job}.tif")) if media else None
            self.dev = open_device(self.srv.config.device, self.srv.profile, media_path=media_path)
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
        self.spool.wait_for_printer(job_id, f"waiting for the printer: {message}")
        log.warning("printer offline: %s (retrying in %.1f s)", message, self._backoff)
        with self.wake:
            self.wake.wait(self._backoff)
        self._backoff = min(self._backoff * 2, self.srv.config.reconnect_backoff[1])

    def _run_job(self, job_id: int) -> None:
        from ..rip.load import ImageError
        from ..rip.pipeline import RipJob
        from .job import JobCancelled, JobError, PrintJob
        from .link import DeviceError, LinkError
        from .stream import StreamError

        job = self.spool.claim(job_id)
        if job is None:
            return
        resumed = job["checkpoint"] is not None
        self.current = dict(id=job_id, name=job["name"], copy=job["copies_done"] + 1,
                            copies=job["copies"], state="ripping", detail="", pass_index=None,
                            passes_total=job["passes_total"], passes_printed=job["passes_done"],
                            resumed=resumed)
        self.printer_state = "printing"
        settings = dict(job["settings"])
        icc = self.srv.state_dir / "icc"
        for k in ("input_icc", "output_icc"):
            if settings.get(k):
                settings[k] = str(icc / settings[k])
        first = True
        while job["copies_done"] < job["copies"]:
            copy = job["copies_done"] + 1
            if not first:
                self.spool.start_copy(job_id)
                job = self.spool.get(job_id)
                resumed = False
            self.current.update(copy=copy, state="ripping", pass_index=None, passes_printed=0)
            cp = job["checkpoint"] if first else None
            first = False
            started = job["copy_started"] or time.time()
            if job_id in self._cancel:
                self._account(job, copy, started, None, "cancelled", "cancelled by the operator",
                              resumed)
                self._finish(job, "cancelled", "cancelled by the operator")
                return
            try:
                rip = RipJob(job["spool_path"], rip_settings(settings), self.srv.profile)
            except (ImageError, ValueError, OSError) as exc:
                msg = str(exc).replace(job["spool_path"] or "", job["name"])
                self._account(job, copy, started, None, "failed", msg, resumed)
                self._finish(job, "failed", msg)
                return
            try:
                try:
                    dev = self._device()
                    if cp is None and copy == 1 and job["attempt"] > 1:
                        self._close_earlier_attempt(dev, job_id)
                except (LinkError, OSError, ValueError) as exc:
                    self._offline(job_id, str(exc))
                    return
                except DeviceError as exc:
                    msg = f"ending the earlier attempt on the printer: {exc}"
                    self._account(job, copy, started, None, "failed", msg, resumed)
                    self._finish(job, "failed", msg)
                    return
                epoch = job.get("epoch") or self.spool.epoch()

                def on_event(kind, **kw):
                    cur = self.current
                    if kind == "checkpoint":
                        self.spool.save_checkpoint(job_id, dict(kw["checkpoint"], epoch=epoch,
                                                                copy=copy),
                                                   pj.report.passes_total)
                        cur["passes_printed"] = kw["checkpoint"].get("next_pass", 0)
                        cur["passes_total"] = pj.report.passes_total
                    elif kind == "state":
                        cur["state"], cur["detail"] = kw["state"], kw.get("detail", "")
                    elif kind == "pass":
                        cur["pass_index"], cur["passes_total"] = kw["index"], kw["total"]

                pj = PrintJob(dev, rip, job_id=job_id, on_event=on_event, resume=cp)
                self.job = pj
                if job_id in self._cancel:
                    pj.control.cancel()
                if self.stopping:
                    pj.control.pause()
                try:
                    rep = pj.run()
                except JobCancelled as exc:
                    self._account(job, copy, started, pj.report, "cancelled", str(exc), resumed)
                    self._finish(job, "cancelled", f"cancelled by the operator ({exc})")
                    return
                except JobError as exc:
                    cause = exc.__cause__
                    if isinstance(cause, (LinkError, StreamError)) and not self.stopping:
                        self._drop_device()
                        self._offline(job_id, str(exc))
                        return
                    self._account(job, copy, started, pj.report, "failed", str(exc), resumed)
                    self._finish(job, "failed", str(exc))
                    if exc.fault:
                        self.set_paused(True, f"printer fault: {exc}; clear it and resume the queue")
                    return
                finally:
                    self.job = None
            finally:
                rip.close()
            self.printer_state, self.printer_error = "printing", ""
            self._backoff = self.srv.config.reconnect_backoff[0]
            self._account(job, copy, started, rep, "done", "", resumed)
            job = self.spool.copy_done(job_id)
        self._finish(job, "done", "")

    @staticmethod
    def _close_earlier_attempt(dev, job_id: int) -> None:
        """A requeued job prints afresh under the same printer job id.  Its earlier attempt
        failed or was cancelled without JOB_END, so the printer may still hold it open, and
        would take the new JOB_BEGIN (same id, same image area) for the host reconnecting:
        keep the old placement's media and paper position.  End it first (docs/server.md,
        "Requeue")."""
        from . import protocol as P
        dev.connect()
        if dev.link.status().flags & P.FLAG_JOB_OPEN:
            dev.link.call(P.Op.JOB_END, job=job_id)

    def _finish(self, job: dict, state: str, message: str) -> None:
        self.srv.hot_done(job, state, message)
        keep = self.srv.keeps_copy(state)
        self.spool.finish(job["id"], state, message, keep_copy=keep)
        self._cancel.discard(job["id"])
        path = job.get("spool_path")
        if path and not keep:
            try:
                os.unlink(path)
            except OSError:
                pass
        log.info("job %s %s %s", job["id"], state, message)

    def _account(self, job: dict, copy: int, started: float, rep, outcome: str, message: str,
                 resumed: bool) -> None:
        prof = self.srv.profile
        ended = time.time()
        r = rep.as_dict() if rep is not None else {}
        drops = [int(d) for d in r.get("drops", [0, 0, 0, 0])]
        pl = prof.drop_volume_pl
        row = dict(job_id=job["id"], copy=copy, file=job["name"], source=job["source"],
                   preset=job["preset"], settings=json.dumps(job["settings"], sort_keys=True),
                   started=started, ended=ended, duration_s=round(ended - started, 3),
                   passes_total=r.get("passes_total", 0), passes_printed=r.get("passes_printed", 0),
                   width_dots=r.get("width_dots", 0), height_rows=r.get("height_rows", 0),
                   area_m2=r.get("area_m2", 0.0), outcome=outcome, message=message,
                   resumed=int(bool(resumed)), recoveries=r.get("recoveries", 0),
                   retries=r.get("retries", 0), attempt=job["attempt"])
        for c, d in zip(COLORS, drops):
            row[f"drops_{c}"] = d
            row[f"ink_{c}_ml"] = round(d * pl * 1e-9, 12)
        self.spool.add_print(row)


# -- hot folders ------------------------------------------------------------------------------
def open_for_writing(path: str) -> bool:
    """Whether any process we can see has this file open for writing (Linux /proc)."""
    try:
        target = os.stat(path)
    except OSError:
        return False
    proc = Path("/proc")
    if not proc.is_dir():
        return False
    for pid in os.listdir(proc):
        if not pid.isdigit():
            continue
        fd_dir = f"/proc/{pid}/fd"
        try:
            fds = os.listdir(fd_dir)
        except OSError:
            continue
        for fd in fds:
            try:
                st = os.stat(f"{fd_dir}/{fd}")
            except OSError:
                continue
            if st.st_ino != target.st_ino or st.st_dev != target.st_dev:
                continue
            try:
                with open(f"/proc/{pid}/fdinfo/{fd}") as f:
                    for line in f:
                        if line.startswith("flags:"):
                            flags = int(line.split()[1], 8)
                            if flags & os.O_ACCMODE in (os.O_WRONLY, os.O_RDWR):
                                return True
            except (OSError, ValueError):
                continue
    return False


class HotFolders(threading.Thread):
    """ROOT/PRESET/ for every preset.  A file becomes a job once complete: the same size
    and modification time on two scans in a row and open for writing by nobody.  Dotfiles
    and partial names (*.part, *.tmp, ...) are ignored, folders are left alone; symlinks,
    non-regular files (FIFOs, sockets, devices), oversize and unreadable files go straight
    to failed/ with NAME.reason.txt."""

    def __init__(self, server: "PrintServer", root: Path):
        super().__init__(name="wideprint-hot-folders", daemon=True)
        self.srv = server
        self.root = root
        self.seen: dict[str, tuple] = {}
        self.stopping = threading.Event()
        self.lock = threading.Lock()
        self.made: set[str] = set()
        self.make_folders(server.presets)

    def make_folders(self, presets) -> None:
        """ROOT/PRESET/{done,failed}/ for presets that have none yet (start-up, and
        presets added to the file later).  A removed preset's folder is left as it is."""
        for preset in set(presets) - self.made:
            for sub in ("", "done", "failed"):
                (self.root / preset / sub).mkdir(parents=True, exist_ok=True)
            self.made.add(preset)

    def run(self) -> None:
        while not self.stopping.wait(self.srv.config.scan_interval):
            try:
                self.scan_once()
            except Exception:  # noqa: BLE001 - the scanner must keep going
                log.exception("hot folder scan")

    @staticmethod
    def ignored(name: str) -> bool:
        low = name.lower()
        return name.startswith(".") or low.endswith(IGNORED_SUFFIXES) or name.startswith("~$")

    def scan_once(self) -> None:
        presets = self.srv.presets             # re-read first if the file changed
        with self.lock:
            self.make_folders(presets)
            active = self.srv.spool.active_hot_paths()
            present = set()
            for preset, settings in presets.items():
                folder = self.root / preset
                try:
                    entries = list(os.scandir(folder))
                except OSError as exc:
                    log.warning("hot folder %s: %s", folder, exc)
                    continue
                for e in entries:
                    if self.ignored(e.name):
                        continue
                    path = os.path.join(folder, e.name)
                    if path in active:
                        continue
                    try:
                        st = os.lstat(path)
                    except OSError:
                        continue
                    if stat.S_ISDIR(st.st_mode):
                        continue                       # done/, failed/, a folder being copied
                    present.add(path)
                    self._consider(preset, settings, folder, e.name, path, st)
            for gone in set(self.seen) - present:
                del self.seen[gone]

    def _consider(self, preset: str, settings: dict, folder: Path, name: str, path: str,
                  st) -> None:
        if stat.S_ISLNK(st.st_mode):
            target = os.path.realpath(path)
            inside = target.startswith(str(folder.resolve()) + os.sep)
            return self._refuse(folder, name, f"{name} is a symbolic link to {target}"
                                + ("" if inside else ", outside the hot folder")
                                + ": links are not followed; copy the file itself")
        if not stat.S_ISREG(st.st_mode):
            kind = ("a FIFO" if stat.S_ISFIFO(st.st_mode) else "a socket" if stat.S_ISSOCK(st.st_mode)
                    else "a device" if stat.S_ISCHR(st.st_mode) or stat.S_ISBLK(st.st_mode)
                    else "not a regular file")
            return self._refuse(folder, name, f"{name} is {kind}: only regular files are printed")
        limit = self.srv.config.max_file_bytes
        if st.st_size > limit:
            return self._refuse(folder, name, f"{name} is {st.st_size} bytes, above the "
                                f"{limit}-byte limit")
        sig = (st.st_size, st.st_mtime_ns, st.st_ino)
        if self.seen.get(path) != sig:
            self.seen[path] = sig                   # new or still changing: look again
            return
        if open_for_writing(path):
            return                                  # stable but still open: a slow writer
        del self.seen[path]
        if st.st_size == 0:
            return self._refuse(folder, name, f"{name} is empty")
        try:
            validate_name(name)
        except Invalid as exc:
            return self._refuse(folder, name, str(exc))
        try:
            fd = os.open(path, os.O_RDONLY | os.O_NOFOLLOW | os.O_NONBLOCK | os.O_CLOEXEC)
        except OSError as exc:
            return self._refuse(folder, name, f"{name}: cannot open ({exc.strerror})")
        try:
            fst = os.fstat(fd)
            if not stat.S_ISREG(fst.st_mode) or fst.st_ino != st.st_ino:
                return self._refuse(folder, name, f"{name} changed while being read")
            with os.fdopen(fd, "rb", closefd=False) as f:
                try:
                    spool_path, size, digest = self.srv.spool_copy(f, name, fst.st_size)
                except Invalid as exc:
                    return self._refuse(folder, name, str(exc))
        finally:
            os.close(fd)
        job, _ = self.srv.spool.add_job(name=name, source=f"hot:{preset}", spool_path=spool_path,
                                        size=size, sha256=digest,
                                        settings=dict(settings), preset=preset,
                                        client="hot-folder", hot_path=path)
        log.info("hot folder %s: %s is job %s", preset, name, job["id"])
        self.srv.worker.notify()

    def _refuse(self, folder: Path, name: str, reason: str) -> None:
        log.warning("hot folder: %s", reason)
        self.seen.pop(os.path.join(folder, name), None)
        self.move(folder / name, folder / "failed", reason)

    @staticmethod
    def move(src: Path, dest_dir: Path, reason: str | None = None) -> Path | None:
        dest_dir.mkdir(exist_ok=True)
        dest = _unique(dest_dir / src.name)
        try:
            os.rename(src, dest)                    # the link/FIFO itself, never its target
        except OSError as exc:
            log.warning("cannot move %s to %s: %s", src, dest_dir, exc)
            return None
        if reason is not None:
            (dest_dir / (dest.name + ".reason.txt")).write_text(reason.rstrip() + "\n")
        return dest


# -- the API ----------------------------------------------------------------------------------
class ApiHandler(BaseHTTPRequestHandler):
    server_version = "wideprint"
    protocol_version = "HTTP/1.1"
    srv: "PrintServer"                               # set on the subclass

    def log_message(self, fmt, *args) -> None:  # noqa: D401 - quiet; to the logger
        log.debug("api %s " + fmt, self.client_address[0], *args)

    # responses
    def _send(self, status: int, body: bytes, ctype: str, close: bool = False,
              extra: dict | None = None) -> None:
        self.send_response(status)
        self.send_header("Content-Type", ctype)
        self.send_header("Content-Length", str(len(body)))
        self.send_header("Cache-Control", "no-store")
        for k, v in (extra or {}).items():
            self.send_header(k, v)
        if close:
            self.send_header("Connection", "close")
            self.close_connection = True
        self.end_headers()
        if self.command != "HEAD":
            self.wfile.write(body)

    def _json(self, status: int, obj, close: bool = False, extra: dict | None = None) -> None:
        self._send(status, (json.dumps(obj, indent=1) + "\n").encode(), "application/json",
                   close, extra)

    def _error(self, status: int, message: str, close: bool = False) -> None:
        extra = {"WWW-Authenticate": 'Bearer realm="wideprint"'} if status == 401 else None
        self._json(status, {"error": message}, close=close, extra=extra)

    def _authorised(self) -> bool:
        auth = self.headers.get("Authorization", "")
        scheme, _, token = auth.partition(" ")
        if scheme.lower() != "bearer" or not hmac.compare_digest(
                token.strip().encode(), self.srv.token.encode()):
            return False
        return True

    def _read_json(self, allow_empty: bool = True):
        length = self.headers.get("Content-Length")
        if length is None:
            if self.headers.get("Transfer-Encoding"):
                raise Invalid("send a Content-Length (chunked bodies are not accepted)", 411)
            return {} if allow_empty else None
        try:
            n = int(length)
        except ValueError:
            raise Invalid("bad Content-Length") from None
        if n < 0 or n > 1 << 20:
            raise Invalid("JSON body too large (1 MiB at most)", 413)
        body = self.rfile.read(n)
        if not body.strip():
            return {}
        try:
            return json.loads(body)
        except (ValueError, UnicodeDecodeError) as exc:
            raise Invalid(f"bad JSON: {exc}") from None

    def _dispatch(self, method: str) -> None:
        url = urlsplit(self.path)
        parts = [p for p in url.path.split("/") if p]
        query = parse_qs(url.query)
        if not self._authorised():
            # nothing of an unauthorised request is read; the connection is closed
            return self._error(401, "missing or wrong bearer token (see the token file in "
                               "the server's state directory)", close=True)
        try:
            if parts[:1] != ["v1"]:
                raise Invalid(f"no such endpoint {url.path}", 404)
            route = parts[1:]
            if method == "POST" and route == ["jobs"]:
                return self._submit()
            if method in ("POST", "PATCH", "DELETE"):
                body = self._read_json()
            if method == "GET" and route == ["status"]:
                return self._json(200, self.srv.status())
            if method == "GET" and route == ["jobs"]:
                states = None
                if "state" in query:
                    states = tuple(s for v in query["state"] for s in v.split(",") if s)
                limit = int(query.get("limit", ["0"])[0]) or None
                after = int(query.get("after", ["0"])[0])
                return self._json(200, {"jobs": self.srv.jobs(states, limit, after)})
            if method == "GET" and route == ["presets"]:
                presets = self.srv.presets
                return self._json(200, dict(self.srv.preset_source.info(), presets=presets))
            if method == "POST" and route == ["presets", "reload"]:
                if body:
                    raise Invalid("reload takes no parameters")
                return self._json(200, self.srv.reload_presets())
            if method == "GET" and route == ["report"]:
                job = int(query["job"][0]) if "job" in query else None
                if query.get("format", ["json"])[0] == "csv":
                    return self._send(200, self.srv.report_csv(job).encode(), "text/csv")
                return self._json(200, {"prints": self.srv.spool.prints(job)})
            if method == "POST" and route == ["queue"]:
                if not isinstance(body, dict) or set(body) - {"paused"} or \
                        not isinstance(body.get("paused"), bool):
                    raise Invalid('expected {"paused": true|false}')
                self.srv.worker.set_paused(body["paused"], "paused by the operator")
                return self._json(200, self.srv.status())
            if len(route) >= 2 and route[0] == "jobs":
                try:
                    job_id = int(route[1])
                except ValueError:
                    raise Invalid(f"bad job id {route[1]!r}", 404) from None
                if method == "GET" and len(route) == 2:
                    job = self.srv.spool.get(job_id)
                    if job is None:
                        raise Invalid(f"no job {job_id}", 404)
                    return self._json(200, {"job": self.srv.public(job)})
                if method == "PATCH" and len(route) == 2:
                    if not isinstance(body, dict) or set(body) != {"priority"}:
                        raise Invalid('expected {"priority": N}')
                    pr = _check_int("priority", body["priority"], *PRIORITY_RANGE)
                    job = self.srv.spool.set_priority(job_id, pr)
                    return self._json(200, {"job": self.srv.public(job)})
                if method == "POST" and len(route) == 3 and route[2] in ("cancel", "hold", "release",
                                                                          "requeue"):
                    if body:
                        raise Invalid(f"{route[2]} takes no parameters")
                    job = getattr(self.srv, route[2])(job_id)
                    return self._json(200, {"job": self.srv.public(job)})
            raise Invalid(f"no such endpoint {method} {url.path}", 404)
        except Invalid as exc:
            return self._error(exc.status, str(exc))
        except SpoolError as exc:
            return self._error(exc.status, str(exc))
        except ValueError as exc:
            return self._error(400, str(exc))

    def _submit(self) -> None:
        srv = self.srv
        header = self.headers.get("X-Wideprint-Job")
        try:
            if header is None:
                raise Invalid("missing X-Wideprint-Job header (the job description, JSON)")
            try:
                raw = json.loads(header)
            except ValueError as exc:
                raise Invalid(f"bad JSON in X-Wideprint-Job: {exc}") from None
            req = validate_job_request(raw, srv.presets, srv.profile, srv.state_dir / "icc")
            if self.headers.get("Transfer-Encoding"):
                raise Invalid("send a Content-Length (chunked bodies are not accepted)", 411)
            length = self.headers.get("Content-Length")
            if length is None:
                raise Invalid("Content-Length is required", 411)
            try:
                size = int(length)
            except ValueError:
                raise Invalid("bad Content-Length") from None
            if size <= 0:
                raise Invalid("empty file")
            if size > srv.config.max_file_bytes:
                raise Invalid(f"file is {size} bytes, above the {srv.config.max_file_bytes}-byte "
                              "limit", 413)
        except Invalid as exc:
            # the body was not read: close the connection rather than read a file we refuse
            return self._error(exc.status, str(exc), close=True)
        try:
            spool_path, size, digest = srv.spool_copy(self.rfile, req["name"], size, exact=True)
        except Invalid as exc:
            return self._error(exc.status, str(exc), close=True)
        job, created = srv.spool.add_job(
            name=req["name"], source="api", spool_path=spool_path, size=size, sha256=digest,
            settings=req["settings"], preset=req["preset"], copies=req["copies"],
            priority=req["priority"], hold=req["hold"], key=req["key"], client=req["client"])
        if not created:
            os.unlink(spool_path)
            return self._json(200, {"job": srv.public(job), "duplicate": True})
        srv.worker.notify()
        self._json(201, {"job": srv.public(job), "duplicate": False})

    def do_GET(self):
        self._dispatch("GET")

    def do_POST(self):
        self._dispatch("POST")

    def do_PATCH(self):
        self._dispatch("PATCH")

    def do_DELETE(self):
        self._dispatch("DELETE")


class _HTTPServer(ThreadingHTTPServer):
    daemon_threads = True
    allow_reuse_address = True
    request_queue_size = 64


# -- the server ---------------------------------------------------------------------------------
class PrintServer:
    def __init__(self, config: ServerConfig):
        from ..rip.profile import load_profile
        self.config = config
        self.state_dir = Path(config.state_dir)
        self.state_dir.mkdir(parents=True, exist_ok=True)
        os.chmod(self.state_dir, 0o700) if self.state_dir.stat().st_uid == os.geteuid() else None
        (self.state_dir / "icc").mkdir(exist_ok=True)
        if config.media_dir:
            Path(config.media_dir).mkdir(parents=True, exist_ok=True)
        self.profile = load_profile(config.profile_path)
        self.preset_source = Presets(self.state_dir, self.profile)
        self.token = ensure_token(self.state_dir)
        self.spool = Spool(self.state_dir)
        self.started = time.time()
        self.recovered = self.spool.recover(config.on_crash)
        for job in self.recovered:
            log.warning("job %s: %s", job["id"], job["message"])
        self._clean_spool()
        self.expire_spool()
        self.worker = Worker(self)
        self.hot = HotFolders(self, Path(config.hot_folder_root)) if config.hot_folder_root else None
        handler = type("Handler", (ApiHandler,), {"srv": self})
        if config.host not in ("127.0.0.1", "localhost", "::1"):
            log.warning("the API listens on %s, beyond this machine: anyone with the token "
                        "can print", config.host)
        self.http = _HTTPServer((config.host, config.port), handler)
        self.port = self.http.server_address[1]
        self.url = f"http://{config.host}:{self.port}"
        self._http_thread = threading.Thread(target=self.http.serve_forever, name="wideprint-api",
                                             daemon=True)
        self._stopped = threading.Event()

    def _clean_spool(self) -> None:
        """Private copies nobody references (a crash between copy and commit) go."""
        used = self.spool.spool_files_in_use()
        for p in self.spool.spool_dir.iterdir():
            if str(p) not in used:
                try:
                    p.unlink()
                except OSError:
                    pass

    def expire_spool(self) -> None:
        """Spool copies of failed and cancelled jobs older than --keep-failed go (those
        jobs can no longer be requeued)."""
        for path in self.spool.expire_copies(time.time() - self.config.keep_failed_s):
            try:
                os.unlink(path)
            except OSError:
                pass

    def keeps_copy(self, state: str) -> bool:
        """Whether a job ending in `state` keeps its spool copy: failed and cancelled jobs
        do, for requeue (docs/server.md, "Requeue"), unless --keep-failed is 0."""
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
        self.worker.start()
        self._http_thread.start()
        if self.hot:
            self.hot.start()
        info = dict(url=self.url, pid=os.getpid(), started=self.started,
                    device=self.config.device, state_dir=str(self.state_dir))
        tmp = self.state_dir / (SERVER_FILE + ".tmp")
        tmp.write_text(json.dumps(info) + "\n")
        os.replace(tmp, self.state_dir / SERVER_FILE)

    def stop(self, timeout: float = 30.0) -> None:
        if self._stopped.is_set():
            return
        self._stopped.set()
        if self.hot:
            self.hot.stopping.set()
        self.worker.interrupt(timeout)
        self.http.shutdown()
        self.http.server_close()
        try:
            (self.state_dir / SERVER_FILE).unlink()
        except OSError:
            pass

    # -- intake -------------------------------------------------------------------------------
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
        cp = job.get("checkpoint")
        d["next_pass"] = cp.get("next_pass") if cp else None
        if positions is not None:
            d["position"] = positions.get(job["id"])
        return d

    def jobs(self, states=None, limit=None, after=0) -> list[dict]:
        pos = self.spool.queue_position()
        return [self.public(j, pos) for j in self.spool.jobs(states, limit, after)]

    def cancel(self, job_id: int) -> dict:
        before = self.spool.get(job_id)
        keep = self.keeps_copy("cancelled")
        job = self.spool.cancel_waiting(job_id, keep_copy=keep)
        if job is None:                                # printing: stop it at the printer
            if not self.worker.cancel(job_id):
                # claimed but not started yet, or between copies: the worker checks this set
                self.worker._cancel.add(job_id)
            deadline = time.monotonic() + 10
            while time.monotonic() < deadline:
                job = self.spool.get(job_id)
                if job["state"] != "printing":
                    break
                time.sleep(0.05)
            return job
        self.hot_done(job, "cancelled", "cancelled by the operator")
        if before and before.get("spool_path") and not keep:
            try:
                os.unlink(before["spool_path"])
            except OSError:
                pass
        self.worker.notify()
        return job

    def hold(self, job_id: int) -> dict:
        return self.spool.hold(job_id)

    def release(self, job_id: int) -> dict:
        job = self.spool.release(job_id)
        self.worker.notify()
        return job

    def requeue(self, job_id: int) -> dict:
        """A failed or cancelled job back in the queue, to print afresh (docs/server.md,
        "Requeue"); refused, with the reason, for other states or a spool copy gone."""
        before = self.spool.get(job_id)
        if before is not None and before["state"] in ("failed", "cancelled"):
            self.worker.forget_cancel(job_id)      # a late cancel of the ended attempt
        job = self.spool.requeue(job_id)
        log.info("job %s requeued (attempt %s)", job_id, job["attempt"])
        self.worker.notify()
        return job

    def hot_done(self, job: dict, state: str, message: str) -> None:
        """A hot-folder job ended: its original goes to done/ or failed/ (with reason)."""
        hot = job.get("hot_path")
        if not hot or not self.hot:
            return
        src = Path(hot)
        if not src.exists():
            return
        with self.hot.lock:
            if state == "done":
                HotFolders.move(src, src.parent / "done")
            else:
                HotFolders.move(src, src.parent / "failed", f"job {job['id']} {state}: {message}")

    def status(self) -> dict:
        w = self.worker
        self.preset_source.get()                     # the status reports the file as it is now
        cur = dict(w.current) if w.current else None
        if cur is not None and w.job is not None:
            t = w.job.telemetry
            cur["telemetry"] = dict(carriage_counts=t.carriage_counts, paper_steps=t.paper_steps,
                                    fires_done=t.fires_done, head_temps_c=list(t.head_temps_c),
                                    fault=t.fault, retries=t.retries)
        return dict(server=dict(version=_version(), pid=os.getpid(), url=self.url,
                                started=self.started, device=self.config.device,
                                on_crash=self.config.on_crash,
                                hot_folder_root=str(self.config.hot_folder_root or "") or None),
                    queue=dict(paused=w.paused, reason=w.pause_reason, counts=self.spool.counts()),
                    presets=self.preset_source.info(),
                    printer=dict(state=w.printer_state, error=w.printer_error),
                    current=cur)

    def report_csv(self, job_id: int | None = None) -> str:
        return prints_csv(self.spool.prints(job_id))


CSV_COLUMNS = ["print_id", "job_id", "copy", "file", "source", "preset", "settings", "dpi",
               "passes_mode", "bidir", "dither", "started", "ended", "duration_s",
               "passes_total", "passes_printed", "width_dots", "height_rows", "area_m2",
               "drops_c", "drops_m", "drops_y", "drops_k",
               "ink_c_ml", "ink_m_ml", "ink_y_ml", "ink_k_ml", "ink_total_ml",
               "outcome", "message", "resumed", "recoveries", "retries", "attempt"]


def _iso(t: float) -> str:
    return time.strftime("%Y-%m-%dT%H:%M:%S", time.gmtime(t)) + f".{int(t % 1 * 1000):03d}Z"


def prints_csv(rows: list[dict]) -> str:
    out = io.StringIO()
    w = csv.writer(out, lineterminator="\n")
    w.writerow(CSV_COLUMNS)
    for r in rows:
        s = json.loads(r["settings"])
        ink = [r[f"ink_{c}_ml"] for c in COLORS]
        w.writerow([r["id"], r["job_id"], r["copy"], r["file"], r["source"], r["preset"] or "",
                    r["settings"], s.get("dpi", 300), s.get("passes", 1),
                    int(bool(s.get("bidir", False))), s.get("dither", "fs"),
                    _iso(r["started"]), _iso(r["ended"]), f"{r['duration_s']:.3f}",
                    r["passes_total"], r["passes_printed"], r["width_dots"], r["height_rows"],
                    f"{r['area_m2']:.10f}", *(r[f"drops_{c}"] for c in COLORS),
                    *(f"{v:.9f}" for v in ink), f"{sum(ink):.9f}",
                    r["outcome"], r["message"], r["resumed"], r["recoveries"], r["retries"],
                    r["attempt"]])
    return out.getvalue()


def _version() -> str:
    try:
        from .. import __version__
        return __version__
    except ImportError:
        return "?"


def serve(config: ServerConfig, ready=None) -> int:
    """Run the server until SIGTERM/SIGINT: a job printing then is paused at its next pass
    boundary and resumed by the next start."""
    server = PrintServer(config)
    server.start()
    done = threading.Event()

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
    while not done.wait(1.0):
        pass
    server.stop()
    return 0
