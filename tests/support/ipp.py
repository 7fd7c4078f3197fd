"""Talking IPP to wideprint's Printer Application with CUPS' own ipptool (tests/test_ipp.py
and every test that prints or asks through IPP): the binary `make` builds, ipptool's plist
output read into dicts, Print-Job and Get-Job-Attributes."""

from __future__ import annotations

import plistlib
import subprocess
import time
from pathlib import Path

from wideprint.app.ipp.bridge import find_binary

BINARY = find_binary()                         # None when `make` has not built it
IPPTOOL_DIR = Path("/usr/share/cups/ipptool")


def ipptool(uri: str, test: str | Path, *args: str, cwd=None, timeout=120) -> dict:
    """Run ipptool with plist output (-X); returns {"Tests": [...]} (the tests of every
    file an INCLUDE brought in: ipptool writes one plist per file)."""
    r = subprocess.run(["ipptool", "-X", *args, uri, str(test)], capture_output=True,
                       cwd=cwd, timeout=timeout)
    assert r.stdout, r.stderr.decode()
    tests = []
    for doc in r.stdout.split(b"<?xml")[1:]:
        tests += plistlib.loads(b"<?xml" + doc).get("Tests", [])
    return {"Tests": tests}


def attrs(test: dict) -> dict:
    """A test's response attributes, every group merged."""
    return {k: v for group in test["ResponseAttributes"] for k, v in group.items()}


PRINT_JOB = """{
  NAME "Print-Job"
  OPERATION Print-Job
  GROUP operation-attributes-tag
  ATTR charset attributes-charset utf-8
  ATTR naturalLanguage attributes-natural-language en
  ATTR uri printer-uri $uri
  ATTR name requesting-user-name tester
  ATTR mimeMediaType document-format $format
  ATTR name job-name $name
  GROUP job-attributes-tag
%s
  FILE $filename
  STATUS successful-ok
  EXPECT job-id OF-TYPE integer
}
"""


def print_job(tmp: Path, uri: str, path: Path, fmt: str, name: str, job_attrs: str = "") -> dict:
    test = tmp / f"pj-{name}.test"
    test.write_text(PRINT_JOB % job_attrs)
    out = ipptool(uri, test, "-f", str(path), "-d", f"format={fmt}", "-d", f"name={name}")
    t = out["Tests"][0]
    assert t["Successful"], (t["StatusCode"], t.get("Errors"), attrs(t))
    return attrs(t)


JOB_OPERATION = """{
  NAME "%(op)s"
  OPERATION %(op)s
  GROUP operation-attributes-tag
  ATTR charset attributes-charset utf-8
  ATTR naturalLanguage attributes-natural-language en
  ATTR uri printer-uri $uri
  ATTR integer job-id $job_id
  ATTR name requesting-user-name tester
  STATUS successful-ok
}
"""


def job_operation(uri: str, op: str, job_id: int, tmp: Path) -> dict:
    """An operation on one job (Get-Job-Attributes, Cancel-Job, ...) expecting
    successful-ok: ipptool's test result."""
    test = tmp / f"{op.lower()}.test"
    test.write_text(JOB_OPERATION % {"op": op})
    return ipptool(uri, test, "-d", f"job_id={job_id}")["Tests"][0]


def ipp_job_state(uri: str, job_id: int, tmp: Path) -> dict:
    return attrs(job_operation(uri, "Get-Job-Attributes", job_id, tmp))


def wait_ipp_job(uri: str, job_id: int, tmp: Path, timeout: float = 120) -> dict:
    deadline = time.monotonic() + timeout
    while time.monotonic() < deadline:
        a = ipp_job_state(uri, job_id, tmp)
        if a["job-state"] >= 7:                    # canceled, aborted, completed
            return a
        time.sleep(0.3)
    raise AssertionError(f"IPP job {job_id} did not end")
