"""`wideprint gui`: the operator GUI (PySide6).  docs/gui.md describes it.

    main(argv) -> exit code;  argv: [FILE ...] [--config-dir DIR] [--device SPEC]
"""

from __future__ import annotations

import argparse
import logging
import sys


def build_parser() -> argparse.ArgumentParser:
    ap = argparse.ArgumentParser(prog="wideprint gui", description="The wideprint operator GUI.")
    ap.add_argument("files", nargs="*", metavar="FILE", help="images (or folders) to put in the queue")
    ap.add_argument("--config-dir", metavar="DIR",
                    help="settings and the user printer profile (default: the platform's user config dir)")
    ap.add_argument("--device", metavar="SPEC", help="device spec ('emulator' or serial=PORT,data=tcp://HOST:PORT)")
    ap.add_argument("-v", "--verbose", action="store_true", help="debug messages in the log")
    return ap


def main(argv: list[str] | None = None) -> int:
    args = build_parser().parse_args(sys.argv[1:] if argv is None else argv)
    import os
    if not (os.environ.get("DISPLAY") or os.environ.get("WAYLAND_DISPLAY")
            or os.environ.get("QT_QPA_PLATFORM")):
        # Qt would abort (SIGABRT) with a long message about platform plugins
        print("wideprint gui: no display (DISPLAY and WAYLAND_DISPLAY are unset); run it on a "
              "desktop, under xvfb-run, or with QT_QPA_PLATFORM=offscreen", file=sys.stderr)
        return 2
    try:
        from PySide6.QtWidgets import QApplication
    except ImportError as exc:  # pragma: no cover - depends on the installation
        print(f"wideprint gui: PySide6 is not installed ({exc}); pip install 'wideprint[gui]'",
              file=sys.stderr)
        return 2
    from .main_window import MainWindow

    logging.getLogger("wideprint").setLevel(logging.DEBUG if args.verbose else logging.INFO)
    app = QApplication.instance() or QApplication(["wideprint"])
    app.setApplicationName("wideprint")
    app.setOrganizationName("wideprint")
    win = MainWindow(config_dir=args.config_dir)
    if args.device:
        win.device.spec.setText(args.device)
        win._device_config_changed()
    if args.files:
        win.add_files(args.files)
    win.show()
    return int(app.exec())


__all__ = ["main"]
