"""The live media view: what has landed on the emulated paper, filling in stroke by stroke.

The printer thread paints media rows into a LiveSink canvas (workers.py) before they
leave the emulator's media window; a 200 ms QTimer on the UI thread also asks for the
rows of the stroke in progress (Media.snapshot) and repaints from the canvas.
"""

from __future__ import annotations

from PySide6.QtCore import QRectF, Qt
from PySide6.QtGui import QColor, QImage, QPainter, QPen
from PySide6.QtWidgets import QLabel, QSizePolicy, QVBoxLayout, QWidget

from .messages import short_paths

from .preview import qimage_from_rgb


class _Canvas(QWidget):
    def __init__(self, parent=None):
        super().__init__(parent)
        self.image: QImage | None = None
        self.mm = (1.0, 1.0)          # physical size of the job
        self.rows_done = 0.0          # fraction of the job's rows written out
        self.setMinimumSize(200, 150)

    def paintEvent(self, ev):
        p = QPainter(self)
        p.fillRect(self.rect(), QColor("#8a8f96"))
        if self.image is None:
            p.setPen(QColor("#eee"))
            p.drawText(self.rect(), Qt.AlignCenter, "The live view shows the emulator's media while a job prints")
            p.end()
            return
        w_mm, h_mm = self.mm
        margin = 12
        avail_w, avail_h = self.width() - 2 * margin, self.height() - 2 * margin
        s = min(avail_w / w_mm, avail_h / h_mm) if h_mm * avail_w / w_mm <= avail_h * 4 else avail_w / w_mm
        dw, dh = w_mm * s, h_mm * s
        x = (self.width() - dw) / 2
        # a long banner: keep the rows being printed in sight
        y0 = margin
        if dh > avail_h:
            focus = self.rows_done * dh
            y0 = margin - min(max(0.0, focus - 0.6 * avail_h), dh - avail_h)
        target = QRectF(x, y0, dw, dh)
        p.fillRect(target.adjusted(-4, -4, 4, 4), QColor("#fdfdfb"))
        p.setRenderHint(QPainter.SmoothPixmapTransform, s * w_mm / max(1, self.image.width()) < 1)
        p.drawImage(target, self.image)
        p.setPen(QPen(QColor("#1565c0"), 1))
        p.drawRect(target)
        if 0 < self.rows_done < 1:
            yy = y0 + self.rows_done * dh
            p.setPen(QPen(QColor("#e53935"), 2))
            p.drawLine(int(x) - 8, int(yy), int(x + dw) + 8, int(yy))
        p.end()


class LiveView(QWidget):
    def __init__(self, parent=None):
        super().__init__(parent)
        self.setObjectName("live_view")
        self.label = QLabel("No job printing")
        self.label.setObjectName("live_label")
        self.label.setSizePolicy(QSizePolicy.Ignored, QSizePolicy.Preferred)
        self.canvas = _Canvas()
        lay = QVBoxLayout(self)
        lay.setContentsMargins(4, 4, 4, 4)
        lay.addWidget(self.label)
        lay.addWidget(self.canvas, 1)
        self.sink = None
        self._version = -1
        self.title = ""

    def start(self, sink, width_mm: float, height_mm: float, title: str) -> None:
        self.sink = sink
        self._version = -1
        self.title = title
        self.canvas.mm = (max(width_mm, 1e-3), max(height_mm, 1e-3))
        self.canvas.rows_done = 0.0
        self.label.setText(title)
        self.refresh()

    def refresh(self, status: str = "") -> bool:
        """Repaint from the sink if it changed; returns True when it did."""
        sink = self.sink
        if sink is None:
            return False
        if status:
            self.label.setText(f"{self.title} — {status}")
        if sink.version == self._version:
            return False
        rgb, self._version = sink.image()
        self.canvas.image = qimage_from_rgb(rgb)
        self.canvas.rows_done = sink.rows_done / max(1, sink.height)
        self.canvas.update()
        return True

    def finish(self, status: str) -> None:
        self.refresh()
        self.canvas.rows_done = 1.0
        self.label.setText(f"{self.title} — {short_paths(status)}")
        self.label.setToolTip(status)
        self.canvas.update()

    def canvas_array(self):
        """The current canvas (tests): (h, w, 3) uint8 or None."""
        return None if self.sink is None else self.sink.image()[0]
