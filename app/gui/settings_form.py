"""The job settings editor, built from the one settings schema (rip/settings.py), so the
GUI offers exactly what the CLI, the server and the presets accept (docs/gui.md,
"Settings").

It shows the settings of one job, of several (a setting whose values differ is shown as
mixed: "— mixed —" in a list, an empty field with "mixed" greyed in it, a part-checked
box), or the defaults for new jobs.  An edit emits `edited(key, value)` for that one setting
only ("dpi", "placement.rotate", or the job fields "copies" and "priority"; value None puts a
setting back to its default), so the window changes only that setting of each selected job.
"""

from __future__ import annotations

import math

from PySide6.QtCore import Qt, Signal
from PySide6.QtWidgets import (QCheckBox, QComboBox, QFormLayout, QGroupBox, QLabel, QLineEdit,
                               QSizePolicy, QVBoxLayout, QWidget)

from ...rip.settings import SETTINGS, SettingsError

MIXED = object()                  # several jobs, several values
MIXED_TEXT = "— mixed —"
SECTIONS = (("Printing", ("dpi", "passes", "bidir", "pass_mask", "dither")),
            ("Colour", ("media", "intent", "ink_limit", "input_icc", "output_icc")),
            ("Size and position", ("size", "width_mm", "height_mm", "scale", "fit_width_mm",
                                   "rotate", "mirror", "filter", "align", "x_mm", "margin_mm",
                                   "top_mm")),
            ("PDF and PostScript", ("page_box", "pages", "page_gap_mm")))
UNITS = {"ink_limit": "%", "scale": "×"}
AUTO = {"media": "printer's default",
        "ink_limit": "profile's", "input_icc": "embedded, else sRGB", "output_icc": "built-in CMYK",
        "width_mm": "auto", "height_mm": "auto", "scale": "1", "fit_width_mm": "off",
        "margin_mm": "profile's"}
# job fields beside the settings: (key, label, minimum, maximum)
JOB_FIELDS = (("copies", "Copies", 1, 100), ("priority", "Priority", -100, 100))


def key_of(s) -> str:
    return f"placement.{s.name}" if s.group == "placement" else s.name


def effective(job: dict, key: str):
    """The value a job prints with: its own setting, else the schema's default; job fields
    (copies, priority) from the job."""
    if "." not in key and key in dict(JOB_FIELDS_KEYS):
        return job.get(key, dict(JOB_FIELDS_KEYS)[key])
    settings = job.get("settings") or {}
    if key.startswith("placement."):
        name = key.split(".", 1)[1]
        v = (settings.get("placement") or {}).get(name)
    else:
        name = key
        v = settings.get(name)
    return BY_KEY[key].default if v is None else v


JOB_FIELDS_KEYS = (("copies", 1), ("priority", 0))
BY_KEY = {key_of(s): s for s in SETTINGS}


def _fmt(v) -> str:
    if isinstance(v, float):
        return f"{v:g}"
    return "" if v is None else str(v)


