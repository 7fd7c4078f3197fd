"""Resuming a job after a printer fault (docs/driver.md, "Resuming after a fault"): the
operator clears the fault, the job restarts at its first unfinished stroke with its
checkpoint, and a stroke the fault stopped part-way goes on from the next column: the
media is bit-exact, no dot printed twice, none missing."""

import numpy as np
import pytest

from support.images import PX, random_planes, write_cmyk_tiff
from wideprint.app.devices import close_device, open_device
from wideprint.device_sim.faults import Faults
from wideprint.driver.job import JobError, PrintJob
from wideprint.driver.printer import Printer
from wideprint.rip.pipeline import RipJob, RipSettings
from wideprint.rip.planes import read_planes


@pytest.mark.parametrize("faults, words, mid_stroke", [
    (Faults(overtemp=[("K2", 2)]), "head over-temperature (head K2, stroke 2", True),
    (Faults(limit_at=9000), "right limit switch (stroke 0", True),
    (Faults(paper_length_mm=40), "paper out", False),
])
def test_a_cleared_fault_resumes_bit_exact(tmp_path, profile, faults, words, mid_stroke):
    planes = random_planes(900, 1200, seed=5)
    src = write_cmyk_tiff(tmp_path / "in.tif", planes)
    settings = RipSettings(placement=PX, passes=2, bidir=True)
    dev = open_device("emulator", profile, faults, media_path=str(tmp_path / "m.tif"))
    try:
        checkpoints, events = [], []

        def on_event(kind, **kw):
            if kind == "checkpoint":
                checkpoints.append(kw["checkpoint"])
            events.append(kind)
        with pytest.raises(JobError, match=words.replace("(", r"\(")):
            PrintJob(dev, RipJob(str(src), settings, profile), on_event=on_event).run()
        emu = dev.emulator
        emu.paper_left_steps, emu.faults.limit_at = None, None      # a new roll; the rail freed
        assert Printer(dev).clear_fault() != 0
        resumed = []
        rep = PrintJob(dev, RipJob(str(src), settings, profile), resume=checkpoints[-1],
                       on_event=lambda kind, **kw: resumed.append(kind)).run()
        assert rep.state == "done"
        assert ("stroke_resumed" in resumed) == mid_stroke
    finally:
        close_device(dev)
    media = read_planes(tmp_path / "m.tif")
    assert media.max() == 1                                  # no dot printed twice
    assert np.array_equal(media, planes)
