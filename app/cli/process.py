"""The `wideprint` process's own settings, made before any work: glibc's allocator, numpy's
BLAS threads, the garbage collector during start-up."""

from __future__ import annotations

import sys


def _give_back_big_buffers() -> None:
    """glibc raises its mmap threshold to the size of each large block freed (up to 32 MiB),
    so the RIP's band buffers soon come from the heap arenas, and freed they stay in the
    process's memory, fragmented among threads (an arena each, up to 8 per core).  A fixed
    threshold of 4 MiB keeps the big buffers (media window, whole strokes, image rows) an
    mmap of their own, returned when freed, and two arenas hold the rest.  Not lower: a
    band's buffers (1-3 MB at full width) would each be a fresh mmap, page-faulted and
    zeroed at every band - 256 KiB cost `print` 0.55 s and `rip` 0.6 s of 3 at full width
    for 16 MB less (bench/README.md, "Memory").  The smaller blocks freed at the top of an
    arena stay there up to 32 MiB (M_TRIM_THRESHOLD; glibc's default gives back all beyond
    128 KiB, and the next band faults the same pages in again): a full-width print's page
    faults 110,000 -> 35,000 and its system time -0.1 s for ~6 MB more peak.  Before any
    thread starts."""
    if not sys.platform.startswith("linux"):
        return
    import ctypes
    try:
        libc = ctypes.CDLL(None)
        libc.mallopt(-3, 4 << 20)           # M_MMAP_THRESHOLD (glibc)
        libc.mallopt(-8, 2)                 # M_ARENA_MAX: the RIP's few threads share two
        libc.mallopt(-1, 32 << 20)          # M_TRIM_THRESHOLD
    except (OSError, AttributeError):       # not glibc: its own policy stays
        pass


def _one_blas_thread() -> None:
    """numpy's OpenBLAS starts a thread per core at its first matrix product (the emulator's
    servo model multiplies 4 x 4 matrices) and those threads spin on after it: ~0.1 CPU-s a
    job taken from the RIP for nothing.  Before numpy is loaded; OPENBLAS_NUM_THREADS set by
    the user wins."""
    import os
    os.environ.setdefault("OPENBLAS_NUM_THREADS", "1")


_collector_was_off = False


def _collector_off() -> None:
    """Start-up makes ~30,000 container objects that live as long as the process (modules,
    classes, functions, the parser), and Python's cyclic garbage collector walks the young
    ones every 700 allocations and all of them at each full collection during the imports:
    25-30 ms of a tiny `rip`'s 0.23 s (median of 15).  Off until the command's modules are
    imported (`_collector_on`).  Only when `wideprint` is the process (main() without
    argv): a caller's own process keeps its collector as it is."""
    global _collector_was_off
    import gc
    if gc.isenabled():
        gc.disable()
        _collector_was_off = True


def _collector_on() -> None:
    """The objects made so far frozen (never walked again, since they are never garbage)
    and the collector back on for the job's own."""
    global _collector_was_off
    if _collector_was_off:
        import gc
        gc.freeze()
        gc.enable()
        _collector_was_off = False


# the commands that turn the collector back on themselves, once their modules are imported
_QUICK_START = ("print", "rip")
