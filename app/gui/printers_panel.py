"""The server's printers side by side (docs/gui.md, "Printers"): one card per printer with
its state, the job it prints, its live telemetry (carriage, FIFO levels, head temperatures)
and its fault in plain words, and the operator's buttons: pause / resume, clear the fault
(the stopped job resumes at its first unfinished stroke, or fails), test prints.

Every text has a place of fixed height, so a fault appearing moves nothing."""

from __future__ import annotations

import time

from PySide6.QtCore import Qt, Signal
from PySide6.QtWidgets import (QFrame, QGridLayout, QHBoxLayout, QLabel, QMenu, QProgressBar,
                               QPushButton, QScrollArea, QSizePolicy, QToolButton, QWidget)

from ..estimate import fmt_duration
from .messages import plain_message, short_paths


def roll_text(roll: dict | None) -> str:
    """The roll on a printer in a few words (docs/server.md "Rolls")."""
    if not roll:
        return " · no roll loaded"
    left = roll.get("remaining_m")
    return f" · {roll['media']}" + ("" if left is None else f", {left:,.2f} m left")


def _fixed_lines(label: QLabel, lines: int) -> QLabel:
    label.setWordWrap(True)
    label.setAlignment(Qt.AlignTop | Qt.AlignLeft)
    label.setFixedHeight(lines * label.fontMetrics().lineSpacing() + 4)
    label.setSizePolicy(QSizePolicy.Ignored, QSizePolicy.Fixed)
    return label


