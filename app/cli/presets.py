"""`wideprint presets [--reload]`: the print server's settings presets."""

from __future__ import annotations

import json
import sys

from ..client import ApiError
from .common import EXIT_OK
from .remote import _age, _client, _client_parser, _fail


def cmd_presets(args) -> int:
    try:
        client = _client(args)
        if args.reload:
            r = client.reload_presets()
            changes = "; ".join(f"{k} {', '.join(r[k])}" for k in ("added", "removed", "changed")
                                if r[k])
            # the server also re-reads a changed file by itself: then this finds nothing new
            print(f"re-read {r['file']}: "
                  + (changes or f"no change (the presets in use date from {_age(r['loaded'])})"),
                  file=sys.stderr if args.json else sys.stdout)
        else:
            r = client.presets()
    except ApiError as exc:
        return _fail("presets", exc)
    if r.get("error"):                     # changed on disk but broken: these are the old ones
        print(f"wideprint presets: {r['error']}", file=sys.stderr)
    if args.json:
        print(json.dumps(r["presets"], indent=2))
        return EXIT_OK
    for name, settings in sorted(r["presets"].items()):
        print(f"{name:12} " + (", ".join(f"{k}={json.dumps(v)}" for k, v in settings.items())
                               or "(the RIP's defaults)"))
    return EXIT_OK


def add_parser(sub) -> None:
    p = _client_parser(sub, "presets", "the server's settings presets")
    p.add_argument("--reload", action="store_true",
                   help="re-read the presets file now (it is also re-read when it changes)")
    p.add_argument("--json", action="store_true")
    p.set_defaults(func=cmd_presets)
