"""The API under hostile clients (docs/server.md, "The API: the rules"), with raw sockets
(http.client cannot send malformed requests): every malformed request gets a 4xx and the
server goes on serving; ids and numbers beyond SQLite's range are refused, not crashed on;
Content-Length is digits only and given once; idle and half-open connections are closed
after the timeout; connections beyond the limit get 503 at once; clients that go away are
one log line — and nothing of it leaves a traceback in the server's log.

Every connection goes to 127.0.0.1 only; every loop and wait is bounded."""

import json
import logging
import socket
import threading
import time

import pytest

TIMEOUT = 1.0            # the server's idle timeout in these tests
LIMIT = 4                # the server's connection limit in these tests


@pytest.fixture(scope="module")
def api(tmp_path_factory):
    from wideprint.app.server import PrintServer, ServerConfig
    root = tmp_path_factory.mktemp("api")
    server = PrintServer(ServerConfig(device="emulator", state_dir=root / "state", port=0,
                                      start_paused=True, api_timeout_s=TIMEOUT,
                                      api_max_connections=LIMIT, max_file_bytes=1_000_000))
    server.start()
    yield server
    server.stop(timeout=5)


@pytest.fixture(autouse=True)
def no_traceback(api, caplog, capfd):
    """No traceback in the server's log (records and stderr) for anything a test does, and
    the server still answers a normal request afterwards."""
    caplog.set_level(logging.DEBUG, logger="wideprint")
    yield
    assert get(api, "/v1/status")[0] == 200, "the server stopped serving"
    err = capfd.readouterr().err
    assert "Traceback" not in caplog.text and "Traceback" not in err, caplog.text + err
    assert not [r for r in caplog.records if r.exc_info], caplog.text


# -- raw HTTP ----------------------------------------------------------------------------------
def connect(api, timeout=10.0) -> socket.socket:
    return socket.create_connection(("127.0.0.1", api.port), timeout=timeout)


def read_all(s: socket.socket, limit_s: float = 10.0) -> bytes:
    """Everything the server sends until it closes (bounded in time)."""
    out, end = b"", time.monotonic() + limit_s
    while time.monotonic() < end:
        s.settimeout(max(0.05, end - time.monotonic()))
        try:
            chunk = s.recv(65536)
        except (ConnectionResetError, TimeoutError):
            break
        if not chunk:
            break
        out += chunk
    return out


def exchange(api, data: bytes, half_close: bool = True) -> tuple[int, dict, bytes]:
    """Send raw bytes, read the answer: (status, headers, body) of the first response."""
    with connect(api) as s:
        s.sendall(data)
        if half_close:
            s.shutdown(socket.SHUT_WR)
        raw = read_all(s)
    return parse_response(raw)


def parse_response(raw: bytes) -> tuple[int, dict, bytes]:
    assert raw.startswith(b"HTTP/1."), raw[:200]
    head, _, rest = raw.partition(b"\r\n\r\n")
    lines = head.decode("latin-1").split("\r\n")
    status = int(lines[0].split()[1])
    headers = {k.lower(): v.strip() for k, _, v in (ln.partition(":") for ln in lines[1:])}
    n = int(headers.get("content-length", len(rest)))
    return status, headers, rest[:n]


def auth(api) -> bytes:
    return f"Authorization: Bearer {api.token}\r\n".encode()


def get(api, path: str, extra: bytes = b"") -> tuple[int, dict]:
    status, _, body = exchange(api, f"GET {path} HTTP/1.1\r\n".encode() + auth(api) + extra
                               + b"Connection: close\r\n\r\n")
    return status, (json.loads(body) if body.startswith(b"{") else {})


def request(api, method: str, path: str, headers: bytes = b"", body: bytes = b""):
    return exchange(api, f"{method} {path} HTTP/1.1\r\n".encode() + auth(api) + headers
                    + b"\r\n" + body)


# -- ids and numbers ---------------------------------------------------------------------------
HUGE = "99999999999999999999999"
BEYOND = str(2 ** 63)                      # one more than SQLite's largest integer


