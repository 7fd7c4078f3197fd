"""CUPS lands jobs in the wideprint queue (issue 7, docs/server.md "CUPS"): a private cupsd
on its own port runs the `wideprint://` backend (resources/cups/wideprint) for a queue
added with lpadmin and the wideprint PPD; `lp -h 127.0.0.1:PORT -d wideprint file.tif`
prints on the emulator, bit-exact."""

import os
import shutil
import socket
import subprocess
import time
from pathlib import Path

import numpy as np
import pytest

from conftest import ROOT, random_planes, write_cmyk_tiff
from wideprint.app.server_cli import Client
from wideprint.rip.planes import read_planes

BACKEND = ROOT / "resources" / "cups" / "wideprint"
PPD = ROOT / "resources" / "cups" / "wideprint.ppd"
CUPS_LIB = Path("/usr/lib/cups")
DEBIAN_PACKAGES = ["cups-daemon", "cups-client", "cups-bsd"]


def _cups_missing() -> str | None:
    """Why cupsd cannot run here (None: it can).  A test never installs anything: CI's
    .ci/run installs the Debian packages; elsewhere this test fails and says what is missing."""
    missing = [t for t in ("/usr/sbin/cupsd", "lpadmin", "lp", "lpstat")
               if not (shutil.which(t) or Path(t).exists())]
    if not (CUPS_LIB / "daemon" / "cups-exec").exists():
        missing.append(str(CUPS_LIB / "daemon" / "cups-exec"))
    if missing:
        return (f"CUPS is not installed ({', '.join(missing)} missing): apt-get install "
                f"{' '.join(DEBIAN_PACKAGES)} (.ci/run does), or see tests/test_cups_backend.py, "
                f"which tests the backend without cupsd")
    return None


def _free_port() -> int:
    with socket.socket() as s:
        s.bind(("127.0.0.1", 0))
        return s.getsockname()[1]


@pytest.fixture(scope="module")
def wideprint_server(tmp_path_factory):
    from wideprint.app.server import PrintServer, ServerConfig
    root = tmp_path_factory.mktemp("wp")
    server = PrintServer(ServerConfig(device="emulator", state_dir=root / "state",
                                      media_dir=root / "media", port=0))
    server.start()
    server.root = root
    yield server
    server.stop(timeout=5)


