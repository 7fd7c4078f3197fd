"""`wideprint submit FILE...`: files sent to the print server's queue."""

from __future__ import annotations

import json
import os
import sys
from pathlib import Path

from ..client import ApiError
from .common import EXIT_FAILED, EXIT_OK, EXIT_SERVER, EXIT_USAGE, _media_path, progress
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


def _cut_settings(args) -> tuple[dict, str | None]:
    """The command line's settings and, with --cut-out, the cut file's route ("plt" or
    "dxf", by its name): a print-and-cut job prints the cutter's marks (`marks cut`)
    unless --marks asks for others (docs/cut.md "Through the print server")."""
    settings = _settings_from(args)
    if not getattr(args, "cut_out", None):
        return settings, None
    from ...rip.cutfile import cut_format
    route = "dxf" if cut_format(args.cut_out) == "dxf" else "plt"
    placement = dict(settings.get("placement") or {})
    placement.setdefault("marks", "cut")
    return dict(settings, placement=placement), route


def _fetch_cut(client, job: dict, route: str, out: str) -> str | None:
    """A done job's cut file from the server, written to `out`; the reason when there is
    none to write (not a print-and-cut job, or no path in a cut colour)."""
    from ...rip.cutfile import parse_hpgl
    try:
        data = client.cut_file(job["id"], route)
        paths = client.cut_file(job["id"], "plt") if route == "dxf" else data
    except ApiError as exc:
        return str(exc)
    if not parse_hpgl(paths.decode("ascii", "replace"))[0]:
        return (f"job {job['id']} has no cut paths: nothing in its file is drawn in a cut spot "
                f"colour (CutContour, Thru-cut, ... or $WIDEPRINT_CUT_NAMES, docs/cut.md); "
                f"{out} not written")
    tmp = f"{out}.part"
    with open(tmp, "wb") as fh:
        fh.write(data)
    os.replace(tmp, out)
    return None


def cmd_submit(args) -> int:
    try:
        settings, cut_route = _cut_settings(args)
    except ValueError as exc:                        # --cut-out with another extension
        print(f"submit: {exc}", file=sys.stderr)
        return EXIT_USAGE
    try:
        client = _client(args)
    except ApiError as exc:
        return _fail("submit", exc)
    files = _expand(args.files)
    results, failed = [], 0
    for i, f in enumerate(files):
        try:
            r = client.submit(f, preset=args.preset, copies=args.copies, priority=args.priority,
                              hold=args.hold or None, settings=settings or None,
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
    wait = args.wait or (3600.0 if cut_route else None)     # a cut file comes once it printed
    if wait and not failed:
        for i, job in enumerate(results):
            done = client.wait(job["id"], timeout=wait)
            print(f"job {done['id']}: {done['state']}" + (f": {done['message']}" if done["message"] else ""),
                  file=sys.stderr if args.json else sys.stdout)
            if done["state"] != "done":
                failed += 1
                continue
            if cut_route:                                # docs/cut.md "Through the print server"
                out = _media_path(args.cut_out, i, len(results)) or args.cut_out
                why = _fetch_cut(client, done, cut_route, out)
                if why:
                    failed += 1
                    print(f"{files[i]}: {why}", file=sys.stderr)
                elif not args.json:
                    print(f"{files[i]}: cut file {out}")
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
    p.add_argument("--cut-out", metavar="CUT.plt",
                   help="print and cut: once the job has printed, fetch its cut file from the "
                   "server and write it here, .plt/.hpgl (HP-GL/2) or .dxf; turns on --marks cut "
                   "unless other marks are asked for, and waits as --wait does (exit 1 when the "
                   "job has no cut paths; docs/cut.md; with several files: -N suffix or {job})")
    # every print option of `wideprint print`, from the one settings schema; ICC profiles
    # are named from the server's icc/ folder
    add_settings_arguments(p)
    p.set_defaults(func=cmd_submit)
