"""CUPS in front of the Printer Application (docs/ipp.md, "CUPS queues and a shop of several
plotters"; issue 15): a shop of two plotter host PCs, each `wideprint serve --ipp` with its
own emulated printer and its own Printer Application on its own port, and a private cupsd
with a driverless queue for each (`lpadmin -m everywhere`) and a class of the two.
`lp` of a JPEG and a TIFF to a queue, and six jobs to the class, land in the wideprint
queues with the client's original file and print bit-exact on the emulator against
`wideprint rip` of the same file with the job's settings; CUPS spreads the class's jobs over
both plotters, each job printed once."""

import shutil
import subprocess
import sys
import time
from pathlib import Path

import numpy as np
import pytest

from support.images import ROOT, random_planes, write_cmyk_tiff
from support.private_cups import IppServe, assert_bit_exact, private_cupsd, sha256, wait_job
from support.cups import conversions_from
from wideprint.app.ipp.bridge import find_binary

PLOTTERS = ("plotter1", "plotter2")           # one per host PC, each its own server
CONVS = ROOT / "resources" / "cups" / "wideprint.convs"


@pytest.fixture(scope="module")
def shop(tmp_path_factory):
    """The two plotter hosts: {printer name: IppServe}."""
    if find_binary() is None:
        pytest.fail("the Printer Application is not built: `make test` (or make install) builds "
                    "app/ipp/wideprint-ipp from libpappl-dev (resources/debian-packages.txt)")
    hosts = {}
    try:
        for name in PLOTTERS:
            hosts[name] = IppServe(tmp_path_factory.mktemp(name), [name])
        yield hosts
    finally:
        for serve in hosts.values():
            serve.stop()


def _ppd(cups, name: str) -> str:
    """The PPD cupsd made for a driverless queue, once it is there."""
    deadline = time.monotonic() + 10
    ppd = cups.dir / "conf" / "ppd" / f"{name}.ppd"
    while not ppd.exists() and time.monotonic() < deadline:
        time.sleep(0.1)
    return ppd.read_text()


def _queues(cupsd, shop: dict, names) -> None:
    """A driverless queue for each plotter, as docs/ipp.md tells an operator: the URI with
    the server's token as password, on the loopback address."""
    for name in names:
        uri = shop[name].auth_uri[name].replace("localhost", "127.0.0.1")
        cupsd.run("lpadmin", "-h", cupsd.host, "-p", name, "-E", "-v", uri,
                  "-m", "everywhere", timeout=60)
        # cupsd makes the queue's PPD after lpadmin returns; a job queued before it
        # exists goes out raw (docs/ipp.md): the tests want the queue as it stays
        _ppd(cupsd, name)


@pytest.fixture(scope="module")
def plain_cups(tmp_path_factory, shop):
    """A CUPS server as installed: a driverless queue for plotter1, no wideprint.convs."""
    for cupsd in private_cupsd(tmp_path_factory):
        _queues(cupsd, shop, ["plotter1"])
        yield cupsd


@pytest.fixture(scope="module")
def cups(tmp_path_factory, shop):
    """The shop's CUPS server: resources/cups/wideprint.convs installed, a driverless queue
    per plotter and the class `shop` of both."""
    for cupsd in private_cupsd(tmp_path_factory, conf=(CONVS,)):
        _queues(cupsd, shop, PLOTTERS)
        for name in PLOTTERS:
            cupsd.run("lpadmin", "-h", cupsd.host, "-p", name, "-c", "shop")
        cupsd.run("cupsenable", "-h", cupsd.host, "shop")
        cupsd.run("cupsaccept", "-h", cupsd.host, "shop")
        yield cupsd


