"""`wideprint queue`: the print server's queue."""

from __future__ import annotations

import json

from ..client import ApiError
from .common import EXIT_OK
from .remote import _age, _client, _client_parser, _fail


def cmd_queue(args) -> int:
    try:
        client = _client(args)
        states = None if args.all else "queued,held,printing"
        if args.state:
            states = args.state
        jobs = client.jobs(states)
    except ApiError as exc:
        return _fail("queue", exc)
    if args.json:
        print(json.dumps(jobs, indent=2))
        return EXIT_OK
    if not jobs:
        print("the queue is empty" + ("" if args.all else " (--all shows finished jobs)"))
        return EXIT_OK
    from ..safe_text import safe
    print(f"{'ID':>6} {'STATE':9} {'POS':>4} {'PRI':>4} {'STROKES':>9} {'COPIES':>6} "
          f"{'PRESET':10} {'SOURCE':12} {'SUBMITTED':9} NAME / MESSAGE")
    for j in jobs:
        strokes = f"{j['strokes_done']}/{j['strokes_total']}" if j["strokes_total"] else ""
        print(f"{j['id']:>6} {j['state']:9} {j.get('position') or '':>4} {j['priority']:>4} "
              f"{strokes:>9} {j['copies_done']}/{j['copies']:<4} {(j['preset'] or '-'):10.10} "
              f"{safe(j['source']):12.12} {_age(j['submitted']):9} {safe(j['name'])}"
              + (f" (attempt {j['attempt']})" if j.get("attempt", 1) > 1 else "")
              + (f"  [{safe(j['message'])}]" if j["message"] else ""))
    return EXIT_OK


def add_parser(sub) -> None:
    p = _client_parser(sub, "queue", "list the print server's queue")
    p.add_argument("--all", action="store_true", help="finished jobs too")
    p.add_argument("--state", help="only these states, e.g. failed or queued,held")
    p.add_argument("--json", action="store_true")
    p.set_defaults(func=cmd_queue)
