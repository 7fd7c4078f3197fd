"""A real printer measured by the shop's own scanner (docs/media.md "A real printer,
another instrument"): with `--measure-dir` and a scanner profile, each chart is printed
with its bars and a scan of it, saved as DIR/NAME-scan.tif wherever it lay on the glass,
is read through the profile like the emulated scanner's."""

from __future__ import annotations

import json
import sys
import threading

import numpy as np
import pytest
import tifffile

from wideprint.app import mediacal, medialib
from wideprint.device_sim.spectral import delta_e2000

#: the scanner profile comes from tests/test_media.py's `media create --scan` loop, started
#: with the session (tests/support/background.py; the same key runs once)
BACKGROUND = {
    "test_a_chart_scanned_by_the_shop_reads_as_the_emulated_scanner": (
        "media-scanned", [sys.executable, "-m", "wideprint.app.cli", "media", "create",
                          "scanned", "--scan", "--json"], {"WIDEPRINT_MEDIA_DIR": "{dir}"}),
}


def shop_scanner(measure, profile, stop, inject=("scan-margin=40", "scan-rotation=2.5",
                                                 "scan-offset=11,7")):
    """The shop's instrument: each chart that appears in `measure` is printed on the
    emulator and scanned turned and shifted, saved 16 bits as NAME-scan.tif with its dpi."""
    from wideprint.app.devices import close_device, open_device
    from wideprint.device_sim.faults import Faults
    from wideprint.driver.job import PrintJob
    from wideprint.rip.pipeline import RipJob
    pr = mediacal.Printer(profile)
    while not stop.is_set():
        for chart in measure.glob("*.tif") if measure.is_dir() else ():
            if chart.stem.endswith("-scan") or chart.with_name(f"{chart.stem}-scan.tif").exists():
                continue
            raw = measure.parent / f"{chart.stem}-raw.tif"
            job = RipJob(str(chart), pr._settings(), profile)
            dev = open_device("emulator", profile, Faults.parse(list(inject)),
                              scan_path=str(raw), scan_dpi=mediacal.SCAN_DPI)
            try:
                PrintJob(dev, job).run()
            finally:
                close_device(dev)
                job.close()
            rgb = tifffile.imread(raw).astype(np.uint16) * 257
            part = measure.parent / f"{chart.stem}-scan.part"
            tifffile.imwrite(part, rgb, photometric="rgb", resolution=(mediacal.SCAN_DPI,) * 2,
                             resolutionunit="INCH")
            part.rename(chart.with_name(f"{chart.stem}-scan.tif"))
        stop.wait(0.05)


def test_a_chart_scanned_by_the_shop_reads_as_the_emulated_scanner(background, monkeypatch,
                                                                    tmp_path, profile):
    json.loads(background.output("media-scanned"))               # the loop succeeded
    monkeypatch.setenv("WIDEPRINT_MEDIA_DIR", str(background.folder("media-scanned")))
    icc = medialib.find("scanned").folder / "scanner.icc"
    values = np.random.default_rng(8).integers(0, 256, (30, 4)).astype(np.uint8)
    values[values.astype(int).sum(axis=1) > 700] //= 2
    straight = mediacal.Printer(profile, scanner_icc=icc).measure(values, profile)
    measure = tmp_path / "measure"
    stop = threading.Event()
    th = threading.Thread(target=shop_scanner, args=(measure, profile, stop), daemon=True)
    th.start()
    said: list[str] = []
    try:
        lab = mediacal.Printer(profile, scanner_icc=icc, measure_dir=measure, wait_s=120,
                               progress=said.append).measure(values, profile)
    finally:
        stop.set()
        th.join(30)
    assert (measure / "chart.ti1").is_file() and not (measure / "chart.ti3").exists()
    assert "chart-scan.tif" in said[-1]                  # the operator is told where
    de = delta_e2000(lab, straight)
    # the same chart read turned 2.5° and shifted: only the sensor's noise differs
    assert de.mean() < 0.5 and de.max() < 1.5, de
    # and the patches are told apart
    assert delta_e2000(lab[1:], lab[:-1]).mean() > 10


def test_a_scan_that_cannot_be_read_is_refused_naming_the_file(tmp_path):
    scan = tmp_path / "chart-scan.tif"
    tifffile.imwrite(scan, np.full((50, 60, 3), 200, np.uint8), photometric="rgb")
    with pytest.raises(ValueError, match=r"chart-scan.tif: a scan needs the scanner's input"):
        mediacal.scan_lab(scan, [(0, 0, 5, 5)], None, None)
    with pytest.raises(ValueError, match=r"chart-scan.tif: the scan says no resolution"):
        mediacal.scan_lab(scan, [(0, 0, 5, 5)], None, tmp_path / "scanner.icc")
    grey = tmp_path / "grey-scan.tif"
    tifffile.imwrite(grey, np.full((50, 60), 200, np.uint8), resolution=(150, 150),
                     resolutionunit="INCH")
    with pytest.raises(ValueError, match=r"grey-scan.tif: expected an RGB scan"):
        mediacal.scan_lab(grey, [(0, 0, 5, 5)], None, tmp_path / "scanner.icc")
    blank = tmp_path / "blank-scan.tif"
    tifffile.imwrite(blank, np.full((300, 400, 3), 240, np.uint8), photometric="rgb",
                     resolution=(150, 150), resolutionunit="INCH")
    with pytest.raises(ValueError, match=r"blank-scan.tif: the scan is blank"):
        mediacal.scan_lab(blank, [(0, 0, 5, 5)], [(0, 0, 3, 36), (250, 0, 253, 36)],
                          tmp_path / "scanner.icc")
