"""`wideprint estop`: the emergency stop of every printing printer."""

from __future__ import annotations

from ..client import ApiError
from .common import EXIT_OK
from .remote import _client, _client_parser, _fail


def cmd_estop(args) -> int:
    try:
        stopped = _client(args).estop()
    except ApiError as exc:
        return _fail("estop", exc)
    print("emergency stop: " + (", ".join(stopped) or "nothing was printing") +
          "; every printer paused")
    return EXIT_OK


def add_parser(sub) -> None:
    p = _client_parser(sub, "estop", "emergency stop: every printing printer stops at once")
    p.set_defaults(func=cmd_estop)
