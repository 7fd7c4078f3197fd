"""Look before printing, the archive and reprints (issue 34 part 3; docs/server.md "Presets",
"Archive and reprint"): a preset that holds its jobs, the estimate and quote before release;
a done job's file kept by the retention policy (declared once, documented), and reprinted -
as it was (its media bit for bit the original's) or with changed settings - from the CLI
and the API."""

from __future__ import annotations

import json
import os
import re
import time
from pathlib import Path

import numpy as np
import pytest

from support.images import random_planes, write_cmyk_tiff
from support.server import wait_for
from wideprint.app.client import ApiError, Client
from wideprint.app.server import archive
from wideprint.app.server.spool import Spool
from wideprint.rip.planes import read_planes

DOCS = Path(__file__).resolve().parent.parent / "docs" / "server.md"


def test_the_archive_options_are_declared_once_and_documented():
    text = DOCS.read_text()
    section = text.split("## Archive and reprint", 1)[1].split("\n## ", 1)[0]
    rows = re.findall(r"^\| `(--[a-z-]+)(?: [A-Z]+)?` \| ([0-9.]+|off) \| (.+) \|$", section, re.M)
    assert [(f, False if d == "off" else float(d), doc) for f, d, doc in rows] == \
        [(o.flag, o.default, o.doc) for o in archive.OPTIONS]
    from wideprint.app.cli import build_parser
    serve = build_parser()._subparsers._group_actions[0].choices["serve"]
    flags = {s for a in serve._actions for s in a.option_strings}
    assert {o.flag for o in archive.OPTIONS} <= flags
    from wideprint.app.server.config import ServerConfig
    cfg = ServerConfig()
    assert all(getattr(cfg, o.name) == o.default for o in archive.OPTIONS)


def test_retention_keeps_the_newest_within_days_and_size(tmp_path):
    sp = Spool(tmp_path / "state")
    now = time.time()
    ids = []
    for i, (age_days, size) in enumerate([(40, 100), (10, 300), (5, 300), (1, 300)]):
        job, _ = sp.add_job(name=f"f{i}.tif", source="api", spool_path=f"/x/{i}", size=size,
                            sha256="0" * 64, settings={})
        sp.db.execute("UPDATE jobs SET state='done', finished=? WHERE id=?",
                      (now - age_days * 86400, job["id"]))
        ids.append(job["id"])
    # 30 days and 700 bytes: the 40-day-old goes (days), then the oldest over the size
    gone = sp.expire_archive(now - 30 * 86400, 700)
    assert sorted(gone) == ["/x/0", "/x/1"]
    assert [sp.get(i)["spool_path"] for i in ids] == [None, None, "/x/2", "/x/3"]
    assert sp.expire_archive(now - 30 * 86400, None) == []


@pytest.fixture
def shop(print_server, tmp_path):
    """A server whose `proof` preset holds its jobs (the presets file written first)."""
    state = tmp_path / "server" / "state"
    state.mkdir(parents=True)
    (state / "presets.json").write_text(json.dumps(
        {"default": {}, "proof": {"hold": True, "passes": 2}}))
    s = print_server(root=tmp_path / "server")
    c = Client(s.state_dir)
    yield s, c
    c.close()


def test_hold_by_preset_then_release_with_estimate_and_quote(shop, tmp_path):
    s, c = shop
    planes = random_planes(200, 160, seed=5)
    src = write_cmyk_tiff(tmp_path / "proof.tif", planes)
    assert c.presets()["held"] == ["proof"]
    job = c.submit(src, preset="proof")["job"]
    assert job["state"] == "held" and job["settings"] == {"passes": 2}
    time.sleep(1.0)
    assert c.job(job["id"])["state"] == "held"                      # the queue runs: it waits
    assert c.submit(src, preset="proof", hold=False)["job"]["state"] in ("queued", "printing",
                                                                        "done")
    c.prices({"ink_per_ml": {"c": 0.5, "m": 0.5, "y": 0.5, "k": 0.5},
              "media_per_m2": {"default": 10.0}, "machine_per_hour": 36.0})
    p = c.preview(job["id"])
    q, a = p["quote"], p["all_copies"]
    assert p["fit"]["fits"] and p["width_mm"] > 0 and a["ink_total_ml"] > 0
    assert q["total"] == pytest.approx(a["ink_total_ml"] * 0.5 + a["area_m2"] * 10.0 +
                                       a["time_s"] / 100.0, abs=2e-4)
    c.action(job["id"], "release")
    assert c.wait(job["id"], 60)["state"] == "done"
    assert np.array_equal(read_planes(s.root / "media" / f"job-{job['id']}.tif"), planes)


