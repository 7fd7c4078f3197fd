"""Whole jobs on the emulator: what landed equals what the RIP meant, bit for bit."""

import json
import subprocess
import sys

import numpy as np
import pytest

from support.images import PX, ROOT, random_planes, write_cmyk_tiff
from support.printing import print_on_emulator
from wideprint.app.devices import open_device
from wideprint.driver.job import JobError, PrintJob
from wideprint.rip.pipeline import RipJob, RipSettings
from wideprint.rip.planes import read_planes


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


def test_sparse_image_skips_blank_strokes_and_still_matches(tmp_path, profile):
    planes = np.zeros((1500, 200, 4), np.uint8)
    planes[10:20, 5:50, 0] = 1           # a cyan bar at the top
    planes[1400:1450, 150:190, 3] = 1    # a black bar near the bottom
    src = write_cmyk_tiff(tmp_path / "in.tif", planes)
    rep, emu = print_on_emulator(src, RipSettings(placement=PX, passes=2, bidir=True), profile,
                                 tmp_path / "m.tif")
    assert np.array_equal(read_planes(tmp_path / "m.tif"), planes)
    assert rep.strokes_skipped > 0 and rep.strokes_printed < rep.strokes_total


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
    log, emu_log = tmp_path / "log.jsonl", tmp_path / "emu.jsonl"
    subprocess.run(exe + ["print", str(sample), "--device", "emulator", "--media-out", str(media),
                          "--report", str(report), "--log-json", str(log), "--event-log", str(emu_log),
                          "--align", "center", "--x-mm", "-20", "--top-mm", "15"] + opts,
                   check=True, capture_output=True)
    events = [json.loads(line) for line in log.read_text().splitlines()]
    assert [e["state"] for e in events if e["event"] == "state"][-1] == "done"
    assert any(e["event"] == "status" and len(e["telemetry"]["fifo_words"]) == 8 for e in events)
    subprocess.run(exe + ["rip", str(sample), "-o", str(planes)] + opts, check=True,
                   capture_output=True)
    assert np.array_equal(read_planes(media), read_planes(planes))
    rep = json.loads(report.read_text())[0]
    assert rep["state"] == "done" and rep["stray_drops"] == 0
    assert rep["strokes_printed"] > 0
    # placed as asked: centred on the emulator's 3200 mm sheet, 20 mm to the left
    from wideprint.rip.profile import load_profile
    prof = load_profile()
    end = [json.loads(line) for line in emu_log.read_text().splitlines()
           if json.loads(line)["event"] == "job_end"][-1]
    width_mm = rep["width_dots"] * prof.k(300) / prof.counts_per_inch * 25.4
    assert abs(end["left_mm"] - ((3200 - width_mm) / 2 - 20)) < 0.2


