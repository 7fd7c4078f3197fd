"""The CUPS backend `resources/cups/wideprint` run as cupsd runs it (argv job-id user title
copies options [file], DEVICE_URI in the environment, the job on stdin when there is no
file), against a real `wideprint serve`, against no server, and against small fake
servers for what a real one rarely does.  No cupsd needed (tests/test_cups.py has that).

Every case checks the CUPS exit code of docs/server.md ("CUPS", exit codes) and that
stderr is only `LEVEL: one line` messages, never a traceback."""

import json
import os
import shutil
import signal
import socket
import subprocess
import threading
import time
from pathlib import Path

import pytest

from support.cups_backend import (CANCEL, FAILED, MAX_FILE, OK,
                                  RETRY, STOP, backend_cmd, check_stderr, run_backend, uri_of)
from support.images import random_planes, write_cmyk_tiff
from support.server import ServerProcess

# -- a real server ------------------------------------------------------------------------------
@pytest.fixture(scope="module")
def server(tmp_path_factory):
    srv = ServerProcess(tmp_path_factory.mktemp("cupsbk") / "state", "--paused",
                        "--max-file-size", str(MAX_FILE))
    yield srv.state, srv.client
    srv.stop()


@pytest.fixture(scope="module")
def tiff(tmp_path_factory):
    return write_cmyk_tiff(tmp_path_factory.mktemp("img") / "in.tif", random_planes(20, 30, seed=3))


def jobs_named(client, name):
    return [j for j in client.jobs() if j["name"] == name]


def test_a_file_is_queued(server, tiff):
    state, client = server
    r = run_backend(uri_of(state), file=tiff, title="/home/alice/poster.tif",
                    options="WPPasses=2 WPBidir=True job-uuid=urn:uuid:1234 job-priority=75",
                    copies="2")
    assert r.returncode == OK, r.err
    assert "INFO: queued as wideprint job" in r.err
    [job] = jobs_named(client, "poster.tif")
    assert job["client"] == "cups:alice" and job["copies"] == 2 and job["priority"] == 50
    assert job["settings"]["passes"] == 2 and job["settings"]["bidir"] is True
    assert job["size"] == tiff.stat().st_size
    r = run_backend(uri_of(state), file=tiff, title="/home/alice/poster.tif",   # CUPS retries
                    options="job-uuid=urn:uuid:1234")
    assert r.returncode == OK and "(already submitted)" in r.err
    assert len(jobs_named(client, "poster.tif")) == 1


def test_the_job_on_stdin_is_queued_and_its_spool_file_removed(server, tiff, tmp_path):
    state, client = server
    r = run_backend(uri_of(state), stdin=tiff.read_bytes(), title="from stdin",
                    options="job-uuid=urn:uuid:stdin-1", tmpdir=tmp_path)
    assert r.returncode == OK, r.err
    assert jobs_named(client, "from stdin.tif")
    assert list(tmp_path.iterdir()) == []


def test_an_oversize_file_is_cancelled_not_retried(server, tmp_path):
    """The server refuses it before reading it and closes: the backend must read that
    answer, not take the closed connection for a server that went away (RETRY forever)."""
    state, _ = server
    big = tmp_path / "big.tif"
    big.write_bytes(b"II*\x00" + os.urandom(30 << 20))        # far more than socket buffers
    r = run_backend(uri_of(state), file=big, options="job-uuid=urn:uuid:big")
    assert r.returncode == CANCEL, r.err
    assert f"above the {MAX_FILE}-byte limit" in r.err
    assert r.seconds < 20
    (tmp_path / "t").mkdir()
    r = run_backend(uri_of(state), stdin=big.read_bytes(), tmpdir=tmp_path / "t",
                    options="job-uuid=urn:uuid:big-stdin")
    assert r.returncode == CANCEL and "limit" in r.err
    assert list((tmp_path / "t").iterdir()) == []


def test_a_wrong_token_stops_the_queue_even_with_a_large_file(server, tmp_path, tiff):
    state, _ = server
    other = tmp_path / "state"
    other.mkdir()
    shutil.copy(state / "server.json", other / "server.json")
    (other / "token").write_text("not-the-token\n")
    big = tmp_path / "big.tif"
    big.write_bytes(b"II*\x00" + os.urandom(30 << 20))
    for f in (big, tiff):
        r = run_backend(uri_of(other), file=f)
        assert r.returncode == STOP, r.err
        assert "refused the token" in r.err


@pytest.mark.parametrize("options,phrase", [
    ("WPPreset=no-such-preset", "unknown preset 'no-such-preset'"),
    ("WPPasses=5", "passes must be one of"),
    ("WPPasses=abc", "bad option WPPasses='abc': not a number"),
    ("WPResolution=lotsdpi", "bad option WPResolution"),
])
def test_a_job_the_server_refuses_is_cancelled(server, tiff, options, phrase):
    state, _ = server
    r = run_backend(uri_of(state), file=tiff, options=options)
    assert r.returncode == CANCEL, r.err
    assert phrase in r.err


