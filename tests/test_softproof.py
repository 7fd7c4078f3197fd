"""Soft proof (docs/color.md "Soft proof"): the job as its media prints it, checked against
what the emulator's spectrophotometer measures on the print, with the gamut warning on
exactly the colours the media cannot reach."""

import json
import subprocess
import sys

import numpy as np
import pytest
from PIL import Image

from wideprint.app.jobpreview import proof_job
from wideprint.app.softproof import ALARM_RGB, GAMUT_DE2000, cmyk_to_lab, proof_image
from wideprint.device_sim.spectral import delta_e2000
from wideprint.device_sim.spectro import read_lab
from wideprint.rip.profile import load_profile
from wideprint.rip.settings import from_mapping

#: sRGB patches: the paper (white: the spectrophotometer's reference for media-relative
#: colour), two colours the default media prints (a warm orange, a dull blue), a grey, and
#: sRGB's green, far outside any CMYK gamut
PATCHES = {"white": (255, 255, 255), "orange": (210, 120, 60), "blue": (70, 90, 140),
           "grey": (128, 128, 128), "green": (0, 255, 0)}
SIDE = 160                                  # px = dots at --size pixels (0.53 in at 300 dpi)


@pytest.fixture(scope="module")
def chart(tmp_path_factory):
    d = tmp_path_factory.mktemp("proof")
    rgb = np.concatenate([np.full((SIDE, SIDE, 3), c, np.uint8) for c in PATCHES.values()], 1)
    Image.fromarray(rgb).save(d / "chart.png")
    return d


def srgb_lab(rgb) -> np.ndarray:
    import pyvips
    img = pyvips.Image.new_from_array(np.array([[rgb]], np.uint8)).copy(interpretation="srgb")
    return img.icc_import(input_profile="srgb", intent="relative", embedded=False).numpy()[0, 0]


def test_the_proof_is_what_the_spectrophotometer_measures_on_the_print(chart):
    """Each patch's proof colour (its ink through the media profile, relative colorimetric)
    against the emulator's spectrophotometer on the printed patch made media-relative (ICC
    v4's XYZ scaling by the measured paper): within 1 ΔE2000, in gamut and out (measured
    0.5 at most); the out-of-gamut green's print is far from its source, and the proof
    shows the print, not the source."""
    from wideprint.device_sim.spectral import lab_to_xyz, observer, xyz_to_lab
    subprocess.run([sys.executable, "-m", "wideprint.app.cli", "print", str(chart / "chart.png"),
                    "--size", "pixels", "--spectro-out", str(chart / "lab.tif"),
                    "--preview", str(chart / "proof.png"), "--proof",
                    "--report", str(chart / "report.json")],
                   check=True, capture_output=True, timeout=300)
    measured, _ = read_lab(chart / "lab.tif")
    n = measured.shape[1] // len(PATCHES)

    def patch(i):
        return measured[n // 4:3 * n // 4, i * n + n // 4:i * n + 3 * n // 4].reshape(-1, 3).mean(0)
    paper = lab_to_xyz(patch(0))
    profile = load_profile(None)
    rgb = np.asarray(Image.open(chart / "chart.png"))
    proof = proof_image(rgb, "rgb", 8, ink_limit=profile.color.ink_limit_percent)
    from wideprint.rip.color import Separator, default_output_icc
    icc = default_output_icc("rgb")
    ink = Separator("rgb", 8, output_icc=icc,
                    ink_limit=profile.color.ink_limit_percent).convert(rgb)
    proof_lab = cmyk_to_lab(ink, icc)
    for i, (name, c) in enumerate(PATCHES.items()):
        m = xyz_to_lab(lab_to_xyz(patch(i)) * observer().white / paper)
        p = proof_lab[SIDE // 2, i * SIDE + SIDE // 2]
        assert delta_e2000(p, m) < 1.0, (name, p, m)
        oog = proof.out_of_gamut[:, i * SIDE:(i + 1) * SIDE].mean()
        if name == "green":
            assert delta_e2000(srgb_lab(c), m) > 10 and oog == 1.0
        else:
            assert delta_e2000(srgb_lab(c), m) < GAMUT_DE2000 and oog == 0.0
    report = json.loads((chart / "report.json").read_text())
    rep = report[0] if isinstance(report, list) else report["jobs"][0]
    assert rep["out_of_gamut"] == pytest.approx(0.2, abs=1e-9)
    png = np.asarray(Image.open(chart / "proof.png").convert("RGB"))
    assert png.shape == proof.rgb.shape
    alarm = (png != proof.rgb).any(axis=2)          # what the gamut warning painted
    green = slice(4 * SIDE, 5 * SIDE)
    assert alarm[:, green].mean() == pytest.approx(0.5, abs=0.05)   # striped, half
    assert (png[alarm] == ALARM_RGB).all()
    assert not alarm[:, :4 * SIDE].any()


def test_a_cmyk_file_printed_as_it_is_is_proofed_but_not_gamut_checked(tmp_path):
    import tifffile
    cmyk = np.zeros((40, 60, 4), np.uint8)
    cmyk[:, :30, 0] = 255
    tifffile.imwrite(tmp_path / "c.tif", cmyk, photometric="separated")
    profile = load_profile(None)
    p = proof_job(str(tmp_path / "c.tif"), from_mapping({"placement": {"size": "pixels"}},
                                                         profile), profile)
    assert p.share is None and p.out_of_gamut is None
    cyan, white = p.rgb[20, 10].astype(int), p.rgb[20, 50].astype(int)
    assert tuple(white) == (255, 255, 255)
    assert cyan[0] < 80 and cyan[2] > 150          # solid cyan on vinyl: a blue-green


def test_the_estimate_gives_the_share_out_of_gamut(chart):
    from wideprint.app.jobpreview import compute_preview
    profile = load_profile(None)
    pd = compute_preview(str(chart / "chart.png"),
                         from_mapping({"placement": {"size": "pixels"}}, profile), profile)
    assert pd.out_of_gamut == pytest.approx(0.2, abs=0.01)


def test_proof_needs_a_preview_to_write(chart):
    r = subprocess.run([sys.executable, "-m", "wideprint.app.cli", "rip", str(chart / "chart.png"),
                        "-o", str(chart / "p.tif"), "--proof"], capture_output=True, text=True)
    assert r.returncode == 2 and "--proof" in r.stderr


def test_the_server_gives_a_jobs_soft_proof(chart, tmp_path):
    from wideprint.app.server import PrintServer, ServerConfig
    from wideprint.app.client import Client
    srv = PrintServer(ServerConfig(state_dir=tmp_path / "state", port=0, start_paused=True))
    srv.start()
    client = Client(srv.state_dir)
    try:
        job = client.submit(chart / "chart.png",
                            settings={"placement": {"size": "pixels"}})["job"]
        import io
        png = np.asarray(Image.open(io.BytesIO(client.proof_png(job["id"], 400))).convert("RGB"))
        profile = load_profile(None)
        rgb = np.asarray(Image.open(chart / "chart.png"))
        want = proof_job(str(chart / "chart.png"), from_mapping({"placement": {"size": "pixels"}},
                                                                profile), profile, max_px=400)
        assert png.shape == want.rgb.shape and png.shape[1] == 400
        assert np.array_equal(png, want.with_warning())
        assert rgb.shape[1] == 5 * SIDE
        info = client.preview(job["id"], 400)
        assert info["out_of_gamut"] == pytest.approx(0.2, abs=0.01)
    finally:
        client.close()
        srv.stop(timeout=5)
