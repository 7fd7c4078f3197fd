"""The spectral colour model, the spectrophotometer and the scanner that sees the same
spectra (docs/physical.md "The colour of the print")."""

import shutil
import subprocess

import cv2
import numpy as np
import pytest
import tifffile

from support.images import PX
from wideprint.app.devices import open_device
from wideprint.device_sim.physical import dot_diameter_um
from wideprint.device_sim.scanner import scanner_tone, sensor_lut
from wideprint.device_sim.spectral import (SpectralMedia, delta_e2000, demichel, lab_to_xyz,
                                           observer, reflectance_to_lab, xyz_to_lab)
from wideprint.device_sim.spectro import measure_patches, read_lab, write_ti3
from wideprint.driver.job import PrintJob
from wideprint.rip.pipeline import RipSettings
from wideprint.rip.planes import read_planes
from wideprint.rip.testprints import PatternJob

# ISO 12647-2:2004/Amd 1:2007, paper type 1 (FOGRA39L): what the inks were fitted to
ISO = {"W": (95, 0, -2), "C": (55, -37, -50), "M": (48, 74, -3), "Y": (89, -5, 93),
       "K": (16, 0, 0), "MY": (47, 68, 48), "CY": (50, -65, 27), "CM": (24, 22, -46),
       "CMY": (23, 0, 0)}
PATCH = 120                    # columns (300 dpi) and rows of one patch


@pytest.fixture(scope="module")
def media(profile):
    return SpectralMedia.from_profile(profile)


def print_planes(tmp_path, name, planes, profile, spectro_dpi=50, scan_dpi=None, dpi=300):
    """Print 1-pass planes on the emulator, measured: (media, Lab, dpi, printer)."""
    job = PatternJob(name, planes, RipSettings(placement=PX, dpi=dpi, passes=1), profile)
    media_path, lab_path = tmp_path / f"{name}.tif", str(tmp_path / f"{name}-lab.tif")
    scan = dict(scan_path=str(tmp_path / f"{name}-scan.tif"), scan_dpi=scan_dpi) if scan_dpi else {}
    dev = open_device("emulator", profile, None, media_path=str(media_path),
                      spectro_path=lab_path, spectro_dpi=spectro_dpi, **scan)
    try:
        PrintJob(dev, job).run()
    finally:
        dev.emulator.close()
    lab, dpi_read = read_lab(lab_path)
    return read_planes(media_path), lab, dpi_read, dev.emulator


def tints(coverages, rows=2 * PATCH, seed=1):
    """Patches side by side, each of independent random dots with these C, M, Y, K
    coverages (the chance of a dot in a cell): a halftone whose Demichel weights are known."""
    rng = np.random.default_rng(seed)
    planes = np.zeros((rows, PATCH * len(coverages), 4), np.uint8)
    for i, cov in enumerate(coverages):
        planes[:, i * PATCH:(i + 1) * PATCH] = rng.random((rows, PATCH, 4)) < np.asarray(cov)
    return planes


def patch_rects(n, profile, rows=2 * PATCH, dpi=300):
    col_mm, row_mm = 25.4 / dpi, profile.row_um / 1000
    return [(i * PATCH * col_mm, 0.0, (i + 1) * PATCH * col_mm, rows * row_mm) for i in range(n)]


def reference_lab(planes, media, profile, dpi=300, step_um=5.0, inset_um=1500.0):
    """The model's Lab of a printed patch computed apart from the instrument: every dot a
    disc at its cell's centre on a 5 µm grid, coverage min(1, discs), the Demichel weights
    of each point averaged over the patch, Yule-Nielsen spectral Neugebauer."""
    col_um, row_um = 25_400 / dpi, profile.row_um
    h, w = planes.shape[:2]
    gh, gw = int(h * row_um / step_um), int(w * col_um / step_um)
    dot = dot_diameter_um(profile)
    r = dot / 2 / step_um
    n = int(np.ceil(r))
    yy, xx = np.mgrid[-n:n + 1, -n:n + 1]
    disc = ((xx * xx + yy * yy) <= r * r).astype(np.float32)
    cov = np.zeros((gh, gw, 4), np.float32)
    for i in range(4):
        imp = np.zeros((gh, gw), np.float32)
        rr, cc = np.nonzero(planes[:, :, i])
        gy = ((rr + 0.5) * row_um / step_um).astype(int)
        gx = ((cc + 0.5) * col_um / step_um).astype(int)
        np.add.at(imp, (gy, gx), 1.0)
        cov[:, :, i] = np.minimum(cv2.filter2D(imp, -1, disc, borderType=cv2.BORDER_CONSTANT), 1)
    k = int(inset_um / step_um)
    inner = cov[k:gh - k, k:gw - k].reshape(-1, 4)
    return media.lab(demichel(inner).mean(axis=0))