@pytest.mark.parametrize("method,path", [
    ("GET", f"/v1/jobs/{HUGE}"), ("PATCH", f"/v1/jobs/{HUGE}"),
    ("POST", f"/v1/jobs/{HUGE}/cancel"), ("POST", f"/v1/jobs/{HUGE}/hold"),
    ("POST", f"/v1/jobs/{HUGE}/release"), ("POST", f"/v1/jobs/{HUGE}/requeue"),
    ("GET", f"/v1/jobs/{BEYOND}"), ("GET", "/v1/jobs/-1"), ("GET", "/v1/jobs/+1"),
    ("GET", "/v1/jobs/1e3"), ("GET", "/v1/jobs/0x10"), ("GET", "/v1/jobs/1_0"),
    ("GET", "/v1/jobs/%31"), ("GET", "/v1/jobs/\u0661\u0662"),    # Arabic-Indic digits
    ("GET", f"/v1/jobs/{2 ** 63 - 1}"), ("GET", "/v1/jobs/0"),
])
def test_job_ids_beyond_sqlite_or_not_digits_are_404(api, method, path):
    body = b'{"priority": 1}' if method == "PATCH" else b""
    status, _, answer = request(api, method, path, f"Content-Length: {len(body)}\r\n".encode(), body)
    assert status == 404, answer
    assert "no job" in json.loads(answer)["error"]


@pytest.mark.parametrize("query", [
    "limit=1e20", f"limit={HUGE}", f"limit={BEYOND}", "limit=-1", "limit=+5", "limit= 5",
    "limit=", "limit=5&limit=6", "after=1.5", f"after={HUGE}", "after=%FF", "state=nope",
    "state=", "colour=red", "limit=" + "9" * 5000,
])
def test_query_numbers_are_parsed_strictly(api, query):
    status, body = get(api, f"/v1/jobs?{query}")
    assert status == 400, body
    assert body["error"]


@pytest.mark.parametrize("query", [f"job={HUGE}", f"job={BEYOND}", "job=-1", "job=1e3",
                                   "format=xml", "job=1&job=2"])
def test_report_query_is_parsed_strictly(api, query):
    status, body = get(api, f"/v1/report?{query}")
    assert status == 400, body


def test_largest_numbers_are_answered(api):
    assert get(api, f"/v1/jobs?after={2 ** 63 - 1}&limit={2 ** 63 - 1}") == (200, {"jobs": []})
    assert get(api, f"/v1/report?job={2 ** 63 - 1}")[1] == {"prints": []}


# -- framing -----------------------------------------------------------------------------------
QUEUE = b'{"paused": true}'


@pytest.mark.parametrize("headers", [
    b"Content-Length:  16\r\n",              # " 16": a blank before the digits
    b"Content-Length: +16\r\n",
    b"Content-Length: 16 \r\n",
    b"Content-Length: -16\r\n",
    b"Content-Length: 0x10\r\n",
    b"Content-Length: 1_6\r\n",
    b"Content-Length: 16, 16\r\n",
    b"Content-Length: \r\n",
    b"Content-Length: 16\r\nContent-Length: 16\r\n",
    b"Content-Length: 16\r\nContent-Length: 17\r\n",
    b"Content-Length: 16\r\nTransfer-Encoding: chunked\r\n",
    b"Content-Length : 16\r\n",
])
def test_content_length_is_strict(api, headers):
    was = api.worker.paused
    flip = json.dumps({"paused": not was}, separators=(",", ":")).encode().ljust(16)  # 16 bytes
    status, _, body = request(api, "POST", "/v1/queue", headers, flip)
    assert status == 400, body
    assert api.worker.paused is was                         # nothing of it was acted on


def test_chunked_and_oversize_bodies(api):
    status, _, _ = request(api, "POST", "/v1/queue", b"Transfer-Encoding: chunked\r\n",
                           b"10\r\n" + QUEUE + b"\r\n0\r\n\r\n")
    assert status == 411
    status, _, _ = request(api, "POST", "/v1/queue", b"Content-Length: " + b"9" * 30 + b"\r\n")
    assert status == 413
    status, _, _ = request(api, "GET", "/v1/status", b"Content-Length: 5\r\n", b"hello")
    assert status == 400                                    # GET takes no body
    # the well-formed request does what it says
    status, _, _ = request(api, "POST", "/v1/queue", b"Content-Length: 17\r\n",
                           b'{"paused": false}')
    assert status == 200


