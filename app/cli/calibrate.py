"""`wideprint calibrate` (docs/calibration.md): the command's options.  Apart from the
measuring (app/calibrate.py), so that building the command line - `wideprint --help` and
every other command - does not load numpy and the scan analysis."""

from __future__ import annotations

# the scans `calibrate KIND` measures: the test print each is a scan of (the registry of
# test patterns, rip/testpatterns.py; this name kept for its users)
from ...rip.testpatterns import CALIBRATION_KINDS as KINDS


def cmd_calibrate(args) -> int:
    from ..calibrate import cmd_calibrate as measure
    return measure(args)


def add_parser(sub) -> None:
    from ...rip.settings import setting
    p = sub.add_parser("calibrate", help="measure a scanned calibration print and store the "
                       "result in the printer profile (docs/calibration.md)",
                       description="Finds the test pattern in a scan (any placement, a few "
                       "degrees of rotation), measures it and reports dead nozzles (and, "
                       "on a 1200 dpi scan, every nozzle's landing error and drop volume, "
                       "which --pass-mask hiding prints with), the "
                       "bidirectional offset, head x/y offsets, the feed error or the inks' tone "
                       "curves, or the banding chart's banding and grain; --write stores it "
                       "in --profile. Print the pattern first: "
                       "wideprint test-print nozzle-check|bidir-scan|heads-scan|feed-scan|"
                       "wedge-scan|banding-scan.")
    p.add_argument("kind", choices=tuple(KINDS))
    p.add_argument("--scan", metavar="SCAN.tif", help="the scan (TIFF)")
    p.add_argument("--values", action="append", metavar="INK=T0,...,T10",
                   help="wedge: measured tones typed in instead of a scan, one for each of the "
                   "eleven wedge steps from no ink to solid in tenths, in any unit rising "
                   "from paper to solid (e.g. dot area in percent); repeat per ink")
    p.add_argument("--dpi", type=int, choices=setting("dpi").choices, default=150,
                   help="the dpi mode the pattern was printed at (default 150)")
    p.add_argument("--width-mm", type=float, default=100.0,
                   help="the pattern's length along the sweep, as printed (default 100)")
    p.add_argument("--scan-dpi", type=float, metavar="N",
                   help="the scan's resolution (default: its TIFF resolution tags)")
    p.add_argument("--passes", type=int, choices=setting("passes").choices,
                   help="banding: the weave the chart was printed with (its periods reported)")
    p.add_argument("--profile", metavar="TOML", help="the profile the pattern was printed with; "
                   "--write updates it")
    p.add_argument("--write", action="store_true", help="store the result in --profile")
    p.add_argument("--json", action="store_true", help="print the result as JSON")
    p.set_defaults(func=cmd_calibrate)
