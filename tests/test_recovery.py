"""The driver finishes jobs through line noise and lost links with every dot in place:
no stroke printed twice, none missing (issue 5)."""

import numpy as np
import pytest

from support.images import PX, random_planes, write_cmyk_tiff
from wideprint.device_sim.faults import Faults
from wideprint.app.devices import open_device
from wideprint.driver.job import PrintJob
from wideprint.rip.pipeline import RipJob, RipSettings
from wideprint.rip.planes import read_planes


def print_job(tmp_path, profile, faults, settings=None, planes=None, spec="emulator"):
    planes = random_planes(900, 1500, seed=21) if planes is None else planes
    src = write_cmyk_tiff(tmp_path / "in.tif", planes)
    dev = open_device(spec, profile, faults, media_path=str(tmp_path / "m.tif"))
    try:
        rep = PrintJob(dev, RipJob(str(src), settings or RipSettings(placement=PX, passes=2, bidir=True),
                                   profile)).run()
    finally:
        dev.emulator.close()
    return rep, dev.emulator, planes, read_planes(tmp_path / "m.tif")


@pytest.mark.parametrize("after,spec", [(1, "emulator"), (5, "emulator"), (40, "emulator"),
                                        (200, "emulator"), (40, "emulator-usb")])
def test_data_link_dropped_mid_job_resumes_bit_exact(tmp_path, profile, after, spec):
    rep, emu, planes, media = print_job(tmp_path, profile, Faults(data_drop_after=after),
                                        spec=spec)
    assert any(e["event"] == "data_link_lost" for e in emu.events)
    assert rep.recoveries >= 1
    assert np.array_equal(media, planes)
    lines = [e for e in emu.events if e["event"] == "line"]
    assert len({e["stroke"] for e in lines}) == len(lines)       # no stroke run twice


@pytest.mark.parametrize("faults", [
    Faults(serial_byte_error=1e-3, seed=1),
    Faults(serial_byte_error=1e-3, seed=2),
    Faults(serial_ber=1e-3, seed=3),
    Faults(serial_drop=1e-3, seed=4),
])
def test_serial_noise_prints_bit_exact(tmp_path, profile, faults):
    rep, emu, planes, media = print_job(tmp_path, profile, faults)
    assert rep.retries > 0
    assert np.array_equal(media, planes)
    assert emu.jobs_done[1]["stray"] == 0


@pytest.mark.parametrize("key", ["next_stroke", "next_pass"])
def test_a_job_resumes_from_its_checkpoint_on_the_same_printer(tmp_path, profile, key):
    """A host that died after stroke 3 (the printer kept its state) resumes at stroke 4: the
    media equals an uninterrupted print (the server's crash recovery builds on this).  A
    checkpoint saved by an older version, which named the next stroke `next_pass`, resumes
    the same way."""
    from wideprint.driver.job import JobCancelled
    planes = random_planes(900, 400, seed=41)
    src = write_cmyk_tiff(tmp_path / "in.tif", planes)
    dev = open_device("emulator", profile, media_path=str(tmp_path / "m.tif"))
    checkpoints = []

    def on_event(kind, **kw):
        if kind == "checkpoint":
            checkpoints.append(kw["checkpoint"])
            if kw["checkpoint"].get("next_stroke") == 4:
                first.control.cancel()           # the host "dies" between strokes
    first = PrintJob(dev, RipJob(str(src), RipSettings(placement=PX, passes=2), profile), on_event=on_event)
    with pytest.raises(JobCancelled):
        first.run()
    cp = checkpoints[-1]
    assert cp["next_stroke"] == 4
    if key == "next_pass":                       # as the previous version saved it
        cp = {("next_pass" if k == "next_stroke" else k): v for k, v in cp.items()}
        assert "next_stroke" not in cp and cp["next_pass"] == 4
    started = []
    again = PrintJob(dev, RipJob(str(src), RipSettings(placement=PX, passes=2), profile), resume=cp,
                     on_event=lambda kind, **kw: kind == "stroke" and started.append(kw["index"]))
    rep = again.run()
    dev.emulator.close()
    assert rep.state == "done"
    assert np.array_equal(read_planes(tmp_path / "m.tif"), planes)
    lines = [e["stroke"] for e in dev.emulator.events if e["event"] == "line"]
    assert len(lines) == len(set(lines))                       # no stroke printed twice
    assert started[0] == 4 and started == sorted(started)     # from stroke 4 on, no earlier one
    assert rep.strokes_printed == rep.strokes_total


