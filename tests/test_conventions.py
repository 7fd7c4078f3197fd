"""What a Linux print server and desktop tool is expected to ship, each checked with the
tool made for it: the systemd unit (systemd-analyze verify) and its readiness protocol,
the desktop entry (desktop-file-validate), the man page (current with the parser, renders
with groff), shell completion, the licence, the dependency pins, the Debian package list
CI installs, and `wideprint gui` without a display."""

import configparser
import os
import re
import shutil
import signal
import socket
import subprocess
import sys
from pathlib import Path

import pytest

ROOT = Path(__file__).resolve().parent.parent
RES = ROOT / "resources"
WIDEPRINT = [sys.executable, "-m", "wideprint.app.cli"]


def need(tool):
    path = shutil.which(tool)
    if path is None:
        pytest.fail(f"{tool} is missing: .ci/run installs it (resources/debian-packages.txt)")
    return path


def test_the_systemd_unit_verifies(tmp_path):
    need("systemd-analyze")
    exe = shutil.which("wideprint") or str(Path(sys.executable).parent / "wideprint")
    unit = tmp_path / "wideprint.service"
    text = (RES / "systemd" / "wideprint.service").read_text()
    assert "ExecStart=/usr/bin/wideprint serve" in text and "Type=notify" in text
    unit.write_text(text.replace("/usr/bin/wideprint", exe))
    r = subprocess.run(["systemd-analyze", "verify", str(unit)], capture_output=True, text=True)
    complaints = [ln for ln in r.stderr.splitlines() if str(unit) in ln or "wideprint" in ln]
    assert r.returncode == 0 and not complaints, r.stderr


def test_serve_tells_systemd_it_is_ready_and_stopping(tmp_path):
    """sd_notify(3): READY=1 once the API answers, STOPPING=1 on SIGTERM, exit 0."""
    sock_path = tmp_path / "notify.sock"
    sock = socket.socket(socket.AF_UNIX, socket.SOCK_DGRAM)
    sock.bind(str(sock_path))
    sock.settimeout(60)
    env = dict(os.environ, NOTIFY_SOCKET=str(sock_path))
    proc = subprocess.Popen(WIDEPRINT + ["serve", "--state-dir", str(tmp_path / "state"),
                                         "--port", "0"], env=env,
                            stdout=subprocess.PIPE, stderr=subprocess.PIPE, text=True)
    try:
        ready = sock.recv(4096).decode()
        assert "READY=1" in ready.splitlines(), ready
        url = re.search(r"STATUS=serving (http://\S+)", ready).group(1)
        import urllib.request
        token = (tmp_path / "state" / "token").read_text().strip()
        req = urllib.request.Request(url + "/v1/status", headers={"Authorization": f"Bearer {token}"})
        with urllib.request.urlopen(req, timeout=10) as resp:               # it answers
            assert resp.status == 200
        proc.send_signal(signal.SIGTERM)
        assert "STOPPING=1" in sock.recv(4096).decode().splitlines()
        assert proc.wait(60) == 0
    finally:
        if proc.poll() is None:
            proc.kill()
        out, err = proc.communicate(timeout=10)
        sock.close()
    assert "Traceback" not in err, err


def test_the_desktop_entry_validates():
    need("desktop-file-validate")
    r = subprocess.run(["desktop-file-validate", str(RES / "desktop" / "wideprint.desktop")],
                       capture_output=True, text=True)
    assert r.returncode == 0 and not r.stdout.strip(), r.stdout + r.stderr
    icon = (RES / "desktop" / "wideprint.svg").read_text()
    assert icon.lstrip().startswith("<?xml") and "<svg" in icon


