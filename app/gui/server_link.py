"""The GUI's connection to the print server (docs/gui.md, "One server"): the GUI is a
client of the server that owns the printers and the queue, like `submit`, CUPS and the hot
folders.

- `find_or_start(state_dir, device)`: the running server of that state directory, or a
  new one started as its own process (its own session: it outlives the GUI, so a GUI that
  crashes or is killed loses nothing and a printing job goes on).
- `ServerLink`: requests off the UI thread (a thread pool; one HTTP client per thread,
  http.client is not thread-safe), results back as queued signals; and the server's live
  state (`GET /v1/events`, server-sent events) read on a thread of its own and handed to
  the UI as signals, reconnecting when the stream drops.  No polling.
"""

from __future__ import annotations

import json
import logging
import subprocess
import sys
import threading
import time
from concurrent.futures import ThreadPoolExecutor
from pathlib import Path
from typing import Any

from PySide6.QtCore import QObject, Signal

from ..client import ApiError, Client

log = logging.getLogger("wideprint.gui")

START_TIMEOUT_S = 30.0


def _alive(state_dir: Path) -> Client | None:
    try:
        c = Client(state_dir, timeout=5.0)
        c.status()
        return c
    except ApiError:
        return None


def find_or_start(state_dir: Path, device: str = "emulator", media_dir: Path | None = None,
                  timeout: float = START_TIMEOUT_S) -> tuple[Client, subprocess.Popen | None]:
    """A client of the state directory's server; starts one (`wideprint serve`, port chosen
    by the system, the emulator's media in media_dir) when none answers.  Returns the client
    and the process started (None when the server was already running).  RuntimeError with
    the server's own words when it cannot start."""
    state_dir = Path(state_dir)
    c = _alive(state_dir)
    if c is not None:
        return c, None
    state_dir.mkdir(parents=True, exist_ok=True)
    logfile = state_dir / "server.log"
    cmd = [sys.executable, "-m", "wideprint.app.cli", "serve", "--state-dir", str(state_dir),
           "--device", device, "--port", "0"]
    if media_dir is not None:
        cmd += ["--media-dir", str(media_dir)]
    log.info("starting the print server: %s", " ".join(cmd))
    with open(logfile, "ab") as out:
        proc = subprocess.Popen(cmd, stdin=subprocess.DEVNULL, stdout=out, stderr=subprocess.STDOUT,
                                start_new_session=True, close_fds=True)
    deadline = time.monotonic() + timeout
    while time.monotonic() < deadline:
        c = _alive(state_dir)
        if c is not None:
            return c, proc
        if proc.poll() is not None:
            # another GUI may have started one at the same moment: ours lost the lock
            c = _alive(state_dir)
            if c is not None:
                return c, None
            tail = logfile.read_text(errors="replace").strip().splitlines()[-3:]
            raise RuntimeError(f"the print server did not start (exit {proc.returncode}): "
                               + (" ".join(tail) or "no message"))
        time.sleep(0.1)
    raise RuntimeError(f"the print server did not answer within {timeout:.0f} s (see {logfile})")


class _Call:
    """fn(client) on a pool thread; its result or failure goes back through the link's
    queued signal, so the callbacks run on the UI thread."""

    def __init__(self, link: "ServerLink", fn, done, failed):
        self.link, self.fn, self.done, self.failed = link, fn, done, failed

    def run(self) -> None:
        try:
            res = self.fn(self.link.client())
        except ApiError as exc:
            self.link._answer.emit(self.failed, str(exc))
            return
        except OSError as exc:                 # a file to upload: gone, unreadable
            self.link._answer.emit(self.failed,
                                   f"{exc.filename or ''}: {exc.strerror or exc}".lstrip(": "))
            return
        except Exception as exc:  # noqa: BLE001 - shown to the operator, never a dead thread
            log.exception("server request")
            self.link._answer.emit(self.failed, f"{type(exc).__name__}: {exc}")
            return
        self.link._answer.emit(self.done, res)