def test_a_done_job_is_reprinted_bit_exact_and_with_changed_settings(shop, tmp_path, capsys):
    s, c = shop
    planes = random_planes(240, 200, seed=11)
    src = write_cmyk_tiff(tmp_path / "poster.tif", planes)
    first = c.submit(src, settings={"passes": 4}, client="alice")["job"]
    assert c.wait(first["id"], 60)["state"] == "done"
    src.unlink()                                        # the original is gone: the archive has it
    again = c.reprint(first["id"])
    assert again["id"] != first["id"] and again["reprint_of"] == first["id"]
    assert (again["name"], again["settings"], again["client"], again["source"]) == \
        ("poster.tif", {"passes": 4}, "alice", "reprint")
    assert c.wait(again["id"], 60)["state"] == "done"
    media = s.root / "media"
    original = read_planes(media / f"job-{first['id']}.tif")
    assert np.array_equal(original, planes)
    assert np.array_equal(read_planes(media / f"job-{again['id']}.tif"), original)
    # changed settings and copies, from the CLI
    from wideprint.app.cli import main
    rc = main(["reprint", str(first["id"]), "--set", "passes=2", "--copies", "2", "--hold",
               "--state-dir", str(s.state_dir)])
    out = capsys.readouterr().out
    assert rc == 0, out
    new_id = int(re.search(r"reprinted as job (\d+)", out).group(1))
    changed = c.job(new_id)
    assert (changed["settings"], changed["copies"], changed["state"]) == ({"passes": 2}, 2, "held")
    c.action(new_id, "release")
    assert c.wait(new_id, 60)["state"] == "done"
    assert np.array_equal(read_planes(media / f"job-{new_id}.tif"), planes)
    assert [r["copy"] for r in c.report(new_id)] == [1, 2]
    # the original and its accounting are untouched
    assert [r["outcome"] for r in c.report(first["id"])] == ["done"]
    # refused: a waiting job (it prints as it is), a file no longer archived
    waiting = c.reprint(first["id"], hold=True)
    with pytest.raises(ApiError) as e:
        c.reprint(waiting["id"])
    assert e.value.status == 409 and "only a finished job is reprinted" in str(e.value)
    s.spool.db.execute("UPDATE jobs SET spool_path=NULL WHERE id=?", (first["id"],))
    with pytest.raises(ApiError) as e:
        c.reprint(first["id"])
    assert e.value.status == 410 and "poster.tif" in str(e.value)


