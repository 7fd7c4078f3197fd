"""The operator GUI (app/gui), driven through the real main window with pytest-qt:
files added by the dialog's method and by drag and drop, settings changed through the
widgets, jobs printed on the in-process emulator and the media compared dot for dot with
the RIP's planes, a corrupt file failing its own row while the queue goes on, pause /
resume / cancel within a second, the calibration loop (alignment, dead nozzles from the
nozzle check), queue rows dragged to a new place, remembered settings."""

from __future__ import annotations

import time
import warnings
from pathlib import Path

import numpy as np
import pytest

pytest.importorskip("PySide6")
pytest.importorskip("pytestqt")

from PySide6.QtCore import QByteArray, QItemSelectionModel, QMimeData, QPoint, QPointF, Qt, QUrl  # noqa: E402
from PySide6.QtGui import QDragEnterEvent, QDragMoveEvent, QDropEvent  # noqa: E402
from PySide6.QtWidgets import QApplication  # noqa: E402

from conftest import random_planes, write_cmyk_tiff  # noqa: E402
from wideprint.app.gui import queue as Q  # noqa: E402
from wideprint.app.gui.main_window import MainWindow  # noqa: E402
from wideprint.rip.pipeline import RipJob  # noqa: E402
from wideprint.rip.planes import read_planes, render_rgb  # noqa: E402
from wideprint.rip.profile import DEFAULT_PROFILE, load_profile  # noqa: E402

LONG = 60_000      # ms: generous waits for whole jobs


def make_window(qtbot, cfg: Path, media: Path | None = None, speed: float = 0.0) -> MainWindow:
    w = MainWindow(config_dir=cfg)
    w.ask_before_closing = False
    qtbot.addWidget(w)
    w.show()
    if media is not None:
        w.device.media_dir.setText(str(media))
        w.device.media_dir.editingFinished.emit()
    w.device.speed.setCurrentIndex(w.device.speed.findData(speed))
    one_pixel_one_dot(w)
    return w


@pytest.fixture
def win(qtbot, tmp_path):
    return make_window(qtbot, tmp_path / "cfg", tmp_path / "media")


def choose(combo, data) -> None:
    i = combo.findData(data)
    assert i >= 0, f"{combo.objectName()}: no item {data!r}"
    combo.setCurrentIndex(i)


def wait_ready(qtbot, items, timeout=30_000) -> None:
    qtbot.waitUntil(lambda: all(i.state != Q.LOADING for i in items), timeout=timeout)


def cell(win, item, col) -> str:
    return win.model.data(win.model.index(win.model.row_of(item.id), col))


def drop_files(win, paths) -> None:
    md = QMimeData()
    md.setUrls([QUrl.fromLocalFile(str(p)) for p in paths])
    with warnings.catch_warnings():      # the QPoint constructor is the only one PySide6 has
        warnings.simplefilter("ignore", DeprecationWarning)
        enter = QDragEnterEvent(QPoint(200, 200), Qt.CopyAction, md, Qt.LeftButton, Qt.NoModifier)
    QApplication.sendEvent(win, enter)
    assert enter.isAccepted()
    drop = QDropEvent(QPointF(200, 200), Qt.CopyAction, md, Qt.LeftButton, Qt.NoModifier)
    QApplication.sendEvent(win, drop)


def one_pixel_one_dot(win) -> None:
    """Keep these pixel-exact test images 1:1 (no resampling by rip/place.py)."""
    choose(win.settings_panel.size_mode, "pixels")


def rip_planes(tmp_path, item, win) -> np.ndarray:
    """What the RIP intends for this item, with the very settings the GUI printed it with."""
    prof = load_profile(win.profile_path(item.settings))
    job = RipJob(item.path, item.settings.rip_settings(win._media_width(item.settings)), prof)
    out = tmp_path / f"planes-{item.id}.tif"
    job.write_planes(out)
    job.close()
    return read_planes(out)


