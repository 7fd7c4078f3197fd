"""The state directory under damage (issue 31 item 3, docs/server.md "The state directory"):
a lost or damaged database beside a spool that holds jobs is refused at start with a
message naming the file — the spool is never "cleaned" — and `serve --check --repair`
queues the spooled files again, held; a spool copy damaged on disk fails its job naming
the file instead of printing it."""

import json
import os
import sqlite3
import subprocess
import sys

import numpy as np
import pytest

from support.images import random_planes, write_cmyk_tiff
from support.server import start_server, stop
from wideprint.rip.planes import read_planes

PY = sys.executable


def serve(state, *extra, timeout=60):
    return subprocess.run([PY, "-m", "wideprint.app.cli", "serve", "--device", "emulator",
                           "--state-dir", str(state), "--port", "0", *extra],
                          capture_output=True, text=True, timeout=timeout)


@pytest.fixture
def queued(tmp_path):
    """A state directory whose server queued two held jobs and was stopped."""
    planes = [random_planes(120, 90, seed=s) for s in (5, 6)]
    srcs = [write_cmyk_tiff(tmp_path / f"j{i}.tif", p) for i, p in enumerate(planes)]
    state = tmp_path / "state"
    srv, client = start_server(state, "emulator", media_dir=tmp_path / "media")
    try:
        ids = [client.submit(s, hold=True, settings={"passes": 2})["job"]["id"] for s in srcs]
    finally:
        assert "Traceback" not in stop(srv)
    files = sorted(p.name for p in (state / "spool").iterdir())
    assert len(files) == 2 and len(list((state / "spool-info").iterdir())) == 2
    return state, ids, planes, files


@pytest.mark.parametrize("damage", ["deleted", "truncated", "garbage"])
def test_a_lost_database_is_refused_and_the_spool_kept(queued, damage):
    state, ids, planes, files = queued
    db = state / "wideprint.db"
    for extra in ("-wal", "-shm"):
        if os.path.exists(str(db) + extra):
            os.unlink(str(db) + extra)
    if damage == "deleted":
        db.unlink()
    elif damage == "truncated":
        db.write_bytes(b"")
    else:
        db.write_bytes(b"this is not SQLite" * 300)
    r = serve(state)
    assert r.returncode == 2, r
    assert "Traceback" not in r.stderr
    assert str(db) in r.stderr and "serve --check" in r.stderr, r.stderr
    assert sorted(p.name for p in (state / "spool").iterdir()) == files   # nothing cleaned


def test_check_reports_and_repair_rebuilds_the_queue_held(queued, tmp_path):
    state, ids, planes, files = queued
    (state / "wideprint.db").write_bytes(b"")
    r = subprocess.run([PY, "-m", "wideprint.app.cli", "serve", "--check", "--json",
                        "--state-dir", str(state)], capture_output=True, text=True, timeout=60)
    assert r.returncode == 1, r
    rep = json.loads(r.stdout)
    assert "empty" in rep["database"] and len(rep["orphans"]) == 2 and not rep["ok"]
    r = subprocess.run([PY, "-m", "wideprint.app.cli", "serve", "--check", "--repair",
                        "--state-dir", str(state)], capture_output=True, text=True, timeout=60)
    assert r.returncode == 0, r.stdout + r.stderr
    assert "rebuilt: 2 job(s)" in r.stdout
    assert list(state.glob("wideprint.db.lost-*"))          # set aside, never deleted
    srv, client = start_server(state, "emulator", media_dir=tmp_path / "media")
    try:
        jobs = client.jobs()
        assert [j["state"] for j in jobs] == ["held", "held"]
        assert all("rebuilt from the spool" in j["message"] for j in jobs)
        assert sorted(j["name"] for j in jobs) == ["j0.tif", "j1.tif"]
        for j in jobs:
            client.action(j["id"], "release")
        done = [client.wait(j["id"], timeout=60) for j in jobs]
    finally:
        assert "Traceback" not in stop(srv)
    assert [d["state"] for d in done] == ["done", "done"]
    for d in done:
        want = planes[int(d["name"][1])]
        assert np.array_equal(read_planes(tmp_path / "media" / f"job-{d['id']}.tif"), want)


def test_a_damaged_spool_copy_fails_its_job_naming_the_file(tmp_path):
    planes = random_planes(120, 90, seed=9)
    src = write_cmyk_tiff(tmp_path / "logo.tif", planes)
    state = tmp_path / "state"
    srv, client = start_server(state, "emulator", media_dir=tmp_path / "media")
    try:
        jid = client.submit(src, hold=True)["job"]["id"]
        c = sqlite3.connect(state / "wideprint.db")
        (path,) = c.execute("SELECT spool_path FROM jobs WHERE id=?", (jid,)).fetchone()
        c.close()
        data = bytearray(open(path, "rb").read())
        data[-50:] = bytes(b ^ 0xFF for b in data[-50:])     # same size, other pixels
        open(path, "wb").write(bytes(data))
        client.action(jid, "release")
        j = client.wait(jid, timeout=60)
        report = client.report(jid)
    finally:
        assert "Traceback" not in stop(srv)
    assert j["state"] == "failed" and "logo.tif" in j["message"] and "damaged" in j["message"], j
    assert path in j["message"]
    assert not (tmp_path / "media" / f"job-{jid}.tif").exists()      # not a drop printed
    assert [r["outcome"] for r in report] == ["failed"] and report[0]["strokes_printed"] == 0
