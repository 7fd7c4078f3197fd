"""DNS-SD (issue 15; docs/ipp.md "DNS-SD"): the Printer Application's printers are found by
any machine of the network the way CUPS, macOS, Windows and phones find printers, and print
from what they find.

The test runs itself again inside private namespaces (tests/support/private_mdns.py): an avahi-daemon
on a private veth interface, so nothing is announced on the machine's network. There it
starts `wideprint serve --ipp` on the network (`--ipp-listen '*'`) with two printers, browses
with avahi and with CUPS' own `ippfind`, checks what IPP Everywhere clients read from the
announcement (the `_print` and `_universal` subtypes, the TXT keys of the IPP Everywhere
spec and PWG 5100.14), resolves the announced host name by mDNS, prints a JPEG and a TIFF to
the announced address, port and resource (bit-exact against `wideprint rip`), and checks
that the default loopback-only Printer Application announces nothing."""

from __future__ import annotations

import os
import subprocess
import time
from pathlib import Path

import numpy as np
import pytest

from tests.support import private_mdns
from tests.support.private_cups import IppServe, assert_bit_exact, wait_job

FORMATS = {"image/jpeg", "image/png", "image/tiff", "application/pdf", "image/pwg-raster",
           "image/urf"}


def _images(d: Path) -> tuple[Path, Path]:
    from PIL import Image
    rng = np.random.default_rng(15)
    y, x = np.mgrid[0:90, 0:120]
    rgb = np.stack([x * 2, y * 2, (x + y) % 256], axis=-1).astype(np.uint8)
    rgb[20:40, 30:60] = rng.integers(0, 256, (20, 30, 3), dtype=np.uint8)
    jpg, tif = d / "chart.jpg", d / "chart.tif"
    Image.fromarray(rgb).save(jpg, quality=92)
    Image.fromarray(rgb[::-1]).save(tif, dpi=(300, 300))
    return jpg, tif


def _ipptool_print(uri: str, path: Path, fmt: str, job_name: str) -> str:
    test = path.with_suffix(".test")
    test.write_text(
        '{\n  NAME "print from DNS-SD"\n  OPERATION Print-Job\n'
        '  GROUP operation-attributes-tag\n  ATTR charset attributes-charset utf-8\n'
        '  ATTR naturalLanguage attributes-natural-language en\n  ATTR uri printer-uri $uri\n'
        '  ATTR name requesting-user-name $user\n'
        f'  ATTR mimeMediaType document-format {fmt}\n  ATTR name job-name "{job_name}"\n'
        f'  FILE "{path}"\n  STATUS successful-ok\n}}\n')
    out = subprocess.run(["ipptool", "-tv", uri, str(test)], capture_output=True, text=True,
                         timeout=60)
    assert out.returncode == 0, out.stdout + out.stderr
    return out.stdout


def _wait_found(mdns, regtype: str, names: set[str], timeout: float = 20) -> list[dict]:
    deadline = time.monotonic() + timeout
    while True:
        found = [s for s in mdns.browse(regtype) if s["name"] in names]
        if {s["name"] for s in found} == names or time.monotonic() > deadline:
            return found
        time.sleep(0.5)


def test_printers_are_found_by_dns_sd_and_print_from_what_is_found(tmp_path):
    if not private_mdns.inside():
        if os.geteuid() != 0:
            pytest.skip("the private mDNS network needs root (network, mount, PID namespaces)")
        why = private_mdns.mdns_missing()
        if why:
            pytest.fail(f"the private mDNS network cannot be made: {why}")
        nodeid = "tests/test_ipp_dnssd.py::test_printers_are_found_by_dns_sd_and_print_from_what_is_found"
        out = private_mdns.run_inside(nodeid, tmp_path / "inside")
        assert out.returncode == 0, f"inside the namespaces:\n{out.stdout}\n{out.stderr}"
        assert "1 passed" in out.stdout, out.stdout
        return

    mdns = private_mdns.PrivateMdns(tmp_path / "mdns")
    try:
        _found_and_printed(mdns, tmp_path)
        _loopback_announces_nothing(mdns, tmp_path)
    finally:
        mdns.stop()


