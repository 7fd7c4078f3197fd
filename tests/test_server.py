"""The print server (issue 7, docs/server.md): nothing submitted is ever lost — a server
killed mid-job resumes it bit-exact; 1,000 concurrent submissions are all accepted once,
in order per client; hostile inputs are refused with their reason; hot folders take only
complete files; the accounting matches the planes; a failed or cancelled job requeued
prints again bit-exact with both attempts accounted; edited presets are taken without a
restart and a broken presets file changes nothing."""

import csv
import http.client
import io
import json
import os
import re
import signal
import sqlite3
import subprocess
import sys
import threading
import time

import numpy as np
import pytest

from support.images import random_planes, tiny_tiff, write_cmyk_tiff
from support.server import inprocess_server, raw_request, start_server, stop, wait_for
from support.server import start_emulator as _start_emulator
from wideprint.app.client import ApiError, Client
from wideprint.rip.planes import read_planes

PY = sys.executable
DONE = ("done", "failed", "cancelled")


# -- helpers ------------------------------------------------------------------------------------
def start_emulator(tmp_path):
    return _start_emulator(tmp_path, event_log=tmp_path / "emulator.jsonl")


def db_job(state, job_id):
    c = sqlite3.connect(state / "wideprint.db")
    c.row_factory = sqlite3.Row
    try:
        return dict(c.execute("SELECT * FROM jobs WHERE id=?", (job_id,)).fetchone())
    finally:
        c.close()


def mid_line(cur):
    """The status shows a stroke being printed: started, some columns fired, not finished."""
    if not cur or cur.get("stroke_index") is None or "telemetry" not in cur:
        return None
    if cur["stroke_index"] == cur["strokes_printed"] and cur["telemetry"]["fires_done"] > 0:
        return cur
    return None


def lines_printed(event_log):
    ids = []
    for line in open(event_log):
        e = json.loads(line)
        if e.get("event") == "line":
            ids.append(e["stroke"])
    return ids


# -- kill -9 in the middle of a job ------------------------------------------------------------
@pytest.mark.parametrize("on_crash", ["resume", "hold"])
def test_server_killed_mid_job_resumes_bit_exact(tmp_path, on_crash):
    planes = random_planes(700, 900, seed=71)
    src = write_cmyk_tiff(tmp_path / "big.tif", planes)
    state = tmp_path / "state"
    emu, spec = start_emulator(tmp_path)
    try:
        srv, client = start_server(state, spec, "--on-crash", on_crash)
        try:
            job = client.submit(src, settings={"passes": 4, "bidir": True})["job"]
            jid = job["id"]
            os.unlink(src)                       # the spool has its own copy
            j = wait_for(lambda: (lambda j: j if j["strokes_done"] >= 2 else None)(client.job(jid)),
                         what="two strokes printed")
            assert j["state"] == "printing" and j["strokes_total"] > j["strokes_done"] + 2
            in_flight = None
            if on_crash == "resume":             # kill it in the middle of a line
                in_flight = wait_for(lambda: mid_line(client.status()["current"]), 20,
                                     poll=0.005, what="a stroke half printed")
        finally:
            srv.send_signal(signal.SIGKILL)
            srv.wait(10)
        before = db_job(state, jid)
        assert before["state"] == "printing"
        cp = json.loads(before["checkpoint"])
        assert cp["next_stroke"] >= 2
        if in_flight is not None:
            # it died in that stroke or soon after (the status reply and the kill are not
            # instantaneous; the printer may also finish a line from its FIFOs and ring)
            assert cp["next_stroke"] >= in_flight["stroke_index"]

        srv, client = start_server(state, spec, "--on-crash", on_crash)
        try:
            if on_crash == "hold":
                j = client.job(jid)
                assert j["state"] == "held" and "interrupted" in j["message"], j
                time.sleep(0.5)
                assert client.job(jid)["state"] == "held"       # nothing moves by itself
                client.action(jid, "release")
            done = client.wait(jid, timeout=60)
            assert done["state"] == "done", done
            jobs = client.jobs("queued,held,printing")
            all_jobs = [j for j in client.request("GET", "/v1/jobs")["jobs"]]
            prints = client.report()
        finally:
            err = stop(srv)
        assert "Traceback" not in err, err
    finally:
        stop(emu)
    assert jobs == []                                            # nothing left in the queue
    assert [j["id"] for j in all_jobs] == [jid]                 # the job once, done
    assert np.array_equal(read_planes(tmp_path / f"media-{jid}.tif"), planes)
    ids = lines_printed(tmp_path / "emulator.jsonl")
    assert len(ids) == len(set(ids)) == done["strokes_total"]    # no stroke twice, none missing
    assert len(prints) == 1 and prints[0]["resumed"] == 1 and prints[0]["outcome"] == "done"
    assert [prints[0][f"drops_{c}"] for c in "cmyk"] == planes.reshape(-1, 4).sum(0).tolist()


# -- an in-process server for the API, hot folder and accounting tests --------------------------
@pytest.fixture(scope="module")
def srv(tmp_path_factory):
    server = inprocess_server(tmp_path_factory.mktemp("server"), scan_interval=0.2,
                              settle_s=1.0, max_file_bytes=2_000_000)
    yield server
    server.stop(timeout=5)


@pytest.fixture
def client(srv):
    c = Client(srv.state_dir)
    yield c
    c.close()


def test_api_binds_loopback_and_token_file_is_private(srv):
    assert srv.http.server_address[0] == "127.0.0.1"
    assert (srv.state_dir / "token").stat().st_mode & 0o777 == 0o600