# -------------------------------------------------------------------------------------------
def test_add_by_dialog_method_and_by_drop_with_previews_and_estimates(qtbot, win, tmp_path):
    a = write_cmyk_tiff(tmp_path / "a.tif", random_planes(200, 300, seed=1))
    b = write_cmyk_tiff(tmp_path / "b.tif", random_planes(150, 250, seed=2))
    import cv2
    c = tmp_path / "c.bmp"
    cv2.imwrite(str(c), (np.random.default_rng(3).random((90, 130, 3)) * 255).astype(np.uint8))
    items = win.add_files([str(a)])                     # what the file dialog calls
    drop_files(win, [b, c])
    assert [Path(i.path).name for i in win.model.items] == ["a.tif", "b.tif", "c.bmp"]
    items = win.model.items
    wait_ready(qtbot, items)
    assert [i.state for i in items] == [Q.READY] * 3, [i.message for i in items]
    assert items[2].estimate.width_dots > 0 and win._previews[items[2].id].dots.any()
    e = items[0].estimate
    prof = load_profile(win.user_profile)
    assert (e.width_dots, e.height_rows, e.strokes) == (300, 200, 1)
    assert e.width_mm == pytest.approx(300 / 300 * 25.4)
    assert e.height_mm == pytest.approx(200 * prof.row_um / 1000)
    # the preview of a small image is the RIP's own halftone: its drops give the ink exactly
    job = RipJob(str(a), items[0].settings.rip_settings(), prof)
    ht = np.concatenate(list(job.halftone_bands()))
    job.close()
    data = win._previews[items[0].id]
    assert data.exact and np.array_equal(data.dots, ht)
    assert e.drops == [int(v) for v in ht.reshape(-1, 4).sum(axis=0)]
    assert e.ink_ml[0] == pytest.approx(e.drops[0] * prof.drop_volume_pl * 1e-9)
    assert cell(win, items[0], Q.QueueModel.COL_SIZE) == "25 × 14 mm"
    # the selected job's preview is painted; C only shows no magenta, yellow or black
    win.select_item(items[0].id)
    qtbot.waitUntil(lambda: win.preview.has_image, timeout=10_000)
    for name in "MYK":
        win.preview.seps[name].setChecked(False)

    def only_cyan():
        img = win.preview.image_item.pixmap().toImage().convertToFormat(
            win.preview.image_item.pixmap().toImage().Format.Format_RGB888)
        arr = np.frombuffer(img.constBits(), np.uint8).reshape(img.height(), img.bytesPerLine())[:, :img.width() * 3]
        rgb = arr.reshape(img.height(), img.width(), 3)
        return np.array_equal(rgb, render_rgb(ht * np.array([1, 0, 0, 0], np.uint8)))
    qtbot.waitUntil(only_cyan, timeout=10_000)


def test_settings_widgets_print_on_the_emulator_equal_to_the_rip_planes(qtbot, win, tmp_path):
    src = write_cmyk_tiff(tmp_path / "job.tif", random_planes(300, 240, density=0.35, seed=3))
    sp = win.settings_panel
    choose(sp.passes, 2)
    choose(sp.direction, True)
    choose(sp.dither, "stucki")
    choose(sp.dpi, 600)
    if sp.pass_mask.isEnabled():
        choose(sp.pass_mask, sp.pass_mask.itemData(sp.pass_mask.count() - 1))
    (item,) = win.add_files([str(src)])
    assert (item.settings.passes, item.settings.bidir, item.settings.dither, item.settings.dpi) == \
        (2, True, "stucki", 600)
    if sp.pass_mask.isEnabled():
        assert item.settings.rip_settings().pass_mask == sp.pass_mask.currentData() != "checker"
    wait_ready(qtbot, [item])
    with qtbot.waitSignal(win.queueFinished, timeout=LONG):
        assert win.print_queue() == 1
    assert item.state == Q.DONE, item.message
    assert item.progress == 1.0
    media = read_planes(item.media[0])
    planes = rip_planes(tmp_path, item, win)
    assert media.shape == planes.shape
    assert planes.any() and np.array_equal(media, planes)
    rep = item.reports[0]
    assert rep["strokes_total"] == item.estimate.strokes
    # the live view filled in with exactly what landed (1 canvas pixel per dot here)
    assert np.array_equal(win.live.canvas_array(), render_rgb(media))
    assert "done" in win.logview.toPlainText()


