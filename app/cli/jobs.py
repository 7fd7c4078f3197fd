"""`wideprint cancel|hold|release|requeue ID...`: jobs of the print server's queue."""

from __future__ import annotations

import sys

from ..client import ApiError
from .common import EXIT_FAILED, EXIT_OK
from .remote import _client, _client_parser, _fail


def _job_action(what: str):
    def cmd(args) -> int:
        from ..safe_text import safe
        try:
            client = _client(args)
            rc = EXIT_OK
            for job_id in args.ids:
                try:
                    if what == "cancel":
                        # exit 0 only for a job that is cancelled (docs/server.md "The API")
                        job = client.cancel(job_id, timeout=args.timeout)
                        if job["state"] != "cancelled":
                            print(f"wideprint cancel: job {job['id']} is {job['state']}"
                                  + (f" {args.timeout:g} s after the cancel: the printer has "
                                     f"not stopped yet (still printing); run cancel again "
                                     f"or see `wideprint queue`" if job["state"] == "printing"
                                     else ""), file=sys.stderr)
                            rc = EXIT_FAILED
                            continue
                    elif what == "release" and args.force:
                        job = client.release(job_id, force=True)
                    elif what == "hold" and args.rip:
                        job = client.rip_hold(job_id)
                    else:
                        job = client.action(job_id, what)
                    print(f"job {job['id']}: {job['state']}"
                          + (f" ({safe(job['message'])})" if job["message"] else ""))
                except ApiError as exc:
                    if exc.status == 0:
                        raise
                    print(f"wideprint {what}: {exc}", file=sys.stderr)
                    rc = EXIT_FAILED
            return rc
        except ApiError as exc:
            return _fail(what, exc)
    return cmd


def add_parser(sub) -> None:
    for name, help in (("cancel", "cancel jobs (a printing job stops at once)"),
                       ("hold", "hold queued jobs"), ("release", "release held jobs"),
                       ("requeue", "put failed or cancelled jobs back in the queue "
                                   "(they print again from the start)")):
        p = _client_parser(sub, name, help)
        p.add_argument("ids", nargs="+", type=int, metavar="ID")
        if name == "release":
            p.add_argument("--force", action="store_true", help="past the fit checks (a job "
                           "held because the roll is too short: the operator knows better)")
        if name == "hold":
            p.add_argument("--rip", action="store_true", help="and RIP them ahead: their "
                           "release prints the kept planes without ripping again")
        if name == "cancel":
            p.add_argument("--timeout", type=float, default=60.0, metavar="S",
                           help="wait at most this long for a printing job to stop (default "
                                "60 s); exit 1 if it has not")
        p.set_defaults(func=_job_action(name))
