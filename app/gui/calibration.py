"""Test prints and calibration (docs/testprints.md): nozzle check, bidirectional and head
alignment.  The operator prints a pattern, picks the straight block (on the emulator the
dialog shows the printed media and suggests it), and the chosen offsets are written to
the user's copy of the printer profile with rip.profile.save_calibration.  After a nozzle
check the operator marks the nozzles whose dash is missing as dead (or clears them after a
head is replaced); they go into the profile's dead_nozzles, which the stroke planner prints
around (with two or more passes)."""

from __future__ import annotations

import logging
from pathlib import Path

import numpy as np
from PySide6.QtCore import QEvent, QRectF, Qt, Signal
from PySide6.QtGui import QColor, QFont, QPainter, QPen
from PySide6.QtWidgets import (QAbstractItemView, QComboBox, QDialog, QDialogButtonBox,
                               QDoubleSpinBox, QFileDialog, QFormLayout, QGridLayout, QGroupBox, QHBoxLayout,
                               QLabel, QListView, QListWidget, QListWidgetItem, QMessageBox,
                               QPushButton, QSizePolicy, QSpinBox, QStackedWidget, QVBoxLayout,
                               QWidget)

from ...rip.planes import read_planes, render_rgb
from ...rip.profile import Profile, load_profile, save_calibration
from ...rip.testpatterns import CALIBRATION_KINDS
from ...rip.testprints import ALIGN_BLOCK, PatternJob, align_offsets, nozzle_check_layout
from .preview import qimage_from_rgb
from .wheel_guard import guard_wheel

log = logging.getLogger("wideprint.gui")

PATTERN_NAMES = {
    "nozzle-check": "Nozzle check",
    "bidir-align": "Bidirectional alignment",
    "head-align": "Head alignment",
    "line": "Line (one nozzle)",
    "sawtooth": "Sawtooth (encoder / shift register)",
    "bidir-scan": "Bidirectional, for a scan",
    "heads-scan": "Head positions, for a scan",
    "feed-scan": "Paper feed, for a scan",
    "wedge-scan": "Step wedge (ink curves), for a scan",
    "banding-scan": "Banding and grain chart, for a scan",
}
# the scan patterns -> the `wideprint calibrate` measurement that reads them (app/calibrate.py;
# the registry: rip/testpatterns.py)
SCAN_KINDS = {pattern: kind for kind, pattern in CALIBRATION_KINDS.items()}


