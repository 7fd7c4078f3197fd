"""The server killed (SIGKILL) at every named point of a job's life and started again
(issue 31, docs/server.md "Crash recovery: the facts and their order"): a job is done
only with the printer's media equal to its planes, otherwise held (the printer could not
confirm the sheet) or printed again; never lost, never a copy accounted twice.

Three printers: the in-process emulator (it dies with the server), a standalone emulator
that outlives the server, and a standalone emulator switched off and on while the server
is down.  The server kills itself at the point (`WIDEPRINT_CRASH_AT`, app/server/
crashpoints.py), so each point is hit exactly, not by a race."""

import signal
import socket
import sqlite3
import subprocess
import sys
import threading
from concurrent.futures import ThreadPoolExecutor

import numpy as np
import pytest

from support.images import random_planes, write_cmyk_tiff
from support.server import readline, start_server, stop, wait_for
from wideprint.app.client import ApiError
from wideprint.rip.pipeline import RipJob
from wideprint.rip.planes import read_planes
from wideprint.rip.profile import load_profile
from wideprint.rip.settings import RipSettings

PY = sys.executable
COPIES = 2
SETTINGS = {"passes": 2}
FINAL = ("done", "failed", "cancelled")


# -- processes -----------------------------------------------------------------------------------
_PORTS_TAKEN: set[int] = set()
_PORTS_LOCK = threading.Lock()


def free_port() -> int:
    """A free port no other Emulator of this run holds (scenarios run two at once, and a
    power-cycled printer's ports are free while it is off)."""
    with _PORTS_LOCK:
        while True:
            with socket.socket() as s:
                s.bind(("127.0.0.1", 0))
                port = s.getsockname()[1]
            if port not in _PORTS_TAKEN:
                _PORTS_TAKEN.add(port)
                return port


class Emulator:
    """A standalone `wideprint emulator` on fixed ports, so that it can be switched off and
    on again under the same device spec."""

    def __init__(self, tmp):
        self.tmp, self.ports = tmp, (free_port(), free_port())
        self.proc, self.spec, self.boots = None, None, 0

    def start(self):
        self.boots += 1
        self.proc = subprocess.Popen(
            [PY, "-m", "wideprint.app.cli", "emulator", "--serial-port", str(self.ports[0]),
             "--data-port", str(self.ports[1]), "--media-out", str(self.tmp / "media-{job}.tif"),
             "--event-log", str(self.tmp / f"emulator-{self.boots}.jsonl")],
            stdout=subprocess.PIPE, stderr=subprocess.PIPE, text=True)
        line = readline(self.proc, 60)
        assert line.startswith("device: "), self.proc.stderr.read()
        self.spec = line.split(" ", 1)[1].strip()
        return self.spec

    def stop(self):
        if self.proc is not None and self.proc.poll() is None:
            self.proc.kill()
            self.proc.communicate(timeout=30)

    def media(self, jid):
        return self.tmp / f"media-{jid}.tif"


def db_rows(state, sql, *args):
    c = sqlite3.connect(state / "wideprint.db")
    c.row_factory = sqlite3.Row
    try:
        return [dict(r) for r in c.execute(sql, args)]
    finally:
        c.close()


# -- the job --------------------------------------------------------------------------------------
@pytest.fixture(scope="module")
def job_file(tmp_path_factory):
    d = tmp_path_factory.mktemp("crash-job")
    planes = random_planes(260, 300, seed=31)
    src = write_cmyk_tiff(d / "job.tif", planes)
    rip = RipJob(str(src), RipSettings(**SETTINGS), load_profile())
    try:
        strokes = rip.planner().total_strokes
    finally:
        rip.close()
    return src, planes, strokes


def points(strokes: int) -> list[str]:
    """Every named point; checkpoints at the first (JOB_BEGIN, no stroke yet), in the middle
    of copy 1 and in the middle of copy 2 (a copy's checkpoints: JOB_BEGIN, then one a
    stroke; `ended` is the point job_end)."""
    per_copy = strokes + 1
    return ["upload", "claim", "checkpoint:1", "checkpoint:3", "job_end:1", "copy_done:1",
            f"checkpoint:{per_copy + 3}", "job_end:2", "finish"]


POINT_IDS = ["upload", "claim", "checkpoint:1", "checkpoint:3", "job_end:1", "copy_done:1",
             "checkpoint:copy2", "job_end:2", "finish"]


