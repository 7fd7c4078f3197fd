"""Calibration from a scan (docs/calibration.md), closed loop on the emulator: a known error
is injected, the pattern printed and scanned (noise, 1.5° rotation, 0.2 % scale error, an
offset on the glass), `wideprint calibrate` recovers it and writes the profile, and a
print with the calibrated profile shows the error gone on its physical scan."""

import json
import shutil

import numpy as np
import pytest
import tifffile

from support.images import PX, write_cmyk_tiff
from wideprint.app.calibrate import CalibrationError, calibrate
from wideprint.app.cli import main
from wideprint.app.devices import open_device
from wideprint.device_sim.faults import Faults
from wideprint.driver.job import PrintJob
from wideprint.rip.pipeline import RipJob, RipSettings
from wideprint.rip.planes import read_planes
from wideprint.rip.profile import DEFAULT_PROFILE, FINE_STEPS, load_profile
from wideprint.rip.testprints import PatternJob

SCANNER = ["scan-rotation=1.5", "scan-scale=1.002", "scan-offset=1.5,-1", "scan-noise=2", "seed=7"]
BAND = (0, 1, 2, 1)


def injects(items):
    return [a for item in items for a in ("--inject", item)]


def test_print(tmp_path, name, pattern, inject, width_mm, dpi=150, scan_dpi=1200, profile=None):
    """`wideprint test-print PATTERN --scan-out` on the emulator: (scan path, media path)."""
    scan, media = tmp_path / f"{name}.tif", tmp_path / f"{name}-media.tif"
    args = ["test-print", pattern, "--width-mm", str(width_mm), "--dpi", str(dpi),
            "--scan-out", str(scan), "--scan-dpi", str(scan_dpi), "--media-out", str(media),
            *injects([*inject, *SCANNER])] + (["--profile", str(profile)] if profile else [])
    assert main(args) == 0
    return str(scan), str(media)


test_print.__test__ = False      # a helper, not a test


def run_calibrate(capsys, kind, scan, width_mm, dpi=150, profile=None, write=False):
    """`wideprint calibrate KIND --json`: what it found."""
    capsys.readouterr()
    args = ["calibrate", kind, "--scan", scan, "--width-mm", str(width_mm), "--dpi", str(dpi),
            "--json"] + (["--profile", str(profile)] if profile else []) + (["--write"] if write else [])
    assert main(args) == 0
    out = json.loads(capsys.readouterr().out)
    return out["found"]


@pytest.fixture
def user_profile(tmp_path):
    path = tmp_path / "printer.toml"
    shutil.copy(DEFAULT_PROFILE, path)
    return path


def registered(found):
    """The scanner's geometry was found: 1.5° and 1.002."""
    assert abs(found["registration"]["rotation_deg"] - 1.5) < 0.01
    assert abs(found["registration"]["scale"] - 1.002) < 2e-4


# -- dead nozzles -------------------------------------------------------------------------------
DEAD = ["C2:10", "M1:57", "Y1:3", "K2:100", "K2:101"]


def tint_run(tmp_path, name, profile, planes, faults):
    """A 2-pass print of `planes` on the machine with these faults (the machine is the
    default profile; the driver uses `profile`), with an unrotated scan: (media, scan,
    scanner)."""
    src = write_cmyk_tiff(tmp_path / f"{name}-in.tif", planes)
    media, scan = tmp_path / f"{name}-m.tif", str(tmp_path / f"{name}-s.tif")
    dev = open_device("emulator", profile, faults, media_path=str(media), scan_path=scan,
                      scan_dpi=1200, machine_profile=load_profile())
    try:
        PrintJob(dev, RipJob(str(src), RipSettings(placement=PX, dpi=150, passes=2), profile)).run()
    finally:
        dev.emulator.close()
    return read_planes(media), tifffile.imread(scan), dev.emulator.scans[scan]


def row_ink(scan, scanner, rows, c0, c1, channel, row_um, col_um):
    """Mean darkness (8-bit levels below paper white) of the scan over image rows `rows`
    (each ±half a row) and columns [c0, c1), in the ink's band."""
    white = np.percentile(scan[:, :, BAND[channel]], 99)
    out = []
    for r in rows:
        u0, v0 = scanner.paper_to_scan(c0 * col_um, (r + 0.0) * row_um)
        u1, v1 = scanner.paper_to_scan(c1 * col_um, (r + 1.0) * row_um)
        win = scan[int(round(v0)):int(round(v1)), int(round(u0)):int(round(u1)), BAND[channel]]
        out.append(white - win.astype(np.float64).mean())
    return np.array(out)


