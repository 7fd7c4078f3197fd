"""Authentication fails closed, and who may act on a job (issue 31; docs/server.md "Users
and roles", "Safety rules").

- a token file that is empty, too short, not text or unreadable stops the server with a
  message naming the file; one readable by others is made 0600 with a warning; an empty
  bearer token never authenticates; a token never reaches the log;
- each client says who it is; the operator token may act on every job, a user's token
  (`wideprint users add NAME`) only on that user's own jobs, and never on the queue or the
  printers; the CUPS backend and the IPP bridge pass the requesting user.

Every connection goes to 127.0.0.1 only."""

import json
import logging
import os
import stat
import subprocess
import sys

import pytest

from support.images import ROOT, random_planes, write_cmyk_tiff
from support.server import raw_request
from wideprint.app.client import ApiError, Client

PY = sys.executable


def make_server(state, **kw):
    from wideprint.app.server import PrintServer, ServerConfig
    return PrintServer(ServerConfig(device="emulator", state_dir=state, port=0,
                                    start_paused=True, **kw))


def raw(srv, method, path, token, headers=None):
    return raw_request(srv, method, path, headers=headers, token=token)


# -- the token file ----------------------------------------------------------------------------
@pytest.mark.parametrize("content,why", [
    (b"", "empty"), (b"\n  \n", "empty"), (b"short-token\n", "too short"),
    (b"\xff\xfe\x00\x01binary" * 8, "not text"), ("é".encode("latin-1") * 40, "not text"),
    (b"a" * 20 + b" " + b"b" * 20 + b"\n", "blank"),
])
def test_a_bad_token_file_refuses_to_start_naming_the_file(tmp_path, content, why):
    state = tmp_path / "state"
    state.mkdir()
    (state / "token").write_bytes(content)
    os.chmod(state / "token", 0o600)
    with pytest.raises(ValueError) as e:
        make_server(state)
    assert str(state / "token") in str(e.value) and why in str(e.value), str(e.value)
    assert (state / "token").read_bytes() == content          # left as it was, for the operator


def test_serve_with_an_empty_token_file_exits_with_the_file_named(tmp_path):
    state = tmp_path / "state"
    state.mkdir()
    (state / "token").write_bytes(b"")
    r = subprocess.run([PY, "-m", "wideprint.app.cli", "serve", "--state-dir", str(state),
                        "--port", "0"], capture_output=True, text=True, timeout=120)
    assert r.returncode == 2, r.stdout + r.stderr
    assert str(state / "token") in r.stderr and "Traceback" not in r.stderr, r.stderr


@pytest.mark.skipif(os.geteuid() == 0, reason="root reads any file")
def test_an_unreadable_token_file_refuses_to_start(tmp_path):
    state = tmp_path / "state"
    state.mkdir()
    (state / "token").write_text("x" * 43 + "\n")
    os.chmod(state / "token", 0)
    try:
        with pytest.raises(ValueError) as e:
            make_server(state)
        assert str(state / "token") in str(e.value)
    finally:
        os.chmod(state / "token", 0o600)


def test_a_token_file_readable_by_others_is_made_private_with_a_warning(tmp_path, caplog):
    state = tmp_path / "state"
    state.mkdir()
    token = "k" * 43
    (state / "token").write_text(token + "\n")
    os.chmod(state / "token", 0o644)
    caplog.set_level(logging.INFO, logger="wideprint")
    srv = make_server(state)
    try:
        assert stat.S_IMODE(os.stat(state / "token").st_mode) == 0o600
        assert srv.token == token
        warned = [r for r in caplog.records if r.levelno == logging.WARNING
                  and str(state / "token") in r.getMessage()]
        assert warned and "0600" in warned[0].getMessage(), caplog.text
    finally:
        srv.stop(timeout=5)


def test_a_new_token_file_is_complete_and_private(tmp_path):
    state = tmp_path / "state"
    srv = make_server(state)
    try:
        text = (state / "token").read_text()
        assert len(text.strip()) >= 32 and stat.S_IMODE(os.stat(state / "token").st_mode) == 0o600
        assert not [p for p in state.iterdir() if p.name.startswith(".token")]   # no temporary
    finally:
        srv.stop(timeout=5)


@pytest.fixture(scope="module")
def srv(tmp_path_factory):
    root = tmp_path_factory.mktemp("auth")
    server = make_server(root / "state")
    server.start()
    yield server
    server.stop(timeout=5)