def test_no_token_or_wrong_token_is_401(srv):
    for token in (None, "wrong", srv.token + "x", ""):
        status, body = raw_request(srv, "GET", "/v1/status", token=token)
        assert status == 401, token
        assert "token" in body["error"]
    status, body = raw_request(srv, "POST", "/v1/jobs", body=tiny_tiff(), token="nope",
                               headers={"X-Wideprint-Job": json.dumps({"name": "a.tif"})})
    assert status == 401
    status, _ = raw_request(srv, "GET", "/v1/status", headers={"Authorization": f"Basic {srv.token}"},
                            token=None)
    assert status == 401


@pytest.mark.parametrize("name", ["../../etc/passwd", "a/b.tif", "..", ".hidden.tif",
                                  "..\\x.tif", "a\nb.tif", "/abs.tif"])
def test_path_traversal_names_are_refused(client, name):
    with pytest.raises(ApiError) as e:
        client.submit_bytes(tiny_tiff(), name=name)
    assert e.value.status == 400
    assert "name" in str(e.value)


@pytest.mark.parametrize("desc,reason", [
    ({"name": "a.tif", "settings": {"speed": 3}}, "unknown setting 'speed'"),
    ({"name": "a.tif", "color": "red"}, "unknown field 'color'"),
    ({"name": "a.tif", "settings": {"passes": 5}}, "passes must be one of"),
    ({"name": "a.tif", "settings": {"passes": "2"}}, "passes must be one of"),
    ({"name": "a.tif", "settings": {"dpi": 1200}}, "dpi must be one of"),
    ({"name": "a.tif", "settings": {"bidir": "yes"}}, "bidir must be true or false"),
    ({"name": "a.tif", "settings": {"ink_limit": 1000}}, "ink_limit 1000 is out of range"),
    ({"name": "a.tif", "settings": {"dither": "magic"}}, "dither must be one of"),
    ({"name": "a.tif", "settings": {"input_icc": "../../etc/x.icc"}}, "input_icc"),
    ({"name": "a.tif", "settings": []}, "settings must be a JSON object"),
    ({"name": "a.tif", "settings": {"placement": {"align": "middle"}}}, "align must be one of"),
    ({"name": "a.tif", "settings": {"placement": {"x_mm": "10"}}}, "placement x_mm must be a number"),
    ({"name": "a.tif", "settings": {"placement": {"top_mm": -4}}}, "top_mm must not be negative"),
    ({"name": "a.tif", "settings": {"placement": {"margin_mm": True}}}, "margin_mm must be a number"),
    ({"name": "a.tif", "copies": 0}, "copies 0 is out of range"),
    ({"name": "a.tif", "copies": True}, "copies must be an integer"),
    ({"name": "a.tif", "priority": 1000}, "priority 1000 is out of range"),
    ({"name": "a.tif", "preset": "nope"}, "unknown preset 'nope'"),
    ({"name": 7}, "name must be a string"),
    ({}, "name is required"),
    ([1, 2], "must be a JSON object"),
])
def test_bad_job_descriptions_are_refused_with_their_reason(srv, desc, reason):
    status, body = raw_request(srv, "POST", "/v1/jobs", body=tiny_tiff(),
                               headers={"X-Wideprint-Job": json.dumps(desc)})
    assert status == 400, body
    assert reason in body["error"], body


def test_bad_json_is_refused(srv, client):
    status, body = raw_request(srv, "POST", "/v1/jobs", body=tiny_tiff(),
                               headers={"X-Wideprint-Job": "{name: a.tif"})
    assert status == 400 and "bad JSON" in body["error"]
    status, body = raw_request(srv, "POST", "/v1/jobs", body=tiny_tiff())
    assert status == 400 and "X-Wideprint-Job" in body["error"]
    job = client.submit_bytes(tiny_tiff(), name="patch.tif", hold=True)["job"]
    for bad, reason in ((b"{not json", "bad JSON"), (b'{"priority": "high"}', "integer"),
                        (b'{"priority": 1, "state": "done"}', "expected"),
                        (b'{"priority": -101}', "out of range")):
        status, body = raw_request(srv, "PATCH", f"/v1/jobs/{job['id']}", body=bad,
                                   headers={"Content-Type": "application/json"})
        assert status == 400 and reason in body["error"], body
    status, body = raw_request(srv, "POST", "/v1/queue", body=b'{"paused": "yes"}')
    assert status == 400
    status, body = raw_request(srv, "GET", "/v1/jobs/999999")
    assert status == 404
    client.action(job["id"], "cancel")


def test_oversize_upload_is_refused_before_it_is_read(srv):
    conn = http.client.HTTPConnection("127.0.0.1", srv.port, timeout=10)
    conn.putrequest("POST", "/v1/jobs")
    conn.putheader("Authorization", f"Bearer {srv.token}")
    conn.putheader("X-Wideprint-Job", json.dumps({"name": "huge.tif"}))
    conn.putheader("Content-Length", str(5 * 1024 ** 3))
    conn.endheaders()
    r = conn.getresponse()                 # answered without sending a byte of the body
    body = json.loads(r.read())
    conn.close()
    assert r.status == 413 and "limit" in body["error"]


def test_client_gets_the_reason_for_an_oversize_file(srv, client, tmp_path):
    big = tmp_path / "big.tif"
    big.write_bytes(b"II*\x00" + bytes(srv.config.max_file_bytes))
    with pytest.raises(ApiError) as e:
        client.submit(big)
    assert e.value.status == 413 and "limit" in str(e.value)
    assert client.status()["server"]["pid"] == os.getpid()       # and the client goes on


