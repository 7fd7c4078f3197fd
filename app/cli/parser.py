"""The `wideprint` command's parser: each command's module adds its own subparser
(`add_parser(sub)`), in the order `wideprint --help` lists them (docs/cli.md)."""

from __future__ import annotations

import argparse

from . import (acceptance, calibrate, clear_fault, completion, cups, devices, emulator, estop,
               gui, jobs, media, move, presets, prices, print_cmd, printer, quality, queue,
               report, reprint, rip, serve, spot, status, submit, test_print, users)
from ... import __version__

#: the commands in the order of `wideprint --help`; completion comes with the root parser
COMMANDS = (print_cmd, rip, gui, media, spot, serve, submit, queue, jobs, users, status, presets,
            report, reprint, prices, clear_fault, move, estop, cups, completion, acceptance,
            printer, calibrate, quality, devices, test_print, emulator)


def build_parser() -> argparse.ArgumentParser:
    ap = argparse.ArgumentParser(prog="wideprint", description="RIP and driver for the "
                                 "3.4 m CMYK solvent printer (8 x Xaar XJ128), with its emulator.")
    ap.add_argument("--version", action="version", version=f"wideprint {__version__}")
    ap.add_argument("-v", "--verbose", action="store_true")
    sub = ap.add_subparsers(dest="command", required=True)
    for command in COMMANDS:
        if command is completion:
            command.add_parser(sub, ap)
        else:
            command.add_parser(sub)
    return ap
