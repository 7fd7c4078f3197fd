"""The local HTTP/JSON API with a bearer token (docs/server.md, "The API" and "The API:
the rules").

Every request gets an answer or a closed connection within the connection timeout, and
every malformed one a 4xx with one log line: the request head must arrive within
`api_timeout_s` (a connection silent that long is closed), framing headers are parsed
strictly (one Content-Length, digits only), ids and numbers are digits within SQLite's
64-bit range.  One listener thread reads request heads without a thread each (slow and
half-open clients cost a socket, not a thread); at most `api_max_connections` requests are
served at once, a quarter of the threads kept for plain GETs — the next ones get 503 at
once.  A client that goes away is one log line, never a traceback.

Who may do what (the operator's token, users' tokens, job owners) is `auth.py`
(docs/server.md "Users and roles"); a full disk is 507 (`storage_full`).
"""

from __future__ import annotations

import errno
import hmac
import io
import json
import logging
import math
import queue
import re
import selectors
import socket
import socketserver
import sqlite3
import sys
import threading
import time
from http import HTTPStatus
from http.server import BaseHTTPRequestHandler
from urllib.parse import parse_qsl, urlsplit

from ..safe_text import REDACTED, add_secret, install_log_filter, safe
from .auth import OPERATOR, USER, Identity, Owners, Users, claimed_name, may_act
from .config import DEFAULT_API_TIMEOUT_S, MIN_TOKEN, SQLITE_MAX_INT
from .ports import ApiHost  # what it sees of the server (core.py composes it)
from .previews import PREVIEW_PX, THUMB_PX
from .spool import STATES, SpoolError
from .validate import Invalid, _check_int, validate_job_request
from . import routes, web

log = logging.getLogger("wideprint.server")
# every log line of the server's loggers: names shown escaped, tokens taken out (safe_text)
install_log_filter("wideprint.server", "wideprint.ipp", "wideprint.job", "wideprint.link")

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


SAFE_QUERY = frozenset(("state", "limit", "after", "newest", "job", "format", "px", "max_s"))


def _loggable(target: str) -> str:
    """A request target for the log: the values of query parameters other than the API's
    own are taken out (a client that puts its token in the URL does not put it in the log)."""
    path, q, query = target.partition("?")
    if not q:
        return target
    parts = []
    for item in query.split("&"):
        k, eq, _ = item.partition("=")
        parts.append(item if (not eq or k in SAFE_QUERY) else f"{k}={REDACTED}")
    return path + "?" + "&".join(parts)


def _shown(text: str, limit: int = 120) -> str:
    """Request text for a log line: secrets in the query out, repr'd (no control character
    reaches the log), cut."""
    r = repr(_loggable(text))
    return r if len(r) <= limit else r[:limit] + "..."


def storage_full(exc: BaseException) -> str | None:
    """The plain reason when `exc` is a full disk (SQLite's "database or disk is full", or
    ENOSPC/EDQUOT from the file system): such requests are answered 507, never 500."""
    if isinstance(exc, sqlite3.OperationalError) and "full" in str(exc).lower():
        return ("the server's disk is full: the queue's database cannot be written "
                f"({exc}); nothing was changed — free space on the state directory's disk "
                "and try again")
    if isinstance(exc, OSError) and exc.errno in (errno.ENOSPC, errno.EDQUOT):
        return (f"the server's disk is full ({exc.strerror or exc}); nothing was changed — "
                "free space and try again")
    return None


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
    """The connection as the handler reads it: first what the listener read already (the
    request head, `prefetch`), then the socket.  While a request head is awaited, every
    read waits at most until the head's deadline (a head trickled a byte at a time is cut
    off too); otherwise at most the idle timeout.  `stop` makes it read nothing more (the
    handler takes what is buffered back to the listener)."""

    def __init__(self, handler: "ApiHandler", prefetch: bytes = b""):
        super().__init__()
        self.h = handler
        self.prefetch = memoryview(prefetch)
        self.stop = False

    def readable(self) -> bool:
        return True

    def readinto(self, b) -> int | None:
        h = self.h
        if len(self.prefetch):
            n = min(len(b), len(self.prefetch))
            b[:n] = self.prefetch[:n]
            self.prefetch = self.prefetch[n:]
            h._got += n
            if h._raw is not None and len(h._raw) < RAW_HEAD_LIMIT:
                h._raw += memoryview(b)[:n]
            return n
        if self.stop:
            return None                      # "nothing now": the buffered reader stops here
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


def token_identity(operator_token: str | None, users: Users | None, token: str
                   ) -> Identity | None:
    """Whose token this is: the operator's (the `token` file), a user's (`users/NAME`), or
    nobody's (None).  An empty or short token is nobody's, whatever the files say; every
    comparison takes constant time."""
    if len(token) < MIN_TOKEN or not token.isascii():
        return None
    mine = operator_token or ""
    if len(mine) >= MIN_TOKEN and hmac.compare_digest(token.encode(), mine.encode()):
        return Identity(None, OPERATOR)
    name = users.lookup(token) if users is not None else None
    return Identity(name, USER) if name else None