class PrinterCard(QFrame):
    action = Signal(str, str, object)      # printer, what (pause, resume, clear-fault, test-prints, head-care), body

    def __init__(self, name: str, parent=None):
        super().__init__(parent)
        self.name = name
        self.setObjectName(f"printer_{name}")
        self.setFrameShape(QFrame.StyledPanel)
        self.setMinimumWidth(300)
        g = QGridLayout(self)
        g.setContentsMargins(8, 4, 8, 4)
        g.setVerticalSpacing(1)
        self.title = QLabel(f"<b>{name}</b>")
        self.title.setTextFormat(Qt.RichText)
        self.device = self.title                       # its device spec: in the tooltip
        self.state = _fixed_lines(QLabel("—"), 1)
        self.state.setObjectName("printer_state")
        g.addWidget(self.title, 0, 0)
        g.addWidget(self.state, 0, 1, 1, 2)
        self.job = _fixed_lines(QLabel(""), 1)
        self.job.setObjectName("printer_job")
        g.addWidget(self.job, 1, 0, 1, 2)
        self.progress = QProgressBar()
        self.progress.setRange(0, 1000)
        self.progress.setTextVisible(True)
        self.progress.setFormat("")
        self.progress.setFixedWidth(150)
        self.progress.setFixedHeight(self.job.height())
        g.addWidget(self.progress, 1, 2)
        self.telemetry = _fixed_lines(QLabel(""), 1)
        self.telemetry.setObjectName("printer_telemetry")
        self.telemetry.setStyleSheet("color: #333;")
        g.addWidget(self.telemetry, 2, 0, 1, 3)
        # an emulated printer's media as it lands (GET /v1/printers/NAME/media.png)
        self.media = QLabel()
        self.media.setObjectName("printer_media")
        self.media.setFixedSize(150, 84)
        self.media.setAlignment(Qt.AlignCenter)
        self.media.setStyleSheet("background: #8a8d93; border: 1px solid #777;")
        self.media.setToolTip("the media as it lands (emulated printer)")
        g.addWidget(self.media, 0, 3, 5, 1)
        self.media_version = None
        self.fault = _fixed_lines(QLabel(""), 3)      # the fault and its advice, whole at 1366 px
        self.fault.setObjectName("printer_fault")
        self.fault.setStyleSheet("color: #c62828;")
        self.fault.setProperty("colour", "#c62828")
        g.addWidget(self.fault, 3, 0, 1, 3)
        row = QHBoxLayout()
        self.pause = QPushButton("Pause")
        self.pause.setObjectName("printer_pause")
        self.pause.clicked.connect(self._pause_clicked)
        self.clear = QToolButton()
        self.clear.setObjectName("printer_clear")
        self.clear.setText("Clear fault")
        self.clear.setPopupMode(QToolButton.InstantPopup)
        m = QMenu(self.clear)
        self.act_resume = m.addAction("Clear and resume the stopped job",
                                      lambda: self.action.emit(self.name, "clear-fault", {"then": "resume"}))
        self.act_fail = m.addAction("Clear and fail the stopped job",
                                    lambda: self.action.emit(self.name, "clear-fault", {"then": "fail"}))
        self.clear.setMenu(m)
        self.tests = QPushButton("Test prints…")
        self.tests.setObjectName("printer_tests")
        self.tests.clicked.connect(lambda: self.action.emit(self.name, "test-prints", None))
        # head care between jobs (docs/server.md "Head care"): the server runs it
        self.care = QToolButton()
        self.care.setObjectName("printer_care")
        self.care.setText("Head care")
        self.care.setToolTip("spit, purge or cap the heads (between jobs)")
        self.care.setPopupMode(QToolButton.InstantPopup)
        m = QMenu(self.care)
        for label, what in (("Spit all heads", "spit"), ("Purge and wipe all heads", "purge"),
                            ("Park and cap", "cap"), ("Uncap", "uncap")):
            m.addAction(label, lambda _w=what: self.action.emit(self.name, "head-care", {"action": _w}))
        self.care.setMenu(m)
        # the roll loaded (docs/server.md "Rolls"): media, length left; the server counts feeds
        self.roll = QPushButton("Roll…")
        self.roll.setObjectName("printer_roll")
        self.roll.setToolTip("the roll loaded: its media and length (the server counts every "
                             "feed off it and holds a job the roll cannot hold)")
        self.roll.clicked.connect(lambda: self.action.emit(self.name, "roll", None))
        row.addWidget(self.pause)
        row.addWidget(self.clear)
        row.addWidget(self.tests)
        row.addWidget(self.care)
        row.addWidget(self.roll)
        # head care (or another printer request) running: a busy bar and what runs, in the
        # button row (its height does not change: nothing moves when it shows)
        self.busy = QProgressBar()
        self.busy.setObjectName("printer_busy")
        self.busy.setRange(0, 0)
        self.busy.setTextVisible(False)
        self.busy.setFixedSize(48, 10)
        self.busy_text = QLabel("")
        self.busy_text.setObjectName("printer_busy_text")
        self.busy_text.setStyleSheet("color: #1565c0;")
        self.busy.hide()
        self.busy_text.hide()
        row.addWidget(self.busy)
        row.addWidget(self.busy_text)
        row.addStretch(1)
        g.addLayout(row, 4, 0, 1, 3)
        g.setColumnStretch(1, 1)
        self.info: dict = {}
        self._pace: tuple | None = None        # (job id, copy, first seen at, strokes then)

    def show_media(self, png: bytes) -> None:
        from PySide6.QtGui import QImage, QPixmap
        img = QImage.fromData(png, "PNG")
        if not img.isNull():
            self.media.setPixmap(QPixmap.fromImage(img).scaled(
                self.media.width() - 2, self.media.height() - 2, Qt.KeepAspectRatio,
                Qt.SmoothTransformation))

    def set_busy(self, text: str | None) -> None:
        """`text`: what the printer does at the operator's request (head care), shown with a
        busy bar until it answers; None: done."""
        on = bool(text)
        self.busy.setVisible(on)
        self.busy_text.setVisible(on)
        self.busy_text.setText(text or "")
        self.busy_text.setToolTip(text or "")
        self.info["_busy"] = on
        self.care.setEnabled(not on and not self.info.get("fault") and not self.info.get("current"))

    def _time_left(self, cur: dict, done: int, total: int) -> float | None:
        """Seconds left of the job (this copy's strokes and the copies after it), at the pace
        seen since this card first saw the copy; None until 2 strokes and 2 s are seen."""
        key = (cur.get("id"), cur.get("copy"))
        now = time.monotonic()
        if self._pace is None or self._pace[:2] != key or done < self._pace[3]:
            self._pace = (*key, now, done)
            return None
        _, _, t0, d0 = self._pace
        if not total or done - d0 < 2 or now - t0 < 2:
            return None
        per_stroke = (now - t0) / (done - d0)
        copies_after = max(0, (cur.get("copies") or 1) - (cur.get("copy") or 1))
        return per_stroke * ((total - done) + copies_after * total)

    def _pause_clicked(self) -> None:
        self.action.emit(self.name, "resume" if self.info.get("paused") else "pause", None)

    def show_info(self, p: dict) -> None:
        busy = self.info.get("_busy", False)
        self.info = dict(p, _busy=busy)
        self.title.setText(f"<b>{self.name}</b> <span style='color:#666'>{p.get('device', '')}</span>")
        self.title.setToolTip(f"device {p.get('device')}\nprofile {p.get('profile')}")
        fault = p.get("fault") or ""
        st = p.get("state", "idle")
        cur = p.get("current")
        if fault:
            text = "<span style='color:#c62828'><b>Fault</b></span> — queue stopped"
        elif st == "offline":
            text = f"<span style='color:#b26a00'><b>Offline</b></span> — {short_paths(p.get('error') or '')}"
        elif cur:
            text = "<span style='color:#1565c0'><b>Printing</b></span>"
            if p.get("paused"):
                text += " — pausing after this job"
        elif p.get("paused"):
            text = f"<b>Paused</b> — {p.get('reason') or 'by the operator'}"
        else:
            text = "<span style='color:#2e7d32'><b>Ready</b></span> — waiting for jobs"
        if p.get("capped") and not cur and not fault:
            text += " (heads capped)"
        # the server's warnings (docs/server.md "Rolls: the warning"): nothing stops
        warnings = [w["message"] for w in p.get("warnings") or [] if w.get("message")]
        if warnings:
            text += " · <span style='color:#b26a00'><b>roll low</b></span>"
        self.state.setText(text)
        self.state.setToolTip(p.get("reason") or "")
        if cur:
            job = f"job {cur['id']}: " if cur.get("id") is not None else ""
            copies = f", copy {cur['copy']}/{cur['copies']}" if cur.get("copies", 1) > 1 else ""
            total = cur.get("strokes_total") or 0
            done = cur.get("strokes_printed") or 0
            self.job.setText(f"{job}{cur.get('name', '')}{copies} — {cur.get('state', '')}"
                             + (f", stroke {done}/{total}" if total else ""))
            self.job.setToolTip(self.job.text())
            self.progress.setValue(int(1000 * done / total) if total else 0)
            left = self._time_left(cur, done, total)
            self.progress.setFormat((f"{100 * done / total:.0f} %" if total else "")
                                    + (f" · {fmt_duration(left)} left" if left is not None else ""))
            self.progress.setToolTip("" if left is None else
                                     f"about {fmt_duration(left)} left, from the pace of the strokes "
                                     f"printed so far ({cur.get('copies', 1)} copies in all)")
            t = cur.get("telemetry") or {}
            parts = []
            if t:
                parts.append(f"carriage {t.get('carriage_counts', 0):,}")
                fifo = t.get("fifo_words") or []
                temps = t.get("head_temps_c") or []
                if fifo:
                    parts.append(f"FIFO {min(fifo)}–{max(fifo)} words")
                if temps:
                    parts.append(f"heads {min(temps):.0f}–{max(temps):.0f} °C")
            self.telemetry.setText("; ".join(parts))
            self.telemetry.setToolTip(
                "carriage position (encoder counts); words in each head's FIFO: "
                + " ".join(str(w) for w in t.get("fifo_words") or []) + "; head temperatures: "
                + " ".join(f"{c:.1f}" for c in t.get("head_temps_c") or []))
        else:
            self._pace = None
            self.job.setText("")
            self.progress.setValue(0)
            self.progress.setFormat("")
            self.progress.setToolTip("")
            pm = p.get("printable_mm")
            self.telemetry.setText(("" if pm is None else
                                    f"paper: {pm:,.0f} mm printable"
                                    + ("" if p.get("paper_mm") is not None else " (profile's sheet)"))
                                   + roll_text(p.get("roll")))
            self.telemetry.setToolTip("the paper's width less the side margins; measured by "
                                      "the printer at its last job")
        # the fault's place shows a warning, in amber, while there is no fault
        colour = "#c62828" if fault or not warnings else "#b26a00"
        if self.fault.property("colour") != colour:
            self.fault.setStyleSheet(f"color: {colour};")
            self.fault.setProperty("colour", colour)
        if fault:
            advice = plain_message(fault)
            self.fault.setText(short_paths(fault) + (f" {advice}" if advice else ""))
            self.fault.setToolTip("\n".join([fault] + warnings))
        elif warnings:
            self.fault.setText("Warning: " + " ".join(warnings))
            self.fault.setToolTip("\n".join(warnings))
        else:
            self.fault.setText("")
            self.fault.setToolTip("")
        self.pause.setText("Resume" if p.get("paused") else "Pause")
        self.pause.setEnabled(not fault)
        self.clear.setEnabled(bool(fault))
        self.tests.setEnabled(not fault and not cur)
        self.care.setEnabled(not fault and not cur and not busy)
        self.roll.setEnabled(not cur)


