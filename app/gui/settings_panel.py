"""Job settings (printer profile, RIP, placement) and the estimate box."""

from __future__ import annotations

from pathlib import Path

from PySide6.QtCore import Qt, Signal
from PySide6.QtWidgets import (QCheckBox, QComboBox, QDoubleSpinBox, QFileDialog, QFormLayout,
                               QGridLayout, QGroupBox, QHBoxLayout, QLabel, QLineEdit,
                               QSpinBox, QToolButton, QVBoxLayout, QWidget)

from ...rip.settings import setting
from ..estimate import Estimate, fmt_duration, fmt_ml
from .jobsettings import SIZE_MODES, JobSettings, cached_profile


def _fill(combo: QComboBox, name: str) -> None:
    """A combo box's items: the setting's choices and labels from the settings schema."""
    s = setting(name)
    choices = s.choices if s.choices is not None else (False, True)
    for value in choices:
        combo.addItem((s.labels or {}).get(value, str(value)), value)
    combo.setToolTip(s.help[:1].upper() + s.help[1:])


class _FileField(QWidget):
    """A line edit with a browse button (ICC profiles)."""
    changed = Signal()

    def __init__(self, placeholder: str, filt: str, parent=None):
        super().__init__(parent)
        self.filt = filt
        lay = QHBoxLayout(self)
        lay.setContentsMargins(0, 0, 0, 0)
        lay.setSpacing(2)
        self.edit = QLineEdit()
        self.edit.setPlaceholderText(placeholder)
        self.edit.setClearButtonEnabled(True)
        self.edit.editingFinished.connect(self.changed)
        b = QToolButton()
        b.setText("…")
        b.setToolTip("Choose a file")
        b.clicked.connect(self._browse)
        lay.addWidget(self.edit, 1)
        lay.addWidget(b)

    def _browse(self):
        path, _ = QFileDialog.getOpenFileName(self, "Choose an ICC profile", self.edit.text(), self.filt)
        if path:
            self.edit.setText(path)
            self.changed.emit()

    def text(self) -> str:
        return self.edit.text().strip()

    def setText(self, t: str) -> None:
        self.edit.setText(t or "")


