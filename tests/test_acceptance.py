"""Whole jobs on the emulator: what landed equals what the RIP meant, bit for bit."""

import json
import subprocess
import sys

import numpy as np
import pytest

from conftest import PX, ROOT, random_planes, write_cmyk_tiff
from wideprint.driver.device import open_device
from wideprint.driver.job import JobError, PrintJob
from wideprint.rip.pipeline import RipJob, RipSettings
from wideprint.rip.planes import read_planes


def print_on_emulator(path, settings, profile, media, faults=None):
    dev = open_device("emulator", profile, faults, media_path=str(media))
    try:
        rep = PrintJob(dev, RipJob(str(path), settings, profile)).run()
    finally:
        dev.emulator.close()
    return rep, dev.emulator


@pytest.mark.parametrize("dpi,passes,bidir", [
    (300, 1, False), (300, 2, True), (600, 4, False), (150, 3, True), (300, 8, True),
    (600, 6, True),
])
def test_binary_cmyk_tiff_prints_bit_exact(tmp_path, profile, dpi, passes, bidir):
    planes = random_planes(700, 333, density=0.35, seed=dpi + passes)
    src = write_cmyk_tiff(tmp_path / "in.tif", planes)
    media = tmp_path / "media.tif"
    rep, emu = print_on_emulator(src, RipSettings(placement=PX, dpi=dpi, passes=passes, bidir=bidir),
                                 profile, media)
    got = read_planes(media)
    assert got.shape == planes.shape
    assert np.array_equal(got, planes)
    assert emu.jobs_done[1]["stray"] == 0
    assert rep.drops == planes.reshape(-1, 4).sum(axis=0).tolist()


def test_sparse_image_skips_blank_passes_and_still_matches(tmp_path, profile):
    planes = np.zeros((1500, 200, 4), np.uint8)
    planes[10:20, 5:50, 0] = 1           # a cyan bar at the top
    planes[1400:1450, 150:190, 3] = 1    # a black bar near the bottom
    src = write_cmyk_tiff(tmp_path / "in.tif", planes)
    rep, emu = print_on_emulator(src, RipSettings(placement=PX, passes=2, bidir=True), profile,
                                 tmp_path / "m.tif")
    assert np.array_equal(read_planes(tmp_path / "m.tif"), planes)
    assert rep.passes_skipped > 0 and rep.passes_printed < rep.passes_total


def test_job_wider_than_paper_is_refused_before_printing(tmp_path, profile):
    from wideprint.device_sim.faults import Faults
    src = write_cmyk_tiff(tmp_path / "wide.tif", random_planes(20, 1300, seed=3))
    with pytest.raises(JobError, match="wide.tif.*wide at 300 dpi but the paper is 100 mm"):
        print_on_emulator(src, RipSettings(placement=PX), profile, tmp_path / "m.tif",
                          Faults(paper_width_mm=100))


def test_cli_print_media_equals_cli_rip_planes(tmp_path):
    sample = ROOT / "resources" / "samples" / "sample.tif"
    exe = [sys.executable, "-m", "wideprint.app.cli"]
    media, planes, report = tmp_path / "media.tif", tmp_path / "planes.tif", tmp_path / "r.json"
    opts = ["--passes", "2", "--bidir", "--dither", "bayer"]
    log = tmp_path / "log.jsonl"
    subprocess.run(exe + ["print", str(sample), "--device", "emulator", "--media-out", str(media),
                          "--report", str(report), "--log-json", str(log)] + opts,
                   check=True, capture_output=True)
    events = [json.loads(line) for line in log.read_text().splitlines()]
    assert [e["state"] for e in events if e["event"] == "state"][-1] == "done"
    assert any(e["event"] == "status" and len(e["telemetry"]["fifo_words"]) == 8 for e in events)
    subprocess.run(exe + ["rip", str(sample), "-o", str(planes)] + opts, check=True,
                   capture_output=True)
    assert np.array_equal(read_planes(media), read_planes(planes))
    rep = json.loads(report.read_text())[0]
    assert rep["state"] == "done" and rep["stray_drops"] == 0
    assert rep["passes_printed"] > 0


def test_cli_bad_file_fails_its_job_and_the_next_prints(tmp_path):
    bad = tmp_path / "bad.tif"
    bad.write_bytes(b"II*\x00garbage")
    good = write_cmyk_tiff(tmp_path / "good.tif", random_planes(50, 40, seed=9))
    exe = [sys.executable, "-m", "wideprint.app.cli"]
    r = subprocess.run(exe + ["print", str(bad), str(good), "--media-out",
                              str(tmp_path / "m.tif"), "--json", "--size", "pixels"],
                       capture_output=True, text=True)
    assert r.returncode == 1
    assert "bad.tif" in r.stderr
    reports = json.loads(r.stdout)
    assert [x["state"] for x in reports] == ["failed", "done"]
    assert np.array_equal(read_planes(tmp_path / "m-2.tif"), random_planes(50, 40, seed=9))


def test_file_corrupt_far_down_fails_its_job_cleanly(tmp_path, profile):
    """A strip deep in the file is garbage: the job fails naming the file; the printer is
    left stopped with the heads off, ready for the next job."""
    import tifffile
    planes = random_planes(2000, 300, seed=17)
    path = tmp_path / "late.tif"
    tifffile.imwrite(path, planes * 255, photometric="separated", compression="deflate",
                     rowsperstrip=64)
    with tifffile.TiffFile(path) as t:
        off = t.pages[0].tags["StripOffsets"].value[-5]
        cnt = t.pages[0].tags["StripByteCounts"].value[-5]
    raw = bytearray(path.read_bytes())
    raw[off:off + cnt] = np.random.default_rng(0).integers(0, 256, cnt, dtype=np.uint8).tobytes()
    path.write_bytes(bytes(raw))
    dev = open_device("emulator", profile, media_path=str(tmp_path / "m.tif"))
    job = PrintJob(dev, RipJob(str(path), RipSettings(placement=PX), profile))
    with pytest.raises(JobError, match="late.tif: corrupt TIFF data"):
        job.run()
    assert job.report.state == "failed" and job.report.passes_printed > 0
    from wideprint.driver import protocol as P
    assert dev.emulator.fpga.we_en is False and not dev.emulator.busy()
    good = write_cmyk_tiff(tmp_path / "good.tif", random_planes(100, 80, seed=18))
    dev.emulator.media_path = str(tmp_path / "m2.tif")
    PrintJob(dev, RipJob(str(good), RipSettings(placement=PX), profile), job_id=2).run()
    dev.emulator.close()
    assert np.array_equal(read_planes(tmp_path / "m2.tif"), random_planes(100, 80, seed=18))