def test_an_empty_bearer_token_never_authenticates(srv):
    real = srv.token
    try:
        srv.token = ""                # as an empty token file made it before issue 31
        for token in ("", " "):
            status, body = raw(srv, "GET", "/v1/status", token)
            assert status == 401, body
    finally:
        srv.token = real
    assert raw(srv, "GET", "/v1/status", "")[0] == 401
    assert raw(srv, "GET", "/v1/status", real)[0] == 200


def test_a_token_in_the_url_never_reaches_the_log(srv, caplog):
    caplog.set_level(logging.DEBUG, logger="wideprint")
    for query in (f"token={srv.token}", f"access_token={srv.token}", f"x=1&auth={srv.token}"):
        status, _ = raw(srv, "GET", f"/v1/status?{query}", srv.token)
        assert status == 400
        status, _ = raw(srv, "GET", f"/v1/jobs/{srv.token}", srv.token)
        assert status == 404
        status, _ = raw(srv, "GET", f"/v1/status?{query}", None)      # unauthorised too
        assert status == 401
    assert srv.token not in caplog.text, caplog.text
    assert "token=[redacted]" in caplog.text, caplog.text


def test_a_binary_token_file_gives_a_client_error_naming_the_file(tmp_path):
    state = tmp_path / "state"
    state.mkdir()
    (state / "server.json").write_text(json.dumps({"url": "http://127.0.0.1:9"}))
    (state / "token").write_bytes(b"\xff\xfe\x00garbage")
    with pytest.raises(ApiError) as e:
        Client(state)
    assert str(state / "token") in str(e.value)


# -- users and roles ----------------------------------------------------------------------------
def users_cli(srv, *args):
    from wideprint.app.cli import main
    return main(["users", *args, "--state-dir", str(srv.state_dir)])


@pytest.fixture(scope="module")
def people(srv, tmp_path_factory):
    """alice and bob with their own tokens, and the operator's client."""
    tokens = {}
    for name in ("alice", "bob"):
        path = tmp_path_factory.mktemp("home") / "token"
        assert users_cli(srv, "add", name, "--out", str(path)) == 0
        assert stat.S_IMODE(os.stat(path).st_mode) == 0o600
        tokens[name] = path.read_text().strip()
        assert stat.S_IMODE(os.stat(srv.state_dir / "users" / name).st_mode) == 0o600
    clients = {name: Client(srv.state_dir, token=tok, user=name) for name, tok in tokens.items()}
    clients["operator"] = Client(srv.state_dir, user="root")
    yield clients
    for c in clients.values():
        c.close()


@pytest.fixture(scope="module")
def tif(tmp_path_factory):
    return write_cmyk_tiff(tmp_path_factory.mktemp("img") / "a.tif", random_planes(8, 16, seed=3))


def test_a_user_acts_on_own_jobs_only(srv, people, tif):
    alice, bob, op = people["alice"], people["bob"], people["operator"]
    job = alice.submit(tif, hold=True)["job"]
    assert job["owner"] == "alice"
    jid = job["id"]
    for what in ("cancel", "hold", "release", "requeue"):
        with pytest.raises(ApiError) as e:
            bob.action(jid, what)
        assert e.value.status == 403 and "alice" in str(e.value), str(e.value)
    with pytest.raises(ApiError) as e:
        bob.move(jid, "any")
    assert e.value.status == 403
    with pytest.raises(ApiError) as e:
        bob.edit(jid, priority=5)
    assert e.value.status == 403
    assert alice.job(jid)["state"] == "held" and alice.job(jid)["priority"] == 0
    # reading the queue is everyone's
    assert any(j["id"] == jid for j in bob.jobs())
    assert bob.status()["queue"]
    # the owner may
    assert alice.edit(jid, priority=3)["priority"] == 3
    assert alice.action(jid, "release")["state"] == "queued"
    assert alice.action(jid, "hold")["state"] == "held"
    # and the operator may act on anyone's job
    assert op.action(jid, "cancel")["state"] == "cancelled"


def test_the_queue_and_the_printers_are_the_operators(srv, people):
    bob = people["bob"]
    for method, path, body in (("POST", "/v1/queue", {"paused": False}),
                               ("POST", "/v1/estop", {}), ("POST", "/v1/shutdown", {}),
                               ("POST", "/v1/presets/reload", None),
                               ("POST", "/v1/printers/main/pause", None),
                               ("POST", "/v1/printers/main/clear-fault", {"then": "resume"})):
        with pytest.raises(ApiError) as e:
            bob.request(method, path, body=body)
        assert e.value.status == 403 and "operator" in str(e.value), (path, str(e.value))
    assert not srv.stop_requested.is_set()