@pytest.fixture(scope="module", params=["with cups-filters", "cups-daemon alone"])
def installed_cups(request, tmp_path_factory, shop):
    """A shop's CUPS server as Debian installs it — the `cups` package with cups-filters (a
    desktop), or cups-daemon alone — running, where `wideprint cups install` put the
    conversions and told cupsd to reload; then a driverless queue for plotter1."""
    filters = request.param == "with cups-filters"
    if filters and not conversions_from("application/pdf"):
        pytest.fail("cups-filters is not installed: apt-get install cups-filters "
                    "(resources/debian-packages.txt; .ci/run installs it)")
    for cupsd in private_cupsd(tmp_path_factory, filters=filters):
        # what this CUPS converts before the rules: cups-filters' PDF from a TIFF and a
        # PDF, or nothing at all (a queue refuses both)
        mime = [Path(cupsd.dir / "data" / "mime")] if not filters else [Path("/usr/share/cups/mime")]
        for fmt in ("image/tiff", "application/pdf"):
            assert bool(conversions_from(fmt, mime)) == filters, (fmt, conversions_from(fmt, mime))
        before = cupsd.mime_loads()
        r = subprocess.run([sys.executable, "-m", "wideprint.app.cli", "cups", "install",
                            "--server-root", str(cupsd.dir / "conf"),
                            "--cupsd-pid", str(cupsd.proc.pid)],
                           capture_output=True, text=True, timeout=60)
        assert r.returncode == 0, r.stdout + r.stderr
        assert "wideprint.convs: installed" in r.stdout and "SIGHUP" in r.stdout, r.stdout
        cupsd.wait_reload(before)
        assert (cupsd.dir / "conf" / "wideprint.convs").read_bytes() == CONVS.read_bytes()
        _queues(cupsd, shop, ["plotter1"])
        yield request.param, cupsd


def _jpeg(path, seed: int, dpi: int = 200):
    from PIL import Image
    px = (np.random.default_rng(seed).random((150, 220, 3)) * 255).astype(np.uint8)
    Image.fromarray(px).save(path, quality=85, dpi=(dpi, dpi))
    return path


def lp(cups, dest: str, path, *opts: str) -> str:
    out = cups.run("lp", "-h", cups.host, "-d", dest, *opts, str(path))
    assert f"request id is {dest}-" in out
    return out.split()[3]                          # "request id is shop-7 (1 file(s))"


def _pdf(path):
    """A one-page PDF (2 x 1 in) drawn by Ghostscript."""
    if not shutil.which("gs"):
        pytest.fail("Ghostscript (gs) is not installed: resources/debian-packages.txt lists it "
                    "and .ci/run installs it")
    ps = path.with_suffix(".ps")
    ps.write_bytes(b"%!PS\n<< /PageSize [144 72] >> setpagedevice 0 0.6 0.4 0 setcmykcolor\n"
                   b"10 10 100 40 rectfill 1 0 0 setrgbcolor 60 20 70 45 rectfill showpage\n")
    subprocess.run(["gs", "-q", "-dSAFER", "-dBATCH", "-dNOPAUSE", "-sDEVICE=pdfwrite",
                    f"-sOutputFile={path}", str(ps)], check=True, capture_output=True)
    return path


def test_conversions_from_reads_convs_files_as_cupsd_does(tmp_path):
    (tmp_path / "filter").mkdir()
    (tmp_path / "filter" / "imagetopdf").write_text("")
    (tmp_path / "mime.convs").write_text("# image/tiff application/pdf 33 imagetopdf\n"
                                         "image/jpeg application/pdf 33 imagetopdf\n")
    assert conversions_from("image/tiff", [tmp_path], tmp_path / "filter") == []
    (tmp_path / "cupsfilters.convs").write_text(
        "image/tiff\tapplication/vnd.cups-pdf\t65\timagetopdf\n"
        "image/*   application/vnd.cups-raster 100 imagetoraster  # not installed\n")
    assert conversions_from("image/tiff", [tmp_path], tmp_path / "filter") == [
        "cupsfilters.convs: image/tiff application/vnd.cups-pdf 65 imagetopdf"]