def test_unreadable_input_fails(server, tmp_path):
    state, _ = server
    fifo = tmp_path / "pipe"
    os.mkfifo(fifo)
    for f, phrase in ((tmp_path, "it is a directory"), (tmp_path / "gone.tif", "No such file"),
                      (fifo, "not a regular file")):
        r = run_backend(uri_of(state), file=f, timeout=30)
        assert r.returncode == FAILED, r.err
        assert f"ERROR: cannot read the job file {f}: " in r.err and phrase in r.err
    empty = tmp_path / "empty.tif"
    empty.write_bytes(b"")
    for kw in (dict(file=empty), dict(stdin=b"")):
        r = run_backend(uri_of(state), **kw)
        assert r.returncode == CANCEL and "empty job" in r.err


def test_wrong_arguments_and_the_device_listing(server, tiff):
    state, _ = server
    r = subprocess.run(backend_cmd(), capture_output=True, text=True, timeout=30)
    assert r.returncode == OK and r.stdout.startswith("direct wideprint ")
    r = subprocess.run(backend_cmd() + ["1", "2"], capture_output=True, text=True, timeout=30,
                       env=dict(os.environ, DEVICE_URI=uri_of(state)))
    assert r.returncode == FAILED and r.stderr.startswith("ERROR: usage: ")


def test_sigterm_from_cupsd_ends_cleanly(server, tmp_path):
    """cupsd cancels a job with SIGTERM: no traceback, no spool file left behind."""
    state, _ = server
    e = dict(os.environ, DEVICE_URI=uri_of(state), TMPDIR=str(tmp_path))
    p = subprocess.Popen(backend_cmd() + ["7", "alice", "t", "1", ""], stdin=subprocess.PIPE,
                         stderr=subprocess.PIPE, env=e)
    p.stdin.write(b"II*\x00" + bytes(1000))
    p.stdin.flush()
    deadline = time.monotonic() + 10
    while not list(tmp_path.iterdir()) and time.monotonic() < deadline:
        time.sleep(0.05)
    p.send_signal(signal.SIGTERM)
    _, err = p.communicate(timeout=20)
    assert p.returncode == FAILED
    check_stderr(err.decode())
    assert list(tmp_path.iterdir()) == []


# -- no server, broken set-ups -------------------------------------------------------------------
def _closed_port():
    with socket.socket() as s:
        s.bind(("127.0.0.1", 0))
        return s.getsockname()[1]


def test_no_server_running_is_retried(tmp_path, tiff):
    state = tmp_path / "state"
    state.mkdir()
    (state / "token").write_text("t0ken\n")
    r = run_backend(uri_of(state), file=tiff)
    assert r.returncode == RETRY and "not running" in r.err and "server.json is missing" in r.err
    (state / "server.json").write_text(json.dumps({"url": f"http://127.0.0.1:{_closed_port()}"}))
    r = run_backend(uri_of(state), file=tiff)                 # left by a server that died
    assert r.returncode == RETRY and "Connection refused" in r.err


@pytest.mark.parametrize("content", [
    b"", b"garbage", b"[]", b"null", b"42", b'{"url": 5}', b'{"pid": 1}', b'{"url": null}',
    b'{"url": "ftp://127.0.0.1:80"}', b'{"url": "http://127.0.0.1:99999"}',
    b'{"url": "http://127.0.0.1:port"}', b'{"url": "http://"}', b"\xff\xfe\x00garbage",
    b'{"url": "http://127.0.0.1:8631"' + b" " * 70000 + b"}",
], ids=lambda c: repr(c[:24]))
def test_a_damaged_server_json_stops_the_queue(tmp_path, tiff, content):
    state = tmp_path / "state"
    state.mkdir()
    (state / "token").write_text("t0ken\n")
    (state / "server.json").write_bytes(content)
    r = run_backend(uri_of(state), file=tiff)
    assert r.returncode == STOP, r.err
    assert "server.json is damaged" in r.err and "restart `wideprint serve`" in r.err


def test_setup_errors_stop_the_queue(tmp_path, tiff):
    state = tmp_path / "state"
    state.mkdir()
    (state / "server.json").write_text(json.dumps({"url": f"http://127.0.0.1:{_closed_port()}"}))
    cases = [
        (f"wideprint://{tmp_path}/no-such-dir", "no such wideprint state directory"),
        (f"wideprint://printhost{state}", "only the local server is supported"),
        (f"ipp://localhost{state}", "not a wideprint:// URI"),
        (uri_of(state), "cannot read the wideprint API token"),          # no token file
    ]
    for uri, phrase in cases:
        r = run_backend(uri, file=tiff)
        assert r.returncode == STOP, (uri, r.err)
        assert phrase in r.err
    (state / "token").mkdir()                                 # unreadable token
    r = run_backend(uri_of(state), file=tiff)
    assert r.returncode == STOP and "cannot read the wideprint API token" in r.err
    (state / "token").rmdir()
    (state / "token").write_text("\n")
    r = run_backend(uri_of(state), file=tiff)
    assert r.returncode == STOP and "empty or damaged" in r.err