class _Field:
    """One setting's widget: set(value or MIXED), and the edit it reports."""

    def __init__(self, form: "SettingsForm", key: str, s=None, lo=None, hi=None):
        self.form, self.key, self.s = form, key, s
        self.lo, self.hi = lo, hi
        self.mixed = False
        labels = (s.labels or {}) if s is not None else {}
        if s is not None and (s.choices or labels):
            self.kind = "combo"
            w = QComboBox()
            choices = s.choices if s.choices else tuple(labels)
            for c in choices:
                w.addItem(labels.get(c, str(c)), c)
            w.activated.connect(self._combo)
            # long choice names must not widen the form: the list shows them whole
            w.setSizeAdjustPolicy(QComboBox.AdjustToMinimumContentsLengthWithIcon)
            w.setMinimumContentsLength(10)
            w.view().setMinimumWidth(w.view().sizeHintForColumn(0) + 24)
            self.choices = choices
        elif s is not None and s.kind is bool:
            self.kind = "check"
            w = QCheckBox()
            w.clicked.connect(self._check)
        else:
            self.kind = "text"
            w = QLineEdit()
            w.editingFinished.connect(self._text)
        w.setObjectName(key.replace(".", "_"))
        w.setSizePolicy(QSizePolicy.Expanding, QSizePolicy.Fixed)
        if s is not None:
            w.setToolTip(s.help)
        self.w = w

    # value -> widget
    def set(self, value) -> None:
        self.mixed = value is MIXED
        w = self.w
        w.blockSignals(True)
        try:
            if self.kind == "combo":
                i = w.findText(MIXED_TEXT)
                if self.mixed:
                    if i < 0:
                        w.insertItem(0, MIXED_TEXT, MIXED)
                    w.setCurrentIndex(0)
                else:
                    if i >= 0:
                        w.removeItem(i)
                    w.setCurrentIndex(max(0, w.findData(value)))
            elif self.kind == "check":
                w.setTristate(self.mixed)
                w.setCheckState(Qt.PartiallyChecked if self.mixed else
                                Qt.Checked if value else Qt.Unchecked)
            else:
                w.setText("" if self.mixed else _fmt(value))
                w.setPlaceholderText("mixed" if self.mixed else
                                     AUTO.get(self.s.name, "") if self.s is not None else "")
                w.setProperty("last", w.text())
        finally:
            w.blockSignals(False)

    # widget -> edit
    def _combo(self, i: int) -> None:
        v = self.w.itemData(i)
        if v is MIXED:
            return
        i0 = self.w.findText(MIXED_TEXT)
        if i0 >= 0:
            self.w.removeItem(i0)
        self.mixed = False
        self.form._emit(self.key, v)

    def _check(self, checked: bool) -> None:
        self.w.setTristate(False)
        self.mixed = False
        self.form._emit(self.key, bool(self.w.isChecked()))

    def _text(self) -> None:
        w = self.w
        text = w.text().strip()
        if text == (w.property("last") or "") and not (self.mixed and text):
            return
        try:
            v = self.parse(text)
        except ValueError as exc:
            self.form.show_problem(str(exc))
            w.setText(w.property("last") or "")
            return
        w.setProperty("last", text)
        self.mixed = False
        self.form._emit(self.key, v)

    def parse(self, text: str):
        s = self.s
        if s is None:                                   # copies, priority
            try:
                v = int(text)
            except ValueError:
                raise ValueError(f"{self.key} must be a whole number") from None
            if not self.lo <= v <= self.hi:
                raise ValueError(f"{self.key} must be {self.lo}..{self.hi}")
            return v
        if not text:
            return None                                 # back to the default
        if s.kind in (int, float):
            try:
                v = int(text) if s.kind is int else float(text.replace(",", "."))
            except ValueError:
                raise ValueError(f"{s.label or s.name}: {text!r} is not a number") from None
            if isinstance(v, float) and not math.isfinite(v):
                raise ValueError(f"{s.label or s.name}: {text!r} is not a number")
        else:
            v = text
        try:
            return s.check(v)
        except SettingsError as exc:
            raise ValueError(str(exc)) from None


