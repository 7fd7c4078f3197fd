"""wideprint's sample acceptance suite (docs/acceptance.md): the thesis' test prints, a
colour chart and a fault drill, written with the pytest plugin as a print shop or a
firmware engineer would write their own.  Run it with one command:

    wideprint acceptance --junit-xml acceptance.xml            # the emulator
    wideprint acceptance --device serial=/dev/ttyS0,data=usb://1209:5750   # a real printer
"""

import numpy as np
import pytest
import tifffile

from wideprint.app.pytest_plugin import (assert_fault, assert_ink_within,
                                         assert_media_equals_planes, assert_no_underrun,
                                         assert_nothing_printed_after_fault)


@pytest.fixture
def chart(tmp_path):
    """A CMYK colour chart: 10 % steps of each ink and of CMY grey, 1 pixel = 1 dot."""
    steps = np.arange(0, 101, 10) * 255 // 100
    patch, rows = 24, []
    for ink in range(5):
        row = np.zeros((patch, patch * len(steps), 4), np.uint8)
        for i, v in enumerate(steps):
            block = row[:, i * patch:(i + 1) * patch]
            if ink < 4:
                block[..., ink] = v
            else:
                block[..., :3] = v
        rows.append(row)
    path = tmp_path / "chart.tif"
    tifffile.imwrite(path, np.concatenate(rows), photometric="separated")
    return path


def test_thesis_one_nozzle_line(wideprint_printer):
    """Seed 4.2.4, test 1: one nozzle fires every column: a straight line one drop wide;
    after a paper feed, a second one."""
    result = wideprint_printer().print_pattern("line", head="K1", nozzle=64, width_mm=80)
    assert result.ok, result.message
    assert_media_equals_planes(result)
    if result.media is not None:
        k_rows = np.nonzero(result.media[..., 3].any(axis=1))[0]
        assert len(k_rows) == 2 and not result.media[..., :3].any()
        assert all(result.media[r, :, 3].all() for r in k_rows)       # no break, no gap


def test_thesis_sawtooth(wideprint_printer):
    """Seed 4.2.4, test 2: a 118-bit shift register walks across the nozzles."""
    result = wideprint_printer().print_pattern("sawtooth", head="K1", width_mm=60)
    assert result.ok, result.message
    assert_media_equals_planes(result)


def test_nozzle_check_shows_every_head(wideprint_printer):
    result = wideprint_printer().print_pattern("nozzle-check", width_mm=40)
    assert result.ok, result.message
    assert_media_equals_planes(result)


@pytest.mark.parametrize("passes, bidir", [(1, False), (2, True), (4, True)])
def test_colour_chart(print_job, wideprint_rip, chart, passes, bidir):
    settings = dict(passes=passes, bidir=bidir, dither="bayer", size="pixels")
    result = print_job(chart, **settings)
    assert result.ok, result.message
    planes = wideprint_rip(chart, **settings)
    assert_media_equals_planes(result, planes)
    assert_no_underrun(result)
    drop_ml = result.profile.drop_volume_pl * 1e-9
    # the report rounds ink to nl: within half a percent of the planes' drops
    assert_ink_within(result, planes.reshape(-1, 4).sum(axis=0) * drop_ml, rel=0.005)


@pytest.mark.emulator_only
def test_fault_drill_paper_out(wideprint_printer, chart):
    """The roll runs out mid-job: the job stops with the fault in plain words, nothing
    fires after it; cleared and reloaded, the next job prints exactly."""
    printer = wideprint_printer(faults=["paper-length-mm=4"])
    result = printer.print(chart, passes=2, size="pixels")
    assert_fault(result, "paper out")
    assert_nothing_printed_after_fault(result)
    printer.emulator.paper_left_steps = None          # a new roll ...
    from wideprint.driver.printer import Printer
    Printer(printer.device).clear_fault()             # ... and the fault cleared
    again = printer.print(chart, passes=2, size="pixels")
    assert again.ok, again.message
    from wideprint.app import api
    assert_media_equals_planes(again, api.rip(chart, passes=2, size="pixels"))