def test_corrupt_image_fails_its_job_alone(srv, client, tmp_path):
    planes = random_planes(40, 64, seed=9)
    good = write_cmyk_tiff(tmp_path / "good.tif", planes)
    bad = client.submit_bytes(b"II*\x00" + b"\xff" * 200, name="corrupt.tif")["job"]
    ok = client.submit(good)["job"]
    badj = client.wait(bad["id"], timeout=60)
    okj = client.wait(ok["id"], timeout=60)
    assert badj["state"] == "failed" and "corrupt.tif" in badj["message"], badj
    assert okj["state"] == "done", okj
    assert np.array_equal(read_planes(srv.root / "media" / f"job-{ok['id']}.tif"), planes)
    assert client.status()["queue"]["paused"] is False


def test_rtl_in_a_hot_folder_and_a_hostile_postscript_job(srv, client, tmp_path):
    """Documents and RTL are jobs like images: an RTL dropped into a hot folder prints its
    dots bit-exact; a PostScript program that reads files fails its own job with
    Ghostscript's reason, and the queue goes on."""
    import shutil
    from support.rtl_encode import encode_bits
    planes = random_planes(50, 120, seed=21)
    folder = srv.root / "hot" / "banner"
    (tmp_path / "plot.rtl").write_bytes(encode_bits(planes, "simple-kcmy", 2))
    before = {j["id"] for j in client.request("GET", "/v1/jobs")["jobs"]}
    os.rename(tmp_path / "plot.rtl", folder / "plot.rtl")
    jobs = wait_for(lambda: [j for j in client.request("GET", "/v1/jobs")["jobs"]
                             if j["id"] not in before and j["name"] == "plot.rtl"], 20, what="the RTL job")
    done = client.wait(jobs[0]["id"], 60)
    assert done["state"] == "done", done
    assert np.array_equal(read_planes(srv.root / "media" / f"job-{done['id']}.tif"), planes)
    if shutil.which("gs"):
        bad = client.submit_bytes(b"%!PS\n(/etc/passwd) (r) file showpage\n", name="sneaky.ps")["job"]
        badj = client.wait(bad["id"], timeout=60)
        assert badj["state"] == "failed" and "invalidfileaccess" in badj["message"], badj


def test_hold_release_cancel_and_priority(srv, client):
    client.pause_queue(True)
    try:
        a = client.submit_bytes(tiny_tiff(), name="a.tif")["job"]
        b = client.submit_bytes(tiny_tiff(), name="b.tif", priority=5)["job"]
        c = client.submit_bytes(tiny_tiff(), name="c.tif", hold=True)["job"]
        q = {j["id"]: j for j in client.jobs()}
        assert q[b["id"]]["position"] < q[a["id"]]["position"]   # priority first
        assert q[c["id"]]["state"] == "held" and q[c["id"]]["position"] is None
        assert client.action(a["id"], "hold")["state"] == "held"
        assert client.action(c["id"], "release")["state"] == "queued"
        assert client.action(a["id"], "cancel")["state"] == "cancelled"
        for what in ("cancel", "release", "hold"):
            with pytest.raises(ApiError) as e:
                client.action(a["id"], what)
            assert e.value.status == 409 and "cancelled" in str(e.value)
    finally:
        client.pause_queue(False)
    assert client.wait(b["id"], 60)["state"] == "done"
    assert client.wait(c["id"], 60)["state"] == "done"


# -- 1,000 concurrent submissions --------------------------------------------------------------
def test_thousand_concurrent_submissions_accepted_once_in_order(tmp_path, print_server):
    server = print_server(tmp_path, media=False, hot=False, start_paused=True)
    data = tiny_tiff()
    errors, per_client = [], {}

    def client_thread(n):
        c = Client(server.state_dir)
        ids = []
        try:
            for i in range(250):
                r = c.submit_bytes(data, name=f"c{n}-{i:03d}.tif", client=f"c{n}",
                                   key=f"c{n}-{i}")
                assert r["duplicate"] is False
                ids.append(r["job"]["id"])
            # a retry of an accepted submission is the same job, not a second one
            r = c.submit_bytes(data, name=f"c{n}-000.tif", client=f"c{n}", key=f"c{n}-0")
            assert r["duplicate"] is True and r["job"]["id"] == ids[0]
        except Exception as exc:  # noqa: BLE001
            errors.append(exc)
        finally:
            c.close()
        per_client[n] = ids

    t0 = time.monotonic()
    threads = [threading.Thread(target=client_thread, args=(n,)) for n in range(4)]
    for t in threads:
        t.start()
    for t in threads:
        t.join()
    took = time.monotonic() - t0
    assert not errors, errors
    jobs = Client(server.state_dir).jobs()
    assert len(jobs) == 1000 and all(j["state"] == "queued" for j in jobs)
    assert len({j["name"] for j in jobs}) == 1000
    for n, ids in per_client.items():
        assert len(ids) == 250 and ids == sorted(ids)          # monotonic per client
        mine = [j for j in jobs if j["client"] == f"c{n}"]
        assert [j["name"] for j in mine] == [f"c{n}-{i:03d}.tif" for i in range(250)]
    # the queue order (position) is the acceptance order
    pos = sorted(jobs, key=lambda j: j["position"])
    assert [j["id"] for j in pos] == sorted(j["id"] for j in jobs)
    assert len(list((server.state_dir / "spool").iterdir())) == 1000
    print(f"1000 submissions in {took:.1f} s")


