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

from support.gui import (LONG, Server, image, job_named, names_in, open_window,  # noqa: E402
                         paused_server, select, window)
from wideprint.app.gui.main_window import MainWindow  # noqa: E402
from wideprint.app.gui.server_link import ServerLink, find_or_start  # noqa: E402


# the paused server and the window on it, as every GUI test file has them (tests/support/gui.py)
server, win = paused_server, window


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


# -- look before printing, reprint, fit, rolls and costs (issue 34 parts 2-5) -----------------
import numpy as np  # noqa: E402


@pytest.fixture(scope="module")
def shop(tmp_path_factory):
    """One paused server for the tests below (a server's start and stop cost ~20 s); each
    test leaves it as it found it: paused, no roll, nothing waiting."""
    s = Server(tmp_path_factory.mktemp("shop"), "--paused")
    yield s
    s.stop()


@pytest.fixture
def shop_win(qtbot, shop, tmp_path):
    w = open_window(qtbot, shop, tmp_path / "cfg")
    yield w
    w.link.stop()
    c = shop.client
    c.pause_queue(True)
    for j in c.jobs("queued,held,printing"):
        c.cancel(j["id"])
    c.roll("main", {"unload": True})
PRICES = {"currency": "EUR", "ink_per_ml": {"c": 0.2, "m": 0.2, "y": 0.2, "k": 0.1},
          "media_per_m2": {"default": 3.0}, "machine_per_hour": 40.0}


def test_hold_then_release_after_the_estimate_and_its_quote(qtbot, shop_win, shop, tmp_path):
    """Added as held, the job waits with the queue running; its estimate shows the quote at
    the shop's price list; released, it prints bit-exact."""
    from wideprint.rip.planes import read_planes
    shop.client.prices(PRICES)
    shop.client.pause_queue(False)
    a, planes = image(tmp_path, "look-first.tif", 70, rows=200, cols=240)
    shop_win.add_held.setChecked(True)
    shop_win.add_files([a])
    qtbot.waitUntil(lambda: shop_win.queue_view.selected_ids() != [], timeout=20_000)
    job = job_named(shop_win, "look-first.tif")
    assert job["state"] == "held"
    cost = shop_win.estimate.all["cost"]
    qtbot.waitUntil(lambda: cost.text() != "–", timeout=20_000)
    quote = shop.client.preview(job["id"], 900)["quote"]
    assert cost.text() == f"{quote['total']:,.2f} EUR" and quote["total"] > 0
    assert shop_win.estimate.fit.text() == ""                              # it fits: no warning
    qtbot.wait(1000)
    assert shop.client.job(job["id"])["state"] == "held"            # the queue runs: it waits
    shop_win.actions_["release"].trigger()
    qtbot.waitUntil(lambda: shop.client.job(job["id"])["state"] == "done", timeout=LONG)
    assert np.array_equal(read_planes(shop.media / f"job-{job['id']}.tif"), planes)


def test_a_job_too_wide_is_refused_naming_the_file_flagged_and_fitted_with_a_click(
        qtbot, shop_win, shop, tmp_path):
    a, _ = image(tmp_path, "banner.tif", 71, rows=40, cols=60)
    wide = {"placement": {"width_mm": 5080, "height_mm": 1000}}
    shop_win.gs.job = dict(wide)
    shop_win.add_files([a])
    qtbot.waitUntil(lambda: "banner.tif" in shop_win.statusBar().currentMessage(), timeout=20_000)
    msg = shop_win.statusBar().currentMessage()
    assert "banner.tif is 5,080 mm wide" in msg and "spool" not in msg
    assert [j for j in shop.client.jobs() if j["name"] == "banner.tif"] == []   # refused
    # forced and held: the estimate flags it and offers what makes it fit
    job = shop.client.submit(a, settings=wide, force=True, hold=True)["job"]
    qtbot.waitUntil(lambda: len(shop_win.queue_model.jobs) == 1, timeout=20_000)
    select(shop_win, ["banner.tif"])
    qtbot.waitUntil(lambda: "Does not fit" in shop_win.estimate.fit.text(), timeout=20_000)
    assert "5,080 mm wide" in shop_win.estimate.fit.text()
    rotate = shop_win.estimate.offer_buttons["rotate"]
    assert rotate.isVisible() and shop_win.estimate.offer_buttons["fit-to-width"].isVisible()
    rotate.click()
    qtbot.waitUntil(lambda: shop.client.job(job["id"])["settings"]["placement"].get("rotate")
                    == 90, timeout=10_000)
    assert shop.client.fit(job["id"])["fits"]
    qtbot.waitUntil(lambda: shop_win.estimate.fit.text() == "", timeout=20_000)


