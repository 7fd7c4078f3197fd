"""The operator's day in the GUI (issue 34): nothing changes by accident (no wheel edits on
an unfocused field; cancel, move and requeue of printing or part-printed jobs ask first, and
"No" changes nothing), and the small things: the jobs table's progress bar fills left to
right, a printer's fault is in the log and its advice not clipped, File > Quit (Ctrl+Q),
a window that fits a 1366 x 768 screen, head care that shows it is running.  The real window
against a real `wideprint serve` (tests/test_gui.py's helpers)."""

from __future__ import annotations

import pytest

pytest.importorskip("PySide6")
pytest.importorskip("pytestqt")

from PySide6.QtCore import QPoint, QPointF, QRect, Qt, QTimer  # noqa: E402
from PySide6.QtGui import QImage, QPainter, QWheelEvent  # noqa: E402
from PySide6.QtWidgets import (QAbstractSlider, QAbstractSpinBox, QApplication, QComboBox,  # noqa: E402
                               QMessageBox, QStyleOptionViewItem)

from test_gui import LONG, Server, image, job_named, names_in, open_window, select  # noqa: E402
from wideprint.app.gui.main_window import MainWindow  # noqa: E402
from wideprint.app.gui.server_link import ServerLink, find_or_start  # noqa: E402


@pytest.fixture
def server(tmp_path):
    s = Server(tmp_path, "--paused")
    yield s
    s.stop()


@pytest.fixture
def win(qtbot, server, tmp_path):
    w = open_window(qtbot, server, tmp_path / "cfg")
    yield w
    w.link.stop()


def wheel(widget, steps: int = -1) -> None:
    """A mouse wheel turn over `widget` (as the window system delivers it)."""
    pos = QPointF(widget.width() / 2, widget.height() / 2)
    ev = QWheelEvent(pos, QPointF(widget.mapToGlobal(pos.toPoint())), QPoint(0, 0),
                     QPoint(0, 120 * steps), Qt.NoButton, Qt.NoModifier, Qt.NoScrollPhase, False)
    QApplication.sendEvent(widget, ev)


def answer_box(qtbot, button, seen: list) -> None:
    """Answer the next message box with `button`, noting its text in `seen`."""
    tries = [100]                     # 2 s, then the box is not coming

    def click():
        box = QApplication.activeModalWidget()
        if not isinstance(box, QMessageBox):
            tries[0] -= 1
            if tries[0] > 0:
                QTimer.singleShot(20, click)
            return
        seen.append(box.text() + "\n" + box.informativeText())
        box.button(button).click()
    QTimer.singleShot(20, click)


# -------------------------------------------------------------------------------------------
def test_no_field_takes_the_wheel_unless_focused(qtbot, win, server, tmp_path):
    """The wheel over the settings form scrolls the form; it never sets a field (the Size
    combo box once turned a 2 m banner into pixels)."""
    a, _ = image(tmp_path, "banner.tif", 60)
    server.client.submit(a, settings={"placement": {"size": "physical"}})
    qtbot.waitUntil(lambda: len(win.queue_model.jobs) == 1, timeout=20_000)
    select(win, ["banner.tif"])
    edits = []
    win.form.edited.connect(lambda k, v: edits.append((k, v)))
    fields = [w for t in (QComboBox, QAbstractSpinBox, QAbstractSlider) for w in win.findChildren(t)]
    assert fields
    for w in fields:
        assert w.focusPolicy() == Qt.StrongFocus, w.objectName()
    size = win.form.fields["placement.size"].w
    before = {w.objectName(): (w.currentIndex() if isinstance(w, QComboBox) else w.value()
                               if hasattr(w, "value") else None) for w in fields}
    for w in fields:
        if w.isVisible() and w.isEnabled():
            wheel(w, -1)
            wheel(w, +1)
    after = {w.objectName(): (w.currentIndex() if isinstance(w, QComboBox) else w.value()
                              if hasattr(w, "value") else None) for w in fields}
    assert after == before
    assert not edits
    qtbot.wait(300)
    assert server.client.jobs()[0]["settings"] == {"placement": {"size": "physical"}}
    # the calibration dialog's fields too
    dlg = win.open_calibration("main")
    dpi = dlg.dpi.currentIndex()
    assert all(w.focusPolicy() == Qt.StrongFocus for t in (QComboBox, QAbstractSpinBox)
               for w in dlg.findChildren(t))
    wheel(dlg.dpi, -1)
    assert dlg.dpi.currentIndex() == dpi
    dlg.close()
    # focused (clicked into or tabbed to), the wheel works as ever
    win.activateWindow()
    size.setFocus()
    if size.hasFocus():                         # the offscreen platform may not give focus
        wheel(size, -1)
        assert size.currentIndex() != before[size.objectName()]


