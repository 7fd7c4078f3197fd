"""The server's jobs in the GUI (docs/gui.md, "Queue and history"): the queue (queued,
held and printing jobs, in the order the printers take them) and the history (done, failed
and cancelled, newest first), each row with its thumbnail.  The rows are the server's job
objects as the API gives them; nothing here is a second queue."""

from __future__ import annotations

import time

from PySide6.QtCore import QAbstractTableModel, QModelIndex, QSize, Qt
from PySide6.QtGui import QColor, QImage, QPixmap
from PySide6.QtWidgets import (QAbstractItemView, QApplication, QHeaderView, QStyle,
                               QStyledItemDelegate, QStyleOptionProgressBar, QTableView)

from ..estimate import fmt_duration
from ..safe_text import safe

THUMB = 48                    # thumbnail cell, pixels
STATE_COLORS = {"failed": "#c62828", "cancelled": "#6d6d6d", "held": "#b26a00",
                "printing": "#1565c0", "done": "#2e7d32"}


def state_text(job: dict) -> str:
    st = job["state"]
    if job.get("nested_in") and st not in ("done", "failed", "cancelled"):
        return f"nested on job {job['nested_in']}"
    if st == "held" and job.get("fault"):
        return "stopped: printer fault"
    if st == "held" and "held before printing" in (job.get("message") or ""):
        return "held: roll too short"          # the worker's roll check (docs/server.md "Rolls")
    if st == "held" and job.get("rip_hold"):   # RIP and hold (docs/server.md)
        ripped = job.get("ripped") or {}
        if ripped.get("error"):
            return "held (RIP failed)"
        return "held, ripped" if ripped.get("ready") else "held, ripping"
    if st == "queued" and job.get("interrupted"):
        return "queued, part-way"
    if st == "printing" and job.get("copies", 1) > 1:
        return f"printing {min(job['copies_done'] + 1, job['copies'])}/{job['copies']}"
    return st


def progress_of(job: dict) -> float | None:
    if job["state"] == "done":
        return 1.0
    total = job.get("strokes_total") or 0
    copies = max(1, job.get("copies") or 1)
    if not total and not job.get("copies_done"):
        return None if job["state"] != "printing" else 0.0
    per = (job.get("strokes_done") or 0) / total if total else 0.0
    return min(1.0, (job.get("copies_done", 0) + per) / copies)


def _when(t) -> str:
    if not t:
        return ""
    # today: the time; before: the date (the tooltip has both)
    return time.strftime("%H:%M:%S" if time.time() - t < 86400 else "%d %b", time.localtime(t))


class JobsModel(QAbstractTableModel):
    """Rows: job dicts (the API's); `history` picks the history's columns."""
    QUEUE = ("", "Job", "Printer", "State", "Progress", "Copies", "Prio", "Submitted")
    HISTORY = ("", "Job", "Printer", "Outcome", "Ended", "Took", "Copies", "Message")

    def __init__(self, history: bool = False, parent=None):
        super().__init__(parent)
        self.history = history
        self.columns = self.HISTORY if history else self.QUEUE
        self.jobs: list[dict] = []
        self.thumbs: dict[int, QPixmap] = {}

    def rowCount(self, parent=QModelIndex()) -> int:
        return 0 if parent.isValid() else len(self.jobs)

    def columnCount(self, parent=QModelIndex()) -> int:
        return 0 if parent.isValid() else len(self.columns)

    def headerData(self, section, orientation, role=Qt.DisplayRole):
        if orientation == Qt.Horizontal and role == Qt.DisplayRole:
            return self.columns[section]
        return None

    def set_jobs(self, jobs: list[dict]) -> None:
        """Replace the rows, keeping rows that stay (selection and scroll stay put)."""
        old = [j["id"] for j in self.jobs]
        new = [j["id"] for j in jobs]
        if old == new:
            self.jobs = list(jobs)
            if jobs:
                self.dataChanged.emit(self.index(0, 0), self.index(len(jobs) - 1, len(self.columns) - 1))
            return
        self.beginResetModel()
        self.jobs = list(jobs)
        self.endResetModel()

    def job_at(self, row: int) -> dict | None:
        return self.jobs[row] if 0 <= row < len(self.jobs) else None

    def row_of(self, job_id: int) -> int:
        for i, j in enumerate(self.jobs):
            if j["id"] == job_id:
                return i
        return -1

    def set_thumb(self, job_id: int, png: bytes) -> None:
        img = QImage.fromData(png, "PNG")
        if img.isNull():
            return
        self.thumbs[job_id] = QPixmap.fromImage(img.scaled(THUMB, THUMB, Qt.KeepAspectRatio,
                                                           Qt.SmoothTransformation))
        r = self.row_of(job_id)
        if r >= 0:
            self.dataChanged.emit(self.index(r, 0), self.index(r, 0))

    def data(self, index, role=Qt.DisplayRole):
        if not index.isValid():
            return None
        j = self.jobs[index.row()]
        col = self.columns[index.column()]
        if role == Qt.DecorationRole and col == "":
            return self.thumbs.get(j["id"])
        if role == Qt.UserRole and col == "Progress":
            return progress_of(j)
        if role == Qt.ForegroundRole and col in ("State", "Outcome"):
            c = STATE_COLORS.get(j["state"])
            return QColor(c) if c else None
        if role == Qt.ToolTipRole:
            if col in ("Job", ""):
                return f"job {j['id']}: {safe(j['name'])} ({safe(j['source'])}, {j['size']:,} bytes)"
            if col in ("State", "Outcome", "Message"):
                return safe(j.get("fault") or j.get("message") or "", keep="\n") or None
            return None
        if role == Qt.TextAlignmentRole and col in ("Copies", "Prio"):
            return int(Qt.AlignCenter)
        if role != Qt.DisplayRole:
            return None
        if col == "Job":
            return f"{j['id']}  {safe(j['name'])}"
        if col == "Printer":
            return j.get("printed_on") or j.get("printer") or "any"
        if col in ("State", "Outcome"):
            return state_text(j)
        if col == "Copies":
            return f"{j['copies_done']}/{j['copies']}" if self.history or j["copies_done"] else str(j["copies"])
        if col == "Prio":
            return str(j["priority"])
        if col == "Submitted":
            return _when(j["submitted"])
        if col == "Ended":
            return _when(j.get("finished"))
        if col == "Took":
            s, f = j.get("started"), j.get("finished")
            return fmt_duration(f - s) if s and f else ""
        if col == "Message":
            return j.get("message") or ""
        return None


