"""A scan against the physical model's prediction (issue 20 part 3, docs/acceptance.md):
the emulator stands in for the real printer.  Its own scan - sensor noise, the sheet
rotated and offset on the glass, the scanner's scale error - must match; a scan of a print
with a dead nozzle or a bidirectional error must not, and must say why."""

from __future__ import annotations

import subprocess
import sys
import textwrap

import numpy as np
import pytest
import tifffile

from wideprint.app import api
from wideprint.app.pytest_plugin import assert_scan_matches

SETTINGS = dict(passes=1, bidir=True, dpi=150)
GLASS = ["scan-rotation=0.7", "scan-offset=2,1.5", "scan-noise=1.5", "seed=3"]


@pytest.fixture(scope="module")
def chart(tmp_path_factory):
    """Colour bars (C, M, Y, K, R, G, B, grey) with a white stripe: 60 x 25 mm at 150 ppi;
    and the predicted scan of it at 600 dpi."""
    d = tmp_path_factory.mktemp("scan")
    w, h = 354, 148
    img = np.full((h, w, 3), 255, np.uint8)
    colours = [(0, 255, 255), (255, 0, 255), (255, 255, 0), (0, 0, 0), (255, 0, 0), (0, 255, 0),
               (0, 0, 255), (128, 128, 128)]
    bw = w // 16
    for i in range(16):
        img[:, i * bw:(i + 1) * bw - 6] = colours[i % 8]
    img[h // 2:h // 2 + 10] = 255
    path = d / "chart.tif"
    tifffile.imwrite(path, img, photometric="rgb", resolution=(150, 150), resolutionunit="INCH")
    predicted = api.predict_scan(path, d / "predicted.tif", scan_dpi=600, **SETTINGS)
    return path, predicted, d


def scan_of(chart, name, faults):
    path, _, d = chart
    with api.EmulatedPrinter(faults=faults, scan_dpi=600) as printer:
        result = printer.print(path, scan_out=d / f"{name}.tif", **SETTINGS)
    assert result.ok and result.scan_path == d / f"{name}.tif"
    assert 1 < result.report["printer_s"] < 60        # the job on the printer's own clock
    return result


def test_the_emulators_own_scan_matches_the_prediction(chart):
    result = scan_of(chart, "good", [*GLASS, "scan-scale=1.003"])
    cmp = api.compare_scan(result.scan_path, chart[1])
    assert cmp.ok, cmp.explain()
    # the registration found the sheet where the scanner put it
    assert cmp.rotation_deg == pytest.approx(0.7, abs=0.02)
    assert cmp.scale == pytest.approx(1.003, abs=0.001)
    assert cmp.correlation > 0.95
    # and the plugin's assertion agrees (the scan given explicitly, as --wideprint-scan would)
    assert assert_scan_matches(result, result.scan_path).ok


def test_a_dead_nozzle_fails_with_the_row_it_left(chart):
    result = scan_of(chart, "dead", ["dead-nozzle=M1:57", *GLASS])
    cmp = api.compare_scan(result.scan_path, chart[1])
    assert not cmp.ok
    text = cmp.explain()
    assert "rows: the scan row at" in text and "lighter" in text and "nozzle" in text, text
    with pytest.raises(AssertionError, match="does not match the prediction"):
        assert_scan_matches(result, result.scan_path)


def test_a_bidirectional_error_fails_with_the_shifted_rows(chart):
    result = scan_of(chart, "bidir", ["bidir-error=40um", *GLASS])
    cmp = api.compare_scan(result.scan_path, chart[1])
    assert not cmp.ok
    assert "dot positions" in cmp.explain() and "bidirectional" in cmp.explain(), cmp.explain()
    assert abs(cmp.shift_worst_um) > 25


def test_a_scan_of_another_job_is_refused_at_registration(chart, tmp_path):
    other = np.full((600, 1500, 3), 230, np.uint8)
    other[100:200, 100:1400] = 20
    path = tmp_path / "other.tif"
    tifffile.imwrite(path, other, photometric="rgb", resolution=(600, 600), resolutionunit="INCH")
    cmp = api.compare_scan(path, chart[1])
    assert not cmp.ok and "registration" in cmp.explain()


OUTSIDE_TEST = '''
import os
from wideprint.app.pytest_plugin import assert_scan_matches

def test_chart_on_the_printer(print_job):
    result = print_job(os.environ["CHART"], passes=1, bidir=True, dpi=150)
    assert result.ok
    assert_scan_matches(result)
'''


def test_the_plugin_compares_the_scan_given_on_the_command_line(chart, tmp_path):
    """`pytest --wideprint-scan SCAN.tif` from a project outside the repository: the
    emulator's own scan passes; the scan of a print with a dead nozzle fails, saying why."""
    (tmp_path / "test_outside.py").write_text(textwrap.dedent(OUTSIDE_TEST))
    good = scan_of(chart, "outside-good", GLASS).scan_path
    dead = scan_of(chart, "outside-dead", ["dead-nozzle=C2:40", *GLASS]).scan_path
    env = dict(__import__("os").environ, CHART=str(chart[0]))
    runs = {}
    for name, scan in (("good", good), ("dead", dead)):
        runs[name] = subprocess.run(
            [sys.executable, "-m", "pytest", "-q", "-p", "no:cacheprovider", str(tmp_path),
             f"--wideprint-scan={scan}", f"--wideprint-artifacts={tmp_path / name}"],
            cwd=tmp_path, env=env, capture_output=True, text=True, timeout=600)
    assert runs["good"].returncode == 0, runs["good"].stdout[-3000:]
    out = runs["dead"].stdout
    assert runs["dead"].returncode == 1, out[-3000:]
    assert "does not match the prediction" in out and "a nozzle that does not fire" in out, out[-3000:]
    assert list((tmp_path / "dead").rglob("*-predicted-scan.tif"))     # kept for a look


def test_a_grey_scan_at_another_resolution_is_predicted_alike(chart):
    """assert_scan_matches predicts at the scan's own resolution and mode (here grey, 300
    dpi) and the comparison holds there too."""
    path, _, d = chart
    with api.EmulatedPrinter(faults=[*GLASS, "scan-mode=grey"], scan_dpi=300) as printer:
        result = printer.print(path, scan_out=d / "grey300.tif", **SETTINGS)
    assert tifffile.imread(result.scan_path).ndim == 2
    cmp = assert_scan_matches(result, result.scan_path)
    assert cmp.ok and cmp.dpi == 300 and len(cmp.density_worst) == 1, cmp.explain()
