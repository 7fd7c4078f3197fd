"""The job queue: items, the table model, and the progress-bar delegate."""

from __future__ import annotations

import itertools
import os
from dataclasses import dataclass, field
from pathlib import Path

from PySide6.QtCore import QAbstractTableModel, QModelIndex, Qt, Signal
from PySide6.QtGui import QBrush, QColor
from PySide6.QtWidgets import QApplication, QStyle, QStyledItemDelegate, QStyleOptionProgressBar

from .estimate import Estimate, fmt_duration
from .jobsettings import JobSettings
from .messages import short_paths

IMAGE_SUFFIXES = (".tif", ".tiff", ".bmp", ".dib", ".jpg", ".jpeg", ".jpe", ".png")

# item states
LOADING, READY, ERROR = "loading", "ready", "error"
WAITING, PRINTING, PAUSED = "waiting", "printing", "paused"
DONE, FAILED, CANCELLED = "done", "failed", "cancelled"
ACTIVE = (WAITING, PRINTING, PAUSED)
PRINTABLE = (READY, ERROR, FAILED, CANCELLED, LOADING)   # what "Print" picks up (not DONE)

STATE_LABELS = {
    LOADING: "Reading…", READY: "Ready", ERROR: "Error", WAITING: "Waiting",
    PRINTING: "Printing", PAUSED: "Paused", DONE: "Done", FAILED: "Failed",
    CANCELLED: "Cancelled",
}
STATE_COLORS = {
    ERROR: "#c62828", FAILED: "#c62828", DONE: "#2e7d32", PRINTING: "#1565c0",
    PAUSED: "#ef6c00", CANCELLED: "#6d4c41", WAITING: "#1565c0",
}

_ids = itertools.count(1)


@dataclass
class QueueItem:
    path: str
    settings: JobSettings
    id: int = field(default_factory=lambda: next(_ids))
    state: str = LOADING
    detail: str = ""                  # driver state detail ("homing", "before pass 3")
    message: str = ""                 # error / failure text, shown in the row
    progress: float = 0.0             # 0..1 over all copies
    estimate: Estimate | None = None
    source_desc: str = ""
    media: list = field(default_factory=list)       # media files written (emulator)
    reports: list = field(default_factory=list)     # driver JobReports (dicts)
    preview_key: tuple | None = None

    @property
    def name(self) -> str:
        return os.path.basename(self.path)


def is_image_file(path: str) -> bool:
    return Path(path).suffix.lower() in IMAGE_SUFFIXES


def expand_paths(paths) -> list[str]:
    """Files as given; folders give their image files (sorted, no hidden ones)."""
    out = []
    for p in paths:
        p = Path(p)
        if p.is_dir():
            out += sorted(str(c) for c in p.iterdir()
                          if c.is_file() and not c.name.startswith(".") and is_image_file(str(c)))
        else:
            out.append(str(p))
    return out


