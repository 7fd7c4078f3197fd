"""The main window: queue, job settings, preview / live media, device panel, log."""

from __future__ import annotations

import itertools
import json
import logging
from pathlib import Path

from PySide6.QtCore import QByteArray, QItemSelectionModel, QThread, QThreadPool, QTimer, Qt, Signal
from PySide6.QtGui import QAction, QKeySequence
from PySide6.QtWidgets import (QDockWidget, QFileDialog,
                               QHBoxLayout, QLabel, QMainWindow, QMenu, QMessageBox,
                               QScrollArea, QSizePolicy, QSplitter, QStyle, QTabWidget, QToolButton,
                               QVBoxLayout, QWidget)

from ... import __version__
from ...rip.profile import DEFAULT_PROFILE, RESOURCES
from . import queue as Q
from .calibration import CalibrationDialog
from .config import GuiSettings, default_cache_dir, default_config_dir, ensure_user_profile, SETTINGS_FILE
from .device_panel import DevicePanel
from ..estimate import fmt_duration, fmt_ml
from .jobsettings import JobSettings, cached_profile, printable_width_mm
from .liveview import LiveView
from .logview import LogView
from .messages import plain_message, short_paths
from .preview import PreviewPanel
from ..jobpreview import compute_preview, render_separations
from .settings_panel import EstimateBox, SettingsPanel
from .workers import DeviceConfig, Pace, PrinterWorker, Task, Ticket

log = logging.getLogger("wideprint.gui")

FILE_FILTER = "Images (*.tif *.tiff *.bmp *.jpg *.jpeg *.png);;All files (*)"


