"""Fit before it fails and the roll on each printer (issue 34 parts 4-5; docs/server.md "Fit
before it fails", "Rolls", "Accounting"): a job wider than the paper is refused at
submission naming its file, with the settings that make it fit; forced, it fails at the
printer and is billed 0 m² for its 0 strokes; every copy's feed comes off the roll; a job
the roll cannot hold any more is held before its first stroke - never half printed."""

from __future__ import annotations

import json
from types import SimpleNamespace

import numpy as np
import pytest

from support.images import random_planes, write_cmyk_tiff
from support.server import wait_for
from wideprint.app.client import ApiError, Client
from wideprint.app.server.rolls import paper_per_copy_mm, parse_label, parse_length_m
from wideprint.app.server.validate import Invalid
from wideprint.rip.planes import read_planes


@pytest.fixture
def srv(print_server):
    s = print_server(start_paused=True)
    c = Client(s.state_dir)
    yield s, c
    c.close()


def test_roll_labels_and_lengths_parse_as_a_shop_writes_them():
    assert parse_length_m("50") == 50.0 and parse_length_m("50m") == 50.0
    assert parse_length_m("50000mm") == 50.0 and parse_length_m("2.5 m") == 2.5
    assert parse_label("media=vinyl-300 length=50m;width=3200") == \
        dict(media="vinyl-300", length_m=50.0, width_mm=3200.0)
    for bad in ("fifty", "-3", "0", "20000"):
        with pytest.raises(Invalid):
            parse_length_m(bad)
    with pytest.raises(Invalid, match="colour=red"):
        parse_label("media=vinyl-300 colour=red")


def test_a_job_wider_than_the_paper_is_refused_naming_the_file_and_forced_is_billed_nothing(
        srv, tmp_path):
    s, c = srv
    src = write_cmyk_tiff(tmp_path / "banner.tif", random_planes(40, 60, seed=3))
    wide = {"placement": {"width_mm": 5080}}
    with pytest.raises(ApiError) as e:
        c.submit(src, settings=wide)
    msg = str(e.value)
    assert e.value.status == 422
    assert msg.startswith("banner.tif is 5,080 mm wide: printer main's paper takes 3,190 mm")
    assert "spool" not in msg and str(s.state_dir) not in msg
    assert "fit-to-width" in msg and "force" in msg
    assert c.jobs() == [] and list(s.spool.spool_dir.iterdir()) == []   # nothing queued
    # the offers make it fit: fit-to-width (scaled to the printable width) and rotation
    held = c.submit(src, settings={"placement": {"width_mm": 5080, "height_mm": 1000}},
                    force=True, hold=True)["job"]
    fit = c.fit(held["id"])
    assert not fit["fits"] and fit["width_mm"] == 5080.0 and fit["printable_mm"] == 3190.0
    kinds = {o["kind"]: o for o in fit["offers"]}
    assert kinds["fit-to-width"]["width_mm"] <= 3190 and kinds["rotate"]["width_mm"] == 1000.0
    preview = c.preview(held["id"])
    assert preview["fit"]["problems"] == fit["problems"]                 # the estimate flags it
    fixed = c.edit(held["id"], settings=kinds["rotate"]["settings"])
    assert c.fit(fixed["id"])["fits"]
    c.action(held["id"], "cancel")
    # forced: queued, fails at the printer with the file's name, billed 0 m² for 0 strokes
    job = c.submit(src, settings=wide, force=True)["job"]
    c.pause_queue(False)
    end = c.wait(job["id"], 60)
    assert end["state"] == "failed" and end["message"].startswith("banner.tif: ")
    assert "spool" not in end["message"]
    rows = c.report(job["id"])
    assert [(r["outcome"], r["strokes_printed"], r["area_m2"], r["ink_c_ml"]) for r in rows] == \
        [("failed", 0, 0.0, 0.0)]
    assert rows[0]["strokes_total"] > 0 and rows[0]["width_dots"] == 60000


