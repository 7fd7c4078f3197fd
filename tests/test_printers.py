"""One server, several printers (docs/server.md, "Several printers"): each with its own
device, profile, worker and state; a job targets a printer or any; a fault on one printer
stops only that printer."""

import time

import numpy as np
import pytest

from support.images import random_planes, write_cmyk_tiff
from wideprint.app.client import ApiError, Client
from wideprint.rip.planes import read_planes


@pytest.fixture
def two(tmp_path):
    from wideprint.app.server import PrintServer, ServerConfig
    from wideprint.app.server.config import PrinterConfig
    cfg = ServerConfig(state_dir=tmp_path / "state", media_dir=tmp_path / "media", port=0,
                       printers=[PrinterConfig("left", "emulator"), PrinterConfig("right", "emulator")])
    srv = PrintServer(cfg)
    srv.start()
    client = Client(srv.state_dir)
    yield srv, client, tmp_path
    client.close()
    srv.stop(timeout=5)


def _image(tmp_path, name, seed, rows=600):
    planes = random_planes(rows, 400, seed=seed)
    return write_cmyk_tiff(tmp_path / name, planes), planes


def test_two_printers_print_two_jobs_at_once(two):
    srv, client, tmp = two
    assert [p["name"] for p in client.status()["printers"]] == ["left", "right"]
    (a, pa), (b, pb) = _image(tmp, "a.tif", 1), _image(tmp, "b.tif", 2)
    ja = client.submit(a, settings={"passes": 4}, printer="left")["job"]
    jb = client.submit(b, settings={"passes": 4}, printer="right")["job"]
    both = False
    deadline = time.monotonic() + 60
    while time.monotonic() < deadline and not both:
        states = [client.job(j["id"])["state"] for j in (ja, jb)]
        both = states == ["printing", "printing"]
        if "done" in states:
            break
        time.sleep(0.01)
    assert both, "the two printers never printed at the same time"
    for job, planes, printer in ((ja, pa, "left"), (jb, pb, "right")):
        done = client.wait(job["id"], 120)
        assert done["state"] == "done" and done["printed_on"] == printer, done
        assert np.array_equal(read_planes(tmp / "media" / f"job-{job['id']}.tif"), planes)


def test_any_printer_takes_jobs_and_a_fault_stops_only_its_printer(two):
    srv, client, tmp = two
    client.pause_queue(True)
    files = [_image(tmp, f"j{i}.tif", 10 + i, rows=300) for i in range(4)]
    first = client.submit(files[0][0], settings={"passes": 4}, printer="left")["job"]["id"]
    rest = [client.submit(f, settings={"passes": 2})["job"]["id"] for f, _ in files[1:]]
    client.pause_queue(False)
    deadline = time.monotonic() + 30
    while client.job(first)["strokes_done"] < 1 and time.monotonic() < deadline:
        time.sleep(0.005)
    left = srv.workers["left"].dev.emulator
    left.paper_left_steps = 1                          # left's roll runs out
    try:
        for job_id in rest:                              # right prints every "any" job
            done = client.wait(job_id, 120)
            assert done["state"] == "done", done
        held = client.job(first)
        assert held["state"] == "held" and "paper out" in held["fault"]
        printers = {p["name"]: p for p in client.status()["printers"]}
        assert printers["left"]["state"] == "fault" and printers["right"]["state"] != "fault"
        left.paper_left_steps = None
        client.request("POST", "/v1/printers/left/clear-fault", body={"then": "resume"})
    finally:
        left.paper_left_steps = None
    done = client.wait(first, 120)
    assert done["state"] == "done" and done["printed_on"] == "left"
    for job_id, (_, planes) in zip([first] + rest, files):
        assert np.array_equal(read_planes(tmp / "media" / f"job-{job_id}.tif"), planes)


def test_moving_and_naming_printers(two):
    srv, client, tmp = two
    client.pause_queue(True)
    try:
        f, _ = _image(tmp, "m.tif", 5, rows=100)
        job = client.submit(f, printer="left")["job"]
        assert job["printer"] == "left"
        moved = client.request("POST", f"/v1/jobs/{job['id']}/move", body={"printer": "right"})["job"]
        assert moved["printer"] == "right"
        assert client.request("POST", f"/v1/jobs/{job['id']}/move", body={"printer": "any"})["job"]["printer"] is None
        for bad, status in (({"printer": "middle"}, 404), ({"printer": 3}, 400)):
            with pytest.raises(ApiError) as e:
                client.request("POST", f"/v1/jobs/{job['id']}/move", body=bad)
            assert e.value.status == status
        with pytest.raises(ApiError) as e:
            client.submit(f, printer="nowhere")
        assert e.value.status == 400 and "unknown printer 'nowhere'" in str(e.value)
    finally:
        client.pause_queue(False)


def test_serve_refuses_bad_printer_options(tmp_path):
    import subprocess
    import sys
    for args, words in ((["--printer", "a=emulator", "--printer", "a=emulator"], "must differ"),
                        (["--printer", "bad name=emulator"], "printer name"),
                        (["--printer", "noequals"], "NAME=SPEC"),
                        (["--printer-profile", "x=y.toml"], "goes with --printer")):
        r = subprocess.run([sys.executable, "-m", "wideprint.app.cli", "serve", "--state-dir",
                            str(tmp_path / "s"), "--port", "0", *args],
                           capture_output=True, text=True, timeout=60)
        assert r.returncode == 2 and words in r.stderr, (args, r.stderr)