def test_cancel_of_a_printing_job_asks_and_no_changes_nothing(qtbot, tmp_path):
    srv = Server(tmp_path, "--paused")
    try:
        w = open_window(qtbot, srv, tmp_path / "cfg")
        big, _ = image(tmp_path, "long.tif", 61, rows=2400, cols=600)
        srv.client.submit(big, settings={"passes": 8})
        qtbot.waitUntil(lambda: len(w.queue_model.jobs) == 1, timeout=20_000)
        w.actions_["resume_all"].trigger()
        qtbot.waitUntil(lambda: job_named(w, "long.tif")["state"] == "printing", timeout=LONG)
        select(w, ["long.tif"])
        seen = []
        answer_box(qtbot, QMessageBox.No, seen)
        w.actions_["cancel"].trigger()
        assert seen and "long.tif" in seen[0] and "printing" in seen[0], seen
        qtbot.wait(500)
        j = srv.client.jobs()[0]
        assert j["state"] in ("printing", "done"), j          # not cancelled
        if j["state"] == "printing":
            answer_box(qtbot, QMessageBox.Yes, seen)
            w.actions_["cancel"].trigger()
            assert len(seen) == 2
            qtbot.waitUntil(lambda: srv.client.jobs()[0]["state"] == "cancelled", timeout=LONG)
        # requeue prints it again (media, ink): it asks too; No changes nothing
        qtbot.waitUntil(lambda: "long.tif" in names_in(w.history_view), timeout=20_000)
        w.tabs.setCurrentIndex(1)
        w.history_view.select_ids([job_named(w, "long.tif")["id"]])
        w._update_actions()
        if w.actions_["requeue"].isEnabled():
            answer_box(qtbot, QMessageBox.No, seen)
            w.actions_["requeue"].trigger()
            assert "long.tif" in seen[-1]
            qtbot.wait(500)
            assert srv.client.jobs()[0]["state"] == "cancelled"
        w.link.stop()
    finally:
        srv.stop()


def test_a_fault_is_logged_its_advice_fits_and_moving_the_stopped_job_asks(qtbot, tmp_path):
    srv = Server(tmp_path, "--paused", "--inject", "overtemp=K1:0",
                 "--printer", "main=emulator", "--printer", "other=emulator")
    try:
        w = open_window(qtbot, srv, tmp_path / "cfg")
        w.resize(1366, 768)
        f, _ = image(tmp_path, "hot.tif", 62, rows=240)
        srv.client.submit(f, printer="main")
        qtbot.waitUntil(lambda: len(w.queue_model.jobs) == 1, timeout=20_000)
        card = w.printers_panel.cards["main"]
        w.actions_["resume_all"].trigger()
        qtbot.waitUntil(lambda: "over-temperature" in card.fault.text(), timeout=LONG)
        # in the log, once, as a warning
        qtbot.waitUntil(lambda: "over-temperature" in w.logview.toPlainText(), timeout=10_000)
        text = w.logview.toPlainText()
        assert "WARNING" in text and "main" in text
        # the advice is whole at 1366 px: the text's height fits the label's
        lab = card.fault
        assert lab.heightForWidth(lab.width()) <= lab.height(), (lab.width(), lab.text())
        # moving the stopped (part-printed) job asks; No leaves it where it is
        select(w, ["hot.tif"])
        seen = []
        answer_box(qtbot, QMessageBox.No, seen)
        w._move("other")
        assert seen and "hot.tif" in seen[0]
        qtbot.wait(500)
        assert srv.client.jobs()[0]["printer"] == "main"
        w.link.stop()
    finally:
        srv.stop()


