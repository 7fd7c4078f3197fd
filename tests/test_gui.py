"""The operator GUI (app/gui) as a client of the print server: the real main window
(pytest-qt) against a real `wideprint serve` process.  Jobs from `wideprint submit` and a
hot folder appear in the GUI, a GUI job appears in `wideprint queue`; the GUI killed with
SIGKILL mid-print loses nothing and the print is bit-exact; a fault on job 1 of 5 stops
only that printer, Clear fault resumes and all five print bit-exact; two printers print at
once; a multi-select edit changes only the edited setting; cancel, history, test prints,
and a layout that neither clips nor jumps at 1366 x 768 and 1920 x 1080."""

from __future__ import annotations

import json
import os
import signal
import subprocess
import sys
import time
import warnings
from pathlib import Path

import numpy as np
import pytest

pytest.importorskip("PySide6")
pytest.importorskip("pytestqt")

from PySide6.QtCore import QMimeData, QPoint, QPointF, Qt, QUrl  # noqa: E402
from PySide6.QtGui import QDragEnterEvent, QDropEvent  # noqa: E402
from PySide6.QtWidgets import QApplication, QHeaderView, QLabel  # noqa: E402

from support.gui import (LONG, Server, image, job_named, names_in, open_window,  # noqa: E402
                         paused_server, select, window)
from wideprint.rip.planes import read_planes  # noqa: E402


# the paused server and the window on it, as every GUI test file has them (tests/support/gui.py)
server, win = paused_server, window


def media_of(srv: Server, job_id: int) -> np.ndarray:
    return read_planes(srv.media / f"job-{job_id}.tif")


def wait_done(qtbot, srv: Server, ids, timeout=LONG) -> None:
    def done():
        states = {j["id"]: j["state"] for j in srv.client.jobs()}
        bad = {i: s for i, s in states.items() if i in ids and s in ("failed", "cancelled")}
        assert not bad, bad
        return all(states.get(i) == "done" for i in ids)
    qtbot.waitUntil(done, timeout=timeout)


def drop_files(win, paths) -> None:
    md = QMimeData()
    md.setUrls([QUrl.fromLocalFile(str(p)) for p in paths])
    with warnings.catch_warnings():      # the QPoint constructor is the only one PySide6 has
        warnings.simplefilter("ignore", DeprecationWarning)
        enter = QDragEnterEvent(QPoint(200, 200), Qt.CopyAction, md, Qt.LeftButton, Qt.NoModifier)
    QApplication.sendEvent(win, enter)
    assert enter.isAccepted()
    QApplication.sendEvent(win, QDropEvent(QPointF(200, 200), Qt.CopyAction, md, Qt.LeftButton,
                                           Qt.NoModifier))


# -------------------------------------------------------------------------------------------
def test_submit_hot_folder_and_gui_jobs_are_one_queue(qtbot, win, server, tmp_path):
    a, _ = image(tmp_path, "from-submit.tif", 1)
    out = server.cli("submit", str(a))
    assert "job" in out
    qtbot.waitUntil(lambda: "from-submit.tif" in names_in(win.queue_view), timeout=20_000)
    folder = server.hot / "default"
    b, _ = image(tmp_path, "x.tif", 2)
    (folder / "from-hot-folder.tif").write_bytes(b.read_bytes())
    qtbot.waitUntil(lambda: "from-hot-folder.tif" in names_in(win.queue_view), timeout=30_000)
    c, _ = image(tmp_path, "from-gui.tif", 3)
    drop_files(win, [c])
    qtbot.waitUntil(lambda: "from-gui.tif" in names_in(win.queue_view), timeout=20_000)
    listing = server.cli("queue", "--json")
    assert {"from-submit.tif", "from-hot-folder.tif", "from-gui.tif"} <= \
        {j["name"] for j in json.loads(listing)}
    # thumbnails come from the server's previews
    qtbot.waitUntil(lambda: all(j["id"] in win.queue_model.thumbs for j in win.queue_model.jobs),
                    timeout=30_000)
    # the estimate says which figures are per copy and which for all copies
    select(win, ["from-gui.tif"])
    win.form.fields["copies"].w.setText("3")
    win.form.fields["copies"].w.editingFinished.emit()
    qtbot.waitUntil(lambda: job_named(win, "from-gui.tif")["copies"] == 3, timeout=10_000)
    win._show_selection()
    qtbot.waitUntil(lambda: win.estimate.head_all.text() == "all 3 copies", timeout=30_000)
    e = win.estimate.shown
    assert e["copies"] == 3 and e["all_copies"]["area_m2"] == pytest.approx(3 * e["per_copy"]["area_m2"])
    assert e["all_copies"]["time_s"] == pytest.approx(3 * e["per_copy"]["time_s"])
    assert win.estimate.all["area"].text() != win.estimate.one["area"].text()


