"""Fit checked when a job comes in by any door (issue 34 part 4; docs/server.md "Fit
before it fails"): a file wider than the paper is refused as it arrives - a hot folder
moves it to failed/ with the reason naming the file, the CUPS backend exits CANCEL (5,
the CUPS backend contract: this job can never print) with one ERROR line naming it, an
IPP Print-Job ends aborted with document-unprintable-error and the reason in its
job-state-message (docs/ipp.md "A job that does not fit") - and none of them is queued.

The file: 60 x 20 pixels tagged 0.3 pixels an inch, so 200 inches = 5,080 mm wide on a
printer whose paper takes 3,190 mm."""

from __future__ import annotations

import numpy as np
import pytest
import tifffile

from support.images import random_planes, tiny_tiff
from support.server import ServerProcess, inprocess_server, wait_for

WIDE_WORDS = "is 5,080 mm wide: printer {printer}'s paper takes 3,190 mm"


def wide_tiff(path):
    planes = (random_planes(20, 60, seed=3) * 255).astype(np.uint8)
    tifffile.imwrite(path, planes, photometric="separated", resolution=(0.3, 0.3),
                     resolutionunit="INCH")
    return path


def test_a_hot_folder_file_wider_than_the_paper_goes_to_failed_naming_it(tmp_path):
    srv = inprocess_server(tmp_path / "srv", scan_interval=0.1, settle_s=0.3, start_paused=True)
    try:
        folder = srv.root / "hot" / "default"
        wide_tiff(tmp_path / "banner.tif").rename(folder / "banner.tif")
        (folder / "small.tif").write_bytes(tiny_tiff())          # one that fits: queued
        reason = folder / "failed" / "banner.tif.reason.txt"
        wait_for(reason.exists, 30, what=reason.name)
        text = reason.read_text()
        assert text.startswith("banner.tif " + WIDE_WORDS.format(printer="main")), text
        assert "fit-to-width" in text and str(srv.state_dir) not in text
        assert (folder / "failed" / "banner.tif").exists() and not (folder / "banner.tif").exists()
        small = wait_for(lambda: [j for j in srv.jobs() if j["name"] == "small.tif"], 30,
                         what="small.tif queued")
        assert [j["name"] for j in srv.jobs()] == ["small.tif"] and small[0]["state"] == "queued"
        used = srv.spool.spool_files_in_use()
        assert [p for p in srv.spool.spool_dir.iterdir() if str(p) not in used] == []
    finally:
        srv.stop(timeout=5)


def test_a_hot_folder_file_the_roll_left_cannot_hold_is_queued_then_held_not_refused(tmp_path):
    """Not too wide, only longer than the roll left: the file is not lost to failed/ - it
    is queued and the worker holds it before its first stroke until a new roll is loaded
    (the API refuses it, the operator there can force it: a hot folder's writer cannot)."""
    from wideprint.app.client import ApiError, Client
    srv = inprocess_server(tmp_path / "srv", scan_interval=0.1, settle_s=0.3, start_paused=True)
    c = Client(srv.state_dir)
    try:
        c.roll("main", {"media": "vinyl-300", "length_m": 0.01})
        with pytest.raises(ApiError) as e:
            c.submit_bytes(tiny_tiff(), "api.tif")
        assert e.value.status == 422 and "roll has 0.01 m left" in str(e.value)
        folder = srv.root / "hot" / "default"
        (folder / "short.tif").write_bytes(tiny_tiff())
        [job] = wait_for(lambda: [j for j in srv.jobs() if j["name"] == "short.tif"], 30,
                         what="short.tif queued")
        assert not (folder / "failed" / "short.tif.reason.txt").exists()
        c.pause_queue(False)
        held = wait_for(lambda: (lambda j: j if j["state"] == "held" else None)(c.job(job["id"])),
                        30, what="short.tif held")
        assert "held before printing; load a new roll" in held["message"]
        assert (folder / "short.tif").exists()                     # waiting with its job
    finally:
        c.close()
        srv.stop(timeout=5)


def test_the_cups_backend_cancels_a_job_wider_than_the_paper(tmp_path):
    from support.cups_backend import CANCEL, run_backend, uri_of
    srv = ServerProcess(tmp_path / "state", "--paused")
    try:
        r = run_backend(uri_of(srv.state), file=wide_tiff(tmp_path / "in.tif"),
                        title="/home/alice/banner.tif", options="job-uuid=urn:uuid:wide-1")
        assert r.returncode == CANCEL, r.err
        [line] = [ln for ln in r.err.splitlines() if ln.startswith("ERROR: ")]
        assert ("banner.tif " + WIDE_WORDS.format(printer="main")) in line, line
        assert srv.client.jobs() == []
    finally:
        srv.stop()


@pytest.mark.timeout(300)
def test_an_ipp_print_job_wider_than_the_paper_ends_aborted_naming_it(tmp_path):
    from support.private_cups import IppServe
    from support.ipp import BINARY, print_job, wait_ipp_job
    if BINARY is None:
        pytest.fail("the Printer Application is not built (make app/ipp/wideprint-ipp)")
    (tmp_path / "ipp").mkdir()
    ipp = IppServe(tmp_path / "ipp", ["left"])
    try:
        a = print_job(tmp_path, ipp.auth_uri["left"], wide_tiff(tmp_path / "w.tif"),
                      "image/tiff", "banner.tif")
        done = wait_ipp_job(ipp.auth_uri["left"], a["job-id"], tmp_path)
        assert done["job-state"] == 8, done                          # aborted
        assert "document-unprintable-error" in done["job-state-reasons"], done
        msg = done["job-state-message"]
        assert msg.startswith("Not queued: banner.tif " + WIDE_WORDS.format(printer="left")), msg
        assert ipp.client.jobs("queued,held,printing,done,failed,cancelled") == []
    finally:
        ipp.stop()