class PrintersPanel(QScrollArea):
    """The printer cards, side by side (scrolling when there are more than fit)."""
    action = Signal(str, str, object)

    def __init__(self, parent=None):
        super().__init__(parent)
        self.setObjectName("printers_panel")
        self.setWidgetResizable(True)
        self.setFrameShape(QFrame.NoFrame)
        self.inner = QWidget()
        self.row = QHBoxLayout(self.inner)
        self.row.setContentsMargins(2, 2, 2, 2)
        self.setWidget(self.inner)
        self.cards: dict[str, PrinterCard] = {}
        self.setVerticalScrollBarPolicy(Qt.ScrollBarAlwaysOff)

    def show_printers(self, printers: list[dict]) -> None:
        names = [p["name"] for p in printers]
        for name in list(self.cards):
            if name not in names:
                self.cards.pop(name).deleteLater()
        for i, p in enumerate(printers):
            card = self.cards.get(p["name"])
            if card is None:
                card = PrinterCard(p["name"])
                card.action.connect(self.action)
                self.cards[p["name"]] = card
                self.row.insertWidget(i, card, 1)
            card.show_info(p)
        h = max((c.sizeHint().height() for c in self.cards.values()), default=0)
        self.setFixedHeight(h + 8)


__all__ = ["PrinterCard", "PrintersPanel"]