def test_placement_controls_scale_rotate_mirror_reach_the_rip(qtbot, win, tmp_path):
    sp = win.settings_panel
    src = write_cmyk_tiff(tmp_path / "p.tif", random_planes(90, 160, density=0.4, seed=10))
    choose(sp.size_mode, "scale")
    sp.scale.setValue(150)
    choose(sp.rotate, 90)
    sp.mirror.setChecked(True)
    (item,) = win.add_files([str(src)])
    wait_ready(qtbot, [item])
    pl = item.settings.placement()
    assert (pl.scale, pl.rotate, pl.mirror) == (1.5, 90, True)
    assert (pl.align, pl.x_mm, pl.margin_mm, pl.top_mm) == ("left", 0.0, None, 0.0)
    e = item.estimate
    from wideprint.rip.load import open_image
    with open_image(str(src)) as f:
        xres, yres = f.xres or 300.0, f.yres or f.xres or 300.0
    rows_per_inch = 25.4e3 / load_profile(win.user_profile).row_um
    # rotated a quarter turn: the 90 source rows become the width, the 160 columns the length
    assert (e.width_dots, e.height_rows) == (round(90 / yres * 1.5 * 300),
                                             round(160 / xres * 1.5 * rows_per_inch))
    assert win._previews[item.id].dots.shape[:2] == (e.height_rows, e.width_dots)
    with qtbot.waitSignal(win.queueFinished, timeout=LONG):
        win.print_queue()
    assert item.state == Q.DONE, item.message
    media = read_planes(item.media[0])
    assert media.shape[:2] == (e.height_rows, e.width_dots)
    assert np.array_equal(media, rip_planes(tmp_path, item, win))
    # position and margins reach the placement too (the driver applies them)
    choose(sp.align, "center")
    sp.x_mm.setValue(-12.5)
    sp.margin_mm.setValue(8)
    sp.top_mm.setValue(30)
    js = sp.settings()
    assert (js.align, js.x_mm, js.margin_mm, js.top_mm) == ("center", -12.5, 8.0, 30.0)
    pl2 = js.placement()
    assert (pl2.align, pl2.x_mm, pl2.margin_mm, pl2.top_mm) == ("center", -12.5, 8.0, 30.0)
    sp.margin_mm.setValue(-0.1)                    # "profile"
    assert sp.settings().margin_mm is None
    sp.set_settings(js)
    assert sp.settings() == js


def test_corrupt_file_fails_its_row_and_the_queue_goes_on(qtbot, win, tmp_path):
    bad = tmp_path / "bad.tif"
    bad.write_bytes(b"II*\x00" + b"\x08\x00\x00\x00" + b"\xff" * 40)
    cut = tmp_path / "cut.tif"
    good_src = write_cmyk_tiff(tmp_path / "whole.tif", random_planes(400, 300, seed=4))
    cut.write_bytes(good_src.read_bytes()[:2000])          # header fine, pixel data gone
    good = write_cmyk_tiff(tmp_path / "good.tif", random_planes(120, 200, seed=5))
    items = win.add_files([str(bad), str(cut), str(good)])
    wait_ready(qtbot, items)
    assert items[0].state == Q.ERROR and "bad.tif" in cell(win, items[0], Q.QueueModel.COL_MESSAGE)
    with qtbot.waitSignal(win.queueFinished, timeout=LONG):
        win.print_queue()
    assert [i.state for i in items] == [Q.FAILED, Q.FAILED, Q.DONE], [i.message for i in items]
    for it in items[:2]:
        msg = cell(win, it, Q.QueueModel.COL_MESSAGE)
        assert Path(it.path).name in msg, msg
        assert cell(win, it, Q.QueueModel.COL_STATE) == "Failed"
    assert np.array_equal(read_planes(items[2].media[0]), rip_planes(tmp_path, items[2], win))


def test_pause_resume_and_cancel_within_a_second(qtbot, tmp_path):
    win = make_window(qtbot, tmp_path / "cfg", speed=0.0)
    qtbot.mouseClick(win.device.connect_btn, Qt.LeftButton)          # home and measure, fast
    qtbot.waitUntil(lambda: win.connected, timeout=LONG)
    assert "3,200 mm" in win.device.paper.text()
    win.device.speed.setCurrentIndex(win.device.speed.findData(1.0))  # now at real time
    assert win.pace.speed == 1.0
    src = write_cmyk_tiff(tmp_path / "long.tif", random_planes(600, 400, seed=6))
    choose(win.settings_panel.passes, 8)
    (item,) = win.add_files([str(src)])
    wait_ready(qtbot, [item])
    assert item.estimate.strokes > 20
    win.print_queue()
    qtbot.waitUntil(lambda: item.progress > 0, timeout=LONG)           # the 2nd stroke is coming
    win.actions_["pause"].trigger()
    qtbot.waitUntil(lambda: item.state == Q.PAUSED, timeout=10_000)
    printed = win.worker.current_job.telemetry.strokes_printed
    qtbot.wait(600)
    assert win.worker.current_job.telemetry.strokes_printed == printed   # nothing moves
    win.actions_["resume"].trigger()
    qtbot.waitUntil(lambda: item.state == Q.PRINTING, timeout=5_000)
    qtbot.waitUntil(lambda: win.worker.current_job is not None and
                    win.worker.current_job.telemetry.strokes_printed > printed, timeout=LONG)
    # cancel mid-line: the job stops within a second
    qtbot.waitUntil(lambda: win.worker.current_job is not None and
                    win.worker.current_job.telemetry.fires_done > 0, timeout=LONG)
    t0 = time.monotonic()
    win.actions_["cancel"].trigger()
    qtbot.waitUntil(lambda: item.state == Q.CANCELLED, timeout=1_000)
    assert time.monotonic() - t0 < 1.0
    rep = item.reports[-1]
    assert rep["state"] == "cancelled" and rep["strokes_printed"] < rep["strokes_total"]
    assert win.device.state.text().startswith("Cancelled")
    assert not win.running and win.actions_["print"].isEnabled()


