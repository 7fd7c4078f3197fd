"""Print quality where the eye sees it (issue 36, docs/quality.md): the banding, graininess
and mottle measures on known inputs, the machine's errors (docs/physical.md "The machine"),
the shingled pass mask (docs/rip.md "Pass masks"), and the report on the emulator's scans."""

import json
import math

import numpy as np
import pytest

from support.printing import replay
from wideprint.app import api, quality as Q
from wideprint.app.cli import main as wideprint
from wideprint.device_sim.faults import MACHINES, Faults
from wideprint.device_sim.physical import PhysicalModel
from wideprint.device_sim.scanner import disc_kernel, ring_kernel
from wideprint.rip.swath import PASS_COUNTS, StrokePlanner, shingle_weights
from wideprint.rip.testprints import BANDING_TINTS

PIX = 25.4 / 600                      # a 600 dpi scan's pixel, mm


def synthetic(rows=1500, cols=160, period_mm=5.0, amplitude=0.0, noise=0.0, seed=0):
    """A flat tint of L* 60 with a sinusoidal banding along the rows and white grain."""
    y = np.arange(rows)[:, None] * PIX
    rng = np.random.default_rng(seed)
    return (60.0 + amplitude * np.sin(2 * np.pi * y / period_mm)
            + noise * rng.standard_normal((rows, cols))).astype(np.float32)


# -- the measures on known inputs -----------------------------------------------------------
def test_the_eye_peaks_at_one_and_moves_with_the_distance():
    f = np.linspace(0.01, 10, 20_000)
    assert vtf_max(f, 500) == pytest.approx(1.0, abs=1e-3)
    near, far = f[np.argmax(Q.vtf(f, 250))], f[np.argmax(Q.vtf(f, 500))]
    assert near == pytest.approx(2 * far, rel=0.01)              # cycles per degree are fixed
    assert 0.5 < far < 0.75                                       # 5.5 cycles/degree at 500 mm
    assert Q.vtf(np.array([0.0]))[0] == 0.0                       # no sensitivity to a DC level


def vtf_max(f, d):
    return float(Q.vtf(f, d).max())


def test_a_known_sinusoidal_banding_is_measured_at_its_period_and_amplitude():
    area = synthetic(period_mm=5.0, amplitude=0.5, noise=4.0)
    q = Q.measure_area("t", area, PIX, periods={"advance": 5.0})
    assert q.period_mm == pytest.approx(5.0, rel=0.01)
    first = q.components[0]
    assert first.what == "advance" and first.amplitude == pytest.approx(0.5, rel=0.1)
    # the eye-weighted banding of one sinusoid: its RMS (a / sqrt 2) times the eye at 0.2 c/mm
    assert q.banding == pytest.approx(0.5 / math.sqrt(2) * float(Q.vtf(np.array([0.2]))[0]), rel=0.15)
    # the grain (4 L* per pixel, much more than the banding) is not banding
    clean = Q.measure_area("t", synthetic(noise=4.0), PIX)
    assert clean.banding < 0.1 * q.banding and clean.period_mm == 0.0


def test_graininess_and_mottle_of_white_grain_follow_the_eye():
    """White noise of sigma s has the same power everywhere: the graininess is s times the
    RMS of the eye over the frequencies above 0.4 cycles/mm, mottle the same from 0.1 to 0.4."""
    s = 3.0
    area = synthetic(rows=1024, cols=512, noise=s, seed=2)
    grain, mottle = Q.grain_mottle(area, PIX, 500.0)
    fy, fx = np.fft.fftfreq(1024, PIX), np.fft.fftfreq(512, PIX)
    f = np.hypot(fy[:, None], fx[None, :])
    keep = (fy[:, None] != 0) & (fx[None, :] != 0)
    eye = Q.vtf(f) ** 2
    expect_g = s * math.sqrt(float((eye * (keep & (f >= 0.4))).sum()) / f.size)
    expect_m = s * math.sqrt(float((eye * (keep & (f >= 0.1) & (f < 0.4))).sum()) / f.size)
    assert grain == pytest.approx(expect_g, rel=0.05)
    assert mottle == pytest.approx(expect_m, rel=0.25)           # few bins: a noisy figure
    assert Q.grain_mottle(synthetic(rows=1024, cols=512, noise=2 * s, seed=3), PIX, 500.0)[0] == \
        pytest.approx(2 * grain, rel=0.05)