def test_gui_jobs_print_bit_exact_and_history_shows_them(qtbot, win, server, tmp_path):
    (a, pa), (b, pb) = image(tmp_path, "a.tif", 4), image(tmp_path, "b.tif", 5, rows=200)
    win.add_files([a, b])
    qtbot.waitUntil(lambda: len(win.queue_model.jobs) == 2, timeout=20_000)
    win.actions_["resume_all"].trigger()
    ids = [job_named(win, n)["id"] for n in ("a.tif", "b.tif")]
    wait_done(qtbot, server, ids)
    assert np.array_equal(media_of(server, ids[0]), pa)
    assert np.array_equal(media_of(server, ids[1]), pb)
    qtbot.waitUntil(lambda: {"a.tif", "b.tif"} <= set(names_in(win.history_view)), timeout=20_000)
    # the emulated printer's media, as it landed, on its card
    card = win.printers_panel.cards["main"]
    qtbot.waitUntil(lambda: card.media.pixmap() is not None and not card.media.pixmap().isNull(),
                    timeout=20_000)
    win.tabs.setCurrentIndex(1)
    win.history_view.select_ids([ids[0]])
    win._show_selection()
    qtbot.waitUntil(lambda: win.estimate.title() == "Accounting"
                    and win.estimate.all["ink"].text() not in ("–", ""), timeout=20_000)


def test_multi_select_edit_changes_only_the_edited_setting(qtbot, win, server, tmp_path):
    a, _ = image(tmp_path, "m1.tif", 6)
    b, _ = image(tmp_path, "m2.tif", 7)
    server.client.submit(a, settings={"dpi": 150, "passes": 2, "dither": "bluenoise"})
    server.client.submit(b, settings={"dpi": 300, "passes": 4, "placement": {"rotate": 90}})
    qtbot.waitUntil(lambda: len(win.queue_model.jobs) == 2, timeout=20_000)
    select(win, ["m1.tif", "m2.tif"])
    f = win.form.fields
    # values that differ are shown as mixed, shared ones as they are
    assert f["dpi"].w.currentText() == "— mixed —"
    assert f["passes"].w.currentText() == "— mixed —"
    assert f["placement.rotate"].w.currentText() == "— mixed —"
    assert f["intent"].w.currentText() != "— mixed —"
    combo = f["bidir"].w
    combo.setCurrentIndex(combo.findData(True))
    combo.activated.emit(combo.currentIndex())
    qtbot.waitUntil(lambda: all(j["settings"].get("bidir") is True for j in win.queue_model.jobs),
                    timeout=10_000)
    s1, s2 = (job_named(win, n)["settings"] for n in ("m1.tif", "m2.tif"))
    assert s1 == {"dpi": 150, "passes": 2, "dither": "bluenoise", "bidir": True}
    assert s2 == {"dpi": 300, "passes": 4, "placement": {"rotate": 90}, "bidir": True}
    # a placement field, then back to its default: only that field of each job
    f["placement.x_mm"].w.setText("12.5")
    f["placement.x_mm"].w.editingFinished.emit()
    qtbot.waitUntil(lambda: all(j["settings"].get("placement", {}).get("x_mm") == 12.5
                                for j in win.queue_model.jobs), timeout=10_000)
    assert job_named(win, "m2.tif")["settings"]["placement"] == {"rotate": 90, "x_mm": 12.5}
    # a value the schema refuses is refused in the form and sent nowhere
    f["placement.top_mm"].w.setText("-4")
    f["placement.top_mm"].w.editingFinished.emit()
    assert "top_mm" in win.form.problem.text()
    time.sleep(0.3)
    assert all("top_mm" not in j["settings"].get("placement", {}) for j in server.client.jobs())