def test_live_state_is_pushed_as_server_sent_events(two):
    """GET /v1/events: the printers' state, the unfinished jobs and the mark of the ended
    ones, sent when they change; a client sees a job queued, printing on a printer, and gone
    when done (into the history), without polling."""
    import http.client
    import json
    import threading
    srv, client, tmp = two
    events = []

    def listen():
        conn = http.client.HTTPConnection("127.0.0.1", srv.port, timeout=30)
        conn.request("GET", "/v1/events?max_s=8", headers={"Authorization": f"Bearer {srv.token}"})
        resp = conn.getresponse()
        assert resp.status == 200 and resp.getheader("Content-Type") == "text/event-stream"
        kind = None
        for raw in resp:
            line = raw.decode().rstrip("\n")
            if line.startswith("event: "):
                kind = line[7:]
            elif line.startswith("data: "):
                events.append((kind, json.loads(line[6:])))
        conn.close()
    t = threading.Thread(target=listen)
    t.start()
    time.sleep(0.5)
    f, planes = _image(tmp, "live.tif", 7, rows=300)
    job_id = client.submit(f, settings={"passes": 2}, printer="right")["job"]["id"]
    assert client.wait(job_id, 60)["state"] == "done"
    t.join(30)
    kinds = [k for k, _ in events]
    assert kinds[:3] == ["printers", "jobs", "ended"]             # the state at once
    ended = [v for k, v in events if k == "ended"]
    # the job's end moves the mark of ended jobs (what a history follows; a job that comes
    # and goes between two samples of `jobs` shows only here)
    assert ended[-1]["count"] == ended[0]["count"] + 1 and ended[-1]["last_id"] == job_id
    printing = [p for k, v in events if k == "printers" for p in v
                if p["name"] == "right" and p["current"] and p["current"]["id"] == job_id]
    assert printing, "no event showed the job printing on its printer"
    seen = [any(j["id"] == job_id for j in v) for k, v in events if k == "jobs"]
    assert True in seen and seen[-1] is False                     # queued, then finished
    assert len(events) < 200                                      # changes, not a stream of copies


def test_an_emulated_printers_media_is_live_at_its_physical_aspect(two):
    """GET /v1/printers/NAME/media.png (docs/server.md, "Live media"): the media as it landed,
    area-averaged (its mean ink equals the media's), at the true physical aspect; the
    printers' event data says which version it is, so clients fetch only on a change."""
    import cv2
    from wideprint.rip.planes import render_rgb
    srv, client, tmp = two
    with pytest.raises(ApiError) as e:
        client.media_png("left")
    assert e.value.status == 404
    f, planes = _image(tmp, "live.tif", 7, rows=900)
    job = client.submit(f, printer="left")["job"]["id"]
    assert client.wait(job, 120)["state"] == "done"
    info = {p["name"]: p for p in client.printers()}["left"]["media"]
    assert info["job"] == job and info["version"] > 0
    img = cv2.imdecode(np.frombuffer(client.media_png("left"), np.uint8), cv2.IMREAD_COLOR)
    prof = srv.profiles["left"]
    w_mm = planes.shape[1] * 25.4 / 300
    h_mm = planes.shape[0] * prof.row_um / 1000
    assert abs(img.shape[1] / img.shape[0] - w_mm / h_mm) < 0.02 * w_mm / h_mm
    want = render_rgb(planes).astype(float).mean()
    assert abs(img.astype(float).mean() - want) < 2.0


def test_any_goes_to_a_printer_whose_paper_holds_the_job(tmp_path):
    """A job for any printer goes to the first free printer whose paper holds it: a narrow
    roll's printer leaves a wide job for the wide one, and still takes the narrow jobs."""
    from wideprint.app.server import PrintServer, ServerConfig
    from wideprint.app.server.config import PrinterConfig
    from wideprint.rip.profile import DEFAULT_PROFILE
    narrow = tmp_path / "narrow.toml"
    narrow.write_text(DEFAULT_PROFILE.read_text().replace(
        "default_width_mm = 3200.0", "default_width_mm = 100.0"))
    cfg = ServerConfig(state_dir=tmp_path / "state", media_dir=tmp_path / "media", port=0,
                       printers=[PrinterConfig("wide", "emulator"),
                                 PrinterConfig("narrow", "emulator", str(narrow))])
    srv = PrintServer(cfg)
    srv.start()
    client = Client(srv.state_dir)
    try:
        client.printer_action("wide", "pause")
        wide, pw = _wide_image(tmp_path)
        small, ps = _image(tmp_path, "small.tif", 2, rows=200)
        jw = client.submit(wide)["job"]["id"]
        js = client.submit(small)["job"]["id"]
        done = client.wait(js, 60)
        assert done["state"] == "done" and done["printed_on"] == "narrow"
        time.sleep(1.0)                          # the narrow printer is free: it must not take it
        assert client.job(jw)["state"] == "queued"
        printers = {p["name"]: p for p in client.printers()}
        assert printers["narrow"]["printable_mm"] < 100 < printers["wide"]["printable_mm"]
        client.printer_action("wide", "resume")
        done = client.wait(jw, 120)
        assert done["state"] == "done" and done["printed_on"] == "wide"
        assert np.array_equal(read_planes(tmp_path / "media" / f"job-{jw}.tif"), pw)
    finally:
        client.close()
        srv.stop(timeout=5)


def _wide_image(tmp_path):
    """1,500 dots at 300 dpi: 127 mm, wider than the narrow roll's 90 mm printable."""
    planes = random_planes(150, 1500, seed=5)
    return write_cmyk_tiff(tmp_path / "wide.tif", planes), planes