# -- the API ----------------------------------------------------------------------------------
class ApiHandler(BaseHTTPRequestHandler):
    server_version = "wideprint"
    protocol_version = "HTTP/1.1"
    default_request_version = "HTTP/1.0"             # errors always carry a status line
    srv: ApiHost                                     # set on the subclass (core.py)
    server: _HTTPServer                              # socketserver's: the users, the owners
    who: Identity                                    # the request's, set first by _dispatch

    # -- connection and request head ------------------------------------------------------------
    def setup(self) -> None:
        super().setup()
        self.idle = float(self.srv.config.api_timeout_s)
        self.connection.settimeout(self.idle)
        self._deadline: float | None = None
        self._got = 0
        self._raw: bytearray | None = None
        self.keep: bytes | None = None
        self.rfile.close()
        self._reader = _Reader(self, getattr(self, "_prefetch", b""))
        self.rfile = io.BufferedReader(self._reader, 65536)

    def handle(self) -> None:
        """One request.  A connection kept alive goes back to the listener with whatever
        the client sent beyond this request (`keep`): waiting for its next request head
        holds no thread."""
        self.close_connection = True
        try:
            self.handle_one_request()
            if not self.close_connection:
                self.wfile.flush()
                self._reader.stop = True
                self.keep = self.rfile.peek(0) + bytes(self._reader.prefetch)
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
        log.debug("api %s " + fmt, self.client_address[0],
                  *(_loggable(a) if isinstance(a, str) else a for a in args))

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
        the printers (`printers`: state, fault, current job and its telemetry), of the
        jobs not finished (`jobs`) and a mark of the ended ones (`ended`), each sent when
        it changes, checked 5 times a second on the server; a comment every 15 s keeps the
        connection alive.  One stream replaces a client's polling.  `?max_s=N` ends the
        stream after N seconds (tests, scripts)."""
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
                         "jobs": self._out(srv.jobs(("queued", "held", "printing"))),
                         "ended": srv.spool.ended_mark()}
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
        if status == 405 and getattr(self, "_allow", None):
            extra = {"Allow": ", ".join(self._allow)}
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
    def _identity(self) -> Identity | None:
        """Who sent the request (docs/server.md "Users and roles"), None when its one
        `Authorization: Bearer` token is nobody's: the operator's token (the `token` file),
        or a user's (`users/NAME`).  An empty or short token is nobody's, whatever the
        files say; every comparison takes constant time."""
        values = self.headers.get_all("Authorization") or []
        if not values:                 # the web page's session cookie (web.py, docs/web.md)
            sessions = getattr(self.server, "sessions", None)
            sid = web.parse_cookie(self.headers.get_all("Cookie") or [])
            found = sessions.identity(sid, self.command, self.headers,
                                      self.headers.get("Host")) if sessions and sid else None
            return found[0] if found else None
        if len(values) != 1:
            return None
        scheme, _, token = values[0].partition(" ")
        if scheme.lower() != "bearer":
            return None
        return self._token_identity(token.strip())

    def _token_identity(self, token: str) -> Identity | None:
        return token_identity(self.srv.token, getattr(self.server, "users", None), token)

    def _operator_only(self, what: str) -> None:
        if not self.who.operator:
            raise Invalid(f"{what} is for the operator: {self.who.shown()} may submit jobs, "
                          f"read the queue and act on its own jobs", 403)

    def _may_act(self, job_id: int, what: str) -> None:
        """A user may act on its own jobs only (an operator on all): 403 otherwise."""
        if self.who.operator:
            return
        job = self.srv.spool.get(job_id)
        if job is None:
            raise Invalid(f"no job {job_id}", 404)
        owner = self.server.owners.get(job_id)
        if not may_act(self.who, owner):
            raise Invalid(f"job {job_id} belongs to {safe(owner) if owner else 'the operator'}"
                          f": only its owner or an operator may {what} it (you are "
                          f"{self.who.shown()})", 403)
        members = job.get("nest_members")
        if what == "cancel" and members:
            ids = json.loads(members) if isinstance(members, str) else list(members)
            owners = self.server.owners.of([{"id": i} for i in ids])
            others = [i for i in ids if owners.get(i) != self.who.name]
            if others:
                raise Invalid(f"job {job_id}'s nested sheet holds jobs of others "
                              f"({', '.join(map(str, others[:10]))}): only an operator may "
                              f"cancel it", 403)

    def _out(self, jobs: list[dict]) -> list[dict]:
        """Jobs as the API shows them: with their `owner` and their `display_name` (the name
        with invisible and reordering characters escaped; `name` is as it was sent)."""
        owners = getattr(self.server, "owners", None)
        found = owners.of(jobs) if owners is not None else {}
        for j in jobs:
            j["owner"] = found.get(j["id"])
            j["display_name"] = safe(j["name"])
        return jobs

    def _job(self, job: dict) -> dict:
        return {"job": self._out([self.srv.public(job)])[0]}

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
        self._allow: list[str] = []            # the methods a 405's Allow header names
        url = urlsplit(self.path)
        parts = [p for p in url.path.split("/") if p]
        if url.path in web.STATIC or url.path in web.SESSION_ROUTES:
            return self._web(method, url.path)
        who = self._identity()
        if who is None:
            # nothing of an unauthorised request is read; the connection is closed
            return self._error(401, "missing or wrong bearer token (see the token file in "
                               "the server's state directory, or your user token)", close=True)
        self.who = who
        claimed = self.headers.get_all("X-Wideprint-User") or []
        if claimed:
            try:
                if len(claimed) > 1:
                    raise ValueError("given more than once")
                name = claimed_name(claimed[0])
            except ValueError as exc:
                return self._error(400, f"bad X-Wideprint-User header: {exc}", close=True)
            if self.who.operator:                 # a user is who its token says, whatever it says
                self.who = Identity(name, OPERATOR)
        try:
            try:
                self._length = self._body_length()
            except Invalid as exc:
                return self._error(exc.status, str(exc), close=True)
            self._body_left = self._length or 0
            if parts[:1] != ["v1"]:
                raise Invalid(f"no such endpoint {url.path[:80]}", 404)
            if routes.find(method, parts) is None:     # declared once: app/server/routes.py
                self._allow = routes.methods(parts)
                if self._allow:
                    raise Invalid(f"{method} {url.path[:80]}: not allowed here (allowed: "
                                  f"{', '.join(self._allow)})", 405)
                raise Invalid(f"no such endpoint {method} {url.path[:80]}", 404)
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
                return self._json(200, {"jobs": self._out(self.srv.jobs(
                    states, limit or None, after, newest == "1"))})
            if method == "GET" and route == ["presets"]:
                self._query(url.query, ())
                presets = self.srv.presets
                return self._json(200, dict(self.srv.preset_source.info(), presets=presets))
            if method == "POST" and route == ["presets", "reload"]:
                self._query(url.query, ())
                self._operator_only("re-reading the presets")
                if body:
                    raise Invalid("reload takes no parameters")
                return self._json(200, self.srv.reload_presets())
            if method == "GET" and route == ["report"]:
                q = self._query(url.query, ("job", "format", "costs"))
                of_job = _number("job", q["job"]) if "job" in q else None
                fmt = q.get("format", "json")
                if fmt not in ("json", "csv"):
                    raise Invalid(f"format must be json or csv, not {fmt[:20]!r}")
                if q.get("costs", "0") not in ("0", "1"):
                    raise Invalid("costs must be 0 or 1")
                with_costs = q.get("costs") == "1"       # docs/server.md "Prices and costs"
                if fmt == "csv":
                    return self._send(200, self.srv.report_csv(of_job, with_costs).encode(),
                                      "text/csv")
                if with_costs:
                    return self._json(200, self.srv.report_costs(of_job))
                return self._json(200, {"prints": self.srv.spool.prints(of_job)})
            if route == ["prices"] and method in ("GET", "POST"):
                self._query(url.query, ())             # docs/server.md "Prices and costs"
                if method == "POST":
                    self._operator_only("setting the price list")
                    return self._json(200, self.srv.prices(body))
                return self._json(200, self.srv.prices())
            if method == "POST" and route == ["queue"]:
                self._query(url.query, ())
                self._operator_only("pausing or resuming the queue")
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
                self._operator_only("stopping the server")
                if body:
                    raise Invalid("shutdown takes no parameters")
                self._json(200, {"stopping": True})
                self.srv.request_stop()
                return
            if method == "POST" and route == ["estop"]:
                self._query(url.query, ())
                self._operator_only("the emergency stop")
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
            if len(route) == 3 and route[0] == "printers" and route[2] == "roll" and \
                    method in ("GET", "POST"):
                self._query(url.query, ())             # docs/server.md "Rolls"
                if method == "POST":
                    self._operator_only("loading a roll")
                return self._json(200, self.srv.roll(route[1], body if method == "POST" else None))
            if len(route) == 3 and route[0] == "printers" and method == "POST":
                self._query(url.query, ())
                name, what = route[1], route[2]
                self._operator_only(f"{what} of a printer")
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
                self._query(url.query, ("px",) if route[2:] in (["preview"], ["preview.png"],
                                                                ["proof.png"]) else ())
                if method == "GET" and len(route) == 2:
                    job = self.srv.spool.get(job_id)
                    if job is None:
                        raise Invalid(f"no job {job_id}", 404)
                    return self._json(200, self._job(job))
                if method == "GET" and len(route) == 3 and route[2] in ("cut.plt", "cut.dxf"):
                    data = self._cut_file(job_id, route[2])    # print and cut (docs/cut.md)
                    return self._send(200, data, "application/vnd.hp-hpgl" if route[2] == "cut.plt"
                                      else "image/vnd.dxf")
                if method == "PATCH" and len(route) == 2:
                    self._may_act(job_id, "edit")
                    return self._json(200, self._job(self.srv.edit(job_id, body)))
                if method == "GET" and len(route) == 3 and route[2] in ("preview", "preview.png",
                                                                         "proof.png"):
                    job = self.srv.spool.get(job_id)
                    if job is None:
                        raise Invalid(f"no job {job_id}", 404)
                    q = self._query(url.query, ("px",))
                    px = _check_int("px", _number("px", q["px"]), *PREVIEW_PX) if "px" in q \
                        else THUMB_PX
                    if route[2] == "preview.png":
                        return self._send(200, self.srv.previews.png(job, px), "image/png")
                    if route[2] == "proof.png":          # the soft proof (docs/color.md)
                        return self._send(200, self.srv.previews.proof_png(job, px), "image/png")
                    info = self.srv.previews.info(job, px)
                    # a quote at the price list, and whether it fits the paper loaded
                    info["quote"] = self.srv.quote(job, info)
                    if job["state"] in ("queued", "held") and job.get("spool_path"):
                        info["fit"] = self.srv.fit(job)
                    return self._json(200, info)
                if method == "GET" and len(route) == 3 and route[2] == "fit":
                    job = self.srv.spool.get(job_id)
                    if job is None:
                        raise Invalid(f"no job {job_id}", 404)
                    if not job.get("spool_path"):
                        raise Invalid(f"job {job_id}: its file is no longer spooled", 410)
                    return self._json(200, self.srv.fit(job))
                if method == "POST" and len(route) == 3 and route[2] == "reprint":
                    self._may_act(job_id, "reprint")   # docs/server.md "Archive and reprint"
                    new = self.srv.reprint(job_id, body)
                    owner = self.who.name
                    if owner is not None:
                        self.server.owners.set(new["id"], owner)
                    return self._json(201, self._job(new))
                if method == "POST" and len(route) == 3 and route[2] == "rip-hold":
                    if body:                           # docs/server.md "RIP and hold"
                        raise Invalid("rip-hold takes no parameters")
                    self._may_act(job_id, "rip and hold")
                    return self._json(200, self._job(self.srv.rip_hold(job_id)))
                if method == "POST" and len(route) == 3 and route[2] == "release" and body:
                    if not isinstance(body, dict) or set(body) != {"force"} or \
                            not isinstance(body["force"], bool):
                        raise Invalid('release takes {"force": true|false} or nothing')
                    self._may_act(job_id, "release")
                    return self._json(200, self._job(self.srv.release(job_id, body["force"])))
                if method == "POST" and len(route) == 3 and route[2] == "move":
                    if not isinstance(body, dict) or set(body) != {"printer"} or \
                            not isinstance(body["printer"], (str, type(None))):
                        raise Invalid('expected {"printer": NAME|"any"}')
                    self._may_act(job_id, "move")
                    return self._json(200, self._job(self.srv.move(job_id, body["printer"])))
                if method == "POST" and len(route) == 3 and route[2] in ("cancel", "hold", "release",
                                                                          "requeue"):
                    if body:
                        raise Invalid(f"{route[2]} takes no parameters")
                    self._may_act(job_id, route[2])
                    job = getattr(self.srv, route[2])(job_id)
                    if route[2] == "cancel" and job["state"] == "printing":
                        # told to stop, not stopped yet: the client follows the job to its end
                        return self._json(202, dict(self._job(job), cancelling=True))
                    return self._json(200, self._job(job))
            raise Invalid(f"no such endpoint {method} {url.path[:80]}", 404)
        except Invalid as exc:
            return self._error(exc.status, str(exc))
        except SpoolError as exc:
            return self._error(exc.status, str(exc))
        except (TimeoutError, *GONE):
            raise                                      # the connection's end: handled above
        except ValueError as exc:
            return self._error(400, str(exc))
        except (sqlite3.OperationalError, OSError) as exc:
            why = storage_full(exc)
            if why is None:
                log.exception("api %s %s %s", self.client_address[0], method, _shown(self.path))
                return self._error(500, f"internal error: {type(exc).__name__}: {exc}",
                                   close=True, quiet=True)
            log.error("api %s %s %s: %s", self.client_address[0], method, _shown(self.path), exc)
            return self._error(507, why, close=bool(self._body_left), quiet=True)
        except Exception as exc:  # noqa: BLE001 - a bug: the client still gets an answer
            log.exception("api %s %s %s", self.client_address[0], method, _shown(self.path))
            return self._error(500, f"internal error: {type(exc).__name__}: {exc}", close=True,
                               quiet=True)

    def _web(self, method: str, path: str) -> None:
        """The shop's web page (web.py, docs/web.md): its files (no login needed: they hold
        no data), and `/login`, `/session`, `/logout`."""
        extra = dict(web.SECURITY_HEADERS)
        try:
            self._length = self._body_length()
            self._body_left = self._length or 0
            if path in web.STATIC:
                if method != "GET" or self._length:
                    raise Invalid(f"{path} is a page: GET it", 405 if method != "GET" else 400)
                page = web.static_file(path)
                assert page is not None
                return self._send(200, page[0], page[1], extra=extra)
            sessions = self.server.sessions
            sid = web.parse_cookie(self.headers.get_all("Cookie") or [])
            host = self.headers.get("Host")
            if path == "/session" and method == "GET":
                found = sessions.identity(sid, "GET", self.headers, host)
                if found is None:
                    return self._json(401, {"error": "not signed in"}, extra=extra)
                who, s = found
                return self._json(200, {"name": who.name, "role": who.role, "csrf": s.csrf},
                                  extra=extra)
            if method != "POST" or path == "/session":
                raise Invalid(f"{path}: POST it", 405)
            if path == "/logout":
                self._read_json()
                if sessions.identity(sid, "POST", self.headers, host) is not None:
                    sessions.logout(sid)
                extra["Set-Cookie"] = web.cookie("", clear=True)
                return self._json(200, {"signed_out": True}, extra=extra)
            # /login: JSON only (a cross-site form cannot send it without a preflight) and
            # from this origin; throttled per address; a wrong token gets nothing
            ctype = (self.headers.get("Content-Type") or "").split(";")[0].strip().lower()
            if ctype != "application/json":
                raise Invalid("send the login as application/json", 415)
            if not web.same_origin(self.headers, host):
                raise Invalid("a login from another site's page is refused", 403)
            address = self.client_address[0]
            if sessions.throttled(address):
                raise Invalid(f"too many wrong logins from {address}: wait "
                              f"{int(web.LOGIN_WINDOW_S / 60)} minutes", 429)
            body = self._read_json()
            if not isinstance(body, dict) or set(body) - {"token", "name"}:
                raise Invalid('expected {"token": TOKEN, "name": YOUR NAME}')
            made = sessions.login(address, body.get("token"), body.get("name"))
            if made is None:
                log.info("api %s: a web login with a wrong token", address)
                return self._json(401, {"error": "wrong token"}, extra=extra)
            sid, s, who = made
            log.info("api %s: %s signed in to the web page", address, who.shown())
            extra["Set-Cookie"] = web.cookie(
                sid, secure=(self.headers.get("X-Forwarded-Proto") or "").lower() == "https")
            return self._json(200, {"name": who.name, "role": who.role, "csrf": s.csrf},
                              extra=extra)
        except (Invalid, ValueError) as exc:
            status = exc.status if isinstance(exc, Invalid) else 400
            return self._error(status, str(exc), close=bool(self._body_left))

    def _cut_file(self, job_id: int, name: str) -> bytes:
        """A print-and-cut job's cut file (docs/cut.md): as its rip wrote it, or, for a job
        not ripped yet (queued, held: its settings may have been edited), made now from its
        spooled file (the GUI's preview)."""
        import os
        from ...rip.cutfile import server_cut_path, write_cut_files
        from .validate import job_rip_settings
        path = server_cut_path(self.srv.state_dir, job_id, name)
        job = self.srv.spool.get(job_id)
        if job is None:
            raise Invalid(f"no job {job_id}", 404)
        if not os.path.exists(path) or job["state"] in ("queued", "held"):
            rs, media_profile = job_rip_settings(job["settings"], self.srv.profile, self.srv.state_dir)
            if rs.placement.marks != "cut":
                raise Invalid(f"job {job_id} has no cut file: it is not a print-and-cut job "
                              f"(placement marks cut)", 404)
            if not job.get("spool_path"):
                raise Invalid(f"job {job_id}: its file is no longer spooled", 410)
            write_cut_files(self.srv.state_dir, job_id, [job["spool_path"]], rs, media_profile)
        with open(path, "rb") as fh:
            return fh.read()

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
                priority=req["priority"], hold=req["hold"] if "hold" in raw else None,
                key=req["key"], client=req["client"], printer=req["printer"],
                force=req["force"], rip_hold=req["rip_hold"], fit=True)
        except Invalid as exc:
            self.close_connection = True
            return self._error(exc.status, str(exc), close=True)
        except (TimeoutError, *GONE):
            raise
        except (OSError, sqlite3.OperationalError) as exc:  # the spool's disk: full, read-only
            why = storage_full(exc)
            if why is None and isinstance(exc, sqlite3.OperationalError):
                raise
            log.error("api: cannot spool %s: %s", req["name"], exc)
            return self._error(507, why or f"the server cannot store the file: "
                               f"{exc.strerror or exc}", close=True, quiet=True)
        self._body_left = 0
        if not created:
            return self._json(200, dict(self._job(job), duplicate=True))
        owner = self.who.name
        if owner is not None:
            try:
                self.server.owners.set(job["id"], owner)
            except (OSError, sqlite3.OperationalError) as exc:
                # queued, but its owner not recorded: the operator's job alone (fails closed)
                log.error("job %s: its owner %s could not be recorded (%s): only an operator "
                          "may act on it", job["id"], owner, exc)
        srv.notify()
        self._json(201, dict(self._job(job), duplicate=False))

    def do_GET(self):
        self._dispatch("GET")

    def do_POST(self):
        self._dispatch("POST")

    def do_PATCH(self):
        self._dispatch("PATCH")

    def do_DELETE(self):
        self._dispatch("DELETE")


