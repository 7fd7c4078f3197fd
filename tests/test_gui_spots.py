"""The GUI lists a job's spot colours (docs/gui.md "Spot colours", docs/spot.md; issue 35):
a PDF with two library spots, one spot in no library and a cut line, printed by a real
`wideprint serve --state-dir` whose spot library is in that state folder; the preview panel
lists each with its swatch, how it printed and its ΔE2000."""

from __future__ import annotations

import pytest

pytest.importorskip("PySide6")
pytest.importorskip("pytestqt")

from support.gui import LONG, Server, open_window  # noqa: E402
from support.printcut import BRAND, make_pdf  # noqa: E402
from wideprint.app.gui.preview import lab_to_srgb  # noqa: E402
from wideprint.rip import spot  # noqa: E402


def test_the_preview_lists_the_jobs_spots_with_swatch_resolution_and_de(qtbot, tmp_path, monkeypatch):
    monkeypatch.delenv("WIDEPRINT_SPOT_DIR", raising=False)        # the server's own library
    monkeypatch.setenv("WIDEPRINT_STATE_DIR", str(tmp_path / "elsewhere"))
    spot.SpotBook(tmp_path / "state" / "spots").add(
        [spot.Spot(n, lab) for n, lab in BRAND.items()], "brand")
    pdf = make_pdf(tmp_path / "spots.pdf")
    server = Server(tmp_path)
    win = open_window(qtbot, server, tmp_path / "cfg")
    try:
        job = server.client.submit(pdf, settings={"dpi": 150})["job"]
        assert server.client.wait(job["id"], timeout=LONG / 1000)["state"] == "done"
        win.tabs.setCurrentIndex(1)
        qtbot.waitUntil(lambda: any(j["id"] == job["id"] for j in win.history_model.jobs),
                        timeout=30_000)
        win.history_view.select_ids([job["id"]])
        win._show_selection()
        lst = win.preview.spot_list
        qtbot.waitUntil(lambda: lst.rowCount() == 4, timeout=30_000)
        assert lst.isVisible()
        rows = {r[0]: r for r in lst.rows()}
        assert set(rows) == {"Brand Red", "Brand Teal", "Other Green", "CutContour"}
        recorded = {s["name"]: s for s in server.client.job(job["id"])["spots"]}
        for name, lab in BRAND.items():
            _, how, de, rgb = rows[name]
            assert how == "library: through the media profile"
            assert de == f"{recorded[name]['de2000']:.2f}" and float(de) <= 1.0
            assert rgb == lab_to_srgb(lab)                 # the brand's colour, not the recipe's guess
        assert rows["Brand Red"][3][0] > 180 and rows["Brand Red"][3][1] < 80      # a red swatch
        assert rows["Other Green"][1:] == ("alternate: the document's own", "", None)
        assert rows["CutContour"][1] == "cut line: not printed"
        win.history_view.select_ids([])                    # nothing selected: no list
        win._show_selection()
        assert lst.rowCount() == 0 and not lst.isVisible()
    finally:
        win.link.stop()
        server.stop()
