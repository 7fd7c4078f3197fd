"""CUPS lands jobs in the wideprint queue (issue 7, docs/server.md "CUPS"): a private cupsd
on its own port runs the `wideprint://` backend (resources/cups/wideprint) for a queue
added with lpadmin and the wideprint PPD; `lp -h 127.0.0.1:PORT -d wideprint file.tif`
prints on the emulator, bit-exact."""

import shutil
import subprocess
import time

import numpy as np
import pytest

from support.images import ROOT, random_planes, write_cmyk_tiff
from support.private_cups import private_cupsd
from support.cups import conversions_from
from wideprint.app.client import Client
from wideprint.rip.planes import read_planes

BACKEND = ROOT / "resources" / "cups" / "wideprint"
PPD = ROOT / "resources" / "cups" / "wideprint.ppd"
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
    yield from private_cupsd(tmp_path_factory, {"wideprint": BACKEND})


@pytest.fixture(scope="module")
def queue(cupsd, wideprint_server):
    cupsd.run("lpadmin", "-h", cupsd.host, "-p", "wideprint", "-E",
              "-v", f"wideprint://{wideprint_server.state_dir}", "-P", str(PPD),
              "-D", "wideprint 3.4 m CMYK")
    out = cupsd.run("lpstat", "-h", cupsd.host, "-v", "wideprint")
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
    out = queue.run("lp", "-h", queue.host, "-d", "wideprint",
              "-o", "WPPasses=2", "-o", "WPBidir=True", str(src))
    assert "request id is wideprint-" in out
    job = _wait_job(client, "poster.tif", known)
    assert job["state"] == "done", job["message"] + queue.log()
    assert job["source"] == "api" and job["client"].startswith("cups:")
    assert job["settings"] == {"passes": 2, "bidir": True}
    media = wideprint_server.root / "media" / f"job-{job['id']}.tif"
    assert np.array_equal(read_planes(media), planes)


def test_lp_raw_and_copies(queue, wideprint_server, tmp_path):
    planes = random_planes(60, 200, seed=32)
    src = write_cmyk_tiff(tmp_path / "raw.tif", planes)
    client = Client(wideprint_server.state_dir)
    known = {j["id"] for j in client.jobs()}
    queue.run("lp", "-h", queue.host, "-d", "wideprint", "-o", "raw", "-n", "2",
        "-o", "WPPreset=banner", str(src))
    job = _wait_job(client, "raw.tif", known)
    assert job["state"] == "done", job["message"]
    assert job["copies"] == 2 and job["copies_done"] == 2 and job["preset"] == "banner"
    assert np.array_equal(read_planes(wideprint_server.root / "media" / f"job-{job['id']}.tif"),
                          planes)


def test_cups_refuses_a_format_the_printer_does_not_take(queue, tmp_path):
    """Plain text: the PPD takes none.  CUPS refuses it unless it has a filter for it
    (Debian's cups-filters, on any desktop: texttopdf), and then takes it to convert."""
    txt = tmp_path / "note.txt"
    txt.write_text("hello\n")
    r = subprocess.run(["lp", "-h", queue.host, "-d", "wideprint", str(txt)],
                       capture_output=True, text=True, timeout=30, env=queue.env)
    filters = conversions_from("text/plain")
    if filters:
        assert r.returncode == 0, f"CUPS has {filters}, yet refused the text: {r.stderr}"
    else:
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
    queue.run("lp", "-h", queue.host, "-d", "wideprint", str(pdf))
    job = _wait_job(client, "flyer.pdf", known, timeout=90)
    assert job["state"] == "done", job["message"] + queue.log()
    planes = tmp_path / "planes.tif"
    RipJob(str(pdf), RipSettings(), load_profile()).write_planes(planes)
    media = read_planes(wideprint_server.root / "media" / f"job-{job['id']}.tif")
    assert media.shape == (round(72 / 72 * 25400 / 68.55), 600, 4)
    assert np.array_equal(media, read_planes(planes))
