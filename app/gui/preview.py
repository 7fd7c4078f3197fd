"""The preview: the placed image on the media, in millimetres, with rulers, zoom and
per-separation toggles.  The picture itself is computed off the UI thread (render.py)."""

from __future__ import annotations

import math

import numpy as np
from PySide6.QtCore import QPoint, QPointF, QRectF, Qt, Signal
from PySide6.QtGui import QBrush, QColor, QFont, QImage, QPainter, QPainterPath, QPen, QPixmap
from PySide6.QtWidgets import (QAbstractItemView, QCheckBox, QGraphicsPathItem, QGraphicsPixmapItem,
                               QGraphicsRectItem, QGraphicsScene,
                               QGraphicsView, QGridLayout, QHBoxLayout, QHeaderView,
                               QLabel, QSizePolicy, QTableWidget, QTableWidgetItem, QToolButton,
                               QVBoxLayout, QWidget)

INK_COLORS = {"C": "#00aeef", "M": "#ec008c", "Y": "#e6d200", "K": "#231f20"}
CUT_COLOR = "#ff3d00"   # cut lines (docs/cut.md): an orange red no ink prints, never a CMYK colour
RULER = 22          # ruler thickness, px


def qimage_from_rgb(rgb: np.ndarray) -> QImage:
    rgb = np.ascontiguousarray(rgb)
    h, w = rgb.shape[:2]
    return QImage(rgb.data, w, h, 3 * w, QImage.Format_RGB888).copy()


# -- a job's spot colours (docs/spot.md "The job's report", docs/gui.md "Spot colours") ----------
#: how each spot printed, as the operator reads it
SPOT_RESOLVED = {"recipe": "saved recipe", "library": "library: through the media profile",
                 "alternate": "alternate: the document's own", "cut": "cut line: not printed"}
# CIELAB D50 -> sRGB (D65): XYZ of the D50 white, Bradford D50 -> D65, XYZ -> linear sRGB
_D50 = np.array([0.9642, 1.0, 0.8249])
_BRADFORD_D50_D65 = np.array([[0.9555766, -0.0230393, 0.0631636], [-0.0282895, 1.0099416, 0.0210077],
                              [0.0122982, -0.0204830, 1.3299098]])
_XYZ_SRGB = np.array([[3.2404542, -1.5371385, -0.4985314], [-0.9692660, 1.8760108, 0.0415560],
                      [0.0556434, -0.2040259, 1.0572252]])


def lab_to_srgb(lab) -> tuple[int, int, int]:
    """A CIELAB (D50, as the spot libraries keep it) as an 8-bit sRGB swatch, clipped."""
    L, a, b = (float(v) for v in lab)
    fy = (L + 16) / 116
    f = np.array([fy + a / 500, fy, fy - b / 200])
    t = np.where(f ** 3 > 216 / 24389, f ** 3, (116 * f - 16) * 27 / 24389)
    lin = _XYZ_SRGB @ (_BRADFORD_D50_D65 @ (t * _D50))
    lin = np.clip(lin, 0.0, 1.0)
    rgb = np.where(lin <= 0.0031308, 12.92 * lin, 1.055 * lin ** (1 / 2.4) - 0.055)
    return tuple(int(round(v * 255)) for v in rgb)       # type: ignore[return-value]


def spot_swatch(entry: dict) -> QColor | None:
    """The colour a spot's row shows: its library Lab (the brand's colour); a cut line in
    the cut colour; None for a name in no library (its colour is the document's alternate)."""
    if entry.get("resolved") == "cut":
        return QColor(CUT_COLOR)
    if entry.get("lab"):
        return QColor(*lab_to_srgb(entry["lab"]))
    return None