# -- the model -------------------------------------------------------------------------------
def test_observer_is_cie_d50():
    white = observer().white
    assert np.allclose(white, [0.9642, 1.0, 0.8251], atol=2e-4)
    lab = np.array([[50, 20, -30], [90, -3, 5]])
    assert np.allclose(xyz_to_lab(lab_to_xyz(lab)), lab, atol=1e-9)
    assert reflectance_to_lab(np.ones(observer().wavelengths.size)) == pytest.approx([100, 0, 0])


def test_observer_matches_colour_science():
    """The weights as colour-science computes them (in a process of its own: without SciPy
    colour-science puts a mock in its place, which breaks numba's import)."""
    import importlib.util
    import sys
    if importlib.util.find_spec("colour") is None:
        pytest.skip("colour-science is not installed (only tools/spectral_data.py needs it)")
    wl = observer().wavelengths
    refl = 0.5 + 0.4 * np.sin(wl / 37.0)
    code = ("import sys, json, colour\n"
            "wl, r = json.loads(sys.argv[1])\n"
            "sd = colour.SpectralDistribution(dict(zip(wl, r)))\n"
            "x = colour.sd_to_XYZ(sd, colour.MSDS_CMFS['CIE 1931 2 Degree Standard Observer'],"
            " colour.SDS_ILLUMINANTS['D50'], method='ASTM E308') / 100\n"
            "print(json.dumps(list(x)))")
    import json
    out = subprocess.run([sys.executable, "-W", "ignore", "-c", code,
                          json.dumps([wl.tolist(), refl.tolist()])],
                         capture_output=True, text=True, timeout=120, check=True)
    xyz = json.loads(out.stdout.strip().splitlines()[-1])
    assert np.allclose(refl @ observer().weights.T, xyz, atol=1e-6)


def test_delta_e2000_reference_pairs():
    """Sharma, Wu, Dalal (2005), pairs 1 and 4."""
    assert delta_e2000([50, 2.6772, -79.7751], [50, 0, -82.7485]) == pytest.approx(2.0425, abs=1e-4)
    assert delta_e2000([50, -1.3802, -84.2814], [50, 0, -82.7485]) == pytest.approx(1.0, abs=1e-4)


def test_paper_and_primaries_match_the_cited_targets(media):
    lab = media.primary_lab()
    white = lab["W"]
    assert 93 <= white[0] <= 96 and -4 <= white[2] <= 0.5 and abs(white[1]) < 1
    de = {k: float(delta_e2000(lab[k], v)) for k, v in ISO.items()}
    assert max(de.values()) < 1.5, de
    assert np.mean(list(de.values())) < 0.8, de
    assert lab["CMYK"][0] < lab["K"][0] < lab["CMY"][0]          # black is the darkest
    assert np.all((media.primaries > 0) & (media.primaries < 1))
    for ink in media.density:                                     # smooth, physical spectra
        assert np.abs(np.diff(ink, 2)).max() < 0.5


def test_yule_nielsen_mixing(media):
    """n = 1 mixes reflectances linearly; the media's n makes a tint darker (optical dot
    gain); a coverage of 0 or 1 is the paper or the solid whatever n is."""
    assert media.n > 1
    w = demichel([0.5, 0, 0, 0])
    linear = w @ media.primaries
    assert np.all(media.reflectance(w) <= linear + 1e-12)
    assert np.allclose(media.coverage_lab([1, 0, 0, 0]), media.primary_lab()["C"])
    assert np.allclose(media.coverage_lab([0, 0, 0, 0]), media.primary_lab()["W"])