def test_the_operator_submits_for_the_user_it_names(srv, people, tif):
    op, alice = people["operator"], people["alice"]
    carol = Client(srv.state_dir, user="carol")           # the operator token, for carol
    try:
        job = carol.submit(tif, hold=True)["job"]
    finally:
        carol.close()
    assert job["owner"] == "carol"
    with pytest.raises(ApiError) as e:
        alice.action(job["id"], "cancel")
    assert e.value.status == 403
    op.action(job["id"], "cancel")


def test_a_user_token_cannot_claim_another_name(srv, people, tif):
    token = people["bob"].token
    mallory = Client(srv.state_dir, token=token, user="alice")
    try:
        job = mallory.submit(tif, hold=True)["job"]
    finally:
        mallory.close()
    assert job["owner"] == "bob"
    people["bob"].action(job["id"], "cancel")


def test_a_removed_user_is_refused_and_unknown_names_are_refused(srv, tmp_path):
    out = tmp_path / "dave.token"
    assert users_cli(srv, "add", "dave", "--out", str(out)) == 0
    dave = out.read_text().strip()
    assert raw(srv, "GET", "/v1/status", dave)[0] == 200
    assert users_cli(srv, "remove", "dave") == 0
    assert raw(srv, "GET", "/v1/status", dave)[0] == 401
    for bad in ("../x", ".hidden", "a/b", "", "x" * 100):
        assert users_cli(srv, "add", bad) == 2
    assert not (srv.state_dir / "x").exists()


def test_a_bad_user_header_is_refused(srv):
    status, body = raw(srv, "GET", "/v1/status", srv.token,
                       headers={"X-Wideprint-User": "a%0Ab"})
    assert status == 400 and "X-Wideprint-User" in body["error"]


def test_the_cli_says_who_it_is(srv, tif):
    import getpass
    r = subprocess.run([PY, "-m", "wideprint.app.cli", "submit", str(tif), "--hold",
                        "--json", "--state-dir", str(srv.state_dir)],
                       capture_output=True, text=True, timeout=120)
    assert r.returncode == 0, r.stderr
    job = json.loads(r.stdout)[0]
    assert job["owner"] == getpass.getuser()
    Client(srv.state_dir).action(job["id"], "cancel")


def test_the_cups_backend_passes_the_requesting_user(srv, tif):
    backend = ROOT / "resources" / "cups" / "wideprint"
    env = {k: v for k, v in os.environ.items() if k != "WIDEPRINT_STATE_DIR"}
    env.update(DEVICE_URI=f"wideprint://{srv.state_dir}", PRINTER="wideprint",
               CONTENT_TYPE="image/tiff")
    r = subprocess.run([PY, str(backend), "77", "erin", "poster.tif", "1", "", str(tif)],
                       capture_output=True, env=env, timeout=120)
    assert r.returncode == 0, r.stderr.decode()
    jobs = [j for j in Client(srv.state_dir).jobs("held,queued") if j["name"] == "poster.tif"]
    assert jobs and jobs[-1]["owner"] == "erin", jobs
    Client(srv.state_dir).action(jobs[-1]["id"], "cancel")


def test_the_ipp_bridge_passes_the_requesting_user(srv, tif, monkeypatch):
    from wideprint.app.ipp.bridge import IppBridge
    bridge = IppBridge(srv.state_dir, url=srv.url, token=srv.token)
    sent = []
    monkeypatch.setattr(bridge, "_send", sent.append)
    bridge._submit(["5", "main", "image/tiff", str(tif), "1", "normal", "0", "3", "auto",
                    "frank", "flyer.tif"])
    assert sent and sent[0].startswith("job\t5\t"), sent
    job = Client(srv.state_dir).job(int(sent[0].split("\t")[2]))
    assert job["owner"] == "frank"
    Client(srv.state_dir).action(job["id"], "cancel")


def test_a_user_account_without_the_state_directory_uses_its_own_token(srv, people, tif,
                                                                       tmp_path, monkeypatch):
    cfg = tmp_path / "cfg"
    (cfg / "wideprint").mkdir(parents=True)
    (cfg / "wideprint" / "token").write_text(people["alice"].token + "\n")
    monkeypatch.setenv("XDG_CONFIG_HOME", str(cfg))
    monkeypatch.setenv("WIDEPRINT_URL", srv.url)
    monkeypatch.delenv("WIDEPRINT_TOKEN_FILE", raising=False)
    c = Client(tmp_path / "no-state-here", user="someone")
    try:
        job = c.submit(tif, hold=True)["job"]
        assert job["owner"] == "alice"
        with pytest.raises(ApiError) as e:
            c.pause_queue(True)
        assert e.value.status == 403
        assert c.action(job["id"], "cancel")["state"] == "cancelled"
    finally:
        c.close()
