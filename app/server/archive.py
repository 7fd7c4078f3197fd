"""The job archive (docs/server.md "Archive and reprint"): a done job keeps its spooled file
for a while, so the operator can print it again - with its settings or changed ones - from
the GUI's history, `wideprint reprint` or `POST /v1/jobs/ID/reprint`.

The retention policy is the server's configuration, declared once here (`OPTIONS`): the
`serve` options are made from it and docs/server.md's table is checked against it
(tests/test_archive.py), as the job settings are (rip/settings.py).
"""

from __future__ import annotations

import os
import uuid
from dataclasses import dataclass
from pathlib import Path

from . import fsck
from .config import _fsync_dir


@dataclass(frozen=True)
class Option:
    name: str              # ServerConfig field; the `serve` option is --name-with-dashes
    kind: type             # float, or bool: a flag (on when given)
    default: float
    metavar: str
    doc: str

    @property
    def flag(self) -> str:
        return "--" + self.name.replace("_", "-")


# the archive's policy: every option once (docs/server.md "Archive and reprint" lists them)
OPTIONS: tuple[Option, ...] = (
    Option("archive_days", float, 30.0, "DAYS",
           "keep the spooled file of a done job this long, for reprints (0: delete it when "
           "the job ends, as before)"),
    Option("archive_max_gb", float, 20.0, "GB",
           "the archive's total size at most: the oldest done jobs' files go first (0: no "
           "limit but the days)"),
    Option("archive_planes", bool, False, "",
           "keep a done job's ripped planes (RIP and hold) with its file: a reprint with the "
           "same settings prints them without ripping again"),
)
DEFAULTS = {o.name: o.default for o in OPTIONS}


def add_arguments(parser) -> None:
    """The archive's `serve` options, from OPTIONS."""
    for o in OPTIONS:
        if o.kind is bool:
            parser.add_argument(o.flag, action="store_true", default=None, help=o.doc)
        else:
            parser.add_argument(o.flag, type=o.kind, metavar=o.metavar, default=None,
                                help=f"{o.doc} (default {o.default:g})")


def from_args(args) -> dict:
    """The ServerConfig fields the `serve` options give (ValueError for a bad value)."""
    out = {}
    for o in OPTIONS:
        v = getattr(args, o.name, None)
        if v is None:
            continue
        if o.kind is bool:
            out[o.name] = bool(v)
            continue
        if not v >= 0:                                  # negative or NaN
            raise ValueError(f"{o.flag} must be 0 or more")
        out[o.name] = o.kind(v)
    return out


def max_bytes(config) -> int | None:
    gb = float(getattr(config, "archive_max_gb", DEFAULTS["archive_max_gb"]))
    return None if gb <= 0 else int(gb * 1e9)


def keeps_done(config) -> bool:
    return float(getattr(config, "archive_days", DEFAULTS["archive_days"])) > 0


def keeps_planes(config) -> bool:
    return keeps_done(config) and bool(getattr(config, "archive_planes", False))


def link_copy(spool_dir: Path, src: str) -> str:
    """A new spool name for an archived file: a hard link (no second copy of a 2 GB
    banner), else a copy; fsync'd.  The reprint owns it, whatever the archive does with
    the original's name later."""
    suffix = Path(src).suffix
    final = spool_dir / f"{uuid.uuid4().hex}{suffix}"
    try:
        os.link(src, final)
    except OSError:
        import shutil
        tmp = spool_dir / f".{final.name}.part"
        shutil.copyfile(src, tmp)
        with open(tmp, "rb+") as f:
            os.fsync(f.fileno())
        os.rename(tmp, final)
    _fsync_dir(spool_dir)
    return str(final)


def check_archived(job: dict) -> str:
    """The archived file of a finished job, checked against its digest: its path, or
    SpoolError-ready words saying why it cannot be reprinted."""
    path = job.get("spool_path")
    if not path or not os.path.exists(path):
        raise FileNotFoundError(f"job {job['id']} ({job['name']}): its file is no longer "
                                f"archived (the archive keeps done jobs' files for "
                                f"--archive-days, failed and cancelled ones' for "
                                f"--keep-failed); submit the file again")
    if fsck.file_digest(path) != job["sha256"]:
        raise ValueError(f"job {job['id']} ({job['name']}): its archived file is damaged (its "
                         f"SHA-256 is not the one taken when it was queued); submit the file "
                         f"again")
    return path
