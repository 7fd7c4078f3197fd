"""Slow clients cannot starve the operator (issue 31; docs/server.md "The API: the rules"):
with 500 connections to the API that sent part of a request line and nothing more (and
some of them trickling a byte now and then), `GET /v1/status` keeps answering within
100 ms; slow uploads hold at most the threads for requests with a body, never all of them.

Every connection goes to 127.0.0.1 only; the counts and waits are bounded and every socket
is closed at the end."""

import http.client
import json
import resource
import socket
import statistics
import threading
import time

import pytest

HALF_OPEN = 500
TRICKLING = 50             # of them, one byte each every 0.2 s
STATUS_CALLS = 20
LATENCY_S = 0.100


@pytest.fixture
def fds():
    """Room for both ends of 500 connections in this one process."""
    soft, hard = resource.getrlimit(resource.RLIMIT_NOFILE)
    want = min(hard, 4096) if hard != resource.RLIM_INFINITY else 4096
    if soft < want:
        resource.setrlimit(resource.RLIMIT_NOFILE, (want, hard))
    if min(want, hard) < 2 * HALF_OPEN + 200:
        pytest.skip(f"needs {2 * HALF_OPEN + 200} file descriptors (limit {hard})")
    yield
    resource.setrlimit(resource.RLIMIT_NOFILE, (soft, hard))


@pytest.fixture
def api(tmp_path, fds):
    from wideprint.app.server import PrintServer, ServerConfig
    server = PrintServer(ServerConfig(device="emulator", state_dir=tmp_path / "state", port=0,
                                      start_paused=True))          # default timeout, 32 threads
    server.start()
    yield server
    server.stop(timeout=5)


def status_call(api) -> tuple[int, float]:
    t0 = time.perf_counter()
    conn = http.client.HTTPConnection("127.0.0.1", api.port, timeout=5)
    try:
        conn.request("GET", "/v1/status", headers={"Authorization": f"Bearer {api.token}"})
        r = conn.getresponse()
        body = r.read()
        status = r.status if json.loads(body).get("server") else -1
    finally:
        conn.close()
    return status, time.perf_counter() - t0


def test_status_answers_within_100_ms_under_500_half_open_connections(api):
    socks: list[socket.socket] = []
    stop = threading.Event()

    def trickle():
        while not stop.wait(0.2):
            for s in socks[:TRICKLING]:
                try:
                    s.send(b"a")
                except OSError:
                    pass
    t = threading.Thread(target=trickle, daemon=True)
    try:
        for i in range(HALF_OPEN):
            s = socket.create_connection(("127.0.0.1", api.port), timeout=5)
            s.sendall(b"GET /v1/status HT" if i >= TRICKLING else b"GET /v1/status?x=")
            socks.append(s)
        t.start()
        time.sleep(0.5)                       # the server has seen them all
        status_call(api)                      # warm
        results = [status_call(api) for _ in range(STATUS_CALLS)]
    finally:
        stop.set()
        t.join(5)
        for s in socks:
            s.close()
    times = [dt for _, dt in results]
    print(f"status under {HALF_OPEN} half-open connections: median "
          f"{statistics.median(times) * 1000:.1f} ms, max {max(times) * 1000:.1f} ms")
    assert [st for st, _ in results] == [200] * STATUS_CALLS, results
    assert max(times) < LATENCY_S, times


def test_slow_uploads_cannot_take_every_thread(tmp_path, fds):
    """Requests with a body that never comes hold a thread each until the timeout, but only
    up to the limit for such requests: a GET still finds a thread; one more slow upload is
    refused at once (503)."""
    from wideprint.app.server import PrintServer, ServerConfig
    api = PrintServer(ServerConfig(device="emulator", state_dir=tmp_path / "state", port=0,
                                   start_paused=True, api_timeout_s=5, api_max_connections=8))
    api.start()
    socks = []
    try:
        for _ in range(8):
            s = socket.create_connection(("127.0.0.1", api.port), timeout=5)
            s.sendall(b"POST /v1/queue HTTP/1.1\r\nAuthorization: Bearer " + api.token.encode()
                      + b"\r\nContent-Length: 17\r\n\r\n{")
            socks.append(s)
        time.sleep(0.3)
        for _ in range(5):
            status, dt = status_call(api)
            assert status == 200 and dt < 1.0, (status, dt)
        # the ones beyond the limit for uploads were refused at once
        refused = 0
        for s in socks:
            s.settimeout(0.05)
            try:
                refused += s.recv(100).startswith(b"HTTP/1.1 503")
            except (TimeoutError, OSError):
                pass
        assert refused >= 1
    finally:
        for s in socks:
            s.close()
        api.stop(timeout=5)
