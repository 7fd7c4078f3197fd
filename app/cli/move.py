"""`wideprint move ID PRINTER`: a job not yet started moved to another printer."""

from __future__ import annotations

from ..client import ApiError
from .common import EXIT_OK
from .remote import _client, _client_parser, _fail


def cmd_move(args) -> int:
    try:
        job = _client(args).move(args.id, args.printer)
    except ApiError as exc:
        return _fail("move", exc)
    print(f"job {job['id']}: printer {job['printer'] or 'any'}")
    return EXIT_OK


def add_parser(sub) -> None:
    p = _client_parser(sub, "move", "move a job not yet started to another printer")
    p.add_argument("id", type=int, metavar="ID")
    p.add_argument("printer", metavar="PRINTER", help="a printer's name, or any")
    p.set_defaults(func=cmd_move)
