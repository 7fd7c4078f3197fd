"""The RIP's worker threads: small pools (as many workers as cores, at most 2 here) shared
by every compiled kernel.  Kernels are numba `nogil`, so they run truly in parallel; the
pools are made anew in a forked child, whose copy has no threads.

Two ways to use both cores (docs/rip.md "Threads"):
- `run_parallel`: one band's work split across the workers and waited for (the
  halftoner's planes, whose error rows pass from band to band);
- `ordered`: whole bands side by side, results in order, for stages whose bands are
  independent (separation, ordered screening).  No barrier per band: a split band waits
  for its slower half, and a half is slow whenever the driver, reader or writer threads
  hold a core - in a whole `rip -o` the two screening workers were each busy only ~50 %.
"""

from __future__ import annotations

import collections
import os
import threading
from concurrent.futures import ThreadPoolExecutor
from typing import Callable, Iterator, TypeVar

T = TypeVar("T")

WORKERS = max(1, min(2, os.cpu_count() or 1))
_POOLS: dict[str, tuple[ThreadPoolExecutor, int]] = {}
_LOCK = threading.Lock()
_HERE = threading.local()          # .inline: this thread runs a whole band; no splitting


def _band_worker() -> None:
    _HERE.inline = True


def _pool(name: str, initializer=None, workers: int = WORKERS) -> ThreadPoolExecutor:
    with _LOCK:
        pool, pid = _POOLS.get(name, (None, -1))
        if pool is None or pid != os.getpid():
            pool = ThreadPoolExecutor(max_workers=workers, thread_name_prefix=name,
                                      initializer=initializer)
            _POOLS[name] = (pool, os.getpid())
        return pool


def pool() -> ThreadPoolExecutor:
    return _pool("wideprint-rip")


def run_parallel(jobs) -> None:
    """Run callables on the pool (one alone runs here, and all of them here on a thread of
    `ordered`, which already keeps every core busy with other bands) and wait for all of
    them; the first exception is raised."""
    jobs = list(jobs)
    if len(jobs) == 1 or getattr(_HERE, "inline", False):
        for job in jobs:
            job()
        return
    futures = [pool().submit(job) for job in jobs]
    for f in futures:
        f.result()


def ordered(jobs: Iterator[Callable[[], T]], workers: int = WORKERS) -> Iterator[T]:
    """Each job (a band's work; nothing shared with the other jobs) run on one of `workers`
    band workers (1 beside a sequential stage that needs the other core), one more job
    than workers submitted ahead, the results yielded in the jobs' order.  `jobs` is drawn
    here, in the consumer's thread.  A pool of its own: the halftoner's `run_parallel` jobs
    never queue behind separation bands."""
    ahead = workers + 1
    pending: collections.deque = collections.deque()
    band_pool = _pool(f"wideprint-band{workers}", _band_worker, workers)
    try:
        for job in jobs:
            pending.append(band_pool.submit(job))
            if len(pending) >= ahead:
                yield pending.popleft().result()
        while pending:
            yield pending.popleft().result()
    finally:                    # closed early or failed: what has not started never will
        for f in pending:
            f.cancel()


def split(n: int, parts: int = WORKERS, minimum: int = 1) -> list[tuple[int, int]]:
    """[0, n) cut into at most `parts` contiguous ranges of at least `minimum` items."""
    parts = max(1, min(parts, n // max(1, minimum)))
    edges = [n * i // parts for i in range(parts + 1)]
    return [(a, b) for a, b in zip(edges, edges[1:]) if b > a]
