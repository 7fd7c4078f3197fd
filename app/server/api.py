"""The local HTTP/JSON API with a bearer token (docs/server.md, "The API" and "The API:
the rules").

Every request gets an answer or a closed connection within the connection timeout, and
every malformed one a 4xx with one log line: the request head must arrive within
`api_timeout_s` (a connection silent that long is closed), framing headers are parsed
strictly (one Content-Length, digits only), ids and numbers are digits within SQLite's
64-bit range, and at most `api_max_connections` connections are served at once — the
next ones get 503 at once from one small thread.  A client that goes away is one log line,
never a traceback.
"""

from __future__ import annotations

import hmac
import io
import json
import logging
import math
import queue
import re
import selectors
import socket
import sys
import threading
import time
from http import HTTPStatus
from http.server import BaseHTTPRequestHandler, ThreadingHTTPServer
from typing import TYPE_CHECKING
from urllib.parse import parse_qsl, urlsplit

from .config import SQLITE_MAX_INT
from .previews import PREVIEW_PX, THUMB_PX
from .spool import STATES, SpoolError
from .validate import Invalid, _check_int, validate_job_request

if TYPE_CHECKING:
    from .core import PrintServer

log = logging.getLogger("wideprint.server")

METHODS = ("GET", "POST", "PATCH", "DELETE")
JSON_LIMIT = 1 << 20
MAX_LINE = 65536
RAW_HEAD_LIMIT = 1 << 20           # bytes of a request head kept to check it as sent
RAW_CONTENT_LENGTH = re.compile(rb"(?i)content-length:[ \t]?([^\r\n]*?)\r?")
GONE = (BrokenPipeError, ConnectionResetError, ConnectionAbortedError)


# -- strict parsing -------------------------------------------------------------------------------
def parse_number(text: str) -> int | None:
    """A whole number as the API takes it: ASCII digits only (no sign, space, `_`, exponent),
    at most SQLite's largest integer; None otherwise."""
    if not text or len(text) > 19 or not (text.isascii() and text.isdigit()):
        return None
    n = int(text)
    return n if n <= SQLITE_MAX_INT else None


def _number(name: str, text: str) -> int:
    n = parse_number(text)
    if n is None:
        raise Invalid(f"{name} must be a whole number 0..{SQLITE_MAX_INT}, not {text[:40]!r}")
    return n


def _shown(text: str, limit: int = 120) -> str:
    """Request text for a log line: repr'd (no control character reaches the log), cut."""
    r = repr(text)
    return r if len(r) <= limit else r[:limit] + "..."


def _printable(text: str, limit: int = 300) -> str:
    """A message for a log line: control and other unprintable characters escaped, cut."""
    out = "".join(c if c.isprintable() else repr(c)[1:-1] for c in text[:limit])
    return out + ("..." if len(text) > limit else "")


def loads(data) -> object:
    """JSON as the API takes it: NaN, Infinity and numbers beyond a double are refused,
    and so is nesting too deep for the parser (ValueError for all)."""
    def constant(name):
        raise ValueError(f"{name} is not a number")

    def number(text):
        v = float(text)
        if not math.isfinite(v):
            raise ValueError(f"number {text[:20]} is out of range")
        return v
    try:
        return json.loads(data, parse_constant=constant, parse_float=number)
    except RecursionError:
        raise ValueError("nested too deeply") from None


class _Reader(io.RawIOBase):
    """The connection as the handler reads it: while a request head is awaited, every read
    waits at most until the head's deadline (a head trickled a byte at a time is cut off
    too); otherwise at most the idle timeout."""

    def __init__(self, handler: "ApiHandler"):
        super().__init__()
        self.h = handler

    def readable(self) -> bool:
        return True

    def readinto(self, b) -> int:
        h = self.h
        if h._deadline is not None:
            left = h._deadline - time.monotonic()
            if left <= 0:
                raise TimeoutError("request head not complete in time")
            h.connection.settimeout(min(h.idle, left))
        n = h.connection.recv_into(b)
        h._got += n
        if h._raw is not None and len(h._raw) < RAW_HEAD_LIMIT:
            h._raw += memoryview(b)[:n]
        return n


