"""A print server runs for days: what its in-process emulators keep is bounded
(app/server/worker.py EMULATOR_EVENTS_KEPT; the 30-minute GUI soak's RSS grew with each
emulated printer's event deque of 200,000 records, ~350 B each)."""

import time

import numpy as np
import tifffile

from wideprint.app.client import Client
from wideprint.app.server.worker import EMULATOR_EVENTS_KEPT



def one_job_printed(tmp_path):
    """An in-process server that has printed one small CMYK job: (server, client)."""
    from wideprint.app.server import PrintServer, ServerConfig
    srv = PrintServer(ServerConfig(state_dir=tmp_path / "state", media_dir=tmp_path / "m",
                                   port=0))
    srv.start()
    client = Client(srv.state_dir)
    try:
        src = tmp_path / "a.tif"
        tifffile.imwrite(src, np.full((40, 80, 4), 90, np.uint8), photometric="separated")
        job = client.submit(src, settings={"placement": {"size": "pixels"}})["job"]
        assert client.wait(job["id"], 120)["state"] == "done"
    except BaseException:
        client.close()
        srv.stop(timeout=5)
        raise
    return srv, client


def test_a_server_emulator_keeps_a_bounded_event_log(tmp_path):
    srv, client = one_job_printed(tmp_path)
    try:
        emulators = [w.dev.emulator for w in srv.workers.values() if w.dev is not None]
        assert emulators and all(e.events.maxlen == EMULATOR_EVENTS_KEPT for e in emulators)
        assert EMULATOR_EVENTS_KEPT <= 20_000
        assert any(e["event"] == "job_end" for e in emulators[0].events)   # still a log
    finally:
        client.close()
        srv.stop(timeout=5)


# what a fragmented C heap looks like to a server: 1 kB blocks (above pymalloc's 512 B, so
# glibc's), one kept in every 16 (one page in four still used), the rest freed; then the
# worker's trim once idle after a job (app/server/heap.py).  In a fresh process: pytest's own heap
# would blur the figure.
_FRAGMENT = """
import sys, time
from wideprint.app.server import heap
def rss():
    with open("/proc/self/statm") as f:
        return int(f.read().split()[1]) * 4096 / 2**20
blocks = [bytes(1000) + bytes([i % 256]) for i in range(200_000)]
kept = blocks[::16]
del blocks
before = rss()
heap.enable()                       # as `wideprint serve` does in its own process
heap.IDLE_S = 0.0
heap.job_ended()
first = heap.give_back_when_idle()
after = rss()
again = heap.give_back_when_idle()  # no job ended since: not again
print(before, after, first, again, len(kept))
"""


def test_the_worker_gives_the_free_c_heap_back_once_idle():
    import subprocess
    import sys
    out = subprocess.run([sys.executable, "-c", _FRAGMENT], capture_output=True, text=True,
                         timeout=60, check=True).stdout.split()
    before, after = float(out[0]), float(out[1])
    assert out[2:4] == ["True", "False"]
    # ~190 MB allocated, 15/16 freed but held by the allocator among the kept blocks
    assert before - after > 60, (before, after)


def test_an_idle_worker_trims_after_its_jobs(tmp_path, monkeypatch):
    from wideprint.app.server import heap
    trims: list[float] = []
    monkeypatch.setattr(heap, "_trim", lambda pad: trims.append(time.monotonic()))
    monkeypatch.setattr(heap, "IDLE_S", 0.2)
    monkeypatch.setattr(heap, "_ended", None)      # no earlier test's job pending
    monkeypatch.setattr(heap, "_enabled", True)    # as in `wideprint serve`'s own process
    srv, client = one_job_printed(tmp_path)
    try:
        ended = time.monotonic()
        deadline = ended + 10
        while not [t for t in trims if t >= ended - 5] and time.monotonic() < deadline:
            time.sleep(0.05)
        assert trims, "no malloc_trim once the printers were idle after the job"
        n = len(trims)
        time.sleep(1.5)                    # idle on: nothing more ended, nothing more to trim
        assert len(trims) == n
    finally:
        client.close()
        srv.stop(timeout=5)


def test_wideprint_serve_trims_its_own_heap_once_idle(tmp_path):
    """`wideprint serve` is its own process: it enables the trim (app/cli/__init__.py), and a
    server embedded in another process (the test above without enable) does not."""
    from support.server import ServerProcess, wait_for
    srv = ServerProcess(tmp_path / "state", "--verbose-server", log=tmp_path / "serve.log")
    try:
        src = tmp_path / "a.tif"
        tifffile.imwrite(src, np.full((40, 80, 4), 90, np.uint8), photometric="separated")
        job = srv.client.submit(src, settings={"placement": {"size": "pixels"}})["job"]
        assert srv.client.wait(job["id"], 120)["state"] == "done"
        wait_for(lambda: "free pages given back" in srv.log.read_text(errors="replace"), 20,
                 what="the idle trim in the server's log")
    finally:
        srv.stop()


def test_an_embedded_server_leaves_its_host_heap_alone(monkeypatch):
    from wideprint.app.server import heap
    trims: list[int] = []
    monkeypatch.setattr(heap, "_trim", lambda pad: trims.append(pad))
    monkeypatch.setattr(heap, "_enabled", False)
    monkeypatch.setattr(heap, "IDLE_S", 0.0)
    heap.job_ended()
    assert heap.give_back_when_idle() is False and trims == []