class SpotList(QTableWidget):
    """The selected job's spot colours: swatch, name, how each printed and its ΔE2000 to
    its Lab (the job's record, docs/server.md); hidden when the job has none or is not
    ripped yet."""
    COLUMNS = ("", "Spot colour", "Prints as", "ΔE2000")

    def __init__(self, parent=None):
        super().__init__(0, len(self.COLUMNS), parent)
        self.setObjectName("spot_list")
        self.setHorizontalHeaderLabels(list(self.COLUMNS))
        self.verticalHeader().hide()
        self.setEditTriggers(QAbstractItemView.NoEditTriggers)
        self.setSelectionMode(QAbstractItemView.NoSelection)
        self.setFocusPolicy(Qt.NoFocus)
        head = self.horizontalHeader()
        head.setSectionResizeMode(0, QHeaderView.Fixed)
        self.setColumnWidth(0, 28)
        head.setSectionResizeMode(1, QHeaderView.Stretch)
        head.setSectionResizeMode(2, QHeaderView.ResizeToContents)
        head.setSectionResizeMode(3, QHeaderView.ResizeToContents)
        self.spots: list[dict] = []
        self.hide()

    def set_spots(self, spots) -> None:
        from ..safe_text import safe
        spots = list(spots or [])
        if spots == self.spots:
            return
        self.spots = spots
        self.setRowCount(len(spots))
        for r, e in enumerate(spots):
            sw = QTableWidgetItem("")
            colour = spot_swatch(e)
            if colour is not None:
                sw.setBackground(QBrush(colour))
            else:
                sw.setText("?")
                sw.setTextAlignment(Qt.AlignmentFlag.AlignCenter)
            de = e.get("de2000")
            de_text = "" if de is None else f"{de:.2f}" + ("" if e.get("in_gamut") is not False
                                                          else " (out of gamut)")
            how = SPOT_RESOLVED.get(e.get("resolved"), e.get("resolved") or "")
            tip = [f"{e.get('name')}: {how}"]
            if e.get("cmyk"):
                tip.append("recipe C {:.1f} M {:.1f} Y {:.1f} K {:.1f} %".format(
                    *(100 * v for v in e["cmyk"])))
            if e.get("lab"):
                tip.append("target Lab {:.1f} {:.1f} {:.1f} (D50)".format(*e["lab"]))
            if e.get("library"):
                tip.append(f"library {e['library']}, media {e.get('media') or '-'}")
            for c, text in enumerate(("", safe(e.get("name") or ""), how, de_text)):
                item = sw if c == 0 else QTableWidgetItem(text)
                item.setToolTip("\n".join(tip))
                self.setItem(r, c, item)
        rows = min(len(spots), 5)
        self.setFixedHeight(self.horizontalHeader().height() + 2 * self.frameWidth()
                            + sum(self.rowHeight(i) for i in range(rows)))
        self.setVisible(bool(spots))

    def rows(self) -> list[tuple]:
        """(name, prints as, ΔE text, swatch RGB or None) per row, as shown."""
        out = []
        for r in range(self.rowCount()):
            cells = [self.item(r, c) for c in range(len(self.COLUMNS))]
            texts = [c.text() if c is not None else "" for c in cells]
            sw = cells[0]
            rgb = None
            if sw is not None and texts[0] != "?":
                colour = sw.background().color()
                rgb = (colour.red(), colour.green(), colour.blue())
            out.append((texts[1], texts[2], texts[3], rgb))
        return out


def nice_step(min_mm: float) -> float:
    """The smallest of 1, 2, 5 x 10^n mm that is >= min_mm."""
    if min_mm <= 0:
        return 1.0
    e = 10 ** math.floor(math.log10(min_mm))
    for m in (1, 2, 5, 10):
        if m * e >= min_mm:
            return m * e
    return 10 * e


class MediaView(QGraphicsView):
    """A QGraphicsView of a scene in millimetres; zoom with Ctrl+wheel or the buttons."""
    viewChanged = Signal()
    resized = Signal()
    zoomed = Signal()          # the operator zoomed (not a fit)

    def __init__(self, scene, parent=None):
        super().__init__(scene, parent)
        self.setRenderHint(QPainter.SmoothPixmapTransform, True)
        self.setDragMode(QGraphicsView.ScrollHandDrag)
        self.setTransformationAnchor(QGraphicsView.AnchorUnderMouse)
        self.setBackgroundBrush(QBrush(QColor("#8a8f96")))
        self.horizontalScrollBar().valueChanged.connect(self.viewChanged)
        self.verticalScrollBar().valueChanged.connect(self.viewChanged)

    @property
    def zoom(self) -> float:
        """Screen pixels per millimetre."""
        return self.transform().m11()

    def set_zoom(self, px_per_mm: float, anchor=None) -> None:
        px_per_mm = max(0.02, min(400.0, px_per_mm))
        f = px_per_mm / max(self.zoom, 1e-12)
        if anchor is not None:
            self.setTransformationAnchor(QGraphicsView.AnchorViewCenter)
        self.scale(f, f)
        self.zoomed.emit()
        self.setTransformationAnchor(QGraphicsView.AnchorUnderMouse)
        # dots are crisp when enlarged, smooth when reduced
        self.setRenderHint(QPainter.SmoothPixmapTransform, self.zoom < 4)
        self.viewChanged.emit()

    def wheelEvent(self, ev):
        if ev.modifiers() & Qt.ControlModifier:
            f = 1.25 if ev.angleDelta().y() > 0 else 0.8
            self.set_zoom(self.zoom * f)
            ev.accept()
        else:
            super().wheelEvent(ev)

    def resizeEvent(self, ev):
        super().resizeEvent(ev)
        self.resized.emit()
        self.viewChanged.emit()


