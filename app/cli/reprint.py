"""`wideprint reprint ID...`: finished jobs printed again from the archive."""

from __future__ import annotations

import json
import sys

from ..client import ApiError
from .common import EXIT_FAILED, EXIT_OK, EXIT_SERVER
from .remote import _client, _client_parser, _fail, _settings_from


def _set_values(items: list[str] | None) -> dict:
    """--set KEY=VALUE (repeated) as a partial settings mapping: VALUE as JSON when it is
    JSON (numbers, true, null), else a string; placement.KEY for a placement setting."""
    out: dict = {}
    for item in items or []:
        key, eq, text = item.partition("=")
        if not eq or not key:
            raise ValueError(f"--set {item!r}: expected KEY=VALUE (e.g. dpi=600, "
                             f"placement.rotate=90)")
        try:
            value = json.loads(text)
        except ValueError:
            value = text
        if key.startswith("placement."):
            out.setdefault("placement", {})[key[len("placement."):]] = value
        else:
            out[key] = value
    return out


def cmd_reprint(args) -> int:
    """`wideprint reprint ID...`: finished jobs printed again from the archive
    (docs/server.md "Archive and reprint")."""
    from ..safe_text import safe
    try:
        client = _client(args)
        change: dict = {}
        settings = dict(_settings_from(args) or {})
        more = _set_values(args.set)
        if "placement" in more and "placement" in settings:
            more["placement"] = dict(settings["placement"], **more["placement"])
        settings.update(more)
        if settings:
            change["settings"] = settings
        for key in ("copies", "priority", "printer"):
            if getattr(args, key) is not None:
                change[key] = getattr(args, key)
        if args.hold:
            change["hold"] = True
        if args.force:
            change["force"] = True
    except (ApiError, ValueError) as exc:
        return _fail("reprint", exc)
    rc = EXIT_OK
    for job_id in args.ids:
        try:
            job = client.reprint(job_id, **change)
        except ApiError as exc:
            print(f"wideprint reprint: job {job_id}: {exc}", file=sys.stderr)
            if exc.status == 0:
                return EXIT_SERVER
            rc = EXIT_FAILED
            continue
        print(f"job {job_id}: reprinted as job {job['id']} ({safe(job['name'])}) {job['state']}")
        if args.wait:
            done = client.wait(job["id"], timeout=args.wait)
            print(f"job {done['id']}: {done['state']}"
                  + (f": {safe(done['message'])}" if done["message"] else ""))
            rc = rc if done["state"] == "done" else EXIT_FAILED
    return rc


def add_parser(sub) -> None:
    from ...rip.settings import add_arguments as add_settings_arguments
    p = _client_parser(sub, "reprint", "print finished jobs again from the archive, with "
                       "their settings or changed ones")
    p.add_argument("ids", nargs="+", type=int, metavar="ID")
    p.add_argument("--set", action="append", metavar="KEY=VALUE",
                   help="change a setting (repeat; placement.KEY for placement, e.g. "
                        "placement.rotate=90; null: back to automatic)")
    p.add_argument("--copies", type=int)
    p.add_argument("--priority", type=int)
    p.add_argument("--printer", metavar="NAME", help="print it on this printer (or any)")
    p.add_argument("--hold", action="store_true", help="add it held (default: its preset's)")
    p.add_argument("--force", action="store_true", help="even if it does not fit the paper")
    p.add_argument("--wait", type=float, nargs="?", const=3600.0, metavar="S",
                   help="wait until it has printed (exit 1 if it did not)")
    add_settings_arguments(p)
    p.set_defaults(func=cmd_reprint)
