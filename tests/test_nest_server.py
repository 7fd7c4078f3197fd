"""The print server nests jobs (docs/server.md, "Nesting jobs"): queued jobs asking to nest
with the same settings go side by side on one sheet once the nest's start rule holds (a
count, a length, or a time limit); the sheet prints bit-exact as the RIP lays it out, and
every job of it ends with it."""

import time

import numpy as np
import pytest

from support.images import random_planes, write_cmyk_tiff
import wideprint.rip.layout  # noqa: F401 - imported here, before the server's threads do
from wideprint.app.client import ApiError, Client
from wideprint.rip.pipeline import RipJob
from wideprint.rip.planes import read_planes


@pytest.fixture
def server(tmp_path):
    from wideprint.app.server import PrintServer, ServerConfig
    srv = PrintServer(ServerConfig(state_dir=tmp_path / "state", media_dir=tmp_path / "media",
                                   port=0, start_paused=True))
    srv.start()
    client = Client(srv.state_dir)
    yield srv, client, tmp_path
    client.close()
    srv.stop(timeout=5)


def files(tmp_path, n):
    out = []
    for i in range(n):
        planes = random_planes(120 + 30 * i, 200 + 40 * i, seed=40 + i)
        out.append(write_cmyk_tiff(tmp_path / f"n{i}.tif", planes))
    return out


NEST = {"placement": {"size": "pixels", "nest": True, "nest_count": 3, "gap_mm": 4}}


def sheet_planes(srv, job_ids, settings, tmp_path):
    """What the RIP lays out for these jobs' spooled files, as one nested sheet."""
    from wideprint.rip.settings import from_mapping
    paths = [srv.spool.get(i)["spool_path"] for i in job_ids]
    rip = RipJob(paths[0], from_mapping(settings), srv.profile, more=tuple(paths[1:]))
    out = tmp_path / "sheet.tif"
    rip.write_planes(out)
    rip.close()
    return read_planes(out), rip.width, rip.height


def test_a_count_rule_nests_three_jobs_on_one_sheet_bit_exact(server):
    srv, client, tmp = server
    fs = files(tmp, 4)
    ids = [client.submit(f, settings=NEST)["job"]["id"] for f in fs[:2]]
    client.pause_queue(False)
    time.sleep(1.5)                   # two of three: the count rule waits
    assert [client.job(i)["state"] for i in ids] == ["queued", "queued"]
    ids.append(client.submit(fs[2], settings=NEST)["job"]["id"])
    planes, w, h = sheet_planes(srv, ids, NEST, tmp)   # (the spool copies go when printed)
    done = client.wait(ids[0], 120)
    assert done["state"] == "done", done
    for i in ids[1:]:
        j = client.job(i)
        assert j["state"] == "done" and j["nested_in"] == ids[0], j
        assert "nested sheet" in j["message"]
    media = read_planes(tmp / "media" / f"job-{ids[0]}.tif")
    assert media.shape[:2] == (h, w) and np.array_equal(media, planes)
    assert len(client.report(ids[0])) == 1          # one sheet printed, accounted once
    assert "layout nest: 3 items" in done["message"] and "mm of media saved" in done["message"]
    # a job with other settings is not nested with them
    other = client.submit(fs[3], settings={"placement": {"size": "pixels"}})["job"]["id"]
    assert client.wait(other, 60)["state"] == "done"
    assert client.job(other)["nested_in"] is None


def test_a_time_limit_starts_a_nest_with_what_there_is(server):
    srv, client, tmp = server
    fs = files(tmp, 2)
    s = {"placement": {"size": "pixels", "nest": True, "nest_count": 10, "nest_wait_s": 1.0}}
    ids = [client.submit(f, settings=s)["job"]["id"] for f in fs]
    planes, w, h = sheet_planes(srv, ids, s, tmp)
    t0 = time.monotonic()
    client.pause_queue(False)
    done = client.wait(ids[0], 120)
    assert done["state"] == "done" and client.job(ids[1])["nested_in"] == ids[0]
    assert np.array_equal(read_planes(tmp / "media" / f"job-{ids[0]}.tif"), planes)
    assert time.monotonic() - t0 >= 0.5


def test_a_nest_member_is_acted_on_through_its_sheet(server):
    srv, client, tmp = server
    fs = files(tmp, 2)
    s = {"placement": {"size": "pixels", "nest": True, "nest_count": 2}}
    ids = [client.submit(f, settings=s)["job"]["id"] for f in fs]
    assert srv.spool.nest(ids[0], [ids[1]])
    with pytest.raises(ApiError) as e:
        client.action(ids[1], "cancel")
    assert e.value.status == 409 and f"job {ids[0]}" in str(e.value)
    client.action(ids[0], "cancel")                 # not started: its sheet's jobs with it
    assert [client.job(i)["state"] for i in ids] == ["cancelled", "cancelled"]
    client.action(ids[1], "requeue")                # a requeued member prints alone
    client.pause_queue(False)
    s2 = client.job(ids[1])
    assert s2["nested_in"] is None and s2["state"] == "queued"


def test_labels_name_the_jobs_not_their_spooled_copies(server):
    """A print server's files are spooled under names of their own: a labelled sheet still
    shows each job's file name (RipJob names=, docs/layout.md)."""
    srv, client, tmp = server
    fs = files(tmp, 2)
    s = {"placement": {"size": "pixels", "nest": True, "label": True}}
    ids = [client.submit(f, name=f"poster-{i}.tif", settings=s)["job"]["id"] for i, f in enumerate(fs)]
    jobs = [srv.spool.get(i) for i in ids]
    from wideprint.rip.settings import from_mapping
    rip = RipJob(jobs[0]["spool_path"], from_mapping(s), srv.profile,
                 more=(jobs[1]["spool_path"],), names=("poster-0.tif", "poster-1.tif"))
    labels = sorted(sl.label for sl in rip.layout.plan.slots)
    rip.close()
    assert [lb.split()[0] for lb in labels] == ["poster-0.tif", "poster-1.tif"]
    assert all(jobs[0]["spool_path"].rsplit("/", 1)[1] not in lb for lb in labels)
