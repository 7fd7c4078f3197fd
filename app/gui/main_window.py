"""The main window (docs/gui.md): a client of the print server.

The server owns the printers and the one persistent queue; the window shows them (the
server pushes its state: ServerLink), and every operator action is a request to it: add
files (uploads), edit settings (only the setting edited, of each selected job), hold,
release, requeue, cancel, priority, move to a printer, pause, clear a fault, emergency stop,
test prints.  Nothing is kept only here: kill the GUI and reopen it, and the queue, the
history and the settings are as they were (the settings for new jobs are saved at each
change)."""

from __future__ import annotations

import json
import logging
import uuid
from pathlib import Path

import numpy as np
from PySide6.QtCore import QByteArray, QTimer, Qt, Signal
from PySide6.QtGui import QAction, QImage, QKeySequence
from PySide6.QtWidgets import (QCheckBox, QComboBox, QFileDialog, QGridLayout, QGroupBox,
                               QHBoxLayout, QLabel, QMainWindow, QMenu, QMessageBox, QPushButton,
                               QScrollArea, QSizePolicy, QSplitter, QStyle, QTabWidget,
                               QToolButton, QVBoxLayout, QWidget)

from ... import __version__
from ..estimate import fmt_duration, fmt_ml
from ..safe_text import safe
from .config import GuiSettings, SETTINGS_FILE, default_config_dir
from .jobs_view import JobsModel, JobsView, state_text
from .logview import LogView
from .messages import plain_message, short_paths
from .preview import PreviewPanel
from .printers_panel import PrintersPanel
from .server_link import ServerLink
from .wheel_guard import guard_wheel
from .settings_form import (JOB_FIELDS_KEYS, SettingsForm, apply_edit, effective, overrides,
                            settings_patch)

log = logging.getLogger("wideprint.gui")

FILE_FILTER = ("Printable files (*.tif *.tiff *.bmp *.jpg *.jpeg *.png *.pdf *.ps *.eps *.rtl "
               "*.prn *.plt);;All files (*)")
HISTORY_ROWS = 300
PREVIEW_PX = 900
ENDED = {"done": logging.INFO, "cancelled": logging.INFO, "failed": logging.WARNING}


def _rgb_of_png(png: bytes) -> np.ndarray | None:
    img = QImage.fromData(png, "PNG")
    if img.isNull():
        return None
    img = img.convertToFormat(QImage.Format_RGB888)
    w, h, bpl = img.width(), img.height(), img.bytesPerLine()
    a = np.frombuffer(img.constBits(), np.uint8, count=bpl * h).reshape(h, bpl)
    # a copy, always: `a` is a view of the QImage's pixels, which go with `img` on return
    # (ascontiguousarray would hand the view itself back when the rows have no padding)
    return a[:, :w * 3].reshape(h, w, 3).copy()


def _own_value(job: dict, key: str):
    """A job's own value of a setting (None: unset, the default) or job field."""
    if key in dict(JOB_FIELDS_KEYS):
        return job.get(key)
    settings = job.get("settings") or {}
    if key.startswith("placement."):
        return (settings.get("placement") or {}).get(key.split(".", 1)[1])
    return settings.get(key)


def _shown(v) -> str:
    return f"{v:g}" if isinstance(v, float) else str(v)


def _money(v: float, currency: str) -> str:
    return f"{v:,.2f} {currency}"


def _m2(a: float) -> str:
    return f"{a:.3f} m²" if a >= 0.1 else f"{a * 1e4:.1f} cm²"