class SettingsPanel(QWidget):
    """Edits a JobSettings; emits changed(JobSettings) on every edit by the operator."""
    changed = Signal(object)
    profileBrowse = Signal()

    def __init__(self, parent=None):
        super().__init__(parent)
        self._loading = False
        self._profiles: list[tuple[str, str]] = []    # (label, path)
        outer = QVBoxLayout(self)
        outer.setContentsMargins(4, 4, 4, 4)
        self.title = QLabel("Settings for new jobs")
        self.title.setStyleSheet("font-weight: bold;")
        self.title.setWordWrap(True)
        outer.addWidget(self.title)

        # -- printer & RIP ----------------------------------------------------------------
        g = QGroupBox("Printer and RIP")
        f = QFormLayout(g)
        f.setFieldGrowthPolicy(QFormLayout.AllNonFixedFieldsGrow)
        row = QHBoxLayout()
        self.profile = QComboBox()
        self.profile.setObjectName("profile")
        self.profile.setToolTip("Printer profile (geometry, calibration, speeds)")
        row.addWidget(self.profile, 1)
        pb = QToolButton()
        pb.setText("…")
        pb.setToolTip("Use another printer profile file")
        pb.clicked.connect(self._browse_profile)
        row.addWidget(pb)
        f.addRow("Printer profile", row)
        self.dpi = QComboBox()
        self.dpi.setObjectName("dpi")
        _fill(self.dpi, "dpi")
        self.profile.currentIndexChanged.connect(self._profile_changed)
        f.addRow("Resolution", self.dpi)
        self.passes = QComboBox()
        self.passes.setObjectName("passes")
        _fill(self.passes, "passes")
        f.addRow("Passes", self.passes)
        self.pass_mask = QComboBox()
        self.pass_mask.setObjectName("pass_mask")
        _fill(self.pass_mask, "pass_mask")
        f.addRow("Pass mask", self.pass_mask)
        self.direction = QComboBox()
        self.direction.setObjectName("direction")
        _fill(self.direction, "bidir")
        f.addRow("Direction", self.direction)
        self.dither = QComboBox()
        self.dither.setObjectName("dither")
        _fill(self.dither, "dither")
        f.addRow("Dither", self.dither)
        self.input_icc = _FileField("embedded, else sRGB", "ICC profiles (*.icc *.icm);;All files (*)")
        f.addRow("Input ICC", self.input_icc)
        self.output_icc = _FileField("built-in CMYK", "ICC profiles (*.icc *.icm);;All files (*)")
        f.addRow("Output ICC", self.output_icc)
        self.intent = QComboBox()
        self.intent.setObjectName("intent")
        _fill(self.intent, "intent")
        f.addRow("Intent", self.intent)
        ink = QHBoxLayout()
        self.ink_on = QCheckBox()
        self.ink_on.setToolTip("Off: the profile's limit for RGB/grey images, none for CMYK files")
        self.ink_limit = QDoubleSpinBox()
        self.ink_limit.setObjectName("ink_limit")
        self.ink_limit.setRange(0, 400)
        self.ink_limit.setDecimals(0)
        self.ink_limit.setSuffix(" %")
        self.ink_limit.setValue(300)
        ink.addWidget(self.ink_on)
        ink.addWidget(self.ink_limit, 1)
        f.addRow("Ink limit", ink)
        self.copies = QSpinBox()
        self.copies.setObjectName("copies")
        self.copies.setRange(1, 999)
        f.addRow("Copies", self.copies)
        outer.addWidget(g)

        # -- placement ----------------------------------------------------------------------
        self.place_box = QGroupBox("Size and position")
        pf = QFormLayout(self.place_box)
        pf.setFieldGrowthPolicy(QFormLayout.AllNonFixedFieldsGrow)
        self.size_mode = QComboBox()
        self.size_mode.setObjectName("size_mode")
        for k, v in SIZE_MODES.items():
            self.size_mode.addItem(v, k)
        pf.addRow("Size", self.size_mode)
        wh = QGridLayout()
        self.width_mm = self._mm_spin("width_mm")
        self.height_mm = self._mm_spin("height_mm")
        wh.addWidget(QLabel("W"), 0, 0)
        wh.addWidget(self.width_mm, 0, 1)
        wh.addWidget(QLabel("H"), 0, 2)
        wh.addWidget(self.height_mm, 0, 3)
        pf.addRow("Width / height", wh)
        self.scale = QDoubleSpinBox()
        self.scale.setObjectName("scale")
        self.scale.setRange(1, 10000)
        self.scale.setSuffix(" %")
        self.scale.setValue(100)
        pf.addRow("Scale", self.scale)
        self.fit_width = self._mm_spin("fit_width_mm")
        self.fit_width.setSpecialValueText("media width")
        pf.addRow("Fit width", self.fit_width)
        self.rotate = QComboBox()
        self.rotate.setObjectName("rotate")
        _fill(self.rotate, "rotate")
        pf.addRow("Rotate", self.rotate)
        self.mirror = QCheckBox("Mirror (print from the back)")
        self.mirror.setObjectName("mirror")
        pf.addRow("", self.mirror)
        self.filter = QComboBox()
        self.filter.setObjectName("filter")
        _fill(self.filter, "filter")
        pf.addRow("Resampling", self.filter)
        # position on the measured paper (applied when the job starts: docs/placement.md)
        pos = QHBoxLayout()
        self.align = QComboBox()
        self.align.setObjectName("align")
        _fill(self.align, "align")
        self.x_mm = self._mm_spin("x_mm", lo=-10_000)
        self.x_mm.setSpecialValueText("")
        self.x_mm.setPrefix("+ ")
        self.x_mm.setToolTip("Shift right from the aligned position (negative: left)")
        pos.addWidget(self.align)
        pos.addWidget(self.x_mm, 1)
        pf.addRow("Position", pos)
        mar = QHBoxLayout()
        self.margin_mm = self._mm_spin("margin_mm")
        self.margin_mm.setMinimum(-0.1)
        self.margin_mm.setSpecialValueText("profile")
        self.margin_mm.setToolTip("Side margins inside the measured paper edges")
        self.top_mm = self._mm_spin("top_mm")
        self.top_mm.setSpecialValueText("none")
        self.top_mm.setToolTip("Blank paper fed before the image")
        mar.addWidget(QLabel("sides"))
        mar.addWidget(self.margin_mm, 1)
        mar.addWidget(QLabel("top"))
        mar.addWidget(self.top_mm, 1)
        pf.addRow("Margins", mar)
        outer.addWidget(self.place_box)

        outer.addStretch(1)

        for w in (self.profile, self.dpi, self.passes, self.pass_mask, self.direction, self.dither, self.intent,
                  self.size_mode, self.rotate, self.filter, self.align):
            w.currentIndexChanged.connect(self._edited)
        for w in (self.ink_limit, self.width_mm, self.height_mm, self.scale, self.fit_width,
                  self.x_mm, self.margin_mm, self.top_mm):
            w.valueChanged.connect(self._edited)
        self.copies.valueChanged.connect(self._edited)
        for w in (self.ink_on, self.mirror):
            w.toggled.connect(self._edited)
        self.input_icc.changed.connect(self._edited)
        self.output_icc.changed.connect(self._edited)
        self._update_enabled()

    def _mm_spin(self, name: str, lo: float = 0) -> QDoubleSpinBox:
        s = QDoubleSpinBox()
        s.setObjectName(name)
        s.setRange(lo, 1_000_000)
        s.setDecimals(1)
        s.setSuffix(" mm")
        s.setSpecialValueText("auto")
        return s

    # -- profiles ----------------------------------------------------------------------
    def set_profiles(self, profiles: list[tuple[str, str]], current: str | None = None) -> None:
        self._loading = True
        try:
            cur = current if current is not None else self.profile.currentData()
            self._profiles = list(profiles)
            self.profile.clear()
            for label, path in profiles:
                self.profile.addItem(label, path)
                self.profile.setItemData(self.profile.count() - 1, path, Qt.ToolTipRole)
            i = self.profile.findData(cur)
            self.profile.setCurrentIndex(max(0, i))
        finally:
            self._loading = False

    def _profile_changed(self, *_):
        """Only the chosen printer profile's dpi modes can be picked."""
        path = self.profile.currentData()
        try:
            modes = cached_profile(path).dpi_modes if path else None
        except (OSError, ValueError):
            modes = None
        model = self.dpi.model()
        for i in range(self.dpi.count()):
            item = model.item(i)
            if item is not None:
                item.setEnabled(modes is None or self.dpi.itemData(i) in modes)

    def _browse_profile(self):
        path, _ = QFileDialog.getOpenFileName(self, "Printer profile", "", "Printer profiles (*.toml)")
        if path:
            if self.profile.findData(path) < 0:
                self.profile.addItem(Path(path).stem, path)
            self.profile.setCurrentIndex(self.profile.findData(path))

    # -- settings <-> widgets ------------------------------------------------------------
    def settings(self) -> JobSettings:
        return JobSettings(
            profile=self.profile.currentData() or "",
            dpi=self.dpi.currentData(), passes=self.passes.currentData(),
            bidir=bool(self.direction.currentData()), dither=self.dither.currentData(),
            pass_mask=self.pass_mask.currentData() or "checker",
            input_icc=self.input_icc.text(), output_icc=self.output_icc.text(),
            intent=self.intent.currentData(),
            ink_limit=float(self.ink_limit.value()) if self.ink_on.isChecked() else None,
            copies=self.copies.value(), size_mode=self.size_mode.currentData(),
            width_mm=self.width_mm.value() or None, height_mm=self.height_mm.value() or None,
            scale_pct=self.scale.value(), fit_width_mm=self.fit_width.value() or None,
            rotate=self.rotate.currentData(), mirror=self.mirror.isChecked(),
            filter=self.filter.currentData(), align=self.align.currentData(),
            x_mm=self.x_mm.value(),
            margin_mm=None if self.margin_mm.value() < 0 else self.margin_mm.value(),
            top_mm=self.top_mm.value())

    def set_settings(self, js: JobSettings, title: str | None = None) -> None:
        self._loading = True
        try:
            if title is not None:
                self.title.setText(title)
            i = self.profile.findData(js.profile)
            if i < 0 and js.profile:
                self.profile.addItem(Path(js.profile).stem, js.profile)
                i = self.profile.count() - 1
            self.profile.setCurrentIndex(max(0, i))
            for combo, value in ((self.dpi, js.dpi), (self.passes, js.passes),
                                 (self.direction, bool(js.bidir)), (self.dither, js.dither),
                                 (self.pass_mask, js.pass_mask),
                                 (self.intent, js.intent), (self.size_mode, js.size_mode),
                                 (self.rotate, js.rotate), (self.filter, js.filter),
                                 (self.align, js.align)):
                combo.setCurrentIndex(max(0, combo.findData(value)))
            self.input_icc.setText(js.input_icc)
            self.output_icc.setText(js.output_icc)
            self.ink_on.setChecked(js.ink_limit is not None)
            if js.ink_limit is not None:
                self.ink_limit.setValue(js.ink_limit)
            self.copies.setValue(js.copies)
            self.width_mm.setValue(js.width_mm or 0)
            self.height_mm.setValue(js.height_mm or 0)
            self.scale.setValue(js.scale_pct)
            self.fit_width.setValue(js.fit_width_mm or 0)
            self.mirror.setChecked(bool(js.mirror))
            self.x_mm.setValue(js.x_mm)
            self.margin_mm.setValue(-0.1 if js.margin_mm is None else js.margin_mm)
            self.top_mm.setValue(js.top_mm)
        finally:
            self._loading = False
        self._update_enabled()

    def _update_enabled(self) -> None:
        self.ink_limit.setEnabled(self.ink_on.isChecked())
        m = self.size_mode.currentData()
        self.width_mm.setEnabled(m == "size")
        self.height_mm.setEnabled(m == "size")
        self.scale.setEnabled(m == "scale")
        self.fit_width.setEnabled(m == "fit")
        self.filter.setEnabled(m != "pixels")

    def _edited(self, *_):
        self._update_enabled()
        if not self._loading:
            self.changed.emit(self.settings())


