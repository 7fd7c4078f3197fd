"""No form field changes under a passing mouse wheel (issue 34): a combo box, spin box or
slider takes wheel events only when it has the keyboard focus (clicked into or tabbed to);
otherwise the wheel goes on to what is under it (the settings form scrolls).  The usual Qt
fix: Qt.StrongFocus, so the wheel does not give the focus either, and an event filter that
ignores the wheel of an unfocused field (an ignored wheel event propagates to the parent)."""

from __future__ import annotations

from PySide6.QtCore import QEvent, QObject, Qt
from PySide6.QtWidgets import QAbstractSlider, QAbstractSpinBox, QComboBox, QWidget

FIELDS = (QComboBox, QAbstractSpinBox, QAbstractSlider)


class _WheelGuard(QObject):
    def eventFilter(self, obj, ev) -> bool:       # noqa: N802 - Qt's name
        if ev.type() == QEvent.Type.Wheel and isinstance(obj, QWidget) and not obj.hasFocus():
            ev.ignore()
            return True
        return False


_GUARD: _WheelGuard | None = None


def guard_wheel(root: QWidget) -> int:
    """Every field under `root` (and `root` itself): StrongFocus and the wheel guard.
    Call it again for fields created later; a field is guarded once.  Returns how many
    fields were guarded now."""
    global _GUARD
    if _GUARD is None:
        _GUARD = _WheelGuard()
    found = [root] if isinstance(root, FIELDS) else []
    for t in FIELDS:
        found.extend(root.findChildren(t))
    n = 0
    for w in found:
        if w.property("wheel_guarded"):
            continue
        w.setProperty("wheel_guarded", True)
        w.setFocusPolicy(Qt.FocusPolicy.StrongFocus)
        w.installEventFilter(_GUARD)
        n += 1
    return n


__all__ = ["guard_wheel"]
