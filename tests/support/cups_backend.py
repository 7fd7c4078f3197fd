"""The CUPS backend `resources/cups/wideprint` run as cupsd runs it (argv job-id user title
copies options [file], DEVICE_URI in the environment), its exit codes (docs/server.md
"CUPS") and the check that its stderr is only `LEVEL: one line` messages."""

from __future__ import annotations

import os
import subprocess
import sys
import time
from pathlib import Path

from support.images import ROOT

BACKEND = ROOT / "resources" / "cups" / "wideprint"
OK, FAILED, AUTH_REQUIRED, HOLD, STOP, CANCEL, RETRY = range(7)
LEVELS = ("ERROR: ", "INFO: ", "ATTR: ", "DEBUG: ", "STATE: ", "WARNING: ")
MAX_FILE = 100_000


def backend_cmd():
    # as cupsd: the script itself (its #!/usr/bin/python3), else this interpreter
    if Path("/usr/bin/python3").exists() and os.access(BACKEND, os.X_OK):
        return [str(BACKEND)]
    return [sys.executable, str(BACKEND)]


def run_backend(uri, *, file=None, stdin=b"", options="", title="poster.tif", job="42",
                copies="1", env=None, tmpdir=None, timeout=60):
    e = {k: v for k, v in os.environ.items() if k not in ("WIDEPRINT_STATE_DIR", "PPD")}
    e.update(PRINTER="wideprint", CONTENT_TYPE="image/tiff", **(env or {}))
    if uri is not None:
        e["DEVICE_URI"] = uri
    if tmpdir is not None:
        e["TMPDIR"] = str(tmpdir)
    argv = backend_cmd() + [job, "alice", title, copies, options] + ([str(file)] if file else [])
    t0 = time.monotonic()
    r = subprocess.run(argv, input=stdin, capture_output=True, env=e, timeout=timeout)
    r.seconds = time.monotonic() - t0
    r.err = r.stderr.decode("utf-8", "replace")
    check_stderr(r.err)
    return r


def check_stderr(err):
    assert "Traceback" not in err, err
    for line in err.splitlines():
        assert line.startswith(LEVELS), f"not a CUPS message line: {line!r}\n{err}"
        assert "\x1b" not in line and "\r" not in line


def uri_of(state):
    return f"wideprint://{state}"