def _run(tmp_path, job_file, point_id, printer):
    """Submit, die at the point, start again (the printer per `printer`), finish the job,
    and check what the issue asks: done only with the media equal to the planes, held
    (then released) when the printer cannot confirm, never lost, copies accounted once."""
    src, planes, strokes = job_file
    point = dict(zip(POINT_IDS, points(strokes)))[point_id]
    state, media_dir = tmp_path / "state", tmp_path / "media"
    emu = None
    if printer == "in-process":
        device, media = "emulator", (lambda jid: media_dir / f"job-{jid}.tif")
    else:
        emu = Emulator(tmp_path)
        device, media = emu.start(), emu.media
    try:
        srv, client = start_server(state, device, media_dir=media_dir if emu is None else None,
                                   crash=point)
        key = f"crash-{point_id}"
        jid = None
        try:
            jid = client.submit(src, copies=COPIES, settings=SETTINGS, key=key)["job"]["id"]
        except (ApiError, OSError, ConnectionError):
            assert point == "upload", point          # only this point dies before the answer
        assert srv.wait(120) == -signal.SIGKILL, srv.stderr.read()
        srv.communicate()
        if printer == "power-cycled":
            emu.stop()
            assert emu.start() == device              # same ports: same spec, a new power-up
        srv, client = start_server(state, device, media_dir=media_dir if emu is None else None)
        try:
            if jid is None:                            # the client retries with its key
                again = client.submit(src, copies=COPIES, settings=SETTINGS, key=key)
                assert again["duplicate"] is True
                jid = again["job"]["id"]
            j = wait_for(lambda: (lambda j: j if j["state"] in FINAL or j["state"] == "held"
                                  else None)(client.job(jid)), 120, what="the job to settle")
            held = j["state"] == "held"
            if held:
                assert "strokes are on the sheet" in j["message"], j
                assert "held" in j["message"]
                client.action(jid, "release")
            final = client.wait(jid, timeout=120)
            prints = client.report(jid)
            jobs = client.request("GET", "/v1/jobs")["jobs"]
        finally:
            err = stop(srv)
        assert "Traceback" not in err, err
    finally:
        if emu is not None:
            emu.stop()
    assert [x["id"] for x in jobs] == [jid]            # never lost, never two
    assert final["state"] == "done", final
    assert np.array_equal(read_planes(media(jid)), planes)   # done means printed
    done = [p for p in prints if p["outcome"] == "done"]
    assert sorted(p["copy"] for p in done) == list(range(1, COPIES + 1)), prints
    assert all(p["outcome"] in ("done", "interrupted") for p in prints), prints
    for p in done:
        assert [p[f"drops_{c}"] for c in "cmyk"] == planes.reshape(-1, 4).sum(0).tolist()
    for p in prints:
        if p["outcome"] == "interrupted":
            assert 0 < p["strokes_printed"] < p["strokes_total"] and "restarted" in p["message"]
    # the done job's spool copy is its archived file (docs/server.md "Archive and reprint"):
    # one file, the job's, never a second copy or an orphan
    from wideprint.app.server.fsck import file_digest
    left = list((state / "spool").iterdir())
    assert len(left) == 1 and file_digest(left[0]) == final["sha256"], left
    return held, prints


#: the printer each test function runs its scenarios with
PRINTER = {"test_in_process_printer": "in-process",
           "test_standalone_printer_outlives_the_server": "standalone",
           "test_standalone_printer_power_cycled_while_the_server_was_down": "power-cycled"}


@pytest.fixture(scope="module")
def scenarios(request, tmp_path_factory, job_file):
    """Every (printer, point) scenario of this run's tests, started on two threads when the
    first test needs one: a scenario is processes (the server, a standalone printer) that
    this process mostly waits on, so one at a time left a core idle; two at once keep both
    busy.  Each test takes its own scenario's outcome (or the exception it raised) and
    checks it; the scenarios share nothing but the job's file (read only) and get ports no
    other holds (free_port)."""
    wanted = [(PRINTER[item.originalname], item.callspec.params["point_id"])
              for item in request.session.items
              if item.module is request.module and item.originalname in PRINTER]
    pool = ThreadPoolExecutor(2, thread_name_prefix="scenario")
    futures = {}
    for printer, point_id in wanted:
        tmp = tmp_path_factory.mktemp(f"{printer}-{point_id.replace(':', '-')}")
        futures[printer, point_id] = pool.submit(_run, tmp, job_file, point_id, printer)
    yield futures
    pool.shutdown(wait=True, cancel_futures=True)


def outcome(scenarios, printer: str, point_id: str):
    """(held, prints) of the scenario, once it ended; its own AssertionError if it failed."""
    return scenarios[printer, point_id].result(timeout=900)