def test_a_fresh_job_stops_a_line_an_earlier_host_left_running(tmp_path, profile):
    """A host that went away mid-line (a killed server) leaves the line starved, PRINTING;
    the next job, starting afresh, stops it instead of failing on BUSY (before: 'printer
    refused GET_PAPER: BUSY'; found by bench/crash_soak.py as 'refused SPIT: BUSY')."""
    from wideprint.driver import protocol as P
    from wideprint.driver.printer import Printer
    from wideprint.rip.settings import Placement
    planes = random_planes(100, 120, seed=1)
    src = write_cmyk_tiff(tmp_path / "a.tif", planes)
    dev = open_device("emulator", profile, Faults(starve_guard=1), media_path=str(tmp_path / "m.tif"))
    try:
        Printer(dev).ready()
        link = dev.link
        link.call(P.Op.JOB_BEGIN, job=77, x0=7680, width=2000, height=100, dpi=300,
                  row_nm=profile.row_nm, y0=0)
        link.call(P.Op.SET_LINE, stroke=0, direction=0, dpi=300, fire_start=3840,
                  fire_count=2000, speed=15590, accel=47244)
        link.write_reg(P.REG_DIR, 1)
        link.write_reg(P.REG_DPI, P.DPI_CODE[300])
        link.write_reg(P.REG_WE_EN, 1)
        link.command(P.Op.START_LINE)            # no data follows: the line starves
        assert link.status().motion == P.Motion.PRINTING
        rep = PrintJob(dev, RipJob(str(src), RipSettings(placement=Placement(size="pixels")),
                                   profile)).run()
    finally:
        dev.emulator.close()
    assert rep.state == "done"
    assert np.array_equal(read_planes(tmp_path / "m.tif"), planes)


def test_a_resumed_job_spits_not_into_its_own_starved_line(tmp_path, profile):
    """The host died in the middle of stroke 3, its line starving; the resumed job's head
    care (a new server's: every nozzle idle for ever) must not spit before the line it
    resumes - refused BUSY, the job failed (found by bench/crash_soak.py: 'refused SPIT:
    BUSY').  The dead host's last steps are replayed from a reference print's events."""
    from wideprint.driver import protocol as P
    from wideprint.driver.headcare import NEVER, HeadCare
    from wideprint.driver.job import JobCancelled
    from wideprint.driver.printer import Printer
    planes = random_planes(900, 400, seed=42)
    src = write_cmyk_tiff(tmp_path / "in.tif", planes)
    settings = RipSettings(placement=PX, passes=2)
    ref = open_device("emulator", profile, media_path=str(tmp_path / "ref.tif"))
    PrintJob(ref, RipJob(str(src), settings, profile)).run()
    ref.emulator.close()
    ev = list(ref.emulator.events)
    i3 = next(i for i, e in enumerate(ev) if e["event"] == "set_line" and e["stroke"] == 3)
    line = ev[i3]
    paper = [e for e in ev[:i3] if e["event"] == "feed"][-1]["paper_steps"]

    dev = open_device("emulator", profile, Faults(starve_guard=1), media_path=str(tmp_path / "m.tif"))
    checkpoints = []

    def on_event(kind, **kw):
        if kind == "checkpoint":
            checkpoints.append(kw["checkpoint"])
            if kw["checkpoint"].get("next_stroke") == 3:
                first.control.cancel()
    first = PrintJob(dev, RipJob(str(src), settings, profile), on_event=on_event)
    with pytest.raises(JobCancelled):
        first.run()
    link, printer = dev.link, Printer(dev)
    # what the dead host did next: feed, set stroke 3's line, start it; its data never came
    printer.feed_steps(paper - link.status().paper_steps)
    link.call(P.Op.SET_LINE, stroke=3, direction=line["direction"], dpi=line["dpi"],
              fire_start=line["first"], fire_count=line["count"], speed=line["speed"],
              accel=line["accel"])
    link.write_reg(P.REG_DIR, 1 if line["direction"] == 0 else 0)
    link.write_reg(P.REG_DPI, P.DPI_CODE[line["dpi"]])
    link.write_reg(P.REG_WE_EN, 1)
    link.command(P.Op.START_LINE)
    st = link.status()
    assert st.motion == P.Motion.PRINTING and st.stroke == 3       # starved at its start
    care = HeadCare(printer)
    care.status()
    care.last_fire[:] = NEVER
    again = PrintJob(dev, RipJob(str(src), settings, profile), resume=checkpoints[-1],
                     head_care=care)
    rep = again.run()
    dev.emulator.close()
    assert rep.state == "done", rep.message
    assert np.array_equal(read_planes(tmp_path / "m.tif"), planes)
