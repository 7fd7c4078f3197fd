"""A scanned chart is found wherever it lies on the glass (docs/media.md "Measuring with
the scanner"): its two bars give the similarity transform, so a chart turned a few degrees,
shifted and scaled gives the same patch readings as one lying straight."""

import numpy as np
import pytest

from wideprint.app.mediacal import Printer, find_chart
from wideprint.rip.profile import load_profile


@pytest.fixture(scope="module")
def charts():
    profile = load_profile(None)
    values = np.random.default_rng(3).integers(0, 256, (60, 4)).astype(np.uint8)
    out = {}
    for key, inject in (("straight", ()),
                        ("turned", ("scan-margin=40", "scan-rotation=3", "scan-offset=17,9")),
                        ("turned back", ("scan-margin=40", "scan-rotation=-4.5",
                                         "scan-offset=-2,30", "scan-scale=1.01"))):
        pr = Printer(profile, scan_dpi=150, inject=inject)
        pr.measure(values, profile)
        out[key] = pr.last_scan_rgb
    return out


@pytest.mark.parametrize("key", ["turned", "turned back"])
def test_a_turned_shifted_chart_reads_as_a_straight_one(charts, key):
    diff = np.abs(charts[key] - charts["straight"])
    # the patch means (4 x 4 mm at 150 dpi, ~550 pixels) differ only by the sensor's noise
    assert diff.max() < 1.5 and diff.mean() < 0.4, diff.max()
    # and the patches are really told apart: neighbours differ by far more
    assert np.abs(np.diff(charts["straight"], axis=0)).mean() > 20


def test_a_scan_without_the_chart_is_refused():
    blank = np.full((300, 400, 3), 240.0)
    with pytest.raises(ValueError, match="blank"):
        find_chart(blank, [(0, 0, 3, 36), (250, 0, 253, 36)], 150)
    dots = blank.copy()
    dots[100:120, 100:120] = 20                 # a dark square, not a bar
    with pytest.raises(ValueError, match="two bars were not found"):
        find_chart(dots, [(0, 0, 3, 36), (250, 0, 253, 36)], 150)
