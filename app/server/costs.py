"""The price list and what things cost (docs/server.md "Prices and costs"): ink per ml per
colour, media per m² (per media library name, with a default), machine time per hour.  It
turns every estimate into a quote and every accounting row into a cost:

    ink    = sum over c, m, y, k of ink_ml[colour] x ink_per_ml[colour]
    media  = area_m2 x media_per_m2[media]  (the media of the roll it printed on; the
             area printed - a copy that printed no stroke costs no media)
    time   = duration_s / 3600 x machine_per_hour
    cost   = ink + media + time

The list is the state directory's prices.json, written whole by `PUT /v1/prices` (or
`wideprint prices --set`), read at every use (one small file).  Its fields are declared
once here (`FIELDS`); docs/server.md's table is checked against them (tests/test_costs.py).
"""

from __future__ import annotations

import json
import os
from pathlib import Path

from .validate import Invalid

PRICES_FILE = "prices.json"
COLOURS = ("c", "m", "y", "k")

# field: (default, doc) - the price list's every field once
FIELDS: dict[str, tuple[object, str]] = {
    "currency": ("EUR", "the currency's code (ISO 4217), shown with every cost"),
    "ink_per_ml": ({c: 0.0 for c in COLOURS}, "price of one ml of each ink: {c, m, y, k}"),
    "media_per_m2": ({"default": 0.0}, "price of one m² of each media (library name); "
                     "`default` for a media not listed or no roll loaded"),
    "machine_per_hour": (0.0, "price of one hour of the printer's time (the copy's "
                         "duration, start to end)"),
}


def _money(name: str, v) -> float:
    if isinstance(v, bool) or not isinstance(v, (int, float)) or not 0 <= v <= 1e6:
        raise Invalid(f"{name} must be a price of 0..1,000,000")
    return float(v)


def check(raw) -> dict:
    """A whole price list checked (missing fields take their defaults); Invalid naming
    the field."""
    if not isinstance(raw, dict) or set(raw) - set(FIELDS):
        raise Invalid(f"a price list is an object with some of {', '.join(FIELDS)}")
    out = {k: json.loads(json.dumps(d)) for k, (d, _) in FIELDS.items()}
    if "currency" in raw:
        cur = raw["currency"]
        if not isinstance(cur, str) or not cur.isalpha() or not 1 <= len(cur) <= 8:
            raise Invalid("currency must be a code of letters, e.g. EUR")
        out["currency"] = cur.upper()
    if "ink_per_ml" in raw:
        ink = raw["ink_per_ml"]
        if not isinstance(ink, dict) or set(ink) - set(COLOURS):
            raise Invalid("ink_per_ml is {c, m, y, k: price per ml}")
        out["ink_per_ml"].update({c: _money(f"ink_per_ml.{c}", v) for c, v in ink.items()})
    if "media_per_m2" in raw:
        med = raw["media_per_m2"]
        if not isinstance(med, dict) or len(med) > 500:
            raise Invalid("media_per_m2 is {MEDIA or default: price per m²}")
        out["media_per_m2"].update({str(m)[:64]: _money(f"media_per_m2.{m}", v)
                                    for m, v in med.items()})
    if "machine_per_hour" in raw:
        out["machine_per_hour"] = _money("machine_per_hour", raw["machine_per_hour"])
    return out


def read(state_dir: Path) -> dict:
    """The price list in use (the defaults, all 0, when none was set)."""
    path = Path(state_dir) / PRICES_FILE
    try:
        raw = json.loads(path.read_text())
    except FileNotFoundError:
        return check({})
    except (OSError, ValueError) as exc:
        raise Invalid(f"{path}: {exc}", 500) from None
    try:
        return check(raw)
    except Invalid as exc:
        raise Invalid(f"{path}: {exc}", 500) from None


def write(state_dir: Path, raw) -> dict:
    """Check and store a new price list (whole, atomically)."""
    prices = check(raw)
    path = Path(state_dir) / PRICES_FILE
    tmp = path.with_name(f".{PRICES_FILE}.tmp")
    with open(tmp, "w") as f:
        json.dump(prices, f, indent=2, sort_keys=True)
        f.write("\n")
        f.flush()
        os.fsync(f.fileno())
    os.replace(tmp, path)
    return prices


def media_price(prices: dict, media: str | None) -> float:
    table = prices["media_per_m2"]
    return float(table.get(media or "", table.get("default", 0.0)))


def cost(prices: dict, ink_ml, area_m2: float, duration_s: float, media: str | None) -> dict:
    """{ink, media, time, total} for ink per colour (ml), area printed, time taken."""
    ink = sum(float(v) * prices["ink_per_ml"][c] for c, v in zip(COLOURS, ink_ml))
    med = float(area_m2) * media_price(prices, media)
    tim = float(duration_s) / 3600.0 * prices["machine_per_hour"]
    return dict(ink=round(ink, 4), media=round(med, 4), time=round(tim, 4),
                total=round(ink + med + tim, 4), currency=prices["currency"])


def print_cost(prices: dict, row: dict) -> dict:
    """An accounting row's cost."""
    return cost(prices, [row[f"ink_{c}_ml"] for c in COLOURS], row["area_m2"],
                row["duration_s"], row.get("media"))


def quote(prices: dict, estimate: dict, media: str | None) -> dict:
    """An estimate's quote (all copies): the preview's `all_copies` figures."""
    return dict(cost(prices, estimate["ink_ml"], estimate["area_m2"], estimate["time_s"], media),
                media_name=media)


def totals(prices: dict, rows: list[dict]) -> dict:
    """The sum of the rows' costs, and their area and ink."""
    out = dict(ink=0.0, media=0.0, time=0.0, total=0.0, area_m2=0.0, ink_ml=0.0, prints=len(rows))
    for r in rows:
        c = print_cost(prices, r)
        for k in ("ink", "media", "time", "total"):
            out[k] += c[k]
        out["area_m2"] += float(r["area_m2"])
        out["ink_ml"] += sum(float(r[f"ink_{c}_ml"]) for c in COLOURS)
    return {k: (round(v, 4) if isinstance(v, float) else v) for k, v in out.items()} | \
        dict(currency=prices["currency"])