@pytest.mark.parametrize("raw", [
    b"GARBAGE\r\n\r\n",
    b"GET /v1/status HTTP/1.1.1\r\n\r\n",
    b"GET /v1/status HTTP/x.y\r\n\r\n",
    b"GET /v1/status\r\n\r\n",                              # HTTP/0.9
    b"GET /v1/status HTTP/1.1 extra\r\n\r\n",
    b"\r\n" * 8,
    b"\x16\x03\x01\x02\x00\x01\x00\x01\xfc\x03\x03" + bytes(64) + b"\r\n\r\n",   # TLS hello
    b"GET /v1/status HTTP/1.1\r\nNo colon here\r\n\r\n",
    b"GET /v1/status HTTP/1.1\r\nX-A: 1\r\n folded\r\n\r\n",
    b"GET /v1/status HTTP/1.1\r\n" + b"X-Long: " + b"a" * 70000 + b"\r\n\r\n",
    b"GET /v1/status HTTP/1.1\r\n" + b"".join(b"X-%d: 1\r\n" % i for i in range(120)) + b"\r\n",
    b"GET /" + b"a" * 70000 + b" HTTP/1.1\r\n\r\n",
    b"FROB /v1/status HTTP/1.1\r\n\r\n",
    b"PUT /v1/status HTTP/1.1\r\n\r\n",
    b"HEAD /v1/status HTTP/1.1\r\n\r\n",
])
def test_malformed_requests_get_a_4xx(api, raw):
    status, headers, body = exchange(api, raw)
    assert 400 <= status < 500, (status, body)
    assert headers.get("connection") == "close"


@pytest.mark.parametrize("body,why", [
    (b"[" * 100_000, "nested too deeply"),
    (b'{"priority": NaN}', "NaN"),
    (b'{"priority": Infinity}', "Infinity"),
    (b'{"priority": 1e999}', "out of range"),
    (b'{"priority": 1' + b"0" * 5000 + b"}", "bad JSON"),
    (b"\xff\xfe{}", "bad JSON"),
])
def test_hostile_json_bodies_are_400(api, body, why):
    status, _, answer = request(api, "PATCH", "/v1/jobs/1",
                                f"Content-Length: {len(body)}\r\n".encode(), body)
    assert status == 400 and why in json.loads(answer)["error"], answer


@pytest.mark.parametrize("desc", ["[" * 30000, '{"name": "a.tif", "copies": NaN}',
                                  '{"name": "a.tif", "priority": 1e999}'])
def test_hostile_job_descriptions_are_400(api, desc):
    status, _, answer = request(api, "POST", "/v1/jobs",
                                f"X-Wideprint-Job: {desc}\r\nContent-Length: 4\r\n".encode(),
                                b"II*\x00")
    assert status == 400, answer


def test_two_job_descriptions_are_refused(api):
    status, _, answer = request(api, "POST", "/v1/jobs",
                                b'X-Wideprint-Job: {"name": "a.tif"}\r\n'
                                b'X-Wideprint-Job: {"name": "b.tif"}\r\nContent-Length: 4\r\n',
                                b"II*\x00")
    assert status == 400 and "X-Wideprint-Job" in json.loads(answer)["error"]


def test_two_authorization_headers_are_401(api):
    status, _, _ = exchange(api, b"GET /v1/status HTTP/1.1\r\n" + auth(api) + auth(api) + b"\r\n")
    assert status == 401