def test_bidirectional_calibration_writes_the_user_profile(qtbot, tmp_path):
    cfg = tmp_path / "cfg"
    win = make_window(qtbot, cfg, tmp_path / "media")
    win.device.faults.setText("bidir-error=2")                       # a misaligned machine
    win.device.faults.editingFinished.emit()
    dlg = win.open_calibration()
    choose(dlg.pattern, "bidir-align")
    choose(dlg.dpi, 150)
    qtbot.mouseClick(dlg.print_btn, Qt.LeftButton)
    qtbot.waitUntil(lambda: dlg.media is not None or "failed" in dlg.status.text(), timeout=LONG)
    assert dlg.media is not None, dlg.status.text()
    assert dlg.bidir_choice.currentData() == 2                       # suggested from the media
    user = cfg / "printers" / "user.toml"
    assert load_profile(user).bidir_offset_columns[150] == 0
    qtbot.mouseClick(dlg.save_btn, Qt.LeftButton)
    assert load_profile(user).bidir_offset_columns[150] == 2
    assert load_profile(DEFAULT_PROFILE).bidir_offset_columns[150] == 0
    assert dlg.view.suggested == 2
    # the next pattern in the same dialog does not keep the bidir suggestion's box
    choose(dlg.pattern, "head-align")
    qtbot.mouseClick(dlg.print_btn, Qt.LeftButton)
    qtbot.waitUntil(lambda: dlg.media is not None, timeout=LONG)
    assert dlg.view.suggested is None
    dlg.close()
    # the calibrated user profile now prints bidirectionally exactly on the same machine
    src = write_cmyk_tiff(tmp_path / "bi.tif", random_planes(400, 200, seed=7))
    choose(win.settings_panel.dpi, 150)
    choose(win.settings_panel.passes, 2)
    choose(win.settings_panel.direction, True)
    (item,) = win.add_files([str(src)])
    wait_ready(qtbot, [item])
    with qtbot.waitSignal(win.queueFinished, timeout=LONG):
        win.print_queue()
    assert item.state == Q.DONE, item.message
    assert np.array_equal(read_planes(item.media[0]), rip_planes(tmp_path, item, win))


def test_head_alignment_and_nozzle_check_through_the_dialog(qtbot, tmp_path):
    cfg = tmp_path / "cfg"
    win = make_window(qtbot, cfg)
    win.device.faults.setText("head-error=M1:12 dead-nozzle=Y2:40")   # M1 sits 3 columns right
    win.device.faults.editingFinished.emit()
    dlg = win.open_calibration()
    choose(dlg.pattern, "nozzle-check")
    qtbot.mouseClick(dlg.print_btn, Qt.LeftButton)
    qtbot.waitUntil(lambda: dlg.media is not None, timeout=LONG)
    assert "Y2:40" in dlg.nozzle_result.text() and "M1" not in dlg.nozzle_result.text()
    choose(dlg.pattern, "head-align")
    choose(dlg.dpi, 150)
    qtbot.mouseClick(dlg.print_btn, Qt.LeftButton)
    qtbot.waitUntil(lambda: dlg.media is not None, timeout=LONG)
    assert dlg.head_choice["M1"].currentData() == -3
    assert all(cb.currentData() == 0 for n, cb in dlg.head_choice.items() if n != "M1")
    user = cfg / "printers" / "user.toml"
    before = {h.name: h.x_counts for h in load_profile(user).heads}
    qtbot.mouseClick(dlg.save_btn, Qt.LeftButton)
    after = {h.name: h.x_counts for h in load_profile(user).heads}
    assert after == {**before, "M1": before["M1"] + 12}


