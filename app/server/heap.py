"""Giving the C heap's free pages back to the system once the printers are idle
(docs/server.md, "Memory").

A server's jobs each allocate and free many C blocks of every size (HTTP bodies, PNG
previews, JSON, sqlite pages, numpy band buffers under the 4 MiB mmap threshold set at
start-up in app/cli/process.py), and glibc keeps what is freed inside an arena as the
arena's own: the server's RSS rose ~0.5 MB a minute at ~60 jobs a minute with the heap in
use flat, and stayed there when the jobs stopped (bench/server_rss.py, 60 minutes, 2,900
jobs: 255 -> 285 MB).  `malloc_trim(0)` returns every whole free page of every arena
(madvise), which glibc never does by itself except at an arena's top: after those 2,900
jobs it took the idle server back to 250 MB, below its first minute.  Trimming after each
job instead did not (280 MB: the other printer's job was still freeing), so the trim waits
until no job has ended for IDLE_S.  A few ms for the server's heap.  Nothing to do off glibc."""

from __future__ import annotations

import ctypes
import logging
import sys
import threading
import time

#: seconds without a job ending before the heap is trimmed
IDLE_S = 2.0

# Only in the server's own process (`wideprint serve`: app/cli/__init__.py enables it), as
# the allocator settings of app/cli/process.py: a process that embeds a PrintServer (the
# tests, a user's script) keeps its heap as it is - a trim locks every arena in turn, ~0.2 s
# for a fragmented 1 GB heap, and the host's own threads would wait on malloc meanwhile.
_enabled = False
_lock = threading.Lock()
log = logging.getLogger("wideprint.server")
_ended: float | None = None          # when the last job ended, if not trimmed since
_trim = None
if sys.platform.startswith("linux"):
    try:
        _trim = ctypes.CDLL(None).malloc_trim
        _trim.argtypes = [ctypes.c_size_t]
    except (OSError, AttributeError):       # not glibc (musl has no malloc_trim)
        _trim = None


def enable() -> None:
    """This process is the print server's own: trim its heap when the printers are idle."""
    global _enabled
    _enabled = True


def job_ended() -> None:
    """A job ended (any printer): its freed memory waits for the next idle moment."""
    global _ended
    with _lock:
        _ended = time.monotonic()


def give_back_when_idle() -> bool:
    """From an idle worker's loop: return the C heap's free pages to the system once no job
    has ended for IDLE_S since the last trim; True when it trimmed."""
    global _ended
    with _lock:
        if _ended is None or time.monotonic() - _ended < IDLE_S:
            return False
        _ended = None
    if _trim is None or not _enabled:
        return False
    t0 = time.monotonic()
    _trim(0)
    log.debug("idle: the C heap's free pages given back (malloc_trim, %.0f ms)",
              (time.monotonic() - t0) * 1000)
    return True