# -- the spectrophotometer -----------------------------------------------------------------
@pytest.fixture(scope="module")
def flat(tmp_path_factory, profile):
    """Paper, solids, random tints: one print measured by the spectrophotometer."""
    covs = [(0, 0, 0, 0), (1, 0, 0, 0), (0, 1, 0, 0), (0, 0, 1, 0), (0, 0, 0, 1),
            (0.5, 0, 0, 0), (0.3, 0.4, 0, 0), (0.2, 0.3, 0.5, 0.1)]
    planes = tints(covs)
    return covs, planes, print_planes(tmp_path_factory.mktemp("flat"), "flat", planes, profile)


def test_spectro_file_covers_the_image_area(flat, profile):
    covs, planes, (media_planes, lab, dpi, printer) = flat
    assert np.array_equal(media_planes, planes)          # the bit-exact media is unchanged
    assert dpi == 50 and lab.dtype == np.float32 and lab.shape[2] == 3
    pitch = 25_400 / 50
    assert lab.shape[1] == int(np.ceil(planes.shape[1] * 25_400 / 300 / pitch))
    assert lab.shape[0] == int(np.ceil(planes.shape[0] * profile.row_um / pitch))
    assert [e["event"] for e in printer.events if e["event"] == "spectro"] == ["spectro"]


def test_flat_patches_equal_the_model(flat, profile, media):
    """The spectro's reading of each flat patch equals the model's Lab of the patch's dots
    computed apart (5 µm grid, exact disc positions): ΔE2000 < 1 (the instrument counts
    drops on a grid a third of a dot wide)."""
    covs, planes, (_, lab, dpi, _) = flat
    got = measure_patches(lab, patch_rects(len(covs), profile), dpi, inset_mm=1.5)
    for i, cov in enumerate(covs):
        want = reference_lab(planes[:, i * PATCH:(i + 1) * PATCH], media, profile)
        assert delta_e2000(got[i], want) < 1.0, (cov, got[i], want)
    # and the solids are the primaries, paper the paper (a 300 dpi solid leaves 0.9 % of
    # the area between its dots)
    prim = media.primary_lab()
    for i, name in enumerate(["W", "C", "M", "Y", "K"]):
        assert delta_e2000(got[i], prim[name]) < 1.2, (name, got[i], prim[name])
        assert delta_e2000(got[i], ISO[name]) < 1.5, (name, got[i], ISO[name])


def test_spectro_is_uniform_over_a_flat_patch(flat, profile):
    covs, planes, (_, lab, dpi, _) = flat
    x0, _, x1, y1 = patch_rects(len(covs), profile)[1]
    p = 25.4 / dpi
    solid = lab[2:int(y1 / p) - 2, int(x0 / p) + 2:int(x1 / p) - 2]
    assert np.ptp(solid[..., 0]) < 1.0


def test_ink_beyond_the_media_limit_gets_no_darker(tmp_path, profile, media):
    """Equal C, M, Y, K tints from 200 % to 400 %: darker up to the media's limit (20 ml/m²:
    ~290 % at 300 dpi), then the ink pools and the patches get no darker."""
    tac = [2.0, 2.4, 2.8, 3.2, 3.6, 4.0]
    planes = tints([(t / 4,) * 4 for t in tac])
    _, lab, dpi, _ = print_planes(tmp_path, "tac", planes, profile)
    got = measure_patches(lab, patch_rects(len(tac), profile), dpi, inset_mm=1.5)
    volume = np.array(tac) * profile.drop_volume_pl * 1000 / (25_400 / 300 * profile.row_um)
    within = volume <= media.ink_limit_ml_m2
    assert within[:2].all() and not within[-2:].any()
    L = got[:, 0]
    assert np.all(np.diff(L[within]) < 0), L                     # more ink, darker
    assert np.all(np.diff(L[~within]) > 0), L                    # beyond: it pools, lighter
    assert np.argmin(L) in (within.sum() - 1, within.sum()), L   # the darkest at the limit