def test_a_driverless_queue_passes_jpeg_through_and_tiff_only_raw(plain_cups, shop, tmp_path):
    """What `-m everywhere` makes of the printer (docs/ipp.md, "CUPS queues"): CUPS'
    generated PPD passes JPEG and PNG through unchanged; it has no TIFF entry (IPP Everywhere
    knows no TIFF), so without wideprint.convs a TIFF is not passed through: where CUPS has
    no filter for TIFF (cups-daemon alone) it is refused, where it has one (cups-filters, on
    any desktop Debian) CUPS converts it and wideprint gets CUPS' conversion, not the
    client's file.  Sent raw it is passed through.  JPEG and the raw TIFF print bit-exact
    from the client's original file."""
    ppd = _ppd(plain_cups, "plotter1")
    assert '*cupsFilter2: "image/jpeg image/jpeg 0 -"' in ppd
    assert '*cupsFilter2: "image/png image/png 0 -"' in ppd
    assert "image/tiff" not in ppd and "*DefaultResolution: 300dpi" in ppd
    serve = shop["plotter1"]
    jpeg = _jpeg(tmp_path / "poster.jpg", seed=41)
    tif = write_cmyk_tiff(tmp_path / "plan.tif", random_planes(120, 90, seed=42))
    lp(plain_cups, "plotter1", jpeg, "-n", "2")
    converted = write_cmyk_tiff(tmp_path / "converted.tif", random_planes(60, 50, seed=44))
    r = subprocess.run(["lp", "-h", plain_cups.host, "-d", "plotter1", str(converted)],
                       capture_output=True, text=True, timeout=30, env=plain_cups.env)
    filters = conversions_from("image/tiff")
    if filters:
        assert r.returncode == 0, f"CUPS has {filters}, yet refused the TIFF: {r.stderr}"
    else:
        assert r.returncode != 0 and 'Unsupported document-format "image/tiff"' in r.stderr, \
            r.stdout + r.stderr
    lp(plain_cups, "plotter1", tif, "-o", "raw")
    job = wait_job(serve.client, "poster.jpg", timeout=240)
    # the JPEG went through CUPS unchanged (sha256), with CUPS' print-quality normal
    assert job["client"] == "ipp:root" and job["preset"] == "default"
    assert job["copies"] == 2 and job["copies_done"] == 2
    assert_bit_exact(serve, job, jpeg, "plotter1")
    job = wait_job(serve.client, "plan.tif", timeout=240)
    assert job["preset"] == "default"
    assert_bit_exact(serve, job, tif, "plotter1")
    if filters:
        # CUPS planned a conversion of the TIFF and, a queue's jobs going out in order, had
        # dealt with it before the raw one: the plotter did not get the client's file.  (A
        # desktop's cupsd sends a PDF; this private one's filters, run as `lp`, cannot reach
        # its spool in the test's 0700 temporary folder, so there the conversion fails.)
        log = (plain_cups.dir / "log" / "error_log").read_text(errors="replace")
        assert "(image/tiff to " in log, "CUPS planned no conversion of the TIFF" + plain_cups.log()
        sums = {j["sha256"] for j in serve.client.jobs("done,failed,cancelled,queued,held,printing")}
        assert sha256(converted) not in sums, "a TIFF went through a driverless queue unconverted"


def test_with_wideprint_convs_tiff_and_pdf_pass_through_unchanged(cups, shop, tmp_path):
    """resources/cups/wideprint.convs: `lp file.tif` and `lp file.pdf`, no -o raw."""
    serve = shop["plotter2"]
    tif = write_cmyk_tiff(tmp_path / "map.tif", random_planes(90, 140, seed=43))
    pdf = _pdf(tmp_path / "flyer.pdf")
    lp(cups, "plotter2", tif, "-o", "print-quality=5")
    lp(cups, "plotter2", pdf)
    job = wait_job(serve.client, "map.tif", timeout=240)
    assert job["preset"] == "photo"                   # print-quality high
    assert_bit_exact(serve, job, tif, "plotter2")
    job = wait_job(serve.client, "flyer.pdf", timeout=240)
    assert_bit_exact(serve, job, pdf, "plotter2")