def test_strips_are_found_and_a_white_scan_is_refused(tmp_path):
    light = np.full((900, 700), 100.0, np.float32)
    light[100:800, 100:300] = 70.0
    light[100:800, 400:600] = 50.0
    light[450:452, 100:300] = 100.0                  # a white banding line: not the strip's end
    strips = Q.find_strips(light, PIX)
    lo, hi = 0.3 / PIX, 0.8 / PIX                   # 0.3-0.8 mm inside the strip's edges
    for s, (x0, x1) in zip(strips, [(100, 300), (400, 600)]):
        assert x0 + lo <= s.x0 <= x0 + hi and x1 - hi <= s.x1 <= x1 - lo
        assert 100 + lo <= s.y0 <= 100 + hi and 800 - hi <= s.y1 <= 800 - lo
    assert len(strips) == 2
    with pytest.raises(Q.QualityError):
        Q.find_strips(np.full((300, 300), 100.0, np.float32), PIX)


# -- the machine ------------------------------------------------------------------------------
def test_machine_presets_parse_and_explicit_kinds_win():
    typical = Faults.parse(["machine=typical"])
    assert typical.machine == "typical" and typical.machine_errors
    assert typical.feed_noise.um(0, 0) == 3.0 and typical.volume_spread == 0.03
    assert typical.direction_spread.um(0, 0) == 3.0                     # 3 mrad over a 1 mm gap
    both = Faults.parse(["feed-noise=10um", "machine=tired"])
    assert both.feed_noise.um(0, 0) == 10.0 and both.volume_spread == 0.08
    assert not Faults.parse(["machine=perfect"]).machine_errors
    assert set(MACHINES) == {"perfect", "typical", "tired"}
    for bad in ("machine=new", "volume-spread=80%", "direction-spread=2col", "head-density=K1"):
        with pytest.raises(ValueError):
            Faults.parse([bad])


def test_the_machines_errors_are_drawn_from_the_seed(profile):
    a = PhysicalModel(profile, Faults.parse(["machine=tired", "seed=5"]))
    b = PhysicalModel(profile, Faults.parse(["machine=tired", "seed=5"]))
    c = PhysicalModel(profile, Faults.parse(["machine=tired", "seed=6"]))
    assert np.array_equal(a.spread_dy_um, b.spread_dy_um) and np.array_equal(a.volume, b.volume)
    assert not np.array_equal(a.spread_dy_um, c.spread_dy_um)
    assert a.spread_dy_um.std() == pytest.approx(10.0, rel=0.1)           # 10 mrad x 1 mm
    per_nozzle = a.volume / a.volume.mean(axis=1, keepdims=True)
    assert per_nozzle.std() == pytest.approx(0.08, rel=0.15)
    feeds = np.array([a.feed_error_um(4318.0, 68.55) for _ in range(4000)])
    assert feeds.mean() == pytest.approx(0.0, abs=0.5) and feeds.std() == pytest.approx(8.0, rel=0.05)
    assert a.feed_error_um(0.0, 68.55) == 0.0                            # no feed, no error
    k1 = PhysicalModel(profile, Faults.parse(["head-density=K1:+10%"]))
    idx = next(h.index for h in profile.heads if h.name == "K1")
    assert k1.volume[idx] == pytest.approx(1.1) and k1.volume.sum() == pytest.approx(k1.volume.size + 0.1 * 128)
    assert k1.diameter_dev[idx, 0] == pytest.approx(1.1 ** (1 / 3) - 1)
    assert not PhysicalModel(profile, Faults()).has_sizes