# -- fake servers: what a real one rarely does ----------------------------------------------------
class FakeServer:
    """A raw HTTP server: GET /v1/status answers like wideprint's (unless told otherwise);
    a POST is handled by `post(conn, headers)`."""

    def __init__(self, state: Path, post, status=None):
        self.sock = socket.socket()
        self.sock.bind(("127.0.0.1", 0))
        self.sock.listen(8)
        self.port = self.sock.getsockname()[1]
        self.post, self.status = post, status
        self.received = 0
        state.mkdir()
        (state / "token").write_text("t0ken\n")
        (state / "server.json").write_text(json.dumps({"url": f"http://127.0.0.1:{self.port}"}))
        threading.Thread(target=self._serve, daemon=True).start()

    def _serve(self):
        while True:
            try:
                conn, _ = self.sock.accept()
            except OSError:
                return
            threading.Thread(target=self._handle, args=(conn,), daemon=True).start()

    def _handle(self, conn):
        with conn:
            data = b""
            while b"\r\n\r\n" not in data:
                chunk = conn.recv(4096)
                if not chunk:
                    return
                data += chunk
            head, _, rest = data.partition(b"\r\n\r\n")
            self.received += len(rest)
            lines = head.decode("latin-1").split("\r\n")
            headers = {k.lower(): v.strip() for k, _, v in (ln.partition(":") for ln in lines[1:])}
            if lines[0].startswith("GET /v1/status"):
                answer(conn, *(self.status or (200, {"server": {"pid": 1}})))
            else:
                self.post(self, conn, headers)

    def close(self):
        self.sock.close()


def answer(conn, status, body, close=True):
    data = body if isinstance(body, bytes) else json.dumps(body).encode()
    conn.sendall(f"HTTP/1.1 {status} X\r\nContent-Type: application/json\r\nContent-Length: "
                 f"{len(data)}\r\n{'Connection: close' + chr(13) + chr(10) if close else ''}"
                 f"\r\n".encode() + data)


def refuse_at_once(srv, conn, headers):
    # no 100 Continue: the refusal comes right after the headers; not a byte of the body read
    answer(conn, 413, {"error": "file is too large for this fake"})


def read_some_then_vanish(srv, conn, headers):
    conn.sendall(b"HTTP/1.1 100 Continue\r\n\r\n")
    got = 0
    while got < 200_000:
        chunk = conn.recv(65536)
        if not chunk:
            break
        got += len(chunk)
    conn.setsockopt(socket.SOL_SOCKET, socket.SO_LINGER, b"\x01\x00\x00\x00\x00\x00\x00\x00")


def server_error(srv, conn, headers):
    answer(conn, 503, {"error": "the spool disk is full"})


def nasty_message(srv, conn, headers):
    answer(conn, 400, {"error": "bad name\n\x1b[31mred\rERROR: forged line"})


@pytest.fixture
def big(tmp_path):
    p = tmp_path / "big.tif"
    p.write_bytes(b"II*\x00" + os.urandom(8 << 20))
    return p


def test_a_refusal_before_the_body_is_read_even_without_100_continue(tmp_path, big):
    fake = FakeServer(tmp_path / "state", refuse_at_once)
    try:
        r = run_backend(uri_of(tmp_path / "state"), file=big)
    finally:
        fake.close()
    assert r.returncode == CANCEL, r.err
    assert "file is too large for this fake" in r.err


def test_a_server_vanishing_mid_upload_is_retried(tmp_path, big):
    fake = FakeServer(tmp_path / "state", read_some_then_vanish)
    try:
        r = run_backend(uri_of(tmp_path / "state"), file=big)
    finally:
        fake.close()
    assert r.returncode == RETRY, r.err
    assert "went away" in r.err and "will retry" in r.err


def test_a_server_error_is_retried(tmp_path, tiff):
    fake = FakeServer(tmp_path / "state", server_error)
    try:
        r = run_backend(uri_of(tmp_path / "state"), file=tiff)
    finally:
        fake.close()
    assert r.returncode == RETRY and "the spool disk is full" in r.err


def test_the_servers_words_stay_one_line(tmp_path, tiff):
    fake = FakeServer(tmp_path / "state", nasty_message)
    try:
        r = run_backend(uri_of(tmp_path / "state"), file=tiff)
    finally:
        fake.close()
    assert r.returncode == CANCEL
    assert [ln for ln in r.err.splitlines() if ln.startswith("ERROR: ")] == [
        "ERROR: the wideprint server refused the job: bad name\\x0a\\x1b[31mred\\x0dERROR: "
        "forged line"]


@pytest.mark.parametrize("status,phrase", [
    ((200, b"<html>hello</html>"), "is not a wideprint server"),
    ((404, {"error": "no such endpoint"}), "does not know /v1/status"),
    ((401, {"error": "missing or wrong bearer token"}), "refused the token"),
])
def test_something_else_on_the_port_stops_the_queue(tmp_path, tiff, status, phrase):
    fake = FakeServer(tmp_path / "state", server_error, status=status)
    try:
        r = run_backend(uri_of(tmp_path / "state"), file=tiff)
    finally:
        fake.close()
    assert r.returncode == STOP, r.err
    assert phrase in r.err