def test_dead_nozzles_are_found_exactly_and_printed_around(tmp_path, capsys, user_profile):
    scan, _ = test_print(tmp_path, "nc", "nozzle-check", [f"dead-nozzle={d}" for d in DEAD], 50,
                         scan_dpi=600)
    found = run_calibrate(capsys, "nozzles", scan, 50, profile=user_profile, write=True)
    registered(found)
    print(f"dead {found['dead']}, ink fractions {found['ink_fraction']}")
    assert found["dead"] == DEAD                           # exactly, in the --inject notation
    assert found["dashes"] == 8 * 126
    prof = load_profile(user_profile)
    names = {(prof.heads[h].name, z) for h, z in prof.dead_nozzles}
    assert names == {(d.split(":")[0], int(d.split(":")[1])) for d in DEAD}
    # a 2-pass flat tint of every ink (a band of columns each) on the same machine: with
    # the default profile the dead nozzles' rows lose dots; with the calibrated one the
    # planner prints them with the other pass: the media is exact and the scan shows no
    # light row
    planes = np.zeros((300, 160, 4), np.uint8)
    for c in range(4):
        planes[:, 40 * c:40 * c + 40, c] = 1
    faults = Faults.parse([f"dead-nozzle={d}" for d in DEAD])
    bad, bad_scan, bad_scanner = tint_run(tmp_path, "bad", load_profile(), planes, faults)
    good, good_scan, good_scanner = tint_run(tmp_path, "good", prof, planes, faults)
    assert np.array_equal(good, planes)
    lost = np.argwhere((bad != planes).any(axis=1))        # (row, channel) that lost dots
    assert len(lost) > 4
    col_um, row_um = 25_400 / 150, prof.row_um
    for r, c in lost:
        if not 3 <= r < planes.shape[0] - 3:
            continue
        c0, c1 = 40 * c + 3, 40 * c + 37
        ref_rows = [x for x in range(max(0, r - 12), min(planes.shape[0], r + 13)) if abs(x - r) > 3]
        for scan_, scanner, what in ((bad_scan, bad_scanner, "default"), (good_scan, good_scanner, "calibrated")):
            ink = row_ink(scan_, scanner, [r], c0, c1, c, row_um, col_um)[0]
            ref = np.median(row_ink(scan_, scanner, ref_rows, c0, c1, c, row_um, col_um))
            print(f"row {r} ink {'CMYK'[c]}: {what} {ink / ref:.3f} of the tint")
            if what == "default":
                assert ink < 0.85 * ref
            else:
                assert ink > 0.95 * ref


# -- bidirectional offset: a fraction of a column, and more than one ----------------------------
@pytest.mark.parametrize("dpi, error", [(300, 0.3), (150, 1.3)])
def test_bidir_offset_is_measured_and_corrected(tmp_path, capsys, user_profile, dpi, error):
    inject = [f"bidir-error={error}col"]
    col_um = 25_400 / dpi
    scan, media = test_print(tmp_path, "b", "bidir-scan", inject, 40, dpi)
    job = PatternJob.for_pattern("bidir-scan", load_profile(), int(round(40 / 25.4 * dpi)), dpi)
    found = run_calibrate(capsys, "bidir", scan, 40, dpi, user_profile, write=True)
    registered(found)
    print(f"{dpi} dpi, injected {-error * col_um:.2f} µm: measured {found['offset_um']} µm")
    assert abs(found["offset_um"] + error * col_um) < 3.0
    prof = load_profile(user_profile)
    assert abs(prof.bidir_shift_columns(dpi) - error) <= 0.5 / FINE_STEPS + 3.0 / col_um
    assert all(prof.bidir_shift_columns(d) == 0 for d in prof.dpi_modes if d != dpi)
    if error >= 0.5:          # the uncalibrated media already shows it: drops in the next cell
        assert not np.array_equal(read_planes(media), job.planes)
    # the same machine with the calibrated profile: the reverse stroke meets the forward one
    scan2, media2 = test_print(tmp_path, "b2", "bidir-scan", inject, 40, dpi, profile=user_profile)
    after = run_calibrate(capsys, "bidir", scan2, 40, dpi, user_profile)
    print(f"after calibration: {after['offset_um']} µm")
    assert abs(after["offset_um"]) < 3.0
    assert np.array_equal(read_planes(media2), job.planes)       # and every drop in its cell


# -- head offsets -------------------------------------------------------------------------------
HEAD_ERRORS = {"C2": (20.0, -10.0), "M1": (-35.0, 140.0), "Y2": (60.0, 0.0)}