# -- hot folders -------------------------------------------------------------------------------
def test_hot_folder_slow_copy_becomes_one_job_when_complete(srv, client, tmp_path):
    planes = random_planes(60, 200, seed=13)
    data = write_cmyk_tiff(tmp_path / "slow.tif", planes).read_bytes()
    folder = srv.root / "hot" / "photo"
    dest = folder / "slow.tif"
    before = {j["id"] for j in client.request("GET", "/v1/jobs")["jobs"]}

    def hot_jobs():
        return [j for j in client.request("GET", "/v1/jobs")["jobs"]
                if j["id"] not in before and j["name"] == "slow.tif"]
    chunk = len(data) // 6 + 1
    with open(dest, "wb") as f:
        for i in range(0, len(data), chunk):
            f.write(data[i:i + chunk])
            f.flush()
            time.sleep(0.6)                  # three scans with the size unchanged
            assert hot_jobs() == [], "a job from a file still being written"
    jobs = wait_for(hot_jobs, 10, what="the hot-folder job")
    done = client.wait(jobs[0]["id"], 60)
    assert done["state"] == "done" and done["preset"] == "photo" and done["source"] == "hot:photo"
    assert done["settings"] == srv.presets["photo"]
    wait_for(lambda: (folder / "done" / "slow.tif").exists(), 10, what="done/slow.tif")
    assert not dest.exists()
    time.sleep(0.6)
    assert len(hot_jobs()) == 1                                       # exactly one job
    assert np.array_equal(read_planes(srv.root / "media" / f"job-{done['id']}.tif"), planes)


def test_hot_folder_ignores_partial_names_until_renamed(srv, client, tmp_path):
    folder = srv.root / "hot" / "banner"
    (folder / "big.tif.part").write_bytes(tiny_tiff())
    (folder / ".hidden.tif").write_bytes(tiny_tiff())
    time.sleep(0.8)
    assert (folder / "big.tif.part").exists() and (folder / ".hidden.tif").exists()
    os.rename(folder / "big.tif.part", folder / "big.tif")
    wait_for(lambda: (folder / "done" / "big.tif").exists(), 20, what="done/big.tif")
    assert (folder / ".hidden.tif").exists()


def test_hot_folder_corrupt_file_goes_to_failed_with_reason(srv):
    folder = srv.root / "hot" / "photo"
    (folder / "broken.jpg").write_bytes(b"\xff\xd8\xff\xe0garbage" * 10)
    reason = folder / "failed" / "broken.jpg.reason.txt"
    wait_for(reason.exists, 20, what="failed/broken.jpg.reason.txt")
    assert (folder / "failed" / "broken.jpg").exists()
    assert "failed" in reason.read_text() and "broken.jpg" in reason.read_text()


def test_hot_folder_refuses_symlinks_fifos_and_oversize(srv, tmp_path):
    folder = srv.root / "hot" / "photo"
    outside = tmp_path / "secret.tif"
    outside.write_bytes(tiny_tiff())
    os.symlink(outside, folder / "link.tif")
    os.mkfifo(folder / "pipe.tif")
    with open(folder / "huge.tif", "wb") as f:
        f.truncate(srv.config.max_file_bytes + 1)        # sparse
    failed = folder / "failed"
    for name, why in (("link.tif", "outside the hot folder"), ("pipe.tif", "FIFO"),
                      ("huge.tif", "limit")):
        reason = failed / f"{name}.reason.txt"
        wait_for(reason.exists, 10, what=reason.name)
        assert why in reason.read_text(), reason.read_text()
        assert os.path.lexists(failed / name)
    assert (failed / "link.tif").is_symlink() and outside.exists()   # the link moved, not its target


# -- accounting ----------------------------------------------------------------------------------
def test_accounting_csv_columns_and_values(srv, client, tmp_path):
    from wideprint.app.server import CSV_COLUMNS
    from wideprint.rip.pipeline import RipJob, RipSettings
    planes = random_planes(300, 480, seed=17)
    src = write_cmyk_tiff(tmp_path / "acct.tif", planes)
    job = client.submit(src, preset="banner", copies=2)["job"]
    done = client.wait(job["id"], 60)
    assert done["state"] == "done" and done["copies_done"] == 2
    text = client.report_csv(job["id"])
    rows = list(csv.DictReader(io.StringIO(text)))
    assert text.splitlines()[0].split(",") == CSV_COLUMNS
    assert len(rows) == 2 and [r["copy"] for r in rows] == ["1", "2"]
    dots = RipJob(str(src), RipSettings(**srv.presets["banner"]), srv.profile).write_planes(
        tmp_path / "planes.tif")
    assert dots.tolist() == planes.reshape(-1, 4).sum(0).tolist()
    pl = srv.profile.drop_volume_pl
    for r in rows:
        assert r["file"] == "acct.tif" and r["outcome"] == "done" and r["preset"] == "banner"
        assert (r["passes"], r["bidir"], r["dither"]) == ("2", "1", "bayer")
        assert [int(r[f"drops_{c}"]) for c in "cmyk"] == dots.tolist()
        for c, d in zip("cmyk", dots):
            assert float(r[f"ink_{c}_ml"]) == pytest.approx(d * pl * 1e-9, abs=1e-9)
        assert float(r["ink_total_ml"]) == pytest.approx(dots.sum() * pl * 1e-9, abs=1e-8)
        assert r["strokes_printed"] == r["strokes_total"] and int(r["strokes_total"]) > 1
        assert (int(r["width_dots"]), int(r["height_rows"])) == (480, 300)
        k = srv.profile.k(300)
        area = 480 * k / srv.profile.counts_per_inch * 0.0254 * 300 * srv.profile.row_um * 1e-6
        assert float(r["area_m2"]) == pytest.approx(area, rel=1e-5)
        assert float(r["duration_s"]) > 0 and r["ended"] >= r["started"]
    out = tmp_path / "report.csv"
    r = subprocess.run([PY, "-m", "wideprint.app.cli", "report", "--state-dir",
                        str(srv.state_dir), "--csv", str(out)], capture_output=True, text=True,
                       timeout=60)
    assert r.returncode == 0, r.stderr
    assert out.read_text().splitlines()[0].split(",") == CSV_COLUMNS
    assert len(out.read_text().splitlines()) >= 3


