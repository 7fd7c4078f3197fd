"""The print server and the standalone printer as the tests start them, one way each.

- **In the test's process** (`inprocess_server`): a `PrintServer` on the in-process emulator,
  for the API, hot-folder, accounting and auth tests: no interpreter to start, and the test
  can look at the server's objects.
- **As its own process** (`ServerProcess`, `start_server`): `wideprint serve`, for what only
  a process shows: kill -9 and the crash points, the command line, CUPS's backend, the GUI.
  Ready when it prints its `wideprint serve: http://...` line; `stop()` sends SIGTERM and
  returns what it wrote on stderr (the tests look for tracebacks there).
- **The standalone printer** (`start_emulator`): `wideprint emulator`, ready when it prints
  its `device: ...` spec.

tests/conftest.py turns these into fixtures (`print_server`, `server_process`) that stop
whatever they started."""

from __future__ import annotations

import http.client
import json
import os
import select
import signal
import subprocess
import sys
import time
from pathlib import Path

from wideprint.app.client import Client

PY = sys.executable
SERVE = [PY, "-m", "wideprint.app.cli", "serve"]
CLI = [PY, "-m", "wideprint.app.cli"]
EMULATOR = CLI + ["emulator"]
READY = "wideprint serve: http://127.0.0.1:"


def readline(proc: subprocess.Popen, timeout: float) -> str:
    """The process's next line of stdout, or an AssertionError with its stderr (the process
    killed) when none comes within `timeout` seconds."""
    ready, _, _ = select.select([proc.stdout], [], [], timeout)
    if not ready:
        proc.kill()
        raise AssertionError("no output from " + " ".join(map(str, proc.args)) + "\n"
                             + proc.stderr.read())
    return proc.stdout.readline()


def stop(proc: subprocess.Popen, sig: int = signal.SIGTERM) -> str:
    """Stop a process started with pipes (SIGTERM, then SIGKILL after 30 s): its stderr."""
    if proc.poll() is None:
        proc.send_signal(sig)
    try:
        _, err = proc.communicate(timeout=30)
    except subprocess.TimeoutExpired:
        proc.kill()
        _, err = proc.communicate()
    return err or ""


def wait_for(cond, timeout: float = 60.0, poll: float = 0.02, what: str = "condition"):
    """`cond()`'s first true value, polled every `poll` s; AssertionError after `timeout` s."""
    deadline = time.monotonic() + timeout
    while time.monotonic() < deadline:
        v = cond()
        if v:
            return v
        time.sleep(poll)
    raise AssertionError(f"timed out waiting for {what}")


# -- in the test's process ------------------------------------------------------------------------
def server_config(root: Path, media: bool = True, hot: bool = True, **config):
    """A ServerConfig on the in-process emulator under `root`: state in ROOT/state, the
    printed media in ROOT/media and hot folders under ROOT/hot unless `media` / `hot` are
    false, an ephemeral port; `config` sets any other field."""
    from wideprint.app.server import ServerConfig
    fields = dict(device="emulator", state_dir=root / "state", port=0,
                  media_dir=root / "media" if media else None,
                  hot_folder_root=root / "hot" if hot else None)
    fields.update(config)
    return ServerConfig(**fields)


def inprocess_server(root: Path, start: bool = True, **config):
    """A PrintServer (`server_config(root, **config)`), started unless `start` is false; its
    `root` attribute is `root`.  The caller stops it (`server.stop(timeout=5)`), or uses
    the `print_server` fixture, which does."""
    from wideprint.app.server import PrintServer
    server = PrintServer(server_config(Path(root), **config))
    server.root = Path(root)
    if start:
        server.start()
    return server


def raw_request(srv, method, path, body=b"", headers=None, token="default"):
    """One HTTP request to an in-process server's API, with its token unless `token` says
    otherwise (None: no Authorization header): (status, JSON body or bytes)."""
    conn = http.client.HTTPConnection("127.0.0.1", srv.port, timeout=30)
    hdrs = dict(headers or {})
    if token == "default":
        token = srv.token
    if token is not None:
        hdrs["Authorization"] = f"Bearer {token}"
    conn.request(method, path, body=body, headers=hdrs)
    r = conn.getresponse()
    data = r.read()
    conn.close()
    return r.status, json.loads(data) if data.startswith(b"{") else data


