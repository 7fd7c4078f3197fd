"""Where the print server's RSS goes in the GUI soak, without the GUI (issue 34).

bench/gui_soak.py saw `wideprint serve` (two emulated printers, ~60 small CMYK jobs a minute)
grow 73 -> 282 MB in 2 minutes, then ~1.3 MB a minute.  This starts the same server in this
process (PrintServer, printers left/right on the in-process emulator, --keep-failed 0), feeds
it the way the soak's parent does (keep 3 jobs waiting per printer, copies 1-3, passes 1/2/4,
every 0.5 s) plus what the GUI asks (status, printers, previews of recent jobs, each on a
fresh HTTP connection, so the ThreadingHTTPServer makes a thread per request), and every
minute records:

- RSS (VmRSS), tracemalloc's traced total, and the top growth by traceback since the first
  sample after warm-up (`Snapshot.compare_to(..., "traceback")`);
- live sqlite3.Connection objects and live threads (spool.py keeps one connection per thread);
- glibc's view (mallinfo2: arena bytes, in use, free) and, at the end, RSS before and after
  `malloc_trim(0)`.

The process is set up as `wideprint serve` sets itself up (app/cli/process.py: mmap
threshold 4 MiB, two arenas, trim threshold 32 MiB) unless --raw-malloc; the server trims the
C heap once its printers are idle (app/server/heap.py) unless --no-job-trim.  --idle-after M stops
feeding after M minutes (the pollers go on): a rise that stops with the jobs is per job, not
per minute.

    python bench/server_rss.py --minutes 60 --frames 0 --idle-after 50 --out OUT.json
"""

from __future__ import annotations

import argparse
import ctypes
import gc
import http.client
import json
import os
import random
import sqlite3
import sys
import tempfile
import threading
import time
import tracemalloc
from pathlib import Path

sys.path.insert(0, str(Path(__file__).resolve().parent))
from gui_soak import feed, make_images, rss_mb  # noqa: E402

_libc = ctypes.CDLL("libc.so.6")


class _Mallinfo2(ctypes.Structure):
    _fields_ = [(n, ctypes.c_size_t) for n in (
        "arena", "ordblks", "smblks", "hblks", "hblkhd", "usmblks", "fsmblks",
        "uordblks", "fordblks", "keepcost")]


def mallinfo() -> dict:
    """glibc's heap: arena (bytes from sbrk/mmap'd arenas), in use, free inside them, mmapped."""
    try:
        f = _libc.mallinfo2
    except AttributeError:
        return {}
    f.restype = _Mallinfo2
    m = f()
    mb = 1 / 2**20
    return dict(arena_mb=round(m.arena * mb, 1), in_use_mb=round(m.uordblks * mb, 1),
                free_mb=round(m.fordblks * mb, 1), mmapped_mb=round(m.hblkhd * mb, 1))


def get(port: int, token: str, path: str) -> bytes:
    """One GET on a fresh connection (as the GUI's pollers and image loaders do)."""
    c = http.client.HTTPConnection("127.0.0.1", port, timeout=30)
    c.request("GET", path, headers={"Authorization": f"Bearer {token}"})
    data = c.getresponse().read()
    c.close()
    return data


