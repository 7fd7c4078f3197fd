"""The one HTTP client of the print server's local API (docs/server.md): `Client` finds the
server (STATE/server.json or $WIDEPRINT_URL) and a token (`find_token`), says who it acts
for, and maps the API's endpoints to methods; `ApiError` is every refusal and every server
that cannot be reached.

Its users - the commands (app/cli/: serve, submit, queue, ... through app/cli/remote.py),
the GUI (app/gui/server_link.py), the IPP bridge (app/ipp/bridge.py), the pytest plugin -
import it from here.  Light: the standard library only, http.client loaded on the first
request, so building the command line stays quick."""

from __future__ import annotations

import json
import os
import time
from pathlib import Path
from typing import TYPE_CHECKING
from urllib.parse import urlsplit

if TYPE_CHECKING:
    import http.client


class ApiError(Exception):
    def __init__(self, status: int, message: str):
        super().__init__(message)
        self.status = status


def user_token_file() -> Path:
    """Where a user keeps the token the operator made for it (`wideprint users add`):
    $XDG_CONFIG_HOME/wideprint/token, else ~/.config/wideprint/token."""
    base = os.environ.get("XDG_CONFIG_HOME") or str(Path.home() / ".config")
    return Path(base) / "wideprint" / "token"


def _read_client_token(path: Path) -> str:
    """A token file as a client reads it: ApiError naming the file for one that is not
    text or is empty (OSError passes for the caller to try the next file)."""
    data = path.read_bytes()[:65536]
    try:
        token = data.decode("utf-8").strip()
    except UnicodeDecodeError:
        raise ApiError(0, f"the token file {path} is not text (binary or not UTF-8): ask the "
                          f"operator for your token") from None
    if not token or any(ch.isspace() or not ch.isprintable() for ch in token):
        raise ApiError(0, f"the token file {path} is "
                          + ("empty" if not token else "not a token (blanks or control characters)"))
    return token


def find_token(state_dir: Path) -> str:
    """The client's token: the file $WIDEPRINT_TOKEN_FILE names, else the server's own
    (STATE/token: the operator's), else the user's (`user_token_file()`)."""
    from .server.config import TOKEN_FILE
    env = os.environ.get("WIDEPRINT_TOKEN_FILE")
    paths = [Path(env)] if env else [state_dir / TOKEN_FILE, user_token_file()]
    problems = []
    for path in paths:
        try:
            return _read_client_token(path)
        except FileNotFoundError:
            problems.append(f"no {path}")
        except OSError as exc:
            problems.append(f"{path}: {exc.strerror}")
    raise ApiError(0, "cannot read an API token: " + "; ".join(problems))


def read_server_file(state_dir: Path) -> str:
    """The running server's URL from STATE/server.json.  ApiError (status 0) saying which:
    no file (no server running), or a file that cannot be read or is not what a server
    writes — then a server may well be running, and the file is named."""
    from .server.config import SERVER_FILE
    path = state_dir / SERVER_FILE
    try:
        raw = path.read_bytes()
    except FileNotFoundError:
        raise ApiError(0, f"no wideprint server running for {state_dir} (no {SERVER_FILE}; "
                          f"start `wideprint serve`)") from None
    except OSError as exc:
        raise ApiError(0, f"{path} cannot be read ({exc.strerror})") from None
    try:
        url = json.loads(raw.decode("utf-8"))["url"]
        if not isinstance(url, str) or not url.startswith("http://") or not urlsplit(url).port:
            raise ValueError(f"url {str(url)[:60]!r}")
    except (ValueError, KeyError, TypeError) as exc:
        why = "no url" if isinstance(exc, (KeyError, TypeError)) else str(exc)[:80]
        raise ApiError(0, f"{path} is unreadable ({why}): it is not what a running server "
                          f"writes; if a server runs, restart it (it writes the file anew), "
                          f"else delete the file") from None
    return url


def _os_user() -> str | None:
    try:
        import getpass
        return getpass.getuser()
    except (ImportError, KeyError, OSError):
        return None


