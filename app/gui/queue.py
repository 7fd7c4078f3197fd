"""The job queue: items, the table model (rows reorder by the buttons or by dragging), the
table view, and the progress-bar delegate."""

from __future__ import annotations

import itertools
import json
import os
from dataclasses import dataclass, field
from pathlib import Path

from PySide6.QtCore import QAbstractTableModel, QByteArray, QMimeData, QModelIndex, QPoint, QRect, Qt, Signal
from PySide6.QtGui import QBrush, QColor, QDrag, QFontMetrics, QPainter, QPalette, QPen, QPixmap
from PySide6.QtWidgets import (QAbstractItemView, QApplication, QStyle, QStyledItemDelegate,
                               QStyleOptionProgressBar, QTableView)

from ..estimate import Estimate, fmt_duration
from .jobsettings import JobSettings
from .messages import short_paths

IMAGE_SUFFIXES = (".tif", ".tiff", ".bmp", ".dib", ".jpg", ".jpeg", ".jpe", ".png")

# item states
LOADING, READY, ERROR = "loading", "ready", "error"
WAITING, PRINTING, PAUSED = "waiting", "printing", "paused"
DONE, FAILED, CANCELLED = "done", "failed", "cancelled"
ACTIVE = (WAITING, PRINTING, PAUSED)
FIXED = (PRINTING, PAUSED)        # the job at the printer stays where it is (buttons and drags)
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
    detail: str = ""                  # driver state detail ("homing", "before stroke 3")
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


def movable(item: QueueItem) -> bool:
    """Whether a job may change its place in the queue: not while the printer works on it."""
    return item.state not in FIXED


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
    """The queue, top to bottom = print order.  Rows move with move() (the buttons) or
    move_items() (drag and drop: dropMimeData, and Qt's moveRows); a job being printed or
    paused (FIXED) never moves."""
    COLUMNS = ("#", "File", "State", "Progress", "Size", "Time", "Copies", "Settings", "Message")
    COL_FILE, COL_STATE, COL_PROGRESS, COL_SIZE, COL_MESSAGE = 1, 2, 3, 4, 8
    MIME_TYPE = "application/x-wideprint-queue-items"
    itemChanged = Signal(int)        # item id

    def __init__(self, parent=None):
        super().__init__(parent)
        self.items: list[QueueItem] = []
        self._token = f"{os.getpid()}:{id(self)}"      # drags from this model only

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
            return Qt.ItemIsDropEnabled                 # drops go between rows, never onto one
        f = Qt.ItemIsEnabled | Qt.ItemIsSelectable
        if movable(self.items[index.row()]):
            f |= Qt.ItemIsDragEnabled
        return f

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

    # -- drag and drop: moving rows ------------------------------------------------------
    def supportedDropActions(self):
        return Qt.MoveAction

    def supportedDragActions(self):
        return Qt.MoveAction

    def mimeTypes(self) -> list[str]:
        return [self.MIME_TYPE]

    def mimeData(self, indexes) -> QMimeData | None:
        """The movable jobs among these rows (top to bottom), by id."""
        rows = sorted({i.row() for i in indexes if i.isValid()})
        ids = [self.items[r].id for r in rows if movable(self.items[r])]
        if not ids:
            return None
        md = QMimeData()
        md.setData(self.MIME_TYPE, QByteArray(json.dumps({"model": self._token, "ids": ids}).encode()))
        return md

    def _dragged_ids(self, data) -> list[int] | None:
        if data is None or not data.hasFormat(self.MIME_TYPE):
            return None
        try:
            d = json.loads(bytes(data.data(self.MIME_TYPE)).decode())
        except ValueError:
            return None
        if d.get("model") != self._token:
            return None
        return [int(i) for i in d.get("ids", [])]

    def canDropMimeData(self, data, action, row, column, parent) -> bool:
        ids = self._dragged_ids(data)
        if not ids or parent.isValid() or action != Qt.MoveAction:
            return False
        items = [self.item(i) for i in ids]
        return all(it is not None and movable(it) for it in items)

    def dropMimeData(self, data, action, row, column, parent) -> bool:
        """A drop between rows: the dragged jobs move to before `row` (-1: the end)."""
        if not self.canDropMimeData(data, action, row, column, parent):
            return False
        return self.move_items(self._dragged_ids(data), len(self.items) if row < 0 else row)

    def moveRows(self, sourceParent, sourceRow, count, destinationParent, destinationChild) -> bool:
        if sourceParent.isValid() or destinationParent.isValid() or count < 1 or \
                not (0 <= sourceRow and sourceRow + count <= len(self.items)):
            return False
        return self.move_items([it.id for it in self.items[sourceRow:sourceRow + count]], destinationChild)

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
        """Move one row to position `to` (0..n-1) (Move up / Move down)."""
        n = len(self.items)
        if not (0 <= row < n and 0 <= to < n) or row == to or not movable(self.items[row]):
            return False
        return self._move_row(row, to + 1 if to > row else to)

    def move_items(self, ids, dest: int) -> bool:
        """Move these jobs (any rows) together, in their queue order, to before row `dest`
        (0..n, in the rows as they are now): what a drop between two rows does.  Refused
        (False) if one of them is being printed, or if nothing would change."""
        n = len(self.items)
        rows = sorted({self.row_of(i) for i in ids})
        if not rows or rows[0] < 0 or not 0 <= dest <= n or \
                not all(movable(self.items[r]) for r in rows):
            return False
        picked = set(rows)
        order = [r for r in range(dest) if r not in picked] + rows + \
            [r for r in range(dest, n) if r not in picked]
        if order == list(range(n)):
            return False
        # one row at a time (only the moved ones), so selections and persistent indexes
        # follow: those above dest from the bottom up, then those below from the top down
        ins = dest
        for r in reversed([r for r in rows if r < dest]):
            self._move_row(r, ins)
            ins -= 1
        ins = dest
        for r in [r for r in rows if r >= dest]:
            self._move_row(r, ins)
            ins += 1
        return True

    def _move_row(self, row: int, dest: int) -> bool:
        """Qt's move: row goes before row `dest` of the current rows."""
        if dest in (row, row + 1):
            return False
        if not self.beginMoveRows(QModelIndex(), row, row, QModelIndex(), dest):
            return False
        self.items.insert(dest - 1 if dest > row else dest, self.items.pop(row))
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


