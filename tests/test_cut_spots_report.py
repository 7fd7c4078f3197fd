"""A print-and-cut job prints through a layout (its registration marks): its report and its
summary still say the spots it printed and how each resolved (docs/spot.md "The job's
report"), as a plain print does."""

import json

from support.printcut import BRAND, make_pdf
from wideprint.app.cli import main
from wideprint.rip import spot


def test_a_print_and_cut_job_reports_its_spots(tmp_path, monkeypatch, capsys):
    monkeypatch.setenv("WIDEPRINT_SPOT_DIR", str(tmp_path / "spots"))
    spot.SpotBook(tmp_path / "spots").add([spot.Spot(n, lab) for n, lab in BRAND.items()], "brand")
    pdf = make_pdf(tmp_path / "decal.pdf")
    for cut in ([], ["--cut-out", str(tmp_path / "decal.plt")]):
        report = tmp_path / f"report{len(cut)}.json"
        assert main(["print", str(pdf), "--dpi", "150", "--report", str(report), *cut]) == 0
        job = json.loads(report.read_text())[0]
        assert ("layout" in job) == bool(cut)                       # the marks' layout
        by = {s["name"]: s["resolved"] for s in job["spots"]}
        assert by == {"Brand Red": "library", "Brand Teal": "library",
                      "Other Green": "alternate", "CutContour": "cut"}, by
        assert "spots: Brand Red (library" in capsys.readouterr().out
