"""Hot folders under attack (docs/server.md, "Hot folders: the rules"): symbolic links
anywhere below the root — a preset folder, done/, failed/, a file — are never followed,
so nothing outside the root is read, moved or created; names that cannot be named go to
failed/ once, under a safe name; no spool copy is ever left without a job; a file written
in chunks by a writer that closes it between them is one job, made when it is complete;
hard links are refused."""

import logging
import os
import threading
import time

import numpy as np
import pytest

from support.images import random_planes, tiny_tiff, write_cmyk_tiff
from support.server import inprocess_server, wait_for
from wideprint.app.client import Client
from wideprint.rip.planes import read_planes

SCAN = 0.1
SETTLE = 0.8


@pytest.fixture
def hot(tmp_path, caplog):
    caplog.set_level(logging.DEBUG, logger="wideprint")
    server = inprocess_server(tmp_path, scan_interval=SCAN, settle_s=SETTLE,
                              max_file_bytes=2_000_000)
    server.outside = tmp_path / "outside"
    server.outside.mkdir()
    server.client = Client(server.state_dir)
    try:
        yield server
    finally:
        server.client.close()
        server.stop(timeout=5)
    assert "Traceback" not in caplog.text, caplog.text
    assert not [r for r in caplog.records if r.exc_info], caplog.text


def snapshot(folder):
    """Every entry below `folder` (links not followed) with its type, size, mtime, inode
    and link count: equal snapshots mean nothing was created, moved or written there."""
    out = {}
    for dirpath, dirnames, filenames in os.walk(folder, followlinks=False):
        for n in dirnames + filenames:
            p = os.path.join(dirpath, n)
            st = os.lstat(p)
            out[os.path.relpath(p, folder)] = (st.st_mode, st.st_size, st.st_mtime_ns, st.st_ino,
                                              st.st_nlink)
    return out


def scans(n=1):
    time.sleep(SETTLE + SCAN * (n + 3))


def jobs(server):
    return server.client.request("GET", "/v1/jobs")["jobs"]


def spool_orphans(server, settle: float = 5.0):
    """Files in spool/ that no job owns, once the worker had `settle` seconds to delete
    them: a job's original is moved before its end commits, and its spool copy deleted
    after (docs/server.md "Crash recovery"), so a test that saw the original move may look
    a moment before the copy goes."""
    deadline = time.monotonic() + settle
    while True:
        used = server.spool.spool_files_in_use()
        out = sorted(str(p) for p in server.spool.spool_dir.iterdir() if str(p) not in used)
        if not out or time.monotonic() > deadline:
            return out
        time.sleep(0.05)


def wait_idle(server, timeout=60):
    wait_for(lambda: all(j["state"] in ("done", "failed", "cancelled") for j in jobs(server)),
             timeout, what="every job ended")


# -- symbolic links ------------------------------------------------------------------------------
def test_preset_folder_replaced_by_a_symlink_is_not_entered(hot, caplog):
    outside = hot.outside
    (outside / "secret.tif").write_bytes(tiny_tiff())
    (outside / "notes.txt").write_text("not an image\n")
    folder = hot.root / "hot" / "photo"
    with hot.hot.lock:                    # between two scans (the scanner remakes the folder)
        for sub in ("done", "failed"):
            os.rmdir(folder / sub)
        os.rmdir(folder)
        os.symlink(outside, folder)
    before = snapshot(outside)
    scans(3)
    assert snapshot(outside) == before                  # nothing read into a job, moved, made
    assert not [j for j in jobs(hot) if j["name"] in ("secret.tif", "notes.txt")]
    warnings = [r.getMessage() for r in caplog.records if "photo" in r.getMessage()
                and "not scanned" in r.getMessage()]
    assert len(warnings) == 1, warnings                 # said once, not every scan
    assert "symbolic link" in warnings[0]
    # the link removed, the next scan makes the folder again and works in it
    os.unlink(folder)
    wait_for(lambda: (folder / "done").is_dir() and not (folder / "done").is_symlink(), 5,
             what="photo/done made again")
    (folder / "p.tif").write_bytes(tiny_tiff())
    wait_for(lambda: (folder / "done" / "p.tif").exists(), 30, what="photo/done/p.tif")
    assert snapshot(outside) == before
    assert spool_orphans(hot) == []