class ServerLink(QObject):
    printersChanged = Signal(list)       # GET /v1/events "printers"
    jobsChanged = Signal(list)           # GET /v1/events "jobs" (queued, held, printing)
    endedChanged = Signal(dict)          # GET /v1/events "ended" (a job ended: the history)
    connected = Signal(bool, str)        # the event stream is up / down (and why)
    requestFailed = Signal(str)
    _answer = Signal(object, object)     # callback, value: from pool threads to the UI thread

    def __init__(self, state_dir: Path, client: Client, parent=None):
        super().__init__(parent)
        self.state_dir = Path(state_dir)
        self._url = (client.host, client.port, client.token)
        self._local = threading.local()
        # Python threads, not QThreadPool: PySide6 runs each QRunnable under a new Python
        # thread state, so the thread-local client was a new Client (and connection) per
        # request, and their thread-state dicts piled up (bench/gui_soak.py: ~14 a second)
        self.pool = ThreadPoolExecutor(3, thread_name_prefix="wideprint-gui-call")
        # machine commands in the order the operator gave them (spit, then cap: never the
        # other way round because two pool threads raced)
        self.ordered = ThreadPoolExecutor(1, thread_name_prefix="wideprint-gui-ordered")
        self._stop = threading.Event()
        self._events: threading.Thread | None = None
        self._resp = None
        self._sock: Any = None             # the event stream's socket (stop() shuts it down)
        self._answer.connect(self._deliver)

    def _deliver(self, callback, value) -> None:
        if callback is not None:
            callback(value)

    def client(self) -> Client:
        """This thread's client (a fresh one per thread)."""
        c = getattr(self._local, "client", None)
        if c is None:
            host, port, token = self._url
            c = Client(self.state_dir, url=f"http://{host}:{port}", token=token)
            self._local.client = c
        return c

    def call(self, fn, done=None, failed=None, ordered: bool = False) -> None:
        """fn(client) on the pool; done(result) or failed(message) on the UI thread.
        `ordered`: one after the other, in the order of the calls (printer commands)."""
        try:
            (self.ordered if ordered else self.pool).submit(
                _Call(self, fn, done, failed or self.requestFailed.emit).run)
        except RuntimeError:              # stopped (the window closing): nothing more to ask
            pass

    def call_now(self, fn):
        """fn(client) on this thread (start-up, tests)."""
        return fn(self.client())

    # -- live state ------------------------------------------------------------------------
    def start_events(self) -> None:
        self._stop.clear()
        self._events = threading.Thread(target=self._read_events, name="wideprint-gui-events",
                                        daemon=True)
        self._events.start()

    def stop(self) -> None:
        self._stop.set()
        # the event stream's reader is blocked in readline: shut its socket down, which ends
        # that read at once (closing the response here instead waits for the reader's
        # buffer lock - up to the next event, ~15 s: the window took that long to close)
        sock = self._sock
        if sock is not None:
            import socket
            try:
                sock.shutdown(socket.SHUT_RDWR)
            except OSError:
                pass
        for ex in (self.pool, self.ordered):
            ex.shutdown(wait=False, cancel_futures=True)
        deadline = time.monotonic() + 3
        for ex in (self.pool, self.ordered):          # the calls running: 3 s at most
            for t in list(getattr(ex, "_threads", ())):
                t.join(max(0.0, deadline - time.monotonic()))

    def _rediscover(self) -> None:
        """The server restarted (another port): read server.json again."""
        try:
            c = Client(self.state_dir)
        except ApiError:
            return
        if (c.host, c.port, c.token) != self._url:
            self._url = (c.host, c.port, c.token)
            self._local = threading.local()

    def _read_events(self) -> None:
        import http.client
        backoff = 0.5
        while not self._stop.is_set():
            host, port, token = self._url
            conn = http.client.HTTPConnection(host, port, timeout=30)
            try:
                conn.request("GET", "/v1/events", headers={"Authorization": f"Bearer {token}"})
                resp = conn.getresponse()
                if resp.status != 200:
                    raise ConnectionError(f"HTTP {resp.status}")
                self._resp, self._sock = resp, conn.sock
                if self._stop.is_set():              # stop() came between: end now
                    break
                self.connected.emit(True, "")
                backoff = 0.5
                kind, data = None, []
                while not self._stop.is_set():
                    line = resp.readline()
                    if not line:
                        raise ConnectionError("the server closed the event stream")
                    line = line.decode("utf-8", "replace").rstrip("\r\n")
                    if line.startswith("event:"):
                        kind = line[6:].strip()
                    elif line.startswith("data:"):
                        data.append(line[5:].strip())
                    elif not line:
                        if kind and data:
                            self._dispatch(kind, "\n".join(data))
                        kind, data = None, []
            except (OSError, ConnectionError, http.client.HTTPException, AttributeError) as exc:
                # (AttributeError: http.client when stop() closed the response under readline)
                if self._stop.is_set():
                    break
                self.connected.emit(False, f"lost the print server ({exc}); reconnecting")
                self._stop.wait(backoff)
                backoff = min(backoff * 2, 5.0)
                self._rediscover()
            finally:
                self._resp, self._sock = None, None
                conn.close()

    def _dispatch(self, kind: str, data: str) -> None:
        try:
            value = json.loads(data)
        except ValueError:
            log.warning("a bad event from the server: %.80s", data)
            return
        if kind == "printers":
            self.printersChanged.emit(value)
        elif kind == "jobs":
            self.jobsChanged.emit(value)
        elif kind == "ended":
            self.endedChanged.emit(value)
