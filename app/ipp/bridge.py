"""The bridge between the IPP Everywhere Printer Application (app/ipp/wideprint-ipp.c, built
on PAPPL) and the print server (docs/ipp.md).

`IppBridge` is an ordinary client of the server's HTTP API (`app.client.Client`, the
token of the state directory): it writes the Printer Application's configuration from the
server's printers and their printer profiles, starts the program, and then speaks the line
protocol of docs/ipp.md ("The bridge protocol") on its stdin/stdout:

- a `submit` line (a document PAPPL spooled) becomes a job in the server's queue with the
  original file, its IPP options turned into wideprint settings (`ipp_job_fields`);
- every printer's state (`GET /v1/printers`) goes to the program as `printer` lines, every
  followed job's state as `job` lines, whenever they change (polled 4 times a second);
- a `cancel` line cancels the wideprint job.

`wideprint serve --ipp` starts one beside the server (app/cli/serve.py).
"""

from __future__ import annotations

import logging
import os
import re
import shutil
import subprocess
import threading
import time
import uuid
from pathlib import Path

log = logging.getLogger("wideprint.ipp")

DEFAULT_IPP_PORT = 8632
BINARY_NAME = "wideprint-ipp"
#: print-quality -> the server's preset (docs/ipp.md, "Print quality"): draft, normal, high
QUALITY_PRESETS = {"draft": "banner", "normal": "default", "high": "photo"}
#: orientation-requested (RFC 8011 5.2.10) -> the RIP's rotation, degrees clockwise
ORIENTATION_ROTATE = {3: 0, 4: 270, 5: 90, 6: 180, 7: 0}
#: the spool copy's suffix for each document format (the server detects by content anyway)
FORMAT_SUFFIX = {"image/jpeg": ".jpg", "image/png": ".png", "image/tiff": ".tif",
                 "application/pdf": ".pdf", "application/postscript": ".ps"}
POLL_S = 0.25
FINAL = ("done", "failed", "cancelled")


def find_binary() -> Path | None:
    """The Printer Application: $WIDEPRINT_IPP_BINARY, else the one `make` builds next to
    this file (app/ipp/wideprint-ipp), else `wideprint-ipp` on PATH."""
    env = os.environ.get("WIDEPRINT_IPP_BINARY")
    if env:
        return Path(env) if Path(env).is_file() else None
    here = Path(__file__).with_name(BINARY_NAME)
    if here.is_file() and os.access(here, os.X_OK):
        return here
    found = shutil.which(BINARY_NAME)
    return Path(found) if found else None


def _field(text) -> str:
    """A protocol field: no tabs or line ends."""
    return " ".join(str(text or "").split())


def web_url(host: str | None, port: int | None) -> str:
    """The shop's web page (docs/web.md) for printer-more-info: the server's API address;
    a server listening on every address is reached on the host the IPP client used ("*")."""
    if not host or host in ("0.0.0.0", "::", "*"):
        host = "*"
    elif ":" in host:
        host = f"[{host}]"
    return f"http://{host}:{port}/"


def media_line(printer: dict, profile_width_mm: float, media_types: tuple = ()) -> str:
    """The paper loaded on a printer, for its IPP media attributes (docs/ipp.md "The paper"):
    `media NAME WIDTH_MM LENGTH_MM ROLL_MEDIA TYPES`.  The width: the tracked roll's, else
    the printer's last measurement (its edge sensors), else the profile's paper; the length:
    what is left of the tracked roll, 0 when nobody knows it; the roll's media entry (empty
    when none is named) and the media library's entries, comma separated: the printer's
    media-type values (docs/ipp.md "Media")."""
    roll = printer.get("roll") or {}
    width = roll.get("width_mm") or printer.get("paper_mm") or profile_width_mm
    left = roll.get("remaining_mm")
    length = int(left) if isinstance(left, (int, float)) and left > 0 else 0
    on_roll = roll.get("media") if roll.get("media") in media_types else ""
    return "\t".join(["media", _field(printer["name"]), str(int(round(width))), str(length),
                      on_roll or "", ",".join(media_types)])


def ipp_media_types(library: Path | None = None) -> tuple[str, ...]:
    """The media library's entries that can be IPP media-type keywords (lower-case letters,
    digits, '-', '_', '.'; RFC 8011 keyword syntax), at most 15 (PAPPL's list, "stationery"
    first)."""
    from ..medialib import list_media
    names = [m.name for m in list_media(library)]
    return tuple(n for n in names if re.fullmatch(r"[a-z][a-z0-9._-]*", n))[:15]


