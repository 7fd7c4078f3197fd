"""The HTTP API's routes declared once (app/server/routes.py) and checked both ways: the
table equals docs/server.md's, every declared route reaches its handler on a live server,
and anything undeclared is refused before its body is read (404, or 405 with Allow)."""

import json
import re
import socket
from pathlib import Path

import numpy as np
import pytest
import tifffile

from wideprint.app.server.routes import ROUTES, find

DOC = Path(__file__).resolve().parent.parent / "docs" / "server.md"


def documented() -> set[tuple[str, str]]:
    """(method, path) of every row of docs/server.md's API table ({id}, {name} for ID, NAME)."""
    text = DOC.read_text()
    section = text[text.index("## The API"):]
    section = section[:section.index("\n## ", 5)]
    out = set()
    for line in section.splitlines():
        if not line.startswith("| `"):
            continue
        cell = line.split("|")[1]
        method, base = None, None
        for code in re.findall(r"`([^`]+)`", cell):
            code = re.sub(r"\[[^\]]*\]", "", code).strip()
            m = re.match(r"(GET|POST|PATCH|DELETE|PUT) (\S+)$", code)
            if m:
                method, path = m.groups()
            elif method is not None:          # a sibling: `cut.dxf` or `/release`
                path = base.rsplit("/", 1)[0] + "/" + code.lstrip("/")
            else:
                continue
            base = path
            out.add((method, path.replace("ID", "{id}").replace("NAME", "{name}")))
    return out


def test_the_declared_routes_are_the_documented_ones():
    declared = {(r.method, r.path) for r in ROUTES}
    doc = documented()
    assert declared - doc == set(), "declared but not in docs/server.md's API table"
    assert doc - declared == set(), "in docs/server.md's API table but not declared"


def test_find_matches_ids_names_and_nothing_else():
    assert find("GET", ["v1", "jobs", "12", "preview.png"]).path == "/v1/jobs/{id}/preview.png"
    assert find("POST", ["v1", "printers", "left", "pause"]).path == "/v1/printers/{name}/pause"
    assert find("DELETE", ["v1", "jobs", "12"]) is None
    assert find("GET", ["v1", "jobs", "12", "preview", "x"]) is None
    assert find("GET", ["v2", "status"]) is None


def request(srv, method, path, body=b"", token=None):
    token = token or (srv.state_dir / "token").read_text().strip()
    with socket.create_connection(("127.0.0.1", srv.port), timeout=30) as s:
        s.sendall(f"{method} {path} HTTP/1.1\r\nHost: x\r\nAuthorization: Bearer {token}\r\n"
                  f"Content-Length: {len(body)}\r\nConnection: close\r\n\r\n".encode() + body)
        data = b""
        while chunk := s.recv(65536):
            data += chunk
    head, _, payload = data.partition(b"\r\n\r\n")
    lines = head.decode("latin-1").split("\r\n")
    status = int(lines[0].split()[1])
    headers = dict(ln.split(": ", 1) for ln in lines[1:] if ": " in ln)
    return status, headers, payload


@pytest.fixture(scope="module")
def server(tmp_path_factory):
    from wideprint.app.server import PrintServer, ServerConfig
    tmp = tmp_path_factory.mktemp("routes")
    srv = PrintServer(ServerConfig(state_dir=tmp / "state", media_dir=tmp / "media", port=0,
                                   start_paused=True))
    srv.start()
    from wideprint.app.client import Client
    client = Client(srv.state_dir)
    src = tmp / "a.tif"
    tifffile.imwrite(src, np.full((20, 30, 4), 60, np.uint8), photometric="separated")
    job = client.submit(src, settings={"placement": {"size": "pixels"}})["job"]
    client.close()
    yield srv, job["id"]
    srv.stop(timeout=5)


LAST = ("/v1/estop",)                         # it stops the printers: probed last
#: POST /v1/shutdown ends the serving process, here pytest's own: a server process answers
#: it in tests/test_server.py
NOT_HERE = ("/v1/shutdown",)


def test_every_declared_route_reaches_its_handler(server):
    srv, job_id = server
    printer = next(iter(srv.workers))
    order = sorted((r for r in ROUTES if r.path not in NOT_HERE), key=lambda r: r.path in LAST)
    for r in order:
        path = r.path.replace("{id}", str(job_id)).replace("{name}", printer)
        if r.path == "/v1/events":
            path += "?max_s=0.5"                   # a stream: ended by the server
        body = b"{}" if r.method in ("POST", "PATCH") and r.path != "/v1/jobs" else b""
        status, _, payload = request(srv, r.method, path, body)
        doc = json.loads(payload) if payload.lstrip().startswith(b"{") else {}
        error = doc.get("error") or "" if isinstance(doc, dict) else ""
        assert status != 405 and "no such endpoint" not in error, (r, status, error)


def test_an_undeclared_route_is_refused_404_or_405_with_allow(server):
    srv, job_id = server
    status, _, payload = request(srv, "GET", "/v1/nothing-here")
    assert status == 404 and b"no such endpoint" in payload
    status, headers, payload = request(srv, "DELETE", f"/v1/jobs/{job_id}")
    assert status == 405, payload
    assert headers.get("Allow") == "GET, PATCH"