def test_cli_submit_queue_status(srv, tmp_path):
    src = write_cmyk_tiff(tmp_path / "cli.tif", random_planes(30, 40, seed=2))
    base = [PY, "-m", "wideprint.app.cli"]
    sd = ["--state-dir", str(srv.state_dir)]
    r = subprocess.run(base + ["submit", str(src), *sd, "--passes", "2", "--no-bidir",
                               "--json", "--wait", "60"], capture_output=True, text=True, timeout=90)
    assert r.returncode == 0, r.stderr
    job = json.loads(r.stdout)[0]
    assert job["settings"] == {"passes": 2, "bidir": False}
    r = subprocess.run(base + ["queue", "--all", "--json", *sd], capture_output=True, text=True,
                       timeout=60)
    assert any(j["id"] == job["id"] and j["state"] == "done" for j in json.loads(r.stdout))
    r = subprocess.run(base + ["status", *sd], capture_output=True, text=True, timeout=60)
    assert r.returncode == 0 and "queue    running" in r.stdout, r.stdout + r.stderr
    r = subprocess.run(base + ["submit", str(src), "--state-dir", str(tmp_path / "nothing")],
                       capture_output=True, text=True, timeout=60)
    assert r.returncode == 3 and "no wideprint server" in r.stderr


def test_cancel_a_printing_job_stops_it_and_the_queue_goes_on(srv, client, tmp_path):
    big = write_cmyk_tiff(tmp_path / "long.tif", random_planes(1000, 400, seed=19))
    small = write_cmyk_tiff(tmp_path / "next.tif", random_planes(20, 30, seed=20))
    job = client.submit(big, settings={"passes": 8})["job"]
    nxt = client.submit(small)["job"]
    wait_for(lambda: client.job(job["id"])["strokes_done"] >= 1, 30, poll=0.005,
             what="the first stroke")
    assert client.action(job["id"], "cancel")["state"] == "cancelled"
    j = client.job(job["id"])
    assert j["strokes_done"] < j["strokes_total"] and "cancelled" in j["message"]
    assert client.wait(nxt["id"], 60)["state"] == "done"
    rows = client.report(job["id"])
    assert len(rows) == 1 and rows[0]["outcome"] == "cancelled"
    assert 0 < rows[0]["strokes_printed"] < rows[0]["strokes_total"]
    # the cancelled job keeps its spooled copy (it may be requeued); the done one too, in
    # the archive (it may be reprinted: docs/server.md "Archive and reprint")
    assert os.path.isfile(db_job(srv.state_dir, job["id"])["spool_path"])
    assert os.path.isfile(db_job(srv.state_dir, nxt["id"])["spool_path"])


# -- requeue -------------------------------------------------------------------------------------
def cli(srv_or_state, *args, timeout=60):
    state = getattr(srv_or_state, "state_dir", srv_or_state)
    return subprocess.run([PY, "-m", "wideprint.app.cli", *args, "--state-dir", str(state)],
                          capture_output=True, text=True, timeout=timeout)


def test_requeue_a_cancelled_job_prints_it_again_bit_exact(srv, client, tmp_path):
    planes = random_planes(400, 300, seed=23)
    src = write_cmyk_tiff(tmp_path / "again.tif", planes)
    job = client.submit(src, settings={"passes": 4}, priority=3)["job"]
    jid = job["id"]
    os.unlink(src)                                   # only the spool's copy is left
    wait_for(lambda: client.job(jid)["strokes_done"] >= 1, 30, poll=0.005, what="the first stroke")
    with pytest.raises(ApiError) as e:               # not while it prints
        client.action(jid, "requeue")
    assert e.value.status == 409 and f"job {jid} is printing" in str(e.value)
    assert client.action(jid, "cancel")["state"] == "cancelled"
    first = client.job(jid)
    assert 0 < first["strokes_done"] < first["strokes_total"]

    r = cli(srv, "requeue", str(jid))
    assert r.returncode == 0, r.stderr
    assert r.stdout.strip() == f"job {jid}: queued"
    done = client.wait(jid, 60)
    assert done["state"] == "done" and done["message"] == "", done
    assert (done["attempt"], done["copies_done"], done["priority"]) == (2, 1, 3)
    assert done["settings"] == {"passes": 4}
    assert done["strokes_done"] == done["strokes_total"]
    # a fresh print from the first stroke, on a fresh placement: the media is the image
    assert np.array_equal(read_planes(srv.root / "media" / f"job-{jid}.tif"), planes)
    # both attempts are in the accounting
    rows = client.report(jid)
    assert [(r["attempt"], r["outcome"]) for r in rows] == [(1, "cancelled"), (2, "done")]
    assert 0 < rows[0]["strokes_printed"] < rows[0]["strokes_total"]
    assert rows[1]["strokes_printed"] == rows[1]["strokes_total"] and rows[1]["resumed"] == 0
    assert [rows[1][f"drops_{c}"] for c in "cmyk"] == planes.reshape(-1, 4).sum(0).tolist()
    text = client.report_csv(jid)
    assert [(r["attempt"], r["outcome"]) for r in csv.DictReader(io.StringIO(text))] == \
        [("1", "cancelled"), ("2", "done")]
    assert os.path.isfile(db_job(srv.state_dir, jid)["spool_path"])  # done: archived
    with pytest.raises(ApiError) as e:
        client.action(jid, "requeue")
    assert e.value.status == 409 and f"job {jid} is done" in str(e.value)
    assert f"reprint it (wideprint reprint {jid})" in str(e.value)


def _wait_state(client, job_id, states, timeout=60):
    deadline = time.monotonic() + timeout
    while time.monotonic() < deadline:
        job = client.job(job_id)
        if job["state"] in states:
            return job
        time.sleep(0.02)
    raise AssertionError(f"job {job_id} never reached {states}: {job}")