class EstimateBox(QGroupBox):
    """The selected job's estimate, for one copy and for all its copies side by side; or a
    finished job's accounting (what it really took)."""

    ROWS = (("size", "Size"), ("strokes", "Strokes"), ("time", "Time"), ("area", "Area"),
            ("ink", "Ink"), ("cmyk", "C / M / Y / K"), ("cost", "Cost"))
    offer = Signal(dict)              # the settings change of a fit offer, for the job shown

    def __init__(self, parent=None):
        super().__init__("Estimate", parent)
        self.setObjectName("estimate_box")
        g = QGridLayout(self)
        g.setColumnStretch(1, 1)
        g.setColumnStretch(2, 1)
        self.head_one = QLabel("one copy")
        self.head_all = QLabel("all copies")
        for i, w in enumerate((self.head_one, self.head_all)):
            w.setStyleSheet("color: #666;")
            g.addWidget(w, 0, 1 + i)
        self.one, self.all = {}, {}
        for r, (k, text) in enumerate(self.ROWS, start=1):
            g.addWidget(QLabel(text), r, 0)
            for col, d in ((1, self.one), (2, self.all)):
                v = QLabel("–")
                v.setObjectName(f"est_{k}_{'one' if col == 1 else 'all'}")
                v.setTextInteractionFlags(Qt.TextSelectableByMouse)
                g.addWidget(v, r, col)
                d[k] = v
        self.note = QLabel("")
        self.note.setObjectName("est_note")
        self.note.setWordWrap(True)
        self.note.setStyleSheet("color: #666;")
        self.note.setAlignment(Qt.AlignTop | Qt.AlignLeft)
        self.note.setFixedHeight(2 * self.note.fontMetrics().lineSpacing() + 4)
        g.addWidget(self.note, len(self.ROWS) + 1, 0, 1, 3)
        # a job that does not fit the paper loaded (docs/server.md "Fit before it fails"):
        # the problem, and the offers that make it fit, one click each
        fit = QHBoxLayout()
        self.fit = QLabel("")
        self.fit.setObjectName("est_fit")
        self.fit.setWordWrap(True)
        self.fit.setStyleSheet("color: #c62828;")
        self.fit.setSizePolicy(QSizePolicy.Ignored, QSizePolicy.Preferred)
        fit.addWidget(self.fit, 1)
        self.offer_buttons: dict[str, QPushButton] = {}
        for kind, text in (("fit-to-width", "Fit to width"), ("rotate", "Rotate 90°")):
            b = QPushButton(text)
            b.setObjectName(f"est_offer_{kind}")
            b.hide()
            b.clicked.connect(lambda _=False, _k=kind: self._offer_clicked(_k))
            fit.addWidget(b)
            self.offer_buttons[kind] = b
        g.addLayout(fit, len(self.ROWS) + 2, 0, 1, 3)
        self.offers: dict[str, dict] = {}

    def _offer_clicked(self, kind: str) -> None:
        if kind in self.offers:
            self.offer.emit(self.offers[kind])

    def show_fit(self, fit: dict | None) -> None:
        """The fit of a waiting job: nothing when it fits, else the problems and offers."""
        self.offers = {}
        if not fit or fit.get("fits", True):
            self.fit.setText("")
        else:
            self.fit.setText("Does not fit: " + "; ".join(short_paths(p) for p in fit["problems"]))
            self.offers = {o["kind"]: o for o in fit.get("offers", [])}
        for kind, b in self.offer_buttons.items():
            o = self.offers.get(kind)
            b.setVisible(o is not None)
            if o is not None:
                b.setToolTip(f"prints {o['width_mm']:,.0f} × {o['height_mm']:,.0f} mm")

    def clear(self, note: str = "") -> None:
        for v in list(self.one.values()) + list(self.all.values()):
            v.setText("–")
        self.head_all.setText("all copies")
        self.note.setText(note)
        self.show_fit(None)

    def show_estimate(self, e: dict, note: str = "") -> None:
        self.shown = e
        n = e["copies"]
        self.setTitle("Estimate")
        self.head_one.setText("one copy")
        self.head_all.setText(f"all {n} copies" if n > 1 else "all copies (1)")
        size = f"{e['width_mm']:,.1f} × {e['height_mm']:,.1f} mm"
        for d, part, k in ((self.one, e["per_copy"], 1), (self.all, e["all_copies"], n)):
            d["size"].setText(size if k == 1 else f"× {n}")
            d["strokes"].setText(f"{e['strokes']:,}" if k == 1 else f"{e['strokes'] * n:,}")
            d["time"].setText(fmt_duration(part["time_s"]))
            d["area"].setText(_m2(part["area_m2"]))
            d["ink"].setText(f"{fmt_ml(part['ink_total_ml'])} ml")
            d["cmyk"].setText(" / ".join(fmt_ml(x) for x in part["ink_ml"]))
        q = e.get("quote")                     # the estimate at the server's price list
        if q:
            self.one["cost"].setText(_money(q["total"] / max(1, n), q["currency"]))
            self.all["cost"].setText(_money(q["total"], q["currency"]))
            self.all["cost"].setToolTip(f"ink {q['ink']:.2f} + media {q['media']:.2f} "
                                        f"({q.get('media_name') or 'default media'}) + machine "
                                        f"time {q['time']:.2f} {q['currency']}")
        self.show_fit(e.get("fit"))
        gamut = e.get("out_of_gamut")
        self.note.setText(note or (f"{e['source']}; {e['width_dots']:,} × {e['height_rows']:,} dots at "
                                   f"{e['dpi']} dpi; ink from the preview's halftone"
                                   + (f"; {100 * gamut:.1f} % out of the media's gamut"
                                      if gamut is not None else "")))

    def show_accounting(self, job: dict, prints: list[dict]) -> None:
        """What a finished job took (the server's accounting, one row per copy printed;
        with their costs when the rows carry them: GET /v1/report?costs=1)."""
        self.show_fit(None)
        self.setTitle("Accounting")
        self.head_one.setText("first copy")
        self.head_all.setText(f"all {len(prints)} printed" if prints else "nothing printed")
        for v in list(self.one.values()) + list(self.all.values()):
            v.setText("–")
        if prints:
            for d, rows in ((self.one, prints[:1]), (self.all, prints)):
                p0 = rows[0]
                ink = [sum(r[f"ink_{c}_ml"] for r in rows) for c in "cmyk"]
                d["size"].setText(f"{p0['width_dots']:,} × {p0['height_rows']:,} dots")
                d["strokes"].setText(f"{sum(r['strokes_printed'] for r in rows):,} / "
                                     f"{sum(r['strokes_total'] for r in rows):,}")
                d["time"].setText(fmt_duration(sum(r["duration_s"] for r in rows)))
                d["area"].setText(_m2(sum(r["area_m2"] for r in rows)))
                d["ink"].setText(f"{fmt_ml(sum(ink))} ml")
                d["cmyk"].setText(" / ".join(fmt_ml(x) for x in ink))
                if all("cost" in r for r in rows):
                    d["cost"].setText(_money(sum(r["cost"]["total"] for r in rows),
                                             rows[0]["cost"]["currency"]))
        msg = job.get("message") or ""
        self.note.setText(f"{job['state']}" + (f": {short_paths(msg)}" if msg else ""))