def test_expect_100_continue_is_sent_only_to_an_authorised_request(api):
    status, _, _ = exchange(api, b"POST /v1/jobs HTTP/1.1\r\nAuthorization: Bearer nope\r\n"
                                 b"Expect: 100-continue\r\nContent-Length: 4\r\n\r\n")
    assert status == 401                                    # not 100 first
    with connect(api) as s:
        s.sendall(b"POST /v1/queue HTTP/1.1\r\n" + auth(api) + b"Expect: 100-continue\r\n"
                  b"Content-Length: 17\r\n\r\n")
        s.settimeout(5)
        assert s.recv(100).startswith(b"HTTP/1.1 100 Continue\r\n")
        s.sendall(b'{"paused": false}')
        s.shutdown(socket.SHUT_WR)
        raw = read_all(s)
    assert b"HTTP/1.1 200 OK" in raw


# -- connections -------------------------------------------------------------------------------
def test_clients_closing_before_the_answer_leave_no_traceback(api, caplog):
    """Unauthorised uploads whose clients close at once (the 401 is written to a closed
    socket), and uploads abandoned half-way."""
    for i in range(30):
        with connect(api) as s:
            s.sendall(b"POST /v1/jobs HTTP/1.1\r\nAuthorization: Bearer wrong\r\n"
                      b"Content-Length: 500000\r\n\r\n" + bytes(200_000))
            s.setsockopt(socket.SOL_SOCKET, socket.SO_LINGER, b"\x01\x00\x00\x00\x00\x00\x00\x00")
    for i in range(5):
        with connect(api) as s:
            s.sendall(b"POST /v1/jobs HTTP/1.1\r\n" + auth(api)
                      + b'X-Wideprint-Job: {"name": "cut.tif"}\r\nContent-Length: 500000\r\n\r\n'
                      + bytes(1000))
    time.sleep(0.5)
    assert not (api.spool.spool_dir.exists() and list(api.spool.spool_dir.iterdir()))
    gone = [r for r in caplog.records if "went away" in r.getMessage()
            or "ended after" in r.getMessage()]
    assert all(r.levelno <= logging.INFO for r in gone)


def test_idle_and_half_open_connections_are_closed_after_the_timeout(api):
    t0 = time.monotonic()
    with connect(api) as s:                                 # says nothing at all
        assert read_all(s, 5 * TIMEOUT) == b""
    assert TIMEOUT * 0.8 <= time.monotonic() - t0 < TIMEOUT + 2
    t0 = time.monotonic()
    with connect(api) as s:                                 # half a request head, then silence
        s.sendall(b"GET /v1/status HTTP/1.1\r\nAuthoriz")
        status, _, _ = parse_response(read_all(s, 5 * TIMEOUT))
    assert status == 408 and time.monotonic() - t0 < TIMEOUT + 2
    t0 = time.monotonic()
    with connect(api) as s:                                 # a body announced, never sent
        s.sendall(b"POST /v1/queue HTTP/1.1\r\n" + auth(api) + b"Content-Length: 17\r\n\r\n{")
        status, _, _ = parse_response(read_all(s, 5 * TIMEOUT))
    assert status == 408 and time.monotonic() - t0 < TIMEOUT + 2


def test_a_head_trickled_byte_by_byte_is_cut_off(api):
    """Each byte comes well within the idle timeout, but the head as a whole must arrive
    within it too."""
    t0 = time.monotonic()
    closed = None
    with connect(api) as s:
        for ch in b"GET /v1/status HTTP/1.1\r\nX-Slow: " + b"a" * 40:
            try:
                s.sendall(bytes([ch]))
            except OSError:
                break
            time.sleep(TIMEOUT / 5)
            s.settimeout(0.001)
            try:
                if s.recv(1, socket.MSG_PEEK):
                    closed = time.monotonic() - t0
                    break
            except (BlockingIOError, TimeoutError):
                pass
            if time.monotonic() - t0 > 4 * TIMEOUT:
                break
        s.settimeout(5)
        raw = read_all(s, 3)
    assert raw.startswith(b"HTTP/1.1 408"), raw[:100]
    assert closed is None or closed < TIMEOUT + 1.5