def test_a_printer_fault_stops_the_printer_not_the_queue(srv, client, tmp_path):
    """The paper runs out in job 1 of 3: job 1 is held with the fault and its checkpoint,
    jobs 2 and 3 stay queued (nothing fails); the operator loads paper and clears the fault:
    job 1 resumes at its first unfinished stroke and all three print bit-exact."""
    client.pause_queue(True)
    planes = [random_planes(300, 200, seed=29 + i) for i in range(3)]
    ids = [client.submit(write_cmyk_tiff(tmp_path / f"roll{i}.tif", p),
                         settings={"passes": 4})["job"]["id"] for i, p in enumerate(planes)]
    client.pause_queue(False)
    wait_for(lambda: client.job(ids[0])["strokes_done"] >= 1, 30, poll=0.005, what="the first stroke")
    emu = srv.worker.dev.emulator
    emu.paper_left_steps = 1                         # the roll ends at the next feed
    stopped = _wait_state(client, ids[0], ("held", "failed", "done"))
    try:
        assert stopped["state"] == "held" and "paper out" in stopped["fault"], stopped
        time.sleep(0.3)
        assert [client.job(i)["state"] for i in ids[1:]] == ["queued", "queued"]
        st = client.status()
        printer = st["printers"][0]
        assert printer["state"] == "fault" and "paper out" in printer["fault"] and printer["paused"]
        with pytest.raises(ApiError) as e:                   # release is not the way out
            client.action(ids[0], "release")
        assert e.value.status == 409 and "clear the fault" in str(e.value)
        emu.paper_left_steps = None                      # a new roll ...
        r = client.request("POST", "/v1/printers/main/clear-fault", body={"then": "resume"})
        assert r["jobs"] == [ids[0]] and r["then"] == "resume"
    finally:
        emu.paper_left_steps = None
        client.pause_queue(False)
    for job_id, p in zip(ids, planes):
        done = client.wait(job_id, 120)
        assert done["state"] == "done", done
        assert np.array_equal(read_planes(srv.root / "media" / f"job-{job_id}.tif"), p)
    assert [r["outcome"] for r in client.report(ids[0])] == ["stopped", "done"]


def test_a_cleared_fault_can_fail_the_stopped_job(srv, client, tmp_path):
    planes = random_planes(300, 200, seed=39)
    jid = client.submit(write_cmyk_tiff(tmp_path / "short.tif", planes),
                        settings={"passes": 4})["job"]["id"]
    wait_for(lambda: client.job(jid)["strokes_done"] >= 1, 30, poll=0.005, what="the first stroke")
    emu = srv.worker.dev.emulator
    emu.paper_left_steps = 1
    try:
        assert _wait_state(client, jid, ("held", "failed", "done"))["state"] == "held"
        emu.paper_left_steps = None
        r = client.request("POST", "/v1/printers/main/clear-fault", body={"then": "fail"})
        assert r["jobs"] == [jid]
    finally:
        emu.paper_left_steps = None
        client.pause_queue(False)
    job = client.job(jid)
    assert job["state"] == "failed" and "paper out" in job["message"] and "operator" in job["message"]
    assert client.status()["printers"][0]["state"] == "idle"


def test_requeue_is_refused_with_the_reason(srv, client):
    client.pause_queue(True)
    try:
        q = client.submit_bytes(tiny_tiff(), name="waits.tif")["job"]
        h = client.submit_bytes(tiny_tiff(), name="held.tif", hold=True)["job"]
        for job, state in ((q, "queued"), (h, "held")):
            with pytest.raises(ApiError) as e:
                client.action(job["id"], "requeue")
            assert e.value.status == 409
            assert f"job {job['id']} is {state}: only a failed or cancelled job" in str(e.value)
        status, body = raw_request(srv, "POST", "/v1/jobs/999999/requeue")
        assert status == 404 and "no job 999999" in body["error"]
        # a cancelled job whose spooled copy was deleted behind the server's back
        client.action(q["id"], "cancel")
        os.unlink(db_job(srv.state_dir, q["id"])["spool_path"])
        r = cli(srv, "requeue", str(q["id"]), str(h["id"]))
        assert r.returncode == 1
        assert f"job {q['id']}: its spooled file is gone" in r.stderr, r.stderr
        assert f"job {h['id']} is held" in r.stderr, r.stderr
        assert client.job(q["id"])["state"] == "cancelled"
    finally:
        client.action(h["id"], "cancel")
        client.pause_queue(False)


def test_spool_copies_of_ended_jobs_expire(tmp_path):
    from wideprint.app.server import PrintServer, ServerConfig
    state = tmp_path / "state"

    def server(**kw):
        s = PrintServer(ServerConfig(device="emulator", state_dir=state, port=0,
                                     start_paused=True, **kw))
        s.start()
        return s, Client(state)
    s, c = server(keep_failed_s=3600)
    try:
        old = c.submit_bytes(tiny_tiff(), name="old.tif")["job"]
        new = c.submit_bytes(tiny_tiff(), name="new.tif")["job"]
        c.action(old["id"], "cancel")
        c.action(new["id"], "cancel")
        kept = db_job(state, old["id"])["spool_path"]
        assert os.path.isfile(kept)
    finally:
        c.close()
        s.stop(timeout=5)
    db = sqlite3.connect(state / "wideprint.db")       # cancelled two hours ago
    db.execute("UPDATE jobs SET finished=finished-7200 WHERE id=?", (old["id"],))
    db.commit()
    db.close()
    s, c = server(keep_failed_s=3600)                  # the new server expires it
    try:
        assert not os.path.exists(kept)
        with pytest.raises(ApiError) as e:
            c.action(old["id"], "requeue")
        assert e.value.status == 410 and f"job {old['id']}: its spooled file is gone" in str(e.value)
        assert c.action(new["id"], "requeue")["state"] == "queued"   # still within the hour
        c.action(new["id"], "cancel")
    finally:
        c.close()
        s.stop(timeout=5)
    s, c = server(keep_failed_s=0)                     # 0: deleted at once, as before
    try:
        j = c.submit_bytes(tiny_tiff(), name="x.tif")["job"]
        c.action(j["id"], "cancel")
        assert db_job(state, j["id"])["spool_path"] is None
        assert list((state / "spool").iterdir()) == []
        with pytest.raises(ApiError) as e:
            c.action(j["id"], "requeue")
        assert e.value.status == 410
    finally:
        c.close()
        s.stop(timeout=5)


