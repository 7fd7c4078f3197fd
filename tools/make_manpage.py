"""Write resources/man/wideprint.1 from the command-line parser (argparse-manpage), so the
man page lists exactly the options `wideprint --help` does.  tests/test_conventions.py
checks that the committed page is current:  .venv/bin/python tools/make_manpage.py"""

from __future__ import annotations

import sys
from pathlib import Path

ROOT = Path(__file__).resolve().parent.parent
OUT = ROOT / "resources" / "man" / "wideprint.1"


def manpage() -> str:
    from argparse_manpage.manpage import Manpage
    from wideprint import __version__
    from wideprint.app.cli import build_parser
    data = dict(project_name="wideprint", version=__version__, date="2026-11-23",
                description="RIP, driver and print server for the 3.4 m CMYK solvent plotter "
                            "(8 x Xaar XJ128), with its emulator",
                url="docs/ in the source tree", authors=["the wideprint authors"])
    page = str(Manpage(build_parser(), _data=data))
    # argparse-manpage leaves help text that wraps onto a line starting with ' (troff's
    # other control character) unescaped: \& makes such a line text
    page = "\n".join("\\&" + ln if ln.startswith("'") else ln for ln in page.split("\n"))
    # troff reads its input as Latin-1 unless told otherwise: any other character (the help
    # texts' ΔE, °, ≤) goes in as groff's own escape, so the page is ASCII and renders anywhere
    return "".join(ch if ord(ch) < 128 else f"\\[u{ord(ch):04X}]" for ch in page)


def main() -> int:
    OUT.parent.mkdir(parents=True, exist_ok=True)
    OUT.write_text(manpage())
    print(f"wrote {OUT}")
    return 0


if __name__ == "__main__":
    sys.exit(main())