def job_name(ipp_name: str, fmt: str) -> str:
    """A plain file name for the queue (docs/server.md, "Safety rules") from an IPP job-name,
    with the format's suffix."""
    name = os.path.basename((ipp_name or "").replace("\\", "/")).strip()
    name = "".join(ch for ch in name if ch.isprintable()).lstrip(".") or "ipp-job"
    suffix = FORMAT_SUFFIX.get(fmt, "")
    if suffix and not name.lower().endswith(suffix):
        stem = name.rsplit(".", 1)[0] if name.rsplit(".", 1)[-1].lower() in \
            ("jpg", "jpeg", "png", "tif", "tiff", "pdf", "ps") else name
        name = stem + suffix
    return name.encode("utf-8")[:240].decode("utf-8", "ignore") or "ipp-job"


def requesting_user(user: str) -> str:
    """An IPP requesting-user-name as the server takes it (X-Wideprint-User): without
    control, invisible or reordering characters, at most 100 characters; "anonymous" when
    nothing is left."""
    from ..safe_text import unsafe
    return "".join(ch for ch in user or "" if not unsafe(ch)).strip()[:100] or "anonymous"


def ipp_job_fields(*, copies: int, quality: str, xdpi: int, orientation: int, intent: str,
                   presets, dpi_modes, media_type: str = "", media_types: tuple = ()) -> dict:
    """The wideprint job description fields for a job's IPP options (docs/ipp.md, "What an
    IPP job's options become"): copies; print-quality -> a preset (when the server has it);
    printer-resolution (when the client chose one) -> dpi; orientation-requested -> rotate;
    print-rendering-intent (but auto) -> intent."""
    from ...rip.settings import INTENTS
    fields: dict = {"copies": copies}
    preset = QUALITY_PRESETS.get(quality)
    if preset in presets:
        fields["preset"] = preset
    settings: dict = {}
    if xdpi:
        if xdpi not in dpi_modes:
            raise ValueError(f"printer-resolution {xdpi} dpi is not one of the printer's "
                             f"{', '.join(map(str, dpi_modes))}")
        settings["dpi"] = xdpi
    if intent != "auto":
        if intent not in INTENTS:
            raise ValueError(f"print-rendering-intent {intent!r} is not one of {', '.join(INTENTS)}")
        settings["intent"] = intent
    rotate = ORIENTATION_ROTATE.get(orientation, 0)
    if rotate:
        settings["placement"] = {"rotate": rotate}
    if media_type in media_types:              # media-col media-type: a media entry
        settings["media"] = media_type
    if settings:
        fields["settings"] = settings
    return fields


def printer_line(p: dict) -> str:
    """The `printer` line for one printer of `GET /v1/printers`: state, paused, IPP
    printer-state-reasons and the state in plain words."""
    fault = p.get("fault") or ""
    reasons = []
    if fault:
        reasons.append("media-empty" if "paper out" in fault else "other")
    if p["state"] == "offline":
        reasons.append("offline")
    # the roll running low (docs/ipp.md "The roll running low"): a warning, the printer goes on
    warnings = [w for w in p.get("warnings") or [] if w.get("kind") == "media-low"]
    if warnings:
        reasons.append("media-low-warning")
    if p.get("paused") and p.get("reason"):
        message = p["reason"]
    elif p.get("error"):
        message = f"{p['state']}: {p['error']}"
    elif warnings:
        message = warnings[0]["message"]
    else:
        message = ""
    return "\t".join(["printer", p["name"], p["state"], "1" if p.get("paused") else "0",
                      ",".join(reasons) or "none", _field(message)])


def job_line(tag: int, job: dict) -> str:
    message = job.get("message") or job.get("fault") or ""
    return "\t".join(["job", str(tag), str(job["id"]), job["state"], str(job["copies_done"]),
                      str(job["copies"]), str(job.get("strokes_done") or 0),
                      str(job.get("strokes_total") or 0), _field(message)])