def schema_2() -> str:
    """The schema before strokes had their word: the stroke counts were named passes_*."""
    from wideprint.app.server.spool import RENAMED_COLUMNS, SCHEMA
    old = SCHEMA
    for _, before, now in RENAMED_COLUMNS:
        old = re.sub(rf"\b{now}\b", before, old)
    assert not re.search(r"\bstrokes_", old)
    return old


def test_schema_1_database_gets_the_attempt_columns(tmp_path):
    from wideprint.app.server.spool import SCHEMA_VERSION, Spool
    state = tmp_path / "state"
    state.mkdir()
    old = re.sub(r"\n\s*attempt[^\n]*", "", schema_2())           # schema 1: no attempt columns
    old = re.sub(r",(\s*(--[^\n]*)?\n\);)", r"\1", old)
    assert "attempt" not in old
    db = sqlite3.connect(state / "wideprint.db")
    db.executescript(old + "INSERT INTO meta VALUES ('schema', '1');"
                     "INSERT INTO jobs (name, source, size, sha256, settings, state, submitted) "
                     "VALUES ('a.tif', 'api', 1, 'x', '{}', 'failed', 0);")
    db.close()
    sp = Spool(state)
    assert sp.get(1)["attempt"] == 1
    assert "attempt" in {r[1] for r in sp.db.execute("PRAGMA table_info(prints)")}
    assert sp.db.execute("SELECT value FROM meta WHERE key='schema'").fetchone()[0] == SCHEMA_VERSION == "6"
    sp.close()


def test_schema_2_database_opens_with_its_jobs_and_stroke_columns(tmp_path):
    """A database of the previous version (passes_total, passes_done, passes_printed, and
    checkpoints naming the next stroke `next_pass`) opens with every job and print kept,
    its columns renamed to strokes; an interrupted job still resumes where it stopped."""
    from wideprint.app.server.accounting import prints_csv
    from wideprint.app.server.spool import SCHEMA_VERSION, Spool
    state = tmp_path / "state"
    state.mkdir()
    db = sqlite3.connect(state / "wideprint.db")
    cp = {"x0": 7680, "paper0": 0, "next_pass": 5, "epoch": 1, "copy": 1}
    db.executescript(schema_2() + "INSERT INTO meta VALUES ('schema', '2');"
                     "INSERT INTO meta VALUES ('printer_epoch', '1');")
    db.execute("INSERT INTO jobs (name, source, size, sha256, settings, state, submitted, "
               "passes_total, passes_done, checkpoint) VALUES "
               "('a.tif', 'api', 1, 'x', '{\"passes\": 2}', 'printing', 0, 9, 5, ?)",
               (json.dumps(cp),))
    db.execute("INSERT INTO prints (job_id, copy, file, source, settings, started, ended, "
               "duration_s, passes_total, passes_printed, drops_c, drops_m, drops_y, drops_k, "
               "ink_c_ml, ink_m_ml, ink_y_ml, ink_k_ml, width_dots, height_rows, area_m2, "
               "outcome) VALUES (1, 1, 'a.tif', 'api', '{\"passes\": 2}', 0, 1, 1, 9, 4, "
               "1, 2, 3, 4, 0, 0, 0, 0, 10, 600, 0.01, 'cancelled')")
    db.commit()
    db.close()
    sp = Spool(state)
    try:
        assert sp.db.execute("SELECT value FROM meta WHERE key='schema'").fetchone()[0] == SCHEMA_VERSION == "6"
        for table in ("jobs", "prints"):
            cols = {r[1] for r in sp.db.execute(f"PRAGMA table_info({table})")}
            assert not {c for c in cols if c.startswith("passes")}, cols
        job = sp.get(1)
        assert (job["name"], job["state"], job["strokes_total"], job["strokes_done"]) == \
            ("a.tif", "printing", 9, 5)
        assert job["checkpoint"]["next_stroke"] == 5 and "next_pass" not in job["checkpoint"]
        assert job["settings"] == {"passes": 2}
        (row,) = sp.prints(1)
        assert (row["strokes_total"], row["strokes_printed"], row["outcome"]) == (9, 4, "cancelled")
        line = dict(zip(*list(csv.reader(io.StringIO(prints_csv([row]))))))
        assert (line["passes"], line["strokes_total"], line["strokes_printed"]) == ("2", "9", "4")
        (rec,) = sp.recover("resume")
        assert rec["message"].startswith("interrupted (server stopped); resuming at stroke 5 ")
        claimed = sp.claim(1)                      # same epoch: it resumes from its checkpoint
        assert claimed["checkpoint"]["next_stroke"] == 5 and claimed["strokes_done"] == 5
    finally:
        sp.close()
    Spool(state).close()                           # opening a schema 3 database changes nothing


# -- presets re-read without a restart --------------------------------------------------------------
def write_atomic(path, text):
    tmp = path.with_name(path.name + ".tmp")
    tmp.write_text(text)
    os.replace(tmp, path)