def test_fault_is_explained_in_plain_language(qtbot, tmp_path):
    win = make_window(qtbot, tmp_path / "cfg", tmp_path / "media")
    win.device.faults.setText("paper-width-mm=20")
    win.device.faults.editingFinished.emit()
    src = write_cmyk_tiff(tmp_path / "wide.tif", random_planes(100, 400, seed=8))
    (item,) = win.add_files([str(src)])
    wait_ready(qtbot, [item])
    with qtbot.waitSignal(win.queueFinished, timeout=LONG):
        win.print_queue()
    assert item.state == Q.FAILED and "paper is 20 mm" in item.message
    assert "wider than the loaded paper" in win.device.fault.text()


def test_queue_reorder_duplicate_remove(qtbot, win, tmp_path):
    paths = [write_cmyk_tiff(tmp_path / f"{n}.tif", random_planes(40, 60, seed=i))
             for i, n in enumerate("abc")]
    win.add_files([str(p) for p in paths])
    names = lambda: [Path(i.path).stem for i in win.model.items]  # noqa: E731
    wait_ready(qtbot, win.model.items)
    win.select_item(win.model.items[2].id)
    win.actions_["up"].trigger()
    assert names() == ["a", "c", "b"]
    win.actions_["duplicate"].trigger()
    assert names() == ["a", "c", "c", "b"]
    assert win.model.items[1].id != win.model.items[2].id
    win.select_item(win.model.items[0].id)
    win.actions_["down"].trigger()
    win.actions_["remove"].trigger()
    assert names() == ["c", "c", "b"]


def test_settings_are_remembered(qtbot, tmp_path):
    cfg = tmp_path / "cfg"
    win = make_window(qtbot, cfg, tmp_path / "media", speed=5.0)
    choose(win.settings_panel.dpi, 150)
    choose(win.settings_panel.dither, "bluenoise")
    win.settings_panel.copies.setValue(3)
    win.device.spec.setText("serial=/dev/ttyUSB0,data=tcp://10.0.0.9:5000")
    win.device.spec.editingFinished.emit()
    win.preview.seps["Y"].setChecked(False)
    win.close()
    assert (cfg / "gui.json").exists()
    again = make_window(qtbot, cfg)
    s = again.settings_panel.settings()
    assert (s.dpi, s.dither, s.copies) == (150, "bluenoise", 3)
    assert again.device.spec.text() == "serial=/dev/ttyUSB0,data=tcp://10.0.0.9:5000"
    assert again.device.media_dir.text() == str(tmp_path / "media")
    assert again.preview.separations() == [True, True, False, True]
    assert (cfg / "printers" / "user.toml").exists()


def test_emergency_stop_then_clear_fault_and_print_again(qtbot, tmp_path):
    win = make_window(qtbot, tmp_path / "cfg", tmp_path / "media")
    qtbot.mouseClick(win.device.connect_btn, Qt.LeftButton)
    qtbot.waitUntil(lambda: win.connected, timeout=LONG)
    win.device.speed.setCurrentIndex(win.device.speed.findData(1.0))
    src = write_cmyk_tiff(tmp_path / "e.tif", random_planes(300, 300, seed=9))
    choose(win.settings_panel.passes, 4)
    (item,) = win.add_files([str(src)])
    wait_ready(qtbot, [item])
    win.print_queue()
    qtbot.waitUntil(lambda: win.worker.current_job is not None and
                    win.worker.current_job.telemetry.fires_done > 0, timeout=LONG)
    t0 = time.monotonic()
    qtbot.mouseClick(win.device.estop, Qt.LeftButton)
    qtbot.waitUntil(lambda: item.state == Q.FAILED, timeout=1_000)
    assert time.monotonic() - t0 < 1.0
    assert "emergency stop" in item.message
    assert "Clear fault" in win.device.fault.text()              # the plain-language advice
    emu = win.worker.dev.emulator
    assert emu.fault != 0                                         # the machine is stopped
    win.actions_["clear_fault"].trigger()
    qtbot.waitUntil(lambda: emu.fault == 0 and win.device.fault.text() == "", timeout=10_000)
    win.device.speed.setCurrentIndex(win.device.speed.findData(0.0))
    with qtbot.waitSignal(win.queueFinished, timeout=LONG):
        win.print_queue()
    assert item.state == Q.DONE, item.message
    assert np.array_equal(read_planes(item.media[-1]), rip_planes(tmp_path, item, win))


# -------------------------------------------------------------------------------------------
# dragging queue rows