def test_hold_release_priority_move_and_cancel_logged_as_cancel(qtbot, win, server, tmp_path):
    files = [image(tmp_path, f"q{i}.tif", 10 + i)[0] for i in range(3)]
    win.add_files(files)
    qtbot.waitUntil(lambda: len(win.queue_model.jobs) == 3, timeout=20_000)
    select(win, ["q0.tif"])
    win.actions_["hold"].trigger()
    qtbot.waitUntil(lambda: job_named(win, "q0.tif")["state"] == "held", timeout=10_000)
    select(win, ["q2.tif"])
    win.actions_["up"].trigger()
    qtbot.waitUntil(lambda: job_named(win, "q2.tif")["priority"] == 1, timeout=10_000)
    # the queue shows the printers' order: q2 (priority 1) before q1
    order = [n for n in names_in(win.queue_view) if n != "q0.tif"]
    assert order == ["q2.tif", "q1.tif"]
    select(win, ["q0.tif"])
    win.actions_["release"].trigger()
    qtbot.waitUntil(lambda: job_named(win, "q0.tif")["state"] == "queued", timeout=10_000)
    win._move("main")
    qtbot.waitUntil(lambda: job_named(win, "q0.tif")["printer"] == "main", timeout=10_000)
    select(win, ["q1.tif"])
    win.logview.clear()
    win.actions_["cancel"].trigger()
    qtbot.waitUntil(lambda: "q1.tif" in names_in(win.history_view), timeout=20_000)
    assert job_named(win, "q1.tif")["state"] == "cancelled"
    qtbot.waitUntil(lambda: "q1.tif cancelled" in win.logview.toPlainText(), timeout=10_000)
    text = win.logview.toPlainText()
    assert "ERROR" not in text and text.count("cancelled") <= 2, text
    # requeue from the history
    win.tabs.setCurrentIndex(1)
    win.history_view.select_ids([job_named(win, "q1.tif")["id"]])
    win._update_actions()
    win.confirm = lambda *a: True      # it asks (tests/test_gui_operator.py answers the box)
    win.actions_["requeue"].trigger()
    qtbot.waitUntil(lambda: "q1.tif" in names_in(win.queue_view), timeout=10_000)


