"""Operator control of a running job: pause/resume and cancel at stroke boundaries,
emergency stop at once, and the telemetry the GUI and CLI show."""

import threading
import time

import numpy as np
import pytest

from support.images import PX, random_planes, write_cmyk_tiff
from wideprint.app.devices import open_device
from wideprint.driver.job import JobCancelled, JobError, PrintJob
from wideprint.driver import protocol as P
from wideprint.rip.pipeline import RipJob, RipSettings
from wideprint.rip.planes import read_planes


def make_job(tmp_path, profile, on_event=None, rows=900):
    planes = random_planes(rows, 300, seed=31)
    src = write_cmyk_tiff(tmp_path / "in.tif", planes)
    dev = open_device("emulator", profile, media_path=str(tmp_path / "m.tif"))
    job = PrintJob(dev, RipJob(str(src), RipSettings(placement=PX, passes=2), profile), on_event=on_event)
    return job, dev, planes


def test_pause_then_resume_finishes_exactly(tmp_path, profile):
    states = []

    def on_event(kind, **kw):
        if kind == "state":
            states.append(kw["state"])
            if kw["state"] == "paused":
                threading.Timer(0.2, job.control.resume).start()
    job, dev, planes = make_job(tmp_path, profile, on_event=on_event)
    job.control.pause()
    rep = job.run()
    dev.emulator.close()
    assert "paused" in states and states[-1] == "done"
    assert rep.state == "done"
    assert np.array_equal(read_planes(tmp_path / "m.tif"), planes)


def test_cancel_at_a_stroke_boundary(tmp_path, profile):
    def on_event(kind, **kw):
        if kind == "stroke" and kw["index"] == 3:
            job.control.cancel()
    job, dev, planes = make_job(tmp_path, profile, on_event=on_event)
    with pytest.raises(JobCancelled):
        job.run()
    dev.emulator.close()
    assert job.report.state == "cancelled" and job.telemetry.state == "cancelled"
    lines = [e for e in dev.emulator.events if e["event"] == "line"]
    assert len(lines) <= 4
    assert dev.emulator.status().flags & P.FLAG_FAULT == 0


def test_emergency_stop_from_another_thread(tmp_path, profile):
    def on_event(kind, **kw):
        if kind == "stroke" and kw["index"] == 2:
            threading.Thread(target=job.control.estop).start()
            time.sleep(0.05)
    job, dev, planes = make_job(tmp_path, profile, on_event=on_event)
    with pytest.raises((JobError, JobCancelled)):
        job.run()
    dev.emulator.close()
    assert dev.emulator.fault == P.Fault.ESTOP
    assert not dev.emulator.enabled


def test_telemetry_follows_the_job(tmp_path, profile):
    seen = []
    job, dev, planes = make_job(tmp_path, profile,
                                on_event=lambda kind, **kw: kind == "status" and seen.append(
                                    (kw["telemetry"].stroke_index, kw["telemetry"].paper_steps)))
    rep = job.run()
    dev.emulator.close()
    t = job.telemetry
    assert t.state == "done" and t.strokes_printed == rep.strokes_printed > 0
    assert t.strokes_total == rep.strokes_total
    assert len(t.head_temps_c) == 8 and all(20 < c < 60 for c in t.head_temps_c)
    assert len(t.fifo_words) == 8
    papers = [p for _, p in seen]
    assert papers == sorted(papers) and papers[-1] > 0            # the paper only moves forward
