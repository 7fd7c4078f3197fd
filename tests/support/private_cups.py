"""Test harness shared by the CUPS tests (tests/test_cups.py, tests/test_ipp_cups.py) and the
IPP tests (tests/test_ipp.py): a private cupsd on its own port with its own configuration,
spool and ServerBin under a tmp dir, and `wideprint serve --ipp` as a subprocess.  Nothing
here installs anything: CI's .ci/run installs the Debian packages; a missing one fails the
test that needs it, naming the package."""

from __future__ import annotations

import hashlib
import json
import os
import shutil
import signal
import socket
import subprocess
import sys
import time
from pathlib import Path

import numpy as np
import pytest

CUPS_LIB = Path("/usr/lib/cups")
CUPS_PACKAGES = ["cups-daemon", "cups-client", "cups-bsd"]


def free_port() -> int:
    with socket.socket() as s:
        s.bind(("127.0.0.1", 0))
        return s.getsockname()[1]


def cups_missing() -> str | None:
    """Why cupsd cannot run here (None: it can)."""
    missing = [t for t in ("/usr/sbin/cupsd", "lpadmin", "lp", "lpstat")
               if not (shutil.which(t) or Path(t).exists())]
    if not (CUPS_LIB / "daemon" / "cups-exec").exists():
        missing.append(str(CUPS_LIB / "daemon" / "cups-exec"))
    if missing:
        return (f"CUPS is not installed ({', '.join(missing)} missing): apt-get install "
                f"{' '.join(CUPS_PACKAGES)} (.ci/run does), or see tests/test_cups_backend.py, "
                f"which tests the backend without cupsd")
    return None


#: Debian's cups-filters packages' MIME files in DataDir/mime (cups-filters,
#: cups-filters-core-drivers): left out of a cupsd that is to run without cups-filters
FILTERS_MIME = ("cupsfilters", "braille")