class Ruler(QWidget):
    """Millimetre ruler for a MediaView, horizontal (across the media) or vertical."""

    def __init__(self, view: MediaView, horizontal: bool, parent=None):
        super().__init__(parent)
        self.view, self.horizontal = view, horizontal
        if horizontal:
            self.setFixedHeight(RULER)
        else:
            self.setFixedWidth(RULER)
        view.viewChanged.connect(self.update)
        self.marker: float | None = None

    def paintEvent(self, ev):
        p = QPainter(self)
        p.fillRect(self.rect(), QColor("#f3f3f3"))
        p.setPen(QColor("#999"))
        if self.horizontal:
            p.drawLine(0, self.height() - 1, self.width(), self.height() - 1)
        else:
            p.drawLine(self.width() - 1, 0, self.width() - 1, self.height())
        vp = self.view.viewport()
        z = self.view.zoom
        if z <= 0:
            return
        top_left = self.view.mapToScene(0, 0)
        offset = vp.mapToGlobal(QPoint(0, 0)) - self.mapToGlobal(QPoint(0, 0))
        start = top_left.x() if self.horizontal else top_left.y()
        length = (self.width() if self.horizontal else self.height())
        off = offset.x() if self.horizontal else offset.y()
        minor = nice_step(6 / z)
        major = nice_step(70 / z)
        f = QFont(self.font())
        f.setPointSizeF(7.5)
        p.setFont(f)
        first = math.floor((start - off / z) / minor) * minor
        mm = first
        end = start + (length - off) / z
        p.setPen(QColor("#444"))
        while mm <= end:
            pos = off + (mm - start) * z
            is_major = abs(mm / major - round(mm / major)) < 1e-6
            tick = RULER * (0.55 if is_major else 0.25)
            if self.horizontal:
                p.drawLine(int(pos), RULER - int(tick), int(pos), RULER)
                if is_major:
                    p.drawText(int(pos) + 2, 10, f"{mm:g}")
            else:
                p.drawLine(RULER - int(tick), int(pos), RULER, int(pos))
                if is_major:
                    p.save()
                    p.translate(10, int(pos) + 2)
                    p.rotate(90)
                    p.drawText(0, 0, f"{mm:g}")
                    p.restore()
            mm += minor
        p.end()


