"""The roll dialog (docs/gui.md "Rolls"): what the operator loads on a printer - the media
(a name of the media library, app/medialib.py: the server's STATE/media, then the shipped
entries), its length as entered or the roll's label as read, and how much to spare before the
roll-low warning; the width comes from the
printer's paper sensor.  The server keeps the roll and counts every feed off it
(docs/server.md "Rolls")."""

from __future__ import annotations

from pathlib import Path

from PySide6.QtWidgets import (QComboBox, QDialog, QDialogButtonBox, QDoubleSpinBox, QFormLayout,
                               QLabel, QLineEdit)


def media_names(state_dir: Path) -> list[str]:
    """The media library's names (the server's folder, then the shipped ones)."""
    from ..medialib import list_media
    try:
        return [m.name for m in list_media(Path(state_dir) / "media")]
    except (OSError, ValueError):
        return []


class RollDialog(QDialog):
    def __init__(self, printer: str, roll: dict | None, state_dir: Path, parent=None):
        super().__init__(parent)
        self.setObjectName("roll_dialog")
        self.setWindowTitle(f"Roll on printer {printer}")
        f = QFormLayout(self)
        now = ("no roll loaded" if roll is None else
               f"{roll['media']}, " + ("unknown length" if roll.get("remaining_m") is None else
                                       f"{roll['remaining_m']:,.2f} m left"))
        f.addRow("Loaded now:", QLabel(now))
        self.media = QComboBox()
        self.media.setObjectName("roll_media")
        self.media.setEditable(True)
        self.media.addItems(media_names(state_dir))
        if roll is not None:
            self.media.setCurrentText(roll["media"])
        f.addRow("Media:", self.media)
        self.length = QDoubleSpinBox()
        self.length.setObjectName("roll_length")
        self.length.setRange(0.0, 10_000.0)
        self.length.setDecimals(2)
        self.length.setSuffix(" m")
        self.length.setSpecialValueText("unknown")
        self.length.setValue(50.0)
        f.addRow("Length:", self.length)
        self.label = QLineEdit()
        self.label.setObjectName("roll_label")
        self.label.setPlaceholderText("or the roll's label: media=vinyl-300 length=50m")
        f.addRow("Label:", self.label)
        # the roll-low warning comes when the jobs need more than what is left less this
        # (docs/server.md "Rolls: the warning"); the roll's own, else the server's default
        self.spare = QDoubleSpinBox()
        self.spare.setObjectName("roll_spare")
        self.spare.setRange(0.0, 1000.0)
        self.spare.setDecimals(1)
        self.spare.setSuffix(" m")
        self.spare.setValue(float(roll.get("spare_m", 1.0)) if roll is not None else 1.0)
        self.spare.setToolTip("Warn before a job would run off the roll with this much to spare")
        f.addRow("Warn with:", self.spare)
        buttons = QDialogButtonBox(QDialogButtonBox.StandardButton.Ok |
                                   QDialogButtonBox.StandardButton.Cancel)
        buttons.accepted.connect(self.accept)
        buttons.rejected.connect(self.reject)
        f.addRow(buttons)

    def body(self) -> dict:
        """The API's body for the roll loaded (POST /v1/printers/NAME/roll)."""
        spare = round(self.spare.value(), 1)
        if self.label.text().strip():
            return {"label": self.label.text().strip(), "spare_m": spare}
        out: dict = {"media": self.media.currentText().strip(), "spare_m": spare}
        if self.length.value() > 0:
            out["length_m"] = round(self.length.value(), 3)
        return out
