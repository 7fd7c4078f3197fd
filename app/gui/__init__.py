"""`wideprint gui`: the operator GUI (PySide6).  docs/gui.md describes it.

    main(argv) -> exit code;  argv: [FILE ...] [--state-dir DIR] [--device SPEC] [--config-dir DIR]
"""

from __future__ import annotations

import argparse
import logging
import sys


def add_arguments(ap: argparse.ArgumentParser) -> None:
    """The GUI's options, for `wideprint gui` (app/cli/gui.py) and `python -m` alike."""
    ap.add_argument("files", nargs="*", metavar="FILE", help="files (or folders) to send to the queue")
    ap.add_argument("--state-dir", metavar="DIR",
                    help="the print server's state directory (default: $WIDEPRINT_STATE_DIR, "
                         "else the user's state dir)")
    ap.add_argument("--device", metavar="SPEC",
                    help="the printer of a server the GUI starts (default: the last one used, "
                         "first 'emulator'); a running server keeps its own")
    ap.add_argument("--config-dir", metavar="DIR",
                    help="the GUI's own settings (default: $WIDEPRINT_CONFIG_DIR, else the user's "
                         "config dir)")
    ap.add_argument("-v", "--verbose", dest="verbose_gui", action="store_true",
                    help="debug messages in the log")


def build_parser() -> argparse.ArgumentParser:
    ap = argparse.ArgumentParser(
        prog="wideprint gui",
        description="The wideprint operator GUI: a client of the print server of this machine "
                    "(started in the background when none runs); FILEs go to its queue.")
    add_arguments(ap)
    return ap


def binding_defect(pyside: str, python: tuple = sys.version_info[:2]) -> str | None:
    """Why this PySide6 will not run all day on this Python, or None (docs/gui.md "Which
    PySide6"): 6.12.0 loses a reference to True/None on every signal emission, fatal within
    minutes where those objects are mortal (Python < 3.12)."""
    if pyside == "6.12.0" and tuple(python) < (3, 12):
        return (f"PySide6 {pyside} on Python {python[0]}.{python[1]} loses a reference to True/None "
                "on every signal emission and aborts after minutes of server events; install the "
                "pinned version: pip install -c constraints.txt 'PySide6-Essentials==6.11.3'")
    return None


def main(argv: list[str] | None = None) -> int:
    return run(build_parser().parse_args(sys.argv[1:] if argv is None else argv))


def run(args: argparse.Namespace) -> int:
    import os
    if not (os.environ.get("DISPLAY") or os.environ.get("WAYLAND_DISPLAY")
            or os.environ.get("QT_QPA_PLATFORM")):
        # Qt would abort (SIGABRT) with a long message about platform plugins
        print("wideprint gui: no display (DISPLAY and WAYLAND_DISPLAY are unset); run it on a "
              "desktop, under xvfb-run, or with QT_QPA_PLATFORM=offscreen", file=sys.stderr)
        return 2
    try:
        from PySide6.QtWidgets import QApplication, QMessageBox
    except ImportError as exc:  # pragma: no cover - depends on the installation
        print(f"wideprint gui: PySide6 is not installed ({exc}); pip install 'wideprint[gui]'",
              file=sys.stderr)
        return 2
    from pathlib import Path

    import PySide6
    why = binding_defect(PySide6.__version__)
    if why:
        print(f"wideprint gui: warning: {why}", file=sys.stderr)
        logging.getLogger("wideprint.gui").warning("%s", why)

    from ..server.config import default_state_dir
    from .config import GuiSettings, SETTINGS_FILE, default_config_dir
    from .main_window import MainWindow
    from .server_link import ServerLink, find_or_start

    logging.getLogger("wideprint").setLevel(logging.DEBUG if args.verbose_gui else logging.INFO)
    app = QApplication.instance() or QApplication(["wideprint"])
    app.setApplicationName("wideprint")
    app.setOrganizationName("wideprint")
    config_dir = Path(args.config_dir) if args.config_dir else default_config_dir()
    gs = GuiSettings.load(config_dir / SETTINGS_FILE)
    if args.device:
        gs.device_spec = args.device
        gs.save(config_dir / SETTINGS_FILE)
    state_dir = Path(args.state_dir) if args.state_dir else default_state_dir()
    try:
        client, proc = find_or_start(state_dir, gs.device_spec, media_dir=state_dir / "printed")
    except RuntimeError as exc:
        print(f"wideprint gui: {exc}", file=sys.stderr)
        QMessageBox.critical(None, "wideprint", str(exc))
        return 1
    link = ServerLink(state_dir, client)
    win = MainWindow(link, config_dir=config_dir, started_server=proc)
    if args.files:
        win.add_files(args.files)
    win.show()
    return int(app.exec())


__all__ = ["add_arguments", "main", "run"]