# -- the API ----------------------------------------------------------------------------------
class ApiHandler(BaseHTTPRequestHandler):
    server_version = "wideprint"
    protocol_version = "HTTP/1.1"
    default_request_version = "HTTP/1.0"             # errors always carry a status line
    srv: "PrintServer"                               # set on the subclass

    # -- connection and request head ------------------------------------------------------------
    def setup(self) -> None:
        super().setup()
        self.idle = float(self.srv.config.api_timeout_s)
        self.connection.settimeout(self.idle)
        self._deadline: float | None = None
        self._got = 0
        self._raw: bytearray | None = None
        self.rfile.close()
        self.rfile = io.BufferedReader(_Reader(self), 65536)

    def handle(self) -> None:
        self.close_connection = True
        try:
            self.handle_one_request()
            while not self.close_connection:
                self.handle_one_request()
        except GONE as exc:
            log.info("api %s: the client went away (%s)", self.client_address[0],
                     type(exc).__name__)

    def handle_one_request(self) -> None:
        self._deadline = time.monotonic() + self.idle
        self._got = 0
        self._raw = bytearray()
        self._body_left = 0
        self._expect_100 = False
        self._answered = False
        self.command, self.path, self.requestline = None, "", ""
        self.request_version = self.default_request_version
        try:
            line = self.rfile.readline(MAX_LINE + 1)
            for _ in range(4):                     # empty lines before a request are ignored
                if line not in (b"\r\n", b"\n"):
                    break
                line = self.rfile.readline(MAX_LINE + 1)
            self.raw_requestline = line
            if not line:
                self.close_connection = True       # the client closed: nothing to answer
                return
            if len(line) > MAX_LINE:
                return self.send_error(HTTPStatus.REQUEST_URI_TOO_LONG, "request line too long")
            if not line.strip():
                return self.send_error(HTTPStatus.BAD_REQUEST, "empty request line")
            if not self.parse_request():
                return                             # answered (4xx) already
            self._raw = None
            self._deadline = None
            self.connection.settimeout(self.idle)
            if self.command not in METHODS:
                return self.send_error(HTTPStatus.METHOD_NOT_ALLOWED,
                                       f"method {self.command[:20]!r} is not allowed "
                                       f"(allowed: {', '.join(METHODS)})")
            self._dispatch(self.command)
            self.wfile.flush()
        except TimeoutError:
            self.close_connection = True
            if self._got and not self._answered:
                why = (f"request head not complete within {self.idle:g} s"
                       if self._deadline is not None and time.monotonic() >= self._deadline - 0.01
                       else f"no data for {self.idle:g} s in the middle of a request")
                log.info("api %s: %s; closed", self.client_address[0], why)
                self._error(HTTPStatus.REQUEST_TIMEOUT, why, close=True, quiet=True)
            else:
                log.debug("api %s: idle connection closed after %g s", self.client_address[0],
                          self.idle)

    def parse_request(self) -> bool:
        if not super().parse_request():
            return False
        if len(self.requestline.split()) != 3:
            self.send_error(HTTPStatus.BAD_REQUEST, "HTTP/0.9 requests are not accepted")
            return False
        h = self.headers
        if h.defects or h.get_payload():
            self.send_error(HTTPStatus.BAD_REQUEST, "malformed header line")
            return False
        if any("\n" in v or "\r" in v for v in h.values()):
            self.send_error(HTTPStatus.BAD_REQUEST, "folded header lines are not accepted")
            return False
        bad = self._raw_content_length()
        if bad is not None:
            self.send_error(HTTPStatus.BAD_REQUEST, f"bad Content-Length {bad[:40]!r}: digits "
                            "only")
            return False
        return True

    def _raw_content_length(self) -> str | None:
        """A Content-Length value as it was sent, when it is not plain digits (after one
        optional space): the header parser strips leading blanks, so " 99" would pass
        as 99.  Checked on the head's raw bytes as they came in."""
        raw = bytes(self._raw or b"").lstrip(b"\r\n")
        if not raw.startswith(self.raw_requestline.strip()):
            return None                      # read ahead with an earlier request: parsed only
        end = min((i for i in (raw.find(b"\r\n\r\n"), raw.find(b"\n\n")) if i >= 0),
                  default=len(raw))
        for line in raw[:end].split(b"\n")[1:]:
            m = RAW_CONTENT_LENGTH.fullmatch(line)
            if m and not m.group(1).isdigit():
                return m.group(1).decode("latin-1")
        return None

    def handle_expect_100(self) -> bool:
        # 100 Continue is sent only once the request is authorised and its body wanted
        self._expect_100 = True
        return True

    def _continue(self) -> None:
        if self._expect_100:
            self._expect_100 = False
            self.send_response_only(HTTPStatus.CONTINUE)
            self.end_headers()

    # -- logging ----------------------------------------------------------------------------------
    def log_message(self, fmt, *args) -> None:  # noqa: D401 - quiet; to the logger
        log.debug("api %s " + fmt, self.client_address[0], *args)

    def log_error(self, fmt, *args) -> None:
        log.info("api %s " + fmt, self.client_address[0], *args)

    # -- responses --------------------------------------------------------------------------------
    def _send(self, status: int, body: bytes, ctype: str, close: bool = False,
              extra: dict | None = None) -> None:
        if self._body_left:
            close = True                 # a body not read: the stream cannot be followed
        try:
            self.connection.settimeout(self.idle)     # not a head deadline's last moments
            self.send_response(status)
            self.send_header("Content-Type", ctype)
            self.send_header("Content-Length", str(len(body)))
            self.send_header("Cache-Control", "no-store")
            for k, v in (extra or {}).items():
                self.send_header(k, v)
            if close:
                self.send_header("Connection", "close")
                self.close_connection = True
            self._answered = True
            self.end_headers()
            if self.command != "HEAD":
                self.wfile.write(body)
        except GONE as exc:
            self.close_connection = True
            log.debug("api %s: the client went away before its answer (%s %d; %s)",
                     self.client_address[0], self.command or "-", status, type(exc).__name__)

    def _events(self, max_s: int | None) -> None:
        """Server-sent events (text/event-stream, docs/server.md "Live state"): the state of
        the printers (`printers`: state, fault, current job and its telemetry) and of the
        jobs not finished (`jobs`), each sent when it changes, checked 5 times a second on
        the server; a comment every 15 s keeps the connection alive.  One stream replaces a
        client's polling.  `?max_s=N` ends the stream after N seconds (tests, scripts)."""
        import time as _time
        srv = self.srv
        self.close_connection = True
        try:
            self.connection.settimeout(self.idle)
            self.send_response(200)
            self.send_header("Content-Type", "text/event-stream")
            self.send_header("Cache-Control", "no-store")
            self.send_header("Connection", "close")
            self._answered = True
            self.end_headers()
            last: dict = {}
            beat = start = _time.monotonic()
            while not srv.stopping():
                now = _time.monotonic()
                if max_s is not None and now - start >= max_s:
                    break
                state = {"printers": srv.printers(),
                         "jobs": srv.jobs(("queued", "held", "printing"))}
                for kind, value in state.items():
                    if value != last.get(kind):
                        last[kind] = value
                        data = json.dumps(value, separators=(",", ":"), default=str)
                        self.wfile.write(f"event: {kind}\ndata: {data}\n\n".encode())
                        beat = now
                if now - beat >= 15:
                    self.wfile.write(b": alive\n\n")
                    beat = now
                self.wfile.flush()
                _time.sleep(0.2)
        except GONE as exc:
            log.debug("api %s: an event stream ended (%s)", self.client_address[0], type(exc).__name__)

    def _json(self, status: int, obj, close: bool = False, extra: dict | None = None) -> None:
        self._send(status, (json.dumps(obj, indent=1) + "\n").encode(), "application/json",
                   close, extra)

    def _error(self, status: int, message: str, close: bool = False, quiet: bool = False) -> None:
        status = int(status)
        if not quiet:
            log.info("api %s %s %s: %d %s", self.client_address[0], self.command or "-",
                     _shown(self.path or self.requestline), status, _printable(message))
        extra = {"WWW-Authenticate": 'Bearer realm="wideprint"'} if status == 401 else None
        if status == 503:
            extra = {"Retry-After": "1"}
        self._json(status, {"error": message}, close=close, extra=extra)

    def send_error(self, code, message=None, explain=None) -> None:
        """Protocol errors (from http.server and our own checks): JSON like every other
        error, one log line, and the connection is closed."""
        code = int(code)
        if message is None:
            try:
                message = HTTPStatus(code).phrase
            except ValueError:
                message = "error"
        self._error(code, message, close=True)

    # -- requests ---------------------------------------------------------------------------------
    def _authorised(self) -> bool:
        values = self.headers.get_all("Authorization") or []
        if len(values) != 1:
            return False
        scheme, _, token = values[0].partition(" ")
        return scheme.lower() == "bearer" and hmac.compare_digest(
            token.strip().encode(), self.srv.token.encode())

    def _body_length(self) -> int | None:
        """The body's length from its one Content-Length (None: no body announced).
        Anything else is refused: a Transfer-Encoding, two Content-Lengths, a value that
        is not plain digits (no sign, no space)."""
        te = self.headers.get_all("Transfer-Encoding") or []
        cl = self.headers.get_all("Content-Length") or []
        if te and cl:
            raise Invalid("Content-Length and Transfer-Encoding together are refused")
        if te:
            raise Invalid("send a Content-Length (chunked bodies are not accepted)", 411)
        if len(cl) > 1:
            raise Invalid(f"{len(cl)} Content-Length headers: send exactly one")
        if not cl:
            return None
        v = cl[0]
        if not (v.isascii() and v.isdigit()):
            raise Invalid(f"bad Content-Length {v[:40]!r}: digits only")
        if len(v) > 18:
            raise Invalid("Content-Length is too large", 413)
        return int(v)

    def _query(self, query: str, allowed: tuple[str, ...]) -> dict[str, str]:
        try:
            pairs = parse_qsl(query, keep_blank_values=True, max_num_fields=len(allowed) + 1)
        except ValueError:
            raise Invalid("too many query parameters") from None
        out: dict[str, str] = {}
        for k, v in pairs:
            if k not in allowed:
                known = f" (known: {', '.join(allowed)})" if allowed else ""
                raise Invalid(f"unknown query parameter {k[:40]!r}{known}")
            if k in out:
                raise Invalid(f"query parameter {k!r} given twice")
            out[k] = v
        return out

    def _read_json(self):
        n = self._length
        if not n:
            return {}
        if n > JSON_LIMIT:
            raise Invalid("JSON body too large (1 MiB at most)", 413)
        self._continue()
        body = self.rfile.read(n)
        self._body_left = 0
        if len(body) != n:
            self.close_connection = True
            raise Invalid(f"body ended after {len(body)} of {n} bytes")
        if not body.strip():
            return {}
        try:
            return loads(body)
        except ValueError as exc:                     # UnicodeDecodeError included
            raise Invalid(f"bad JSON: {exc}") from None

    def _dispatch(self, method: str) -> None:
        url = urlsplit(self.path)
        parts = [p for p in url.path.split("/") if p]
        if not self._authorised():
            # nothing of an unauthorised request is read; the connection is closed
            return self._error(401, "missing or wrong bearer token (see the token file in "
                               "the server's state directory)", close=True)
        try:
            try:
                self._length = self._body_length()
            except Invalid as exc:
                return self._error(exc.status, str(exc), close=True)
            self._body_left = self._length or 0
            if parts[:1] != ["v1"]:
                raise Invalid(f"no such endpoint {url.path[:80]}", 404)
            route = parts[1:]
            if method == "POST" and route == ["jobs"]:
                self._query(url.query, ())
                return self._submit()
            if method in ("POST", "PATCH", "DELETE"):
                body = self._read_json()
            elif self._length:
                raise Invalid(f"{method} takes no body")
            if method == "GET" and route == ["status"]:
                self._query(url.query, ())
                return self._json(200, self.srv.status())
            if method == "GET" and route == ["jobs"]:
                q = self._query(url.query, ("state", "limit", "after", "newest"))
                states = None
                if "state" in q:
                    states = tuple(s for s in q["state"].split(",") if s)
                    bad = [s for s in states if s not in STATES]
                    if bad or not states:
                        raise Invalid(f"state must be one or more of {', '.join(STATES)}, "
                                      f"not {q['state'][:60]!r}")
                limit = _number("limit", q["limit"]) if "limit" in q else 0
                after = _number("after", q["after"]) if "after" in q else 0
                newest = q.get("newest", "0")
                if newest not in ("0", "1"):
                    raise Invalid("newest must be 0 or 1")
                return self._json(200, {"jobs": self.srv.jobs(states, limit or None, after,
                                                               newest == "1")})
            if method == "GET" and route == ["presets"]:
                self._query(url.query, ())
                presets = self.srv.presets
                return self._json(200, dict(self.srv.preset_source.info(), presets=presets))
            if method == "POST" and route == ["presets", "reload"]:
                self._query(url.query, ())
                if body:
                    raise Invalid("reload takes no parameters")
                return self._json(200, self.srv.reload_presets())
            if method == "GET" and route == ["report"]:
                q = self._query(url.query, ("job", "format"))
                job = _number("job", q["job"]) if "job" in q else None
                fmt = q.get("format", "json")
                if fmt not in ("json", "csv"):
                    raise Invalid(f"format must be json or csv, not {fmt[:20]!r}")
                if fmt == "csv":
                    return self._send(200, self.srv.report_csv(job).encode(), "text/csv")
                return self._json(200, {"prints": self.srv.spool.prints(job)})
            if method == "POST" and route == ["queue"]:
                self._query(url.query, ())
                if not isinstance(body, dict) or set(body) - {"paused"} or \
                        not isinstance(body.get("paused"), bool):
                    raise Invalid('expected {"paused": true|false}')
                for w in self.srv.workers.values():       # the whole queue: every printer
                    if not w.fault:                       # a fault stays until cleared
                        w.set_paused(body["paused"], "paused by the operator")
                return self._json(200, self.srv.status())
            if method == "GET" and route == ["events"]:
                q = self._query(url.query, ("max_s",))
                max_s = _number("max_s", q["max_s"]) if "max_s" in q else None
                return self._events(max_s)
            if method == "GET" and route == ["printers"]:
                self._query(url.query, ())
                return self._json(200, {"printers": self.srv.printers()})
            if method == "POST" and route == ["shutdown"]:
                self._query(url.query, ())
                if body:
                    raise Invalid("shutdown takes no parameters")
                self._json(200, {"stopping": True})
                self.srv.request_stop()
                return
            if method == "POST" and route == ["estop"]:
                self._query(url.query, ())
                return self._json(200, {"stopped": self.srv.estop()})
            if len(route) == 3 and route[:1] == ["printers"] and route[2] == "media.png" \
                    and method == "GET":
                self._query(url.query, ())
                live = self.srv.printer_worker(route[1]).live
                png = live.png() if live is not None else None
                if png is None:
                    raise Invalid(f"printer {route[1][:40]}: no live media (an emulated printer "
                                  f"shows it once it has printed)", 404)
                return self._send(200, png, "image/png")
            if len(route) == 3 and route[0] == "printers" and method == "POST":
                self._query(url.query, ())
                name, what = route[1], route[2]
                worker = self.srv.printer_worker(name)
                if what == "clear-fault":
                    if not isinstance(body, dict) or set(body) - {"then"}:
                        raise Invalid('expected {"then": "resume"|"fail"}')
                    return self._json(200, self.srv.clear_fault(name, body.get("then", "resume")))
                if what == "test-print":
                    return self._json(200, self.srv.test_print(name, body))
                if what == "head-care":
                    return self._json(200, self.srv.service(name, body))
                if what in ("pause", "resume"):
                    if body:
                        raise Invalid(f"{what} takes no parameters")
                    if what == "resume" and worker.fault:
                        raise Invalid(f"printer {name} has a fault ({worker.fault}): clear it "
                                      f"(resume or fail its job)", 409)
                    worker.set_paused(what == "pause", "paused by the operator")
                    return self._json(200, {"printers": self.srv.printers()})
            if len(route) >= 2 and route[0] == "jobs":
                job_id = parse_number(route[1])
                if job_id is None:
                    raise Invalid(f"no job {route[1][:40]!r} (job ids are whole numbers)", 404)
                self._query(url.query, ("px",) if route[2:] in (["preview"], ["preview.png"]) else ())
                if method == "GET" and len(route) == 2:
                    job = self.srv.spool.get(job_id)
                    if job is None:
                        raise Invalid(f"no job {job_id}", 404)
                    return self._json(200, {"job": self.srv.public(job)})
                if method == "PATCH" and len(route) == 2:
                    return self._json(200, {"job": self.srv.public(self.srv.edit(job_id, body))})
                if method == "GET" and len(route) == 3 and route[2] in ("preview", "preview.png"):
                    job = self.srv.spool.get(job_id)
                    if job is None:
                        raise Invalid(f"no job {job_id}", 404)
                    q = self._query(url.query, ("px",))
                    px = _check_int("px", _number("px", q["px"]), *PREVIEW_PX) if "px" in q \
                        else THUMB_PX
                    if route[2] == "preview.png":
                        return self._send(200, self.srv.previews.png(job, px), "image/png")
                    return self._json(200, self.srv.previews.info(job, px))
                if method == "POST" and len(route) == 3 and route[2] == "move":
                    if not isinstance(body, dict) or set(body) != {"printer"} or \
                            not isinstance(body["printer"], (str, type(None))):
                        raise Invalid('expected {"printer": NAME|"any"}')
                    return self._json(200, {"job": self.srv.public(self.srv.move(job_id, body["printer"]))})
                if method == "POST" and len(route) == 3 and route[2] in ("cancel", "hold", "release",
                                                                          "requeue"):
                    if body:
                        raise Invalid(f"{route[2]} takes no parameters")
                    job = getattr(self.srv, route[2])(job_id)
                    return self._json(200, {"job": self.srv.public(job)})
            raise Invalid(f"no such endpoint {method} {url.path[:80]}", 404)
        except Invalid as exc:
            return self._error(exc.status, str(exc))
        except SpoolError as exc:
            return self._error(exc.status, str(exc))
        except (TimeoutError, *GONE):
            raise                                      # the connection's end: handled above
        except ValueError as exc:
            return self._error(400, str(exc))
        except Exception as exc:  # noqa: BLE001 - a bug: the client still gets an answer
            log.exception("api %s %s %s", self.client_address[0], method, _shown(self.path))
            return self._error(500, f"internal error: {type(exc).__name__}: {exc}", close=True,
                               quiet=True)

    def _submit(self) -> None:
        srv = self.srv
        try:
            headers = self.headers.get_all("X-Wideprint-Job") or []
            if not headers:
                raise Invalid("missing X-Wideprint-Job header (the job description, JSON)")
            if len(headers) > 1:
                raise Invalid("more than one X-Wideprint-Job header")
            try:
                raw = loads(headers[0])
            except ValueError as exc:
                raise Invalid(f"bad JSON in X-Wideprint-Job: {exc}") from None
            req = validate_job_request(raw, srv.presets, srv.profile, srv.state_dir / "icc",
                                       printers=tuple(srv.workers))
            size = self._length
            if size is None:
                raise Invalid("Content-Length is required", 411)
            if size <= 0:
                raise Invalid("empty file")
            if size > srv.config.max_file_bytes:
                raise Invalid(f"file is {size} bytes, above the {srv.config.max_file_bytes}-byte "
                              "limit", 413)
        except Invalid as exc:
            # the body was not read: close the connection rather than read a file we refuse
            return self._error(exc.status, str(exc), close=True)
        self._continue()
        try:
            job, created = srv.queue_file(
                self.rfile, req["name"], size, exact=True, source="api",
                settings=req["settings"], preset=req["preset"], copies=req["copies"],
                priority=req["priority"], hold=req["hold"], key=req["key"], client=req["client"],
                printer=req["printer"])
        except Invalid as exc:
            self.close_connection = True
            return self._error(exc.status, str(exc), close=True)
        except (TimeoutError, *GONE):
            raise
        except OSError as exc:                        # the spool's disk: full, read-only, ...
            log.error("api: cannot spool %s: %s", req["name"], exc)
            return self._error(507, f"the server cannot store the file: {exc.strerror or exc}",
                               close=True, quiet=True)
        self._body_left = 0
        if not created:
            return self._json(200, {"job": srv.public(job), "duplicate": True})
        srv.notify()
        self._json(201, {"job": srv.public(job), "duplicate": False})

    def do_GET(self):
        self._dispatch("GET")

    def do_POST(self):
        self._dispatch("POST")

    def do_PATCH(self):
        self._dispatch("PATCH")

    def do_DELETE(self):
        self._dispatch("DELETE")