@pytest.mark.parametrize("sub,data,final", [("done", "good", "done"), ("failed", "bad", "failed")])
def test_done_or_failed_replaced_by_a_symlink_moves_nothing_outside(hot, sub, data, final):
    outside = hot.outside
    (outside / "keep.tif").write_bytes(tiny_tiff())
    before = snapshot(outside)
    folder = hot.root / "hot" / "banner"
    with hot.hot.lock:                    # between two scans (the scanner remakes the folder)
        os.rmdir(folder / sub)
        os.symlink(outside, folder / sub)
    # found by the scanner: the link is moved into failed/ (as a link), a real folder made
    wait_for(lambda: (folder / sub).is_dir() and not (folder / sub).is_symlink(), 5,
             what=f"a real {sub}/")
    links = [p for p in (folder / "failed").iterdir() if p.is_symlink()]
    assert [p.name for p in links] == [sub] and os.readlink(links[0]) == str(outside)
    assert "not a folder" in (folder / "failed" / f"{sub}.reason.txt").read_text()
    body = tiny_tiff() if data == "good" else b"II*\x00" + b"\xff" * 100
    (folder / "x.tif").write_bytes(body)
    wait_for(lambda: (folder / final / "x.tif").exists(), 30, what=f"{final}/x.tif")
    assert snapshot(outside) == before
    assert not (folder / "x.tif").exists()
    assert spool_orphans(hot) == []


def test_done_replaced_by_a_symlink_while_the_job_prints(hot):
    """The race: done/ and failed/ become links after the scan and before the job ends —
    the move at the end of the job does not follow them either."""
    outside = hot.outside
    folder = hot.root / "hot" / "photo"
    hot.client.pause_queue(True)
    (folder / "a.tif").write_bytes(tiny_tiff())
    (folder / "b.tif").write_bytes(b"II*\x00" + b"\xff" * 100)
    wait_for(lambda: len([j for j in jobs(hot) if j["name"] in ("a.tif", "b.tif")]) == 2, 10,
             what="two hot-folder jobs")
    hot.hot.stopping.set()                       # the scanner stops: only the job end moves
    hot.hot.join(5)
    before = snapshot(outside)
    for sub in ("done", "failed"):
        os.rmdir(folder / sub)
        os.symlink(outside, folder / sub)
    hot.client.pause_queue(False)
    wait_idle(hot)
    assert snapshot(outside) == before
    assert (folder / "done" / "a.tif").is_file() and not (folder / "done").is_symlink()
    assert (folder / "failed" / "b.tif").is_file() and not (folder / "failed").is_symlink()
    assert "failed" in (folder / "failed" / "b.tif.reason.txt").read_text()
    # both links are kept, as links, in failed/ with their reason
    kept = sorted(p.name for p in (folder / "failed").iterdir() if p.is_symlink())
    assert kept == ["done", "failed"]
    assert spool_orphans(hot) == []


def test_symlinked_files_are_refused_never_followed(hot):
    outside = hot.outside
    (outside / "secret.tif").write_bytes(tiny_tiff())
    folder = hot.root / "hot" / "default"
    (folder / "sub").mkdir()
    (folder / "sub" / "inside.tif").write_bytes(tiny_tiff())
    before = snapshot(outside)
    os.symlink(outside / "secret.tif", folder / "abs.tif")
    os.symlink("../../../outside/secret.tif", folder / "rel.tif")
    os.symlink("sub/inside.tif", folder / "in.tif")
    os.symlink("/nonexistent/x.tif", folder / "dangling.tif")
    os.symlink(outside, folder / "dirlink.tif")
    names = ("abs.tif", "rel.tif", "in.tif", "dangling.tif", "dirlink.tif")
    for n in names:
        # the reason is written first, then the link moved (hotfolders.py _rename_into)
        wait_for(lambda: (folder / "failed" / n).is_symlink(), 10, what=n)   # the link itself
        assert (folder / "failed" / f"{n}.reason.txt").exists()
        assert "never followed" in (folder / "failed" / f"{n}.reason.txt").read_text()
    assert "outside the hot folder" in (folder / "failed" / "abs.tif.reason.txt").read_text()
    assert "outside the hot folder" in (folder / "failed" / "rel.tif.reason.txt").read_text()
    assert "outside" not in (folder / "failed" / "in.tif.reason.txt").read_text()
    scans(2)
    assert snapshot(outside) == before
    assert (folder / "sub" / "inside.tif").is_file()              # a folder is left alone
    assert not [j for j in jobs(hot) if j["name"] in names + ("inside.tif",)]
    assert spool_orphans(hot) == []


