"""`wideprint submit FILE...`: files sent to the print server's queue."""

from __future__ import annotations

import json
import sys
from pathlib import Path

from ..client import ApiError
from .common import EXIT_FAILED, EXIT_OK, EXIT_SERVER, progress
from .remote import _client, _client_parser, _fail, _settings_from


def _expand(files: list[str]) -> list[Path]:
    out = []
    for f in files:
        p = Path(f)
        if p.is_dir():
            out += sorted(c for c in p.iterdir() if c.is_file() and not c.name.startswith("."))
        else:
            out.append(p)
    return out


def cmd_submit(args) -> int:
    try:
        client = _client(args)
    except ApiError as exc:
        return _fail("submit", exc)
    files = _expand(args.files)
    results, failed = [], 0
    for i, f in enumerate(files):
        try:
            r = client.submit(f, preset=args.preset, copies=args.copies, priority=args.priority,
                              hold=args.hold or None, settings=_settings_from(args) or None,
                              client=args.client, printer=args.printer,
                              force=args.force or None, rip_hold=args.rip_hold or None)
            job = r["job"]
            results.append(job)
            if not args.json:
                print(f"{f}: job {job['id']} {job['state']}"
                      + (" (already submitted)" if r.get("duplicate") else ""))
        except ApiError as exc:
            failed += 1
            results.append({"file": str(f), "error": str(exc)})
            print(f"{f}: REFUSED: {exc}", file=sys.stderr)
            if exc.status == 0:
                return EXIT_SERVER
        except OSError as exc:
            failed += 1
            results.append({"file": str(f), "error": exc.strerror})
            print(f"{f}: {exc.strerror}", file=sys.stderr)
        if len(files) > 3 and not args.json:
            progress(i + 1, len(files), f.name)
    if args.json:
        print(json.dumps(results, indent=2))
    if args.wait and not failed:
        for job in results:
            done = client.wait(job["id"], timeout=args.wait)
            print(f"job {done['id']}: {done['state']}" + (f": {done['message']}" if done["message"] else ""),
                  file=sys.stderr if args.json else sys.stdout)
            if done["state"] != "done":
                failed += 1
    return EXIT_FAILED if failed else EXIT_OK


def add_parser(sub) -> None:
    from ...rip.settings import add_arguments as add_settings_arguments
    p = _client_parser(sub, "submit", "send files to the print server's queue")
    p.add_argument("files", nargs="+", metavar="FILE", help="images or folders")
    p.add_argument("--preset", help="settings preset (the server's presets file)")
    p.add_argument("--copies", type=int)
    p.add_argument("--priority", type=int, help="-100..100, higher prints first (default 0)")
    p.add_argument("--hold", action="store_true", help="queue the job held (default: the "
                   "preset's hold)")
    p.add_argument("--force", action="store_true", help="queue it even if it does not fit the "
                   "paper loaded (too wide, longer than the roll left)")
    p.add_argument("--rip-hold", action="store_true", help="queue it held and RIP it ahead: "
                   "its release prints the kept planes without ripping again")
    p.add_argument("--client", help="a tag for the accounting (default: none)")
    p.add_argument("--printer", metavar="NAME", help="the printer to print on (default: any, the "
                   "first free one)")
    p.add_argument("--json", action="store_true")
    p.add_argument("--wait", type=float, nargs="?", const=3600.0, metavar="S",
                   help="wait until the jobs have printed (exit 1 if any did not)")
    # every print option of `wideprint print`, from the one settings schema; ICC profiles
    # are named from the server's icc/ folder
    add_settings_arguments(p)
    p.set_defaults(func=cmd_submit)
