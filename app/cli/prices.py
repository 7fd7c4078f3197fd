"""`wideprint prices [--set FILE]`: the price list of the print server."""

from __future__ import annotations

import json
from pathlib import Path

from ..client import ApiError
from .common import EXIT_OK
from .remote import _client, _client_parser, _fail


def cmd_prices(args) -> int:
    """`wideprint prices [--set FILE]`: the server's price list (docs/server.md "Prices and
    costs")."""
    try:
        client = _client(args)
        if args.set:
            text = Path(args.set).read_text()
            if args.set.endswith(".toml"):
                import tomllib
                new = tomllib.loads(text)
            else:
                new = json.loads(text)
            prices = client.prices(new)
        else:
            prices = client.prices()
    except (ApiError, OSError, ValueError) as exc:
        return _fail("prices", exc)
    if args.json:
        print(json.dumps(prices, indent=2))
        return EXIT_OK
    cur = prices["currency"]
    print("ink per ml:      " + ", ".join(f"{c.upper()} {v:g}" for c, v in
                                          prices["ink_per_ml"].items()) + f" {cur}")
    print("media per m²:    " + ", ".join(f"{m} {v:g}" for m, v in
                                          sorted(prices["media_per_m2"].items())) + f" {cur}")
    print(f"machine per hour: {prices['machine_per_hour']:g} {cur}")
    return EXIT_OK


def add_parser(sub) -> None:
    p = _client_parser(sub, "prices", "the price list that turns estimates into quotes and "
                       "prints into costs")
    p.add_argument("--set", metavar="FILE", help="a new price list (JSON or TOML: currency, "
                   "ink_per_ml, media_per_m2, machine_per_hour)")
    p.add_argument("--json", action="store_true")
    p.set_defaults(func=cmd_prices)