def test_jobs_table_progress_fills_left_to_right(qtbot, win):
    from wideprint.app.gui.jobs_view import ProgressDelegate
    view = win.queue_view
    win.queue_model.set_jobs([dict(id=1, name="x", source="gui", size=1, state="printing",
                                   strokes_total=100, strokes_done=50, copies=1, copies_done=0,
                                   priority=0, submitted=0)])
    col = win.queue_model.columns.index("Progress")
    idx = win.queue_model.index(0, col)
    img = QImage(200, 40, QImage.Format_RGB32)
    img.fill(Qt.white)
    opt = QStyleOptionViewItem()
    opt.rect = QRect(0, 0, 200, 40)
    opt.widget = view
    p = QPainter(img)
    ProgressDelegate(view).paint(p, opt, idx)
    p.end()
    # at 50 %: the left part filled from top to bottom, the right part not (not bottom-up)
    def filled(x, y):
        c = img.pixelColor(x, y)
        return c.blue() - c.red() > 60            # the highlight (blue), not the groove
    assert filled(20, 8) and filled(20, 31), (img.pixelColor(20, 8).name(), img.pixelColor(20, 31).name())
    assert not filled(180, 8) and not filled(180, 31)
    win.queue_model.set_jobs([])


def test_file_menu_quit_and_a_window_that_fits_the_screen(qtbot, server, tmp_path):
    client, _ = find_or_start(server.state)
    w = MainWindow(ServerLink(server.state, client), config_dir=tmp_path / "cfg")
    qtbot.addWidget(w)
    # a 1366 x 768 screen less a 40 px task bar (the offscreen screen is 800 x 800)
    avail = QRect(0, 0, 1366, 728)
    w._available = lambda: avail
    w._restore()
    w.show()
    try:
        w.fit_screen()
        frame = w.frameGeometry()
        assert avail.contains(frame), (frame, avail)
        # the layout fits a 1366 x 768 screen (its task bar and the title bar take ~70 px)
        assert w.minimumSizeHint().height() <= 768 - 70, w.minimumSizeHint()
        menus = {a.text().replace("&", ""): a.menu() for a in w.menuBar().actions()}
        assert "File" in menus
        quit_ = next(a for a in menus["File"].actions() if a.text().replace("&", "") == "Quit")
        assert quit_.shortcut().toString() == "Ctrl+Q"
        assert {"Jobs", "Printers"} <= set(menus)
        w.activateWindow()
        qtbot.waitUntil(lambda: QApplication.activeWindow() is w, timeout=5_000)
        qtbot.keyClick(w, Qt.Key_Q, Qt.ControlModifier)
        qtbot.waitUntil(lambda: not w.isVisible(), timeout=5_000)
    finally:
        w.link.stop()


def test_head_care_shows_it_is_running(qtbot, win, server):
    card = win.printers_panel.cards["main"]
    acts = {a.text(): a for a in card.care.menu().actions()}
    acts["Purge and wipe all heads"].trigger()
    # at once: the card and the status bar say it runs, the button waits for it
    assert card.busy.isVisible() and "purging" in card.busy_text.text().lower()
    assert "purging" in win.statusBar().currentMessage().lower()
    assert not card.care.isEnabled()
    qtbot.waitUntil(lambda: not card.busy.isVisible(), timeout=LONG)
    assert card.care.isEnabled()
    qtbot.waitUntil(lambda: "head-care (purge)" in win.logview.toPlainText(), timeout=10_000)