def _found_and_printed(mdns, tmp_path: Path) -> None:
    (tmp_path / "net").mkdir()
    serve = IppServe(tmp_path / "net", ["left", "right"], "--ipp-listen", "*")
    try:
        model = serve.profile["left"].name
        names = {f"left - {model}"[:63], f"right - {model}"[:63]}
        ipp = _wait_found(mdns, "_ipp._tcp", names)
        assert {s["name"] for s in ipp} == names, (ipp, mdns.log("avahi")[-3000:])
        by_name = {s["name"]: s for s in ipp}
        for printer in ("left", "right"):
            s = by_name[f"{printer} - {model}"[:63]]
            txt = s["txt"]
            # what IPP Everywhere clients read from the TXT record (PWG 5100.14 section 4.2)
            assert s["host"] == f"{private_mdns.HOST_NAME}.local"
            assert s["address"] == private_mdns.ADDRESS
            assert s["port"] == serve.port
            assert txt["rp"] == f"ipp/print/{printer}"
            assert txt["txtvers"] == "1" and txt["qtotal"] == "1"
            assert FORMATS <= set(txt["pdl"].split(",")), txt["pdl"]
            assert txt["Color"] == "T"
            assert "roll" in txt["kind"].split(","), txt
            assert txt["UUID"] and txt["ty"] == model[:len(txt["ty"])]
            assert "URF" in txt and "PaperMax" in txt
            assert txt.get("TLS"), txt              # on the network PAPPL offers TLS (ipps)
        # the subtypes print dialogs browse for
        for sub in ("_print._sub._ipp._tcp", "_universal._sub._ipp._tcp"):
            assert {s["name"] for s in _wait_found(mdns, sub, names)} == names, sub
        assert {s["name"] for s in _wait_found(mdns, "_ipps._tcp", names)} == names

        # CUPS' own discovery: ippfind, as `lpadmin -m everywhere` users and cups-browsed use
        out = subprocess.run(["ippfind", "-T", "5", "_ipp._tcp,_print", "--txt-rp", "^ipp/print/",
                              "-x", "echo", "{service_uri}", ";"],
                             capture_output=True, text=True, timeout=60)
        uris = set(out.stdout.split())
        host = f"{private_mdns.HOST_NAME}.local"
        assert uris == {f"ipp://{host}:{serve.port}/ipp/print/{p}" for p in ("left", "right")}, out

        # the announced host name resolves by mDNS; print to what was found, bit-exact
        address = mdns.resolve(host)
        assert address == private_mdns.ADDRESS
        jpg, tif = _images(tmp_path)
        for printer, path, fmt in (("left", jpg, "image/jpeg"), ("right", tif, "image/tiff")):
            s = by_name[f"{printer} - {model}"[:63]]
            uri = f"ipp://wp:{serve.token}@{address}:{s['port']}/{s['txt']['rp']}"
            name = f"dnssd-{printer}{path.suffix}"
            _ipptool_print(uri, path, fmt, name)
            assert_bit_exact(serve, wait_job(serve.client, name), path, printer)
    finally:
        serve.stop()
    # a stopped Printer Application withdraws its printers
    deadline = time.monotonic() + 10
    while mdns.browse("_ipp._tcp") and time.monotonic() < deadline:
        time.sleep(0.5)
    assert mdns.browse("_ipp._tcp") == []


def _loopback_announces_nothing(mdns, tmp_path: Path) -> None:
    """The default (`--ipp-listen localhost`): no one else can reach it, so it announces
    nothing (a network would see printers it cannot print to)."""
    (tmp_path / "lo").mkdir()
    serve = IppServe(tmp_path / "lo", ["left"])
    try:
        time.sleep(3)
        assert mdns.browse("_ipp._tcp") == []
        assert mdns.browse("_http._tcp") == []
        # it does print: the IPP side is up
        out = subprocess.run(["ipptool", "-t", serve.uris["left"], "get-printer-attributes.test"],
                             capture_output=True, text=True, timeout=60)
        assert out.returncode == 0, out.stdout
    finally:
        serve.stop()
