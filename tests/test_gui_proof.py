"""The GUI's soft proof (docs/color.md "Soft proof", docs/gui.md): the preview's Proof box
shows the job as its media prints it, with the gamut warning, and the estimate says how
much of the image is out of the media's gamut.  The real window against a real server."""

from __future__ import annotations

import numpy as np
import pytest

pytest.importorskip("PySide6")
pytest.importorskip("pytestqt")

from PIL import Image  # noqa: E402

from support.gui import Server, open_window, select  # noqa: E402
from wideprint.app.softproof import ALARM_RGB  # noqa: E402


def shown_rgb(win) -> np.ndarray:
    img = win.preview.image_item.pixmap().toImage().convertToFormat(
        win.preview.image_item.pixmap().toImage().Format.Format_RGB888)
    a = np.frombuffer(img.constBits(), np.uint8, img.sizeInBytes()).reshape(
        img.height(), img.bytesPerLine())[:, :img.width() * 3]
    return a.reshape(img.height(), img.width(), 3).copy()


def test_the_proof_box_shows_the_media_print_with_the_gamut_warning(qtbot, tmp_path):
    server = Server(tmp_path, "--paused")
    win = open_window(qtbot, server, tmp_path / "cfg")
    try:
        rgb = np.zeros((120, 240, 3), np.uint8)
        rgb[:, :120] = (200, 140, 90)               # a colour the media prints
        rgb[:, 120:] = (0, 255, 0)                  # sRGB green: out of gamut
        Image.fromarray(rgb).save(tmp_path / "half.png")
        server.client.submit(tmp_path / "half.png", settings={"placement": {"size": "pixels"}})
        qtbot.waitUntil(lambda: len(win.queue_model.jobs) == 1, timeout=20_000)
        select(win, ["half.png"])
        qtbot.waitUntil(lambda: "out of the media's gamut" in win.estimate.note.text(),
                        timeout=30_000)
        assert "50.0 % out of the media's gamut" in win.estimate.note.text()
        halftone = shown_rgb(win)
        win.preview.proof.setChecked(True)
        qtbot.waitUntil(lambda: not np.array_equal(shown_rgb(win), halftone), timeout=30_000)
        proof = shown_rgb(win)
        h, w = proof.shape[:2]
        alarm = (proof == ALARM_RGB).all(axis=2)
        assert alarm[:, w // 2 + 2:].mean() > 0.4            # striped where out of gamut
        assert not alarm[:, :w // 2 - 2].any()
        left = proof[h // 2, w // 4].astype(int)
        assert abs(left - (200, 140, 90)).max() < 25          # in gamut: close to the source
        win.preview.proof.setChecked(False)
        qtbot.waitUntil(lambda: np.array_equal(shown_rgb(win), halftone), timeout=30_000)
    finally:
        win.link.stop()
        server.stop()