class QueueModel(QAbstractTableModel):
    COLUMNS = ("#", "File", "State", "Progress", "Size", "Time", "Copies", "Settings", "Message")
    COL_FILE, COL_STATE, COL_PROGRESS, COL_SIZE, COL_MESSAGE = 1, 2, 3, 4, 8
    itemChanged = Signal(int)        # item id

    def __init__(self, parent=None):
        super().__init__(parent)
        self.items: list[QueueItem] = []

    # -- Qt model API ------------------------------------------------------------------
    def rowCount(self, parent=QModelIndex()) -> int:
        return 0 if parent.isValid() else len(self.items)

    def columnCount(self, parent=QModelIndex()) -> int:
        return 0 if parent.isValid() else len(self.COLUMNS)

    def headerData(self, section, orientation, role=Qt.DisplayRole):
        if orientation == Qt.Horizontal and role == Qt.DisplayRole:
            return self.COLUMNS[section]
        return None

    def flags(self, index):
        if not index.isValid():
            return Qt.ItemIsDropEnabled
        return Qt.ItemIsEnabled | Qt.ItemIsSelectable

    def data(self, index, role=Qt.DisplayRole):
        if not index.isValid():
            return None
        it = self.items[index.row()]
        col = index.column()
        if role == Qt.DisplayRole:
            if col == 0:
                return str(index.row() + 1)
            if col == 1:
                return it.name
            if col == 2:
                label = STATE_LABELS.get(it.state, it.state)
                return f"{label} ({it.detail})" if it.detail and it.state in (PRINTING, PAUSED) else label
            if col == 3:
                return f"{it.progress * 100:.0f} %"
            if col == 4:
                e = it.estimate
                return f"{e.width_mm:,.0f} × {e.height_mm:,.0f} mm" if e else ""
            if col == 5:
                return fmt_duration(it.estimate.time_s) if it.estimate else ""
            if col == 6:
                return str(it.settings.copies)
            if col == 7:
                return it.settings.summary()
            if col == 8:
                return short_paths(it.message)
        if role == Qt.UserRole:
            return it.progress if col == self.COL_PROGRESS else None
        if role == Qt.ToolTipRole:
            tip = [it.path]
            if it.source_desc:
                tip.append(it.source_desc)
            if it.message:
                tip.append(it.message)
            return "\n".join(tip)
        if role == Qt.ForegroundRole and col in (2, 8) and it.state in STATE_COLORS:
            return QBrush(QColor(STATE_COLORS[it.state]))
        if role == Qt.TextAlignmentRole and col in (0, 5, 6):
            return int(Qt.AlignRight | Qt.AlignVCenter)
        return None

    def supportedDropActions(self):
        return Qt.CopyAction | Qt.MoveAction

    # -- items -------------------------------------------------------------------------
    def row_of(self, item_id: int) -> int:
        for i, it in enumerate(self.items):
            if it.id == item_id:
                return i
        return -1

    def item(self, item_id: int) -> QueueItem | None:
        r = self.row_of(item_id)
        return self.items[r] if r >= 0 else None

    def add(self, item: QueueItem, row: int | None = None) -> None:
        row = len(self.items) if row is None else max(0, min(row, len(self.items)))
        self.beginInsertRows(QModelIndex(), row, row)
        self.items.insert(row, item)
        self.endInsertRows()

    def remove_rows(self, rows: list[int]) -> list[QueueItem]:
        removed = []
        for r in sorted(set(rows), reverse=True):
            if 0 <= r < len(self.items):
                self.beginRemoveRows(QModelIndex(), r, r)
                removed.append(self.items.pop(r))
                self.endRemoveRows()
        return removed

    def move(self, row: int, to: int) -> bool:
        """Move one row to position `to` (0..n-1)."""
        n = len(self.items)
        if not (0 <= row < n and 0 <= to < n) or row == to:
            return False
        dest = to + 1 if to > row else to            # Qt's destinationChild convention
        if not self.beginMoveRows(QModelIndex(), row, row, QModelIndex(), dest):
            return False
        self.items.insert(to, self.items.pop(row))
        self.endMoveRows()
        return True

    def changed(self, item_id: int) -> None:
        r = self.row_of(item_id)
        if r >= 0:
            self.dataChanged.emit(self.index(r, 0), self.index(r, len(self.COLUMNS) - 1))
            self.itemChanged.emit(item_id)

    def next_printable(self, after_row: int = -1) -> QueueItem | None:
        for it in self.items[after_row + 1:]:
            if it.state in (WAITING,):
                return it
        return None


class ProgressDelegate(QStyledItemDelegate):
    """Paints the progress column as a progress bar."""

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
        opt.state = option.state | QStyle.State_Enabled
        style = option.widget.style() if option.widget else QApplication.style()
        style.drawControl(QStyle.CE_ProgressBar, opt, painter)


__all__ = ["QueueItem", "QueueModel", "ProgressDelegate", "expand_paths", "is_image_file"]