def test_a_failed_job_is_billed_only_what_it_printed(qtbot, shop_win, shop, tmp_path):
    """Forced onto paper too narrow, it fails at the printer with 0 strokes: the history's
    accounting says 0 area and no media cost, and names the file, not the spool copy."""
    shop.client.prices(PRICES)
    a, _ = image(tmp_path, "too-wide.tif", 72, rows=40, cols=60)
    job = shop.client.submit(a, settings={"placement": {"width_mm": 5080}}, force=True)["job"]
    shop.client.pause_queue(False)
    qtbot.waitUntil(lambda: "too-wide.tif" in names_in(shop_win.history_view), timeout=LONG)
    shop_win.tabs.setCurrentIndex(1)
    shop_win.history_view.select_ids([job["id"]])
    shop_win._show_selection()
    qtbot.waitUntil(lambda: shop_win.estimate.title() == "Accounting"
                    and shop_win.estimate.all["area"].text() != "–", timeout=20_000)
    assert shop_win.estimate.all["area"].text() == "0.0 cm²"
    assert shop_win.estimate.all["strokes"].text().startswith("0 / ")
    rows = shop.client.report_costs(job["id"])["prints"]
    assert rows[0]["cost"]["media"] == 0 and rows[0]["area_m2"] == 0
    assert shop_win.estimate.all["cost"].text() == f"{rows[0]['cost']['total']:,.2f} EUR"
    assert shop_win.estimate.note.text().startswith("failed: too-wide.tif")


def test_reprint_from_the_history_is_bit_exact_and_its_preview_has_true_rulers(
        qtbot, shop_win, shop, tmp_path):
    from wideprint.rip.planes import read_planes
    a, planes = image(tmp_path, "poster.tif", 73, rows=300, cols=400)
    first = shop.client.submit(a)["job"]
    shop.client.pause_queue(False)
    qtbot.waitUntil(lambda: "poster.tif" in names_in(shop_win.history_view), timeout=LONG)
    a.unlink()                                     # the archive has it
    shop_win.tabs.setCurrentIndex(1)
    shop_win.history_view.select_ids([first["id"]])
    shop_win._show_selection()
    info = shop.client.preview(first["id"], 900)
    qtbot.waitUntil(lambda: shop_win.preview.has_image, timeout=20_000)
    # the rulers read the print's millimetres, not the thumbnail's pixels
    assert shop_win.preview.image_mm == pytest.approx((info["width_mm"], info["height_mm"]))
    assert info["width_mm"] == pytest.approx(400 / 300 * 25.4, rel=0.01)
    shop_win.add_held.setChecked(False)
    shop_win.actions_["reprint"].trigger()
    qtbot.waitUntil(lambda: len([j for j in shop.client.jobs() if j["name"] == "poster.tif"]) == 2,
                    timeout=20_000)
    again = max((j for j in shop.client.jobs() if j["name"] == "poster.tif"), key=lambda j: j["id"])
    assert again["reprint_of"] == first["id"]
    qtbot.waitUntil(lambda: shop.client.job(again["id"])["state"] == "done", timeout=LONG)
    media = shop.media
    assert np.array_equal(read_planes(media / f"job-{again['id']}.tif"),
                          read_planes(media / f"job-{first['id']}.tif"))
    assert np.array_equal(read_planes(media / f"job-{again['id']}.tif"), planes)


