"""Linearisation (docs/color.md "Linearisation"): with the profile's [color] drop_budget
set to 150 / dpi, the same image lays down the same ink per m² at 150, 300 and 600 dpi
(within 5 %) for light and mid tones of every ink, through error diffusion and screens;
without it (the shipped default) ink per m² grows with the mode's columns.  A step wedge
printed on a machine with strong dot gain, scanned and measured (`calibrate wedge`), writes
per-ink curves under which the reprinted wedge is linear."""

import json
import shutil

import numpy as np
import pytest
import tifffile

from support.printing import variant_profile
from wideprint.app.cli import main
from wideprint.rip.color import Separator
from wideprint.rip.pipeline import RipJob, RipSettings, profile_curves
from wideprint.rip.place import Placement
from wideprint.rip.profile import DEFAULT_PROFILE, load_profile
from wideprint.rip.testprints import WEDGE_STEPS

MODES = (150, 300, 600)
LINEAR = "drop_budget = { 150 = 1.0, 300 = 0.5, 600 = 0.25 }"


def _profile(tmp, budget_line: str | None, name: str):
    prof = variant_profile(tmp, name=name)
    if budget_line is None:
        return prof
    path = tmp / f"{name}.toml"
    text = path.read_text()
    start = text.index("drop_budget = ")
    end = text.index("\n", start)
    path.write_text(text[:start] + budget_line + text[end:])
    return load_profile(path)


def ink_ml_per_m2(prof, src, dpi: int, dither: str) -> np.ndarray:
    """Per ink: drops x drop volume / area, from the RIP's halftone."""
    settings = RipSettings(placement=Placement(width_mm=30.0, height_mm=30.0), dpi=dpi,
                           passes=2, dither=dither)
    job = RipJob(str(src), settings, prof)
    try:
        drops = np.zeros(4)
        for band in job.halftone_bands():
            drops += band.reshape(-1, 4).sum(axis=0)
        area_m2 = (job.width * 0.0254 / dpi) * (job.height * prof.row_um * 1e-6)
    finally:
        job.close()
    return drops * prof.drop_volume_pl * 1e-9 / area_m2


@pytest.fixture(scope="module")
def tints(tmp_path_factory):
    tmp = tmp_path_factory.mktemp("lin")
    out = {}
    for tone in (13, 26, 45, 64, 128, 150):   # light (5, 10, 18, 25 %) and mid (50, 59 %)
        path = tmp / f"t{tone}.tif"
        tifffile.imwrite(path, np.full((64, 64, 4), tone, np.uint8), photometric="separated")
        out[tone] = path
    return tmp, out


def test_the_shipped_profile_states_linearisation_off():
    assert "\ndrop_budget = { 150 = 1.0, 300 = 1.0, 600 = 1.0 }\n" in DEFAULT_PROFILE.read_text()      # stated, not implied
    prof = load_profile()
    assert prof.color.drop_budget == {d: 1.0 for d in prof.dpi_modes}
    assert all(profile_curves(prof, d) is None for d in prof.dpi_modes)


@pytest.mark.parametrize("dither", ["vced", "bluenoise"])
def test_ink_per_m2_is_the_same_in_every_dpi_mode_with_linearisation(tints, dither):
    tmp, srcs = tints
    on = _profile(tmp, LINEAR, "linear")
    for tone, src in srcs.items():
        ml = np.array([ink_ml_per_m2(on, src, d, dither) for d in MODES])   # (mode, ink)
        ratio = ml / ml[0]
        assert np.all(np.abs(ratio - 1) < 0.05), (tone, ml.round(2).tolist())


def test_without_linearisation_ink_per_m2_doubles_with_each_mode(tints):
    tmp, srcs = tints
    off = _profile(tmp, None, "off")
    ml = np.array([ink_ml_per_m2(off, srcs[128], d, "vced") for d in MODES])
    assert np.allclose(ml / ml[0], [[1], [2], [4]], rtol=0.05), ml.round(2).tolist()


def test_the_emulator_reports_the_same_ink_per_m2_for_every_mode_and_pass_count(tints):
    """The printed drops (the emulator's report): the budget holds through the weave, and
    the pass count only shares the same drops among strokes."""
    from wideprint.app.devices import open_device
    from wideprint.driver.job import PrintJob
    tmp, srcs = tints
    on = _profile(tmp, LINEAR, "linear")
    per_m2 = {}
    for dpi, passes in ((150, 1), (300, 1), (300, 4), (600, 2)):
        settings = RipSettings(placement=Placement(width_mm=20.0, height_mm=20.0), dpi=dpi,
                               passes=passes)
        dev = open_device("emulator", on, None)
        try:
            job = RipJob(str(srcs[64]), settings, on)
            area_m2 = (job.width * 0.0254 / dpi) * (job.height * on.row_um * 1e-6)
            rep = PrintJob(dev, job).run()
        finally:
            dev.emulator.close()
        assert rep.state == "done"
        per_m2[dpi, passes] = np.array(rep.ink_ml) / area_m2
    assert np.array_equal(per_m2[300, 1], per_m2[300, 4])
    ref = per_m2[150, 1]
    for key, v in per_m2.items():
        assert np.all(np.abs(v / ref - 1) < 0.05), (key, v.round(3).tolist(), ref.round(3).tolist())