def test_fault_on_job_1_of_5_pauses_the_printer_and_clear_fault_prints_all_bit_exact(
        qtbot, tmp_path):
    srv = Server(tmp_path, "--paused", "--inject", "overtemp=K1:0")
    try:
        w = open_window(qtbot, srv, tmp_path / "cfg")
        files = [image(tmp_path, f"f{i}.tif", 20 + i, rows=240) for i in range(5)]
        w.add_files([f for f, _ in files[:1]])
        qtbot.waitUntil(lambda: len(w.queue_model.jobs) == 1, timeout=20_000)
        w.add_files([f for f, _ in files[1:]])
        qtbot.waitUntil(lambda: len(w.queue_model.jobs) == 5, timeout=20_000)
        ids = [job_named(w, f"f{i}.tif")["id"] for i in range(5)]
        card = w.printers_panel.cards["main"]
        top = w.split.mapTo(w, w.split.rect().topLeft())
        w.actions_["resume_all"].trigger()
        qtbot.waitUntil(lambda: "over-temperature" in card.fault.text(), timeout=LONG)
        jobs = {j["id"]: j for j in srv.client.jobs()}
        assert jobs[ids[0]]["state"] == "held" and jobs[ids[0]]["fault"]
        assert [jobs[i]["state"] for i in ids[1:]] == ["queued"] * 4
        assert not jobs[ids[1]]["message"]            # not the printer's fault as their reason
        assert not card.clear.isEnabled() is False and not card.pause.isEnabled()
        # the fault appeared: nothing moved
        assert w.split.mapTo(w, w.split.rect().topLeft()) == top
        card.act_resume.trigger()
        wait_done(qtbot, srv, ids)
        for i, (_, planes) in zip(ids, files):
            assert np.array_equal(media_of(srv, i), planes), f"job {i}"
        qtbot.waitUntil(lambda: card.fault.text() == "", timeout=10_000)
        w.link.stop()
    finally:
        srv.stop()


def test_two_printers_side_by_side_print_at_once_bit_exact(qtbot, tmp_path):
    srv = Server(tmp_path, "--paused", "--printer", "left=emulator", "--printer", "right=emulator")
    try:
        w = open_window(qtbot, srv, tmp_path / "cfg")
        qtbot.waitUntil(lambda: set(w.printers_panel.cards) == {"left", "right"}, timeout=10_000)
        left, right = w.printers_panel.cards["left"], w.printers_panel.cards["right"]
        assert left.geometry().top() == right.geometry().top()        # side by side
        (a, pa), (b, pb) = image(tmp_path, "l.tif", 31, rows=600), image(tmp_path, "r.tif", 32, rows=600)
        for f, target in ((a, "left"), (b, "right")):
            w.target.setCurrentIndex(w.target.findData(target))
            w.add_files([f])
        qtbot.waitUntil(lambda: len(w.queue_model.jobs) == 2, timeout=20_000)
        for name in ("l.tif", "r.tif"):
            select(w, [name])
            w.form.fields["passes"].w.setCurrentIndex(w.form.fields["passes"].w.findData(4))
            w.form.fields["passes"].w.activated.emit(w.form.fields["passes"].w.currentIndex())
        qtbot.waitUntil(lambda: all(j["settings"].get("passes") == 4 for j in w.queue_model.jobs),
                        timeout=10_000)
        w.actions_["resume_all"].trigger()
        both = []
        qtbot.waitUntil(lambda: both.append(sum(bool(p.get("current")) for p in w.printers)) or
                        2 in both or len(w.history_model.jobs) == 2, timeout=LONG)
        assert 2 in both, "the two printers never printed at the same time"
        ids = {n: job_named(w, n)["id"] for n in ("l.tif", "r.tif")}
        wait_done(qtbot, srv, list(ids.values()))
        jobs = {j["id"]: j for j in srv.client.jobs()}
        assert jobs[ids["l.tif"]]["printed_on"] == "left" and jobs[ids["r.tif"]]["printed_on"] == "right"
        assert np.array_equal(media_of(srv, ids["l.tif"]), pa)
        assert np.array_equal(media_of(srv, ids["r.tif"]), pb)
        w.link.stop()
    finally:
        srv.stop()


GUI_SCRIPT = """
import sys
from pathlib import Path
from PySide6.QtWidgets import QApplication
from wideprint.app.gui.main_window import MainWindow
from wideprint.app.gui.server_link import ServerLink, find_or_start
app = QApplication([])
state = Path(sys.argv[1])
client, proc = find_or_start(state)
w = MainWindow(ServerLink(state, client), config_dir=Path(sys.argv[2]), started_server=proc)
w.show()
w.add_files([sys.argv[3]])
w.actions_["resume_all"].trigger()
app.exec()
"""


