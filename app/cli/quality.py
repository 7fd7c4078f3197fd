"""`wideprint quality SCAN.tif` (docs/quality.md): the command's options, apart from the
measuring (app/quality.py), so that building the command line loads no numpy."""

from __future__ import annotations


def cmd_quality(args) -> int:
    from ..quality import cmd_quality as measure
    return measure(args)


def add_parser(sub) -> None:
    from ...rip.settings import setting
    p = sub.add_parser("quality", help="banding, graininess and mottle of the flat tints on a "
                       "scan (docs/quality.md)",
                       description="Finds the flat tints of a scan (strips of ink along the "
                       "feed, e.g. `wideprint test-print banding-scan`) and measures each: "
                       "eye-weighted banding along the feed, graininess and mottle "
                       "(ISO/IEC TS 24790, ISO 15311-1), in ΔL*. Any scan: the emulator's "
                       "--scan-out or a real scanner's TIFF.")
    p.add_argument("scan", metavar="SCAN.tif", help="the scan (TIFF, 8 or 16 bits, RGB or grey)")
    p.add_argument("--passes", type=int, choices=setting("passes").choices,
                   help="the weave the print was made with: report the amplitudes at its "
                   "advance and swath periods")
    p.add_argument("--viewing-distance-mm", type=float, default=500.0, metavar="MM",
                   help="the eye's distance from the print (default 500)")
    p.add_argument("--scan-dpi", type=float, metavar="N",
                   help="the scan's resolution (default: its TIFF resolution tags)")
    p.add_argument("--profile", metavar="TOML", help="the printer profile (for the weave's periods)")
    p.add_argument("--json", action="store_true", help="print the report as JSON")
    p.set_defaults(func=cmd_quality)