class PreviewPanel(QWidget):
    """Toolbar (zoom, separations) + rulers + the media view."""
    separationsChanged = Signal(list)

    def __init__(self, parent=None):
        super().__init__(parent)
        self.scene = QGraphicsScene(self)
        self.view = MediaView(self.scene)
        self.view.setObjectName("preview_view")
        self.hruler = Ruler(self.view, True)
        self.vruler = Ruler(self.view, False)
        corner = QLabel("mm")
        corner.setAlignment(Qt.AlignCenter)
        corner.setFixedSize(RULER, RULER)
        corner.setStyleSheet("background:#f3f3f3; color:#444; font-size:7pt;")

        bar = QHBoxLayout()
        bar.setContentsMargins(4, 2, 4, 2)
        self.title = QLabel("No job selected")
        self.title.setObjectName("preview_title")
        self.title.setSizePolicy(QSizePolicy.Ignored, QSizePolicy.Preferred)
        self.title.setStyleSheet("font-weight: bold;")
        bar.addWidget(QLabel("Show:"))
        self.seps = {}
        for name in "CMYK":
            cb = QCheckBox(name)
            cb.setObjectName(f"sep_{name}")
            cb.setChecked(True)
            cb.setToolTip(f"Show the {name} separation")
            cb.setStyleSheet(f"QCheckBox {{ color: {INK_COLORS[name]}; font-weight: bold; }}")
            cb.toggled.connect(self._seps_changed)
            bar.addWidget(cb)
            self.seps[name] = cb
        # the soft proof (docs/color.md): the job as its media prints it, gamut warning on
        self.proof = QCheckBox("Proof")
        self.proof.setObjectName("proof")
        self.proof.setToolTip("Soft proof: the job as its media will print it (its ICC profile "
                              "and ink limit); colours the media cannot print are striped grey")
        bar.addWidget(self.proof)
        bar.addSpacing(12)
        for text, tip, slot in (("−", "Zoom out (Ctrl+wheel)", lambda: self.view.set_zoom(self.view.zoom / 1.5, True)),
                                ("+", "Zoom in (Ctrl+wheel)", lambda: self.view.set_zoom(self.view.zoom * 1.5, True)),
                                ("Fit image", "Zoom to the image", self.fit_image),
                                ("Fit media", "Zoom to the media width", self.fit_media),
                                ("1:1", "Actual size (1 mm = 1 mm on a 96 dpi screen)",
                                 lambda: self.view.set_zoom(self.logicalDpiX() / 25.4, True))):
            b = QToolButton()
            b.setText(text)
            b.setToolTip(tip)
            b.clicked.connect(slot)
            bar.addWidget(b)
        self.zoom_label = QLabel("")
        self.zoom_label.setMinimumWidth(60)
        bar.addWidget(self.zoom_label)
        bar.addStretch(1)
        self.view.viewChanged.connect(self._zoom_text)

        grid = QGridLayout()
        grid.setSpacing(0)
        grid.addWidget(corner, 0, 0)
        grid.addWidget(self.hruler, 0, 1)
        grid.addWidget(self.vruler, 1, 0)
        grid.addWidget(self.view, 1, 1)
        lay = QVBoxLayout(self)
        lay.setContentsMargins(0, 0, 0, 0)
        lay.setSpacing(0)
        trow = QHBoxLayout()
        trow.setContentsMargins(6, 4, 6, 0)
        trow.addWidget(self.title, 1)
        lay.addLayout(trow)
        lay.addLayout(bar)
        lay.addLayout(grid, 1)
        self.spot_list = SpotList()                  # the job's spot colours, under the picture
        lay.addWidget(self.spot_list)

        self.paper_item = QGraphicsRectItem()
        self.paper_item.setBrush(QBrush(QColor("#fdfdfb")))
        self.paper_item.setPen(QPen(Qt.NoPen))
        self.scene.addItem(self.paper_item)
        self.margin_item = QGraphicsRectItem()
        pen = QPen(QColor("#9bb"), 0, Qt.DashLine)
        self.margin_item.setPen(pen)
        self.scene.addItem(self.margin_item)
        self.image_item = QGraphicsPixmapItem()
        self.image_item.setTransformationMode(Qt.FastTransformation)
        self.scene.addItem(self.image_item)
        self.frame_item = QGraphicsRectItem()
        self.frame_item.setPen(QPen(QColor("#1565c0"), 0))
        self.scene.addItem(self.frame_item)
        self.cut_item = QGraphicsPathItem()          # a print-and-cut job's cut lines
        cut_pen = QPen(QColor(CUT_COLOR), 0)         # cosmetic: one screen pixel at any zoom
        self.cut_item.setPen(cut_pen)
        self.scene.addItem(self.cut_item)
        self.overlay = QLabel(self.view.viewport())
        self.overlay.setObjectName("preview_message")
        self.overlay.setWordWrap(True)
        self.overlay.setAlignment(Qt.AlignCenter)
        self.overlay.setTextFormat(Qt.PlainText)
        self.overlay.setStyleSheet("QLabel { background: rgba(255, 255, 255, 225); color: #333; "
                                   "border: 1px solid #bbb; border-radius: 6px; padding: 14px; font-size: 11pt; }")
        self.overlay.hide()
        self.view.viewChanged.connect(self._place_overlay)
        self.paper_mm, self.margin_mm = 3200.0, 5.0
        self.image_mm = (0.0, 0.0)
        self.has_image = False
        self._fitted = False
        self._refitting = False
        self.auto_fit: str | None = "media"
        self.view.resized.connect(self._view_resized)
        self.view.zoomed.connect(self._zoomed)
        self.set_media(3200.0, 5.0)
        self.show_message("Add images with “Add files…” or drop them on the window")

    # -- content -------------------------------------------------------------------------
    def set_media(self, paper_mm: float, margin_mm: float) -> None:
        self.paper_mm, self.margin_mm = float(paper_mm), float(margin_mm)
        self._layout_scene()

    def _layout_scene(self) -> None:
        w_mm, h_mm = self.image_mm
        length = h_mm if self.has_image else 0.25 * self.paper_mm
        lead = max(20.0, 0.05 * max(length, w_mm))
        self.paper_item.setRect(QRectF(0, -lead, self.paper_mm, length + 2 * lead))
        self.margin_item.setRect(QRectF(self.margin_mm, -lead, max(0.0, self.paper_mm - 2 * self.margin_mm),
                                        length + 2 * lead))
        if self.has_image:
            self.frame_item.setRect(QRectF(self.margin_mm, 0, w_mm, h_mm))
        r = self.paper_item.rect().adjusted(-0.05 * self.paper_mm, -lead, 0.05 * self.paper_mm, lead)
        self.scene.setSceneRect(r)

    def set_cut_paths(self, lines) -> None:
        """A print-and-cut job's cut lines over its picture, in their own colour: polylines
        in millimetres of the sheet (the cut file's frame, docs/cut.md); [] for none."""
        path = QPainterPath()
        for line in lines:
            if len(line) < 2:
                continue
            path.moveTo(QPointF(float(line[0][0]), float(line[0][1])))
            for x, y in line[1:]:
                path.lineTo(QPointF(float(x), float(y)))
        self.cut_item.setPath(path)
        self.cut_item.setPos(QPointF(self.margin_mm, 0))

    def set_spots(self, spots) -> None:
        """The job's spot colours under its picture (its record's `spots`); None or []: none."""
        self.spot_list.set_spots(spots)

    def show_message(self, text: str) -> None:
        """No picture: the empty media and a message over it (errors, hints)."""
        self.cut_item.setPath(QPainterPath())
        self.image_item.setPixmap(QPixmap())
        self.has_image = False
        self.image_mm = (0.0, 0.0)
        self.frame_item.setRect(QRectF())
        self._layout_scene()
        self.overlay.setText(text)
        self.overlay.setVisible(bool(text))
        self._place_overlay()
        self.fit_media()

    def message(self) -> str:
        return self.overlay.text() if self.overlay.isVisible() else ""

    def _place_overlay(self) -> None:
        if not self.overlay.isVisible():
            return
        vp = self.view.viewport()
        w = min(560, max(200, vp.width() - 40))
        h = self.overlay.heightForWidth(w)
        if h <= 0:
            h = self.overlay.sizeHint().height()
        self.overlay.setFixedSize(w, h)
        self.overlay.move((vp.width() - w) // 2, max(10, (vp.height() - h) // 2))
        self.overlay.raise_()

    def set_image(self, rgb: np.ndarray, width_mm: float, height_mm: float, title: str = "") -> None:
        first = not self.has_image
        self.overlay.hide()
        img = qimage_from_rgb(rgb)
        self.image_item.setPixmap(QPixmap.fromImage(img))
        h, w = rgb.shape[:2]
        self.image_item.setTransform(self.image_item.transform().fromScale(width_mm / w, height_mm / h))
        self.image_item.setPos(QPointF(self.margin_mm, 0))
        self.image_mm = (width_mm, height_mm)
        self.has_image = True
        self._layout_scene()
        if title:
            self.title.setText(title)
            self.title.setToolTip(title)
        if first or not self._fitted or self.auto_fit == "image":
            self.fit_image()

    def separations(self) -> list[bool]:
        return [self.seps[n].isChecked() for n in "CMYK"]

    def set_separations(self, flags) -> None:
        for n, on in zip("CMYK", flags):
            self.seps[n].blockSignals(True)
            self.seps[n].setChecked(bool(on))
            self.seps[n].blockSignals(False)

    def _seps_changed(self, *_):
        self.separationsChanged.emit(self.separations())

    # -- zoom ----------------------------------------------------------------------------
    def _fit(self, rect: QRectF) -> None:
        if rect.isEmpty():
            return
        self._fitted = True
        self._refitting = True
        self.view.fitInView(rect, Qt.KeepAspectRatio)
        self.view.setRenderHint(QPainter.SmoothPixmapTransform, self.view.zoom < 4)
        self._refitting = False
        self.view.viewChanged.emit()

    def fit_image(self) -> None:
        self.auto_fit = "image"
        if not self.has_image:
            return self._fit_media_rect()
        w, h = self.image_mm
        pad = 0.04 * max(w, h)
        self._fit(QRectF(self.margin_mm - pad, -pad, w + 2 * pad, h + 2 * pad))

    def fit_media(self) -> None:
        self.auto_fit = "media"
        self._fit_media_rect()

    def _fit_media_rect(self) -> None:
        r = self.paper_item.rect()
        self._fit(QRectF(r.x() - 10, r.y(), r.width() + 20, min(r.height(), r.width() * 0.5)))

    def _view_resized(self) -> None:
        """Keep a fitted view fitted when the window changes size (until the operator zooms)."""
        if self.auto_fit == "image":
            self.fit_image()
        elif self.auto_fit == "media":
            self.fit_media()

    def _zoomed(self) -> None:
        if not self._refitting:
            self.auto_fit = None

    def _zoom_text(self):
        z = self.view.zoom
        self.zoom_label.setText(f"{z * 25.4 / max(self.logicalDpiX(), 1) * 100:.0f} %" if z else "")