def test_head_offsets_are_measured_and_corrected(tmp_path, capsys, user_profile):
    inject = [f"head-offset={h}:x={x}um,y={y}um" for h, (x, y) in HEAD_ERRORS.items()]
    scan, _ = test_print(tmp_path, "h", "heads-scan", inject, 60)
    found = run_calibrate(capsys, "heads", scan, 60, profile=user_profile, write=True)
    registered(found)
    for name, got in found["heads"].items():
        x, y = HEAD_ERRORS.get(name, (0.0, 0.0))
        print(f"{name}: injected {x:+.1f}, {y:+.1f} µm; measured {got['x_um']:+.2f}, {got['y_um']:+.2f}")
        assert abs(got["x_um"] - x) < 3.0 and abs(got["y_um"] - y) < 3.0
    prof = load_profile(user_profile)
    m1 = next(h for h in prof.heads if h.name == "M1")
    assert m1.y_rows == 2                                   # two rows: one nozzle pitch down
    assert abs(prof.layout.head_y_um["M1"] - (140.0 - prof.nozzle_pitch_um)) < 3.0
    assert abs(prof.layout.head_x_um["Y2"] - 60.0) < 3.0
    # print again on the same machine (the emulator keeps the default profile: the heads
    # are where they were); x is corrected for every head, y by whole nozzle pitches
    job = PatternJob.for_pattern("heads-scan", prof, int(round(60 / 25.4 * 150)), 150)
    scan2 = str(tmp_path / "h2.tif")
    dev = open_device("emulator", prof, Faults.parse(inject + SCANNER), scan_path=scan2,
                      scan_dpi=1200, machine_profile=load_profile())
    try:
        PrintJob(dev, job).run()
    finally:
        dev.emulator.close()
    after = calibrate("heads", scan2, prof, 150, 60).found["heads"]
    for name, got in after.items():
        print(f"after: {name} {got['x_um']:+.2f}, {got['y_um']:+.2f} µm")
        assert abs(got["x_um"]) < 3.0
    assert abs(after["M1"]["y_um"] - (140.0 - prof.nozzle_pitch_um)) < 3.0
    assert abs(after["C2"]["y_um"] + 10.0) < 3.0       # under a row: only a mechanic moves it


# -- feed ---------------------------------------------------------------------------------------
def test_feed_error_is_measured_and_corrected(tmp_path, capsys, user_profile):
    inject = ["feed-error=15um"]
    scan, _ = test_print(tmp_path, "f", "feed-scan", inject, 40)
    found = run_calibrate(capsys, "feed", scan, 40, profile=user_profile, write=True)
    registered(found)
    print(f"feed: {found}")
    assert abs(found["travel_error_um_per_feed"] - 15.0) < 2.0
    offsets = np.array(found["stroke_offsets_um"])
    assert offsets[-1] > 3 * 15.0 - 3 * 11.8 - 3 and found["placement_um_per_feed"] > 9.0
    prof = load_profile(user_profile)
    feed_um = prof.feed_steps_for_rows(252) * prof.feed_um_per_step
    assert abs(prof.feed.travel_error_ppm - 15.0 / feed_um * 1e6) < 2.0 / feed_um * 1e6
    scan2, _ = test_print(tmp_path, "f2", "feed-scan", inject, 40, profile=user_profile)
    after = run_calibrate(capsys, "feed", scan2, 40, profile=user_profile)
    print(f"after: {after}")
    # what is left is the whole steps' rounding (at most half a step each stroke, never
    # accumulating: over four strokes it can tilt the fit by a few µm a feed)
    half_step = prof.feed_um_per_step / 2
    assert np.abs(after["stroke_offsets_um"]).max() < half_step + 2.0
    assert abs(after["placement_um_per_feed"]) < 5.0


# -- refusals -----------------------------------------------------------------------------------
def test_a_scan_without_the_pattern_is_refused(tmp_path, capsys, user_profile):
    blank = tmp_path / "blank.tif"
    tifffile.imwrite(blank, np.full((400, 600, 3), 230, np.uint8), resolution=(600, 600))
    assert main(["calibrate", "nozzles", "--scan", str(blank)]) == 3
    assert "no pattern" in capsys.readouterr().err
    scan, _ = test_print(tmp_path, "f", "feed-scan", [], 40, scan_dpi=300)
    with pytest.raises(CalibrationError, match="frame bars|not this pattern"):
        calibrate("heads", scan, load_profile(), 150, 60)     # another pattern, another width
    assert main(["calibrate", "feed", "--scan", scan, "--width-mm", "40", "--write"]) == 2
    assert "--write needs --profile" in capsys.readouterr().err