class QueueView(QTableView):
    """The queue table: rows are dragged to a new place (the selected jobs together; a job
    being printed stays put).  Drops land between rows, shown by a line across the table.
    Other drags (image files) are left to the window, which adds them to the queue."""

    def __init__(self, parent=None):
        super().__init__(parent)
        self.setSelectionBehavior(QAbstractItemView.SelectRows)
        self.setSelectionMode(QAbstractItemView.ExtendedSelection)
        self.setDragDropMode(QAbstractItemView.DragDrop)
        self.setDragEnabled(True)
        self.setAcceptDrops(True)
        self.viewport().setAcceptDrops(True)
        self.setDefaultDropAction(Qt.MoveAction)
        self.setDragDropOverwriteMode(False)
        self.setDropIndicatorShown(False)            # drawn across the whole row instead
        self.drop_row: int | None = None

    def drop_row_at(self, pos: QPoint) -> int:
        """The row a drop at this viewport point goes before (rowCount: the end)."""
        n = self.model().rowCount()
        row = self.rowAt(pos.y())
        if row < 0:                      # below the last row
            return n
        return row + (1 if pos.y() >= self.rowViewportPosition(row) + self.rowHeight(row) / 2 else 0)

    def drag_mime(self) -> QMimeData | None:
        """What dragging the selection carries: its movable jobs."""
        m = self.model()
        rows = sorted({i.row() for i in self.selectionModel().selectedRows()})
        idx = [m.index(r, 0) for r in rows if m.flags(m.index(r, 0)) & Qt.ItemIsDragEnabled]
        return m.mimeData(idx) if idx else None

    def startDrag(self, supported_actions) -> None:
        mime = self.drag_mime()
        if mime is None:
            return
        m = self.model()
        ids = m._dragged_ids(mime)
        drag = QDrag(self)
        drag.setMimeData(mime)
        drag.setPixmap(self._drag_pixmap(len(ids), m.item(ids[0]).name))
        # the model moves the rows itself when they are dropped (QAbstractItemView's own
        # startDrag would then remove the "moved" rows from the source)
        drag.exec(Qt.MoveAction, Qt.MoveAction)

    def _drag_pixmap(self, n: int, first: str) -> QPixmap:
        text = first if n == 1 else f"{first} + {n - 1} more"
        fm = QFontMetrics(self.font())
        w, h = min(360, fm.horizontalAdvance(text) + 16), fm.height() + 10
        dpr = self.devicePixelRatioF()
        pm = QPixmap(int(w * dpr), int(h * dpr))
        pm.setDevicePixelRatio(dpr)
        pm.fill(Qt.transparent)
        p = QPainter(pm)
        p.setRenderHint(QPainter.Antialiasing)
        pal = self.palette()
        p.setBrush(pal.color(QPalette.Highlight))
        p.setPen(Qt.NoPen)
        p.drawRoundedRect(QRect(0, 0, w, h), 4, 4)
        p.setPen(pal.color(QPalette.HighlightedText))
        p.drawText(QRect(8, 0, w - 16, h), Qt.AlignVCenter | Qt.AlignLeft,
                   fm.elidedText(text, Qt.ElideMiddle, w - 16))
        p.end()
        return pm

    # -- being dropped on ---------------------------------------------------------------
    def _ours(self, ev) -> bool:
        return ev.mimeData() is not None and ev.mimeData().hasFormat(QueueModel.MIME_TYPE)

    def _track(self, ev) -> None:
        row = self.drop_row_at(ev.position().toPoint())
        if self.model().canDropMimeData(ev.mimeData(), Qt.MoveAction, row, 0, QModelIndex()):
            ev.setDropAction(Qt.MoveAction)
            ev.accept()
            self.drop_row = row
        else:
            ev.ignore()
            self.drop_row = None
        self.viewport().update()

    def dragEnterEvent(self, ev) -> None:
        if not self._ours(ev):
            ev.ignore()                  # files: the main window adds them
            return
        super().dragEnterEvent(ev)
        self._track(ev)

    def dragMoveEvent(self, ev) -> None:
        if not self._ours(ev):
            ev.ignore()
            return
        super().dragMoveEvent(ev)        # auto-scroll near the edges
        self._track(ev)

    def dragLeaveEvent(self, ev) -> None:
        super().dragLeaveEvent(ev)
        self.drop_row = None
        self.viewport().update()

    def dropEvent(self, ev) -> None:
        self.drop_row = None
        self.viewport().update()
        if not self._ours(ev):
            ev.ignore()
            return
        row = self.drop_row_at(ev.position().toPoint())
        if self.model().dropMimeData(ev.mimeData(), Qt.MoveAction, row, 0, QModelIndex()):
            ev.setDropAction(Qt.MoveAction)
            ev.accept()
        else:
            ev.ignore()
        self.stopAutoScroll()
        self.setState(QAbstractItemView.NoState)

    def paintEvent(self, ev) -> None:
        super().paintEvent(ev)
        if self.drop_row is None:
            return
        n = self.model().rowCount()
        if n == 0:
            return
        y = self.rowViewportPosition(self.drop_row) if self.drop_row < n else \
            self.rowViewportPosition(n - 1) + self.rowHeight(n - 1)
        p = QPainter(self.viewport())
        p.setPen(QPen(self.palette().color(QPalette.Highlight), 2))
        y = max(1, min(y, self.viewport().height() - 1))
        p.drawLine(0, y, self.viewport().width(), y)
        p.end()


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


__all__ = ["QueueItem", "QueueModel", "QueueView", "ProgressDelegate", "expand_paths", "is_image_file",
           "movable"]
