"""The local HTTP/JSON API with a bearer token (docs/server.md, "API")."""

from __future__ import annotations

import hmac
import json
import logging
import os
from http.server import BaseHTTPRequestHandler, ThreadingHTTPServer
from typing import TYPE_CHECKING
from urllib.parse import parse_qs, urlsplit

from .config import PRIORITY_RANGE
from .spool import SpoolError
from .validate import Invalid, _check_int, validate_job_request

if TYPE_CHECKING:
    from .core import PrintServer

log = logging.getLogger("wideprint.server")


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