def test_silent_connections_hold_no_thread(api):
    """Connections that say nothing (or half a request head) wait in the listener, not in a
    thread: more of them than the limit do not keep a request from being served at once."""
    idle = [connect(api) for _ in range(LIMIT + 3)]         # LIMIT + 3 silent connections
    try:
        idle[0].sendall(b"GET /v1/status HT")
        time.sleep(0.2)
        threads = [t for t in threading.enumerate() if t.name == "wideprint-api-conn"]
        assert not threads                                  # none of them holds a thread
        t0 = time.monotonic()
        assert get(api, "/v1/status")[0] == 200
        assert time.monotonic() - t0 < 0.5 * TIMEOUT
    finally:
        for s in idle:
            s.close()


def test_requests_beyond_the_limit_get_503_at_once(api):
    """Requests being served (bodies that do not come) are bounded: beyond the threads for
    requests with a body the next one gets 503 at once; a plain GET still has its own."""
    heavy = LIMIT - LIMIT // 4                               # threads bodies may take
    slow = []
    try:
        for _ in range(heavy):
            s = connect(api)
            s.sendall(b"POST /v1/queue HTTP/1.1\r\n" + auth(api) + b"Content-Length: 17\r\n\r\n{")
            slow.append(s)
        time.sleep(0.2)
        threads = [t for t in threading.enumerate() if t.name == "wideprint-api-conn"]
        assert len(threads) <= LIMIT                        # threads are bounded
        t0 = time.monotonic()
        status, headers, body = exchange(api, b"POST /v1/queue HTTP/1.1\r\n" + auth(api)
                                         + b"Content-Length: 17\r\n\r\n" + QUEUE + b" ",
                                         half_close=False)
        took = time.monotonic() - t0
        assert status == 503 and headers.get("retry-after") == "1", body
        assert took < 0.5 * TIMEOUT                          # promptly, not after the timeout
        t0 = time.monotonic()
        assert get(api, "/v1/status")[0] == 200              # a GET still finds a thread
        assert time.monotonic() - t0 < 0.5 * TIMEOUT
        # the slow ones get 408 after the timeout; then everything is served again
        time.sleep(TIMEOUT + 0.5)
        assert request(api, "POST", "/v1/queue", b"Content-Length: 17\r\n",
                       b'{"paused": false}')[0] == 200
    finally:
        for s in slow:
            s.close()


def test_keep_alive_connection_serves_several_requests_then_times_out(api):
    with connect(api) as s:
        for _ in range(3):
            s.sendall(b"GET /v1/status HTTP/1.1\r\n" + auth(api) + b"\r\n")
            head = b""
            s.settimeout(5)
            while b"\r\n\r\n" not in head:
                head += s.recv(1)
            n = int(head.lower().split(b"content-length:")[1].split(b"\r\n")[0])
            body = b""
            while len(body) < n:
                body += s.recv(n - len(body))
            assert head.startswith(b"HTTP/1.1 200") and json.loads(body)["server"]
        t0 = time.monotonic()
        assert read_all(s, 5 * TIMEOUT) == b""                # closed, silently, when idle
        assert time.monotonic() - t0 < TIMEOUT + 2


def test_many_hostile_clients_at_once(api):
    """A burst of malformed, unauthorised and abandoned connections from several threads
    (bounded): every one is answered or closed, and a normal request is served after."""
    errors = []

    def hostile(n):
        try:
            for i in range(10):
                with connect(api) as s:
                    s.sendall([b"GET /v1/jobs/" + HUGE.encode() + b" HTTP/1.1\r\n" + auth(api)
                               + b"\r\n", b"BLAH\r\n\r\n",
                               b"POST /v1/jobs HTTP/1.1\r\nContent-Length: 9\r\n\r\n",
                               b"GET /v1/status HTTP/1.1\r\n" + auth(api)][(n + i) % 4])
                    if (n + i) % 3:
                        s.shutdown(socket.SHUT_WR)
                        read_all(s, 3 * TIMEOUT)
        except OSError as exc:
            errors.append(exc)

    workers = [threading.Thread(target=hostile, args=(n,)) for n in range(6)]
    for w in workers:
        w.start()
    for w in workers:
        w.join(60)
    assert not any(w.is_alive() for w in workers)
    assert not errors, errors
    time.sleep(TIMEOUT + 0.5)
    assert get(api, "/v1/status")[0] == 200