class Cupsd:
    """A cupsd of its own: `Listen 127.0.0.1:PORT`, its config, spool, cache and logs in
    `d`, ServerBin `d/bin` = the system's helpers plus the `backends` given (name -> file,
    and CUPS' `ipp`, installed 0700 root: cupsd runs such a backend as root); `conf`: files
    copied into its ServerRoot (e.g. a .convs file).  `filters=False`: a CUPS without
    cups-filters (cups-daemon alone): its DataDir is the system's less cups-filters' MIME
    types and conversions, so cupsd knows none of its filters."""

    def __init__(self, d: Path, backends: dict[str, Path] | None = None,
                 conf: tuple[Path, ...] = (), filters: bool = True):
        self.dir = Path(d)
        os.chmod(self.dir, 0o755)
        self.port = free_port()
        self.host = f"127.0.0.1:{self.port}"
        self.env = dict(os.environ, CUPS_SERVER=self.host)
        d = self.dir
        for sub in ("conf", "spool", "tmp", "cache", "state", "log", "bin", "bin/backend"):
            (d / sub).mkdir()
        os.chmod(d / "spool", 0o710)
        for sub in ("daemon", "filter", "notifier", "cgi-bin", "monitor"):
            if (CUPS_LIB / sub).exists():
                os.symlink(CUPS_LIB / sub, d / "bin" / sub)
        # the backends: ours, and CUPS' ipp backend (the driverless queues).  All are
        # copied 0700 root, so cupsd runs them as root: as `lp` it could not reach them
        # through the test's 0700 tmp dir
        ipp = CUPS_LIB / "backend" / "ipp"
        system = {n: ipp for n in ("ipp", "ipps")} if ipp.exists() else {}
        for name, src in {**system, **(backends or {})}.items():
            shutil.copy(src, d / "bin" / "backend" / name)
            os.chmod(d / "bin" / "backend" / name, 0o700)
        for f in conf:
            shutil.copy(f, d / "conf" / Path(f).name)
        data = Path("/usr/share/cups")
        if not filters:
            data = d / "data"
            data.mkdir()
            for entry in Path("/usr/share/cups").iterdir():
                if entry.name != "mime":
                    os.symlink(entry, data / entry.name)
            (data / "mime").mkdir()
            for entry in (Path("/usr/share/cups") / "mime").iterdir():
                if not entry.name.startswith(FILTERS_MIME):
                    os.symlink(entry, data / "mime" / entry.name)
            os.chmod(data, 0o755)
        (d / "conf" / "cups-files.conf").write_text(f"""\
ServerRoot {d}/conf
RequestRoot {d}/spool
TempDir {d}/tmp
CacheDir {d}/cache
StateDir {d}/state
ServerBin {d}/bin
DataDir {data}
ErrorLog {d}/log/error_log
AccessLog {d}/log/access_log
PageLog {d}/log/page_log
SystemGroup root
User lp
Group lp
FileDevice No
""")
        (d / "conf" / "cupsd.conf").write_text(f"""\
LogLevel debug
Listen 127.0.0.1:{self.port}
ServerName 127.0.0.1
Browsing No
WebInterface No
DefaultAuthType None
MaxJobs 100
PreserveJobFiles No
<Location />
  Order allow,deny
  Allow 127.0.0.1
</Location>
<Location /admin>
  Order allow,deny
  Allow 127.0.0.1
</Location>
<Policy default>
  <Limit All>
    Order deny,allow
  </Limit>
</Policy>
""")
        self.proc = subprocess.Popen(
            ["/usr/sbin/cupsd", "-f", "-c", str(d / "conf" / "cupsd.conf"),
             "-s", str(d / "conf" / "cups-files.conf")],
            stdout=subprocess.PIPE, stderr=subprocess.STDOUT, text=True)
        deadline = time.monotonic() + 20
        while time.monotonic() < deadline:
            if self.proc.poll() is not None:
                pytest.fail("cupsd exited: " + self.proc.stdout.read() + self.log())
            try:
                socket.create_connection(("127.0.0.1", self.port), timeout=0.5).close()
                return
            except OSError:
                time.sleep(0.1)
        self.proc.kill()
        pytest.fail("cupsd did not listen: " + self.log())

    def mime_loads(self) -> int:
        """How often cupsd has loaded its MIME types and conversions (at start, at reload)."""
        p = self.dir / "log" / "error_log"
        return p.read_text(errors="replace").count("Loaded MIME database") if p.exists() else 0

    def wait_reload(self, before: int, timeout: float = 30) -> None:
        """Until cupsd has loaded its MIME database again (after `before` loads) and listens."""
        deadline = time.monotonic() + timeout
        while self.mime_loads() <= before:
            assert time.monotonic() < deadline, "cupsd did not reload" + self.log()
            time.sleep(0.1)
        while True:
            try:
                socket.create_connection(("127.0.0.1", self.port), timeout=0.5).close()
                return
            except OSError:
                assert time.monotonic() < deadline, "cupsd does not listen" + self.log()
                time.sleep(0.1)

    def log(self) -> str:
        p = self.dir / "log" / "error_log"
        return "\n--- cupsd error_log ---\n" + (p.read_text()[-4000:] if p.exists() else "(none)")

    def run(self, *cmd: str, timeout: float = 30) -> str:
        """A CUPS command against this cupsd; its stdout.  A failure fails the test with
        the command's output and the end of cupsd's log."""
        r = subprocess.run(list(cmd), capture_output=True, text=True, timeout=timeout,
                           env=self.env)
        assert r.returncode == 0, f"{cmd}: {r.stdout}{r.stderr}{self.log()}"
        return r.stdout

    def stop(self) -> None:
        self.proc.terminate()
        try:
            self.proc.wait(10)
        except subprocess.TimeoutExpired:
            self.proc.kill()
            self.proc.wait()


def private_cupsd(tmp_path_factory, backends: dict[str, Path] | None = None,
                  conf: tuple[Path, ...] = (), filters: bool = True):
    """The body of a cupsd fixture: yields a running Cupsd, stops it after."""
    why = cups_missing()
    if why:
        pytest.fail(why)                    # a missing dependency fails loudly, never a skip
    if os.geteuid() != 0:
        pytest.skip("the private cupsd runs its backends as root; run as root")
    cups = Cupsd(tmp_path_factory.mktemp("cups"), backends, conf, filters)
    yield cups
    cups.stop()