# -- the listener -----------------------------------------------------------------------------------
def _answer(status: int, message: str, extra: dict | None = None) -> bytes:
    """A whole error answer (JSON, connection closed), as the listener sends it itself."""
    body = (json.dumps({"error": message}) + "\n").encode()
    head = [f"HTTP/1.1 {status} {HTTPStatus(status).phrase}", "Content-Type: application/json",
            "Cache-Control: no-store", "Connection: close", f"Content-Length: {len(body)}"]
    head += [f"{k}: {v}" for k, v in (extra or {}).items()]
    return ("\r\n".join(head) + "\r\n\r\n").encode() + body


def _busy_answer(limit: int) -> bytes:
    return _answer(503, f"the server is busy ({limit} requests being served, the limit); "
                        "try again", {"Retry-After": "1"})


HEAD_LIMIT = 256 * 1024                 # a request head larger than this: 431
LIGHT = re.compile(rb"(?im)^(?:content-length[ \t]*:[ \t]*0*[1-9]|content-length[ \t]*:[ \t]*[^0-9\s]"
                   rb"|transfer-encoding[ \t]*:)")


class _Head:
    """A connection whose request head is being read by the listener (no thread): its
    bytes so far, where the scan for the head's end stopped, and its deadline."""

    __slots__ = ("sock", "addr", "deadline", "buf", "pos", "searched", "empties", "lines",
                 "phase")

    def __init__(self, sock, addr, deadline: float, data: bytes = b""):
        self.sock, self.addr, self.deadline = sock, addr, deadline
        self.buf = bytearray(data)
        self.pos = self.searched = self.empties = self.lines = self.phase = 0

    def scan(self) -> str:
        """"ready": a thread can take the request without waiting for the client (the head
        is complete, or malformed in a way the handler answers from what is here: too many
        blank lines, a line over MAX_LINE, more than 100 header lines); "large": more than
        HEAD_LIMIT and not complete (431); "more": keep reading.  Incremental: each byte is
        looked at once, however the head trickles in."""
        buf = self.buf
        while True:
            nl = buf.find(b"\n", max(self.pos, self.searched))
            if nl < 0:
                self.searched = len(buf)
                if len(buf) - self.pos > MAX_LINE:
                    return "ready"
                return "large" if len(buf) > HEAD_LIMIT else "more"
            line_end, start = nl + 1, self.pos
            self.pos = self.searched = line_end
            blank = line_end - start <= 2 and buf[start:line_end] in (b"\n", b"\r\n")
            if self.phase == 0:                     # before the request line
                if blank:
                    self.empties += 1
                    if self.empties > 4:            # the handler skips four
                        return "ready"
                    continue
                self.phase = 1
                continue
            if blank:
                return "ready"                      # the end of the head
            self.lines += 1
            if self.lines > 100:
                return "ready"
            if len(buf) > HEAD_LIMIT:
                return "large"

    def light(self) -> bool:
        """A GET without a body that ends at once (not an event stream): such requests may
        use the threads kept for them, which bodies and streams cannot take."""
        first = bytes(self.buf[:self.pos]).lstrip(b"\r\n").split(b"\r\n", 1)[0].split(b"\n", 1)[0]
        words = first.split()
        if len(words) != 3 or words[0] != b"GET" or words[1].startswith(b"/v1/events"):
            return False
        return LIGHT.search(self.buf, 0, self.pos) is None


