"""The RIP's worker threads: small pools shared by every compiled kernel, as many workers as
the cores this process may run on (its CPU affinity: a container's or `taskset`'s share, not
the whole machine's), or $WIDEPRINT_THREADS (`--threads N` on `rip` and `print` sets it):
fewer to leave cores to other work, more only to test.  The results are bit-identical
whatever the count (tests/test_parallel.py).  Kernels are numba `nogil`, so they run truly in
parallel; the pools are made anew in a forked child, whose copy has no threads.

Two ways to use the cores (docs/rip.md "Threads"):
- `run_parallel`: one band's work split across the workers and waited for (the
  halftoner's planes, whose error rows pass from band to band);
- `ordered`: whole bands side by side, results in order, for stages whose bands are
  independent (separation, ordered screening).  No barrier per band: a split band waits
  for its slower half, and a half is slow whenever the driver, reader or writer threads
  hold a core - in a whole `rip -o` on two cores the two screening workers were each busy
  only ~50 %.
"""

from __future__ import annotations

import collections
import os
import threading
from concurrent.futures import ThreadPoolExecutor
from typing import Callable, Iterator, TypeVar

T = TypeVar("T")

ENV = "WIDEPRINT_THREADS"
MAX_WORKERS = 256          # a sanity bound on $WIDEPRINT_THREADS, not a machine's


def machine_cores() -> int:
    """The cores this process may run on: its affinity mask (a container's or taskset's
    share), else every core the machine has."""
    try:
        return max(1, len(os.sched_getaffinity(0)))
    except (AttributeError, OSError):          # not Linux
        return max(1, os.cpu_count() or 1)


def parse_threads(text: str, source: str = ENV) -> int:
    """A thread count as given ("4"): ValueError naming `source` unless 1..MAX_WORKERS."""
    try:
        n = int(str(text).strip())
    except ValueError:
        n = 0
    if not 1 <= n <= MAX_WORKERS:
        raise ValueError(f"{source}={text!r}: expected a whole number of threads, 1 to {MAX_WORKERS}")
    return n


def workers_wanted(environ=os.environ) -> int:
    """$WIDEPRINT_THREADS when set (a bad value is warned of and ignored: importing the RIP
    never fails on it; the command line checks it first), else `machine_cores()`."""
    text = environ.get(ENV, "").strip()
    if text:
        try:
            return parse_threads(text)
        except ValueError as exc:
            import warnings
            warnings.warn(f"{exc}; using the {machine_cores()} cores of this machine", stacklevel=2)
    return machine_cores()


WORKERS = workers_wanted()
_POOLS: dict[str, tuple[ThreadPoolExecutor, int]] = {}
_LOCK = threading.Lock()


def set_workers(n: int) -> None:
    """The count for the pools from now on (`--threads N`, checked as parse_threads); pools
    of another count are let go (their running jobs finish)."""
    global WORKERS
    WORKERS = parse_threads(n, "--threads")
    with _LOCK:
        for pool, _pid in _POOLS.values():
            pool.shutdown(wait=False)
        _POOLS.clear()
_HERE = threading.local()          # .inline: this thread runs a whole band; no splitting


def _band_worker() -> None:
    _HERE.inline = True


def _pool(name: str, initializer=None, workers: int | None = None) -> ThreadPoolExecutor:
    workers = workers or WORKERS
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


def ordered(jobs: Iterator[Callable[[], T]], workers: int | None = None) -> Iterator[T]:
    """Each job (a band's work; nothing shared with the other jobs) run on one of `workers`
    band workers (1 beside a sequential stage that needs the other core), one more job
    than workers submitted ahead, the results yielded in the jobs' order.  `jobs` is drawn
    here, in the consumer's thread.  A pool of its own: the halftoner's `run_parallel` jobs
    never queue behind separation bands.  `workers`: default WORKERS."""
    workers = workers or WORKERS
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


def split(n: int, parts: int | None = None, minimum: int = 1) -> list[tuple[int, int]]:
    """[0, n) cut into at most `parts` (default WORKERS) contiguous ranges of at least
    `minimum` items."""
    parts = max(1, min(parts or WORKERS, n // max(1, minimum)))
    edges = [n * i // parts for i in range(parts + 1)]
    return [(a, b) for a, b in zip(edges, edges[1:]) if b > a]