def test_gui_killed_mid_print_loses_nothing(qtbot, server, tmp_path):
    big, planes = image(tmp_path, "long.tif", 40, rows=2400, cols=600)
    cfg = tmp_path / "cfg"
    (cfg).mkdir()
    (cfg / "gui.json").write_text(json.dumps({"job": {"passes": 8}, "copies": 1}))
    env = dict(os.environ, QT_QPA_PLATFORM="offscreen")
    gui = subprocess.Popen([sys.executable, "-c", GUI_SCRIPT, str(server.state), str(cfg), str(big)],
                           env=env, stdout=subprocess.DEVNULL, stderr=subprocess.DEVNULL)
    try:
        deadline = time.monotonic() + 60
        job = None
        while time.monotonic() < deadline:
            jobs = server.client.jobs()
            if jobs and jobs[0]["strokes_done"] >= 2:
                job = jobs[0]
                break
            time.sleep(0.02)
        assert job is not None and job["state"] == "printing", jobs
    finally:
        gui.send_signal(signal.SIGKILL)
        gui.wait(10)
    assert job["settings"] == {"passes": 8}
    w = open_window(qtbot, server, cfg)
    try:
        qtbot.waitUntil(lambda: "long.tif" in names_in(w.queue_view) + names_in(w.history_view),
                        timeout=10_000)
        j = job_named(w, "long.tif")
        assert j["state"] in ("printing", "done")
        if j["state"] == "printing":
            qtbot.waitUntil(lambda: w.printers_panel.cards["main"].job.text().startswith(
                f"job {j['id']}: long.tif"), timeout=10_000)
        # the settings for new jobs survived: they were saved at each change, not at exit
        assert w.form.fields["passes"].w.currentData() == 8
        wait_done(qtbot, server, [j["id"]])
        assert np.array_equal(media_of(server, j["id"]), planes)
    finally:
        w.link.stop()


def test_test_print_through_the_server_and_calibration_saves_the_printers_profile(
        qtbot, win, server):
    dlg = win.open_calibration("main")
    dlg.pattern.setCurrentIndex(dlg.pattern.findData("bidir-align"))
    dlg.print_pattern()
    qtbot.waitUntil(lambda: dlg.media is not None, timeout=LONG)
    assert dlg.media_file and Path(dlg.media_file).parent == server.media
    dlg.bidir_choice.setCurrentIndex(dlg.bidir_choice.findData(2))
    dlg.save()
    from wideprint.rip.profile import load_profile
    prof = load_profile(server.state / "profiles" / "main.toml")
    assert prof.bidir_offset_columns.get(dlg.dpi.currentData()) == 2
    dlg.close()
    # head care from the card's menu: the server parks and caps, the card says so; uncap
    card = win.printers_panel.cards["main"]
    acts = {a.text(): a for a in card.care.menu().actions()}
    assert set(acts) == {"Spit all heads", "Purge and wipe all heads", "Park and cap", "Uncap"}
    acts["Spit all heads"].trigger()
    acts["Park and cap"].trigger()
    qtbot.waitUntil(lambda: "(heads capped)" in card.state.text(), timeout=LONG)
    assert server.client.request("GET", "/v1/printers")["printers"][0]["capped"] is True
    acts["Uncap"].trigger()
    qtbot.waitUntil(lambda: "(heads capped)" not in card.state.text(), timeout=LONG)


