"""The API says what really happened (issue 31): a cancel answers 202 "cancelling" until
the job has stopped and `wideprint cancel` exits 0 only for a cancelled job; a full disk is
507 with a plain reason, never 500; names with bidirectional controls or invisible
characters are shown escaped (API `display_name`, the CLI's table, the log); a damaged
server.json is named as such; `compare` on a truncated TIFF is an error naming the file.

Every connection goes to 127.0.0.1 only; every wait is bounded."""

import errno
import http.client
import json
import logging
import sqlite3
import subprocess
import sys
import time

import pytest

from support.images import random_planes, write_cmyk_tiff
from support.server import wait_for
from wideprint.app.cli import main
from wideprint.app.client import ApiError, Client

PY = sys.executable


@pytest.fixture(scope="module")
def srv(tmp_path_factory):
    from wideprint.app.server import PrintServer, ServerConfig
    root = tmp_path_factory.mktemp("outcomes")
    server = PrintServer(ServerConfig(device="emulator", state_dir=root / "state", port=0))
    server.start()
    yield server
    server.stop(timeout=5)


@pytest.fixture
def client(srv):
    c = Client(srv.state_dir)
    yield c
    c.close()


@pytest.fixture(scope="module")
def tif(tmp_path_factory):
    return write_cmyk_tiff(tmp_path_factory.mktemp("img") / "a.tif", random_planes(8, 16, seed=4))


def post(srv, path, body=b""):
    conn = http.client.HTTPConnection("127.0.0.1", srv.port, timeout=60)
    conn.request("POST", path, body=body, headers={"Authorization": f"Bearer {srv.token}"})
    r = conn.getresponse()
    data = r.read()
    conn.close()
    return r.status, json.loads(data)


# -- cancel ------------------------------------------------------------------------------------
def test_cancel_answers_202_until_the_job_has_stopped(srv, client, tmp_path, monkeypatch, capsys):
    big = write_cmyk_tiff(tmp_path / "long.tif", random_planes(4000, 400, seed=19))
    jid = client.submit(big, settings={"passes": 8})["job"]["id"]
    wait_for(lambda: client.job(jid)["strokes_done"] >= 1, 60, what="the first stroke")
    # the printer does not stop (yet): the worker is told, the job goes on printing
    monkeypatch.setattr(srv.worker, "cancel", lambda job_id: True)
    monkeypatch.setattr(srv, "CANCEL_WAIT_S", 0.5)
    t0 = time.monotonic()
    status, body = post(srv, f"/v1/jobs/{jid}/cancel")
    assert status == 202 and body["cancelling"] is True, body
    assert body["job"]["state"] == "printing" and time.monotonic() - t0 < 3
    capsys.readouterr()
    rc = main(["cancel", str(jid), "--timeout", "1", "--state-dir", str(srv.state_dir)])
    out = capsys.readouterr()
    assert rc == 1, out
    assert f"job {jid}" in out.err and "still printing" in out.err, out
    assert client.job(jid)["state"] == "printing"
    monkeypatch.undo()
    rc = main(["cancel", str(jid), "--state-dir", str(srv.state_dir)])
    out = capsys.readouterr()
    assert rc == 0, out
    assert f"job {jid}: cancelled" in out.out
    assert client.job(jid)["state"] == "cancelled"
    # a job that has ended cannot be cancelled: an error, and the CLI says so
    rc = main(["cancel", str(jid), "--state-dir", str(srv.state_dir)])
    out = capsys.readouterr()
    assert rc == 1 and "already cancelled" in out.err, out


def test_cancel_of_a_waiting_job_is_200_with_its_final_state(srv, client, tif):
    jid = client.submit(tif, hold=True)["job"]["id"]
    status, body = post(srv, f"/v1/jobs/{jid}/cancel")
    assert status == 200 and body["job"]["state"] == "cancelled" and not body.get("cancelling")


# -- full disks --------------------------------------------------------------------------------
FULL = [sqlite3.OperationalError("database or disk is full"),
        OSError(errno.ENOSPC, "No space left on device")]


@pytest.mark.parametrize("exc", FULL, ids=["sqlite", "enospc"])
@pytest.mark.parametrize("action,method", [("release", "release"), ("cancel", "cancel_waiting"),
                                           ("hold", "hold"), ("requeue", "requeue")])
