"""The shop's web page at the root of the API's address (docs/web.md): its static files,
read from the package by a fixed table (never from a path a client names), and the
browser's login — a session cookie that stands for the token the person typed.

A browser cannot send `Authorization: Bearer`, so `POST /login` takes the token once (the
operator's `token` file or a user's, `wideprint users add`) and answers with a session
cookie (`HttpOnly`: no script reads it; `SameSite=Strict`: no other site's page sends it;
`Path=/`).  A request that carries the cookie is the session's person, with the role
the token has *now*: the token is checked again on every request, so a user removed or a
token replaced ends its sessions at once (authentication fails closed).  A request that
changes something must also carry `X-Wideprint-CSRF` with the session's own random value
(the page holds it in memory; another site can neither read it nor set the header without
a CORS preflight the server never grants) and, when the browser sends `Origin` or
`Sec-Fetch-Site`, come from this very origin.  Sessions live in the server's memory (a
restart signs everyone out), end after SESSION_IDLE_S idle or SESSION_MAX_S in all, or at
`POST /logout`.  Failed logins from one address are limited (LOGIN_FAILS a LOGIN_WINDOW_S:
429 after that), so a token cannot be guessed through the page any faster than through
the API.
"""

from __future__ import annotations

import hmac
import secrets
import threading
import time
from dataclasses import dataclass, field
from importlib import resources

from .auth import OPERATOR, Identity, claimed_name

COOKIE = "wideprint_session"
CSRF_HEADER = "X-Wideprint-CSRF"
SESSION_IDLE_S = 8 * 3600           # a shift without touching the page signs out
SESSION_MAX_S = 24 * 3600           # and every session ends within a day
MAX_SESSIONS = 256                  # the oldest goes first beyond this
LOGIN_FAILS = 10                    # failed logins a client address may make ...
LOGIN_WINDOW_S = 300.0              # ... in this many seconds
MAX_TOKEN_FIELD = 512               # longer than any token

#: what the page is made of: request path -> (file in app/web/, content type).  The only
#: files ever served: a path not in this table is the API's (and so needs a login).
STATIC = {
    "/": ("index.html", "text/html; charset=utf-8"),
    "/index.html": ("index.html", "text/html; charset=utf-8"),
    "/web/app.js": ("app.js", "text/javascript; charset=utf-8"),
    "/web/app.css": ("app.css", "text/css; charset=utf-8"),
    "/web/favicon.svg": ("favicon.svg", "image/svg+xml"),
}
#: the page's own routes (no bearer token: they make or end the session)
SESSION_ROUTES = ("/login", "/logout", "/session")

#: every answer of the page's routes: nothing but the page's own files and API, never in a frame
SECURITY_HEADERS = {
    "Content-Security-Policy": ("default-src 'none'; script-src 'self'; style-src 'self'; "
                                "img-src 'self' data:; connect-src 'self'; "
                                "frame-ancestors 'none'; base-uri 'none'; form-action 'self'"),
    "X-Content-Type-Options": "nosniff",
    "X-Frame-Options": "DENY",
    "Referrer-Policy": "no-referrer",
}


def static_file(path: str) -> tuple[bytes, str] | None:
    """The page's file for a request path (its bytes, content type), None when the path is
    not one of the page's.  Read from the installed package (setup.cfg package_data)."""
    entry = STATIC.get(path)
    if entry is None:
        return None
    name, ctype = entry
    return (resources.files("wideprint.app") / "web" / name).read_bytes(), ctype


@dataclass
class Session:
    token: str                      # what the person typed: checked again on every request
    name: str | None                # who they said they are (an operator token) or the user
    csrf: str
    created: float = field(default_factory=time.monotonic)
    used: float = field(default_factory=time.monotonic)


def parse_cookie(header_values: list[str]) -> str | None:
    """The session id from the request's Cookie headers (None: none, or more than one)."""
    found = []
    for value in header_values:
        for part in value.split(";"):
            k, eq, v = part.strip().partition("=")
            if eq and k == COOKIE:
                found.append(v.strip())
    return found[0] if len(found) == 1 and found[0] else None


