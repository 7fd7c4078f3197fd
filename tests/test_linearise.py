"""Linearisation (docs/color.md "Linearisation"): with the profile's [color] drop_budget
set to 150 / dpi, the same image lays down the same ink per m² at 150, 300 and 600 dpi
(within 5 %) for light and mid tones of every ink, through error diffusion and screens;
without it (the shipped default) ink per m² grows with the mode's columns."""

import numpy as np
import pytest
import tifffile

from test_swath import variant_profile
from wideprint.rip.pipeline import RipJob, RipSettings, profile_curves
from wideprint.rip.place import Placement
from wideprint.rip.profile import load_profile

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
    for tone in (45, 64, 128, 150):        # light (18 %, 25 %) and mid (50 %, 59 %) tones
        path = tmp / f"t{tone}.tif"
        tifffile.imwrite(path, np.full((64, 64, 4), tone, np.uint8), photometric="separated")
        out[tone] = path
    return tmp, out


def test_the_shipped_profile_states_linearisation_off():
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


def test_the_budget_scales_the_curves_lut(tints):
    tmp, _ = tints
    on = _profile(tmp, LINEAR, "linear")
    assert profile_curves(on, 150) is None
    lut = profile_curves(on, 600)
    assert lut[:, 255].tolist() == [64] * 4 and lut[:, 128].tolist() == [32] * 4
    assert lut[:, 45].tolist() == [11] * 4           # 11.25, rounded: the 8-bit bound
