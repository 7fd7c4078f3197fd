"""Dead nozzles in one-pass printing (rip/deadrows.py, docs/geometry.md): a row only a dead
nozzle prints gives its dots to the rows beside it, so a one-pass job with dead nozzles on
several heads prints, bit-exact against the RIP's planes, and the physical scan of a flat
tint shows the local ink deficit around each dead row within 10 % over a few rows (left
empty, the row alone would be a 20 % deficit over five rows)."""

import numpy as np
import pytest
import tifffile

from support.images import PX
from support.printing import variant_profile
from wideprint.app.devices import open_device
from wideprint.driver.job import PrintJob
from wideprint.rip.pipeline import RipJob, RipSettings
from wideprint.rip.planes import read_planes

DEAD = [("M1", 57), ("K2", 30), ("C2", 90)]


@pytest.fixture(scope="module")
def printed(tmp_path_factory):
    tmp = tmp_path_factory.mktemp("dead")
    prof = variant_profile(tmp, dead=DEAD)
    tint = np.zeros((600, 500, 4), np.uint8)
    tint[..., 0] = 64                  # 25 % cyan
    tint[..., 1] = 102                 # 40 % magenta
    tint[..., 3] = 51                  # 20 % black
    src = tmp / "tint.tif"
    tifffile.imwrite(src, tint, photometric="separated")
    settings = RipSettings(placement=PX, passes=1, ink_limit=400)
    rip = RipJob(str(src), settings, prof)
    rip.write_planes(tmp / "planes.tif")
    dead = rip._dead_rows()
    rip.close()
    media, scan = tmp / "media.tif", str(tmp / "scan.tif")
    dev = open_device("emulator", prof, None, media_path=str(media), scan_path=scan, scan_dpi=600)
    try:
        rep = PrintJob(dev, RipJob(str(src), settings, prof)).run()
        scanner = dev.emulator.scans[scan]
    finally:
        dev.emulator.close()
    return dict(rep=rep, planes=read_planes(tmp / "planes.tif"), media=read_planes(media),
                scan=tifffile.imread(scan), scanner=scanner, dead=dead, prof=prof, tint=tint)


def test_a_one_pass_job_with_dead_nozzles_on_several_heads_prints_bit_exact(printed):
    assert printed["rep"].state == "done"
    assert np.array_equal(printed["media"], printed["planes"])
    phases, period = printed["dead"]
    assert [len(p) for p in phases] == [1, 1, 0, 1]            # C2, M1, K2: one row phase each
    for c, ph in enumerate(phases):
        for p in ph:
            assert not printed["planes"][p::period, :, c].any()  # the dead rows print nothing


def _deficit(density_by_row: np.ndarray, rows: np.ndarray, half: int) -> float:
    """The worst ink deficit over bands of 2 * half + 1 rows centred on `rows`, as a share
    of the tint's ink (the mean over rows away from them)."""
    away = np.ones(len(density_by_row), bool)
    for r in rows:
        away[max(0, r - 2 * half):r + 2 * half + 1] = False
    tint = density_by_row[away].mean()
    worst = 0.0
    for r in rows:
        if r - half < 0 or r + half >= len(density_by_row):
            continue
        worst = max(worst, 1 - density_by_row[r - half:r + half + 1].mean() / tint)
    return worst


def test_the_dots_of_a_dead_row_go_to_its_neighbours(printed):
    phases, period = printed["dead"]
    planes = printed["planes"]
    for c in (0, 1, 3):
        rows = np.arange(phases[c][0], planes.shape[0], period)
        by_row = planes[..., c].mean(axis=1)
        assert _deficit(by_row, rows, 2) < 0.05               # dots moved, almost none lost
        assert by_row[rows].max() == 0


def test_the_scan_shows_the_deficit_within_ten_percent_over_a_few_rows(printed):
    """The physical scan (dot gain, real drop positions) of the tint: the darkness of each
    ink's band, averaged across the image, around each dead row."""
    phases, period = printed["dead"]
    scan, scanner, prof = printed["scan"].astype(np.float64), printed["scanner"], printed["prof"]
    white = np.percentile(scan.reshape(-1, 3), 99.5, axis=0)
    absorb = -np.log(np.clip(scan / white, 1e-3, 1.0))              # optical density per band
    H, W = printed["planes"].shape[:2]
    col_um = 25.4e3 / 300
    xs = (np.arange(40, W - 40) + 0.5) * col_um
    band_of = {0: 0, 1: 1, 3: 1}                   # C absorbs red; M and K green
    for c in (0, 1, 3):
        rows = np.arange(phases[c][0], H, period)
        # one value per image row: the scan sampled where that row's dots land
        dens = np.empty(H)
        for r in range(H):
            u, v = scanner.paper_to_scan(xs, np.full_like(xs, (r + 0.5) * prof.row_um))
            u = np.clip(np.rint(u).astype(int), 0, scan.shape[1] - 1)
            v = np.clip(np.rint(v).astype(int), 0, scan.shape[0] - 1)
            dens[r] = absorb[v, u, band_of[c]].mean()
        assert _deficit(dens, rows, 2) < 0.10, "CMYK"[c]


def test_without_compensation_the_same_measure_fails(printed, tmp_path):
    """The measure can fail: the tint halftoned without giving the dead rows away, those
    rows then left empty by the dead nozzle, misses about a fifth of its ink over five rows."""
    src = tmp_path / "tint.tif"
    tifffile.imwrite(src, printed["tint"], photometric="separated")
    rip = RipJob(str(src), RipSettings(placement=PX, passes=1, ink_limit=400), printed["prof"])
    rip.compensate_dead = False
    planes = np.concatenate(list(rip.halftone_bands()))
    rip.close()
    phases, period = printed["dead"]
    for c in (0, 1, 3):
        rows = np.arange(phases[c][0], planes.shape[0], period)
        planes[rows, :, c] = 0                                   # what the dead nozzle prints
        assert _deficit(planes[..., c].mean(axis=1), rows, 2) > 0.15
