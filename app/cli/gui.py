"""`wideprint gui`: the operator GUI (app/gui/), a client of this machine's print server."""

from __future__ import annotations


def cmd_gui(args) -> int:
    from ..gui import run as gui_run        # it says so if PySide6 is missing
    return gui_run(args)


def add_parser(sub) -> None:
    p = sub.add_parser("gui", help="the operator GUI (PySide6), a client of this machine's print "
                                   "server (started in the background when none runs)")
    from ..gui import add_arguments as add_gui_arguments   # argparse only: --help stays light
    add_gui_arguments(p)
    p.set_defaults(func=cmd_gui)