# -- as its own process ---------------------------------------------------------------------------
class ServerProcess:
    """`wideprint serve --state-dir STATE --port 0 ARGS...` as its own process (`device`
    None: no --device, the server's default).  `crash` sets WIDEPRINT_CRASH_AT (the named
    crash points, app/server/crashpoints.py); otherwise it is cleared.  With `log`, stdout and
    stderr go to that file instead of pipes (a server printing many jobs for a long test
    cannot then block on a full pipe) and `stop()` returns the file's text."""

    def __init__(self, state: Path, *args: str, device: str | None = "emulator",
                 media_dir: Path | None = None, crash: str | None = None,
                 log: Path | None = None, timeout: float = 60):
        self.state = Path(state)
        self.log = Path(log) if log is not None else None
        env = dict(os.environ)
        env.pop("WIDEPRINT_CRASH_AT", None)
        if crash:
            env["WIDEPRINT_CRASH_AT"] = crash
        cmd = SERVE + (["--device", device] if device else []) + \
            ["--state-dir", str(self.state), "--port", "0", *args]
        if media_dir is not None:
            cmd += ["--media-dir", str(media_dir)]
        if self.log is None:
            self.proc = subprocess.Popen(cmd, stdout=subprocess.PIPE, stderr=subprocess.PIPE,
                                         text=True, env=env)
            line = readline(self.proc, timeout)
            assert line.startswith(READY), line + self.proc.stderr.read()
        else:
            with open(self.log, "ab") as out:
                self.proc = subprocess.Popen(cmd, stdout=out, stderr=subprocess.STDOUT, env=env)
            line = self._logged_line(timeout)
        self.url = line.split()[2]
        self.client = Client(self.state, url=self.url)

    def _logged_line(self, timeout: float) -> str:
        deadline = time.monotonic() + timeout
        while time.monotonic() < deadline:
            for line in self.log.read_text(errors="replace").splitlines():
                if line.startswith(READY):
                    return line
            if self.proc.poll() is not None:
                break
            time.sleep(0.05)
        if self.proc.poll() is None:
            self.proc.kill()
        raise AssertionError("the server did not start:\n" + self.log.read_text(errors="replace"))

    def cli(self, *args: str, timeout: float = 120) -> str:
        """`wideprint COMMAND --state-dir STATE ARGS...` against this server: its stdout (the
        command must succeed)."""
        r = subprocess.run(CLI + [args[0], "--state-dir", str(self.state), *args[1:]],
                           capture_output=True, text=True, timeout=timeout)
        assert r.returncode == 0, r.stderr
        return r.stdout

    def stop(self, sig: int = signal.SIGTERM) -> str:
        """Stop it (SIGTERM unless `sig`; SIGKILL after 30 s): its stderr, or its log."""
        self.client.close()
        if self.log is None:
            return stop(self.proc, sig)
        if self.proc.poll() is None:
            self.proc.send_signal(sig)
            try:
                self.proc.wait(30)
            except subprocess.TimeoutExpired:
                self.proc.kill()
                self.proc.wait()
        return self.log.read_text(errors="replace")


def start_server(state, device="emulator", *args: str, media_dir=None, crash=None):
    """`ServerProcess(...)` as (process, client): the form the kill -9, crash-point and
    disk-full tests use; stop it with `stop(process)`."""
    s = ServerProcess(state, *args, device=device, media_dir=media_dir, crash=crash)
    return s.proc, s.client


# -- the standalone printer -----------------------------------------------------------------------
def start_emulator(tmp_path: Path, *extra: str, event_log: Path | None = None,
                   timeout: float = 60):
    """`wideprint emulator` writing its media to TMP/media-{job}.tif: (process, device spec)."""
    cmd = EMULATOR + ["--media-out", str(Path(tmp_path) / "media-{job}.tif"), *extra]
    if event_log is not None:
        cmd += ["--event-log", str(event_log)]
    proc = subprocess.Popen(cmd, stdout=subprocess.PIPE, stderr=subprocess.PIPE, text=True)
    line = readline(proc, timeout)
    assert line.startswith("device: "), proc.stderr.read()
    return proc, line.split(" ", 1)[1].strip()