def test_rip_and_hold_prints_the_kept_planes_bit_exact(shop, tmp_path, caplog):
    """Ripped ahead while held, a job's release prints its kept planes (not ripped again),
    bit-exact with the same job ripped at its release; an edit makes them stale; they go
    when the job ends (docs/server.md "RIP and hold")."""
    import logging
    caplog.set_level(logging.INFO, logger="wideprint.server")
    s, c = shop
    planes = random_planes(260, 300, seed=21)
    src = write_cmyk_tiff(tmp_path / "approved.tif", planes)
    plain = c.submit(src, hold=True, settings={"passes": 2})["job"]
    ahead = c.submit(src, rip_hold=True, settings={"passes": 2})["job"]
    assert ahead["state"] == "held" and ahead["rip_hold"] == 1
    ready = wait_for(lambda: (c.job(ahead["id"]).get("ripped") or {}).get("ready") and
                     c.job(ahead["id"])["ripped"], 60, what="the planes ripped ahead")
    assert ready["rip_s"] > 0 and ready["bytes"] > 0 and "path" not in ready
    kept = list((s.state_dir / "ripped").iterdir())
    assert len(kept) == 1 and np.array_equal(read_planes(kept[0]), planes)
    # a job marked later, then edited: its planes are made again for the new settings
    later = c.submit(src, hold=True)["job"]
    c.request("POST", f"/v1/jobs/{later['id']}/rip-hold")
    wait_for(lambda: (c.job(later["id"]).get("ripped") or {}).get("ready"), 60, what="ripped")

    def later_file():        # named by the job and the key of what it was ripped with
        return {p.name for p in (s.state_dir / "ripped").iterdir()
                if p.name.startswith(f"{later['id']}-")}
    first = later_file()
    assert len(first) == 1
    c.edit(later["id"], settings={"passes": 4})
    wait_for(lambda: len(list((s.state_dir / "ripped").iterdir())) == 2 and
             len(later_file()) == 1 and later_file() != first and
             c.job(later["id"])["ripped"]["ready"], 60, what="ripped again")
    for job in (plain, ahead, later):
        c.action(job["id"], "release")
        assert c.wait(job["id"], 60)["state"] == "done"
    used = [r.getMessage() for r in caplog.records if "printing its planes" in r.getMessage()]
    assert used == [f"job {ahead['id']}: printing its planes, ripped ahead",
                    f"job {later['id']}: printing its planes, ripped ahead"], used
    media = s.root / "media"
    for job in (plain, ahead, later):
        assert np.array_equal(read_planes(media / f"job-{job['id']}.tif"), planes)
    assert list((s.state_dir / "ripped").iterdir()) == []            # gone with the jobs
    with pytest.raises(ApiError) as e:
        c.request("POST", f"/v1/jobs/{ahead['id']}/rip-hold")
    assert e.value.status == 409 and "only a job not yet started" in str(e.value)


def test_archived_planes_are_reprinted_without_ripping_again(print_server, tmp_path, caplog):
    """--archive-planes: a done job ripped ahead keeps its planes with its file; its reprint
    with the same settings prints them (a hard link), bit-exact; with other settings it
    rips."""
    import logging
    caplog.set_level(logging.INFO, logger="wideprint.server")
    s = print_server(archive_planes=True)
    c = Client(s.state_dir)
    try:
        planes = random_planes(200, 240, seed=31)
        src = write_cmyk_tiff(tmp_path / "repeat.tif", planes)
        first = c.submit(src, rip_hold=True)["job"]
        wait_for(lambda: (c.job(first["id"]).get("ripped") or {}).get("ready"), 60, what="ripped")
        c.action(first["id"], "release")
        assert c.wait(first["id"], 60)["state"] == "done"
        s.expire_spool()                               # the archive keeps its planes
        kept = list((s.state_dir / "ripped").iterdir())
        assert len(kept) == 1
        same = c.reprint(first["id"])
        other = c.reprint(first["id"], settings={"passes": 2})
        assert same["ripped"]["ready"] and not other.get("ripped")
        for j in (same, other):
            assert c.wait(j["id"], 60)["state"] == "done"
            assert np.array_equal(read_planes(s.root / "media" / f"job-{j['id']}.tif"), planes)
        used = [r.getMessage() for r in caplog.records if "printing its planes" in r.getMessage()]
        assert used == [f"job {first['id']}: printing its planes, ripped ahead",
                        f"job {same['id']}: printing its planes, ripped ahead"], used
        # the reprint is archived with its planes too: a second name, not a second copy
        s.expire_spool()
        assert len(list((s.state_dir / "ripped").iterdir())) == 2
        assert kept[0].exists() and os.stat(kept[0]).st_nlink == 2
    finally:
        c.close()
