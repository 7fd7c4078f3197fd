"""`wideprint status [--pause|--resume]`: the print server, its printers and current job."""

from __future__ import annotations

import json
import time

from ..client import ApiError
from .common import EXIT_OK
from .remote import _client, _client_parser, _fail


def cmd_status(args) -> int:
    try:
        client = _client(args)
        if args.pause or args.resume:
            client.pause_queue(bool(args.pause))
        st = client.status()
    except ApiError as exc:
        return _fail("status", exc)
    if args.json:
        print(json.dumps(st, indent=2))
        return EXIT_OK
    s, q, p, cur = st["server"], st["queue"], st["printer"], st["current"]
    print(f"server   {s['url']}  pid {s['pid']}  up {time.time() - s['started']:.0f} s  "
          f"device {s['device']}  on crash: {s['on_crash']}")
    for pr in st.get("printers") or [dict(name="main", state=p["state"], error=p["error"],
                                           paused=q["paused"], reason=q["reason"], current=cur)]:
        pc = pr["current"]
        print(f"printer  {pr['name']}: {pr['state']}" + (f": {pr['error']}" if pr["error"] else "")
              + (f"  [paused: {pr['reason']}]" if pr["paused"] else "")
              + (f"  job {pc['id']} {pc['name']} stroke {pc['strokes_printed']}/{pc['strokes_total']}"
                 if pc else ""))
        for w in pr.get("warnings") or []:       # docs/server.md "Rolls: the warning"
            print(f"         WARNING: {w['message']}")
    counts = ", ".join(f"{k} {v}" for k, v in q["counts"].items())
    print(f"queue    {'PAUSED (' + q['reason'] + ')' if q['paused'] else 'running'}; {counts}")
    pr = st.get("presets")
    if pr:
        print(f"presets  {', '.join(pr['names'])} ({pr['file']})"
              + (f"; NOT RE-READ: {pr['error']}" if pr["error"] else ""))
    if cur:
        print(f"current  job {cur['id']} {cur['name']}: {cur['state']}"
              f"{' ' + cur['detail'] if cur['detail'] else ''}, stroke "
              f"{cur['strokes_printed']}/{cur['strokes_total']}, copy {cur['copy']}/{cur['copies']}"
              + (" (resumed)" if cur.get("resumed") else ""))
    return EXIT_OK


def add_parser(sub) -> None:
    p = _client_parser(sub, "status", "the print server, printer and current job")
    p.add_argument("--json", action="store_true")
    g = p.add_mutually_exclusive_group()
    g.add_argument("--pause", action="store_true", help="pause the queue (no new job starts)")
    g.add_argument("--resume", action="store_true", help="resume the queue")
    p.set_defaults(func=cmd_status)