def test_cups_install_passes_tiff_and_pdf_unchanged_with_or_without_cups_filters(
        installed_cups, shop, tmp_path):
    """`wideprint cups install` on a running CUPS: `lp file.tif` and `lp file.pdf` (no -o
    raw) reach the plotter as the client's files and print bit-exact — where cups-filters
    would otherwise turn them into its own PDF, and where CUPS alone would refuse them."""
    kind, cups = installed_cups
    tag = "filters" if kind == "with cups-filters" else "plain"
    serve = shop["plotter1"]
    tif = write_cmyk_tiff(tmp_path / f"{tag}-map.tif", random_planes(80, 120, seed=61))
    pdf = _pdf(tmp_path / f"{tag}-flyer.pdf")
    lp(cups, "plotter1", tif)
    lp(cups, "plotter1", pdf)
    job = wait_job(serve.client, tif.name, timeout=240)
    assert_bit_exact(serve, job, tif, "plotter1")
    job = wait_job(serve.client, pdf.name, timeout=240)
    assert_bit_exact(serve, job, pdf, "plotter1")


def test_cups_install_status_and_uninstall(tmp_path):
    """The command on a ServerRoot: installed once (a second time: already), status, removed;
    no ServerRoot: exit 1, naming it."""
    def cli(*args):
        return subprocess.run([sys.executable, "-m", "wideprint.app.cli", "cups", *args,
                               "--server-root", str(tmp_path / "etc-cups")],
                              capture_output=True, text=True, timeout=60)
    r = cli("install", "--no-reload")
    assert r.returncode == 1 and "etc-cups is not there" in r.stderr, r.stdout + r.stderr
    (tmp_path / "etc-cups").mkdir()
    assert cli("status").returncode == 1
    r = cli("install", "--no-reload")
    assert r.returncode == 0 and "installed" in r.stdout, r.stdout + r.stderr
    dest = tmp_path / "etc-cups" / "wideprint.convs"
    assert dest.read_bytes() == CONVS.read_bytes() and dest.stat().st_mode & 0o777 == 0o644
    r = cli("install", "--no-reload")
    assert r.returncode == 0 and "already installed" in r.stdout
    assert cli("status").returncode == 0
    r = cli("uninstall", "--no-reload")
    assert r.returncode == 0 and "removed" in r.stdout and not dest.exists()


def test_a_class_spreads_six_jobs_over_two_plotters_each_printed_once(cups, shop, tmp_path):
    files = {}
    for i in range(6):
        name = f"shop-{i}.jpg" if i % 2 == 0 else f"shop-{i}.tif"
        path = tmp_path / name
        files[name] = _jpeg(path, seed=50 + i) if i % 2 == 0 else \
            write_cmyk_tiff(path, random_planes(150, 120, seed=50 + i))
    ids = [lp(cups, "shop", path) for path in files.values()]
    # CUPS reports every class job completed ...
    deadline = time.monotonic() + 60
    while time.monotonic() < deadline:
        done = cups.run("lpstat", "-h", cups.host, "-W", "completed", "-o", "shop").split()
        if all(i in done for i in ids):
            break
        time.sleep(0.3)
    assert all(i in done for i in ids), cups.run("lpstat", "-h", cups.host, "-W", "all", "-o") \
        + cups.log()
    # ... and each printed once, bit-exact, on one plotter or the other, both used
    printed = {name: [] for name in files}
    for plotter, serve in shop.items():
        for job in serve.client.jobs("done,failed,cancelled,queued,held,printing"):
            if job["name"] in printed:
                printed[job["name"]].append((plotter, job))
    assert {n: len(p) for n, p in printed.items()} == {n: 1 for n in files}, printed
    for name, [(plotter, job)] in printed.items():
        assert job["sha256"] == sha256(files[name])
        assert_bit_exact(shop[plotter], job, files[name], plotter)
    per_plotter = {p: sum(pl == p for [(pl, _)] in printed.values()) for p in PLOTTERS}
    assert all(n >= 1 for n in per_plotter.values()), per_plotter