class ProgressDelegate(QStyledItemDelegate):
    """The progress column as a progress bar."""

    def paint(self, painter, option, index):
        value = index.data(Qt.UserRole)
        if value is None:
            return super().paint(painter, option, index)
        opt = QStyleOptionProgressBar()
        opt.rect = option.rect.adjusted(2, 3, -2, -3)
        opt.minimum, opt.maximum = 0, 1000
        opt.progress = int(round(float(value) * 1000))
        opt.text = f"{float(value) * 100:.0f} %"
        opt.textVisible = True
        # State_Horizontal: without it Qt 6 draws a vertical bar (filling bottom-up)
        opt.state = option.state | QStyle.State_Enabled | QStyle.State_Horizontal
        style = option.widget.style() if option.widget else QApplication.style()
        style.drawControl(QStyle.CE_ProgressBar, opt, painter)


class JobsView(QTableView):
    def __init__(self, model: JobsModel, parent=None):
        super().__init__(parent)
        self.setModel(model)
        self.setSelectionBehavior(QAbstractItemView.SelectRows)
        self.setSelectionMode(QAbstractItemView.ExtendedSelection)
        self.setEditTriggers(QAbstractItemView.NoEditTriggers)
        self.setIconSize(QSize(THUMB, THUMB))
        self.verticalHeader().setDefaultSectionSize(THUMB + 6)
        self.verticalHeader().hide()
        self.setAlternatingRowColors(True)
        self.setWordWrap(False)
        h = self.horizontalHeader()
        h.setStretchLastSection(False)
        fm = self.fontMetrics()
        for i, name in enumerate(model.columns):
            if name == "":
                h.setSectionResizeMode(i, QHeaderView.Fixed)
                self.setColumnWidth(i, THUMB + 8)
            elif name in ("Job", "Message"):
                h.setSectionResizeMode(i, QHeaderView.Stretch)
                h.setMinimumSectionSize(fm.horizontalAdvance("Copies") + 16)
            else:
                h.setSectionResizeMode(i, QHeaderView.Interactive)
                sample = {"State": "printing 2/9", "Outcome": "cancelled",
                          "Progress": "100 %", "Submitted": "00:00:00",
                          "Ended": "00:00:00", "Printer": "main",
                          "Took": "0:00:00", "Copies": "00", "Prio": "0"}.get(name, name)
                hfm = h.fontMetrics()
                self.setColumnWidth(i, max(fm.horizontalAdvance(sample) + 16,
                                           hfm.horizontalAdvance(name) + 24))
        if "Progress" in model.columns:
            self.setItemDelegateForColumn(model.columns.index("Progress"), ProgressDelegate(self))

    def selected_ids(self) -> list[int]:
        m = self.model()
        rows = sorted({i.row() for i in self.selectionModel().selectedRows()})
        return [m.jobs[r]["id"] for r in rows if r < len(m.jobs)]

    def select_ids(self, ids) -> None:
        from PySide6.QtCore import QItemSelection, QItemSelectionModel
        m = self.model()
        sel = QItemSelection()
        for job_id in ids:
            r = m.row_of(job_id)
            if r >= 0:
                sel.select(m.index(r, 0), m.index(r, m.columnCount() - 1))
        self.selectionModel().select(sel, QItemSelectionModel.ClearAndSelect)