def test_the_roll_on_the_card_and_a_job_it_cannot_hold_is_held(qtbot, shop_win, shop, tmp_path):
    """Loaded from the GUI, the roll shows on the printer's card; a job longer than what is
    left is held before its first stroke, with the reason in its row."""
    from wideprint.app.gui.rolls import RollDialog
    dlg = RollDialog("main", None, shop.state, shop_win)
    assert "vinyl-300" in [dlg.media.itemText(i) for i in range(dlg.media.count())]
    dlg.media.setCurrentText("vinyl-300")
    dlg.length.setValue(12.5)
    assert dlg.spare.value() == 1.0                              # the server's default spare
    dlg.spare.setValue(2.5)
    shop_win.load_roll("main", dlg.body())
    card = shop_win.printers_panel.cards["main"]
    qtbot.waitUntil(lambda: "vinyl-300, 12.50 m left" in card.telemetry.text(), timeout=20_000)
    assert shop.client.roll("main")["roll"]["spare_m"] == 2.5    # the warning's spare, as set
    again = RollDialog("main", shop.client.roll("main")["roll"], shop.state, shop_win)
    assert again.spare.value() == 2.5                            # the loaded roll's own
    a, _ = image(tmp_path, "long-banner.tif", 74, rows=300, cols=100)
    job = shop.client.submit(a)["job"]                # fits the roll at submission
    shop_win.load_roll("main", {"remaining_m": 0.02})        # measured: 20 mm left
    qtbot.waitUntil(lambda: shop.client.roll("main")["roll"]["remaining_m"] == 0.02,
                    timeout=10_000)
    shop.client.pause_queue(False)
    qtbot.waitUntil(lambda: shop.client.job(job["id"])["state"] == "held", timeout=LONG)
    j = shop.client.job(job["id"])
    assert j["strokes_done"] == 0 and "needs" in j["message"] and "0.02 m left" in j["message"]
    assert shop.client.report(job["id"]) == []
    assert not (shop.media / f"job-{job['id']}.tif").exists()
    qtbot.waitUntil(lambda: any(j["id"] == job["id"] and j["state"] == "held"
                                for j in shop_win.queue_model.jobs), timeout=20_000)
    row = shop_win.queue_model.row_of(job["id"])
    tip = [shop_win.queue_model.data(shop_win.queue_model.index(row, c), Qt.ToolTipRole)
           for c in range(shop_win.queue_model.columnCount())]
    shown = " ".join(str(t) for t in tip if t) + " ".join(
        str(shop_win.queue_model.data(shop_win.queue_model.index(row, c)))
        for c in range(shop_win.queue_model.columnCount()))
    assert "needs" in shown and "held: roll too short" in shown, shown
    # the warning is in the GUI's log and status bar (once)
    qtbot.waitUntil(lambda: "needs" in shop_win.statusBar().currentMessage(), timeout=10_000)
    qtbot.waitUntil(lambda: "long-banner.tif: needs" in shop_win.logview.toPlainText(),
                    timeout=10_000)


def test_rip_and_hold_from_the_gui(qtbot, shop_win, shop, tmp_path):
    """Jobs > RIP and hold: the job is held and ripped ahead (its row says so); released, it
    prints its kept planes, bit-exact."""
    from wideprint.rip.planes import read_planes
    a, planes = image(tmp_path, "proof-ok.tif", 75, rows=200, cols=200)
    job = shop.client.submit(a, hold=True)["job"]
    qtbot.waitUntil(lambda: any(j["id"] == job["id"] for j in shop_win.queue_model.jobs),
                    timeout=20_000)
    select(shop_win, ["proof-ok.tif"])
    shop_win._update_actions()
    assert shop_win.actions_["rip_hold"].isEnabled()
    shop_win.actions_["rip_hold"].trigger()
    row = lambda: shop_win.queue_model.row_of(job["id"])  # noqa: E731
    state = lambda: shop_win.queue_model.data(shop_win.queue_model.index(row(), 3))  # noqa: E731
    qtbot.waitUntil(lambda: row() >= 0 and state() == "held, ripped", timeout=LONG)
    shop.client.pause_queue(False)
    shop_win.actions_["release"].trigger()
    qtbot.waitUntil(lambda: shop.client.job(job["id"])["state"] == "done", timeout=LONG)
    assert np.array_equal(read_planes(shop.media / f"job-{job['id']}.tif"), planes)
    assert "printing its planes, ripped ahead" in (shop.root / "server.out").read_text()
