"""`wideprint clear-fault [PRINTER]`: a printer's fault cleared through the print server."""

from __future__ import annotations

from ..client import ApiError
from .common import EXIT_OK
from .remote import _client, _client_parser, _fail


def cmd_clear_fault(args) -> int:
    try:
        client = _client(args)
        printer = args.printer or client.status()["printers"][0]["name"]
        r = client.printer_action(printer, "clear-fault", {"then": "fail" if args.fail else "resume"})
    except ApiError as exc:
        return _fail("clear-fault", exc)
    jobs = ", ".join(str(j) for j in r["jobs"]) or "no job was stopped"
    print(f"printer {r['printer']}: fault cleared; {jobs}"
          + (f" {'resumes' if r['then'] == 'resume' else 'failed'}" if r["jobs"] else ""))
    return EXIT_OK


def add_parser(sub) -> None:
    p = _client_parser(sub, "clear-fault", "a printer's fault cleared: its stopped job resumes "
                       "at its first unfinished stroke (or fails), its queue runs again")
    p.add_argument("printer", nargs="?", metavar="PRINTER", help="default: the first printer")
    p.add_argument("--fail", action="store_true", help="fail the stopped job instead of resuming it")
    p.set_defaults(func=cmd_clear_fault)