# -- reading the printed patterns (pure; the tests use them too) ---------------------------
def head_rows(profile: Profile) -> dict[str, tuple[int, int]]:
    """head-align: (image row, channel) of the first bar row each head prints."""
    s0, _ = profile.usable_slots()
    names = [h.name for h in profile.heads]
    band = max(1, (profile.nozzles - 30) // len(names))
    out = {}
    for i, h in enumerate(profile.heads):
        z0 = 25 + i * band
        out[h.name] = (h.y_rows + profile.heads_per_color * z0 - s0, h.channel)
    return out


def reference_row(profile: Profile) -> tuple[int, int]:
    s0, _ = profile.usable_slots()
    k1 = next(h for h in profile.heads if h.name == "K1")
    return k1.y_rows + profile.heads_per_color * 5 - s0, k1.channel


def suggest_bidir(media: np.ndarray) -> int | None:
    """bidir-align: the offset whose forward and reverse bars line up (K channel)."""
    rows = media.shape[0] // 2
    fwd, rev = media[:rows, :, 3].any(axis=0), media[rows:, :, 3].any(axis=0)
    best, score = None, -1.0
    for b, o in enumerate(align_offsets()):
        sl = slice(b * ALIGN_BLOCK, (b + 1) * ALIGN_BLOCK)
        f, r = fwd[sl], rev[sl]
        if not f.any() or not r.any():
            continue
        s = (f & r).sum() / max(1, (f | r).sum())
        if s > score:
            best, score = o, s
    return best if score > 0.99 else None


def suggest_heads(media: np.ndarray, profile: Profile) -> dict[str, int | None]:
    """head-align: per head, the offset whose bars continue the K1 reference bars."""
    rr, rc = reference_row(profile)
    ref = media[rr, :, rc] > 0
    out = {}
    for name, (r, c) in head_rows(profile).items():
        if name == "K1" or r >= media.shape[0]:
            continue
        row = media[r, :, c] > 0
        found = [o for b, o in enumerate(align_offsets())
                 if row[b * ALIGN_BLOCK:(b + 1) * ALIGN_BLOCK].any()
                 and np.array_equal(row[b * ALIGN_BLOCK:(b + 1) * ALIGN_BLOCK],
                                    ref[b * ALIGN_BLOCK:(b + 1) * ALIGN_BLOCK])]
        out[name] = found[0] if len(found) == 1 else None
    return out


def dead_names(profile: Profile) -> set[tuple[str, int]]:
    """The profile's dead nozzles as (head name, nozzle)."""
    return {(profile.heads[h].name, z) for h, z in profile.dead_nozzles}


def fmt_nozzles(nozzles, profile: Profile) -> str:
    order = {h.name: h.index for h in profile.heads}
    return ", ".join(f"{h}:{z}" for h, z in sorted(nozzles, key=lambda hz: (order.get(hz[0], 99), hz[1])))


def missing_nozzles(media: np.ndarray, profile: Profile) -> list[str]:
    """nozzle-check: heads and nozzles whose dash did not print."""
    check = nozzle_check_layout(profile, media.shape[1])
    out = []
    for h in profile.heads:
        for z in range(1, profile.nozzles - 1):
            r, x0, x1 = check.dash_at(h.name, z)
            if 0 <= r < media.shape[0] and not media[r, x0:x1, h.channel].any():
                out.append(f"{h.name}:{z}")
    return out


# -- the picture ---------------------------------------------------------------------------
class PatternView(QWidget):
    """The printed (or intended) pattern at its physical aspect; alignment blocks are
    labelled with their offset and can be clicked."""
    blockClicked = Signal(int, int)      # offset, image row

    def __init__(self, parent=None):
        super().__init__(parent)
        self.setObjectName("pattern_view")
        self.setMinimumSize(560, 260)
        self.image = None
        self.planes_shape = (0, 0)
        self.col_mm = self.row_mm = 1.0
        self.blocks = False
        self.selected: int | None = None
        self.suggested: int | None = None
        self.head_labels: list[tuple[str, int]] = []
        self.caption = ""
        self._target = QRectF()

    def set_planes(self, planes: np.ndarray, col_mm: float, row_mm: float, blocks: bool,
                   head_labels=(), caption: str = "") -> None:
        self.image = qimage_from_rgb(render_rgb(planes))
        self.planes_shape = planes.shape[:2]
        self.col_mm, self.row_mm = col_mm, row_mm
        self.blocks = blocks
        self.head_labels = list(head_labels)
        self.caption = caption
        self.update()

    def clear(self, caption: str = "") -> None:
        self.image = None
        self.caption = caption
        self.update()

    def paintEvent(self, ev):
        p = QPainter(self)
        p.fillRect(self.rect(), QColor("#8a8f96"))
        if self.image is None:
            p.setPen(QColor("#f5f5f5"))
            p.drawText(self.rect(), Qt.AlignCenter | Qt.TextWordWrap, self.caption or "Print a pattern")
            p.end()
            return
        h, w = self.planes_shape
        w_mm, h_mm = w * self.col_mm, h * self.row_mm
        left, top, bottom = 40, 22, 30
        s = min((self.width() - left - 10) / w_mm, (self.height() - top - bottom) / h_mm)
        # whole screen pixels per column when enlarged (bars of equal width), else smooth
        smooth = True
        if s * self.col_mm >= 2:
            s = int(s * self.col_mm) / self.col_mm
            smooth = False
        left = max(left, (self.width() - w_mm * s) / 2)
        target = QRectF(left, top, w_mm * s, h_mm * s)
        self._target = target
        p.fillRect(target, QColor("#fdfdfb"))
        p.setRenderHint(QPainter.SmoothPixmapTransform, smooth)
        p.drawImage(target, self.image)
        p.setPen(QColor("#f5f5f5"))
        f = QFont(self.font())
        f.setPointSizeF(8)
        p.setFont(f)
        p.drawText(QRectF(0, 2, self.width(), top - 4), Qt.AlignCenter, self.caption)
        for name, row in self.head_labels:
            y = top + (row + 0.5) * self.row_mm * s
            p.drawText(QRectF(target.left() - 44, y - 8, 40, 16), Qt.AlignRight | Qt.AlignVCenter, name)
        if self.blocks:
            bw = ALIGN_BLOCK * self.col_mm * s
            for b, o in enumerate(align_offsets()):
                x = left + b * bw
                r = QRectF(x, top, bw, target.height())
                if o == self.selected:
                    p.setPen(QPen(QColor("#1565c0"), 3))
                    p.drawRect(r.adjusted(1, 1, -1, -1))
                elif o == self.suggested:
                    p.setPen(QPen(QColor("#2e7d32"), 2, Qt.DashLine))
                    p.drawRect(r.adjusted(1, 1, -1, -1))
                p.setPen(QColor("#fff") if o != self.selected else QColor("#bbdefb"))
                p.drawText(QRectF(x, target.bottom() + 2, bw, bottom - 4), Qt.AlignCenter, f"{o:+d}")
        p.end()

    def mousePressEvent(self, ev):
        if not self.blocks or self.image is None or self._target.isEmpty():
            return
        x = ev.position().x() - self._target.left()
        y = ev.position().y() - self._target.top()
        if not (0 <= x < self._target.width() and 0 <= y < self._target.height()):
            return
        b = int(x / self._target.width() * len(align_offsets()))
        row = int(y / self._target.height() * self.planes_shape[0])
        self.blockClicked.emit(align_offsets()[b], row)


# -- the dialog ----------------------------------------------------------------------------
class CalibrationDialog(QDialog):
    """print_fn(pattern dict, media_file) starts a test print on the printer thread and
    returns its ticket id; the main window calls job_state / job_finished."""
    profileSaved = Signal(str)

    def __init__(self, profile_path: str, print_fn, media_dir: Path | None, emulator: bool,
                 settings: dict | None = None, parent=None):
        super().__init__(parent)
        self.setWindowTitle("Test prints and calibration")
        self.setObjectName("calibration_dialog")
        self.profile_path = str(profile_path)
        self.print_fn = print_fn
        self.media_dir = Path(media_dir) if media_dir else None
        self.emulator = emulator
        self.ticket: int | None = None
        self.job: PatternJob | None = None
        self.media: np.ndarray | None = None
        self.media_file: str | None = None
        self.profile = load_profile(self.profile_path)
        s = settings or {}

        top = QHBoxLayout()
        form = QFormLayout()
        self.pattern = QComboBox()
        self.pattern.setObjectName("pattern")
        for k, v in PATTERN_NAMES.items():
            self.pattern.addItem(v, k)
        form.addRow("Pattern", self.pattern)
        self.dpi = QComboBox()
        self.dpi.setObjectName("cal_dpi")
        for d in self.profile.dpi_modes:
            self.dpi.addItem(f"{d} dpi", d)
        self.dpi.setCurrentIndex(max(0, self.dpi.findData(int(s.get("dpi", 150)))))
        form.addRow("Resolution", self.dpi)
        self.width_mm = QDoubleSpinBox()
        self.width_mm.setRange(5, 3300)
        self.width_mm.setSuffix(" mm")
        self.width_mm.setValue(float(s.get("width_mm", 100.0)))
        self.width_mm.setToolTip("Length along the sweep (nozzle check, line, sawtooth)")
        form.addRow("Length", self.width_mm)
        self.head = QComboBox()
        for h in self.profile.heads:
            self.head.addItem(h.name, h.name)
        self.head.setCurrentIndex(max(0, self.head.findData("K1")))
        self.nozzle = QSpinBox()
        self.nozzle.setRange(1, self.profile.nozzles - 2)
        self.nozzle.setValue(64)
        hrow = QHBoxLayout()
        hrow.addWidget(self.head)
        hrow.addWidget(QLabel("nozzle"))
        hrow.addWidget(self.nozzle)
        form.addRow("Head", hrow)
        top.addLayout(form, 1)
        right = QVBoxLayout()
        self.print_btn = QPushButton("Print test pattern")
        self.print_btn.setObjectName("cal_print")
        self.print_btn.setDefault(True)
        self.print_btn.clicked.connect(self.print_pattern)
        right.addWidget(self.print_btn)
        self.status = QLabel("")
        self.status.setObjectName("cal_status")
        self.status.setWordWrap(True)
        right.addWidget(self.status, 1)
        top.addLayout(right, 1)

        self.view = PatternView()
        self.view.blockClicked.connect(self._block_clicked)

        # choices per pattern
        self.choice = QStackedWidget()
        self.choice.addWidget(QLabel(""))                                  # 0: nothing to choose
        bid = QGroupBox("Bidirectional offset")
        bl = QFormLayout(bid)
        self.bidir_choice = QComboBox()
        self.bidir_choice.setObjectName("bidir_choice")
        for o in align_offsets():
            self.bidir_choice.addItem(f"{o:+d} columns", o)
        self.bidir_choice.setCurrentIndex(align_offsets().index(0))
        self.bidir_choice.currentIndexChanged.connect(self._choice_changed)
        bl.addRow("Straight block", self.bidir_choice)
        self.bidir_now = QLabel("")
        bl.addRow("Profile", self.bidir_now)
        self.choice.addWidget(bid)                                         # 1
        hd = QGroupBox("Head offsets (block whose bars continue the K1 reference)")
        hg = QGridLayout(hd)
        self.head_choice: dict[str, QComboBox] = {}
        others = [h for h in self.profile.heads if h.name != "K1"]
        for i, h in enumerate(others):
            cb = QComboBox()
            cb.setObjectName(f"head_choice_{h.name}")
            for o in align_offsets():
                cb.addItem(f"{o:+d}", o)
            cb.setCurrentIndex(align_offsets().index(0))
            cb.currentIndexChanged.connect(self._choice_changed)
            hg.addWidget(QLabel(h.name), i // 4, (i % 4) * 2)
            hg.addWidget(cb, i // 4, (i % 4) * 2 + 1)
            self.head_choice[h.name] = cb
        self.choice.addWidget(hd)                                          # 2
        self.choice.addWidget(self._dead_nozzle_box())                     # 3

        buttons = QDialogButtonBox()
        self.save_btn = buttons.addButton("Save to printer profile", QDialogButtonBox.ApplyRole)
        self.save_btn.setObjectName("cal_save")
        self.save_btn.setEnabled(False)
        self.save_btn.clicked.connect(self.save)
        close = buttons.addButton(QDialogButtonBox.Close)
        close.clicked.connect(self.reject)
        self.profile_label = QLabel(f"Writes to: {self.profile_path}")
        self.profile_label.setStyleSheet("color:#666;")
        self.profile_label.setWordWrap(True)

        # calibration from a scan of the printed pattern (docs/calibration.md): load it, see
        # what was measured, accept it into the printer profile
        scanrow = QHBoxLayout()
        self.scan_btn = QPushButton("Measure a scan…")
        self.scan_btn.setObjectName("cal_scan")
        self.scan_btn.setToolTip("Load a scan (TIFF) of this pattern as printed: the pattern is "
                                 "found at any placement and a few degrees of rotation, and "
                                 "measured (wideprint calibrate)")
        self.scan_btn.clicked.connect(self._choose_scan)
        self.scan_result = QLabel("")
        self.scan_result.setObjectName("cal_scan_result")
        self.scan_result.setWordWrap(True)
        self.scan_result.setTextInteractionFlags(Qt.TextSelectableByMouse)
        self.scan_accept = QPushButton("Accept into the profile")
        self.scan_accept.setObjectName("cal_scan_accept")
        self.scan_accept.setEnabled(False)
        self.scan_accept.clicked.connect(self.accept_scan)
        scanrow.addWidget(self.scan_btn)
        scanrow.addWidget(self.scan_result, 1)
        scanrow.addWidget(self.scan_accept)
        self.measured = None

        lay = QVBoxLayout(self)
        lay.addLayout(top)
        lay.addWidget(self.view, 1)
        lay.addWidget(self.choice)
        lay.addLayout(scanrow)
        lay.addWidget(self.profile_label)
        lay.addWidget(buttons)
        self.pattern.currentIndexChanged.connect(self._pattern_changed)
        self.pattern.setCurrentIndex(max(0, self.pattern.findData(s.get("pattern", "nozzle-check"))))
        self._pattern_changed()
        self.resize(860, 640)
        guard_wheel(self)

    def showEvent(self, ev) -> None:              # noqa: N802 - Qt's name
        guard_wheel(self)                         # fields made since (a pattern's choices)
        super().showEvent(ev)

    # -- calibration from a scan -------------------------------------------------------------
    def _choose_scan(self) -> None:
        path, _ = QFileDialog.getOpenFileName(self, "Scan of the printed pattern", "",
                                              "Scans (*.tif *.tiff);;All files (*)")
        if path:
            self.measure_scan(path)

    def measure_scan(self, path: str) -> None:
        """Measure the scan of the pattern chosen (its dpi and length as chosen here)."""
        from ..calibrate import CalibrationError, calibrate
        kind = SCAN_KINDS.get(self.kind)
        self.measured = None
        self.scan_accept.setEnabled(False)
        if kind is None:
            self.scan_result.setText("Choose a pattern made for a scan (nozzle check, "
                                     "bidirectional / head positions / paper feed / step "
                                     "wedge for a scan).")
            return
        try:
            res = calibrate(kind, path, self.profile, self.dpi.currentData(),
                            self.width_mm.value())
        except (CalibrationError, ValueError, OSError) as exc:
            self.scan_result.setText(f"<span style='color:#c62828'>{exc}</span>")
            return
        self.measured = res
        self.scan_result.setText("\n".join(res.text[1:]) or "nothing to change")
        self.scan_result.setToolTip("\n".join(res.text))
        self.scan_accept.setEnabled(bool(res.write))

    def accept_scan(self) -> None:
        res = self.measured
        if res is None or not res.write:
            return
        try:
            self.profile = save_calibration(self.profile_path, **res.write)
        except (ValueError, OSError) as exc:
            self.scan_result.setText(f"<span style='color:#c62828'>not saved: {exc}</span>")
            return
        log.info("calibration from a scan (%s) saved to %s", res.kind, self.profile_path)
        self.scan_accept.setEnabled(False)
        self.scan_result.setText(self.scan_result.text() + "\nSaved to the printer profile.")
        self.profileSaved.emit(self.profile_path)

    def _dead_nozzle_box(self) -> QGroupBox:
        """nozzle-check: mark dead nozzles (per head, 1..126) and clear them; what the
        list says is written to the profile's dead_nozzles by Save."""
        box = QGroupBox("Dead nozzles (the print is planned around them; needs 2 or more passes)")
        box.setObjectName("dead_nozzle_box")
        v = QVBoxLayout(box)
        r1 = QHBoxLayout()
        self.nozzle_result = QLabel("Print the nozzle check: a missing dash is a dead nozzle. The dashes "
                                    "run from nozzle 1 at the top to 126 at the bottom (the two heads of "
                                    "a colour alternate), in 8 staggered columns. Every nozzle fires in "
                                    "the test print, also those marked dead.")
        self.nozzle_result.setWordWrap(True)
        r1.addWidget(self.nozzle_result, 1)
        self.mark_missing_btn = QPushButton("Mark missing as dead")
        self.mark_missing_btn.setObjectName("dead_mark_missing")
        self.mark_missing_btn.setToolTip("Add every nozzle whose dash did not print to the list")
        self.mark_missing_btn.clicked.connect(self._mark_missing)
        self.mark_missing_btn.setEnabled(False)
        r1.addWidget(self.mark_missing_btn, 0, Qt.AlignTop)
        v.addLayout(r1)
        r2 = QHBoxLayout()
        r2.addWidget(QLabel("Head"))
        self.dead_head = QComboBox()
        self.dead_head.setObjectName("dead_head")
        for h in self.profile.heads:
            self.dead_head.addItem(h.name, h.name)
        self.dead_head.currentIndexChanged.connect(self._update_dead_buttons)
        r2.addWidget(self.dead_head)
        r2.addWidget(QLabel("nozzle"))
        self.dead_nozzle = QSpinBox()
        self.dead_nozzle.setObjectName("dead_nozzle")
        self.dead_nozzle.setRange(1, self.profile.nozzles - 2)
        self.dead_nozzle.setToolTip(f"1..{self.profile.nozzles - 2} (nozzles 0 and "
                                    f"{self.profile.nozzles - 1} never fire)")
        r2.addWidget(self.dead_nozzle)
        self.mark_btn = QPushButton("Mark dead")
        self.mark_btn.setObjectName("dead_mark")
        self.mark_btn.clicked.connect(self._mark_one)
        r2.addWidget(self.mark_btn)
        r2.addStretch(1)
        self.remove_dead_btn = QPushButton("Remove")
        self.remove_dead_btn.setObjectName("dead_remove")
        self.remove_dead_btn.setToolTip("Take the selected nozzles off the list (they print again)")
        self.remove_dead_btn.clicked.connect(self._remove_selected_dead)
        r2.addWidget(self.remove_dead_btn)
        self.clear_head_btn = QPushButton("Clear head")
        self.clear_head_btn.setObjectName("dead_clear_head")
        self.clear_head_btn.setToolTip("Take every nozzle of the head chosen on the left off the list "
                                       "(a replaced head)")
        self.clear_head_btn.clicked.connect(self._clear_head)
        r2.addWidget(self.clear_head_btn)
        self.clear_all_btn = QPushButton("Clear all")
        self.clear_all_btn.setObjectName("dead_clear_all")
        self.clear_all_btn.clicked.connect(self._clear_all_dead)
        r2.addWidget(self.clear_all_btn)
        v.addLayout(r2)
        self.dead_list = QListWidget()
        self.dead_list.setObjectName("dead_list")
        self.dead_list.setFlow(QListView.LeftToRight)
        self.dead_list.setWrapping(True)
        self.dead_list.setSpacing(2)
        self.dead_list.setSelectionMode(QAbstractItemView.ExtendedSelection)
        self.dead_list.setFixedHeight(self.dead_list.fontMetrics().height() * 2 + 22)
        self.dead_list.setToolTip("Nozzles marked dead; select and Remove (or Delete) to take them off")
        self.dead_list.itemSelectionChanged.connect(self._update_dead_buttons)
        self.dead_list.installEventFilter(self)                  # Delete takes nozzles off
        v.addWidget(self.dead_list)
        self.dead_now = QLabel("")
        self.dead_now.setObjectName("dead_now")
        self.dead_now.setWordWrap(True)
        v.addWidget(self.dead_now)
        self.dead_pending: set[tuple[str, int]] = dead_names(self.profile)
        self.missing: list[tuple[str, int]] = []
        return box

    # -- dead nozzles ----------------------------------------------------------------------
    def _mark_one(self) -> None:
        self._set_dead(self.dead_pending | {(self.dead_head.currentData(), self.dead_nozzle.value())})

    def _mark_missing(self) -> None:
        self._set_dead(self.dead_pending | set(self.missing))

    def _remove_selected_dead(self) -> None:
        gone = {it.data(Qt.UserRole) for it in self.dead_list.selectedItems()}
        self._set_dead(self.dead_pending - gone)

    def _clear_head(self) -> None:
        head = self.dead_head.currentData()
        self._set_dead({hz for hz in self.dead_pending if hz[0] != head})

    def _clear_all_dead(self) -> None:
        self._set_dead(set())

    def _set_dead(self, nozzles) -> None:
        self.dead_pending = {(str(h), int(z)) for h, z in nozzles}
        self._show_dead()

    def _show_dead(self) -> None:
        now = dead_names(self.profile)
        self.dead_list.clear()
        order = {h.name: h.index for h in self.profile.heads}
        for h, z in sorted(self.dead_pending, key=lambda hz: (order.get(hz[0], 99), hz[1])):
            it = QListWidgetItem(f"{h}:{z}")
            it.setData(Qt.UserRole, (h, z))
            if (h, z) not in now:
                it.setForeground(QColor("#1565c0"))
                it.setToolTip("Not saved yet")
            self.dead_list.addItem(it)
        if self.dead_pending == now:
            self.dead_now.setText("Profile: " + (fmt_nozzles(now, self.profile) or "no dead nozzles"))
        else:
            added, removed = self.dead_pending - now, now - self.dead_pending
            parts = ([f"mark {fmt_nozzles(added, self.profile)} dead"] if added else []) + \
                ([f"clear {fmt_nozzles(removed, self.profile)}"] if removed else [])
            self.dead_now.setText(
                f"Profile: {fmt_nozzles(now, self.profile) or 'no dead nozzles'} → after saving: "
                f"{fmt_nozzles(self.dead_pending, self.profile) or 'none'} ({'; '.join(parts)})")
        self._update_dead_buttons()
        if self.kind == "nozzle-check":
            self.save_btn.setEnabled(self.dead_pending != now)

    def _update_dead_buttons(self) -> None:
        self.mark_missing_btn.setEnabled(bool(set(self.missing) - self.dead_pending))
        self.remove_dead_btn.setEnabled(bool(self.dead_list.selectedItems()))
        self.clear_all_btn.setEnabled(bool(self.dead_pending))
        head = self.dead_head.currentData()
        self.clear_head_btn.setText(f"Clear {head}")
        self.clear_head_btn.setEnabled(any(h == head for h, _ in self.dead_pending))

    def eventFilter(self, obj, ev) -> bool:
        if obj is self.dead_list and ev.type() == QEvent.KeyPress and \
                ev.key() in (Qt.Key_Delete, Qt.Key_Backspace):
            self._remove_selected_dead()
            return True
        return super().eventFilter(obj, ev)

    # -- state -------------------------------------------------------------------------
    @property
    def kind(self) -> str:
        return self.pattern.currentData()

    def settings(self) -> dict:
        return dict(pattern=self.kind, dpi=self.dpi.currentData(), width_mm=self.width_mm.value())

    def _pattern_changed(self, *_):
        k = self.kind
        self.width_mm.setEnabled(k in ("nozzle-check", "line", "sawtooth"))
        self.head.setEnabled(k in ("line", "sawtooth"))
        self.nozzle.setEnabled(k == "line")
        self.choice.setCurrentIndex({"bidir-align": 1, "head-align": 2, "nozzle-check": 3}.get(k, 0))
        for i in range(self.choice.count()):     # as tall as the page shown, not the tallest
            self.choice.widget(i).setSizePolicy(
                QSizePolicy.Preferred, QSizePolicy.Preferred if i == self.choice.currentIndex() else QSizePolicy.Ignored)
        self.choice.updateGeometry()
        self.media = None
        self.job = None
        self.missing = []
        self.save_btn.setEnabled(False)
        self._show_intended()
        self._update_profile_text()
        if k == "nozzle-check":
            self._show_dead()

    def _pattern_job(self) -> PatternJob:
        k, dpi = self.kind, self.dpi.currentData()
        width = int(round(self.width_mm.value() / 25.4 * self.profile.counts_per_inch / self.profile.k(dpi)))
        kw = {}
        if k in ("line", "sawtooth"):
            kw["head"] = self.head.currentData()
        if k == "line":
            kw["nozzle"] = self.nozzle.value()
        return PatternJob.for_pattern(k, self.profile, width, dpi, **kw)

    def _col_row_mm(self) -> tuple[float, float]:
        return 25.4 / self.dpi.currentData(), self.profile.row_um / 1000

    def _labels(self):
        if self.kind == "head-align":
            return [(n, r) for n, (r, _) in head_rows(self.profile).items()] + \
                [("ref", reference_row(self.profile)[0])]
        if self.kind == "bidir-align" and self.job is not None:
            return [("fwd", self.job.height // 4), ("rev", 3 * self.job.height // 4)]
        return []

    def _show_intended(self) -> None:
        try:
            self.job = self._pattern_job()
        except ValueError as exc:
            self.view.clear(str(exc))
            return
        c, r = self._col_row_mm()
        self.view.set_planes(self.job.planes, c, r, self.kind in ("bidir-align", "head-align"),
                             self._labels(), "What the pattern should look like — print it to compare")

    def _update_profile_text(self) -> None:
        dpi = self.dpi.currentData()
        now = self.profile.bidir_offset_columns.get(dpi, 0)
        o = self.bidir_choice.currentData() or 0
        self.bidir_now.setText(f"{now:+d} columns at {dpi} dpi now → {now + o:+d} after saving")

    # -- printing ------------------------------------------------------------------------
    def print_pattern(self) -> None:
        try:
            self.job = self._pattern_job()
        except ValueError as exc:
            self.status.setText(str(exc))
            return
        p = dict(kind=self.kind, dpi=self.dpi.currentData(), width_mm=self.width_mm.value())
        if self.kind in ("line", "sawtooth"):
            p["head"] = self.head.currentData()
        if self.kind == "line":
            p["nozzle"] = self.nozzle.value()
        self.media_file = None
        if self.emulator and self.media_dir is not None:
            self.media_dir.mkdir(parents=True, exist_ok=True)
            self.media_file = str(self.media_dir / f"testprint-{self.kind}.tif")
        self.ticket = self.print_fn(p, self.media_file or "")
        self.print_btn.setEnabled(False)
        self.status.setText("Printing…")

    def job_state(self, state: str, detail: str) -> None:
        self.status.setText(f"{state.capitalize()}{' — ' + detail if detail else ''}")

    def job_finished(self, result: dict) -> None:
        self.print_btn.setEnabled(True)
        state = result.get("state")
        if state != "done":
            self.status.setText(f"<span style='color:#c62828'>{state}: {result.get('message', '')}</span>")
            return
        self.status.setText("Printed. Pick the straight block (click it) and save." if self.kind in
                            ("bidir-align", "head-align") else
                            "Printed. Mark the nozzles whose dash is missing as dead, then save."
                            if self.kind == "nozzle-check" else "Printed.")
        if self.media_file and Path(self.media_file).exists():
            self.media = read_planes(self.media_file)
            c, r = self._col_row_mm()
            self.view.set_planes(self.media, c, r, self.kind in ("bidir-align", "head-align"),
                                 self._labels(), "Printed on the emulator")
            self._suggest()
        else:
            self.status.setText(self.status.text() + " Compare the print with the picture.")
        self.save_btn.setEnabled(self.kind in ("bidir-align", "head-align"))
        if self.kind == "nozzle-check":
            self._show_dead()

    def _suggest(self) -> None:
        m = self.media
        self.view.suggested = None          # a bidir suggestion must not outlive its pattern
        if m is None:
            return
        if self.kind == "bidir-align":
            o = suggest_bidir(m)
            self.view.suggested = o
            if o is not None:
                self.bidir_choice.setCurrentIndex(align_offsets().index(o))
                self.status.setText(self.status.text() + f" Suggested: {o:+d}.")
        elif self.kind == "head-align":
            sug = suggest_heads(m, self.profile)
            for name, o in sug.items():
                if o is not None and name in self.head_choice:
                    self.head_choice[name].setCurrentIndex(align_offsets().index(o))
            off = {n: o for n, o in sug.items() if o}
            self.status.setText(self.status.text() + (" Suggested: " + ", ".join(
                f"{n} {o:+d}" for n, o in off.items()) if off else " All heads look aligned."))
        elif self.kind == "nozzle-check":
            miss = missing_nozzles(m, self.profile)
            self.missing = [(h, int(z)) for h, z in (x.split(":") for x in miss)]
            revived = dead_names(self.profile) - set(self.missing)
            self.nozzle_result.setText(
                ("Every nozzle printed its dash." if not miss else
                 f"Missing dashes (dead nozzles): {', '.join(miss)}") +
                (f" Marked dead but printed: {fmt_nozzles(revived, self.profile)} (remove them if the "
                 f"head was cleaned or replaced)." if revived else ""))
            self._show_dead()
        self._choice_changed()

    # -- choosing and saving -------------------------------------------------------------
    def _block_clicked(self, offset: int, row: int) -> None:
        if self.kind == "bidir-align":
            self.bidir_choice.setCurrentIndex(align_offsets().index(offset))
        elif self.kind == "head-align":
            rows = head_rows(self.profile)
            band = max(1, (self.profile.nozzles - 30) // len(rows)) * self.profile.heads_per_color
            for name, (r, _) in rows.items():
                if r - 2 <= row < r + band and name in self.head_choice:
                    self.head_choice[name].setCurrentIndex(align_offsets().index(offset))
                    break
        self._choice_changed()

    def _choice_changed(self, *_):
        if self.kind == "bidir-align":
            self.view.selected = self.bidir_choice.currentData()
        else:
            self.view.selected = None
        self._update_profile_text()
        self.view.update()

    def calibration_values(self) -> dict:
        """What save() writes: save_calibration keyword arguments."""
        dpi = self.dpi.currentData()
        if self.kind == "bidir-align":
            offs = dict(self.profile.bidir_offset_columns)
            offs[dpi] = offs.get(dpi, 0) + int(self.bidir_choice.currentData())
            return dict(bidir_offset_columns=offs)
        if self.kind == "head-align":
            # x_counts must stay whole columns at the coarsest mode (docs/testprints.md):
            # an offset measured at a finer dpi is rounded to that
            k = self.profile.k(dpi)
            kmax = max(self.profile.k(d) for d in self.profile.dpi_modes)
            out = {}
            for h in self.profile.heads:
                o = int(self.head_choice[h.name].currentData()) if h.name in self.head_choice else 0
                step = int(round(o * k / kmax)) * kmax
                if step:
                    out[h.name] = h.x_counts - step
            return dict(head_x_counts=out)
        if self.kind == "nozzle-check":
            order = {h.name: h.index for h in self.profile.heads}
            return dict(dead_nozzles=sorted(self.dead_pending, key=lambda hz: (order[hz[0]], hz[1])))
        return {}

    def save(self) -> None:
        values = self.calibration_values()
        if "dead_nozzles" in values and set(values["dead_nozzles"]) == dead_names(self.profile):
            self.status.setText("Nothing to change: the list is the profile's.")
            return
        if not values or values == {"head_x_counts": {}}:
            self.status.setText("Nothing to change: every offset is 0.")
            return
        try:
            self.profile = save_calibration(self.profile_path, **values)
        except (ValueError, OSError) as exc:
            QMessageBox.warning(self, "Calibration", f"Cannot save the calibration: {exc}")
            return
        if "dead_nozzles" in values:
            what = "dead nozzles " + (fmt_nozzles(values["dead_nozzles"], self.profile) or "cleared")
        else:
            what = ", ".join(f"{k} = {v}" for k, v in values.items())
        log.info("calibration saved to %s: %s", self.profile_path, what)
        self.status.setText(f"Saved to the printer profile: {what}")
        self.save_btn.setEnabled(False)
        for cb in self.head_choice.values():
            cb.setCurrentIndex(align_offsets().index(0))
        self.bidir_choice.setCurrentIndex(align_offsets().index(0))
        self._update_profile_text()
        if "dead_nozzles" in values:
            self.dead_pending = dead_names(self.profile)
            self._show_dead()
        self.profileSaved.emit(self.profile_path)