def test_a_larger_drop_spreads_to_a_larger_dot():
    """The scanner's ring: a dot s larger in diameter adds s x the ring, the disc's area
    growing as (1 + s)^2 to first order."""
    for d in (0.102 / PIX, 0.102 / PIX * 8):          # a 102 µm dot at 600 and 4800 dpi, pixels
        ring = ring_kernel(d, disc_kernel(d).shape[0] // 2)
        for s in (0.03, -0.05):
            grown = math.pi * (d / 2) ** 2 * ((1 + s) ** 2 - 1)
            assert float(s * ring.sum()) == pytest.approx(grown, rel=0.08)


# -- the shingled mask ----------------------------------------------------------------------
def test_shingle_weights_sum_to_one_and_fade_at_the_run_ends():
    for n in PASS_COUNTS[1:]:
        w = shingle_weights(n, 63)
        assert np.allclose(w.sum(axis=1), 1.0) and (w >= 0).all()
        if n > 2:        # the middle passes of a row carry more than the first and last
            assert w[:, 1:-1].min() > w[:, 0].min() and w[:, 1:-1].min() > w[:, -1].min()


@pytest.mark.parametrize("passes", [2, 3, 4, 8])
def test_the_shingle_mask_is_tone_exact_and_deterministic(profile, passes):
    """Every dot fired exactly once (the mask moves dots between passes, never adds or drops
    one), the same words every time, and the end nozzles fire fewer dots than the middle."""
    h, w = 400, 64
    planes = (np.random.default_rng(passes).random((h, w, 4)) < 0.4).astype(np.uint8)
    runs = []
    for _ in range(2):
        pl = StrokePlanner(profile, w, h, 300, passes, mask="shingle")
        runs.append(pl.feed(planes) + pl.finish())
    assert np.array_equal(replay(profile, pl, runs[0], h, w), planes)
    assert len(runs[0]) == len(runs[1]) and all(
        np.array_equal(a.words, b.words) for a, b in zip(*runs))
    full = StrokePlanner(profile, w, 1200, 300, passes, mask="shingle")
    per_nozzle = sum(
        (np.unpackbits(sd.words[0].view(np.uint8), bitorder="little").reshape(-1, 128).sum(axis=0)
         for sd in full.feed(np.ones((1200, w, 4), np.uint8)) + full.finish()), np.zeros(128))
    used = per_nozzle[2:126]
    assert used[:4].mean() < 0.5 * used[len(used) // 2 - 4:len(used) // 2 + 4].mean()


@pytest.mark.parametrize("mask", ["shingle", "feather"])
def test_masks_print_bit_exact_on_the_perfect_printer(tmp_path, mask):
    """The mask decides which pass fires a dot, never which dots fire: the media is the
    planes, dot for dot, and the same as with the checkerboard."""
    img = tmp_path / "img.tif"
    rng = np.random.default_rng(1)
    import tifffile
    tifffile.imwrite(img, rng.integers(0, 256, (300, 160, 3), dtype=np.uint8), resolution=(300, 300))
    settings = dict(passes=4, pass_mask=mask, dpi=300)
    planes = api.rip(img, settings)
    got = api.print_file(img, settings)
    assert got.ok and api.compare(got.media, planes).equal
    assert np.array_equal(planes, api.rip(img, dict(settings, pass_mask="checker")))


# -- the chart and the report on the emulator's scans ----------------------------------------
def chart(tmp_path, name, *inject, passes=1, mask=None, width_mm=100, scan_dpi=600):
    scan = tmp_path / f"{name}.tif"
    argv = ["test-print", "banding-scan", "--dpi", "300", "--passes", str(passes),
            "--width-mm", str(width_mm), "--scan-out", str(scan), "--scan-dpi", str(scan_dpi)]
    argv += ["--pass-mask", mask] if mask else []
    for i in inject:
        argv += ["--inject", i]
    assert wideprint(argv) == 0
    return scan


def test_a_known_feed_error_is_banding_of_its_period_and_amplitude(tmp_path, capsys):
    """One pass, the paper 80 µm further per feed: a light line every stroke, at the advance
    plus 80 µm.  Its fundamental in reflectance is a narrow pulse's, 2 (e / P) (Y_paper -
    Y_tint) (the ink missing over e, per period), less where dots overlap; the perfect
    printer shows no period and no banding."""
    e = 0.080
    period = Q.weave_periods(1)["advance"] + e
    rep = Q.measure_scan(str(chart(tmp_path, "feed", f"feed-error={e * 1000:g}um")))
    assert [q.name for q in rep.tints] == [t[0] for t in BANDING_TINTS]
    light, dpi = Q.read_lightness(str(tmp_path / "feed.tif"))
    strips = Q.find_strips(light, 25.4 / dpi)
    for q, s in zip(rep.tints, strips):
        assert q.period_mm == pytest.approx(period, abs=0.03), q.name
        if q.name.endswith("25"):              # light tints: dots seldom overlap
            y = ((light[s.y0:s.y1, s.x0:s.x1] + 16) / 116) ** 3
            f, cross, _ = Q.banding_spectrum(y, 25.4 / dpi)
            got = Q._amplitude(f, np.maximum(cross, 0), 1 / period)
            assert got == pytest.approx(2 * e / period * (1 - y.mean()), rel=0.25), q.name
    perfect = Q.measure_scan(str(chart(tmp_path, "perfect")))
    for q, p in zip(rep.tints, perfect.tints):
        assert p.period_mm == 0.0 and p.banding < 0.2 * q.banding, (q.name, p.banding, q.banding)


def test_the_report_runs_on_the_typical_and_tired_machines_scans(tmp_path, capsys):
    figures = {}
    for machine in ("typical", "tired"):
        scan = chart(tmp_path, machine, f"machine={machine}", passes=4, width_mm=80, scan_dpi=400)
        capsys.readouterr()
        assert wideprint(["quality", str(scan), "--passes", "4", "--json"]) == 0
        rep = json.loads(capsys.readouterr().out)
        assert [t["name"] for t in rep["tints"]] == [t[0] for t in BANDING_TINTS]
        assert rep["periods_mm"] == Q.weave_periods(4)
        assert all(t["components"][0]["what"] == "advance" for t in rep["tints"])
        figures[machine] = rep["summary"]
    assert figures["tired"]["banding"] > 2 * figures["typical"]["banding"] > 0
    assert figures["tired"]["graininess"] > figures["typical"]["graininess"]
    assert wideprint(["quality", str(tmp_path / "typical.tif")]) == 0
    assert "C25M25Y25" in capsys.readouterr().out