def test_hard_links_are_refused(hot):
    outside = hot.outside
    (outside / "other.tif").write_bytes(tiny_tiff())
    folder = hot.root / "hot" / "default"
    os.link(outside / "other.tif", folder / "hl.tif")
    reason = folder / "failed" / "hl.tif.reason.txt"
    wait_for(reason.exists, 10, what=reason.name)
    assert "hard links" in reason.read_text()
    assert not [j for j in jobs(hot) if j["name"] == "hl.tif"]
    assert (outside / "other.tif").read_bytes() == tiny_tiff()


# -- names ---------------------------------------------------------------------------------------
def test_names_that_cannot_be_named_go_to_failed_once(hot, caplog):
    folder = hot.root / "hot" / "photo"
    bfolder = os.fsencode(folder)
    odd = {b"caf\xe9.tif": "caf%E9.tif",                 # Latin-1, not UTF-8
           b"\xff\xfe.jpg": "%FF%FE.jpg",
           b"a\nb.tif": "a%0Ab.tif",                     # UTF-8, but a control character
           b"x\x1b[31m.tif": "x%1B[31m.tif"}
    for raw in odd:
        with open(os.path.join(bfolder, raw), "wb") as f:
            f.write(tiny_tiff())
    for raw, safe in odd.items():
        wait_for(lambda: (folder / "failed" / safe).exists(), 10, what=safe)
        assert (folder / "failed" / safe).read_bytes() == tiny_tiff()
        reason = (folder / "failed" / f"{safe}.reason.txt").read_text()
        assert ("not valid UTF-8" in reason) == (b"\xe9" in raw or b"\xff" in raw), reason
    scans(3)
    assert sorted(os.listdir(bfolder)) == [b"done", b"failed"]
    assert len(os.listdir(folder / "failed")) == 2 * len(odd)     # each once, with its reason
    assert not [j for j in jobs(hot) if j["source"] == "hot:photo"]
    assert spool_orphans(hot) == [] and list(hot.spool.spool_dir.iterdir()) == []
    # one warning per file, not one per scan, and no name reaches the log raw
    refused = [r.getMessage() for r in caplog.records if "hot folder photo" in r.getMessage()]
    assert len(refused) == len(odd), refused
    assert not any("\n" in m or "\x1b" in m for m in refused)


def test_a_stuck_refusal_is_not_retried_every_scan(hot, caplog):
    """A refused file that cannot be moved (failed/ unwritable) is logged once and left
    until it changes; no spool copy is made of it."""
    if os.geteuid() == 0:
        pytest.skip("root writes into a read-only folder")
    folder = hot.root / "hot" / "banner"
    os.chmod(folder / "failed", 0o500)
    try:
        with open(os.path.join(os.fsencode(folder), b"bad\xe9.tif"), "wb") as f:
            f.write(b"x")
        scans(4)
        msgs = [r.getMessage() for r in caplog.records if "bad" in r.getMessage()]
        assert 1 <= len(msgs) <= 2, msgs
    finally:
        os.chmod(folder / "failed", 0o700)
    assert list(hot.spool.spool_dir.iterdir()) == []


