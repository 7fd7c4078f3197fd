"""The HTTP API's routes, declared once (docs/server.md "The API").

The dispatcher (app/server/api.py) answers 404 or 405 for any method and path that is not
here, before it reads a byte of the request's body; tests/test_routes.py checks this table
against docs/server.md's and sends every route to a live server, so the code, this table
and the docs cannot drift apart.  The web page's own paths (`/`, its files, its login) are
app/server/web.py's and not part of the versioned API.

Standard library only: the dispatcher consults it for every request.
"""

from __future__ import annotations

from dataclasses import dataclass


@dataclass(frozen=True)
class Route:
    method: str
    path: str           # {id}: a job id; {name}: a printer's name

    @property
    def parts(self) -> tuple[str, ...]:
        return tuple(p for p in self.path.split("/") if p)


def _jobs(*actions: str, method: str = "POST") -> list[tuple[str, str]]:
    return [(method, f"/v1/jobs/{{id}}/{a}") for a in actions]


def _printers(*actions: str, method: str = "POST") -> list[tuple[str, str]]:
    return [(method, f"/v1/printers/{{name}}/{a}") for a in actions]


ROUTES: tuple[Route, ...] = tuple(Route(m, p) for m, p in (
    ("GET", "/v1/status"),
    ("GET", "/v1/events"),
    ("POST", "/v1/queue"),
    ("POST", "/v1/shutdown"),
    ("POST", "/v1/estop"),
    ("GET", "/v1/jobs"),
    ("POST", "/v1/jobs"),
    ("GET", "/v1/jobs/{id}"),
    ("PATCH", "/v1/jobs/{id}"),
    *_jobs("preview", "preview.png", "proof.png", "cut.plt", "cut.dxf", "fit", method="GET"),
    *_jobs("cancel", "hold", "release", "requeue", "move", "rip-hold", "reprint"),
    ("GET", "/v1/printers"),
    *_printers("media.png", "roll", method="GET"),
    *_printers("roll", "pause", "resume", "clear-fault", "test-print", "head-care"),
    ("GET", "/v1/presets"),
    ("POST", "/v1/presets/reload"),
    ("GET", "/v1/report"),
    ("GET", "/v1/prices"),
    ("POST", "/v1/prices"),
))


def _matches(route: Route, parts: list[str]) -> bool:
    want = route.parts
    return len(want) == len(parts) and all(
        w == p or (w.startswith("{") and w.endswith("}") and p != "") for w, p in zip(want, parts))


def find(method: str, parts: list[str]) -> Route | None:
    """The declared route of a request (its path split at '/', empty parts dropped)."""
    for r in ROUTES:
        if r.method == method and _matches(r, parts):
            return r
    return None


def methods(parts: list[str]) -> list[str]:
    """The methods declared for a path (405 and its Allow header when the method is not)."""
    return sorted({r.method for r in ROUTES if _matches(r, parts)})