def test_the_job_estimate_counts_the_budget(tints):
    """The preview's ink estimate (made without the budget) is scaled by it: the same
    ml/m² in every mode, as the RIP lays down."""
    from wideprint.app.jobpreview import compute_preview
    tmp, srcs = tints
    on = _profile(tmp, LINEAR, "linear")
    got = []
    for d in MODES:
        rs = RipSettings(placement=Placement(width_mm=30.0, height_mm=30.0), dpi=d, passes=2)
        est = compute_preview(str(srcs[128]), rs, on).estimate
        got.append(np.array(est.ink_ml) / est.area_m2)
    rip = ink_ml_per_m2(on, srcs[128], 600, "vced")
    assert np.all(np.abs(np.array(got) / rip - 1) < 0.05), (np.round(got, 3).tolist(), rip)


def test_the_budget_scales_the_curves_lut(tints):
    tmp, _ = tints
    on = _profile(tmp, LINEAR, "linear")
    assert profile_curves(on, 150) is None
    lut = profile_curves(on, 600)
    assert lut[:, 255].tolist() == [63.75] * 4 and lut[:, 128].tolist() == [32] * 4
    assert lut[:, 26].tolist() == [6.5] * 4          # not rounded: the separation rounds by
    sep = Separator("cmyk", 8, curves=lut)           # position, 6.5 on average
    out = sep.convert(np.full((16, 64, 4), 26, np.uint8))
    assert set(np.unique(out)) == {6, 7} and out.mean() == 6.5
    assert np.array_equal(Separator("cmyk", 8, curves=np.rint(lut).astype(np.uint8)).convert(
        np.full((4, 16, 4), 26, np.uint8)), np.full((4, 16, 4), 6, np.uint8))   # whole: exact


# -- per-channel curves from a measured step wedge ------------------------------------------------
GAIN = ["dot-diameter=140um", "scan-rotation=1.5", "scan-scale=1.002", "scan-noise=2", "seed=5"]


def _wedge(tmp, name, profile, capsys, write=False):
    """Print the wedge at 300 dpi on a machine with strong dot gain, scan it, calibrate:
    what `calibrate wedge --json` found."""
    scan = tmp / f"{name}.tif"
    args = ["test-print", "wedge-scan", "--width-mm", "100", "--dpi", "300", "--scan-out",
            str(scan), "--scan-dpi", "600", "--profile", str(profile)]
    assert main(args + [a for g in GAIN for a in ("--inject", g)]) == 0
    capsys.readouterr()
    assert main(["calibrate", "wedge", "--scan", str(scan), "--dpi", "300", "--profile",
                 str(profile), "--json"] + (["--write"] if write else [])) == 0
    return json.loads(capsys.readouterr().out)["found"]


def test_a_wedge_with_dot_gain_is_measured_and_its_curves_linearise_the_reprint(tmp_path, capsys):
    profile = tmp_path / "printer.toml"
    shutil.copy(DEFAULT_PROFILE, profile)
    before = _wedge(tmp_path, "before", profile, capsys, write=True)
    assert before["steps"] == list(WEDGE_STEPS)
    for ink in "CMYK":                      # 140 µm dots: 50 % ink covers nearly all paper
        assert before["inks"][ink]["tone"][5] > 0.9 and before["inks"][ink]["max_error"] > 0.4
    curves = load_profile(profile).curves
    for ink in "CMYK":                      # the written curve takes the mid tones down
        pts = dict(getattr(curves, ink))
        assert pts[0] == 0 and pts[255] == 255 and pts[128] < 64
    after = _wedge(tmp_path, "after", profile, capsys)
    for ink in "CMYK":                      # one iteration: every step within 4 points
        assert after["inks"][ink]["max_error"] < 0.04, (ink, after["inks"][ink])


def test_typed_in_wedge_values_write_the_inverse_curve(tmp_path, capsys):
    profile = tmp_path / "printer.toml"
    shutil.copy(DEFAULT_PROFILE, profile)
    # a measured dot area with 20 points of gain at 50 %: the curve must be its inverse
    def gain(v):
        x = np.asarray(v) / 255
        return x + 0.8 * x * (1 - x)
    fine = np.linspace(0, 255, 2551)
    tones = [round(100 * float(gain(v)), 3) for v in WEDGE_STEPS]
    capsys.readouterr()
    assert main(["calibrate", "wedge", "--values", "M=" + ",".join(map(str, tones)),
                 "--profile", str(profile), "--write", "--json"]) == 0
    got = dict(load_profile(profile).curves.M)
    for v in WEDGE_STEPS:
        assert abs(got[v] - np.interp(v / 255, gain(fine), fine)) < 2.0, (v, got[v])
    assert got[128] < 100                       # 50 % ink covers 70 %: far less ink
    assert load_profile(profile).curves.C == ((0, 0), (255, 255))       # others kept
    assert main(["calibrate", "wedge", "--values", "M=1,2,3", "--profile", str(profile)]) == 2
    assert main(["calibrate", "wedge", "--profile", str(profile)]) == 2      # neither given