class _HTTPServer(socketserver.TCPServer):
    """The API's listener (docs/server.md, "The API: the rules").  One thread (the
    selector) accepts connections and reads their request heads without a thread each; a
    complete head goes to a handler thread, at most `max_connections` at once, of which
    requests with a body and event streams may take all but a quarter (kept for plain
    GETs, so slow uploads cannot lock out a status call); a request beyond that gets 503
    (Retry-After: 1) at once.  A kept-alive connection comes back to the selector to await
    its next head.  A head must arrive within the idle timeout of the connection's start
    (or of the previous answer): 408 then (silence: closed without a word); one beyond
    HEAD_LIMIT: 431.  Waiting heads cost a socket and their bytes, no thread: when more
    wait than the process's file descriptors allow, the oldest is closed."""

    allow_reuse_address = True
    request_queue_size = 1024
    REJECT_WAIT_S = 0.5              # a refused client is given this long to read and close

    def __init__(self, address, handler, max_connections: int = 32):
        super().__init__(address, handler)
        srv = getattr(handler, "srv", None)
        self.idle = float(getattr(getattr(srv, "config", None), "api_timeout_s",
                                  DEFAULT_API_TIMEOUT_S))
        if srv is not None:
            add_secret(getattr(srv, "token", "") or "")
            self.users = Users(srv.state_dir, getattr(srv, "token", None))
            self.owners = Owners(srv.spool)
            self.sessions = web.Sessions(lambda t: token_identity(srv.token, self.users, t))
        self.max_connections = max(1, int(max_connections))
        self.max_heavy = max(1, self.max_connections - self.max_connections // 4)
        self._busy = _busy_answer(self.max_connections)
        self._count = self._heavy = 0
        self._slots = threading.Lock()
        self._back: queue.SimpleQueue = queue.SimpleQueue()
        self._wake_r, self._wake_w = socket.socketpair()
        self._wake_r.setblocking(False)
        self._wake_w.setblocking(False)
        self._stop = threading.Event()
        self._done = threading.Event()
        self._done.set()
        self.max_waiting = self._fd_room()
        self._warned: dict[str, list] = {}

    def _fd_room(self) -> int:
        """How many connections may wait for their head: the process's file descriptors
        (its soft limit raised to the hard one, at most 65536) less a margin."""
        try:
            import resource
            soft, hard = resource.getrlimit(resource.RLIMIT_NOFILE)
            want = 65536 if hard == resource.RLIM_INFINITY else min(hard, 65536)
            if soft != resource.RLIM_INFINITY and soft < want:
                resource.setrlimit(resource.RLIMIT_NOFILE, (want, hard))
                soft = want
        except (ImportError, ValueError, OSError):
            soft = 1024
        return max(16, min(16384, (soft if soft > 0 else 1024) - 128 - 2 * self.max_connections))

    def _warn(self, what: str, fmt: str) -> None:
        """At most one warning in ten seconds for each kind, with the count since the last."""
        w = self._warned.setdefault(what, [0.0, 0])
        w[1] += 1
        now = time.monotonic()
        if now - w[0] >= 10:
            log.warning(fmt, w[1])
            w[0], w[1] = now, 0

    # -- the selector thread --------------------------------------------------------------------
    def serve_forever(self, poll_interval: float = 0.5) -> None:
        self._done.clear()
        sel = selectors.DefaultSelector()
        heads: dict = {}                       # socket -> _Head, in deadline order
        draining: dict = {}                    # socket -> deadline (answered, closing)
        self.socket.setblocking(False)
        sel.register(self.socket, selectors.EVENT_READ, "listen")
        sel.register(self._wake_r, selectors.EVENT_READ, "wake")

        def forget(sock) -> None:
            heads.pop(sock, None)
            draining.pop(sock, None)
            try:
                sel.unregister(sock)
            except (KeyError, ValueError):
                pass

        def close(sock) -> None:
            forget(sock)
            try:
                sock.close()
            except OSError:
                pass

        def answer_and_close(sock, data: bytes) -> None:
            forget(sock)
            try:
                sock.send(data)                      # small: fits the socket's buffer
                sock.shutdown(socket.SHUT_WR)
            except OSError:
                return close(sock)
            draining[sock] = time.monotonic() + self.REJECT_WAIT_S
            sel.register(sock, selectors.EVENT_READ, "drain")

        def hand_over(h: _Head) -> None:
            forget(h.sock)
            heavy = not h.light()
            with self._slots:
                ok = self._count < self.max_connections and (not heavy or
                                                             self._heavy < self.max_heavy)
                if ok:
                    self._count += 1
                    self._heavy += heavy
            if not ok:
                self._warn("busy", f"api: {self.max_connections} requests being served, the "
                                   f"limit: %d request(s) answered 503")
                return answer_and_close(h.sock, self._busy)
            t = threading.Thread(target=self._serve, args=(h, heavy), name="wideprint-api-conn",
                                 daemon=True)
            try:
                t.start()
            except RuntimeError as exc:                  # no thread to be had
                self._release(heavy)
                log.warning("api: cannot start a thread (%s); connection closed", exc)
                close(h.sock)

        def add(sock, addr, data: bytes) -> None:
            try:
                sock.setblocking(False)
                h = _Head(sock, addr, time.monotonic() + self.idle, data)
                sel.register(sock, selectors.EVENT_READ, h)
            except (OSError, ValueError):
                return close(sock)
            heads[sock] = h
            verdict = h.scan() if data else "more"
            if verdict != "more":
                return examine(h, verdict)
            while len(heads) > self.max_waiting:       # the oldest waiting head goes
                old = next(iter(heads.values()))
                self._warn("shed", f"api: more than {self.max_waiting} connections waiting for "
                                   f"their request head: %d of the oldest closed")
                close(old.sock)

        def examine(h: _Head, verdict: str) -> None:
            if verdict == "ready":
                return hand_over(h)
            if verdict == "large":
                log.info("api %s: request head larger than %d bytes; closed", h.addr[0],
                         HEAD_LIMIT)
                return answer_and_close(h.sock, _answer(431, f"request head larger than "
                                                             f"{HEAD_LIMIT} bytes"))

        def read(h: _Head) -> None:
            try:
                data = h.sock.recv(65536)
            except (BlockingIOError, InterruptedError):
                return
            except OSError as exc:
                log.debug("api %s: the client went away (%s)", h.addr[0], type(exc).__name__)
                return close(h.sock)
            if not data:                               # the client closed its side
                if h.buf.strip():
                    return hand_over(h)                # what it sent is answered
                return close(h.sock)
            h.buf += data
            examine(h, h.scan())

        def expire(h: _Head) -> None:
            if h.buf.strip():
                why = f"request head not complete within {self.idle:g} s"
                log.info("api %s: %s; closed", h.addr[0], why)
                answer_and_close(h.sock, _answer(408, why))
            else:
                log.debug("api %s: idle connection closed after %g s", h.addr[0], self.idle)
                close(h.sock)

        def accept() -> None:
            for _ in range(256):
                try:
                    sock, addr = self.socket.accept()
                except (BlockingIOError, InterruptedError):
                    return
                except OSError as exc:                 # out of descriptors (EMFILE, ENFILE)
                    self._warn("accept", f"api: cannot accept connections ({exc.strerror}): "
                                         f"%d time(s); the oldest waiting one closed")
                    if heads:
                        close(next(iter(heads)))
                    else:
                        time.sleep(0.05)
                    return
                add(sock, addr, b"")

        try:
            while not self._stop.is_set():
                now = time.monotonic()
                due = [next(iter(heads.values())).deadline] if heads else []
                if draining:
                    due.append(next(iter(draining.values())))
                first = min(due, default=now + poll_interval)
                for key, _ in sel.select(max(0.0, min(poll_interval, first - now))):
                    kind = key.data
                    if kind == "listen":
                        accept()
                    elif kind == "wake":
                        try:
                            while self._wake_r.recv(4096):
                                pass
                        except (BlockingIOError, InterruptedError):
                            pass
                    elif kind == "drain":
                        sock = key.fileobj
                        try:
                            if not sock.recv(65536):
                                close(sock)            # the client read the answer and closed
                        except (BlockingIOError, InterruptedError):
                            pass
                        except OSError:
                            close(sock)
                    elif key.fileobj in heads:
                        read(kind)
                while True:                            # kept-alive connections, back
                    try:
                        sock, addr, data = self._back.get_nowait()
                    except queue.Empty:
                        break
                    add(sock, addr, data)
                now = time.monotonic()
                while heads:
                    h = next(iter(heads.values()))
                    if h.deadline > now:
                        break
                    expire(h)
                while draining:
                    sock, deadline = next(iter(draining.items()))
                    if deadline > now:
                        break
                    close(sock)
        finally:
            for sock in list(heads) + list(draining):
                close(sock)
            while True:
                try:
                    self._back.get_nowait()[0].close()
                except queue.Empty:
                    break
            for sock in (self.socket, self._wake_r):
                try:
                    sel.unregister(sock)
                except (KeyError, ValueError):
                    pass
            sel.close()
            self._done.set()

    def _wake(self) -> None:
        try:
            self._wake_w.send(b"x")
        except OSError:
            pass                                 # full: it is awake already

    def _release(self, heavy: bool) -> None:
        with self._slots:
            self._count -= 1
            self._heavy -= heavy

    # -- a handler thread -------------------------------------------------------------------------
    def _serve(self, h: _Head, heavy: bool) -> None:
        sock, keep = h.sock, None
        try:
            sock.setblocking(True)
            sock.settimeout(self.idle)
            cls = self.RequestHandlerClass
            handler = cls.__new__(cls)
            handler._prefetch = bytes(h.buf)
            handler.__init__(sock, h.addr, self)
            keep = handler.keep
        except Exception:  # noqa: BLE001 - logged by handle_error, the thread goes on
            self.handle_error(sock, h.addr)
        finally:
            self._release(heavy)
            if keep is not None and not self._stop.is_set():
                self._back.put((sock, h.addr, keep))
                self._wake()
            else:
                self.shutdown_request(sock)

    def handle_error(self, request, client_address) -> None:
        exc = sys.exc_info()[1]
        if isinstance(exc, (*GONE, TimeoutError)):
            log.info("api %s: the client went away (%s)", client_address[0], type(exc).__name__)
        else:
            log.error("api %s: unexpected error", client_address[0], exc_info=True)

    def shutdown(self) -> None:
        self._stop.set()
        self._wake()
        self._done.wait()

    def server_close(self) -> None:
        self._stop.set()
        self._wake()
        super().server_close()
        for sock in (self._wake_r, self._wake_w):
            sock.close()