def test_every_feed_comes_off_the_roll_and_a_job_it_cannot_hold_is_held_not_half_printed(
        srv, tmp_path):
    s, c = srv
    planes = [random_planes(300, 200, seed=40 + i) for i in range(3)]
    files = [write_cmyk_tiff(tmp_path / f"job{i}.tif", p) for i, p in enumerate(planes)]
    prof = s.profile
    need = paper_per_copy_mm(prof, 300 * prof.row_um / 1000.0)
    # a roll, from its label, that holds two of these jobs and a half
    length_m = round(2.5 * need / 1000, 4)
    r = c.roll("main", {"label": f"media=vinyl-300 length={length_m}m"})
    assert r["roll"]["media"] == "vinyl-300" and r["roll"]["remaining_m"] == round(length_m, 3)
    ids = [c.submit(f)["job"]["id"] for f in files]          # each fits the roll at submission
    c.pause_queue(False)
    for jid in ids[:2]:
        assert c.wait(jid, 60)["state"] == "done"
    third = wait_for(lambda: (lambda j: j if j["state"] == "held" else None)(c.job(ids[2])), 30,
                     what="the third job held")
    # the warning names the file, says how much it needs and has, and what to do
    assert third["message"].startswith("job2.tif: needs ") and "left: held before printing" \
        in third["message"] and "load a new roll" in third["message"]
    assert third["strokes_done"] == 0 and c.report(ids[2]) == []        # not one stroke
    assert not (s.root / "media" / f"job-{ids[2]}.tif").exists()
    # what the two done copies fed came off the roll, as the printer counted it
    fed = [c.report(jid)[0]["paper_mm"] for jid in ids[:2]]
    assert all(0.9 * need < f <= need + 0.5 for f in fed), (fed, need)
    roll = c.roll("main")["roll"]
    assert roll["remaining_mm"] == pytest.approx(length_m * 1000 - sum(fed), abs=1e-6)
    assert roll["width_mm"] == pytest.approx(3200, abs=1)                 # the paper sensor
    for jid, p in zip(ids[:2], planes):
        assert np.array_equal(read_planes(s.root / "media" / f"job-{jid}.tif"), p)
    # released, it is held again at once (the roll has not changed) ...
    c.action(ids[2], "release")
    wait_for(lambda: c.job(ids[2])["state"] == "held", 30, what="held again")
    # ... until a new roll is loaded; then it prints whole
    c.roll("main", {"media": "vinyl-300", "length_m": 50})
    c.action(ids[2], "release")
    assert c.wait(ids[2], 60)["state"] == "done"
    assert np.array_equal(read_planes(s.root / "media" / f"job-{ids[2]}.tif"), planes[2])
    assert c.roll("main")["roll"]["remaining_mm"] == pytest.approx(
        50_000 - c.report(ids[2])[0]["paper_mm"], abs=1e-6)


def test_printer_roll_commands(srv, capsys):
    s, _ = srv
    from wideprint.app.cli import main

    def run(*args):
        rc = main(["printer", "roll", *args, "--state-dir", str(s.state_dir)])
        out = capsys.readouterr()
        return SimpleNamespace(returncode=rc, stdout=out.out, stderr=out.err)
    r = run()
    assert r.returncode == 0 and "no roll loaded" in r.stdout
    r = run("load", "--media", "vinyl-300", "--length", "50m")
    assert r.returncode == 0 and "vinyl-300" in r.stdout and "50.00 m left of 50.00 m" in r.stdout
    r = run("set", "--remaining", "12.5", "--json")
    assert r.returncode == 0 and json.loads(r.stdout)["roll"]["remaining_m"] == 12.5
    r = run("load", "--media", "no-such-paper", "--length", "5")
    assert r.returncode == 1 and "no media 'no-such-paper'" in r.stderr
    r = run("unload")
    assert r.returncode == 0 and "no roll loaded" in r.stdout