def same_origin(headers, host: str | None) -> bool:
    """Whether a browser says the request comes from this page's own origin.  A request
    without `Origin` and `Sec-Fetch-Site` (not a browser's, or an old one) is judged by
    its CSRF value alone."""
    site = headers.get("Sec-Fetch-Site")
    if site is not None and site not in ("same-origin", "none"):
        return False
    origin = headers.get("Origin")
    if origin is not None:
        scheme, _, rest = origin.partition("://")
        return scheme in ("http", "https") and bool(host) and rest == host
    return True


class Sessions:
    """The web page's sessions and failed-login counts (in memory, thread-safe).
    `check(token)` is the API's own token check: Identity or None."""

    def __init__(self, check):
        self._check = check
        self._by_id: dict[str, Session] = {}
        self._fails: dict[str, list[float]] = {}
        self._lock = threading.Lock()

    # -- login ------------------------------------------------------------------------------------
    def throttled(self, address: str) -> bool:
        now = time.monotonic()
        with self._lock:
            recent = [t for t in self._fails.get(address, []) if now - t < LOGIN_WINDOW_S]
            if recent:
                self._fails[address] = recent
            else:
                self._fails.pop(address, None)
            return len(recent) >= LOGIN_FAILS

    def login(self, address: str, token, name) -> tuple[str, Session, Identity] | None:
        """A new session for a right token (sid, session, who), None for a wrong one (and the
        failure counted against `address`).  `name`: whom an operator token acts for (as
        X-Wideprint-User); a user token is its user whatever is typed."""
        if not isinstance(token, str) or len(token) > MAX_TOKEN_FIELD:
            token = ""
        token = token.strip()
        who = self._check(token) if token else None
        if who is None:
            with self._lock:
                self._fails.setdefault(address, []).append(time.monotonic())
            return None
        shown = None
        if who.operator and isinstance(name, str) and name.strip():
            shown = claimed_name(name)               # ValueError: the page says why
            who = Identity(shown, OPERATOR)
        sid = secrets.token_urlsafe(32)
        session = Session(token=token, name=shown if who.operator else who.name,
                          csrf=secrets.token_urlsafe(24))
        with self._lock:
            self._expire()
            while len(self._by_id) >= MAX_SESSIONS:
                oldest = min(self._by_id, key=lambda k: self._by_id[k].used)
                del self._by_id[oldest]
            self._by_id[sid] = session
            self._fails.pop(address, None)
        return sid, session, who

    def logout(self, sid: str | None) -> None:
        with self._lock:
            self._by_id.pop(sid or "", None)

    # -- requests ---------------------------------------------------------------------------------
    def _expire(self) -> None:
        now = time.monotonic()
        for sid in [k for k, s in self._by_id.items()
                    if now - s.used > SESSION_IDLE_S or now - s.created > SESSION_MAX_S]:
            del self._by_id[sid]

    def get(self, sid: str | None) -> Session | None:
        if not sid:
            return None
        with self._lock:
            self._expire()
            for key, s in self._by_id.items():           # constant time for each compared
                if hmac.compare_digest(key.encode(), sid.encode()):
                    s.used = time.monotonic()
                    return s
        return None

    def identity(self, sid: str | None, method: str, headers, host: str | None
                 ) -> tuple[Identity, Session] | None:
        """Who a cookie's request is, None when it is nobody: no such session, a token no
        longer valid (the session ends), or a change (not GET) without the session's CSRF
        value or from another origin."""
        s = self.get(sid)
        if s is None:
            return None
        who = self._check(s.token)
        if who is None:
            self.logout(sid)
            return None
        if method != "GET":
            sent = headers.get(CSRF_HEADER) or ""
            if not hmac.compare_digest(sent.encode(), s.csrf.encode()) or \
                    not same_origin(headers, host):
                return None
        if who.operator and s.name:
            who = Identity(s.name, OPERATOR)
        return who, s

    def count(self) -> int:
        with self._lock:
            self._expire()
            return len(self._by_id)


def cookie(sid: str, clear: bool = False, secure: bool = False) -> str:
    """The Set-Cookie value: HttpOnly, SameSite=Strict, the whole site; a session cookie
    (gone when the browser closes), or one that deletes it.  `secure`: the page was
    reached over HTTPS (a TLS proxy in front says `X-Forwarded-Proto: https`), so the
    browser is told never to send the cookie over plain HTTP."""
    tail = ("; Max-Age=0" if clear else "") + ("; Secure" if secure else "")
    return f"{COOKIE}={'' if clear else sid}; Path=/; HttpOnly; SameSite=Strict{tail}"