@pytest.fixture(scope="module")
def cupsd(tmp_path_factory):
    why = _cups_missing()
    if why:
        pytest.fail(why)                    # a missing dependency fails loudly, never a skip
    if os.geteuid() != 0:
        pytest.skip("the private cupsd runs the backend as root (its token is 0600); run as root")
    d = tmp_path_factory.mktemp("cups")
    os.chmod(d, 0o755)
    port = _free_port()
    for sub in ("conf", "spool", "tmp", "cache", "state", "log", "bin", "bin/backend"):
        (d / sub).mkdir()
    os.chmod(d / "spool", 0o710)
    # ServerBin: the system's helpers, plus our backend (0700 root: cupsd runs it as root)
    for sub in ("daemon", "filter", "notifier", "cgi-bin", "monitor"):
        if (CUPS_LIB / sub).exists():
            os.symlink(CUPS_LIB / sub, d / "bin" / sub)
    shutil.copy(BACKEND, d / "bin" / "backend" / "wideprint")
    os.chmod(d / "bin" / "backend" / "wideprint", 0o700)
    (d / "conf" / "cups-files.conf").write_text(f"""\
ServerRoot {d}/conf
RequestRoot {d}/spool
TempDir {d}/tmp
CacheDir {d}/cache
StateDir {d}/state
ServerBin {d}/bin
DataDir /usr/share/cups
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
Listen 127.0.0.1:{port}
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
    proc = subprocess.Popen(["/usr/sbin/cupsd", "-f", "-c", str(d / "conf" / "cupsd.conf"),
                             "-s", str(d / "conf" / "cups-files.conf")],
                            stdout=subprocess.PIPE, stderr=subprocess.STDOUT, text=True)
    host = f"127.0.0.1:{port}"
    deadline = time.monotonic() + 20
    while time.monotonic() < deadline:
        if proc.poll() is not None:
            pytest.fail("cupsd exited: " + proc.stdout.read() + _log(d))
        try:
            socket.create_connection(("127.0.0.1", port), timeout=0.5).close()
            break
        except OSError:
            time.sleep(0.1)
    else:
        proc.kill()
        pytest.fail("cupsd did not listen: " + _log(d))
    cups = dict(host=host, dir=d, env=dict(os.environ, CUPS_SERVER=host))
    yield cups
    proc.terminate()
    try:
        proc.wait(10)
    except subprocess.TimeoutExpired:
        proc.kill()


def _log(d) -> str:
    p = Path(d) / "log" / "error_log"
    return "\n--- cupsd error_log ---\n" + (p.read_text()[-4000:] if p.exists() else "(none)")


def run(cups, *cmd):
    r = subprocess.run(list(cmd), capture_output=True, text=True, timeout=30, env=cups["env"])
    assert r.returncode == 0, f"{cmd}: {r.stdout}{r.stderr}{_log(cups['dir'])}"
    return r.stdout


@pytest.fixture(scope="module")
def queue(cupsd, wideprint_server):
    run(cupsd, "lpadmin", "-h", cupsd["host"], "-p", "wideprint", "-E",
        "-v", f"wideprint://{wideprint_server.state_dir}", "-P", str(PPD),
        "-D", "wideprint 3.4 m CMYK")
    out = run(cupsd, "lpstat", "-h", cupsd["host"], "-v", "wideprint")
    assert f"wideprint://{wideprint_server.state_dir}" in out
    return cupsd


def _wait_job(client: Client, name: str, known: set, timeout=40.0) -> dict:
    deadline = time.monotonic() + timeout
    while time.monotonic() < deadline:
        for j in client.jobs():
            if j["id"] not in known and j["name"] == name and \
                    j["state"] in ("done", "failed", "cancelled"):
                return j
        time.sleep(0.1)
    raise AssertionError(f"no finished wideprint job {name}")


def test_lp_prints_a_tiff_through_cups_bit_exact(queue, wideprint_server, tmp_path):
    planes = random_planes(120, 400, seed=31)
    src = write_cmyk_tiff(tmp_path / "poster.tif", planes)
    client = Client(wideprint_server.state_dir)
    known = {j["id"] for j in client.jobs()}
    out = run(queue, "lp", "-h", queue["host"], "-d", "wideprint",
              "-o", "WPPasses=2", "-o", "WPBidir=True", str(src))
    assert "request id is wideprint-" in out
    job = _wait_job(client, "poster.tif", known)
    assert job["state"] == "done", job["message"] + _log(queue["dir"])
    assert job["source"] == "api" and job["client"].startswith("cups:")
    assert job["settings"] == {"passes": 2, "bidir": True}
    media = wideprint_server.root / "media" / f"job-{job['id']}.tif"
    assert np.array_equal(read_planes(media), planes)


def test_lp_raw_and_copies(queue, wideprint_server, tmp_path):
    planes = random_planes(60, 200, seed=32)
    src = write_cmyk_tiff(tmp_path / "raw.tif", planes)
    client = Client(wideprint_server.state_dir)
    known = {j["id"] for j in client.jobs()}
    run(queue, "lp", "-h", queue["host"], "-d", "wideprint", "-o", "raw", "-n", "2",
        "-o", "WPPreset=banner", str(src))
    job = _wait_job(client, "raw.tif", known)
    assert job["state"] == "done", job["message"]
    assert job["copies"] == 2 and job["copies_done"] == 2 and job["preset"] == "banner"
    assert np.array_equal(read_planes(wideprint_server.root / "media" / f"job-{job['id']}.tif"),
                          planes)


def test_cups_refuses_a_format_the_printer_does_not_take(queue, tmp_path):
    txt = tmp_path / "note.txt"
    txt.write_text("hello\n")
    r = subprocess.run(["lp", "-h", queue["host"], "-d", "wideprint", str(txt)],
                       capture_output=True, text=True, timeout=30, env=queue["env"])
    assert r.returncode != 0 and "nsupported" in r.stderr, r.stdout + r.stderr


def test_lp_prints_a_pdf_through_cups(queue, wideprint_server, tmp_path):
    """PDF passes through CUPS unfiltered (the PPD's cupsFilter2) and is ripped by the
    server through Ghostscript: the media equals the planes `wideprint rip` makes of it."""
    if not shutil.which("gs"):
        pytest.fail("Ghostscript (gs) is not installed: resources/debian-packages.txt lists it "
                    "and .ci/run installs it")
    from wideprint.rip.pipeline import RipJob, RipSettings
    from wideprint.rip.profile import load_profile
    ps = tmp_path / "flyer.ps"
    ps.write_bytes(b"%!PS\n<< /PageSize [144 72] >> setpagedevice 0 0.6 0.4 0 setcmykcolor\n"
                   b"10 10 100 40 rectfill 0 0 0 1 setcmykcolor /Helvetica findfont 20 scalefont setfont\n"
                   b"20 30 moveto (PDF) show showpage\n")
    pdf = tmp_path / "flyer.pdf"
    subprocess.run(["gs", "-q", "-dSAFER", "-dBATCH", "-dNOPAUSE", "-sDEVICE=pdfwrite", f"-sOutputFile={pdf}",
                    str(ps)], check=True, capture_output=True)
    client = Client(wideprint_server.state_dir)
    known = {j["id"] for j in client.jobs()}
    run(queue, "lp", "-h", queue["host"], "-d", "wideprint", str(pdf))
    job = _wait_job(client, "flyer.pdf", known, timeout=90)
    assert job["state"] == "done", job["message"] + _log(queue["dir"])
    planes = tmp_path / "planes.tif"
    RipJob(str(pdf), RipSettings(), load_profile()).write_planes(planes)
    media = read_planes(wideprint_server.root / "media" / f"job-{job['id']}.tif")
    assert media.shape == (round(72 / 72 * 25400 / 68.55), 600, 4)
    assert np.array_equal(media, read_planes(planes))
