"""CUPS in front of the Printer Application (docs/ipp.md, "CUPS queues and a shop of several
plotters"; issue 15): a shop of two plotter host PCs, each `wideprint serve --ipp` with its
own emulated printer and its own Printer Application on its own port, and a private cupsd
with a driverless queue for each (`lpadmin -m everywhere`) and a class of the two.
`lp` of a JPEG and a TIFF to a queue, and six jobs to the class, land in the wideprint
queues with the client's original file and print bit-exact on the emulator against
`wideprint rip` of the same file with the job's settings; CUPS spreads the class's jobs over
both plotters, each job printed once."""

import subprocess
import time

import numpy as np
import pytest

from conftest import random_planes, write_cmyk_tiff
from private_cups import IppServe, assert_bit_exact, private_cupsd, sha256, wait_job
from wideprint.app.ipp.bridge import find_binary

PLOTTERS = ("plotter1", "plotter2")           # one per host PC, each its own server


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


@pytest.fixture(scope="module")
def cups(tmp_path_factory, shop):
    """The shop's CUPS server: a driverless queue per plotter (the URI with the server's
    token as password), and the class `shop` of both, as docs/ipp.md tells an operator."""
    for cupsd in private_cupsd(tmp_path_factory):
        for name, serve in shop.items():
            uri = serve.auth_uri[name].replace("localhost", "127.0.0.1")
            cupsd.run("lpadmin", "-h", cupsd.host, "-p", name, "-E", "-v", uri,
                      "-m", "everywhere", timeout=60)
            cupsd.run("lpadmin", "-h", cupsd.host, "-p", name, "-c", "shop")
        cupsd.run("cupsenable", "-h", cupsd.host, "shop")
        cupsd.run("cupsaccept", "-h", cupsd.host, "shop")
        yield cupsd


def _jpeg(path, seed: int, dpi: int = 200):
    from PIL import Image
    px = (np.random.default_rng(seed).random((150, 220, 3)) * 255).astype(np.uint8)
    Image.fromarray(px).save(path, quality=85, dpi=(dpi, dpi))
    return path


def lp(cups, dest: str, path, *opts: str) -> str:
    out = cups.run("lp", "-h", cups.host, "-d", dest, *opts, str(path))
    assert f"request id is {dest}-" in out
    return out.split()[3]                          # "request id is shop-7 (1 file(s))"


def _ppd(cups, name: str) -> str:
    deadline = time.monotonic() + 10
    ppd = cups.dir / "conf" / "ppd" / f"{name}.ppd"
    while not ppd.exists() and time.monotonic() < deadline:
        time.sleep(0.1)
    return ppd.read_text()


def test_the_driverless_queue_passes_jpeg_through_and_tiff_only_raw(cups):
    """What `-m everywhere` makes of the printer (docs/ipp.md): CUPS' generated PPD passes
    JPEG and PNG through unchanged; it has no TIFF entry (CUPS knows no IPP Everywhere
    TIFF), so a TIFF is refused unless sent raw."""
    ppd = _ppd(cups, "plotter1")
    assert '*cupsFilter2: "image/jpeg image/jpeg 0 -"' in ppd
    assert '*cupsFilter2: "image/png image/png 0 -"' in ppd
    assert "image/tiff" not in ppd
    assert "*DefaultResolution: 300dpi" in ppd


def test_lp_jpeg_and_tiff_to_a_driverless_queue_print_bit_exact(cups, shop, tmp_path):
    serve = shop["plotter1"]
    jpeg = _jpeg(tmp_path / "poster.jpg", seed=41)
    tif = write_cmyk_tiff(tmp_path / "plan.tif", random_planes(120, 90, seed=42))
    lp(cups, "plotter1", jpeg, "-n", "2")
    r = subprocess.run(["lp", "-h", cups.host, "-d", "plotter1", str(tif)],
                       capture_output=True, text=True, timeout=30, env=cups.env)
    assert r.returncode != 0 and 'Unsupported document-format "image/tiff"' in r.stderr
    lp(cups, "plotter1", tif, "-o", "raw")
    job = wait_job(serve.client, "poster.jpg", timeout=60)
    # the JPEG went through CUPS unchanged (sha256), with CUPS' print-quality normal
    assert job["client"] == "ipp:root" and job["preset"] == "default"
    assert job["copies"] == 2 and job["copies_done"] == 2
    assert_bit_exact(serve, job, jpeg, "plotter1")
    job = wait_job(serve.client, "plan.tif", timeout=60)
    assert job["preset"] == "default"
    assert_bit_exact(serve, job, tif, "plotter1")


def test_a_class_spreads_six_jobs_over_two_plotters_each_printed_once(cups, shop, tmp_path):
    files = {}
    for i in range(6):
        name = f"shop-{i}.jpg" if i % 2 == 0 else f"shop-{i}.tif"
        path = tmp_path / name
        files[name] = _jpeg(path, seed=50 + i) if i % 2 == 0 else \
            write_cmyk_tiff(path, random_planes(150, 120, seed=50 + i))
    ids = [lp(cups, "shop", path, *(() if name.endswith(".jpg") else ("-o", "raw")))
           for name, path in files.items()]
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