class IppServe:
    """`wideprint serve --ipp` as a subprocess (printers `name=emulator`, or the device spec
    `devices` names), as an operator starts it; `uris` are the printers' ipp:// URIs from
    server.json, `auth_uri` the same with the token as password (docs/ipp.md,
    "Authentication"), `url` the server's API (and web page)."""

    def __init__(self, root: Path, printers: list[str], *args: str,
                 devices: dict[str, str] | None = None):
        from wideprint.app.client import Client
        from wideprint.rip.profile import load_profile
        if not shutil.which("ipptool"):
            pytest.fail("ipptool is missing: apt-get install cups-ipp-utils (.ci/run does)")
        self.root, self.state, self.media = root, root / "state", root / "media"
        self.port = free_port()
        env = dict(os.environ, PYTHONPATH=os.pathsep.join(p for p in sys.path if p))
        self._log = open(root / "serve.log", "w")
        cmd = [sys.executable, "-m", "wideprint.app.cli", "serve", "--state-dir",
               str(self.state), "--media-dir", str(self.media), "--port", "0"]
        for p in printers:
            cmd += ["--printer", f"{p}={(devices or {}).get(p, 'emulator')}"]
        self.proc = subprocess.Popen(cmd + ["--ipp", "--ipp-port", str(self.port), *args],
                                     stdout=self._log, stderr=subprocess.STDOUT, env=env)
        deadline = time.monotonic() + 90
        info: dict = {}
        while time.monotonic() < deadline and self.proc.poll() is None:
            try:
                info = json.loads((self.state / "server.json").read_text())
                if "ipp" in info:
                    break
            except (OSError, ValueError):
                pass
            time.sleep(0.2)
        if "ipp" not in info:
            self.proc.kill()
            self.proc.wait()
            pytest.fail(f"serve --ipp did not start: {(root / 'serve.log').read_text()}")
        self.uris = info["ipp"]
        self.url = info["url"]
        self.client = Client(self.state)
        self.token = (self.state / "token").read_text().strip()
        self.auth_uri = {name: uri.replace("ipp://", f"ipp://wp:{self.token}@")
                         for name, uri in self.uris.items()}
        self.profile = {n: load_profile(self.state / "profiles" / f"{n}.toml") for n in printers}

    def stop(self) -> None:
        self.client.close()
        self.proc.send_signal(signal.SIGTERM)
        try:
            self.proc.wait(30)
        except subprocess.TimeoutExpired:
            self.proc.kill()
            self.proc.wait()
        self._log.close()


def wait_job(client, name: str, timeout: float = 240) -> dict:
    """The wideprint job of that name, once it has ended (the limit is for a machine so busy
    that numba's first compile in a new server takes minutes; a job ends in seconds)."""
    deadline = time.monotonic() + timeout
    while time.monotonic() < deadline:
        jobs = [j for j in client.jobs("done,failed,cancelled,queued,held,printing")
                if j["name"] == name]
        if jobs and jobs[-1]["state"] in ("done", "failed", "cancelled"):
            return jobs[-1]
        time.sleep(0.2)
    raise AssertionError(f"no finished job {name}")


def sha256(path: Path) -> str:
    return hashlib.sha256(Path(path).read_bytes()).hexdigest()


def assert_bit_exact(serve: IppServe, job: dict, original: Path, printer: str) -> None:
    """The job printed the client's original file (its sha256), and its media equals the
    planes `wideprint rip` makes of that file with the job's settings and the printer's
    profile, bit for bit."""
    from wideprint.app.api import rip
    from wideprint.rip.planes import read_planes
    assert job["state"] == "done", job
    assert job["printed_on"] == printer
    assert job["sha256"] == sha256(original)           # the original file, not a copy of it
    media = read_planes(serve.media / f"job-{job['id']}.tif")
    planes = rip(original, job["settings"], profile=serve.profile[printer])
    assert media.shape == planes.shape and media.any()
    assert np.array_equal(media, planes)