def test_presets_reread_when_the_file_changes_and_a_broken_file_is_refused(tmp_path):
    from wideprint.app.server import DEFAULT_PRESETS, PrintServer, ServerConfig
    state, hot = tmp_path / "state", tmp_path / "hot"
    server = PrintServer(ServerConfig(device="emulator", state_dir=state, port=0,
                                      hot_folder_root=hot, scan_interval=0.1, settle_s=0.5,
                                      start_paused=True, media_dir=tmp_path / "media"))
    server.start()
    c = Client(state)
    try:
        assert c.presets()["presets"] == DEFAULT_PRESETS
        banner = c.submit_bytes(tiny_tiff(), name="b.tif", preset="banner")["job"]
        # edited while running: presets.toml (it takes precedence over presets.json)
        write_atomic(state / "presets.toml", '[default]\n[photo]\npasses = 2\n'
                     '[poster]\npasses = 3\nbidir = true\n')
        # picked up by the hot-folder scanner without any request: the new preset's folder
        wait_for(lambda: (hot / "poster" / "done").is_dir(), 5, what="the poster hot folder")
        got = c.presets()
        assert got["presets"] == {"default": {}, "photo": {"passes": 2},
                                  "poster": {"passes": 3, "bidir": True}}
        assert got["file"] == str(state / "presets.toml") and got["error"] is None
        (hot / "poster" / "p.tif").write_bytes(tiny_tiff())
        hot_job = wait_for(lambda: [j for j in c.jobs() if j["name"] == "p.tif"], 10,
                           what="the hot-folder job")[0]
        assert (hot_job["preset"], hot_job["settings"]) == ("poster", {"passes": 3, "bidir": True})
        # a removed preset: new jobs may not name it, queued ones keep their settings
        with pytest.raises(ApiError) as e:
            c.submit_bytes(tiny_tiff(), name="b2.tif", preset="banner")
        assert e.value.status == 400 and "unknown preset 'banner'" in str(e.value)
        assert c.job(banner["id"])["settings"] == DEFAULT_PRESETS["banner"]
        (hot / "banner" / "late.tif").write_bytes(tiny_tiff())
        time.sleep(0.5)                                   # five scans: no longer watched
        assert (hot / "banner" / "late.tif").exists()
        assert not [j for j in c.jobs() if j["name"] == "late.tif"]

        # broken files: the API names the file and the problem, the presets in use stay
        for text, why in (("[photo]\npasses = 5\n", "preset 'photo': passes must be one of"),
                          ("[photo\npasses = 2\n", "line 1"),
                          ("[done]\n", "preset 'done': reserved")):
            write_atomic(state / "presets.toml", text)
            if why.startswith("preset 'photo'"):          # noticed without being asked
                err = wait_for(lambda: c.presets()["error"], 5, what="the broken file noticed")
                assert str(state / "presets.toml") in err and why in err, err
            status, body = raw_request(server, "POST", "/v1/presets/reload")
            assert status == 400, body
            assert str(state / "presets.toml") in body["error"] and why in body["error"], body
            assert "the presets in use are kept" in body["error"]
            assert sorted(c.presets()["presets"]) == ["default", "photo", "poster"]
        r = cli(state, "presets", "--reload")
        assert r.returncode == 1 and "presets.toml: preset 'done'" in r.stderr, r.stderr
        st = c.status()
        assert "preset 'done'" in st["presets"]["error"]
        r = cli(state, "status")
        assert r.returncode == 0 and "NOT RE-READ" in r.stdout, r.stdout + r.stderr
        # the server goes on: jobs with the presets in use are accepted and printed
        c.pause_queue(False)
        ok = c.submit_bytes(tiny_tiff(), name="ok.tif", preset="poster")["job"]
        for jid in (ok["id"], banner["id"], hot_job["id"]):
            assert c.wait(jid, 60)["state"] == "done"
        assert client_job_settings(c, banner["id"]) == DEFAULT_PRESETS["banner"]
        # fixed: re-read (by the scanner or this request, whichever comes first), error cleared
        write_atomic(state / "presets.toml", '[default]\n[photo]\npasses = 4\n')
        r = cli(state, "presets", "--reload")
        assert r.returncode == 0 and r.stderr == "", r.stderr
        assert r.stdout.splitlines()[1:] == ["default      (the RIP's defaults)",
                                             "photo        passes=4"], r.stdout
        got = c.presets()
        assert got["presets"] == {"default": {}, "photo": {"passes": 4}} and got["error"] is None
        assert c.status()["presets"]["error"] is None
    finally:
        c.close()
        server.stop(timeout=5)


def client_job_settings(c, job_id):
    return c.job(job_id)["settings"]


def test_presets_reload_says_what_changed(tmp_path):
    from wideprint.app.server import PrintServer, ServerConfig
    state = tmp_path / "state"
    server = PrintServer(ServerConfig(device="emulator", state_dir=state, port=0,
                                      start_paused=True))      # no hot folders: no scanner
    server.start()
    try:
        presets = json.loads((state / "presets.json").read_text())
        presets["photo"]["passes"] = 6
        presets["poster"] = {"dither": "bayer"}
        del presets["banner"]
        write_atomic(state / "presets.json", json.dumps(presets))
        r = cli(state, "presets", "--reload", "--json")
        assert r.returncode == 0, r.stderr
        assert r.stderr.strip() == (f"re-read {state / 'presets.json'}: added poster; "
                                    f"removed banner; changed photo")
        assert json.loads(r.stdout) == presets
        r = cli(state, "presets", "--reload")
        assert r.returncode == 0 and "no change (the presets in use date from" in r.stdout.splitlines()[0], r.stdout
    finally:
        server.stop(timeout=5)


def test_progress_bar():
    from wideprint.app.cli.common import progress
    buf = io.StringIO()
    line = progress(3, 12, "c.tif", width=12, stream=buf)
    assert line.startswith("[###---------]  25.0%  3/12  c.tif")
    assert buf.getvalue() == ""                      # not a terminal: nothing drawn