class MainWindow(QMainWindow):
    # requests to the printer thread (queued connections)
    requestConnect = Signal(object)
    requestDisconnect = Signal()
    requestTicket = Signal(object)
    requestRefresh = Signal()
    requestClearFault = Signal()
    requestEstop = Signal()
    requestShutdown = Signal()
    queueFinished = Signal()

    def __init__(self, config_dir: str | Path | None = None, parent=None):
        super().__init__(parent)
        self.setObjectName("main_window")
        self.setWindowTitle(f"wideprint {__version__} — WP-3400")
        self.config_dir = Path(config_dir) if config_dir else default_config_dir()
        self.cache_dir = (self.config_dir / "cache") if config_dir else default_cache_dir()
        self.settings_path = self.config_dir / SETTINGS_FILE
        self.gs = GuiSettings.load(self.settings_path)
        self.user_profile = ensure_user_profile(self.config_dir)
        self.defaults = JobSettings.from_dict(self.gs.job)
        self.ask_before_closing = True

        self.pool = QThreadPool(self)
        self.pool.setMaxThreadCount(2)
        self._tasks: dict = {}
        self._previews: dict[int, object] = {}       # item id -> PreviewData
        self._pending_previews: set[int] = set()
        self._ticket_ids = itertools.count(1)
        self.current: tuple[int, Ticket] | None = None
        self.running = False                          # the queue is being printed
        self.paused = False
        self.connected = False
        self.paper_mm: float | None = None
        self.calibration: CalibrationDialog | None = None

        # the printer thread
        self.pace = Pace(self.gs.emulator_speed)
        self.worker = PrinterWorker(self.pace)
        self.printer_thread = QThread(self)
        self.printer_thread.setObjectName("printer")
        self.worker.moveToThread(self.printer_thread)
        self.requestConnect.connect(self.worker.connect_device)
        self.requestDisconnect.connect(self.worker.disconnect_device)
        self.requestTicket.connect(self.worker.run_ticket)
        self.requestRefresh.connect(self.worker.refresh)
        self.requestClearFault.connect(self.worker.clear_fault)
        self.requestEstop.connect(self.worker.estop_idle)
        self.requestShutdown.connect(self.worker.shutdown)
        self.worker.deviceChanged.connect(self._device_changed)
        self.worker.jobStarted.connect(self._job_started)
        self.worker.jobState.connect(self._job_state)
        self.worker.jobStroke.connect(self._job_stroke)
        self.worker.jobFinished.connect(self._job_finished)
        self.printer_thread.start()

        self._build_actions()
        self._build_ui()
        self._restore()
        self.logview.install()
        self.setAcceptDrops(True)

        self.telemetry_timer = QTimer(self)
        self.telemetry_timer.setInterval(200)
        self.telemetry_timer.timeout.connect(self._poll_telemetry)
        self.telemetry_timer.start()
        self.idle_timer = QTimer(self)
        self.idle_timer.setInterval(5000)
        self.idle_timer.timeout.connect(self._idle_refresh)
        self.idle_timer.start()
        self._preview_timer = QTimer(self)
        self._preview_timer.setSingleShot(True)
        self._preview_timer.setInterval(250)
        self._preview_timer.timeout.connect(self._refresh_selected_preview)
        self._update_actions()
        log.info("wideprint GUI %s; settings %s; user printer profile %s", __version__,
                 self.settings_path, self.user_profile)

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
                     "Add images to the queue (or drop them on the window)")
        self._action("remove", "Remove", self.remove_selected, QKeySequence.Delete, S.SP_TrashIcon)
        self._action("duplicate", "Duplicate", self.duplicate_selected, "Ctrl+D", S.SP_FileDialogNewFolder)
        self._action("up", "Move up", lambda: self.move_selected(-1), "Ctrl+Up", S.SP_ArrowUp)
        self._action("down", "Move down", lambda: self.move_selected(1), "Ctrl+Down", S.SP_ArrowDown)
        self._action("reset", "Reset state", self.reset_selected, None, S.SP_BrowserReload,
                     "Make a printed, failed or cancelled job ready to print again")
        self._action("print", "Print", self.print_queue, "Ctrl+P", S.SP_MediaPlay,
                     "Print every job in the queue that has not been printed")
        self._action("pause", "Pause", self.pause_job, None, S.SP_MediaPause,
                     "Pause after the stroke that is printing")
        self._action("resume", "Resume", self.resume_job, None, S.SP_MediaSeekForward)
        self._action("cancel", "Cancel", self.cancel_job, None, S.SP_MediaStop,
                     "Stop the job now (the line stops, the carriage parks) and stop the queue")
        self._action("estop", "Emergency stop", self.emergency_stop, "Ctrl+Shift+X", S.SP_BrowserStop,
                     "Stop the machine at once")
        self._action("clear_fault", "Clear fault", self.clear_fault, None, S.SP_DialogResetButton,
                     "Clear the printer's fault (after making the machine safe)")
        self._action("calibrate", "Test prints && calibration…", self.open_calibration, "Ctrl+K",
                     S.SP_FileDialogDetailedView)
        self._action("quit", "Quit", self.close, QKeySequence.Quit)

    def _build_ui(self) -> None:
        A = self.actions_
        tb = self.addToolBar("Main")
        tb.setObjectName("toolbar")
        tb.setToolButtonStyle(Qt.ToolButtonTextBesideIcon)
        for k in ("add", "print", "pause", "resume", "cancel"):
            tb.addAction(A[k])
        tb.addSeparator()
        tb.addAction(A["calibrate"])
        tb.addSeparator()
        estop = QToolButton()
        estop.setDefaultAction(A["estop"])
        estop.setToolButtonStyle(Qt.ToolButtonTextBesideIcon)
        estop.setStyleSheet("QToolButton { color: #c62828; font-weight: bold; }")
        tb.addWidget(estop)

        m = self.menuBar().addMenu("&File")
        for k in ("add", "calibrate"):
            m.addAction(A[k])
        m.addSeparator()
        m.addAction(A["quit"])
        m = self.menuBar().addMenu("&Queue")
        for k in ("print", "pause", "resume", "cancel", "estop", None, "duplicate", "remove", "up", "down",
                  "reset"):
            m.addSeparator() if k is None else m.addAction(A[k])
        self.view_menu = self.menuBar().addMenu("&View")

        # queue
        self.model = Q.QueueModel(self)
        self.model.rowsMoved.connect(lambda *_: self._update_actions())
        self.table = Q.QueueView()          # rows can be dragged to a new place
        self.table.setObjectName("queue")
        self.table.setModel(self.model)
        self.table.setItemDelegateForColumn(Q.QueueModel.COL_PROGRESS, Q.ProgressDelegate(self.table))
        self.table.verticalHeader().setVisible(False)
        self.table.verticalHeader().setDefaultSectionSize(24)
        self.table.setAlternatingRowColors(True)
        self.table.setWordWrap(False)
        hh = self.table.horizontalHeader()
        hh.setStretchLastSection(True)
        for col, w in enumerate((28, 135, 95, 72, 105, 45, 50, 170, 320)):
            hh.resizeSection(col, w)
        # queue shortcuts (Delete, Ctrl+D, Ctrl+Up/Down) act only while the queue has focus,
        # so they never fire while typing in a field
        for k in ("remove", "duplicate", "up", "down"):
            A[k].setShortcutContext(Qt.WidgetWithChildrenShortcut)
            self.table.addAction(A[k])
        self.table.setContextMenuPolicy(Qt.CustomContextMenu)
        self.table.customContextMenuRequested.connect(self._queue_menu)
        self.table.selectionModel().selectionChanged.connect(self._selection_changed)
        self.table.doubleClicked.connect(lambda *_: self.tabs.setCurrentIndex(0))
        qbar = QHBoxLayout()
        qbar.setContentsMargins(0, 0, 0, 0)
        title = QLabel("<b>Queue</b>")
        qbar.addWidget(title)
        qbar.addStretch(1)
        for k in ("add", "duplicate", "remove", "up", "down"):
            b = QToolButton()
            b.setDefaultAction(A[k])
            b.setToolButtonStyle(Qt.ToolButtonIconOnly if k != "add" else Qt.ToolButtonTextBesideIcon)
            b.setAutoRaise(True)
            qbar.addWidget(b)
        qw = QWidget()
        ql = QVBoxLayout(qw)
        ql.setContentsMargins(4, 4, 4, 4)
        ql.addLayout(qbar)
        ql.addWidget(self.table, 1)
        self.queue_summary = QLabel("")
        self.queue_summary.setObjectName("queue_summary")
        self.queue_summary.setSizePolicy(QSizePolicy.Ignored, QSizePolicy.Preferred)
        ql.addWidget(self.queue_summary)

        self.logview = LogView()
        lw = QWidget()
        ll = QVBoxLayout(lw)
        ll.setContentsMargins(4, 0, 4, 4)
        ll.addWidget(QLabel("<b>Log</b>"))
        ll.addWidget(self.logview, 1)

        self.estimates = EstimateBox()
        self.estimates.setObjectName("estimates")
        self.left = QSplitter(Qt.Vertical)
        self.left.setObjectName("left_split")
        self.left.addWidget(qw)
        self.left.addWidget(self.estimates)
        self.left.addWidget(lw)
        self.left.setStretchFactor(0, 3)
        self.left.setStretchFactor(1, 0)
        self.left.setStretchFactor(2, 1)
        self.left.setCollapsible(1, False)
        self.estimates.setMinimumHeight(self.estimates.sizeHint().height())

        self.preview = PreviewPanel()
        self.preview.set_separations(self.gs.separations)
        self.preview.separationsChanged.connect(self._separations_changed)
        self.live = LiveView()
        self.tabs = QTabWidget()
        self.tabs.setObjectName("tabs")
        self.tabs.addTab(self.preview, "Preview")
        self.tabs.addTab(self.live, "Live media")

        self.split = QSplitter(Qt.Horizontal)
        self.split.setObjectName("main_split")
        self.split.addWidget(self.left)
        self.split.addWidget(self.tabs)
        self.split.setStretchFactor(0, 2)
        self.split.setStretchFactor(1, 3)
        self.setCentralWidget(self.split)

        # settings dock
        self.settings_panel = SettingsPanel()
        self.settings_panel.set_profiles(self._profiles(), self.defaults.profile)
        self.settings_panel.set_settings(self.defaults, "Settings for new jobs")
        self.settings_panel.changed.connect(self._settings_edited)
        sa = QScrollArea()
        sa.setWidgetResizable(True)
        sa.setWidget(self.settings_panel)
        sa.setMinimumWidth(330)
        d = QDockWidget("Job settings", self)
        d.setObjectName("dock_settings")
        d.setWidget(sa)
        d.setFeatures(QDockWidget.DockWidgetMovable | QDockWidget.DockWidgetFloatable)
        self.addDockWidget(Qt.RightDockWidgetArea, d)
        self.view_menu.addAction(d.toggleViewAction())

        # device dock
        self.device = DevicePanel(self.actions_)
        self.device.spec.setText(self.gs.device_spec or "emulator")
        self.device.media_dir.setText(self.gs.media_dir)
        self.device.faults.setText(self.gs.emulator_faults)
        self.device.set_speed(self.gs.emulator_speed)
        self.device.speedChanged.connect(self._speed_changed)
        self.device.connectRequested.connect(self.connect_device)
        self.device.disconnectRequested.connect(self.requestDisconnect.emit)
        self.device.configChanged.connect(self._device_config_changed)
        self.device.set_profile(cached_profile(self.user_profile))
        d = QDockWidget("Printer", self)
        d.setObjectName("dock_device")
        d.setWidget(self.device)
        d.setFeatures(QDockWidget.DockWidgetMovable | QDockWidget.DockWidgetFloatable)
        self.addDockWidget(Qt.BottomDockWidgetArea, d)
        self.view_menu.addAction(d.toggleViewAction())

        self.status_conn = QLabel("Not connected")
        self.statusBar().addPermanentWidget(self.status_conn)
        self._update_media()

    def _restore(self) -> None:
        self.resize(1600, 1000)
        try:
            if self.gs.geometry:
                self.restoreGeometry(QByteArray.fromBase64(self.gs.geometry.encode()))
            if self.gs.window_state:
                self.restoreState(QByteArray.fromBase64(self.gs.window_state.encode()))
            if self.gs.splitter:
                self.split.restoreState(QByteArray.fromBase64(self.gs.splitter.encode()))
        except Exception:  # noqa: BLE001 - a bad layout is not worth failing over
            pass

    def showEvent(self, ev) -> None:
        super().showEvent(ev)
        if not getattr(self, "_sized", False):
            self._sized = True
            if not self.gs.splitter:
                w = max(800, self.split.width())
                self.split.setSizes([int(w * 0.45), w - int(w * 0.45)])

    def _profiles(self) -> list[tuple[str, str]]:
        out = [("User profile (calibrated)", ""), ("Built-in default", str(DEFAULT_PROFILE))]
        seen = {str(self.user_profile), str(DEFAULT_PROFILE)}
        for folder in (self.user_profile.parent, RESOURCES / "printers"):
            for p in sorted(Path(folder).glob("*.toml")):
                if str(p) not in seen:
                    out.append((p.stem, str(p)))
                    seen.add(str(p))
        return out

    def profile_path(self, js: JobSettings) -> str:
        return js.profile or str(self.user_profile)

    # ======================================================================================
    # queue
    def open_files_dialog(self) -> None:
        paths, _ = QFileDialog.getOpenFileNames(self, "Add images to the queue", self.gs.last_dir, FILE_FILTER)
        if paths:
            self.add_files(paths)

    def add_files(self, paths) -> list[Q.QueueItem]:
        """Add images (or folders of images) to the end of the queue; their previews and
        estimates are computed in the background."""
        paths = Q.expand_paths(paths)
        items = []
        for p in paths:
            it = Q.QueueItem(str(p), self.defaults.copy())
            self.model.add(it)
            items.append(it)
            self._request_preview(it)
            log.info("added %s", p)
        if paths:
            self.gs.last_dir = str(Path(paths[-1]).parent)
            self.select_item(items[-1].id)
        self._update_actions()
        return items

    def dragEnterEvent(self, ev):
        md = ev.mimeData()
        if md.hasUrls() and any(u.isLocalFile() for u in md.urls()):
            ev.acceptProposedAction()
        else:
            ev.ignore()

    dragMoveEvent = dragEnterEvent

    def dropEvent(self, ev):
        md = ev.mimeData()
        paths = [u.toLocalFile() for u in md.urls() if u.isLocalFile()]
        if paths:
            self.add_files(paths)
            ev.acceptProposedAction()

    def selected_items(self) -> list[Q.QueueItem]:
        rows = sorted({i.row() for i in self.table.selectionModel().selectedRows()})
        return [self.model.items[r] for r in rows if r < len(self.model.items)]

    def select_item(self, item_id: int) -> None:
        r = self.model.row_of(item_id)
        if r >= 0:
            self.table.selectionModel().select(
                self.model.index(r, 0), QItemSelectionModel.ClearAndSelect | QItemSelectionModel.Rows)
            self.table.scrollTo(self.model.index(r, 0))

    def remove_selected(self) -> None:
        rows = [self.model.row_of(it.id) for it in self.selected_items() if it.state not in Q.ACTIVE]
        for it in self.model.remove_rows(rows):
            self._previews.pop(it.id, None)
            log.info("removed %s", it.path)
        self._update_actions()

    def duplicate_selected(self) -> list[Q.QueueItem]:
        new = []
        for it in self.selected_items():
            dup = Q.QueueItem(it.path, it.settings.copy())
            dup.estimate, dup.source_desc = it.estimate, it.source_desc
            if it.id in self._previews:
                self._previews[dup.id] = self._previews[it.id]
                dup.preview_key = it.preview_key
                dup.state = Q.READY
            self.model.add(dup, self.model.row_of(it.id) + 1)
            if dup.state != Q.READY:
                self._request_preview(dup)
            new.append(dup)
        self._update_actions()
        return new

    def move_selected(self, delta: int) -> None:
        items = self.selected_items()
        if len(items) != 1:
            return
        r = self.model.row_of(items[0].id)
        if self.model.move(r, r + delta):
            self.select_item(items[0].id)

    def reset_selected(self) -> None:
        for it in self.selected_items():
            if it.state not in Q.ACTIVE:
                it.state, it.progress, it.message, it.detail = Q.READY, 0.0, "", ""
                self.model.changed(it.id)
                self._request_preview(it, force=True)
        self._update_actions()

    def _queue_menu(self, pos) -> None:
        m = QMenu(self)
        for k in ("print", "duplicate", "remove", "up", "down", "reset"):
            m.addAction(self.actions_[k])
        m.exec(self.table.viewport().mapToGlobal(pos))

    def _update_summary(self) -> None:
        items = self.model.items
        todo = [it for it in items if it.state not in (Q.DONE,)]
        t = sum(it.estimate.time_s for it in todo if it.estimate)
        ink = sum(it.estimate.total_ink_ml for it in todo if it.estimate)
        area = sum(it.estimate.area_m2 * it.estimate.copies for it in todo if it.estimate)
        done = sum(1 for it in items if it.state == Q.DONE)
        self.queue_summary.setText(
            f"{len(items)} job{'s' if len(items) != 1 else ''} ({done} printed) — to print: "
            f"{fmt_duration(t)}, {area:.2f} m², {fmt_ml(ink)} ml ink" if items else "Queue empty")

    # ======================================================================================
    # settings and previews
    def _selection_changed(self, *_):
        items = self.selected_items()
        if not items:
            self.settings_panel.set_settings(self.defaults, "Settings for new jobs")
            self.settings_panel.setEnabled(True)
            self.estimates.show_estimate(None)
            self.preview.show_message("Select a job to see its preview" if self.model.items else
                                      "Add images with “Add files…” or drop them on the window")
            self.preview.title.setText("No job selected")
        else:
            it = items[0]
            title = f"Settings: {it.name}" if len(items) == 1 else f"Settings: {len(items)} jobs"
            self.settings_panel.set_settings(it.settings, title)
            self.settings_panel.setEnabled(all(i.state not in Q.ACTIVE for i in items))
            self._show_selected_preview()
        self._update_actions()

    def _settings_edited(self, js: JobSettings) -> None:
        self.defaults = js.copy()
        for it in self.selected_items():
            if it.state in Q.ACTIVE:
                continue
            it.settings = js.copy()
            self.model.changed(it.id)
        self._preview_timer.start()

    def _refresh_selected_preview(self) -> None:
        for it in self.selected_items():
            if it.state not in Q.ACTIVE:
                self._request_preview(it)

    def _media_width(self, js: JobSettings) -> float:
        try:
            prof = cached_profile(self.profile_path(js))
        except Exception:  # noqa: BLE001
            return 3190.0
        return printable_width_mm(prof, self.paper_mm, js.margin_mm)

    def _preview_key(self, it: Q.QueueItem) -> tuple:
        path = self.profile_path(it.settings)
        try:
            mtime = Path(path).stat().st_mtime_ns
        except OSError:
            mtime = 0
        return (json.dumps(it.settings.as_dict(), sort_keys=True), path, mtime,
                round(self._media_width(it.settings), 1))

    def _request_preview(self, it: Q.QueueItem, force: bool = False) -> None:
        key = self._preview_key(it)
        if not force and key == it.preview_key and (it.id in self._previews or it.id in self._pending_previews):
            return
        it.preview_key = key
        self._pending_previews.add(it.id)
        if it.state not in Q.ACTIVE and it.state in (Q.READY, Q.ERROR, Q.LOADING):
            it.state = Q.LOADING
            self.model.changed(it.id)
        path, js, prof, mw = it.path, it.settings.copy(), self.profile_path(it.settings), self._media_width(it.settings)
        task = Task(("preview", it.id, key), lambda: compute_preview(path, js.rip_settings(mw), cached_profile(prof), js.copies))
        self._start_task(task, self._preview_done, self._preview_failed)

    def _start_task(self, task: Task, done, failed) -> None:
        self._tasks[task.key] = task.signals
        task.signals.done.connect(done)
        task.signals.failed.connect(failed)
        self.pool.start(task)

    def _preview_done(self, key, data) -> None:
        self._tasks.pop(key, None)
        _, item_id, pkey = key
        it = self.model.item(item_id)
        if it is None or it.preview_key != pkey:
            return
        self._pending_previews.discard(item_id)
        self._previews[item_id] = data
        it.estimate, it.source_desc = data.estimate, data.source_desc
        if it.state in (Q.LOADING, Q.ERROR):
            it.state, it.message = Q.READY, "; ".join(data.warnings)
        self.model.changed(item_id)
        self._update_summary()
        self._update_actions()
        sel = self.selected_items()
        if sel and sel[0].id == item_id:
            self._show_selected_preview()

    def _preview_failed(self, key, message: str) -> None:
        self._tasks.pop(key, None)
        _, item_id, pkey = key
        it = self.model.item(item_id)
        if it is None or it.preview_key != pkey:
            return
        self._pending_previews.discard(item_id)
        self._previews.pop(item_id, None)
        it.estimate = None
        if it.state not in Q.ACTIVE:
            it.state, it.message = Q.ERROR, message
        log.error("%s", message)
        self.model.changed(item_id)
        self._update_summary()
        self._update_actions()
        sel = self.selected_items()
        if sel and sel[0].id == item_id:
            self._show_selected_preview()

    def _show_selected_preview(self) -> None:
        items = self.selected_items()
        if not items:
            return
        it = items[0]
        data = self._previews.get(it.id)
        if data is None:
            if it.state == Q.ERROR or (it.message and it.id not in self._pending_previews):
                advice = plain_message(it.message)
                self.preview.show_message(f"Cannot print {it.name}\n\n{short_paths(it.message)}"
                                          + (f"\n\n{advice}" if advice else ""))
                self.preview.title.setText(f"{it.name} — error")
                self.estimates.show_estimate(None, "")
            else:
                self.preview.title.setText(f"{it.name} — computing the preview…")
                self.estimates.show_estimate(None, "computing…")
            return
        note = (f"{data.source_desc}. Preview: the RIP's halftone "
                + ("dot for dot." if data.exact else
                   f"of a {data.dots.shape[1]} × {data.dots.shape[0]} reduction.")
                + f" Ink from the preview's drops × {cached_profile(self.profile_path(it.settings)).drop_volume_pl:g} pl.")
        self.estimates.show_estimate(data.estimate, note)
        seps = self.preview.separations()
        key = ("render", it.id, it.preview_key, tuple(seps))
        dots = data.dots
        task = Task(key, lambda: render_separations(dots, seps))
        self._start_task(task, self._render_done, lambda k, m: self._tasks.pop(k, None))

    def _render_done(self, key, rgb) -> None:
        self._tasks.pop(key, None)
        _, item_id, pkey, seps = key
        sel = self.selected_items()
        if not sel or sel[0].id != item_id or sel[0].preview_key != pkey or \
                tuple(self.preview.separations()) != seps:
            return
        data = self._previews.get(item_id)
        if data is None:
            return
        it = sel[0]
        shown = "".join(n for n, on in zip("CMYK", seps) if on) or "none"
        self.preview.set_image(rgb, data.width_mm, data.height_mm,
                               f"{it.name} — {data.width_mm:,.0f} × {data.height_mm:,.0f} mm, "
                               f"{data.width_dots:,} × {data.height_rows:,} dots, separations {shown}")

    def _separations_changed(self, flags) -> None:
        self.gs.separations = list(flags)
        self._show_selected_preview()

    def _update_media(self) -> None:
        try:
            prof = cached_profile(self.profile_path(self.defaults))
            paper = self.paper_mm or prof.paper.default_width_mm
            self.preview.set_media(paper, prof.paper.margin_mm)
        except Exception:  # noqa: BLE001
            pass

    # ======================================================================================
    # printing
    def _device_config(self, profile_path: str = "") -> DeviceConfig:
        return DeviceConfig(self.device.spec.text().strip() or "emulator", self.device.faults.text().strip(),
                            profile_path or str(self.user_profile))

    def connect_device(self) -> None:
        self.status_conn.setText("Connecting…")
        self.device.conn_state.setText("Connecting…")
        self.requestConnect.emit(self._device_config(self.profile_path(self.defaults)))

    def _device_config_changed(self) -> None:
        self.gs.device_spec = self.device.spec.text().strip() or "emulator"
        self.gs.media_dir = self.device.media_dir.text().strip()
        self.gs.emulator_faults = self.device.faults.text().strip()

    def _speed_changed(self, speed: float) -> None:
        self.pace.speed = float(speed)
        self.gs.emulator_speed = float(speed)

    def print_queue(self) -> int:
        """Print every job that is not printed yet, top to bottom.  Returns how many."""
        n = 0
        for it in self.model.items:
            if it.state in Q.PRINTABLE:
                it.state, it.progress, it.message, it.detail = Q.WAITING, 0.0, "", ""
                self.model.changed(it.id)
                n += 1
        if n and not self.running and self.current is None:
            self.running = True
            log.info("printing the queue (%d job%s)", n, "s" if n > 1 else "")
            self._start_next()
        self._update_actions()
        return n

    def _start_next(self) -> None:
        it = next((i for i in self.model.items if i.state == Q.WAITING), None)
        if it is None or not self.running:
            self.running = False
            self._update_actions()
            self.queueFinished.emit()
            return
        self._device_config_changed()
        t = Ticket(item_id=it.id, path=it.path, settings=it.settings.copy(),
                   profile_path=self.profile_path(it.settings), copies=it.settings.copies,
                   media_dir=self.gs.media_dir, media_width_mm=self._media_width(it.settings),
                   device=self._device_config(self.profile_path(it.settings)))
        self.current = (it.id, t)
        self.paused = False
        it.state, it.detail = Q.PRINTING, "starting"
        self.model.changed(it.id)
        self.requestTicket.emit(t)
        self._update_actions()

    def _stop_queue(self) -> None:
        self.running = False
        for it in self.model.items:
            if it.state == Q.WAITING:
                it.state = Q.READY
                self.model.changed(it.id)

    def pause_job(self) -> None:
        if self.current:
            self.current[1].control.pause()
            self.paused = True
            log.info("pause requested: the job pauses after the stroke that is printing")
            self._update_actions()

    def resume_job(self) -> None:
        if self.current:
            self.current[1].control.resume()
            self.paused = False
            log.info("resumed")
            self._update_actions()

    def cancel_job(self) -> None:
        if self.current:
            self.current[1].control.cancel()
            log.warning("cancel requested")
        self._stop_queue()
        self._update_actions()

    def emergency_stop(self) -> None:
        log.warning("EMERGENCY STOP")
        self._stop_queue()
        if self.current:
            self.current[1].control.estop()
        else:
            self.requestEstop.emit()
        self._update_actions()

    def clear_fault(self) -> None:
        self.device.show_fault("")
        self.requestClearFault.emit()

    def _job_started(self, item_id: int, info: dict) -> None:
        copies = info.get("copies", 1)
        self.device.show_fault("")
        if item_id < 0:
            name = "test print"
        else:
            it = self.model.item(item_id)
            name = it.name if it else "?"
        if info.get("sink") is None:
            self.live.label.setText("The live media view is available on the emulator; "
                                    f"printing {name} on {self.gs.device_spec}")
        else:
            prof = cached_profile(self.current[1].profile_path) if self.current else None
            k = prof.k(info["dpi"]) if prof else 2
            cpi = prof.counts_per_inch if prof else 600
            w_mm = info["width"] * k / cpi * 25.4
            h_mm = info["height"] * info["row_um"] / 1000
            title = f"{name}" + (f", copy {info['copy'] + 1} of {copies}" if copies > 1 else "") + \
                f" — {w_mm:,.0f} × {h_mm:,.0f} mm, {info.get('strokes', '?')} stroke" + \
                ("" if info.get("strokes") == 1 else "s")
            self.live.start(info["sink"], w_mm, h_mm, title)
            if item_id > 0 and self.tabs.currentIndex() == 0:
                self.tabs.setCurrentWidget(self.live)
        self.device.job_label.setText(f"{name}" + (f" (copy {info['copy'] + 1} of {copies})" if copies > 1 else ""))

    def _job_state(self, item_id: int, state: str, detail: str) -> None:
        self.device.show_state(state, detail)
        if item_id < 0:
            if self.calibration is not None:
                self.calibration.job_state(state, detail)
            return
        it = self.model.item(item_id)
        if it is None:
            return
        if state == "paused":
            it.state, it.detail = Q.PAUSED, detail
        elif state in ("connecting", "printing", "queued"):
            it.state, it.detail = Q.PRINTING, detail
        self.model.changed(item_id)
        self._update_actions()

    def _job_stroke(self, item_id: int, copy: int, copies: int, index: int, total: int) -> None:
        it = self.model.item(item_id)
        if it is not None:
            it.progress = (copy + index / max(1, total)) / max(1, copies)
            self.model.changed(item_id)

    def _job_finished(self, item_id: int, result: dict) -> None:
        state, message = result.get("state", "failed"), result.get("message", "")
        self.current = None
        self.paused = False
        self.device.show_state(state, message if state == "cancelled" else "")
        if item_id > 0 and self.model.item(item_id) is not None:
            self.device.job_label.setText(self.model.item(item_id).name)
        self.live.finish(state if state == "done" else f"{state}: {message}")
        if state != "done":
            self.device.show_fault(message if state == "failed" else "")
        else:
            self.device.show_fault("")
        if item_id < 0:
            if self.calibration is not None:
                self.calibration.job_finished(result)
            self._update_actions()
            return
        it = self.model.item(item_id)
        if it is not None:
            it.state = {"done": Q.DONE, "cancelled": Q.CANCELLED}.get(state, Q.FAILED)
            it.message, it.detail = message, ""
            it.media = list(result.get("media", []))
            it.reports = list(result.get("reports", []))
            if state == "done":
                it.progress = 1.0
            self.model.changed(item_id)
            level = logging.INFO if state == "done" else logging.ERROR
            log.log(level, "%s: %s%s", it.name, state, f": {message}" if message else "")
        self._update_summary()
        if state == "cancelled" or "emergency stop" in message:
            self._stop_queue()
        if self.running:
            self._start_next()
        else:
            self.queueFinished.emit()
        self._update_actions()

    def _device_changed(self, d: dict) -> None:
        self.connected = bool(d.get("connected"))
        self.device.show_connection(d)
        paper = d.get("paper_mm")
        if self.connected and paper and paper != self.paper_mm:
            self.paper_mm = paper
            self._update_media()
        self.status_conn.setText(f"Connected: {d.get('spec')}" if self.connected else "Not connected")
        self._update_actions()

    def _poll_telemetry(self) -> None:
        job = self.worker.current_job
        if job is None:
            return
        t = job.telemetry
        self.device.show_telemetry(t)
        strokes = f"stroke {t.stroke_index + 1 if t.stroke_index is not None else '–'} of " \
                  f"{t.strokes_total}, {t.strokes_printed} printed"
        self.worker.capture_live()
        self.live.refresh(strokes)

    def _idle_refresh(self) -> None:
        if self.connected and self.current is None and not self.worker.busy:
            self.requestRefresh.emit()

    def _update_actions(self) -> None:
        A = self.actions_
        busy = self.current is not None
        sel = self.selected_items()
        printable = any(it.state in Q.PRINTABLE for it in self.model.items)
        A["print"].setEnabled(printable and not self.running)
        A["pause"].setEnabled(busy and not self.paused)
        A["resume"].setEnabled(busy and self.paused)
        A["cancel"].setEnabled(busy or self.running)
        A["clear_fault"].setEnabled(self.connected and not busy)
        A["remove"].setEnabled(any(it.state not in Q.ACTIVE for it in sel))
        A["duplicate"].setEnabled(bool(sel))
        # a job being printed keeps its place (the same rule as dragging, Q.movable)
        one = len(sel) == 1 and Q.movable(sel[0])
        A["up"].setEnabled(one and self.model.row_of(sel[0].id) > 0)
        A["down"].setEnabled(one and 0 <= self.model.row_of(sel[0].id) < len(self.model.items) - 1)
        A["reset"].setEnabled(any(it.state in (Q.DONE, Q.FAILED, Q.CANCELLED, Q.ERROR) for it in sel))
        A["calibrate"].setEnabled(not busy)
        self._update_summary()

    # ======================================================================================
    # calibration
    def open_calibration(self) -> CalibrationDialog:
        if self.calibration is None:
            self.calibration = CalibrationDialog(
                str(ensure_user_profile(self.config_dir)), self._test_print, self.cache_dir / "testprints",
                emulator=(self.device.spec.text().strip() or "emulator") == "emulator",
                settings=self.gs.calibration, parent=self)
            self.calibration.profileSaved.connect(self._profile_saved)
            self.calibration.finished.connect(self._calibration_closed)
        self.calibration.show()
        self.calibration.raise_()
        return self.calibration

    def _calibration_closed(self, *_):
        if self.calibration is not None:
            self.gs.calibration = self.calibration.settings()
            self.calibration.deleteLater()
            self.calibration = None

    def _test_print(self, pattern: dict, media_file: str) -> int | None:
        if self.current is not None or self.running:
            QMessageBox.information(self, "Printer busy", "Wait for the queue to finish (or cancel it) first.")
            return None
        tid = -next(self._ticket_ids)
        prof = str(ensure_user_profile(self.config_dir))
        t = Ticket(item_id=tid, path=f"test-print:{pattern['kind']}", settings=self.defaults.copy(),
                   profile_path=prof, kind="pattern", pattern=dict(pattern), media_file=media_file,
                   device=self._device_config(prof))
        self.current = (tid, t)
        self.paused = False
        log.info("test print %s at %s dpi", pattern["kind"], pattern.get("dpi"))
        self.requestTicket.emit(t)
        self._update_actions()
        return tid

    def _profile_saved(self, path: str) -> None:
        self.device.set_profile(cached_profile(path))
        for it in self.model.items:
            if self.profile_path(it.settings) == path and it.state not in Q.ACTIVE:
                self._request_preview(it)

    # ======================================================================================
    # closing
    def save_settings(self) -> None:
        self.gs.job = self.defaults.as_dict()
        self.gs.geometry = bytes(self.saveGeometry().toBase64()).decode()
        self.gs.window_state = bytes(self.saveState().toBase64()).decode()
        self.gs.splitter = bytes(self.split.saveState().toBase64()).decode()
        self.gs.separations = self.preview.separations()
        self._device_config_changed()
        if self.calibration is not None:
            self.gs.calibration = self.calibration.settings()
        try:
            self.gs.save(self.settings_path)
        except OSError as exc:
            log.warning("cannot save the GUI settings to %s: %s", self.settings_path, exc)

    def closeEvent(self, ev) -> None:
        if self.current is not None and self.ask_before_closing:
            r = QMessageBox.question(self, "Quit", "A job is printing. Cancel it and quit?")
            if r != QMessageBox.Yes:
                ev.ignore()
                return
        self.save_settings()
        self.shutdown()
        super().closeEvent(ev)

    def shutdown(self) -> None:
        if getattr(self, "_shut", False):
            return
        self._shut = True
        self.telemetry_timer.stop()
        self.idle_timer.stop()
        self.running = False
        if self.current is not None:
            self.current[1].control.cancel()
        self.printer_thread.quit()
        if not self.printer_thread.wait(15000):
            log.error("the printer thread did not stop")
        else:
            self.worker.shutdown()          # the thread is gone: close the device from here
        self.pool.clear()
        self.pool.waitForDone(15000)
        self.logview.uninstall()
        if self.calibration is not None:
            self.calibration.close()


__all__ = ["MainWindow"]
