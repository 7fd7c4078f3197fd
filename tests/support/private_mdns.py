"""A private mDNS network for the DNS-SD test (tests/test_ipp_dnssd.py; docs/ipp.md "DNS-SD").

mDNS is multicast on the machine's real interfaces, and avahi-daemon has fixed paths and
talks over the D-Bus system bus, so a test cannot run it beside the machine's (or another
test's) the way it runs cupsd. It runs it in Linux namespaces of its own instead (root
only): a network namespace whose only multicast interface is one end of a veth pair
(`mdns0`, 10.99.0.1/24), a mount namespace with its own /run/dbus, /run/avahi-daemon and a
/etc/passwd that knows the `avahi` user, a UTS namespace with its own host name, and a PID
namespace, so every daemon the test starts dies with it. Nothing it announces leaves the
namespace; nothing of the machine's network is seen in it.

The avahi binaries are Debian's avahi-daemon and avahi-utils packages unpacked into
build/avahi by the Makefile (`make test` does it): not installed, so the machine gets no
mDNS service of its own. Nothing here installs anything."""

from __future__ import annotations

import ctypes
import os
import shutil
import subprocess
import sys
import time
from pathlib import Path

REPO = Path(__file__).resolve().parents[2]
AVAHI = REPO / "build" / "avahi"
AVAHI_DAEMON = AVAHI / "usr" / "sbin" / "avahi-daemon"
AVAHI_BROWSE = AVAHI / "usr" / "bin" / "avahi-browse"
AVAHI_RESOLVE = AVAHI / "usr" / "bin" / "avahi-resolve"
HOST_NAME = "wideprint-dnssd"          # the namespace's host name: HOST_NAME.local
ADDRESS = "10.99.0.1"
IFACE = "mdns0"
NS_ENV = "WIDEPRINT_TEST_PRIVATE_MDNS"   # set in the process that runs inside the namespaces

BUS_CONF = """<!DOCTYPE busconfig PUBLIC "-//freedesktop//DTD D-Bus Bus Configuration 1.0//EN"
 "http://www.freedesktop.org/standards/dbus/1.0/busconfig.dtd">
<busconfig>
  <type>system</type>
  <listen>unix:path=/run/dbus/system_bus_socket</listen>
  <auth>EXTERNAL</auth>
  <policy context="default">
    <allow user="*"/>
    <allow own="*"/>
    <allow send_destination="*"/>
    <allow receive_sender="*"/>
  </policy>
</busconfig>
"""

AVAHI_CONF = f"""[server]
host-name={HOST_NAME}
use-ipv4=yes
use-ipv6=no
allow-interfaces={IFACE}
ratelimit-interval-usec=1000000
ratelimit-burst=1000
[publish]
publish-workstation=no
publish-hinfo=no
"""


def mdns_missing() -> str | None:
    """Why the private mDNS network cannot be made here (None: it can)."""
    if os.geteuid() != 0:
        return "needs root (network, mount and PID namespaces)"
    missing = [str(p) for p in (AVAHI_DAEMON, AVAHI_BROWSE, AVAHI_RESOLVE) if not p.exists()]
    if missing:
        return (f"{', '.join(missing)} missing: `make test` unpacks Debian's avahi-daemon and "
                f"avahi-utils into build/avahi (apt-get download; .ci/run does it)")
    for tool in ("unshare", "ip", "dbus-daemon", "ippfind"):
        if not shutil.which(tool):
            return f"{tool} is missing (resources/debian-packages.txt; .ci/run installs it)"
    return None


def inside() -> bool:
    """Whether this process is the one `run_inside` started in the namespaces."""
    return os.environ.get(NS_ENV) == "1"


def run_inside(nodeid: str, basetemp: Path, timeout: float = 300) -> subprocess.CompletedProcess:
    """Run one test (pytest node id) again in new network, mount, UTS and PID namespaces."""
    env = dict(os.environ, **{NS_ENV: "1"})
    env["PYTHONPATH"] = os.pathsep.join(p for p in sys.path if p)
    cmd = ["unshare", "--net", "--mount", "--uts", "--pid", "--fork", "--kill-child",
           "--mount-proc", sys.executable, "-m", "pytest", "-q", "-p", "no:cacheprovider",
           "-p", "no:randomly", "--basetemp", str(basetemp), "-x", nodeid]
    return subprocess.run(cmd, cwd=REPO, env=env, capture_output=True, text=True,
                          timeout=timeout)