class MainWindow(QMainWindow):
    def __init__(self, link: ServerLink, config_dir: str | Path | None = None,
                 started_server=None, parent=None):
        super().__init__(parent)
        self.setObjectName("main_window")
        self.setWindowTitle(f"wideprint {__version__} — print server {link.state_dir}")
        self.link = link
        self.started_server = started_server        # the server process this GUI started
        self.config_dir = Path(config_dir) if config_dir else default_config_dir()
        self.settings_path = self.config_dir / SETTINGS_FILE
        self.gs = GuiSettings.load(self.settings_path)
        self.ask_before_closing = True
        self.printers: list[dict] = []
        self.active: list[dict] = []
        self.history: list[dict] = []
        self._history_read = False                  # the history has been read once
        self._thumbs_asked: set = set()
        self._media_pending: set[str] = set()
        self._shown_key = None
        self._ended_logged: set[int] = set()
        self._roll_warned: set[int] = set()      # jobs held for a short roll, logged once
        self.calibration = None

        self._faults: dict[str, str] = {}          # printer -> its fault, as logged
        self._warned: dict[str, str] = {}          # printer -> its warnings, as logged
        self._fitted = False
        self._undo: list[tuple] = []                # (key, [(job id, its own value)], text)
        self._select_new: set[int] = set()          # jobs just added: selected when they show
        self._build_actions()
        self._build_ui()
        self._build_menus()
        self._restore()
        guard_wheel(self)
        self.logview.install()
        self.setAcceptDrops(True)

        link.printersChanged.connect(self._printers_changed)
        link.jobsChanged.connect(self._jobs_changed)
        # a job can come and go between two samples of the queue: the history follows the
        # server's mark of ended jobs too (docs/server.md "Live state")
        link.endedChanged.connect(lambda _mark: self.refresh_history(log_new=True))
        link.connected.connect(self._connection_changed)
        link.requestFailed.connect(self._request_failed)
        self._save_timer = QTimer(self)
        self._save_timer.setSingleShot(True)
        self._save_timer.setInterval(300)
        self._save_timer.timeout.connect(self.save_settings)
        self._selection_timer = QTimer(self)
        self._selection_timer.setSingleShot(True)
        self._selection_timer.setInterval(120)
        self._selection_timer.timeout.connect(self._show_selection)
        link.start_events()
        self.refresh_history()
        self._show_selection()
        self._update_actions()
        log.info("wideprint GUI %s: print server %s (%s)", __version__, link.client().host,
                 "started by this GUI" if started_server else "already running")

    # ======================================================================================
    # construction
    def _action(self, key, text, slot, shortcut=None, icon=None, tip=None) -> QAction:
        a = QAction(text, self)
        a.setObjectName(f"act_{key}")
        if shortcut:
            a.setShortcut(QKeySequence(shortcut))
        if icon is not None:
            a.setIcon(self.style().standardIcon(icon))
        if tip:
            a.setToolTip(tip)
        a.triggered.connect(slot)
        self.actions_[key] = a
        return a

    def _build_actions(self) -> None:
        self.actions_: dict[str, QAction] = {}
        S = QStyle.StandardPixmap
        self._action("add", "Add files…", self.open_files_dialog, QKeySequence.Open, S.SP_DialogOpenButton,
                     "Send files to the print server's queue (or drop them on the window)")
        self._action("hold", "Hold", lambda: self._each("hold"), "Ctrl+H", S.SP_MediaPause,
                     "Keep the selected jobs from printing until released")
        self._action("release", "Release", lambda: self._each("release"), "Ctrl+R", S.SP_MediaPlay)
        self._action("rip_hold", "RIP and hold", lambda: self._each("rip-hold"), None, None,
                     "Hold the selected jobs and RIP them now: their release prints at once, "
                     "without ripping again")
        self._action("requeue", "Requeue", lambda: self._each("requeue"), None, S.SP_BrowserReload,
                     "Print the selected failed or cancelled jobs again (History)")
        self._action("reprint", "Reprint", self.reprint_selected, "Ctrl+P", S.SP_FileDialogNewFolder,
                     "Print the selected finished jobs again from the archive, as new jobs with "
                     "their settings (held when “as held” is ticked: change them, then release)")
        self._action("cancel", "Cancel", self.cancel_selected, QKeySequence.Delete, S.SP_DialogCancelButton)
        self._action("up", "Priority up", lambda: self._priority(+1), "Ctrl+Up", S.SP_ArrowUp,
                     "Print the selected jobs sooner")
        self._action("down", "Priority down", lambda: self._priority(-1), "Ctrl+Down", S.SP_ArrowDown)
        self._action("pause_all", "Pause all", lambda: self._queue_paused(True), None, S.SP_MediaPause,
                     "Every printer stops taking jobs (the job printing finishes)")
        self._action("resume_all", "Resume all", lambda: self._queue_paused(False), None, S.SP_MediaPlay)
        self._action("estop", "EMERGENCY STOP", self.emergency_stop, "Ctrl+Shift+Space",
                     S.SP_BrowserStop, "Stop every printer at once")
        self._action("undo", "&Undo setting change", self.undo_edit, "Ctrl+Z", None,
                     "Take back the last change of the selected jobs' settings")
        self.actions_["undo"].setEnabled(False)
        self._action("quit", "&Quit", self.close, "Ctrl+Q", None, "Close the window (the server "
                     "goes on printing the jobs waiting)")

    def _build_menus(self) -> None:
        """The menu bar (the actions' shortcuts work from it, Ctrl+Q among them)."""
        mb = self.menuBar()
        mb.setObjectName("menu_bar")
        a = self.actions_
        for title, keys in (("&File", ("add", None, "quit")),
                            ("&Edit", ("undo",)),
                            ("&Jobs", ("hold", "rip_hold", "release", "cancel", "requeue",
                                       "reprint", None, "up", "down")),
                            ("&Printers", ("pause_all", "resume_all", None, "estop"))):
            m = mb.addMenu(title)
            m.setObjectName(f"menu_{title.strip('&').lower()}")
            for k in keys:
                if k is None:
                    m.addSeparator()
                else:
                    m.addAction(a[k])
            if title == "&Jobs":
                m.addSeparator()
                self.move_menu_bar = m.addMenu("Move to")
                self.move_menu_bar.setObjectName("menu_move")

    def _build_ui(self) -> None:
        tb = self.addToolBar("Main")
        tb.setObjectName("toolbar")
        tb.setToolButtonStyle(Qt.ToolButtonTextBesideIcon)
        tb.addAction(self.actions_["add"])
        tb.addWidget(QLabel(" on "))
        self.target = QComboBox()
        self.target.setObjectName("target_printer")
        self.target.setToolTip("The printer new jobs go to (any: the first free one that fits)")
        self.target.addItem("any printer", None)
        tb.addWidget(self.target)
        # a preset of the server's (GET /v1/presets) for new jobs: its settings become the
        # settings for new jobs, its "hold" default the "as held" box (docs/gui.md "Presets")
        tb.addWidget(QLabel(" preset "))
        self.add_preset = QComboBox()
        self.add_preset.setObjectName("add_preset")
        self.add_preset.setToolTip("The server's preset new jobs are added with: its settings, "
                                   "and whether its jobs are added held (remembered)")
        self.add_preset.addItem("none", None)
        self.add_preset.activated.connect(self._preset_chosen)
        tb.addWidget(self.add_preset)
        self.presets: dict = {}                    # the server's presets: name -> settings
        self.presets_held: set = set()             # the presets whose jobs are added held
        self.add_held = QCheckBox("as held")
        self.add_held.setObjectName("add_held")
        self.add_held.setToolTip("New jobs wait, held, until released: look at the preview and "
                                 "the estimate first (remembered)")
        self.add_held.setChecked(self.gs.add_held)
        self.add_held.toggled.connect(self._add_held_toggled)
        tb.addWidget(self.add_held)
        tb.addSeparator()
        for k in ("hold", "release", "cancel", "requeue", "reprint"):
            tb.addAction(self.actions_[k])
        tb.addSeparator()
        tb.addAction(self.actions_["up"])
        tb.addAction(self.actions_["down"])
        self.move_btn = QToolButton()
        self.move_btn.setObjectName("move_button")
        self.move_btn.setText("Move to")
        self.move_btn.setToolButtonStyle(Qt.ToolButtonTextOnly)
        self.move_btn.setPopupMode(QToolButton.InstantPopup)
        self.move_menu = QMenu(self.move_btn)
        self.move_btn.setMenu(self.move_menu)
        tb.addWidget(self.move_btn)
        tb.addSeparator()
        tb.addAction(self.actions_["pause_all"])
        tb.addAction(self.actions_["resume_all"])
        spacer = QWidget()
        spacer.setSizePolicy(QSizePolicy.Expanding, QSizePolicy.Preferred)
        tb.addWidget(spacer)
        estop = QToolButton()
        estop.setObjectName("estop_button")
        estop.setDefaultAction(self.actions_["estop"])
        estop.setToolButtonStyle(Qt.ToolButtonTextOnly)
        estop.setStyleSheet("QToolButton { background: #c62828; color: white; font-weight: bold; "
                            "padding: 4px 10px; border-radius: 3px; }")
        tb.addWidget(estop)

        central = QWidget()
        lay = QVBoxLayout(central)
        lay.setContentsMargins(4, 4, 4, 4)
        self.printers_panel = PrintersPanel()
        self.printers_panel.action.connect(self.printer_action)
        lay.addWidget(self.printers_panel)

        self.split = QSplitter(Qt.Horizontal)
        self.split.setObjectName("main_split")
        self.split.setChildrenCollapsible(False)
        self.tabs = QTabWidget()
        self.tabs.setObjectName("jobs_tabs")
        self.queue_model = JobsModel(history=False, parent=self)
        self.queue_view = JobsView(self.queue_model)
        self.queue_view.setObjectName("queue")
        self.history_model = JobsModel(history=True, parent=self)
        self.history_view = JobsView(self.history_model)
        self.history_view.setObjectName("history")
        self.tabs.addTab(self.queue_view, "Queue")
        self.tabs.addTab(self.history_view, "History")
        self.tabs.currentChanged.connect(lambda *_: self._selection_changed())
        for v in (self.queue_view, self.history_view):
            v.selectionModel().selectionChanged.connect(self._selection_changed)
        left = QSplitter(Qt.Vertical)
        left.setChildrenCollapsible(False)
        left.addWidget(self.tabs)
        self.logview = LogView()
        left.addWidget(self.logview)
        left.setStretchFactor(0, 3)
        left.setStretchFactor(1, 1)
        self.left = left
        mid = QWidget()
        ml = QVBoxLayout(mid)
        ml.setContentsMargins(0, 0, 0, 0)
        self.preview = PreviewPanel()
        for cb in self.preview.seps.values():        # the server's preview shows every ink
            cb.hide()
        self.preview.proof.toggled.connect(self._proof_toggled)
        ml.addWidget(self.preview, 1)
        self.estimate = EstimateBox()
        self.estimate.offer.connect(self.apply_fit_offer)
        ml.addWidget(self.estimate)
        self.form = SettingsForm()
        self.form.edited.connect(self.setting_edited)
        scroll = QScrollArea()
        scroll.setObjectName("settings_scroll")
        scroll.setWidgetResizable(True)
        scroll.setWidget(self.form)
        scroll.setMinimumWidth(self.form.sizeHint().width() + 24)
        self.split.addWidget(left)
        self.split.addWidget(mid)
        self.split.addWidget(scroll)
        self.split.setStretchFactor(0, 3)
        self.split.setStretchFactor(1, 2)
        self.split.setStretchFactor(2, 0)
        lay.addWidget(self.split, 1)
        self.setCentralWidget(central)
        self.status_conn = QLabel("")
        self.status_conn.setObjectName("status_connection")
        self.statusBar().addPermanentWidget(self.status_conn)

    def _restore(self) -> None:
        if self.gs.geometry:
            self.restoreGeometry(QByteArray.fromBase64(self.gs.geometry.encode()))
        else:
            avail = self._available()
            # 1366 x 768 at most, less a title bar's worth until the frame is known (showEvent)
            self.resize(min(1366, avail.width()), min(768, avail.height() - 32))
        if self.gs.splitter:
            self.split.restoreState(QByteArray.fromBase64(self.gs.splitter.encode()))
        else:
            self.split.setSizes([650, 380, 330])

    # ======================================================================================
    # the server's state
    def _connection_changed(self, up: bool, why: str) -> None:
        c = self.link.client()
        self.status_conn.setText(f"print server {c.host}:{c.port}" if up else "print server: not connected")
        if up:
            self.refresh_history()
            self.refresh_presets()
        elif why:
            log.warning("%s", why)

    def _request_failed(self, message: str) -> None:
        log.error("%s", message)
        self.statusBar().showMessage(short_paths(message), 10000)

    def _available(self):
        from PySide6.QtWidgets import QApplication
        screen = self.screen() or QApplication.primaryScreen()
        return screen.availableGeometry()

    def showEvent(self, ev) -> None:              # noqa: N802 - Qt's name
        super().showEvent(ev)
        if not self._fitted:
            self._fitted = True
            self.fit_screen()

    def fit_screen(self) -> None:
        """The whole window (frame and title bar too) inside the screen's available area
        (a 1366 x 768 screen less its task bar): smaller, and moved in, when it is not."""
        avail = self._available()
        frame, inner = self.frameGeometry(), self.geometry()
        extra_w, extra_h = frame.width() - inner.width(), frame.height() - inner.height()
        w = min(inner.width(), avail.width() - extra_w)
        h = min(inner.height(), avail.height() - extra_h)
        if (w, h) != (inner.width(), inner.height()):
            self.resize(max(w, self.minimumSizeHint().width()), max(h, self.minimumSizeHint().height()))
        frame = self.frameGeometry()
        x = max(avail.left(), min(frame.left(), avail.right() + 1 - frame.width()))
        y = max(avail.top(), min(frame.top(), avail.bottom() + 1 - frame.height()))
        if (x, y) != (frame.left(), frame.top()):
            self.move(x, y)

    def _log_faults(self, printers: list) -> None:
        """A printer's fault into the log when it appears (a WARNING with the advice), and
        when it is cleared."""
        for p in printers:
            name, fault = p["name"], p.get("fault") or ""
            was = self._faults.get(name, "")
            if fault == was:
                continue
            self._faults[name] = fault
            if fault:
                advice = plain_message(fault)
                log.warning("printer %s: fault: %s%s", name, safe(short_paths(fault)),
                            f" — {advice}" if advice else "")
            else:
                log.info("printer %s: fault cleared", name)
        for p in printers:       # the server's warnings (a roll running low): when one
            name = p["name"]     # comes or names another job, not as the metres go down
            ws = p.get("warnings") or []
            key = repr([(w.get("kind"), w.get("job")) for w in ws])
            if key != self._warned.get(name, "[]"):
                self._warned[name] = key
                for w in ws:
                    log.warning("printer %s: %s", name, safe(w.get("message", "")))

    def _printers_changed(self, printers: list) -> None:
        self.printers = printers
        self._log_faults(printers)
        self.printers_panel.show_printers(printers)
        names = [p["name"] for p in printers]
        have = [self.target.itemData(i) for i in range(1, self.target.count())]
        if have != names:
            cur = self.target.currentData()
            self.target.clear()
            self.target.addItem("any printer", None)
            for n in names:
                self.target.addItem(n, n)
            self.target.setCurrentIndex(max(0, self.target.findData(cur)))
            for menu in (self.move_menu, self.move_menu_bar):
                menu.clear()
                for n in [None] + names:
                    menu.addAction(n or "any printer", lambda _n=n: self._move(_n))
        if printers and self.preview is not None:
            self._media_from(printers[0])
        for p in printers:
            self._want_media(p)

    def _want_media(self, p: dict) -> None:
        """An emulated printer's live media, fetched when it changed, one request at a time."""
        card = self.printers_panel.cards.get(p["name"])
        m = p.get("media")
        if card is None or not m or m["version"] == card.media_version or \
                p["name"] in self._media_pending:
            return
        self._media_pending.add(p["name"])
        card.media_version = m["version"]

        def done(png, _card=card, _name=p["name"]):
            self._media_pending.discard(_name)
            _card.show_media(png)

        def failed(_msg, _name=p["name"]):
            self._media_pending.discard(_name)
        self.link.call(lambda c, _n=p["name"]: c.media_png(_n), done, failed)

    def _media_from(self, p: dict) -> None:
        from .config import cached_profile
        try:
            prof = cached_profile(p["profile"])
        except (OSError, ValueError, TypeError):
            return
        if (self.preview.paper_mm, self.preview.margin_mm) != (prof.paper.default_width_mm,
                                                               float(prof.paper.margin_mm)):
            self.preview.set_media(prof.paper.default_width_mm, float(prof.paper.margin_mm))

    def _jobs_changed(self, jobs: list) -> None:
        before = {j["id"] for j in self.active}
        order = {"printing": 0, "queued": 1, "held": 2}
        jobs = sorted(jobs, key=lambda j: (order.get(j["state"], 3),
                                           j.get("position") if j.get("position") is not None else 1 << 30,
                                           j["id"]))
        keep = self.queue_view.selected_ids()
        self.active = jobs
        self.queue_model.set_jobs(jobs)
        if keep:
            self.queue_view.select_ids(keep)
        self._want_thumbs(jobs)
        self._select_added()
        for j in jobs:           # the server held a job the roll cannot hold: say so, once
            if j["state"] == "held" and "held before printing" in (j.get("message") or "") \
                    and j["id"] not in self._roll_warned:
                self._roll_warned.add(j["id"])
                log.warning("job %s: %s", j["id"], safe(short_paths(j["message"])))
                self.statusBar().showMessage(f"job {j['id']}: {short_paths(j['message'])}", 30000)
        gone = before - {j["id"] for j in jobs}
        if gone:
            self.refresh_history(log_ended=gone)
        self._update_actions()
        if self.tabs.currentIndex() == 0:
            self._selection_timer.start()

    def refresh_history(self, log_ended=(), log_new: bool = False) -> None:
        """Read the history again; log the end of the jobs in `log_ended` (seen leaving the
        queue) and, with `log_new`, of those new in it since the last read (jobs that ended
        before the queue ever showed them)."""
        def got(jobs):
            if log_new and self._history_read:
                seen = {j["id"] for j in self.history}
                to_log = ended | {j["id"] for j in jobs if j["id"] not in seen}
            else:
                to_log = ended
            self._history_read = True
            self.history = jobs
            keep = self.history_view.selected_ids()
            self.history_model.set_jobs(jobs)
            if keep:
                self.history_view.select_ids(keep)
            self._want_thumbs(jobs)
            self._forget_old(jobs)
            for j in jobs:
                if j["id"] in to_log and j["id"] not in self._ended_logged:
                    self._ended_logged.add(j["id"])
                    msg = j.get("message") or ""
                    if j["state"] == "cancelled":
                        log.info("job %s %s cancelled", j["id"], safe(j["name"]))
                    else:
                        log.log(ENDED.get(j["state"], logging.INFO), "job %s %s %s%s", j["id"],
                                safe(j["name"]), j["state"], f": {safe(short_paths(msg))}" if msg else "")
        ended = set(log_ended)
        self.link.call(lambda c: c.request("GET", f"/v1/jobs?state=done,failed,cancelled&limit="
                                              f"{HISTORY_ROWS}&newest=1")["jobs"], got)

    def _forget_old(self, history: list) -> None:
        """Thumbnails and notes of jobs no longer shown (older than the history's rows) go:
        a GUI open all day keeps what it shows, not every job it ever saw."""
        keep = {j["id"] for j in history} | {j["id"] for j in self.active}
        for m in (self.queue_model, self.history_model):
            for job_id in [k for k in m.thumbs if k not in keep]:
                del m.thumbs[job_id]
        self._thumbs_asked = {k for k in self._thumbs_asked if k[0] in keep}
        self._ended_logged &= keep
        self._roll_warned &= keep

    def _want_thumbs(self, jobs: list) -> None:
        for j in jobs:
            key = (j["id"], repr(j.get("settings")))
            if key in self._thumbs_asked:
                continue
            self._thumbs_asked.add(key)
            job_id = j["id"]

            def got(png, _id=job_id):
                for m in (self.queue_model, self.history_model):
                    m.set_thumb(_id, png)
            self.link.call(lambda c, _id=job_id: c.preview_png(_id), got, lambda _msg: None)

    # ======================================================================================
    # selection: the settings form, the preview and the estimate
    def current_view(self) -> JobsView:
        return self.queue_view if self.tabs.currentIndex() == 0 else self.history_view

    def selected_jobs(self) -> list[dict]:
        view = self.current_view()
        ids = set(view.selected_ids())
        return [j for j in view.model().jobs if j["id"] in ids]

    def _selection_changed(self, *_) -> None:
        self._update_actions()
        self._selection_timer.start()

    def _show_selection(self) -> None:
        jobs = self.selected_jobs()
        history = self.tabs.currentIndex() == 1
        if not jobs:
            self.form.show_jobs([{"settings": self.gs.job, "copies": self.gs.copies, "priority": 0}],
                                "Settings for new jobs", editable=True)
            self.estimate.clear("Select a job to see its estimate.")
            self.preview.set_spots(None)
            if self._shown_key is not None:
                self.preview.show_message("Add files with “Add files…” or drop them on the window")
                self._shown_key = None
            return
        editable = not history and all(j["state"] in ("queued", "held") and not j.get("interrupted")
                                       and not j.get("fault") for j in jobs)
        if len(jobs) == 1:
            j = jobs[0]
            title = f"Job {j['id']}: {safe(j['name'])}"
        else:
            title = f"{len(jobs)} jobs: changes apply to each (mixed values differ between them)"
        if not editable:
            title += " — printed or printing: settings shown, not editable"
        self.form.show_jobs(jobs, title, editable=editable)
        j = jobs[0]
        self.preview.set_spots(j.get("spots") if len(jobs) == 1 else None)   # as its RIP resolved them
        proof = self.preview.proof.isChecked()
        key = (j["id"], repr(j.get("settings")), j["copies"], j["state"] in ("done", "failed", "cancelled"),
               proof)
        if key == self._shown_key:
            return
        self._shown_key = key
        if history:
            self.link.call(lambda c, _id=j["id"]: c.report_costs(_id)["prints"],
                           lambda prints, _j=j: self.estimate.show_accounting(_j, prints))
            self.link.call(lambda c, _id=j["id"]: self._history_preview(c, _id),
                           lambda r, _k=key, _j=j: self._preview_done(_k, _j, r),
                           lambda msg, _k=key: self._preview_failed(_k, msg))
        else:
            self.estimate.clear("Estimating…")
            self.link.call(lambda c, _id=j["id"]: (c.preview(_id, PREVIEW_PX),
                                                   (c.proof_png if proof else c.preview_png)(
                                                       _id, PREVIEW_PX)),
                           lambda r, _k=key, _j=j: self._preview_done(_k, _j, r),
                           lambda msg, _k=key: self._preview_failed(_k, msg))

    def _proof_toggled(self, _on: bool) -> None:
        """The preview as the media prints it (soft proof) or as the halftone's dots."""
        self._shown_key = None
        self._show_selection()

    @staticmethod
    def _history_preview(c, job_id: int):
        """A finished job's preview: its archived file's, at its true size in mm; once the
        archive let it go, the kept thumbnail with the size its accounting says (a done
        copy's area is the whole image: width from its dots and dpi, length from the
        area), or (None, png) when nothing says."""
        from ..client import ApiError
        try:
            return dict(c.preview(job_id, PREVIEW_PX), history=True), c.preview_png(job_id, PREVIEW_PX)
        except ApiError as exc:
            if exc.status != 410:
                raise
        png = c.preview_png(job_id)
        for r in c.report(job_id):
            if r["outcome"] == "done" and r["width_dots"] and r["area_m2"]:
                import json as _json
                dpi = _json.loads(r["settings"]).get("dpi", 300)
                w = r["width_dots"] * 25.4 / dpi
                return dict(width_mm=w, height_mm=r["area_m2"] * 1e6 / w, history=True), png
        return None, png

    def _preview_done(self, key, job: dict, result) -> None:
        if key != self._shown_key:
            return
        info, png = result
        if info is not None and not info.get("history"):
            self.estimate.show_estimate(info)
        rgb = _rgb_of_png(png)
        if rgb is None:
            return
        if info is None:
            # neither the file nor a done copy tells its size: the picture, no false rulers
            self.preview.show_message(f"Job {job['id']}: {safe(job['name'])} — its file is no "
                                      f"longer archived and no copy printed whole: no preview "
                                      f"in millimetres")
            return
        self.preview.set_image(rgb, info["width_mm"], info["height_mm"],
                               f"Job {job['id']}: {safe(job['name'])}")
        self._show_cut(key, job)

    def _show_cut(self, key, job: dict) -> None:
        """A print-and-cut job's cut lines over its preview, from its cut file (docs/cut.md)."""
        self.preview.set_cut_paths([])
        if ((job.get("settings") or {}).get("placement") or {}).get("marks") != "cut":
            return
        from ..rip.cutfile import parse_hpgl

        def done(lines, _k=key) -> None:
            if _k == self._shown_key:
                self.preview.set_cut_paths(lines)
        self.link.call(lambda c, _id=job["id"]: parse_hpgl(c.cut_file(_id, "plt").decode())[0], done,
                       lambda msg: None)

    def _preview_failed(self, key, message: str) -> None:
        if key != self._shown_key:
            return
        advice = plain_message(message)
        self.preview.show_message(short_paths(message) + (f"\n\n{advice}" if advice else ""))
        self.estimate.clear(short_paths(message))

    # ======================================================================================
    # operator actions
    def setting_edited(self, key: str, value) -> None:
        jobs = self.selected_jobs() if self.tabs.currentIndex() == 0 else []
        if not jobs:
            if key == "copies":
                self.gs.copies = int(value)
            elif key != "priority":
                self.gs.job = apply_edit(self.gs.job, key, value)
            self._save_timer.start()
            return
        body = settings_patch(key, value)
        olds = [(j["id"], _own_value(j, key)) for j in jobs]
        for j in jobs:
            self.link.call(lambda c, _id=j["id"]: c.edit(_id, **body))
        was = sorted({_shown(effective(j, key)) for j in jobs})
        what = (f"job{'s' if len(jobs) > 1 else ''} {', '.join(str(j['id']) for j in jobs)}: "
                f"{key} {' / '.join(was)} → {'default' if value is None else _shown(value)}")
        log.info("%s", what)
        self._undo.append((key, olds, what))
        del self._undo[:-50]
        self.actions_["undo"].setEnabled(True)
        self.statusBar().showMessage(f"{what}   (Edit > Undo, Ctrl+Z)", 15000)

    def undo_edit(self) -> None:
        """The last settings edit of jobs taken back: each job's own value before it (unset:
        back to the default)."""
        if not self._undo:
            return
        key, olds, what = self._undo.pop()
        self.actions_["undo"].setEnabled(bool(self._undo))
        for job_id, old in olds:
            body = settings_patch(key, old)
            self.link.call(lambda c, _id=job_id, _b=body: c.edit(_id, **_b))
        log.info("undone: %s", what)
        self.statusBar().showMessage(f"undone: {what}", 10000)

    def open_files_dialog(self) -> None:
        paths, _ = QFileDialog.getOpenFileNames(self, "Add files", self.gs.last_dir, FILE_FILTER)
        if paths:
            self.gs.last_dir = str(Path(paths[0]).parent)
            self.add_files(paths)

    def refresh_presets(self) -> None:
        """The server's presets, read again (GET /v1/presets: the file as it is now)."""
        self.link.call(lambda c: c.presets(), self._presets_read, lambda msg: None)

    def _presets_read(self, info: dict) -> None:
        self.presets = dict(info.get("presets") or {})
        self.presets_held = set(info.get("held") or ())
        names = sorted(self.presets)
        if [self.add_preset.itemData(i) for i in range(1, self.add_preset.count())] != names:
            self.add_preset.blockSignals(True)
            self.add_preset.clear()
            self.add_preset.addItem("none", None)
            for n in names:
                self.add_preset.addItem(n + (" (held)" if n in self.presets_held else ""), n)
            self.add_preset.blockSignals(False)
        i = self.add_preset.findData(self.gs.preset or None)
        self.add_preset.setCurrentIndex(max(0, i))
        if i < 0 and self.gs.preset:                # gone from the server's file
            log.warning("preset %s: no longer one of the server's presets; new jobs: none",
                        self.gs.preset)
            self.gs.preset = ""
            self._save_timer.start()

    def choose_preset(self, name: str | None) -> None:
        """New jobs with the server's preset `name` (None: none): the settings for new jobs
        become its settings, and "as held" its default."""
        i = self.add_preset.findData(name)
        if i < 0:
            raise KeyError(name)
        self.add_preset.setCurrentIndex(i)
        self._preset_chosen(i)

    def _preset_chosen(self, index: int) -> None:
        name = self.add_preset.itemData(index)
        self.gs.preset = name or ""
        if name is not None:
            self.gs.job = json.loads(json.dumps(self.presets.get(name) or {}))
        held = name in self.presets_held
        self.add_held.setChecked(held)
        log.info("new jobs: preset %s%s", name or "none", " (added held)" if held else "")
        self._save_timer.start()
        if not self.selected_jobs():
            self._show_selection()

    def _add_held_toggled(self, on: bool) -> None:
        self.gs.add_held = bool(on)
        self._save_timer.start()

    def add_files(self, paths) -> None:
        """Each file (or the files of a folder) uploaded to the server as a job with the
        settings for new jobs, held when "as held" is ticked; one after the other in the
        order given (the queue's order), and the new jobs selected when they show."""
        files = []
        for p in map(Path, paths):
            files.extend(sorted(x for x in p.iterdir() if x.is_file() and not x.name.startswith("."))
                         if p.is_dir() else [p])
        if not files:
            return
        printer = self.target.currentData()
        held = self.add_held.isChecked()
        preset = self.add_preset.currentData()
        # with a preset: the preset's name and only what the operator changed of its
        # settings; "as held" said either way (the box follows the preset's default)
        settings = overrides(self.presets.get(preset) or {}, self.gs.job) if preset else \
            dict(self.gs.job)
        descs = [dict(settings=settings or None, copies=self.gs.copies, printer=printer,
                      preset=preset, hold=held if preset else (True if held else None),
                      client="gui", key=f"gui-{uuid.uuid4()}")
                 for _ in files]

        def upload(c):
            out = []
            for f, d in zip(files, descs):
                try:
                    out.append((f, c.submit(f, **d)["job"], None))
                except Exception as exc:  # noqa: BLE001 - named per file; the others go on
                    out.append((f, None, str(exc)))
            return out

        def done(results):
            ids = []
            for f, job, err in results:
                if job is None:
                    log.error("%s: %s", f.name, short_paths(err))
                    self.statusBar().showMessage(f"{f.name}: {short_paths(err)}", 15000)
                    continue
                ids.append(job["id"])
                log.info("job %s: %s queued%s%s%s", job["id"], f.name, " held" if held else "",
                         f" with preset {preset}" if preset else "",
                         f" for printer {printer}" if printer else "")
            self._select_new = set(ids)
            self._select_added()
        self.link.call(upload, done)

    def _select_added(self) -> None:
        """The jobs just added, selected in the Queue once they are in it."""
        if not self._select_new:
            return
        present = {j["id"] for j in self.active}
        if not self._select_new <= present:
            return
        ids, self._select_new = sorted(self._select_new), set()
        self.tabs.setCurrentIndex(0)
        self.queue_view.select_ids(ids)
        r = self.queue_model.row_of(ids[0])
        if r >= 0:
            self.queue_view.scrollTo(self.queue_model.index(r, 0))

    def confirm(self, title: str, text: str, detail: str = "") -> bool:
        """Ask before a destructive action (a modal Yes/No box, No the default)."""
        box = QMessageBox(QMessageBox.Icon.Warning, title, text,
                          QMessageBox.StandardButton.Yes | QMessageBox.StandardButton.No, self)
        box.setObjectName("confirm_box")
        box.setDefaultButton(QMessageBox.StandardButton.No)
        box.setEscapeButton(QMessageBox.StandardButton.No)
        if detail:
            box.setInformativeText(detail)
        return box.exec() == QMessageBox.StandardButton.Yes

    @staticmethod
    def _started(j: dict) -> bool:
        """A job printing, or stopped part-way (a fault, an interrupted print, copies done)."""
        return (j["state"] == "printing" or bool(j.get("interrupted")) or bool(j.get("fault"))
                or bool(j.get("strokes_done")) or bool(j.get("copies_done")))

    @staticmethod
    def _names(jobs: list[dict]) -> str:
        shown = [f"job {j['id']} {safe(j['name'])} ({state_text(j)})" for j in jobs[:6]]
        return "\n".join(shown + ([f"and {len(jobs) - 6} more"] if len(jobs) > 6 else []))

    def _each(self, what: str) -> None:
        jobs = self.selected_jobs()
        if what == "requeue":
            jobs = [j for j in jobs if j["state"] in ("failed", "cancelled")]
            if not jobs or not self.confirm(
                    "Requeue", f"Print {'this job' if len(jobs) == 1 else f'these {len(jobs)} jobs'} "
                    f"again, from the first stroke?\n\n{self._names(jobs)}",
                    "It uses media and ink again."):
                return
        for j in jobs:
            self.link.call(lambda c, _id=j["id"]: c.action(_id, what),
                           lambda job, _w=what: log.info("job %s: %s", job["id"], _w))

    def cancel_selected(self) -> None:
        jobs = [j for j in self.selected_jobs() if j["state"] in ("queued", "held", "printing")]
        if not jobs:
            return
        started = [j for j in jobs if self._started(j)]
        if started and not self.confirm(
                "Cancel", f"Cancel {'this job' if len(jobs) == 1 else f'these {len(jobs)} jobs'}?"
                f"\n\n{self._names(jobs)}",
                f"{len(started)} of them printing or printed part-way: the print stops and what "
                "was printed is waste." if len(jobs) > 1 else
                "It is printing or printed part-way: the print stops and what was printed is waste."):
            return
        for j in jobs:
            self.link.call(lambda c, _id=j["id"]: c.action(_id, "cancel"))
            log.info("job %s %s: cancel asked by the operator", j["id"], safe(j["name"]))

    def reprint_selected(self) -> None:
        """The selected finished jobs printed again from the archive (POST /v1/jobs/ID/reprint):
        new jobs with their settings, held when "as held" is ticked (then change what should
        change and release), selected in the Queue when they show."""
        jobs = [j for j in self.selected_jobs() if j["state"] in ("done", "failed", "cancelled")]
        if not jobs:
            return
        held = self.add_held.isChecked()

        def reprint(c):
            out = []
            for j in jobs:
                try:
                    out.append((j, c.reprint(j["id"], hold=True) if held else c.reprint(j["id"]),
                                None))
                except Exception as exc:  # noqa: BLE001 - named per job; the others go on
                    out.append((j, None, str(exc)))
            return out

        def done(results):
            ids = []
            for j, new, err in results:
                if new is None:
                    log.error("job %s %s: reprint refused: %s", j["id"], safe(j["name"]),
                              short_paths(err))
                    self.statusBar().showMessage(f"job {j['id']}: {short_paths(err)}", 15000)
                    continue
                ids.append(new["id"])
                log.info("job %s %s: reprinted as job %s%s", j["id"], safe(j["name"]), new["id"],
                         " (held)" if new["state"] == "held" else "")
            self._select_new = set(ids)
            self._select_added()
        self.link.call(reprint, done)

    def apply_fit_offer(self, offer: dict) -> None:
        """A fit offer taken (Fit to width, Rotate 90°): its settings change on the job shown."""
        jobs = [j for j in self.selected_jobs() if j["state"] in ("queued", "held")]
        if not jobs:
            return
        j = jobs[0]
        change = offer["settings"]
        self.link.call(lambda c, _id=j["id"]: c.edit(_id, settings=change),
                       lambda job: log.info("job %s %s: %s: now %s × %s mm", job["id"],
                                            safe(job["name"]), offer["kind"],
                                            f"{offer['width_mm']:,.0f}", f"{offer['height_mm']:,.0f}"))

    def _priority(self, step: int) -> None:
        for j in self.selected_jobs():
            if j["state"] in ("queued", "held"):
                pr = max(-100, min(100, j["priority"] + step))
                self.link.call(lambda c, _id=j["id"], _p=pr: c.edit(_id, priority=_p))

    def _move(self, printer) -> None:
        jobs = self.selected_jobs()
        started = [j for j in jobs if self._started(j)]
        if started and not self.confirm(
                "Move", f"Move {'this job' if len(jobs) == 1 else f'these {len(jobs)} jobs'} to "
                f"{printer or 'any printer'}?\n\n{self._names(jobs)}",
                "Printed part-way: on another printer it prints again from its first stroke."):
            return
        for j in jobs:
            self.link.call(lambda c, _id=j["id"]: c.move(_id, printer),
                           lambda job: log.info("job %s: printer %s", job["id"], job["printer"] or "any"))

    def _queue_paused(self, paused: bool) -> None:
        self.link.call(lambda c: c.pause_queue(paused),
                       lambda _r: log.info("every printer %s", "paused" if paused else "resumed"))

    def emergency_stop(self) -> None:
        self.link.call(lambda c: c.estop(),
                       lambda stopped: log.warning("EMERGENCY STOP: %s", ", ".join(stopped) or
                                                   "nothing was printing; every printer paused"))

    def printer_action(self, printer: str, what: str, body) -> None:
        if what == "test-prints":
            return self.open_calibration(printer)
        if what == "roll":
            return self.load_roll(printer, body)
        detail = f" ({body.get('then') or body.get('action')})" if body else ""
        card = self.printers_panel.cards.get(printer)
        if what == "head-care" and card is not None:
            doing = {"spit": "spitting all heads", "purge": "purging and wiping all heads",
                     "cap": "parking and capping", "uncap": "uncapping"}.get(
                         (body or {}).get("action"), "head care")
            card.set_busy(f"Head care: {doing}…")
            self.statusBar().showMessage(f"printer {printer}: head care: {doing}…")

        def done(r):
            if card is not None and what == "head-care":
                card.set_busy(None)
                self.statusBar().showMessage(f"printer {printer}: head care done", 5000)
            log.info("printer %s: %s%s%s", printer, what, detail,
                     f": {r['message']}" if isinstance(r, dict) and r.get("message") else "")

        def failed(msg):
            if card is not None and what == "head-care":
                card.set_busy(None)
                self.statusBar().clearMessage()
            self._request_failed(msg)
        self.link.call(lambda c: c.printer_action(printer, what, body), done, failed, ordered=True)

    def load_roll(self, printer: str, body: dict | None = None) -> None:
        """The roll on `printer` (docs/server.md "Rolls"): `body` as the API takes it, or the
        roll dialog's (media from the media library, length or the roll's label)."""
        if body is None:
            from .rolls import RollDialog
            p = next((x for x in self.printers if x["name"] == printer), {})
            dlg = RollDialog(printer, p.get("roll"), self.link.state_dir, self)
            if not dlg.exec():
                return
            body = dlg.body()

        def done(r):
            roll = r.get("roll")
            log.info("printer %s: %s", printer, "roll taken off" if roll is None else
                     f"roll {roll['media']} loaded" + (f", {roll['remaining_m']:,.2f} m"
                                                       if roll.get("remaining_m") is not None else ""))
        self.link.call(lambda c: c.roll(printer, body), done, self._request_failed, ordered=True)

    def _update_actions(self) -> None:
        jobs = self.selected_jobs()
        states = {j["state"] for j in jobs}
        a = self.actions_
        a["hold"].setEnabled("queued" in states)
        a["rip_hold"].setEnabled(any(j["state"] in ("queued", "held") and not self._started(j)
                                     and not j.get("rip_hold") for j in jobs))
        a["release"].setEnabled(any(j["state"] == "held" and not j.get("fault") for j in jobs))
        a["requeue"].setEnabled(bool(states & {"failed", "cancelled"}))
        a["reprint"].setEnabled(bool(states & {"done", "failed", "cancelled"}))
        a["cancel"].setEnabled(bool(states & {"queued", "held", "printing"}))
        waiting = bool(states & {"queued", "held"})
        a["up"].setEnabled(waiting)
        a["down"].setEnabled(waiting)
        self.move_btn.setEnabled(waiting)
        self.move_menu_bar.setEnabled(waiting)

    # ======================================================================================
    # test prints and calibration (printed by the server on the chosen printer)
    def open_calibration(self, printer: str):
        from .calibration import CalibrationDialog
        p = next((x for x in self.printers if x["name"] == printer), None)
        if p is None:
            return None
        if self.calibration is not None:
            self.calibration.close()
        dlg = CalibrationDialog(p["profile"], lambda pattern, _mf: self._test_print(printer, pattern),
                                None, False, settings=self.gs.calibration, parent=self)
        dlg.setWindowTitle(f"Test prints and calibration — printer {printer}")
        dlg.finished.connect(lambda *_: self._calibration_closed(dlg))
        self.calibration = dlg
        dlg.show()
        return dlg

    def _test_print(self, printer: str, pattern: dict) -> int:
        def done(r):
            dlg = self.calibration
            if dlg is None:
                return
            dlg.media_file = r.get("media")
            dlg.job_finished(r)
        self.link.call(lambda c: c.printer_action(printer, "test-print", pattern), done,
                       lambda msg: self.calibration and self.calibration.job_finished(
                           dict(state="failed", message=msg)))
        return 0

    def _calibration_closed(self, dlg) -> None:
        self.gs.calibration = dlg.settings()
        self._save_timer.start()
        if self.calibration is dlg:
            self.calibration = None

    # ======================================================================================
    # drag and drop, settings, closing
    def dragEnterEvent(self, ev) -> None:
        if ev.mimeData().hasUrls():
            ev.acceptProposedAction()

    def dropEvent(self, ev) -> None:
        paths = [u.toLocalFile() for u in ev.mimeData().urls() if u.isLocalFile()]
        if paths:
            self.add_files(paths)
            ev.acceptProposedAction()

    def save_settings(self) -> None:
        self.gs.geometry = bytes(self.saveGeometry().toBase64()).decode()
        self.gs.splitter = bytes(self.split.saveState().toBase64()).decode()
        try:
            self.gs.save(self.settings_path)
        except OSError as exc:
            log.error("cannot save the GUI settings to %s: %s", self.settings_path, exc)

    def closeEvent(self, ev) -> None:
        self.save_settings()
        busy = bool(self.active)
        if self.started_server is not None and not busy:
            # this GUI started the server and nothing waits: it goes with the GUI
            try:
                self.link.call_now(lambda c: c.shutdown())
            except Exception as exc:  # noqa: BLE001
                log.warning("stopping the print server: %s", exc)
        elif self.started_server is not None:
            log.info("the print server keeps printing the queue in the background")
        self.link.stop()
        self.logview.uninstall()
        super().closeEvent(ev)