class Client:
    """A client of the local API: finds the server (server.json) and its token in the
    state directory (or the user's own token, `find_token`), and says who it acts for
    (`user`, default the OS user: header `X-Wideprint-User`, docs/server.md "Users and
    roles")."""

    def __init__(self, state_dir: str | os.PathLike | None = None, url: str | None = None,
                 token: str | None = None, timeout: float = 60.0, user: str | None = None):
        from .server.config import default_state_dir
        self.state_dir = Path(state_dir) if state_dir else default_state_dir()
        if url is None:
            # a user whose account cannot read the state directory (0700) is told the URL
            url = os.environ.get("WIDEPRINT_URL") or read_server_file(self.state_dir)
        if token is None:
            token = find_token(self.state_dir)
        u = urlsplit(url)
        self.host, self.port = u.hostname, u.port
        self.token, self.timeout = token, timeout
        self.user = user if user is not None else _os_user()
        self._conn: http.client.HTTPConnection | None = None

    def _connection(self) -> http.client.HTTPConnection:
        import http.client                  # here: the CLI's --help does not need it
        if self._conn is None:
            self._conn = http.client.HTTPConnection(self.host, self.port, timeout=self.timeout)
        return self._conn

    def close(self) -> None:
        if self._conn is not None:
            self._conn.close()
            self._conn = None

    def request(self, method: str, path: str, body=None, headers: dict | None = None,
                raw: bool = False, binary: bool = False):
        hdrs = {"Authorization": f"Bearer {self.token}"}
        if self.user:
            from urllib.parse import quote
            hdrs["X-Wideprint-User"] = quote(self.user, safe="@._+-")
        hdrs.update(headers or {})
        if isinstance(body, (dict, list)):
            body = json.dumps(body).encode()
            hdrs["Content-Type"] = "application/json"
        import http.client
        if hasattr(body, "read"):
            # an upload cannot be sent twice: never on a kept-alive connection the server
            # may have closed meanwhile (a long-lived client such as the GUI)
            self.close()
        for attempt in (0, 1):
            conn = self._connection()
            try:
                try:
                    conn.request(method, path, body=body, headers=hdrs)
                except (BrokenPipeError, ConnectionResetError):
                    # the server refused the upload before reading it (401, 413, 400) and
                    # closed: its answer is usually waiting in the socket
                    if not hasattr(body, "read") and not isinstance(body, bytes):
                        raise
                resp = conn.getresponse()
                data = resp.read()
                break
            except (ConnectionError, http.client.HTTPException, OSError) as exc:
                self.close()
                # a kept-alive connection the server closed: one retry for requests that
                # cannot do harm twice (uploads carry an idempotency key)
                if attempt or hasattr(body, "read"):
                    raise ApiError(0, f"cannot reach the wideprint server at "
                                   f"{self.host}:{self.port}: {exc}") from None
        if resp.getheader("Connection", "").lower() == "close":
            self.close()
        if binary and resp.status < 400:
            return data
        if raw and resp.status < 400:
            return data.decode()
        try:
            obj = json.loads(data) if data else {}
        except ValueError:
            obj = {"error": data.decode(errors="replace")}
        if resp.status >= 400:
            raise ApiError(resp.status, obj.get("error", f"HTTP {resp.status}"))
        return obj

    # endpoints
    def submit(self, path: str | os.PathLike, name: str | None = None, **fields) -> dict:
        """Upload a file as a job: fields are preset, copies, priority, hold, key, client,
        settings ({dpi, passes, bidir, dither, intent, ink_limit, input_icc, output_icc})."""
        path = Path(path)
        desc = {"name": name or path.name}
        desc.update({k: v for k, v in fields.items() if v is not None})
        size = path.stat().st_size
        with open(path, "rb") as f:
            return self.request("POST", "/v1/jobs", body=f, headers={
                "X-Wideprint-Job": json.dumps(desc), "Content-Length": str(size),
                "Content-Type": "application/octet-stream"})

    def submit_bytes(self, data: bytes, name: str, **fields) -> dict:
        desc = {"name": name}
        desc.update({k: v for k, v in fields.items() if v is not None})
        return self.request("POST", "/v1/jobs", body=data, headers={
            "X-Wideprint-Job": json.dumps(desc), "Content-Type": "application/octet-stream"})

    def jobs(self, states: str | None = None) -> list[dict]:
        return self.request("GET", "/v1/jobs" + (f"?state={states}" if states else ""))["jobs"]

    def job(self, job_id: int) -> dict:
        return self.request("GET", f"/v1/jobs/{job_id}")["job"]

    def action(self, job_id: int, what: str) -> dict:
        return self.request("POST", f"/v1/jobs/{job_id}/{what}")["job"]

    def cancel(self, job_id: int, timeout: float = 60.0, poll: float = 0.2) -> dict:
        """Cancel a job and follow it to its end: the job as it ended (`cancelled`), or as
        it still is after `timeout` (`printing`: the printer has not stopped yet).  ApiError
        when the server refuses (an ended job, someone else's job, a full disk)."""
        r = self.request("POST", f"/v1/jobs/{job_id}/cancel")
        job = r["job"]
        if not r.get("cancelling"):
            return job
        deadline = time.monotonic() + timeout
        while job["state"] == "printing" and time.monotonic() < deadline:
            time.sleep(poll)
            job = self.job(job_id)
        return job

    def status(self) -> dict:
        return self.request("GET", "/v1/status")

    def pause_queue(self, paused: bool) -> dict:
        return self.request("POST", "/v1/queue", body={"paused": paused})

    def presets(self) -> dict:
        """{presets, file, loaded, error}: the presets in use (error: the file could not
        be re-read)."""
        return self.request("GET", "/v1/presets")

    def reload_presets(self) -> dict:
        """Re-read the presets file now: {presets, file, loaded, added, removed, changed};
        ApiError naming the file and the problem when it is broken."""
        return self.request("POST", "/v1/presets/reload")

    def report_csv(self, job_id: int | None = None, costs: bool = False) -> str:
        return self.request("GET", "/v1/report?format=csv" + (f"&job={job_id}" if job_id else "")
                            + ("&costs=1" if costs else ""), raw=True)

    def report(self, job_id: int | None = None) -> list[dict]:
        return self.request("GET", "/v1/report" + (f"?job={job_id}" if job_id else ""))["prints"]

    def edit(self, job_id: int, **change) -> dict:
        """Change a job not yet started: any of settings (a partial mapping: only the
        settings given change), copies, priority, printer."""
        return self.request("PATCH", f"/v1/jobs/{job_id}", body=change)["job"]

    def reprint(self, job_id: int, **change) -> dict:
        """A finished job's archived file printed again as a new job: with its settings, or
        any of settings (partial), copies, priority, hold, printer, force changed."""
        return self.request("POST", f"/v1/jobs/{job_id}/reprint", body=change)["job"]

    def release(self, job_id: int, force: bool = False) -> dict:
        """A held job to the queue; force: past the fit checks (paper width, roll left)."""
        return self.request("POST", f"/v1/jobs/{job_id}/release",
                            body={"force": True} if force else None)["job"]

    def rip_hold(self, job_id: int) -> dict:
        """Hold a job not yet started and RIP it ahead: its release prints the kept planes."""
        return self.request("POST", f"/v1/jobs/{job_id}/rip-hold", body=None)["job"]

    def fit(self, job_id: int) -> dict:
        return self.request("GET", f"/v1/jobs/{job_id}/fit")

    def roll(self, printer: str, body: dict | None = None) -> dict:
        """A printer's roll ({printer, roll, paper_mm}); body: load one ({media, length_m |
        label}), {remaining_m}, or {unload: true}."""
        if body is None:
            return self.request("GET", f"/v1/printers/{printer}/roll")
        return self.request("POST", f"/v1/printers/{printer}/roll", body=body)

    def prices(self, new: dict | None = None) -> dict:
        if new is None:
            return self.request("GET", "/v1/prices")
        return self.request("POST", "/v1/prices", body=new)

    def report_costs(self, job_id: int | None = None) -> dict:
        """{prices, prints (each with its cost), totals}."""
        return self.request("GET", "/v1/report?costs=1" + (f"&job={job_id}" if job_id else ""))

    def preview(self, job_id: int, px: int | None = None) -> dict:
        return self.request("GET", f"/v1/jobs/{job_id}/preview" + (f"?px={px}" if px else ""))

    def proof_png(self, job_id: int, px: int | None = None) -> bytes:
        """The job's soft proof through its media, with the gamut warning (PNG)."""
        return self.request("GET", f"/v1/jobs/{job_id}/proof.png" + (f"?px={px}" if px else ""),
                            binary=True)

    def preview_png(self, job_id: int, px: int | None = None) -> bytes:
        return self.request("GET", f"/v1/jobs/{job_id}/preview.png" + (f"?px={px}" if px else ""),
                            binary=True)

    def cut_file(self, job_id: int, fmt: str = "plt") -> bytes:
        """A print-and-cut job's cut file: "plt" (HP-GL/2) or "dxf" (docs/cut.md)."""
        return self.request("GET", f"/v1/jobs/{job_id}/cut.{fmt}", binary=True)

    def media_png(self, printer: str) -> bytes:
        """An emulated printer's media as it lands (the job printing or the last one)."""
        return self.request("GET", f"/v1/printers/{printer}/media.png", binary=True)

    def printers(self) -> list[dict]:
        return self.request("GET", "/v1/printers")["printers"]

    def printer_action(self, printer: str, what: str, body: dict | None = None) -> dict:
        """clear-fault ({"then": ...}), pause, resume, test-print ({"kind": ...})."""
        return self.request("POST", f"/v1/printers/{printer}/{what}", body=body or {})

    def move(self, job_id: int, printer: str | None) -> dict:
        return self.request("POST", f"/v1/jobs/{job_id}/move", body={"printer": printer})["job"]

    def estop(self) -> list[str]:
        return self.request("POST", "/v1/estop", body={})["stopped"]

    def shutdown(self) -> None:
        self.request("POST", "/v1/shutdown", body={})

    def wait(self, job_id: int, timeout: float = 300.0, poll: float = 0.2) -> dict:
        deadline = time.monotonic() + timeout
        while True:
            job = self.job(job_id)
            if job["state"] in ("done", "failed", "cancelled") or time.monotonic() > deadline:
                return job
            time.sleep(poll)