def test_a_full_disk_is_507_with_a_plain_reason(srv, client, tif, monkeypatch, exc, action,
                                                method, caplog):
    jid = client.submit(tif, hold=True)["job"]["id"]

    def full(*a, **k):
        raise exc
    monkeypatch.setattr(srv.spool, method, full)
    status, body = post(srv, f"/v1/jobs/{jid}/{action}")
    assert status == 507, body
    assert "full" in body["error"] or "space" in body["error"], body
    assert "Traceback" not in caplog.text
    monkeypatch.undo()
    client.action(jid, "cancel")


@pytest.mark.parametrize("exc", FULL, ids=["sqlite", "enospc"])
def test_a_full_database_refuses_a_submission_with_507(srv, client, tif, monkeypatch, exc):
    def full(*a, **k):
        raise exc
    monkeypatch.setattr(srv.spool, "add_job", full)
    with pytest.raises(ApiError) as e:
        client.submit(tif)
    assert e.value.status == 507, str(e.value)
    monkeypatch.undo()
    assert not [p for p in srv.spool.spool_dir.iterdir() if p.name.startswith(".")]


# -- names shown to people ---------------------------------------------------------------------
def test_names_with_bidi_and_invisible_characters_are_shown_escaped(srv, client, tif, capsys,
                                                                    caplog):
    from wideprint.app.safe_text import safe
    name = "invoice\u202efdp.exe\u200b\u2066x\u2069.tif"
    assert safe(name) == "invoice\\u202efdp.exe\\u200b\\u2066x\\u2069.tif"
    assert safe("Ünïcødé العربية 日本.tif") == "Ünïcødé العربية 日本.tif"     # letters stay
    job = client.submit(tif, name=name, hold=True)["job"]
    assert job["name"] == name                                    # stored exactly
    assert job["display_name"] == safe(name)
    capsys.readouterr()
    assert main(["queue", "--state-dir", str(srv.state_dir)]) == 0
    out = capsys.readouterr().out
    assert safe(name) in out and "\u202e" not in out, out
    caplog.set_level(logging.INFO, logger="wideprint")
    logging.getLogger("wideprint.server").info("job %s: %s", job["id"], name)
    assert "\u202e" not in caplog.text and safe(name) in caplog.text
    client.action(job["id"], "cancel")


# -- smaller --------------------------------------------------------------------------------------
def test_a_damaged_server_json_is_named_not_taken_for_no_server(tmp_path, capsys):
    state = tmp_path / "state"
    state.mkdir()
    (state / "server.json").write_bytes(b"\x00garbage{")
    (state / "token").write_text("t" * 43)
    with pytest.raises(ApiError) as e:
        Client(state)
    assert str(state / "server.json") in str(e.value) and "no wideprint server" not in str(e.value)
    for cmd in (["status"], ["queue"]):
        assert main([*cmd, "--state-dir", str(state)]) == 3
        err = capsys.readouterr().err
        assert "server.json" in err and "unreadable" in err, err


def test_compare_on_a_truncated_tiff_is_an_error_naming_the_file(tmp_path):
    a = write_cmyk_tiff(tmp_path / "a.tif", random_planes(64, 64, seed=1))
    b = tmp_path / "b.tif"
    data = a.read_bytes()
    b.write_bytes(data[:len(data) // 3])
    for args in ([str(a), str(b)], [str(b), str(a)]):
        r = subprocess.run([PY, "-m", "wideprint.app.compare", *args], capture_output=True,
                           text=True, timeout=120)
        assert r.returncode not in (0, 1), r
        assert "Traceback" not in r.stderr and str(b) in r.stderr, r.stderr


def test_the_gui_shows_names_escaped(monkeypatch):
    pytest.importorskip("PySide6")
    monkeypatch.setenv("QT_QPA_PLATFORM", "offscreen")
    from PySide6.QtCore import Qt
    from wideprint.app.gui.jobs_view import JobsModel
    m = JobsModel()
    m.jobs = [dict(id=7, name="a\u202egpj.exe", source="api", size=10, state="failed",
                   message="a\u202egpj.exe: not an image file")]
    col = m.columns.index("Job")
    assert m.data(m.index(0, col)) == "7  a\\u202egpj.exe"
    assert "\u202e" not in m.data(m.index(0, col), Qt.ToolTipRole)
    assert "\u202e" not in m.data(m.index(0, m.columns.index("State")), Qt.ToolTipRole)
