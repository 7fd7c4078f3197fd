"""wideprint's pytest plugin (docs/acceptance.md): fixtures and assertions for acceptance
tests of RIP settings, printer profiles, firmware and releases, against the emulator or a
real printer.  Installed with the package (entry point `pytest11: wideprint`), so a test
file anywhere can use it:

    def test_chart(print_job, wideprint_rip):
        result = print_job("chart.tif", passes=2, dpi=300)
        assert_media_equals_planes(result, wideprint_rip("chart.tif", passes=2, dpi=300))

Options: --wideprint-device SPEC (default: the in-process emulator), --wideprint-profile
TOML, --wideprint-artifacts DIR (diff images, predicted scans; default: each test's
tmp_path), --wideprint-scan TIFF (a scan of the print, for assert_scan_matches).
"""

from __future__ import annotations

import re
from pathlib import Path

import pytest

from . import api
from .devices import is_emulator_spec

_RUNNING: list = []                  # the running test's request (diff images go beside it)


# -- options and fixtures --------------------------------------------------------------------
def pytest_addoption(parser):
    group = parser.getgroup("wideprint", "wideprint acceptance tests")
    group.addoption("--wideprint-device", default="emulator", metavar="SPEC",
                    help="the printer the tests print on (default: the in-process emulator)")
    group.addoption("--wideprint-profile", default=None, metavar="TOML",
                    help="printer profile (default: the built-in one)")
    group.addoption("--wideprint-artifacts", default=None, metavar="DIR",
                    help="where failing comparisons write their diff images "
                         "(default: the test's tmp_path)")
    group.addoption("--wideprint-scan", default=None, metavar="TIFF",
                    help="a scan of the print (with its resolution tags): assert_scan_matches "
                         "compares it with the physical model's prediction")


def pytest_configure(config):
    config.addinivalue_line("markers", "emulator_only: needs the emulator (media read-back, "
                            "fault injection); skipped on a real printer")


def pytest_runtest_setup(item):
    if item.get_closest_marker("emulator_only") and \
            not is_emulator_spec(item.config.getoption("--wideprint-device")):
        pytest.skip("needs the emulator (--wideprint-device is a real printer)")


@pytest.fixture(autouse=True)
def _wideprint_running_test(request):
    _RUNNING.append(request)
    yield
    _RUNNING.pop()


@pytest.fixture
def wideprint_device(request) -> str:
    """The device spec the tests print on."""
    return request.config.getoption("--wideprint-device")


@pytest.fixture
def wideprint_scan(request) -> Path | None:
    """The scan given with --wideprint-scan, or None."""
    scan = request.config.getoption("--wideprint-scan")
    return Path(scan) if scan else None


@pytest.fixture
def wideprint_profile(request):
    """The printer profile (validated)."""
    return api.load_profile(request.config.getoption("--wideprint-profile"))


@pytest.fixture
def wideprint_printer(wideprint_device, wideprint_profile, tmp_path):
    """A factory of printers kept for the test: `wideprint_printer(faults=[...])` gives an
    `api.EmulatedPrinter` (state kept between its jobs); all are closed after the test."""
    made = []

    def make(faults=None, profile=None, **kw):
        if faults and not is_emulator_spec(wideprint_device):
            pytest.skip("fault injection needs the emulator")
        p = api.EmulatedPrinter(profile or wideprint_profile, faults=faults,
                                device=wideprint_device, workdir=tmp_path / f"printer-{len(made) + 1}", **kw)
        made.append(p)
        return p
    yield make
    for p in made:
        p.close()


@pytest.fixture
def print_job(wideprint_printer):
    """`print_job(file, settings=None, faults=None, **settings) -> api.PrintResult` on a
    fresh printer (the emulator: media, report and event log; a real printer: the report)."""
    def run(file, settings=None, *, faults=None, **kw):
        return wideprint_printer(faults=faults).print(file, settings, **kw)
    return run


@pytest.fixture
def wideprint_rip(wideprint_profile):
    """`wideprint_rip(file, settings=None, **settings) -> planes`: what the RIP means."""
    def run(file, settings=None, **kw):
        return api.rip(file, settings, profile=wideprint_profile, **kw)
    return run


@pytest.fixture
def wideprint_server(tmp_path, wideprint_profile):
    """A running print server (its own state directory, the in-process emulator, API on a
    free loopback port) and a client of it: `server.client.submit(path)`,
    `server.client.wait(job_id)`, `server.media(job_id)`."""
    from .server import PrintServer, ServerConfig
    from .client import Client
    media = tmp_path / "server-media"
    srv = PrintServer(ServerConfig(state_dir=tmp_path / "server-state", media_dir=media, port=0,
                                   profile_path=wideprint_profile.path))
    srv.start()
    srv.client = Client(srv.state_dir)
    srv.media = lambda job_id: api.read_planes(media / f"job-{job_id}.tif")
    yield srv
    srv.client.close()
    srv.stop()


# -- assertions that explain themselves ------------------------------------------------------------
def _artifacts() -> Path | None:
    """The running test's folder for diff images: --wideprint-artifacts/NODEID, else its
    tmp_path (made only when a comparison fails)."""
    if not _RUNNING:
        return None
    request = _RUNNING[-1]
    base = request.config.getoption("--wideprint-artifacts")
    if base:
        return Path(base) / re.sub(r"[^\w.-]+", "_", request.node.nodeid)
    return request.getfixturevalue("tmp_path")