def names_of(win) -> list[str]:
    return [Path(i.path).stem for i in win.model.items]


def select_rows(win, rows) -> None:
    sm = win.table.selectionModel()
    sm.clearSelection()
    for r in rows:
        sm.select(win.model.index(r, 0), QItemSelectionModel.Select | QItemSelectionModel.Rows)


def drag_to(win, mime, row: int, half: str = "top"):
    """Drag `mime` over the queue and drop it in the top or bottom half of `row` (a row past
    the last: the empty space below the rows), through the view's own drag and drop
    handlers (a real QDrag cannot run offscreen).  Returns (drag accepted, the row the
    drop line was drawn above, drop accepted)."""
    view = win.table
    n = win.model.rowCount()
    if row >= n:
        y = view.rowViewportPosition(n - 1) + view.rowHeight(n - 1) + 6
        assert y < view.viewport().height()
    else:
        y = view.rowViewportPosition(row) + view.rowHeight(row) * (0.25 if half == "top" else 0.75)
    pos = QPoint(60, int(y))
    with warnings.catch_warnings():      # the QPoint constructors are the only ones PySide6 has
        warnings.simplefilter("ignore", DeprecationWarning)
        enter = QDragEnterEvent(pos, Qt.MoveAction, mime, Qt.LeftButton, Qt.NoModifier)
        move = QDragMoveEvent(pos, Qt.MoveAction, mime, Qt.LeftButton, Qt.NoModifier)
    QApplication.sendEvent(view.viewport(), enter)
    QApplication.sendEvent(view.viewport(), move)
    line = view.drop_row
    drop = QDropEvent(QPointF(pos), Qt.MoveAction, mime, Qt.LeftButton, Qt.NoModifier)
    QApplication.sendEvent(view.viewport(), drop)
    assert view.drop_row is None
    return enter.isAccepted() and move.isAccepted(), line, drop.isAccepted()


def test_queue_rows_are_dragged_to_a_new_place(qtbot, win, tmp_path):
    paths = [write_cmyk_tiff(tmp_path / f"{n}.tif", random_planes(30, 40, seed=i))
             for i, n in enumerate("abcde")]
    win.add_files([str(p) for p in paths])
    wait_ready(qtbot, win.model.items)
    assert names_of(win) == list("abcde")
    # one job, one row down: the same as Move down (which undoes it with Move up)
    select_rows(win, [1])
    assert drag_to(win, win.table.drag_mime(), 2, "bottom") == (True, 3, True)
    assert names_of(win) == list("acbde")
    assert [Path(i.path).stem for i in win.selected_items()] == ["b"]       # the selection follows
    assert cell(win, win.model.items[2], 0) == "3"
    win.actions_["up"].trigger()
    assert names_of(win) == list("abcde")
    # several jobs together, in their order, between two rows and to the end
    select_rows(win, [4, 0, 2])
    assert drag_to(win, win.table.drag_mime(), 1, "top") == (True, 1, True)
    assert names_of(win) == list("acebd")
    assert [Path(i.path).stem for i in win.selected_items()] == list("ace")
    select_rows(win, [0, 3])
    assert drag_to(win, win.table.drag_mime(), 9) == (True, 5, True)
    assert names_of(win) == list("cedab")
    # a drop where the jobs already are changes nothing
    select_rows(win, [1])
    assert drag_to(win, win.table.drag_mime(), 1, "bottom")[2] is False
    assert names_of(win) == list("cedab")
    # Qt's moveRows is the same move (rows 3..4 before row 0)
    assert win.model.moveRows(win.model.index(0, 0).parent(), 3, 2, win.model.index(0, 0).parent(), 0)
    assert names_of(win) == list("abced")
    # other drags are not rows: image files dropped on the queue are added, not moved
    extra = write_cmyk_tiff(tmp_path / "f.tif", random_planes(30, 40, seed=9))
    md = QMimeData()
    md.setUrls([QUrl.fromLocalFile(str(extra))])
    assert drag_to(win, md, 0)[1] is None
    assert names_of(win) == list("abcedf")