class SettingsForm(QWidget):
    edited = Signal(str, object)

    def __init__(self, parent=None):
        super().__init__(parent)
        self.setObjectName("settings_form")
        outer = QVBoxLayout(self)
        outer.setContentsMargins(4, 4, 4, 4)
        self.title = QLabel("Settings for new jobs")
        self.title.setObjectName("settings_title")
        self.title.setStyleSheet("font-weight: bold;")
        self.title.setWordWrap(True)
        outer.addWidget(self.title)
        # problems with a typed value: a fixed two-line place, so nothing jumps
        self.problem = QLabel("")
        self.problem.setObjectName("settings_problem")
        self.problem.setWordWrap(True)
        self.problem.setStyleSheet("color: #c62828;")
        self.problem.setFixedHeight(2 * self.problem.fontMetrics().lineSpacing() + 4)
        self.fields: dict[str, _Field] = {}
        job = QGroupBox("Job")
        f = QFormLayout(job)
        f.setFieldGrowthPolicy(QFormLayout.AllNonFixedFieldsGrow)
        for key, label, lo, hi in JOB_FIELDS:
            fld = _Field(self, key, None, lo, hi)
            self.fields[key] = fld
            f.addRow(label, fld.w)
        outer.addWidget(job)
        by_name = {s.name: s for s in SETTINGS}
        sections = [(t, [by_name[n] for n in names if n in by_name]) for t, names in SECTIONS]
        rest = [s for s in SETTINGS if all(s.name not in names for _, names in SECTIONS)]
        if rest:
            sections.append(("More", rest))
        for title, settings in sections:
            box = QGroupBox(title)
            f = QFormLayout(box)
            f.setFieldGrowthPolicy(QFormLayout.AllNonFixedFieldsGrow)
            for s in settings:
                fld = _Field(self, key_of(s), s)
                self.fields[fld.key] = fld
                label = (s.label or s.name) + (f" ({UNITS[s.name]})" if s.name in UNITS else
                                               " (mm)" if s.name.endswith("_mm") else "")
                f.addRow(label, fld.w)
            outer.addWidget(box)
        outer.addWidget(self.problem)
        outer.addStretch(1)
        self.setEnabled(True)

    def _emit(self, key: str, value) -> None:
        self.problem.setText("")
        self.edited.emit(key, value)

    def show_problem(self, text: str) -> None:
        self.problem.setText(text)

    def show_jobs(self, jobs: list[dict], title: str, editable: bool = True) -> None:
        """The values of these jobs (mixed where they differ)."""
        for key, fld in self.fields.items():
            values = [effective(j, key) for j in jobs] or [None]
            first = values[0]
            fld.set(MIXED if any(v != first for v in values[1:]) else first)
        self.title.setText(title)
        for fld in self.fields.values():
            fld.w.setEnabled(editable)
        self.problem.setText("")

    def value(self, key: str):
        """What the form shows for `key` (MIXED when mixed)."""
        fld = self.fields[key]
        if fld.mixed:
            return MIXED
        w = fld.w
        if fld.kind == "combo":
            return w.currentData()
        if fld.kind == "check":
            return w.isChecked()
        return fld.parse(w.text().strip()) if w.text().strip() else (
            None if fld.s is not None else None)


def apply_edit(mapping: dict, key: str, value) -> dict:
    """A settings mapping with one edit (None: the setting back to its default); job fields
    are not settings.  The window keeps the defaults for new jobs this way."""
    out = {k: (dict(v) if isinstance(v, dict) else v) for k, v in (mapping or {}).items()}
    if key.startswith("placement."):
        name = key.split(".", 1)[1]
        place = out.setdefault("placement", {})
        if value is None:
            place.pop(name, None)
        else:
            place[name] = value
        if not place:
            del out["placement"]
    elif value is None:
        out.pop(key, None)
    else:
        out[key] = value
    return out


def settings_patch(key: str, value) -> dict:
    """The PATCH body for one edit: {"settings": {...}} or {"copies": N} / {"priority": N}."""
    if key in dict(JOB_FIELDS_KEYS):
        return {key: value}
    if key.startswith("placement."):
        return {"settings": {"placement": {key.split(".", 1)[1]: value}}}
    return {"settings": {key: value}}


def overrides(base: dict, mine: dict) -> dict:
    """The settings of `mine` that differ from a preset's `base` (placement field by field):
    what a job added with that preset sends as its own, so the preset's settings stay the
    server's (a preset changed in its file later applies to what the operator did not
    change).  docs/gui.md "Presets"."""
    out = {k: v for k, v in mine.items() if k != "placement" and base.get(k) != v}
    place, base_place = mine.get("placement") or {}, base.get("placement") or {}
    diff = {k: v for k, v in place.items() if base_place.get(k) != v}
    if diff:
        out["placement"] = diff
    return out
