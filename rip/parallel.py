"""The RIP's worker threads: one small pool (as many workers as cores, at most 2 here)
shared by every compiled kernel.  Kernels are numba `nogil`, so they run truly in
parallel; the pool is made anew in a forked child, whose copy has no threads."""

from __future__ import annotations

import os
import threading
from concurrent.futures import ThreadPoolExecutor

WORKERS = max(1, min(2, os.cpu_count() or 1))
_POOL: ThreadPoolExecutor | None = None
_POOL_PID = -1
_LOCK = threading.Lock()


def pool() -> ThreadPoolExecutor:
    global _POOL, _POOL_PID
    with _LOCK:
        if _POOL is None or _POOL_PID != os.getpid():
            _POOL = ThreadPoolExecutor(max_workers=WORKERS, thread_name_prefix="wideprint-rip")
            _POOL_PID = os.getpid()
        return _POOL


def run_parallel(jobs) -> None:
    """Run callables on the pool (one alone runs here) and wait for all of them; the first
    exception is raised."""
    jobs = list(jobs)
    if len(jobs) == 1:
        jobs[0]()
        return
    futures = [pool().submit(job) for job in jobs]
    for f in futures:
        f.result()


def split(n: int, parts: int = WORKERS, minimum: int = 1) -> list[tuple[int, int]]:
    """[0, n) cut into at most `parts` contiguous ranges of at least `minimum` items."""
    parts = max(1, min(parts, n // max(1, minimum)))
    edges = [n * i // parts for i in range(parts + 1)]
    return [(a, b) for a, b in zip(edges, edges[1:]) if b > a]