class EstimateBox(QGroupBox):
    """Time, area, strokes and ink of the selected job (docs/gui.md, "Estimates")."""

    def __init__(self, parent=None):
        super().__init__("Estimate", parent)
        g = QGridLayout(self)
        g.setColumnStretch(1, 1)
        g.setColumnStretch(3, 1)
        self.labels = {}
        rows = [("size", "Size"), ("dots", "Dots"), ("area", "Area"), ("strokes", "Strokes"),
                ("time", "Time"), ("ink", "Ink total")]
        for i, (k, text) in enumerate(rows):
            g.addWidget(QLabel(text + ":"), i, 0)
            v = QLabel("–")
            v.setObjectName(f"est_{k}")
            v.setTextInteractionFlags(Qt.TextSelectableByMouse)
            g.addWidget(v, i, 1, 1, 3)
            self.labels[k] = v
        self.ink = {}
        base = len(rows)
        for c, (name, color) in enumerate((("C", "#00aeef"), ("M", "#ec008c"), ("Y", "#d4c400"),
                                           ("K", "#231f20"))):
            sw = QLabel(f"<span style='color:{color}'>■</span> {name}:")
            v = QLabel("–")
            v.setObjectName(f"est_ink_{name}")
            g.addWidget(sw, base + c // 2, (c % 2) * 2)
            g.addWidget(v, base + c // 2, (c % 2) * 2 + 1)
            self.ink[name] = v
        self.note = QLabel("")
        self.note.setWordWrap(True)
        self.note.setStyleSheet("color: #666;")
        self.note.setAlignment(Qt.AlignTop | Qt.AlignLeft)
        self.note.setMinimumHeight(3 * self.note.fontMetrics().lineSpacing())
        g.addWidget(self.note, base + 2, 0, 1, 4)

    def show_estimate(self, e: Estimate | None, note: str = "") -> None:
        if e is None:
            for v in list(self.labels.values()) + list(self.ink.values()):
                v.setText("–")
            self.note.setText(note)
            return
        copies = f" × {e.copies} copies" if e.copies > 1 else ""
        self.labels["size"].setText(f"{e.width_mm:,.1f} × {e.height_mm:,.1f} mm")
        self.labels["dots"].setText(f"{e.width_dots:,} × {e.height_rows:,}")
        self.labels["area"].setText(f"{e.area_m2:.3f} m²" + (f" (× {e.copies})" if e.copies > 1 else ""))
        self.labels["strokes"].setText(f"{e.strokes}  ({e.stroke_s:.1f} s each)")
        self.labels["time"].setText(fmt_duration(e.time_s) + copies)
        self.labels["ink"].setText(f"{fmt_ml(e.total_ink_ml)} ml" + copies)
        for name, ml in zip("CMYK", e.ink_ml):
            self.ink[name].setText(f"{fmt_ml(ml)} ml")
        self.note.setText(note)