def test_cli_report_counts_strokes_not_passes(tmp_path):
    """A 2-pass job taller than one swath takes more carriage strokes than it has passes:
    the report counts strokes (docs/architecture.md, "Words") and the CLI says so."""
    planes = random_planes(600, 60, seed=12)                   # 600 rows: > 126, one advance
    src = write_cmyk_tiff(tmp_path / "tall.tif", planes)
    exe = [sys.executable, "-m", "wideprint.app.cli"]
    r = subprocess.run(exe + ["print", str(src), "--passes", "2", "--size", "pixels", "--json",
                              "--media-out", str(tmp_path / "m.tif")],
                       capture_output=True, text=True)
    assert r.returncode == 0, r.stderr
    (rep,) = json.loads(r.stdout)
    assert rep["state"] == "done"
    assert rep["strokes_total"] == -(-600 // 126) + 1                # ceil(H / A) + N - 1
    assert rep["strokes_printed"] == rep["strokes_total"] > 2 and rep["strokes_skipped"] == 0
    assert not any(k.startswith("passes") for k in rep)
    assert f"printed {rep['strokes_printed']} strokes" in r.stderr
    assert np.array_equal(read_planes(tmp_path / "m.tif"), planes)


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
    assert job.report.state == "failed" and job.report.strokes_printed > 0
    assert dev.emulator.fpga.we_en is False and not dev.emulator.busy()
    good = write_cmyk_tiff(tmp_path / "good.tif", random_planes(100, 80, seed=18))
    dev.emulator.media_path = str(tmp_path / "m2.tif")
    PrintJob(dev, RipJob(str(good), RipSettings(placement=PX), profile), job_id=2).run()
    dev.emulator.close()
    assert np.array_equal(read_planes(tmp_path / "m2.tif"), random_planes(100, 80, seed=18))


@pytest.mark.parametrize("align,x_mm,margin_mm,top_mm", [
    ("left", 0.0, None, 0.0), ("left", 12.5, 0.0, 20.0), ("center", -30.0, 10.0, 0.0),
    ("right", 0.0, 7.0, 5.0), ("right", -100.0, None, 0.0),
])
def test_position_and_margins_on_the_measured_paper(tmp_path, profile, align, x_mm, margin_mm,
                                                     top_mm):
    """The image lands where the placement says, measured by the emulator from the paper's
    edge and feed, and the media still equals the planes."""
    from dataclasses import replace
    from wideprint.device_sim.faults import Faults
    planes = random_planes(300, 333, density=0.3, seed=5)
    src = write_cmyk_tiff(tmp_path / "in.tif", planes)
    paper = 300.0
    runs = {}
    for top in (0.0, top_mm):
        pl = replace(PX, align=align, x_mm=x_mm, margin_mm=margin_mm, top_mm=top)
        media = tmp_path / f"m{top}.tif"
        rep, emu = print_on_emulator(src, RipSettings(placement=pl, passes=2), profile, media,
                                     Faults(paper_width_mm=paper))
        assert np.array_equal(read_planes(media), planes)
        runs[top] = (emu.jobs_done[1], emu.paper_steps)
    done, steps = runs[top_mm]
    cpi = profile.counts_per_inch
    width_mm = 333 * profile.k(300) / cpi * 25.4
    margin = profile.paper.margin_mm if margin_mm is None else margin_mm
    want = {"left": margin, "center": (paper - width_mm) / 2,
            "right": paper - margin - width_mm}[align] + x_mm
    # x0 sits on the coarsest dpi mode's column grid, inside the margins
    grid_mm = max(profile.k(d) for d in profile.dpi_modes) / cpi * 25.4
    assert abs(done["left_mm"] - want) <= grid_mm + 25.4 / cpi
    # the top margin: image row 0 later by top_mm, and that much more paper used
    row_mm = profile.row_um / 1000
    assert abs(done["lead_mm"] - runs[0.0][0]["lead_mm"] - top_mm) <= row_mm / 2 + 1e-6
    fed_mm = (steps - runs[0.0][1]) * profile.feed_um_per_step / 1000
    assert abs(fed_mm - top_mm) <= row_mm / 2 + profile.feed_um_per_step / 1000


@pytest.mark.parametrize("align,x_mm,msg", [
    ("right", 5.0, r"in.tif: the image \(20 mm wide, right aligned, x offset 5 mm\) would end "
                   r"5.0 mm right of the right margin; the paper is 300 mm with 5 mm margins"),
    ("left", -5.0, "would start 5.0 mm left of the left margin"),
])
def test_position_off_the_paper_is_refused_before_printing(tmp_path, profile, align, x_mm, msg):
    from dataclasses import replace
    from wideprint.device_sim.faults import Faults
    src = write_cmyk_tiff(tmp_path / "in.tif", random_planes(40, 236, seed=2))   # 19.98 mm
    pl = replace(PX, align=align, x_mm=x_mm)
    dev = open_device("emulator", profile, Faults(paper_width_mm=300), media_path=str(tmp_path / "m.tif"))
    try:
        with pytest.raises(JobError, match=msg):
            PrintJob(dev, RipJob(str(src), RipSettings(placement=pl), profile)).run()
        assert dev.emulator.jobs_done == {} and dev.emulator.blocks_total == 0
    finally:
        dev.emulator.close()


def test_one_pass_job_with_dead_nozzles_on_neighbouring_rows_fails_before_anything_moves(tmp_path):
    """One pass gives a dead row's dots to its neighbours (rip/deadrows.py); when a
    neighbour row is dead too, the planner's refusal is the job's failure, before the
    printer is touched (the CLI and the server go on with the next job)."""
    from support.printing import variant_profile
    prof = variant_profile(tmp_path, dead=[("M1", 57), ("M2", 57)])      # slots 114, 115
    src = write_cmyk_tiff(tmp_path / "one.tif", random_planes(60, 50, seed=4))
    dev = open_device("emulator", prof, None, media_path=str(tmp_path / "m.tif"))
    try:
        job = PrintJob(dev, RipJob(str(src), RipSettings(placement=PX, passes=1), prof))
        with pytest.raises(JobError, match=r"one.tif: dead nozzles on neighbouring rows of colour "
                                           r"M \(M1:57, M2:57\): one pass cannot print around them"):
            job.run()
        assert job.report.state == "failed"
        assert not dev.emulator.homed and dev.emulator.blocks_total == 0
        # the same file and profile with two passes prints exactly
        rep, _ = print_on_emulator(src, RipSettings(placement=PX, passes=2), prof, tmp_path / "m2.tif")
        assert np.array_equal(read_planes(tmp_path / "m2.tif"), random_planes(60, 50, seed=4))
    finally:
        dev.emulator.close()