def run(minutes: float, out: Path | None, frames: int, trim_each: bool = False,
        shipped: bool = True, job_trim: bool = True, idle_after: float | None = None) -> dict:
    sys.path.insert(0, str(Path(__file__).resolve().parents[1]))
    from tests.support.server import inprocess_server

    from wideprint.app.server import heap
    if shipped:                              # as `wideprint serve` sets up its process
        from wideprint.app.cli.process import _give_back_big_buffers
        _give_back_big_buffers()
        if job_trim:
            heap.enable()

    from wideprint.app.client import Client
    from wideprint.app.server.config import PrinterConfig
    root = Path(tempfile.mkdtemp(prefix="server-rss-"))
    images = make_images(root)
    srv = inprocess_server(root, keep_failed_s=0,
                           printers=[PrinterConfig("left", "emulator"),
                                     PrinterConfig("right", "emulator")])
    feeder = Client(root / "state", url=f"http://127.0.0.1:{srv.port}")
    rng = random.Random(7)
    submitted, errors = 0, 0
    samples: list[dict] = []
    base = None
    t0 = time.monotonic()
    next_sample = t0
    recent: list[int] = []

    def sample(label: str) -> dict:
        nonlocal base
        gc.collect()
        if frames and not tracemalloc.is_tracing() and time.monotonic() - t0 >= 50:
            tracemalloc.start(frames)        # not from the start: numba's JIT and the first
            #                                  jobs under tracing would take minutes
        snap = tracemalloc.take_snapshot().filter_traces(
            [tracemalloc.Filter(False, tracemalloc.__file__)]) if tracemalloc.is_tracing() else None
        cur, _ = tracemalloc.get_traced_memory()
        conns = sum(1 for o in gc.get_objects() if type(o) is sqlite3.Connection)
        if idle_after is not None and time.monotonic() - t0 >= idle_after * 60:
            label = "idle"
        s = dict(t=round(time.monotonic() - t0, 1), label=label, rss_mb=rss_mb(),
                 traced_mb=round(cur / 2**20, 2),
                 tracemalloc_own_mb=round(tracemalloc.get_tracemalloc_memory() / 2**20, 2),
                 sqlite_connections=conns,
                 threads=threading.active_count(), submitted=submitted, errors=errors,
                 **mallinfo())
        if trim_each:                        # is the rise returned to the system?
            _libc.malloc_trim(0)
            s["rss_after_trim_mb"] = rss_mb()
        if snap is None:
            pass
        elif base is None and s["t"] >= 110:     # after the warm-up the soak saw (73 -> 282 MB)
            base = snap
        elif base is not None:
            top = snap.compare_to(base, "traceback")[:8]
            s["top_growth"] = [dict(kb=round(d.size_diff / 1024, 1), count=d.count_diff,
                                    at=[f"{f.filename.split('wideprint/')[-1]}:{f.lineno}"
                                        for f in list(d.traceback)[-4:]]) for d in top]
        samples.append(s)
        print(json.dumps({k: v for k, v in s.items() if k != "top_growth"}), flush=True)
        return s

    try:
        while time.monotonic() - t0 < minutes * 60:
            feeding = idle_after is None or time.monotonic() - t0 < idle_after * 60
            try:
                for j in (feed(feeder, images, rng) if feeding else ()):
                    submitted += 1
                    jid = j.get("id") or j.get("job", {}).get("id")
                    if jid:
                        recent = (recent + [jid])[-6:]
                # the GUI's pollers: status, printers, the recent jobs' previews
                get(srv.port, srv.token, "/v1/status")
                get(srv.port, srv.token, "/v1/printers")
                for jid in recent[-2:]:
                    get(srv.port, srv.token, f"/v1/jobs/{jid}/preview.png?px=256")
            except Exception as exc:  # noqa: BLE001 - keep feeding; count it
                errors += 1
                print(f"feeder: {exc}", file=sys.stderr)
            if time.monotonic() >= next_sample:
                sample("run")
                next_sample += 60
            time.sleep(0.5)
        end = sample("end")
        before = rss_mb()
        _libc.malloc_trim(0)
        trimmed = dict(rss_before_mb=before, rss_after_mb=rss_mb(), **mallinfo())
        done = {}
        for j in feeder.request("GET", "/v1/jobs?state=done,failed,cancelled&limit=100000")["jobs"]:
            done[j["state"]] = done.get(j["state"], 0) + 1
    finally:
        feeder.close()
        srv.stop(timeout=10)
    runs = [s for s in samples if s["t"] >= 120]
    span = (runs[-1]["t"] - runs[0]["t"]) / 60 if len(runs) > 1 else None
    res = dict(minutes=minutes, shipped_process=shipped, job_trim=job_trim,
               idle_after=idle_after, malloc_env={k: v for k, v in os.environ.items()
                                            if k.startswith("MALLOC_")},
               tracemalloc_frames=frames, trim_each=trim_each, submitted=submitted, jobs=done, errors=errors,
               growth_after_2min=dict(
                   minutes=span,
                   rss_mb=round(runs[-1]["rss_mb"] - runs[0]["rss_mb"], 1) if span else None,
                   traced_mb=round(runs[-1]["traced_mb"] - runs[0]["traced_mb"], 2) if span else None,
                   rss_mb_per_min=round((runs[-1]["rss_mb"] - runs[0]["rss_mb"]) / span, 2) if span else None,
                   traced_mb_per_min=round((runs[-1]["traced_mb"] - runs[0]["traced_mb"]) / span, 3) if span else None),
               malloc_trim_at_end=trimmed, final_top_growth=end.get("top_growth"),
               samples=samples)
    if out is not None:
        out.parent.mkdir(parents=True, exist_ok=True)
        out.write_text(json.dumps(res, indent=1) + "\n")
    return res


def main(argv=None) -> int:
    ap = argparse.ArgumentParser(description=__doc__.split("\n")[0])
    ap.add_argument("--minutes", type=float, default=12.0)
    ap.add_argument("--frames", type=int, default=8,
                    help="tracemalloc traceback depth (0: no tracemalloc)")
    ap.add_argument("--trim-each", action="store_true", help="malloc_trim(0) after each sample")
    ap.add_argument("--raw-malloc", action="store_true",
                    help="glibc's defaults, not `wideprint serve`'s process settings")
    ap.add_argument("--no-job-trim", action="store_true",
                    help="the server does not trim the C heap when idle")
    ap.add_argument("--idle-after", type=float, help="stop feeding after this many minutes")
    ap.add_argument("--out", type=Path)
    a = ap.parse_args(argv)
    res = run(a.minutes, a.out, a.frames, a.trim_each, shipped=not a.raw_malloc,
              job_trim=not a.no_job_trim, idle_after=a.idle_after)
    print(json.dumps({k: v for k, v in res.items() if k != "samples"}, indent=1))
    return 0


if __name__ == "__main__":
    sys.exit(main())