def test_no_ink_limit_no_pooling(tmp_path, profile, media):
    """With a media that takes everything, 400 % is the darkest patch."""
    import dataclasses
    prof = dataclasses.replace(profile, physical=dataclasses.replace(profile.physical,
                                                                     ink_limit_ml_m2=1000.0))
    planes = tints([(0.7,) * 4, (1.0,) * 4])
    _, lab, dpi, _ = print_planes(tmp_path, "free", planes, prof)
    got = measure_patches(lab, patch_rects(2, prof), dpi, inset_mm=1.5)
    assert got[1, 0] < got[0, 0]


def test_measure_patches_averages_in_xyz():
    lab = np.zeros((10, 20, 3), np.float32)
    lab[:, :10] = (90, 0, 0)
    lab[:, 10:] = (20, 0, 0)
    p = 25.4 / 50
    got = measure_patches(lab, [(0, 0, 20 * p, 10 * p)], 50)[0]
    want = xyz_to_lab((lab_to_xyz([90, 0, 0]) + lab_to_xyz([20, 0, 0])) / 2)
    assert got == pytest.approx(want)
    with pytest.raises(ValueError, match="no whole"):
        measure_patches(lab, [(0, 0, 0.3, 0.3)], 50)


def test_ti3_is_read_by_argyll(tmp_path, flat, profile):
    """Argyll's colverify reads two .ti3 files and compares them patch by patch."""
    if shutil.which("colverify") is None:
        pytest.fail("ArgyllCMS is not installed: apt-get install argyll "
                    "(resources/debian-packages.txt; .ci/run installs it)")
    covs, planes, (_, lab, dpi, _) = flat
    got = measure_patches(lab, patch_rects(len(covs), profile), dpi, inset_mm=1.5)
    device = np.array(covs) * 100
    write_ti3(tmp_path / "a.ti3", device, got)
    write_ti3(tmp_path / "b.ti3", device, got + [0.0, 1.0, 0.0])
    out = subprocess.run(["colverify", "-v", str(tmp_path / "a.ti3"), str(tmp_path / "b.ti3")],
                         capture_output=True, text=True, timeout=60)
    assert out.returncode == 0, out.stderr
    assert f"Number of patches = {len(covs)}" in out.stdout or f"{len(covs)} patches" in out.stdout \
        or "Total errors" in out.stdout, out.stdout


# -- the scanner -----------------------------------------------------------------------------
def test_scanner_sees_the_same_spectra(tmp_path, profile, media):
    """The scan renders the media's spectra through its sensor: paper white reads the
    sensor's white, solids read their sensor values, and a scanner is no colorimeter (its
    channels are not the observer's)."""
    planes = tints([(0, 0, 0, 0), (1, 0, 0, 0), (0, 1, 0, 0), (0, 0, 1, 0), (0, 0, 0, 1)])
    _, _, _, printer = print_planes(tmp_path, "sc", planes, profile, scan_dpi=300)
    scan = tifffile.imread(tmp_path / "sc-scan.tif").astype(np.float64)
    scanner = next(iter(printer.scans.values()))
    lut = sensor_lut(media)
    corners = {"W": (0, 0, 0, 0), "C": (-1, 0, 0, 0), "M": (0, -1, 0, 0), "Y": (0, 0, -1, 0),
               "K": (0, 0, 0, -1)}
    for i, (name, idx) in enumerate(corners.items()):
        x0, y0, x1, y1 = patch_rects(5, profile)[i]
        u0, v0 = scanner.paper_to_scan(x0 * 1000 + 1500, y0 * 1000 + 1500)
        u1, v1 = scanner.paper_to_scan(x1 * 1000 - 1500, y1 * 1000 - 1500)
        mean = scan[int(v0):int(v1), int(u0):int(u1)].reshape(-1, 3).mean(axis=0)
        want = scanner_tone(lut[idx])
        tol = 4.0 if name == "W" else 12.0          # solids: the gaps between the dots
        assert np.abs(mean - want).max() < tol, (name, mean, want)
    # contrast the calibration needs: K far below paper in every channel
    assert scanner_tone(lut[0, 0, 0, 0]).min() - scanner_tone(lut[0, 0, 0, -1]).max() > 150
