"""Spot colours on the print server (docs/spot.md, docs/server.md; issue 35): the server's
spot library is its --state-dir's (STATE/spots), and a job's record, the history and the
accounting report carry the spots its RIP resolved - a printed job, a job ripped ahead and
held, and a print-and-cut layout."""

import csv
import io
import json

import numpy as np
import pytest
from support.printcut import BRAND, make_pdf
from support.server import wait_for
from wideprint.app.client import Client
from wideprint.rip import spot
from wideprint.rip.color import DEFAULT_OUTPUT_ICC

FAST = {"dpi": 150}


@pytest.fixture
def spot_env(tmp_path, monkeypatch):
    """An environment whose state directory has a library that must NOT be the server's:
    "Other Green" there, the brand colours in the server's own state directory."""
    monkeypatch.delenv("WIDEPRINT_SPOT_DIR", raising=False)
    env_state = tmp_path / "env-state"
    monkeypatch.setenv("WIDEPRINT_STATE_DIR", str(env_state))
    spot.SpotBook(env_state / "spots").add([spot.Spot("Other Green", (60.0, -50.0, 40.0))], "env")
    root = tmp_path / "srv"
    spot.SpotBook(root / "state" / "spots").add([spot.Spot(n, lab) for n, lab in BRAND.items()], "brand")
    return root


def _by_name(spots):
    return {s["name"]: s for s in spots}


def _check_spots(spots):
    by = _by_name(spots)
    assert {n: s["resolved"] for n, s in by.items()} == {
        "Brand Red": "library", "Brand Teal": "library", "Other Green": "alternate", "CutContour": "cut"}
    for name in BRAND:              # each recipe is its Lab through the default media's profile
        s = by[name]
        assert s["library"] == "brand" and s["media"] == "vinyl-300" and s["in_gamut"] is True
        assert 0 <= s["de2000"] <= 1.0
        cmyk = spot.lab_to_cmyk(np.array([BRAND[name]]), DEFAULT_OUTPUT_ICC)[0]
        assert np.abs(np.array(s["cmyk"]) - cmyk).max() < 1e-3, (name, s["cmyk"], cmyk)
    assert by["Other Green"]["cmyk"] is None and by["CutContour"]["kind"] == "cut"


def test_a_printed_job_records_its_spots_from_the_servers_state_dir(spot_env, print_server, tmp_path):
    pdf = make_pdf(tmp_path / "spots.pdf")
    srv = print_server(spot_env)
    assert srv.state_dir == spot_env / "state"
    c = Client(srv.state_dir)
    try:
        job = c.submit(pdf, settings=FAST)["job"]
        assert job["spots"] is None                            # not ripped yet
        assert c.wait(job["id"], timeout=180)["state"] == "done"
        spots = c.job(job["id"])["spots"]
        _check_spots(spots)
        history = c.request("GET", "/v1/jobs?newest=1&limit=5")["jobs"]
        assert next(j for j in history if j["id"] == job["id"])["spots"] == spots
        rows = c.report(job["id"])
        assert len(rows) == 1 and rows[0]["spots"] == spots
        table = list(csv.DictReader(io.StringIO(c.report_csv(job["id"]))))
        assert json.loads(table[0]["spots"]) == spots
    finally:
        c.close()


def test_ripped_ahead_and_layout_jobs_record_their_spots(spot_env, print_server, tmp_path):
    """A job ripped ahead and held has its spots on its record while it waits (committed
    with its planes), a held job once it has been estimated; a print-and-cut job (a layout:
    its items are ripped while it prints) lists its file's spots too."""
    pdf = make_pdf(tmp_path / "spots.pdf")
    srv = print_server(spot_env)
    c = Client(srv.state_dir)
    try:
        held = c.submit(pdf, settings=FAST, rip_hold=True)["job"]
        ready = wait_for(lambda: (j := c.job(held["id"]))["ripped"] and j["ripped"]["ready"] and j,
                         timeout=180, what="the planes ripped ahead")
        assert ready["state"] == "held"
        _check_spots(ready["spots"])
        # the estimate resolves them as the RIP will, and a waiting job's record keeps them
        waiting = c.submit(pdf, settings=FAST, hold=True)["job"]
        assert waiting["spots"] is None
        _check_spots(c.preview(waiting["id"])["spots"])
        _check_spots(c.job(waiting["id"])["spots"])
        cut = c.submit(pdf, settings=dict(FAST, placement={"marks": "cut"}))["job"]
        assert c.wait(cut["id"], timeout=180)["state"] == "done"
        _check_spots(c.job(cut["id"])["spots"])
    finally:
        c.close()


def test_the_spot_library_is_the_state_dirs_unless_spot_dir_says(tmp_path, monkeypatch):
    """library_dir: $WIDEPRINT_SPOT_DIR, else the server's STATE/spots, else the environment's
    state directory (the CLI's default, unchanged)."""
    from wideprint.app.server.validate import job_rip_settings
    from wideprint.rip.profile import load_profile
    monkeypatch.delenv("WIDEPRINT_SPOT_DIR", raising=False)
    monkeypatch.setenv("WIDEPRINT_STATE_DIR", str(tmp_path / "env"))
    assert spot.library_dir() == tmp_path / "env" / "spots"
    assert spot.SpotBook().folder == tmp_path / "env" / "spots"
    assert spot.library_dir(tmp_path / "srv") == tmp_path / "srv" / "spots"
    rs, _ = job_rip_settings({}, load_profile(), tmp_path / "srv")
    assert rs.spot_dir == str(tmp_path / "srv" / "spots")
    monkeypatch.setenv("WIDEPRINT_SPOT_DIR", str(tmp_path / "shop"))
    assert spot.library_dir(tmp_path / "srv") == tmp_path / "shop"
