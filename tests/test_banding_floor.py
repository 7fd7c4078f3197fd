"""The banding figure's floor on a perfect printer (issue 36, docs/quality.md "The floor"):
the halftone's own texture, correlated over ~2 mm across the sweep, is grain and must not
read as banding; what is left on the perfect printer is the estimator's zero-mean noise."""

import numpy as np
import pytest

from wideprint.app import quality as Q
from wideprint.app.cli import main as wideprint

PIX = 25.4 / 600                      # a 600 dpi scan's pixel, mm


def worms(seed, rows=3000, cols=160, n=6000, length_mm=1.2, dl=8.0):
    """A flat tint of L* 60 with short dark horizontal features at random places: error
    diffusion's worms, as long as a column group is wide, no banding at all."""
    rng = np.random.default_rng(seed)
    a = np.full((rows, cols), 60.0, np.float32)
    n_px = int(round(length_mm / PIX))
    for y, x in zip(rng.integers(0, rows - 2, n), rng.integers(-n_px, cols, n)):
        a[y:y + 2, max(x, 0):max(x + n_px, 0)] -= dl
    return a


def eye_power(area):
    """The eye-weighted coherent power, signed (the banding figure before its square root)."""
    f, cross, _ = Q.banding_spectrum(area, PIX)
    return float((Q.vtf(f) ** 2 * cross).sum())


def test_a_texture_shared_by_neighbouring_groups_is_not_banding(monkeypatch):
    areas = [worms(seed) for seed in range(12)]
    got = np.array([eye_power(a) for a in areas])
    monkeypatch.setattr(Q, "PAIR_GAP", 0)
    own = np.mean([eye_power(a) for a in areas])          # every group with itself too
    monkeypatch.setattr(Q, "PAIR_GAP", 1)
    neighbours = np.array([eye_power(a) for a in areas])
    se = got.std() / np.sqrt(got.size)
    # the shipped estimator: zero within its noise, a small part of the texture's own power
    assert abs(got.mean()) < 3 * se and abs(got.mean()) < 0.06 * own, (got.mean(), se, own)
    # comparing neighbouring groups (the estimator before the floor was found) reads the
    # texture as banding: the trap the test guards against
    assert neighbours.mean() > 0.1 * own and neighbours.mean() > 4 * neighbours.std() / np.sqrt(12)


def test_a_banding_under_the_texture_is_still_measured():
    """A sinusoid of 1.5 ΔL* at 5 mm under the worms: its power is found, the worms add
    nothing on average."""
    y = np.arange(3000)[:, None] * PIX
    band = 1.5 * np.sin(2 * np.pi * y / 5.0)
    expect = 1.5 ** 2 / 2 * float(Q.vtf(np.array([0.2]))[0]) ** 2
    got = np.mean([eye_power(worms(seed) + band) for seed in range(12)])
    assert got == pytest.approx(expect, rel=0.3)     # the worms' noise: 0.045 of 0.45


def test_the_perfect_printer_reads_no_banding_but_the_estimators_noise(tmp_path):
    """The perfect printer's 4-pass chart: the signed coherent powers of its ten tints
    average to zero (measured 0.0012, spread 0.007), so the figure left (mean 0.034 ΔL*,
    0.060 with neighbouring groups compared) is the square root of the estimator's noise."""
    scan = tmp_path / "perfect.tif"
    assert wideprint(["test-print", "banding-scan", "--dpi", "300", "--passes", "4",
                      "--width-mm", "100", "--scan-out", str(scan), "--scan-dpi", "600",
                      "--inject", "machine=perfect"]) == 0
    light, dpi = Q.read_lightness(str(scan))
    pix = 25.4 / dpi
    powers = []
    strips = Q.find_strips(light, pix)
    for s, name in zip(strips, Q.chart_names(len(strips))):
        if name.startswith("bar"):                                # the K frame bars
            continue
        y = Q._luminance(light[s.y0:s.y1, s.x0:s.x1])
        f, cross, _ = Q.banding_spectrum(y, pix)
        powers.append(float((Q.vtf(f) ** 2 * cross).sum()) * Q._lstar_slope(float(y.mean())) ** 2)
    assert len(powers) == 10
    assert abs(np.mean(powers)) < 0.006, powers
    assert Q.measure_scan(str(scan)).summary()["banding"] < 0.045
