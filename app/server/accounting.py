"""Accounting: one row per printed copy, as CSV (docs/server.md, "Accounting")."""

from __future__ import annotations

import csv
import io
import json
import logging
import time

from .spool import COLORS
from ...rip.settings import setting

DEFAULT_DITHER = setting("dither").default     # a job that named none was printed with it

log = logging.getLogger("wideprint.server")


CSV_COLUMNS = ["print_id", "job_id", "copy", "file", "source", "preset", "settings", "dpi",
               "passes", "bidir", "dither", "started", "ended", "duration_s",
               "strokes_total", "strokes_printed", "width_dots", "height_rows", "area_m2",
               "drops_c", "drops_m", "drops_y", "drops_k",
               "ink_c_ml", "ink_m_ml", "ink_y_ml", "ink_k_ml", "ink_total_ml",
               "outcome", "message", "resumed", "recoveries", "retries", "attempt",
               "printer", "media", "paper_mm", "spots"]
# with costs (`report --costs`, docs/server.md "Prices and costs"): these after them
COST_COLUMNS = ["cost_ink", "cost_media", "cost_time", "cost_total", "currency"]


def _iso(t: float) -> str:
    return time.strftime("%Y-%m-%dT%H:%M:%S", time.gmtime(t)) + f".{int(t % 1 * 1000):03d}Z"


def prints_csv(rows: list[dict], prices: dict | None = None) -> str:
    """The accounting CSV; with `prices` (costs.py) each row's cost after its columns."""
    from .costs import print_cost
    out = io.StringIO()
    w = csv.writer(out, lineterminator="\n")
    w.writerow(CSV_COLUMNS + (COST_COLUMNS if prices is not None else []))
    for r in rows:
        more = []
        if prices is not None:
            c = print_cost(prices, r)
            more = [f"{c['ink']:.4f}", f"{c['media']:.4f}", f"{c['time']:.4f}",
                    f"{c['total']:.4f}", c["currency"]]
        s = json.loads(r["settings"])
        ink = [r[f"ink_{c}_ml"] for c in COLORS]
        w.writerow([r["id"], r["job_id"], r["copy"], r["file"], r["source"], r["preset"] or "",
                    r["settings"], s.get("dpi", 300), s.get("passes", 1),
                    int(bool(s.get("bidir", False))), s.get("dither", DEFAULT_DITHER),
                    _iso(r["started"]), _iso(r["ended"]), f"{r['duration_s']:.3f}",
                    r["strokes_total"], r["strokes_printed"], r["width_dots"], r["height_rows"],
                    f"{r['area_m2']:.10f}", *(r[f"drops_{c}"] for c in COLORS),
                    *(f"{v:.9f}" for v in ink), f"{sum(ink):.9f}",
                    r["outcome"], r["message"], r["resumed"], r["recoveries"], r["retries"],
                    r["attempt"], r.get("printer") or "", r.get("media") or "",
                    f"{float(r.get('paper_mm') or 0):.1f}",
                    json.dumps(r["spots"], ensure_ascii=False) if r.get("spots") else "", *more])
    return out.getvalue()
