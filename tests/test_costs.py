"""Prices and costs (issue 34 part 5; docs/server.md "Prices and costs"): a stated price list
turns every accounting row into a cost - ink per ml per colour, media per m² of the roll's
media (the area printed: nothing for a copy that printed no stroke), machine time per hour -
in `wideprint report --costs` (text, CSV, JSON) and the API."""

from __future__ import annotations

import csv
import io
import json
import re
from pathlib import Path

import pytest

from support.images import random_planes, write_cmyk_tiff
from wideprint.app.client import ApiError, Client
from wideprint.app.server import costs
from wideprint.app.server.validate import Invalid

DOCS = Path(__file__).resolve().parent.parent / "docs" / "server.md"

PRICES = {"currency": "EUR", "ink_per_ml": {"c": 0.11, "m": 0.13, "y": 0.07, "k": 0.05},
          "media_per_m2": {"default": 2.0, "vinyl-300": 4.5}, "machine_per_hour": 18.0}


def test_the_price_list_fields_are_declared_once_and_documented():
    section = DOCS.read_text().split("## Prices and costs", 1)[1].split("\n## ", 1)[0]
    rows = re.findall(r"^\| `([a-z_0-9]+)` \| (.+) \|$", section, re.M)
    assert rows == [(k, doc) for k, (_, doc) in costs.FIELDS.items()]
    assert costs.check({})["ink_per_ml"] == {c: 0.0 for c in "cmyk"}
    for bad in ({"ink_per_ml": {"w": 1}}, {"machine_per_hour": -1}, {"tax": 1},
                {"media_per_m2": {"x": True}}, {"currency": "€"}):
        with pytest.raises(Invalid):
            costs.check(bad)


def expected(row: dict) -> dict:
    """A row's cost by hand from PRICES."""
    ink = sum(row[f"ink_{c}_ml"] * PRICES["ink_per_ml"][c] for c in "cmyk")
    media = row["area_m2"] * PRICES["media_per_m2"][row["media"] or "default"]
    time = row["duration_s"] / 3600 * PRICES["machine_per_hour"]
    return dict(ink=ink, media=media, time=time, total=ink + media + time)


def test_report_costs_from_a_stated_price_list(print_server, tmp_path, capsys):
    s = print_server()
    c = Client(s.state_dir)
    from wideprint.app.cli import main
    try:
        c.roll("main", {"media": "vinyl-300", "length_m": 30})
        src = write_cmyk_tiff(tmp_path / "sign.tif", random_planes(200, 240, seed=8))
        done = c.submit(src, copies=2)["job"]
        failed = c.submit(src, settings={"placement": {"width_mm": 5080}}, force=True)["job"]
        assert c.wait(done["id"], 60)["state"] == "done"
        assert c.wait(failed["id"], 60)["state"] == "failed"
        (tmp_path / "prices.json").write_text(json.dumps(PRICES))
        assert main(["prices", "--set", str(tmp_path / "prices.json"),
                     "--state-dir", str(s.state_dir)]) == 0
        assert "vinyl-300 4.5" in capsys.readouterr().out
        with pytest.raises(ApiError) as e:
            c.prices({"machine_per_hour": "cheap"})
        assert e.value.status == 400 and c.prices() == costs.check(PRICES)
        # JSON: every row's cost is the formula's, the failed copy costs no media
        assert main(["report", "--costs", "--json", "--state-dir", str(s.state_dir)]) == 0
        r = json.loads(capsys.readouterr().out)
        assert len(r["prints"]) == 3
        for row in r["prints"]:
            want = expected(row)
            assert row["media"] == "vinyl-300"
            for k in ("ink", "media", "time", "total"):
                assert row["cost"][k] == pytest.approx(want[k], abs=1e-4), (k, row)
        bad = [row for row in r["prints"] if row["job_id"] == failed["id"]][0]
        assert bad["strokes_printed"] == 0 and bad["area_m2"] == 0 and bad["cost"]["media"] == 0
        good = [row for row in r["prints"] if row["job_id"] == done["id"]]
        assert len(good) == 2 and all(row["area_m2"] > 0 for row in good)
        assert [row["cost"]["media"] for row in good] == \
            pytest.approx([row["area_m2"] * 4.5 for row in good], abs=1e-4)
        t = r["totals"]
        assert t["total"] == pytest.approx(sum(expected(row)["total"] for row in r["prints"]),
                                           abs=1e-3)
        assert t["prints"] == 3 and t["currency"] == "EUR"
        # the table and the CSV say the same
        assert main(["report", "--costs", "--state-dir", str(s.state_dir)]) == 0
        text = capsys.readouterr().out
        assert f"= {t['total']:.4f} EUR" in text and text.count("sign.tif") == 3
        out = tmp_path / "costs.csv"
        assert main(["report", "--costs", "--csv", str(out), "--state-dir", str(s.state_dir)]) == 0
        rows = list(csv.DictReader(io.StringIO(out.read_text())))
        assert [float(x["cost_total"]) for x in rows] == pytest.approx(
            [row["cost"]["total"] for row in r["prints"]], abs=1e-4)
        assert {x["currency"] for x in rows} == {"EUR"} and rows[0]["media"] == "vinyl-300"
        assert float(rows[0]["paper_mm"]) > 0
    finally:
        c.close()