def test_a_printing_job_keeps_its_place_and_drags_change_the_print_order(qtbot, win, tmp_path):
    paths = [write_cmyk_tiff(tmp_path / f"{n}.tif", random_planes(30, 40, seed=i))
             for i, n in enumerate("abcd")]
    items = win.add_files([str(p) for p in paths])
    wait_ready(qtbot, items)
    a, b, c, d = items
    started = []
    win.worker.jobStarted.connect(lambda item_id, info: started.append(item_id))
    with qtbot.waitSignal(win.queueFinished, timeout=LONG):
        assert win.print_queue() == 4
        # (no events are processed in this block, so a stays "Printing" while we look)
        assert a.state == Q.PRINTING and [b.state, c.state, d.state] == [Q.WAITING] * 3
        select_rows(win, [0])
        assert win.table.drag_mime() is None                        # it cannot be dragged
        assert not win.model.flags(win.model.index(0, 0)) & Qt.ItemIsDragEnabled
        assert not win.actions_["down"].isEnabled()                 # nor moved by the buttons
        win.move_selected(1)
        assert not win.model.move_items([a.id], 3)
        forged = QMimeData()                                        # nor by a hand-made drop
        forged.setData(Q.QueueModel.MIME_TYPE, QByteArray(
            f'{{"model": "{win.model._token}", "ids": [{a.id}]}}'.encode()))
        assert drag_to(win, forged, 3, "bottom") == (False, None, False)
        assert names_of(win) == list("abcd")
        # the printing job and d selected: only d moves, to right after a
        select_rows(win, [0, 3])
        assert drag_to(win, win.table.drag_mime(), 1, "top") == (True, 1, True)
        assert names_of(win) == list("adbc")
        select_rows(win, [3])
        assert win.actions_["up"].isEnabled()
    assert [it.state for it in items] == [Q.DONE] * 4, [it.message for it in items]
    assert started == [a.id, d.id, b.id, c.id]                      # what printed next


# -------------------------------------------------------------------------------------------
# dead nozzles from the nozzle check

def dead_in(path) -> set[tuple[str, int]]:
    prof = load_profile(path)
    return {(prof.heads[h].name, z) for h, z in prof.dead_nozzles}


def listed(dlg) -> list[str]:
    return [dlg.dead_list.item(i).text() for i in range(dlg.dead_list.count())]