class PrivateMdns:
    """The network, D-Bus system bus and avahi-daemon, set up in the current process's (new)
    namespaces. `stop()` ends the daemons (the PID namespace would anyway)."""

    def __init__(self, d: Path):
        assert inside(), "PrivateMdns runs only inside run_inside()'s namespaces"
        self.dir = Path(d)
        self.dir.mkdir(parents=True, exist_ok=True)
        self.procs: list[subprocess.Popen] = []

        def sh(*cmd: str) -> None:
            subprocess.run(cmd, check=True, capture_output=True)

        name = HOST_NAME.encode()
        if ctypes.CDLL(None, use_errno=True).sethostname(name, len(name)) != 0:
            raise OSError(ctypes.get_errno(), "sethostname")
        sh("ip", "link", "set", "lo", "up")
        sh("ip", "link", "add", IFACE, "type", "veth", "peer", "name", IFACE + "-peer")
        sh("ip", "addr", "add", f"{ADDRESS}/24", "dev", IFACE)
        sh("ip", "link", "set", IFACE, "multicast", "on", "up")
        sh("ip", "link", "set", IFACE + "-peer", "up")
        for run in ("/run/dbus", "/run/avahi-daemon"):
            os.makedirs(run, exist_ok=True)
            sh("mount", "-t", "tmpfs", "tmpfs", run)
        # avahi-daemon chowns its runtime directory to the `avahi` user, even as root
        for db, line in (("passwd", "avahi:x:64999:64999::/nonexistent:/usr/sbin/nologin"),
                         ("group", "avahi:x:64999:")):
            text = Path("/etc", db).read_text()
            if not any(row.startswith("avahi:") for row in text.splitlines()):
                text += line + "\n"
            (self.dir / db).write_text(text)
            sh("mount", "--bind", str(self.dir / db), f"/etc/{db}")
        (self.dir / "bus.conf").write_text(BUS_CONF)
        (self.dir / "avahi.conf").write_text(AVAHI_CONF)
        self._start("dbus", ["dbus-daemon", "--nofork", "--nopidfile",
                             f"--config-file={self.dir / 'bus.conf'}"])
        self._wait(lambda: Path("/run/dbus/system_bus_socket").exists(), "the D-Bus system bus")
        self._start("avahi", [str(AVAHI_DAEMON), "--no-drop-root", "--no-chroot",
                              "--no-rlimits", "--debug", "-f", str(self.dir / "avahi.conf")])
        self._wait(lambda: "Server startup complete" in self.log("avahi"), "avahi-daemon")

    def _start(self, name: str, cmd: list[str]) -> None:
        log = open(self.dir / f"{name}.log", "w")
        self.procs.append(subprocess.Popen(cmd, stdout=log, stderr=subprocess.STDOUT))
        log.close()

    def _wait(self, ready, what: str, timeout: float = 20) -> None:
        deadline = time.monotonic() + timeout
        while not ready():
            if time.monotonic() > deadline or any(p.poll() is not None for p in self.procs):
                raise AssertionError(f"{what} did not start: {self.log('dbus')}\n{self.log('avahi')}")
            time.sleep(0.05)

    def log(self, name: str) -> str:
        try:
            return (self.dir / f"{name}.log").read_text()
        except OSError:
            return ""

    def browse(self, regtype: str) -> list[dict]:
        """Every service of that type (`_ipp._tcp`, `_print._sub._ipp._tcp`...) resolved, as
        avahi-browse's parsable output gives it: name, host, address, port, txt (dict)."""
        out = subprocess.run([str(AVAHI_BROWSE), "-rtpk", regtype], capture_output=True,
                             text=True, timeout=30, check=True).stdout
        found = []
        for line in out.splitlines():
            f = line.split(";", 9)
            if f[0] != "=" or len(f) < 10:
                continue
            txt = {}
            for item in _txt_items(f[9]):
                k, _, v = item.partition("=")
                txt[k] = v
            found.append({"name": _unescape(f[3]), "type": f[4], "host": f[6],
                          "address": f[7], "port": int(f[8]), "txt": txt})
        return found

    def resolve(self, host: str) -> str:
        """The IPv4 address mDNS gives for a .local host name."""
        out = subprocess.run([str(AVAHI_RESOLVE), "-4", "-n", host], capture_output=True,
                             text=True, timeout=30, check=True).stdout.split()
        assert len(out) == 2 and out[0] == host, f"avahi-resolve {host}: {out}"
        return out[1]

    def stop(self) -> None:
        for p in reversed(self.procs):
            p.terminate()
            try:
                p.wait(10)
            except subprocess.TimeoutExpired:
                p.kill()
                p.wait()


def _unescape(s: str) -> str:
    """avahi-browse's escapes in names: \\DDD (decimal byte) and \\X."""
    out, i, b = bytearray(), 0, s.encode()
    while i < len(b):
        if b[i:i + 1] == b"\\" and b[i + 1:i + 4].isdigit() and len(b[i + 1:i + 4]) == 3:
            out.append(int(b[i + 1:i + 4]))
            i += 4
        elif b[i:i + 1] == b"\\" and i + 1 < len(b):
            out.append(b[i + 1])
            i += 2
        else:
            out.append(b[i])
            i += 1
    return out.decode("utf-8", "replace")


def _txt_items(s: str) -> list[str]:
    """The TXT strings of avahi-browse -p: each in double quotes, separated by spaces."""
    items, cur, quoted, i = [], [], False, 0
    while i < len(s):
        c = s[i]
        if c == '"':
            if quoted:
                items.append("".join(cur))
                cur = []
            quoted = not quoted
        elif quoted and c == "\\" and i + 1 < len(s):
            cur.append(s[i + 1])
            i += 1
        elif quoted:
            cur.append(c)
        i += 1
    return items