@pytest.mark.parametrize("size", [(1366, 768), (1920, 1080)])
def test_no_clipped_text_and_a_stable_layout(qtbot, win, server, tmp_path, size):
    a, _ = image(tmp_path, "a-rather-long-file-name-for-the-queue.tif", 50)
    server.client.submit(a, copies=2)
    qtbot.waitUntil(lambda: len(win.queue_model.jobs) == 1, timeout=20_000)
    win.resize(*size)
    select(win, ["a-rather-long-file-name-for-the-queue.tif"])
    qtbot.waitUntil(lambda: win.estimate.all["time"].text() != "–", timeout=30_000)
    qtbot.wait(200)
    clipped = []
    for label in win.findChildren(QLabel):
        if not label.isVisible() or label.wordWrap() or not label.text():
            continue
        if label.sizeHint().width() > label.width() + 1 and label.parent() is not win.statusBar():
            clipped.append((label.objectName(), label.text()[:40], label.sizeHint().width(), label.width()))
    assert not clipped, clipped
    for view in (win.queue_view, win.history_view):
        h = view.horizontalHeader()
        fm = h.fontMetrics()
        for i, name in enumerate(view.model().columns):
            if h.sectionResizeMode(i) == QHeaderView.Interactive:
                assert h.sectionSize(i) >= fm.horizontalAdvance(name) + 8, name
    # the settings form fits its width (no horizontal scrolling)
    scroll = win.findChild(type(win.centralWidget()), "settings_scroll") or \
        win.form.parentWidget().parentWidget()
    assert win.form.width() <= scroll.viewport().width() + 1
    # a message appearing moves nothing
    before = (win.split.geometry(), win.queue_view.geometry(), win.printers_panel.geometry())
    win.form.show_problem("a long problem text " * 6)
    win.printers_panel.cards["main"].fault.setText("over-temperature on head K1 " * 4)
    qtbot.wait(50)
    assert (win.split.geometry(), win.queue_view.geometry(), win.printers_panel.geometry()) == before


def test_calibration_from_a_scan_in_the_dialog(qtbot, tmp_path):
    """The calibration dialog offers what `wideprint calibrate` does: load the scan of the
    printed pattern, see what was measured, accept it into the printer profile."""
    import shutil
    from wideprint.app.cli import main
    from wideprint.app.gui.calibration import CalibrationDialog
    from wideprint.rip.profile import DEFAULT_PROFILE, load_profile
    prof = tmp_path / "printer.toml"
    shutil.copy(DEFAULT_PROFILE, prof)
    scan = tmp_path / "bidir-scan.tif"
    assert main(["test-print", "bidir-scan", "--width-mm", "40", "--dpi", "300", "--scan-out",
                 str(scan), "--scan-dpi", "1200", "--inject", "bidir-error=0.5col",
                 "--inject", "scan-rotation=1.0"]) == 0
    dlg = CalibrationDialog(str(prof), lambda *a: 0, None, False)
    qtbot.addWidget(dlg)
    dlg.pattern.setCurrentIndex(dlg.pattern.findData("bidir-scan"))
    dlg.dpi.setCurrentIndex(dlg.dpi.findData(300))
    dlg.width_mm.setValue(40)
    dlg.measure_scan(str(scan))
    assert dlg.scan_accept.isEnabled(), dlg.scan_result.text()
    assert "bidir" in dlg.measured.kind
    dlg.accept_scan()
    shift = load_profile(prof).bidir_shift_columns(300)
    assert abs(shift - 0.5) < 0.1, shift
    # a scan of something else is named, not measured
    dlg.measure_scan(str(tmp_path / "missing.tif"))
    assert not dlg.scan_accept.isEnabled() and dlg.scan_result.text()
    # the step wedge: measured ink curves into the profile (docs/color.md "Linearisation")
    wedge = tmp_path / "wedge-scan.tif"
    assert main(["test-print", "wedge-scan", "--width-mm", "100", "--dpi", "300", "--scan-out",
                 str(wedge), "--scan-dpi", "600", "--inject", "dot-diameter=140um"]) == 0
    dlg.pattern.setCurrentIndex(dlg.pattern.findData("wedge-scan"))
    dlg.width_mm.setValue(100)
    dlg.measure_scan(str(wedge))
    assert dlg.scan_accept.isEnabled() and dlg.measured.kind == "wedge", dlg.scan_result.text()
    dlg.accept_scan()
    assert dict(load_profile(prof).curves.C)[128] < 64     # dot gain: mid tones taken down
