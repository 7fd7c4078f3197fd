"""Named crash points of a job's life, for the crash-point tests (docs/server.md "Crash
recovery: the facts and their order").

`WIDEPRINT_CRASH_AT=POINT[:N]` in the server's environment kills the server with SIGKILL
the N-th time (default the first) it passes POINT, right after the fact recorded there has
committed — as SQLite's own crash tests stop a process between two writes.  Without the
variable `reached` is one dictionary look-up.  The points, in the order a job meets them:

    upload     the job row and its spool copy committed, before the client is answered
    claim      queued -> printing committed
    checkpoint a stroke's checkpoint committed (N counts strokes across the server's life)
    job_end    the printer confirmed JOB_END and the `ended` checkpoint committed
    copy_done  a copy that is not the last: its accounting row and count committed
    hot_done   a hot-folder job's original moved to done/ or failed/, before `finish`
    finish     the job's final state (with its last copy's row) committed, before its
               spool copy is deleted
"""

from __future__ import annotations

import os
import signal

POINTS = ("upload", "claim", "checkpoint", "job_end", "copy_done", "hot_done", "finish")
ENV = "WIDEPRINT_CRASH_AT"


def _parse(spec: str) -> tuple[str, int] | None:
    if not spec:
        return None
    point, _, n = spec.partition(":")
    if point not in POINTS:
        raise ValueError(f"{ENV}={spec}: unknown crash point; points: {', '.join(POINTS)}")
    return point, int(n or 1)


_target = _parse(os.environ.get(ENV, ""))
_seen: dict[str, int] = {}


def reached(point: str) -> None:
    """The server passed `point`; die here if the tests asked for it."""
    if _target is None or _target[0] != point:
        return
    _seen[point] = _seen.get(point, 0) + 1
    if _seen[point] == _target[1]:
        os.kill(os.getpid(), signal.SIGKILL)