# What each printer must lead to: the in-process printer dies with the server, so a copy
# caught part-way is held (its strokes are on a sheet the new printer knows nothing of);
# a printer that outlives the server confirms the sheet and the job simply goes on.
MID_COPY = ("checkpoint:3", "checkpoint:copy2")


@pytest.mark.parametrize("point_id", POINT_IDS)
def test_in_process_printer(scenarios, point_id):
    held, prints = outcome(scenarios, "in-process", point_id)
    assert held == (point_id in MID_COPY)
    assert any(p["outcome"] == "interrupted" for p in prints) == (point_id in MID_COPY)


@pytest.mark.parametrize("point_id", POINT_IDS)
def test_standalone_printer_outlives_the_server(scenarios, point_id):
    held, prints = outcome(scenarios, "standalone", point_id)
    assert not held
    assert not any(p["outcome"] == "interrupted" for p in prints)
    if point_id in MID_COPY:
        assert any(p["resumed"] for p in prints)


@pytest.mark.parametrize("point_id", ["checkpoint:3", "job_end:1", "checkpoint:copy2"])
def test_standalone_printer_power_cycled_while_the_server_was_down(scenarios, point_id):
    held, prints = outcome(scenarios, "power-cycled", point_id)
    assert held == (point_id in MID_COPY)


# -- the roll: a copy caught by a crash feeds it once, whole --------------------------------------
@pytest.mark.parametrize("printer", ["standalone", "in-process"])
def test_a_copy_caught_by_a_crash_takes_its_feed_off_the_roll(tmp_path, job_file, printer):
    """docs/server.md "Rolls": the feed a copy made before the server died comes off the
    roll with the row that accounts the copy - the resumed copy's whole feed (the printer
    outlived the server: its paper count from the checkpoint's `paper0`), or, for the copy
    caught part-way on a printer that died too, the feed the stroke plan puts under its
    strokes on the sheet, in the restart's transaction.  Never lost, never twice."""
    src, planes, strokes = job_file
    state = tmp_path / "state"
    emu = Emulator(tmp_path) if printer == "standalone" else None
    device = emu.start() if emu else "emulator"
    media_dir = None if emu else tmp_path / "media"
    prof = load_profile()
    step_mm = prof.feed_um_per_step / 1000.0
    try:
        srv, client = start_server(state, device, media_dir=media_dir, crash="checkpoint:3")
        client.roll("main", {"media": "vinyl-300", "length_m": 50})
        jid = client.submit(src, copies=COPIES, settings=SETTINGS)["job"]["id"]
        assert srv.wait(120) == -signal.SIGKILL, srv.stderr.read()
        srv.communicate()
        srv, client = start_server(state, device, media_dir=media_dir)
        try:
            j = wait_for(lambda: (lambda j: j if j["state"] in FINAL or j["state"] == "held"
                                  else None)(client.job(jid)), 120, what="the job to settle")
            if j["state"] == "held":
                client.action(jid, "release")
            assert client.wait(jid, timeout=120)["state"] == "done"
            prints = client.report(jid)
            left = client.roll("main")["roll"]["remaining_mm"]
        finally:
            assert "Traceback" not in stop(srv)
    finally:
        if emu is not None:
            emu.stop()
    done = [p for p in prints if p["outcome"] == "done"]
    assert [p["copy"] for p in done] == [1, 2], prints
    # each done copy fed a whole copy: the one resumed after the crash as much as the other
    assert done[0]["paper_mm"] > 0 and abs(done[0]["paper_mm"] - done[1]["paper_mm"]) <= step_mm, done
    interrupted = [p for p in prints if p["outcome"] == "interrupted"]
    if printer == "in-process":
        # two strokes were on the sheet (checkpoints: JOB_BEGIN, stroke 0, stroke 1): the
        # paper under them, fed from where the copy began, top margin none
        [row] = interrupted
        rip = RipJob(str(src), RipSettings(**SETTINGS), prof)
        try:
            plan = rip.planner()
            want = prof.feed_steps_for_rows(plan.top_row(1) - plan.top_row(0)) * step_mm
        finally:
            rip.close()
        assert row["strokes_printed"] == 2 and row["paper_mm"] == pytest.approx(want, abs=1e-3)
        assert want > 0
    else:
        assert interrupted == [] and done[0]["resumed"]
    # and the roll lost exactly what the rows say, once
    assert left == pytest.approx(50_000 - sum(p["paper_mm"] for p in prints), abs=1e-6)