def assert_media_equals_planes(result: api.PrintResult, planes=None, *, name: str = "diff"):
    """What landed equals what the RIP meant, dot for dot.  `planes`: an array or TIFF
    (default: a test print's own planes).  On failure: the first differing dots, drops
    missing and stray per ink, and a diff image beside the test's artifacts.  On a real
    printer (no media read-back) it checks what the device reported instead: the job done,
    every stroke printed."""
    __tracebackhide__ = True
    if result.media is None:
        if not result.ok:
            pytest.fail(f"{result.file}: the job {result.state}: {result.message}")
        rep = result.report
        total, printed = rep.get("strokes_total"), rep.get("strokes_printed")
        if total is not None and printed is not None and \
                printed + rep.get("strokes_skipped", 0) != total:
            pytest.fail(f"{result.file}: the printer reported {printed} of {total} strokes")
        return
    planes = result.planes if planes is None else planes
    if planes is None:
        raise ValueError("assert_media_equals_planes: give the planes to compare with")
    cmp = api.compare(result, planes)
    if cmp.equal:
        return
    msg = f"{result.file}: " + cmp.explain()
    where = _artifacts()
    if where is not None and cmp.shape_a == cmp.shape_b:
        where.mkdir(parents=True, exist_ok=True)
        image = api.diff_image(result, planes, where / f"{name}.png")
        msg += f"\n  diff image (red missing, blue stray): {image}"
    pytest.fail(msg)


def assert_ink_within(result: api.PrintResult, expected_ml, rel: float = 0.05):
    """Ink per channel (ml, C M Y K) within `rel` of `expected_ml` (or of another result's)."""
    __tracebackhide__ = True
    want = expected_ml.ink_ml if isinstance(expected_ml, api.PrintResult) else list(expected_ml)
    got = result.ink_ml
    bad = [(c, g, w) for c, g, w in zip("CMYK", got, want) if abs(g - w) > rel * max(abs(w), 1e-12)]
    if bad:
        pytest.fail(f"{result.file}: ink outside ±{rel:.0%}: "
                    + ", ".join(f"{c} {g:.6f} ml (expected {w:.6f})" for c, g, w in bad))


def assert_no_underrun(result: api.PrintResult):
    """No head FIFO ran dry and no stroke had to pause for data."""
    __tracebackhide__ = True
    starved = [e for e in result.events if e.get("event") == "starved"]
    if "UNDERRUN" in " ".join(result.faults) or starved:
        pytest.fail(f"{result.file}: FIFO underrun: {len(starved)} starved strokes, faults {result.faults}")


def assert_fault(result: api.PrintResult, words: str):
    """The job failed with a printer fault whose plain words contain `words`."""
    __tracebackhide__ = True
    if result.ok or words.lower() not in result.message.lower():
        pytest.fail(f"{result.file}: expected a fault '{words}', got state {result.state}"
                    + (f": {result.message}" if result.message else ""))


def assert_nothing_printed_after_fault(result: api.PrintResult):
    """After the printer latched a fault, no stroke fired a drop."""
    __tracebackhide__ = True
    events = result.events
    at = next((i for i, e in enumerate(events) if e.get("event") == "fault"), None)
    if at is None:
        pytest.fail(f"{result.file}: no fault happened")
    # the stroke the fault stopped logs its line (with the fault) after the fault itself
    after = [e for e in events[at + 1:] if e.get("event") == "line" and e.get("fired", 0) > 0
             and e.get("fault") in (None, "NONE")]
    if after:
        pytest.fail(f"{result.file}: {len(after)} strokes fired after the fault "
                    f"({events[at].get('fault')}): {after[:3]}")


__all__ = ["assert_fault", "assert_ink_within", "assert_media_equals_planes",
           "assert_no_underrun", "assert_nothing_printed_after_fault"]


def assert_scan_matches(result: api.PrintResult, scan=None, *, tolerances=None):
    """A scan of the printed job (default: --wideprint-scan) against the physical model's
    prediction of it (api.predict_scan at the scan's resolution and mode, api.compare_scan,
    docs/acceptance.md): registered, then ink density, rows and dot positions within the
    tolerances.  Without a scan the assertion checks nothing (a real printer whose print
    was not scanned): the media and device assertions stand."""
    from .scancheck import scan_format
    request = _RUNNING[-1] if _RUNNING else None
    if scan is None and request is not None:
        scan = request.config.getoption("--wideprint-scan")
    if scan is None:
        return None
    out = (_artifacts() or Path(result.file).parent) / f"{Path(result.file).stem}-predicted-scan.tif"
    out.parent.mkdir(parents=True, exist_ok=True)
    dpi, grey = scan_format(scan)
    api.predict_scan(result.file, out, result.settings, scan_dpi=dpi, grey=grey,
                     profile=result.profile)
    cmp = api.compare_scan(scan, out, tolerances)
    if not cmp.ok:
        raise AssertionError(f"{Path(scan).name} against the prediction of {result.file} "
                             f"({out}):\n{cmp.explain()}")
    return cmp