def test_dead_nozzles_marked_after_the_nozzle_check_are_printed_around(qtbot, tmp_path):
    cfg = tmp_path / "cfg"
    user = cfg / "printers" / "user.toml"
    win = make_window(qtbot, cfg, tmp_path / "media")
    win.device.faults.setText("dead-nozzle=M1:57 dead-nozzle=K2:3")
    win.device.faults.editingFinished.emit()
    src = write_cmyk_tiff(tmp_path / "job.tif", random_planes(300, 240, density=0.35, seed=11))
    choose(win.settings_panel.passes, 2)
    (first,) = win.add_files([str(src)])
    wait_ready(qtbot, [first])
    with qtbot.waitSignal(win.queueFinished, timeout=LONG):
        win.print_queue()
    assert first.state == Q.DONE, first.message
    planes = rip_planes(tmp_path, first, win)
    lost = planes.astype(np.int16) - read_planes(first.media[0])
    # not marked yet: the dead nozzles' dots are missing, in magenta and black, nothing else
    assert lost.min() == 0 and lost.max() == 1
    assert set(np.flatnonzero(lost.reshape(-1, 4).any(axis=0))) == {1, 3}

    dlg = win.open_calibration()
    choose(dlg.pattern, "nozzle-check")
    assert listed(dlg) == [] and not dlg.save_btn.isEnabled()
    qtbot.mouseClick(dlg.print_btn, Qt.LeftButton)
    qtbot.waitUntil(lambda: dlg.media is not None or "failed" in dlg.status.text(), timeout=LONG)
    assert "M1:57" in dlg.nozzle_result.text() and "K2:3" in dlg.nozzle_result.text()
    # the operator marks one by hand (what works on a real printer) ...
    choose(dlg.dead_head, "M1")
    dlg.dead_nozzle.setValue(57)
    qtbot.mouseClick(dlg.mark_btn, Qt.LeftButton)
    assert listed(dlg) == ["M1:57"] and dlg.save_btn.isEnabled()
    assert dlg.dead_nozzle.minimum() == 1 and dlg.dead_nozzle.maximum() == 126
    # ... and the rest of what the emulator's print shows
    assert dlg.mark_missing_btn.isEnabled()
    qtbot.mouseClick(dlg.mark_missing_btn, Qt.LeftButton)
    assert listed(dlg) == ["M1:57", "K2:3"] and not dlg.mark_missing_btn.isEnabled()
    assert dead_in(user) == set()                                  # nothing written before Save
    with qtbot.waitSignal(dlg.profileSaved, timeout=5_000):
        qtbot.mouseClick(dlg.save_btn, Qt.LeftButton)
    assert dead_in(user) == {("M1", 57), ("K2", 3)}
    text = user.read_text()
    assert 'dead_nozzles = [{ head = "M1", nozzle = 57 }, { head = "K2", nozzle = 3 }]' in text
    assert "# Nozzles listed here never fire" in text              # the file's comments stay
    assert dead_in(DEFAULT_PROFILE) == set()
    assert not dlg.save_btn.isEnabled() and "M1:57, K2:3" in dlg.dead_now.text()
    # the nozzle check still prints (every nozzle fires in a test print) and still shows them
    dlg.media = None
    qtbot.mouseClick(dlg.print_btn, Qt.LeftButton)
    qtbot.waitUntil(lambda: dlg.media is not None or "failed" in dlg.status.text(), timeout=LONG)
    assert dlg.media is not None, dlg.status.text()
    assert "M1:57" in dlg.nozzle_result.text() and "printed:" not in dlg.nozzle_result.text()
    dlg.close()

    # with the saved profile: a 1-pass job is refused with the planner's reason on its row,
    # the queue goes on, and a 2-pass job prints exactly on the machine with dead nozzles
    win.table.clearSelection()
    choose(win.settings_panel.passes, 1)
    (one,) = win.add_files([str(src)])
    win.table.clearSelection()
    choose(win.settings_panel.passes, 2)
    (two,) = win.add_files([str(src)])
    qtbot.waitUntil(lambda: one.state == Q.ERROR and two.state == Q.READY, timeout=30_000)
    assert "M1:57" in cell(win, one, Q.QueueModel.COL_MESSAGE)
    assert "use more passes" in cell(win, one, Q.QueueModel.COL_MESSAGE)
    with qtbot.waitSignal(win.queueFinished, timeout=LONG):
        win.print_queue()
    assert one.state == Q.FAILED and "use more passes" in one.message
    assert "Traceback" not in win.logview.toPlainText()            # refused, not crashed
    assert cell(win, one, Q.QueueModel.COL_STATE) == "Failed"
    assert two.state == Q.DONE, two.message
    assert two.reports[0]["strokes_total"] == two.estimate.strokes
    assert np.array_equal(read_planes(two.media[0]), rip_planes(tmp_path, two, win))
    win.select_item(one.id)
    qtbot.waitUntil(lambda: "2 or more passes" in win.preview.overlay.text(), timeout=5_000)

    # a replaced head: clear its nozzles; then the rest
    dlg = win.open_calibration()
    assert dlg.kind == "nozzle-check" and listed(dlg) == ["M1:57", "K2:3"]
    choose(dlg.dead_head, "C1")
    assert not dlg.clear_head_btn.isEnabled()                      # nothing marked on C1
    choose(dlg.dead_head, "K2")
    assert dlg.clear_head_btn.isEnabled() and dlg.clear_head_btn.text() == "Clear K2"
    qtbot.mouseClick(dlg.clear_head_btn, Qt.LeftButton)
    assert listed(dlg) == ["M1:57"] and "clear K2:3" in dlg.dead_now.text()
    qtbot.mouseClick(dlg.save_btn, Qt.LeftButton)
    assert dead_in(user) == {("M1", 57)}
    dlg.dead_nozzle.setValue(100)
    qtbot.mouseClick(dlg.mark_btn, Qt.LeftButton)                  # K2:100 marked, then Delete
    assert listed(dlg) == ["M1:57", "K2:100"]
    dlg.dead_list.item(1).setSelected(True)
    qtbot.keyClick(dlg.dead_list, Qt.Key_Delete)
    assert listed(dlg) == ["M1:57"] and not dlg.save_btn.isEnabled()
    dlg.dead_list.item(0).setSelected(True)
    qtbot.mouseClick(dlg.remove_dead_btn, Qt.LeftButton)
    assert listed(dlg) == [] and dlg.save_btn.isEnabled()
    qtbot.mouseClick(dlg.save_btn, Qt.LeftButton)
    assert dead_in(user) == set() and "dead_nozzles = []" in user.read_text()
    dlg.dead_nozzle.setValue(57)                                   # K2:57 marked, then Clear all
    qtbot.mouseClick(dlg.mark_btn, Qt.LeftButton)
    assert listed(dlg) == ["K2:57"]
    qtbot.mouseClick(dlg.clear_all_btn, Qt.LeftButton)
    assert listed(dlg) == [] and not dlg.save_btn.isEnabled()
    dlg.close()
