"""`wideprint report`: the accounting, one row per printed copy, and `--costs`."""

from __future__ import annotations

import json
from pathlib import Path

from ..client import ApiError
from .common import EXIT_OK
from .remote import _client, _client_parser, _fail


def _report_costs(client, args) -> int:
    """`report --costs`: every printed copy with its cost at the server's price list, and
    the totals."""
    if args.csv:
        text = client.report_csv(args.job, costs=True)
        Path(args.csv).write_text(text)
        print(f"{args.csv}: {text.count(chr(10)) - 1} prints, with costs")
        return EXIT_OK
    r = client.report_costs(args.job)
    if args.json:
        print(json.dumps(r, indent=2))
        return EXIT_OK
    cur = r["prices"]["currency"]
    print(f"{'JOB':>5} {'COPY':>4} {'OUTCOME':9} {'M2':>8} {'INK ML':>9} {'SECONDS':>8} "
          f"{'INK':>9} {'MEDIA':>9} {'TIME':>9} {'COST':>10}  FILE")
    for p in r["prints"]:
        c = p["cost"]
        ink = sum(p[f"ink_{k}_ml"] for k in "cmyk")
        print(f"{p['job_id']:>5} {p['copy']:>4} {p['outcome']:9} {p['area_m2']:8.4f} "
              f"{ink:9.4f} {p['duration_s']:8.1f} {c['ink']:9.4f} {c['media']:9.4f} "
              f"{c['time']:9.4f} {c['total']:10.4f}  {p['file']}")
    t = r["totals"]
    print(f"total: {t['prints']} prints, {t['area_m2']:.4f} m², {t['ink_ml']:.4f} ml ink; "
          f"ink {t['ink']:.4f} + media {t['media']:.4f} + time {t['time']:.4f} = "
          f"{t['total']:.4f} {cur}")
    return EXIT_OK


def cmd_report(args) -> int:
    try:
        client = _client(args)
        if args.costs:
            return _report_costs(client, args)
        text = client.report_csv(args.job)
    except ApiError as exc:
        return _fail("report", exc)
    if args.csv:
        Path(args.csv).write_text(text)
        print(f"{args.csv}: {text.count(chr(10)) - 1} prints")
        return EXIT_OK
    if args.json:
        print(json.dumps(client.report(args.job), indent=2))
        return EXIT_OK
    import csv
    import io
    rows = list(csv.DictReader(io.StringIO(text)))
    print(f"{'JOB':>5} {'COPY':>4} {'OUTCOME':9} {'STROKES':>7} {'M2':>9} {'INK ML':>10} "
          f"{'SECONDS':>8}  FILE")
    for r in rows:
        print(f"{r['job_id']:>5} {r['copy']:>4} {r['outcome']:9} "
              f"{r['strokes_printed'] + '/' + r['strokes_total']:>7} {float(r['area_m2']):9.4f} "
              f"{float(r['ink_total_ml']):10.5f} {float(r['duration_s']):8.1f}  {r['file']}")
    return EXIT_OK


def add_parser(sub) -> None:
    p = _client_parser(sub, "report", "accounting: one row per printed copy")
    p.add_argument("--csv", metavar="FILE", help="write the CSV here")
    p.add_argument("--json", action="store_true")
    p.add_argument("--job", type=int, metavar="ID")
    p.add_argument("--costs", action="store_true", help="each copy's cost (ink, media, "
                   "machine time) at the server's price list, and the totals")
    p.set_defaults(func=cmd_report)