def test_the_man_page_is_current_and_renders():
    need("groff")
    sys.path.insert(0, str(ROOT / "tools"))
    try:
        import make_manpage
    finally:
        sys.path.pop(0)
    page = RES / "man" / "wideprint.1"
    assert page.read_text() == make_manpage.manpage(), \
        "resources/man/wideprint.1 is stale: run .venv/bin/python tools/make_manpage.py"
    # every warning but "cannot adjust line" (a long option list that will not justify)
    r = subprocess.run(["groff", "-man", "-Tutf8", "-ww", "-Wbreak", str(page)],
                       capture_output=True, text=True)
    assert r.returncode == 0 and r.stderr == "", r.stderr
    for words in ("wideprint print", "--pass-mask", "wideprint printer", "--device"):
        assert words in r.stdout.replace("\u2010", "-").replace("\u2212", "-"), words


def test_shell_completion_is_valid_bash_and_knows_the_options():
    r = subprocess.run(WIDEPRINT + ["completion", "bash"], capture_output=True, text=True)
    assert r.returncode == 0, r.stderr
    check = subprocess.run(["bash", "-n"], input=r.stdout, capture_output=True, text=True)
    assert check.returncode == 0, check.stderr
    for word in ("print", "submit", "printer", "--pass-mask", "--dither", "clear-fault"):
        assert word in r.stdout, word


def test_licence_and_dependency_bounds():
    cfg = configparser.ConfigParser()
    cfg.read(ROOT / "setup.cfg")
    assert cfg["metadata"]["license"] == "MIT"
    assert "MIT License" in (ROOT / "LICENSE").read_text()
    pinned = {ln.split("==")[0].lower().replace("_", "-")
              for ln in (ROOT / "constraints.txt").read_text().splitlines()
              if "==" in ln and not ln.startswith("#")}
    reqs = [r.strip() for r in cfg["options"]["install_requires"].splitlines() if r.strip()]
    reqs += [r.strip() for part in ("test", "gui")
             for r in cfg["options.extras_require"][part].splitlines()
             if r.strip() and not r.strip().startswith("#")]
    for req in reqs:
        name = re.match(r"[A-Za-z0-9_.-]+", req).group(0).lower().replace("_", "-")
        assert name in pinned, f"{name} has no tested version in constraints.txt"
        if name not in ("tifffile", "imagecodecs"):            # date-versioned: no major to bound
            assert "<" in req, f"{req}: no upper bound"


def test_ci_installs_what_the_suite_runs():
    """Every external program the tests and the product call is in the package list that
    .ci/run installs (and .ci/run fails when one cannot be installed)."""
    listed = {ln.split("#")[0].strip() for ln in (RES / "debian-packages.txt").read_text().splitlines()}
    listed.discard("")
    provides = {"make": "make", "cupsd": "cups-daemon", "lp": "cups-client", "lpadmin": "cups-client",
                "gs": "ghostscript", "Xvfb": "xvfb", "systemd-analyze": "systemd",
                "desktop-file-validate": "desktop-file-utils", "groff": "groff-base",
                "ip": "iproute2", "dbus-daemon": "dbus-daemon", "ippfind": "cups-ipp-utils"}
    for tool, pkg in provides.items():
        assert pkg in listed, f"{tool} comes from {pkg}, which resources/debian-packages.txt lacks"
    ci = (ROOT / ".ci" / "run").read_text()
    assert "resources/debian-packages.txt" in ci and "exit 1" in ci and "make test" in ci
    for test in (ROOT / "tests").glob("*.py"):
        if test.name == Path(__file__).name:
            continue
        text = test.read_text()
        assert not re.search(r"\[\s*[\"']apt-get[\"']", text) and "pip install" not in text, \
            f"{test.name} installs packages; tests never do"


def test_gui_without_a_display_says_so_in_one_line():
    env = {k: v for k, v in os.environ.items() if k not in ("DISPLAY", "WAYLAND_DISPLAY", "QT_QPA_PLATFORM")}
    r = subprocess.run(WIDEPRINT + ["gui"], env=env, capture_output=True, text=True, timeout=60)
    assert r.returncode == 2
    assert len(r.stderr.strip().splitlines()) == 1 and "no display" in r.stderr
