"""What the print server's clients (`submit`, `queue`, `status`, ...) share: their client,
how a failure is said, the --state-dir option, the settings given on the command line."""

from __future__ import annotations

import argparse
import sys
import time

from ..client import ApiError, Client
from .common import EXIT_FAILED, EXIT_SERVER


def _client(args) -> Client:
    return Client(args.state_dir, url=getattr(args, "url", None))


def _fail(cmd: str, exc: Exception) -> int:
    print(f"wideprint {cmd}: {exc}", file=sys.stderr)
    if isinstance(exc, ApiError) and exc.status == 0:
        return EXIT_SERVER
    return EXIT_FAILED



def _settings_from(args) -> dict:
    """The print options given on the command line (the settings schema's mapping); the
    server overlays them on the preset and validates them against its printer profile."""
    from ...rip.settings import mapping_from_args
    return mapping_from_args(args)


def _age(t: float | None) -> str:
    return time.strftime("%H:%M:%S", time.localtime(t)) if t else ""



def _state_dir_option(p: argparse.ArgumentParser) -> None:
    p.add_argument("--state-dir", metavar="DIR",
                   help="the server's state directory (default $WIDEPRINT_STATE_DIR, "
                        "/var/lib/wideprint for root, else ~/.local/state/wideprint)")


def _client_parser(sub, name: str, help: str) -> argparse.ArgumentParser:
    p = sub.add_parser(name, help=help)
    _state_dir_option(p)
    p.add_argument("--url", help=argparse.SUPPRESS)
    return p
