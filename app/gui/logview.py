"""The log view: a logging.Handler that hands records to a QPlainTextEdit through a
queued signal, so any thread may log."""

from __future__ import annotations

import logging

from PySide6.QtCore import QObject, Qt, Signal
from PySide6.QtGui import QFontDatabase
from PySide6.QtWidgets import QPlainTextEdit

FORMAT = "%(asctime)s %(levelname)-7s %(name)s: %(message)s"


class _Bridge(QObject):
    record = Signal(str, int)


class QtLogHandler(logging.Handler):
    def __init__(self, level=logging.INFO):
        super().__init__(level)
        self.bridge = _Bridge()
        self.setFormatter(logging.Formatter(FORMAT, "%H:%M:%S"))

    def emit(self, record: logging.LogRecord) -> None:
        try:
            self.bridge.record.emit(self.format(record), record.levelno)
        except RuntimeError:      # the window is gone (shutdown)
            pass
        except Exception:  # noqa: BLE001
            self.handleError(record)


class LogView(QPlainTextEdit):
    COLORS = {logging.WARNING: "#b26a00", logging.ERROR: "#c62828", logging.CRITICAL: "#c62828"}

    def __init__(self, parent=None):
        super().__init__(parent)
        self.setObjectName("log")
        self.setReadOnly(True)
        self.setMaximumBlockCount(5000)
        self.setLineWrapMode(QPlainTextEdit.NoWrap)
        f = QFontDatabase.systemFont(QFontDatabase.FixedFont)
        f.setPointSize(max(8, f.pointSize() - 1))
        self.setFont(f)
        self.handler = QtLogHandler()
        self.handler.bridge.record.connect(self.append_record, Qt.QueuedConnection)

    def append_record(self, text: str, level: int) -> None:
        color = self.COLORS.get(level)
        if color:
            from html import escape
            self.appendHtml(f"<span style='color:{color}'>{escape(text)}</span>")
        else:
            self.appendPlainText(text)
        sb = self.verticalScrollBar()
        sb.setValue(sb.maximum())

    def install(self, logger_name: str = "wideprint") -> None:
        lg = logging.getLogger(logger_name)
        lg.addHandler(self.handler)
        if lg.level == logging.NOTSET or lg.level > logging.INFO:
            lg.setLevel(logging.INFO)

    def uninstall(self, logger_name: str = "wideprint") -> None:
        logging.getLogger(logger_name).removeHandler(self.handler)


__all__ = ["LogView", "QtLogHandler"]