def test_add_files_as_held_in_the_order_given_and_the_new_jobs_selected(qtbot, win, server, tmp_path):
    big, _ = image(tmp_path, "c-big-first.tif", 63, rows=1500, cols=800)
    a, _ = image(tmp_path, "a-small.tif", 64, rows=50, cols=60)
    b, _ = image(tmp_path, "b-small.tif", 65, rows=60, cols=50)
    win.add_held.setChecked(True)
    win.add_files([big, a, b])
    qtbot.waitUntil(lambda: len(win.queue_model.jobs) == 3, timeout=20_000)
    jobs = sorted(server.client.jobs(), key=lambda j: j["id"])
    assert [j["name"] for j in jobs] == ["c-big-first.tif", "a-small.tif", "b-small.tif"]
    assert all(j["state"] == "held" for j in jobs)
    qtbot.waitUntil(lambda: sorted(win.queue_view.selected_ids()) == [j["id"] for j in jobs],
                    timeout=10_000)
    # remembered, like the other settings for new jobs
    qtbot.waitUntil(lambda: '"add_held": true' in (tmp_path / "cfg" / "gui.json").read_text()
                    if (tmp_path / "cfg" / "gui.json").exists() else False, timeout=5_000)
    # look, then release: it prints
    win.actions_["release"].trigger()
    qtbot.waitUntil(lambda: all(j["state"] != "held" for j in server.client.jobs()), timeout=10_000)


def test_an_edit_says_what_changed_and_undo_puts_it_back(qtbot, win, server, tmp_path):
    a, _ = image(tmp_path, "banner2.tif", 66)
    b, _ = image(tmp_path, "banner3.tif", 67)
    server.client.submit(a, settings={"placement": {"size": "physical"}})
    server.client.submit(b)
    qtbot.waitUntil(lambda: len(win.queue_model.jobs) == 2, timeout=20_000)
    select(win, ["banner2.tif", "banner3.tif"])
    combo = win.form.fields["placement.size"].w
    combo.setCurrentIndex(combo.findData("pixels"))
    combo.activated.emit(combo.currentIndex())
    qtbot.waitUntil(lambda: all((j["settings"].get("placement") or {}).get("size") == "pixels"
                                for j in server.client.jobs()), timeout=10_000)
    # what changed, from what, in the log and the status bar
    qtbot.waitUntil(lambda: "physical → pixels" in win.logview.toPlainText(), timeout=5_000)
    assert "pixels" in win.statusBar().currentMessage()
    undo = win.actions_["undo"]
    assert undo.isEnabled() and undo.shortcut().toString() == "Ctrl+Z"
    undo.trigger()
    qtbot.waitUntil(lambda: {j["name"]: j["settings"] for j in server.client.jobs()} ==
                    {"banner2.tif": {"placement": {"size": "physical"}}, "banner3.tif": {}},
                    timeout=10_000)
    assert not undo.isEnabled()


def test_a_printing_card_shows_the_time_left(qtbot, monkeypatch):
    """From the strokes printed so far: 10 strokes in 20 s, 40 to go (and a second copy of
    50) -> about 3:00 left."""
    from wideprint.app.gui import printers_panel
    from wideprint.app.gui.printers_panel import PrinterCard
    card = PrinterCard("main")
    qtbot.addWidget(card)
    now = [1000.0]
    monkeypatch.setattr(printers_panel.time, "monotonic", lambda: now[0])

    def info(done):
        return dict(name="main", device="emulator", current=dict(
            id=7, name="x.tif", state="printing", copy=1, copies=2, strokes_total=50,
            strokes_printed=done))
    card.show_info(info(0))
    assert "left" not in card.progress.format()
    now[0] += 20
    card.show_info(info(10))
    assert card.progress.format() == "20 % · 3:00 left", card.progress.format()
    assert "left" in card.progress.toolTip()
