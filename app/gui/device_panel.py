"""The printer: connection, state, carriage, paper, FIFO levels, head temperatures,
faults in plain language, and the print / pause / resume / cancel / emergency-stop
buttons (the actions are the main window's, wired to PrintJob.control)."""

from __future__ import annotations

from PySide6.QtCore import Qt, Signal
from PySide6.QtWidgets import (QComboBox, QFileDialog, QFormLayout, QFrame, QGridLayout,
                               QGroupBox, QHBoxLayout, QLabel, QLineEdit, QProgressBar,
                               QPushButton, QSizePolicy, QToolButton, QVBoxLayout, QWidget)

from .messages import plain_message, short_paths

SPEEDS = [(0.0, "As fast as possible"), (1.0, "Real time"), (2.0, "2 × real time"),
          (5.0, "5 × real time"), (10.0, "10 × real time"), (50.0, "50 × real time")]


def _fault_kinds_tip() -> str:
    from ...device_sim.faults import KINDS
    return "Injected faults (emulator only), e.g. bidir-error=2 dead-nozzle=M1:57\n\n" + \
        "\n".join(f"{k}: {v}" for k, v in KINDS.items())


class DevicePanel(QWidget):
    connectRequested = Signal()
    disconnectRequested = Signal()
    configChanged = Signal()        # spec / media folder / faults edited
    speedChanged = Signal(float)

    def __init__(self, actions: dict, parent=None):
        super().__init__(parent)
        self.setObjectName("device_panel")
        lay = QHBoxLayout(self)
        lay.setContentsMargins(4, 4, 4, 4)

        # -- connection -------------------------------------------------------------------
        conn = QGroupBox("Connection")
        cf = QFormLayout(conn)
        cf.setFieldGrowthPolicy(QFormLayout.AllNonFixedFieldsGrow)
        self.spec = QLineEdit("emulator")
        self.spec.setObjectName("device_spec")
        self.spec.setToolTip("“emulator”, or serial=PORT,data=tcp://HOST:PORT")
        self.spec.editingFinished.connect(self.configChanged)
        row = QHBoxLayout()
        row.addWidget(self.spec, 1)
        self.connect_btn = QPushButton("Connect")
        self.connect_btn.setObjectName("connect")
        self.connect_btn.clicked.connect(self._connect_clicked)
        row.addWidget(self.connect_btn)
        cf.addRow("Device", row)
        self.media_dir = QLineEdit()
        self.media_dir.setObjectName("media_dir")
        self.media_dir.setPlaceholderText("not saved")
        self.media_dir.setToolTip("Emulator media folder: each printed job's media is written "
                                  "here as a TIFF (one value per dot, like the RIP's planes)")
        self.media_dir.editingFinished.connect(self.configChanged)
        mrow = QHBoxLayout()
        mrow.addWidget(self.media_dir, 1)
        mb = QToolButton()
        mb.setText("…")
        mb.clicked.connect(self._browse_media)
        mrow.addWidget(mb)
        cf.addRow("Media folder", mrow)
        self.speed = QComboBox()
        self.speed.setObjectName("emulator_speed")
        for v, t in SPEEDS:
            self.speed.addItem(t, v)
        self.speed.setToolTip("How fast the emulated machine runs (its carriage and feed times)")
        self.speed.currentIndexChanged.connect(lambda *_: self.speedChanged.emit(self.speed.currentData()))
        cf.addRow("Emulator speed", self.speed)
        self.faults = QLineEdit()
        self.faults.setObjectName("emulator_faults")
        self.faults.setPlaceholderText("none")
        self.faults.setToolTip(_fault_kinds_tip())
        self.faults.editingFinished.connect(self.configChanged)
        cf.addRow("Emulator faults", self.faults)
        self.conn_state = QLabel("Not connected")
        self.conn_state.setObjectName("conn_state")
        self.conn_state.setWordWrap(True)
        self.conn_state.setSizePolicy(QSizePolicy.Ignored, QSizePolicy.Preferred)
        cf.addRow("Status", self.conn_state)
        lay.addWidget(conn, 3)

        # -- machine state ----------------------------------------------------------------
        st = QGroupBox("Printer")
        sg = QGridLayout(st)
        self.state = QLabel("Idle")
        self.state.setObjectName("printer_state")
        self.state.setSizePolicy(QSizePolicy.Ignored, QSizePolicy.Preferred)
        self.state.setStyleSheet("font-size: 13pt; font-weight: bold;")
        sg.addWidget(self.state, 0, 0, 1, 2)
        self.job_label = QLabel("")
        self.job_label.setObjectName("job_label")
        self.job_label.setSizePolicy(QSizePolicy.Ignored, QSizePolicy.Preferred)
        sg.addWidget(self.job_label, 1, 0, 1, 2)
        sg.addWidget(QLabel("Carriage"), 2, 0)
        self.carriage = QProgressBar()
        self.carriage.setObjectName("carriage")
        self.carriage.setTextVisible(True)
        self.carriage.setRange(0, 1000)
        self.carriage.setFormat("–")
        sg.addWidget(self.carriage, 2, 1)
        sg.addWidget(QLabel("Paper"), 3, 0)
        self.paper = QLabel("–")
        self.paper.setObjectName("paper")
        sg.addWidget(self.paper, 3, 1)
        sg.addWidget(QLabel("Link"), 4, 0)
        self.link = QLabel("–")
        sg.addWidget(self.link, 4, 1)
        sg.setColumnStretch(1, 1)
        sg.setRowStretch(5, 1)
        lay.addWidget(st, 3)

        # -- FIFOs and heads --------------------------------------------------------------
        heads = QGroupBox("Heads: FIFO and temperature")
        hg = QGridLayout(heads)
        hg.setHorizontalSpacing(6)
        self.fifo_bars, self.temp_labels, self.head_names = [], [], []
        for i in range(8):
            name = QLabel("")
            name.setAlignment(Qt.AlignCenter)
            bar = QProgressBar()
            bar.setOrientation(Qt.Vertical)
            bar.setRange(0, 256)
            bar.setValue(0)
            bar.setTextVisible(False)
            bar.setMinimumHeight(50)
            bar.setMaximumWidth(22)
            bar.setSizePolicy(QSizePolicy.Fixed, QSizePolicy.Expanding)
            temp = QLabel("–")
            temp.setAlignment(Qt.AlignCenter)
            temp.setStyleSheet("font-size: 8pt;")
            hg.addWidget(bar, 0, i, Qt.AlignHCenter)
            hg.addWidget(name, 1, i)
            hg.addWidget(temp, 2, i)
            self.fifo_bars.append(bar)
            self.temp_labels.append(temp)
            self.head_names.append(name)
        hg.setRowStretch(0, 1)
        lay.addWidget(heads, 3)

        # -- controls and faults ----------------------------------------------------------
        ctl = QGroupBox("Job")
        cv = QVBoxLayout(ctl)
        grid = QGridLayout()
        order = ("print", "pause", "resume", "cancel")
        for i, key in enumerate(order):
            b = QToolButton()
            b.setDefaultAction(actions[key])
            b.setToolButtonStyle(Qt.ToolButtonTextBesideIcon)
            b.setSizePolicy(QSizePolicy.Expanding, QSizePolicy.Fixed)
            b.setObjectName(f"btn_{key}")
            grid.addWidget(b, i // 2, i % 2)
        cv.addLayout(grid)
        self.estop = QPushButton("EMERGENCY STOP")
        self.estop.setObjectName("btn_estop")
        self.estop.setMinimumHeight(36)
        self.estop.setStyleSheet("QPushButton { background: #d32f2f; color: white; font-weight: bold; "
                                 "border-radius: 4px; } QPushButton:pressed { background: #9a0007; }")
        self.estop.clicked.connect(actions["estop"].trigger)
        cv.addWidget(self.estop)
        self.clear_fault = QToolButton()
        self.clear_fault.setDefaultAction(actions["clear_fault"])
        self.clear_fault.setToolButtonStyle(Qt.ToolButtonTextBesideIcon)
        self.clear_fault.setSizePolicy(QSizePolicy.Expanding, QSizePolicy.Fixed)
        cv.addWidget(self.clear_fault)
        self.fault = QLabel("")
        self.fault.setObjectName("fault")
        self.fault.setWordWrap(True)
        self.fault.setTextFormat(Qt.RichText)
        self.fault.setFrameShape(QFrame.NoFrame)
        self.fault.setSizePolicy(QSizePolicy.Ignored, QSizePolicy.Ignored)
        self.fault.setAlignment(Qt.AlignTop | Qt.AlignLeft)
        cv.addWidget(self.fault, 1)
        lay.addWidget(ctl, 4)

        self._fault_source = ""
        self.rail_counts = 92000
        self.cpi = 600
        self.fifo_max = 256

    # -- configuration ----------------------------------------------------------------------
    def _connect_clicked(self):
        if self.connect_btn.text() == "Connect":
            self.connectRequested.emit()
        else:
            self.disconnectRequested.emit()

    def _browse_media(self):
        d = QFileDialog.getExistingDirectory(self, "Emulator media folder", self.media_dir.text())
        if d:
            self.media_dir.setText(d)
            self.configChanged.emit()

    def set_speed(self, speed: float) -> None:
        i = self.speed.findData(float(speed))
        if i < 0:
            self.speed.addItem(f"{speed:g} × real time", float(speed))
            i = self.speed.count() - 1
        self.speed.setCurrentIndex(i)

    def set_profile(self, profile) -> None:
        self.rail_counts = profile.rail_counts
        self.cpi = profile.counts_per_inch
        self.fifo_max = profile.fifo_words
        for i, bar in enumerate(self.fifo_bars):
            if i < len(profile.heads):
                h = profile.heads[i]
                self.head_names[i].setText(h.name)
                bar.setRange(0, profile.fifo_words)
                bar.setToolTip(f"{h.name}: FIFO level (words of {profile.fifo_words})")
                color = {"C": "#00aeef", "M": "#ec008c", "Y": "#d4c400", "K": "#333"}[h.color]
                bar.setStyleSheet(f"QProgressBar::chunk {{ background: {color}; }}")
            bar.setVisible(i < len(profile.heads))
            self.head_names[i].setVisible(i < len(profile.heads))
            self.temp_labels[i].setVisible(i < len(profile.heads))

    # -- state ------------------------------------------------------------------------------
    def show_connection(self, d: dict) -> None:
        if d.get("connected"):
            info = d.get("info") or {}
            text = f"Connected: {d.get('spec')}"
            if info:
                fw = info.get("firmware")
                fw = f"{fw >> 8}.{fw & 0xFF}" if isinstance(fw, int) else "?"   # 0x0100 = 1.0
                text += f" (firmware {fw}, serial {info.get('serial', '?')})"
            self.conn_state.setText(text)
            self.conn_state.setStyleSheet("color: #2e7d32;")
            self.connect_btn.setText("Disconnect")
        else:
            err = d.get("error", "")
            self.conn_state.setText(f"Not connected{': ' + err if err else ''}")
            self.conn_state.setStyleSheet("color: #c62828;" if err else "")
            self.connect_btn.setText("Connect")
        if d.get("error"):
            self.show_fault(d["error"], "device")
        paper = d.get("paper_mm")
        self.paper.setText(f"{paper:,.0f} mm wide" if paper else "–")
        if "carriage" in d:
            self.show_carriage(d["carriage"])
        if d.get("temps"):
            self.show_temps(d["temps"])
        if "fifo" in d:
            self.show_fifo(d["fifo"])
        if d.get("connected"):
            if d.get("fault"):
                self.show_fault(d["fault"], "device")
            elif self._fault_source == "device":
                self.show_fault("")           # a job's failure stays until the next job

    def show_state(self, state: str, detail: str = "") -> None:
        colors = {"printing": "#1565c0", "paused": "#ef6c00", "failed": "#c62828",
                  "cancelled": "#6d4c41", "done": "#2e7d32", "connecting": "#1565c0"}
        detail = short_paths(detail)
        if len(detail) > 48:
            detail = detail[:47] + "…"
        self.state.setText(state.capitalize() + (f" — {detail}" if detail else ""))
        self.state.setStyleSheet(f"font-size: 13pt; font-weight: bold; color: {colors.get(state, '#222')};")

    def show_carriage(self, counts: int) -> None:
        mm = counts / self.cpi * 25.4
        rail = self.rail_counts / self.cpi * 25.4
        self.carriage.setValue(int(max(0, min(1000, 1000 * counts / max(1, self.rail_counts)))))
        self.carriage.setFormat(f"{mm:,.0f} mm of {rail:,.0f}")

    def show_fifo(self, levels) -> None:
        for bar, v in zip(self.fifo_bars, levels):
            bar.setValue(int(v))

    def show_temps(self, temps) -> None:
        for lab, t in zip(self.temp_labels, temps):
            lab.setText(f"{t:.1f}°")
            lab.setStyleSheet("font-size: 8pt; color: #c62828;" if t >= 50 else "font-size: 8pt;")

    def show_telemetry(self, t, paper_steps_mm: float | None = None) -> None:
        self.show_carriage(t.carriage_counts)
        if t.fifo_words:
            self.show_fifo(t.fifo_words)
        if t.head_temps_c:
            self.show_temps(t.head_temps_c)
        self.link.setText(f"{t.retries} retries, {t.recoveries} reconnections")
        if t.fault:
            self.show_fault(t.fault, "device")

    def show_fault(self, text: str, source: str = "job") -> None:
        """The fault area: the device's own fault ("device") or a job's failure ("job")."""
        self._fault_source = source if text else ""
        if not text:
            self.fault.setText("")
            self.fault.setToolTip("")
            return
        from html import escape
        advice = plain_message(text)
        self.fault.setToolTip(text)
        html = f"<b style='color:#c62828'>{escape(short_paths(text))}</b>"
        if advice:
            html += f"<br>{escape(advice)}"
        self.fault.setText(html)