# -- the listener -----------------------------------------------------------------------------------
def _busy_answer(limit: int) -> bytes:
    body = (json.dumps({"error": f"the server is busy ({limit} connections open, the limit); "
                                 "try again"}) + "\n").encode()
    return (b"HTTP/1.1 503 Service Unavailable\r\nContent-Type: application/json\r\n"
            b"Cache-Control: no-store\r\nRetry-After: 1\r\nConnection: close\r\n"
            + f"Content-Length: {len(body)}\r\n\r\n".encode() + body)


class _HTTPServer(ThreadingHTTPServer):
    """One thread per connection, at most `max_connections` of them; a connection beyond
    that gets 503 (Retry-After: 1) at once from one small thread and is closed."""

    daemon_threads = True
    allow_reuse_address = True
    request_queue_size = 64
    REJECT_WAIT_S = 0.5              # a refused client's request head is waited for this long

    def __init__(self, address, handler, max_connections: int = 32):
        super().__init__(address, handler)
        self.max_connections = max(1, int(max_connections))
        self._slots = threading.BoundedSemaphore(self.max_connections)
        self._busy = _busy_answer(self.max_connections)
        self._rejects: queue.Queue = queue.Queue(maxsize=max(8, self.max_connections))
        self._closing = threading.Event()
        self._refused = 0
        self._refused_logged = 0.0
        self._rejecter = threading.Thread(target=self._reject_loop, name="wideprint-api-busy",
                                          daemon=True)
        self._rejecter.start()

    def process_request(self, request, client_address) -> None:
        if self._slots.acquire(blocking=False):
            t = threading.Thread(target=self._serve, args=(request, client_address),
                                 name="wideprint-api-conn", daemon=True)
            try:
                t.start()
            except RuntimeError as exc:                  # no thread to be had
                self._slots.release()
                log.warning("api: cannot start a thread (%s); connection closed", exc)
                self.shutdown_request(request)
            return
        self._refused += 1
        now = time.monotonic()
        if now - self._refused_logged >= 10:
            log.warning("api: %d connections open, the limit: %d connection(s) answered 503",
                        self.max_connections, self._refused)
            self._refused_logged, self._refused = now, 0
        try:
            self._rejects.put_nowait(request)
        except queue.Full:
            self.shutdown_request(request)             # even the refusals queue is full

    def _serve(self, request, client_address) -> None:
        try:
            self.process_request_thread(request, client_address)
        finally:
            self._slots.release()

    def _reject_loop(self) -> None:
        """Answers 503 to the connections beyond the limit, all of them at once (one
        selector): a connection's request head is read for at most REJECT_WAIT_S (so that
        closing it does not reset the answer away), answered, then drained for at most as
        long and closed."""
        sel = selectors.DefaultSelector()
        pending: dict = {}                         # socket -> [phase, deadline, head]

        def drop(sock) -> None:
            pending.pop(sock, None)
            try:
                sel.unregister(sock)
            except (KeyError, ValueError):
                pass
            sock.close()

        def answer(sock) -> None:
            try:
                sock.send(self._busy)                # small: fits the socket's buffer
                sock.shutdown(socket.SHUT_WR)
            except OSError:
                return drop(sock)
            pending[sock] = ["drain", time.monotonic() + self.REJECT_WAIT_S, b""]

        while not self._closing.is_set():
            try:
                sock = self._rejects.get(timeout=0.05 if pending else 0.5)
            except queue.Empty:
                sock = None
            while sock is not None:
                try:
                    sock.setblocking(False)
                    sel.register(sock, selectors.EVENT_READ)
                    pending[sock] = ["head", time.monotonic() + self.REJECT_WAIT_S, b""]
                except (OSError, ValueError):
                    sock.close()
                try:
                    sock = self._rejects.get_nowait()
                except queue.Empty:
                    sock = None
            if not pending:
                continue
            for key, _ in sel.select(timeout=0.05):
                sock = key.fileobj
                state = pending.get(sock)
                if state is None:
                    continue
                try:
                    data = sock.recv(MAX_LINE)
                except BlockingIOError:
                    continue
                except OSError:
                    drop(sock)
                    continue
                if state[0] == "drain":
                    if not data:
                        drop(sock)                   # the client read the answer and closed
                    continue
                state[2] += data
                if not data or b"\r\n\r\n" in state[2] or len(state[2]) >= MAX_LINE:
                    answer(sock)
            now = time.monotonic()
            for sock, state in list(pending.items()):
                if now >= state[1]:
                    if state[0] == "head":
                        answer(sock)
                    else:
                        drop(sock)
        for sock in list(pending):
            drop(sock)
        sel.close()

    def handle_error(self, request, client_address) -> None:
        exc = sys.exc_info()[1]
        if isinstance(exc, (*GONE, TimeoutError)):
            log.info("api %s: the client went away (%s)", client_address[0], type(exc).__name__)
        else:
            log.error("api %s: unexpected error", client_address[0], exc_info=True)

    def server_close(self) -> None:
        self._closing.set()
        super().server_close()
        while True:
            try:
                self._rejects.get_nowait().close()
            except queue.Empty:
                break
