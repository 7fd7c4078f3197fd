"""A DeviceN that mixes a library colour with a colorant in no library (docs/spot.md "A
DeviceN that mixes"; issue 35): the library colour prints its recipe wherever it appears,
the other colorant as the document's alternate prints it alone.  Measured on the
emulator's spectrophotometer through the default media (vinyl-300)."""

import numpy as np
import pikepdf
import pytest

from wideprint.app.cli import main
from wideprint.device_sim.spectral import delta_e2000
from wideprint.device_sim.spectro import measure_patches
from wideprint.rip import spot
from wideprint.rip.inputs import open_source
from wideprint.rip.profile import load_profile
from wideprint.rip.settings import RipSettings

PT = 25.4 / 72
RED = (48.0, 62.0, 38.0)                         # Brand Red, D50
# the designer's DeviceN alternate, (Brand Red t1, Foil Silver t2) -> CMYK: the red a
# guess (0, 0.9t1, 0.7t1 + 0.3t2, 0), the silver (0.6t2 cyan, its share of yellow)
ALT = b"{ dup 0.6 mul 2 index 0.9 mul 3 index 0.7 mul 3 index 0.3 mul add " \
      b"dup 1 gt { pop 1 } if 0 6 4 roll pop pop }"
SILVER_ALONE = (0.6, 0.0, 0.3, 0.0)             # ALT at (0, 1)
# patches, left to right: the DeviceN at (1, 0), the Separation Brand Red, the DeviceN at
# (0, 1), the alternate's CMYK for (0, 1) painted as DeviceCMYK, the DeviceN at (1, 1)
PATCH_PT, GAP_PT = 60, 12


@pytest.fixture
def spots_dir(tmp_path, monkeypatch):
    d = tmp_path / "spots"
    monkeypatch.setenv("WIDEPRINT_SPOT_DIR", str(d))
    spot.SpotBook(d).add([spot.Spot("Brand Red", RED)], "brand")
    return d


def make_pdf(path):
    pdf = pikepdf.new()
    n = 5
    w = n * PATCH_PT + (n + 1) * GAP_PT
    h = PATCH_PT + 2 * GAP_PT
    page = pdf.add_blank_page(page_size=(w, h))
    fn = pdf.make_stream(ALT)
    fn.FunctionType, fn.Domain, fn.Range = 4, [0, 1, 0, 1], [0, 1] * 4
    dn = pikepdf.Array([pikepdf.Name.DeviceN, pikepdf.Array([pikepdf.Name("/Brand Red"),
                                                             pikepdf.Name("/Foil Silver")]),
                        pikepdf.Name.DeviceCMYK, fn])
    sep = pikepdf.Array([pikepdf.Name.Separation, pikepdf.Name("/Brand Red"), pikepdf.Name.DeviceCMYK,
                         pikepdf.Dictionary(FunctionType=2, Domain=[0, 1], C0=[0, 0, 0, 0],
                                            C1=[0, 0.9, 0.7, 0], N=1)])
    page.Resources = pikepdf.Dictionary(ColorSpace=pikepdf.Dictionary(D0=dn, S0=sep))
    paints = ["/D0 cs 1 0 scn", "/S0 cs 1 scn", "/D0 cs 0 1 scn",
              "{} {} {} {} k".format(*SILVER_ALONE), "/D0 cs 1 1 scn"]
    body = []
    for i, paint in enumerate(paints):
        x = GAP_PT + i * (PATCH_PT + GAP_PT)
        body.append(f"{paint} {x} {GAP_PT} {PATCH_PT} {PATCH_PT} re f")
    page.Contents = pdf.make_stream("\n".join(body).encode())
    pdf.save(path)
    return path, [((GAP_PT + i * (PATCH_PT + GAP_PT)) * PT, GAP_PT * PT,
                   (GAP_PT + i * (PATCH_PT + GAP_PT) + PATCH_PT) * PT, (GAP_PT + PATCH_PT) * PT)
                  for i in range(n)]


def test_a_devicen_mixing_a_library_colour_with_an_unknown_one(spots_dir, tmp_path):
    pdf, rects = make_pdf(tmp_path / "mixed.pdf")
    # the rendered inks: (1, 0) is exactly the Separation's recipe; (0, 1) exactly the
    # alternate for the silver alone; (1, 1) their sum
    src = open_source(str(pdf), RipSettings(dpi=150), load_profile(None))
    try:
        img = np.concatenate(list(src.bands(256))).astype(int)
        by = {s["name"]: s["resolved"] for s in src.spots}
    finally:
        src.close()
    assert by == {"Brand Red": "library", "Foil Silver": "alternate"}
    cy = img.shape[0] // 2
    mid = [img[cy, int((r[0] + r[2]) / 2 / 25.4 * 150)] for r in rects]
    assert np.abs(mid[0] - mid[1]).max() <= 1, (mid[0], mid[1])
    assert np.abs(mid[2] - np.round(np.array(SILVER_ALONE) * 255)).max() <= 1, mid[2]
    assert np.abs(mid[4] - np.minimum(255, mid[1] + mid[2])).max() <= 2, mid[4]
    # measured: printed and read by the emulator's spectrophotometer
    lab = tmp_path / "lab.tif"
    assert main(["print", str(pdf), "--dpi", "300", "--media-out", str(tmp_path / "m.tif"),
                 "--spectro-out", str(lab)]) == 0
    m = measure_patches(str(lab), rects, inset_mm=3.0)
    de_red = delta_e2000(m[:2], np.array([RED, RED]))
    assert de_red.max() <= 2.0, (m[:2], de_red)            # the brand colour, in the DeviceN too
    assert delta_e2000(m[0:1], m[1:2])[0] <= 1.0           # the same as its Separation
    assert delta_e2000(m[2:3], m[3:4])[0] <= 1.0           # the silver as its alternate alone
