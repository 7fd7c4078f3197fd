"""Giving the C heap's free pages back to the system after each job (docs/server.md,
"Memory").

A server's jobs each allocate and free a few hundred small C blocks (HTTP bodies, PNG
previews, JSON, numpy band buffers under the 4 MiB mmap threshold set at start-up in
app/cli/process.py), spread over the per-thread arenas; glibc keeps what is freed in the
middle of an arena as the arena's own, so the server's RSS creeps up while the heap in use
stays flat (bench/server_rss.py measured +1.7 MB a minute at ~60 jobs a minute, 39-50 MB in
use against 90+ MB free inside the arenas).  `malloc_trim(0)` returns every whole free page
of every arena (madvise), which glibc never does by itself except at an arena's top.  Cheap
(a few ms for a 150 MB heap), so once per finished job, at most every few seconds.
Nothing to do off glibc."""

from __future__ import annotations

import ctypes
import sys
import threading
import time

#: at most one trim in this many seconds (a burst of tiny jobs would trim per job)
MIN_INTERVAL_S = 5.0

_lock = threading.Lock()
_last = 0.0
_trim = None
if sys.platform.startswith("linux"):
    try:
        _trim = ctypes.CDLL(None).malloc_trim
        _trim.argtypes = [ctypes.c_size_t]
    except (OSError, AttributeError):       # not glibc (musl has no malloc_trim)
        _trim = None


def give_back() -> bool:
    """Return the C heap's free pages to the system, unless done within MIN_INTERVAL_S;
    True when it trimmed."""
    global _last
    if _trim is None:
        return False
    now = time.monotonic()
    with _lock:
        if now - _last < MIN_INTERVAL_S:
            return False
        _last = now
    _trim(0)
    return True