class IppBridge:
    """Runs the Printer Application for the server of `state_dir` (or `url` + `token`)."""

    def __init__(self, state_dir: str | os.PathLike, *, listen: str = "localhost",
                 port: int = DEFAULT_IPP_PORT, auth: str = "token", url: str | None = None,
                 token: str | None = None, binary: str | os.PathLike | None = None,
                 log_level: str = "info"):
        if auth not in ("token", "none"):
            raise ValueError("auth must be token or none")
        self.state_dir = Path(state_dir).resolve()
        self.listen, self.port, self.auth = listen, port, auth
        self.url, self.token = url, token
        self.binary = Path(binary) if binary else find_binary()
        self.log_level = log_level
        self.dir = self.state_dir / "ipp"
        self.uris: dict[str, str] = {}
        self.proc: subprocess.Popen | None = None
        self._send_lock = threading.Lock()
        self._tracks: dict[int, int] = {}          # tag -> wideprint job id
        self._tracks_lock = threading.Lock()
        self._stop = threading.Event()
        self._threads: list[threading.Thread] = []
        self._dpi: dict[str, tuple] = {}
        self._paper: dict[str, float] = {}         # each printer's profile paper width

    def _client(self, user: str | None = None):
        from ..client import Client
        return Client(self.state_dir, url=self.url, token=self.token, timeout=30, user=user)

    # -- start and stop -------------------------------------------------------------------------
    def config_text(self, client) -> str:
        """The Printer Application's configuration (docs/ipp.md, "The configuration
        file"): where to listen, the token, and each printer from its printer profile."""
        from ...rip.profile import load_profile
        from ...rip.settings import MAX_SIDE, SETTINGS
        default_dpi = next(s.default for s in SETTINGS if s.name == "dpi")
        from ... import __version__
        lines = [f"listen {self.listen}", f"port {self.port}", f"spool {self.dir / 'spool'}",
                 f"log {self.dir / 'wideprint-ipp.log'}", f"loglevel {self.log_level}",
                 f"auth {self.auth}", "name wideprint", f"version {_field(__version__)}",
                 f"web-url {web_url(client.host, client.port)}"]
        if self.auth == "token":
            lines.append(f"token {client.token}")
        for p in client.printers():
            prof = load_profile(p["profile"])
            self._dpi[p["name"]] = tuple(prof.dpi_modes)
            self._paper[p["name"]] = float(prof.paper.default_width_mm)
            max_len = int(MAX_SIDE * prof.row_um / 1000 // 1000 * 1000)   # whole metres
            lines += [f"printer {p['name']}",
                      f"make-and-model {_field(prof.printer.name)}",
                      f"roll-width-mm {int(prof.paper.default_width_mm)}",
                      f"print-width-mm {int(prof.printer.print_width_mm)}",
                      f"margin-mm {prof.paper.margin_mm:g}",
                      f"max-length-mm {max_len}",
                      "dpi " + " ".join(map(str, prof.dpi_modes)),
                      f"default-dpi {default_dpi if default_dpi in prof.dpi_modes else prof.dpi_modes[0]}"]
        return "\n".join(lines) + "\n"

    def start(self, timeout: float = 15.0) -> dict[str, str]:
        """Start the Printer Application; returns {printer name: ipp:// URI}.  RuntimeError
        (with the program's own words) when it cannot start."""
        if self.binary is None:
            raise RuntimeError(f"the Printer Application {BINARY_NAME} is not built: install "
                               f"libpappl-dev and run `make install` (docs/ipp.md)")
        self.dir.mkdir(mode=0o700, exist_ok=True)
        client = self._client()
        conf = self.dir / "wideprint-ipp.conf"
        fd = os.open(conf, os.O_WRONLY | os.O_CREAT | os.O_TRUNC, 0o600)   # holds the token
        with os.fdopen(fd, "w") as f:
            f.write(self.config_text(client))
        client.close()
        self.proc = subprocess.Popen([str(self.binary), str(conf)], stdin=subprocess.PIPE,
                                     stdout=subprocess.PIPE, stderr=subprocess.PIPE,
                                     text=True, bufsize=1)
        got: dict = {}
        ready = threading.Event()

        def first_lines():
            for line in self.proc.stdout:
                f = line.rstrip("\n").split("\t")
                if f[0] == "uri" and len(f) == 3:
                    got[f[1]] = f[2]
                elif f[0] == "ready":
                    break
            ready.set()
        t = threading.Thread(target=first_lines, daemon=True)
        t.start()
        if not ready.wait(timeout) or self.proc.poll() is not None:
            self.proc.kill()
            err = self.proc.stderr.read().strip()
            raise RuntimeError(f"{BINARY_NAME} did not start: {err or 'no answer'}")
        self.uris = got
        for target, name in ((self._read_loop, "ipp-reader"), (self._poll_loop, "ipp-poller"),
                             (self._stderr_loop, "ipp-stderr")):
            th = threading.Thread(target=target, name=name, daemon=True)
            th.start()
            self._threads.append(th)
        return dict(got)

    def stop(self, timeout: float = 5.0) -> None:
        self._stop.set()
        if self.proc is None:
            return
        try:
            self._send("quit")
            self.proc.stdin.close()
        except (OSError, ValueError):
            pass
        try:
            self.proc.wait(timeout)
        except subprocess.TimeoutExpired:
            self.proc.terminate()
            try:
                self.proc.wait(timeout)
            except subprocess.TimeoutExpired:
                self.proc.kill()
                self.proc.wait()
        for th in self._threads:
            th.join(timeout)

    # -- the line protocol ------------------------------------------------------------------------
    def _send(self, line: str) -> None:
        with self._send_lock:
            self.proc.stdin.write(line + "\n")
            self.proc.stdin.flush()

    def _stderr_loop(self) -> None:
        for line in self.proc.stderr:
            log.warning("%s: %s", BINARY_NAME, line.rstrip())

    def _read_loop(self) -> None:
        for line in self.proc.stdout:
            f = line.rstrip("\n").split("\t")
            try:
                if f[0] == "submit" and len(f) == 13:
                    threading.Thread(target=self._submit, args=(f[1:],), daemon=True,
                                     name=f"ipp-submit-{f[1]}").start()
                elif f[0] == "cancel" and len(f) == 2:
                    threading.Thread(target=self._cancel, args=(int(f[1]),), daemon=True).start()
                elif f[0] == "identify" and len(f) == 3:
                    log.warning("IPP Identify-Printer for printer %s%s", f[1],
                                f": {f[2]}" if f[2] else "")
                elif f[0] == "forget" and len(f) == 2:
                    with self._tracks_lock:
                        self._tracks.pop(int(f[1]), None)
                else:
                    log.warning("%s said %r", BINARY_NAME, line)
            except ValueError:
                log.warning("%s said %r", BINARY_NAME, line)
        if not self._stop.is_set():
            log.error("%s stopped (exit code %s)", BINARY_NAME, self.proc.wait())

    def _media_types(self) -> tuple[str, ...]:
        """The server's media library as IPP media-type values (STATE/media, shipped)."""
        from ..medialib import user_dir
        return ipp_media_types(user_dir(self.state_dir))

    def _submit(self, f: list[str]) -> None:
        tag, printer, fmt, path, copies, quality, xdpi, orientation, intent, user, name = f[:11]
        media_type = f[11] if len(f) > 11 else ""
        from ..client import ApiError
        # the job belongs to the IPP requesting-user-name (docs/server.md "Users and roles")
        client = self._client(user=requesting_user(user))
        try:
            fields = ipp_job_fields(copies=int(copies), quality=quality, xdpi=int(xdpi),
                                    orientation=int(orientation), intent=intent,
                                    presets=client.presets()["presets"],
                                    dpi_modes=self._dpi.get(printer, ()),
                                    media_type=media_type, media_types=self._media_types())
            job = client.submit(path, name=job_name(name, fmt), printer=printer,
                                client=("ipp:" + (user or "anonymous"))[:100],
                                key=f"ipp-{uuid.uuid4()}", **fields)["job"]
        except (ApiError, ValueError, OSError) as exc:
            log.warning("IPP job (%s): not queued: %s", name, exc)
            self._send("\t".join(["job", tag, "0", "error", "0", "0", "0", "0", _field(exc)]))
            return
        finally:
            client.close()
        log.info("IPP job %r for %s: wideprint job %s", name, printer, job["id"])
        with self._tracks_lock:
            self._tracks[int(tag)] = job["id"]
        self._send(job_line(int(tag), job))

    def _cancel(self, tag: int) -> None:
        from ..client import ApiError
        with self._tracks_lock:
            job_id = self._tracks.get(tag)
        if job_id is None:
            return
        client = self._client()
        try:
            client.action(job_id, "cancel")
        except ApiError as exc:
            log.warning("cancel of job %s: %s", job_id, exc)
        finally:
            client.close()

    def _poll_loop(self) -> None:
        """The server's printer and job states to the program, when they change."""
        from ..client import ApiError
        client = self._client()
        sent_printers: dict[tuple, str] = {}
        sent_jobs: dict[int, str] = {}
        while not self._stop.wait(POLL_S):
            try:
                for p in client.printers():
                    for line in (printer_line(p),
                                 media_line(p, self._paper.get(p["name"], 0.0),
                                            self._media_types())):
                        key = (p["name"], line.split("\t", 1)[0])
                        if sent_printers.get(key) != line:
                            self._send(line)
                            sent_printers[key] = line
                with self._tracks_lock:
                    tracks = dict(self._tracks)
                for tag, job_id in tracks.items():
                    line = job_line(tag, client.job(job_id))
                    if sent_jobs.get(tag) != line:
                        self._send(line)
                        sent_jobs[tag] = line
                for tag in set(sent_jobs) - set(tracks):
                    del sent_jobs[tag]
            except ApiError as exc:
                log.debug("poll: %s", exc)
                time.sleep(1.0)
            except (OSError, ValueError):
                if self.proc.poll() is not None:
                    break
        client.close()