# -- complete files ------------------------------------------------------------------------------
def chunked_writer(path, data, chunks, gap, errors):
    """scp/SMB-like: open, write a chunk, close, wait, open again to append, ..."""
    try:
        step = len(data) // chunks + 1
        for i in range(0, len(data), step):
            with open(path, "ab") as f:
                f.write(data[i:i + step])
            time.sleep(gap)
    except Exception as exc:  # noqa: BLE001
        errors.append(exc)


def test_writer_closing_between_chunks_gives_one_job(hot, tmp_path):
    planes = [random_planes(50, 120, seed=s) for s in (31, 32)]
    datas = [write_cmyk_tiff(tmp_path / f"c{i}.tif", p).read_bytes() for i, p in enumerate(planes)]
    folder = hot.root / "hot" / "photo"
    errors = []
    # gaps of 4 scans, shorter than the settle time: the old rule took the first chunk
    writers = [threading.Thread(target=chunked_writer,
                                args=(folder / f"chunked{i}.tif", d, 5, SETTLE * 0.5, errors))
               for i, d in enumerate(datas)]
    for w in writers:
        w.start()
    for w in writers:
        w.join(30)
    assert not errors and not any(w.is_alive() for w in writers)
    for i, p in enumerate(planes):
        name = f"chunked{i}.tif"
        wait_for(lambda: (folder / "done" / name).exists(), 60, what=f"done/{name}")
        mine = [j for j in jobs(hot) if j["name"] == name]
        assert len(mine) == 1, mine                          # exactly one job per file
        mine[0] = hot.client.wait(mine[0]["id"], 60)
        assert mine[0]["state"] == "done" and mine[0]["size"] == len(datas[i])
        assert np.array_equal(read_planes(hot.root / "media" / f"job-{mine[0]['id']}.tif"), p)
    assert not os.listdir(folder / "failed")
    scans(2)
    assert len([j for j in jobs(hot) if j["name"].startswith("chunked")]) == 2
    assert spool_orphans(hot) == []


def test_many_files_one_job_each_and_no_orphan_copies(hot):
    folder = hot.root / "hot" / "default"
    hot.client.pause_queue(True)
    names = [f"m{i:02d}.tif" for i in range(12)]
    for n in names:
        (folder / n).write_bytes(tiny_tiff())
    (folder / "empty.tif").write_bytes(b"")
    wait_for(lambda: len([j for j in jobs(hot) if j["name"] in names]) == len(names), 20,
             what="twelve jobs")
    scans(3)                                           # the files are still there: no second job
    mine = [j for j in jobs(hot) if j["name"] in names]
    assert sorted(j["name"] for j in mine) == names
    assert spool_orphans(hot) == []
    assert len(list(hot.spool.spool_dir.iterdir())) == len(names)
    assert "empty" in (folder / "failed" / "empty.tif.reason.txt").read_text()
    hot.client.pause_queue(False)
    wait_idle(hot)
    wait_for(lambda: sorted(os.listdir(folder / "done")) == names, 10, what="all in done/")
    # no orphan: the copies left are the done jobs' own, archived for reprints
    assert spool_orphans(hot) == [] and len(list(hot.spool.spool_dir.iterdir())) == len(names)


def test_file_replaced_while_its_job_waits_is_a_new_job(hot):
    folder = hot.root / "hot" / "default"
    hot.client.pause_queue(True)
    (folder / "r.tif").write_bytes(tiny_tiff())
    first = wait_for(lambda: [j for j in jobs(hot) if j["name"] == "r.tif"], 10, what="r.tif job")[0]
    os.unlink(folder / "r.tif")
    (folder / "r.tif").write_bytes(tiny_tiff())          # another file, same name
    hot.client.action(first["id"], "cancel")
    # the new file was not the cancelled job's: it is left, and becomes a job of its own
    second = wait_for(lambda: [j for j in jobs(hot) if j["name"] == "r.tif"
                               and j["id"] != first["id"]], 10, what="the second r.tif job")[0]
    assert not (folder / "failed" / "r.tif").exists()
    hot.client.pause_queue(False)
    assert hot.client.wait(second["id"], 60)["state"] == "done"
    wait_for(lambda: (folder / "done" / "r.tif").exists(), 10, what="done/r.tif")
