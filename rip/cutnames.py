"""The spot colour names that mean "cut here, never print" (docs/cut.md).

Every RIP and every cutter vendor shares the convention that a path stroked or filled in
a spot colour of one of these names is a cut line: it is never printed (no drop under it,
whatever its stroke width) and it becomes the job's cut file. The names differ by vendor
(Roland VersaWorks and Summa: CutContour, PerfCutContour; Caldera: Thru-cut, KissCut;
Wasatch: CutPath; die-line files: Die*, Dieline), so the list is a set of patterns matched
case-insensitively with shell wildcards, and a shop can replace or extend it
($WIDEPRINT_CUT_NAMES, below).

Standard library only: the rendering (rip/ghostscript.py, which must leave these
separations out) and the cut-path extraction (rip/cut.py) both ask this one module.
"""

from __future__ import annotations

import fnmatch
import os
from typing import Iterable

#: the conventional cut spot names (patterns, case-insensitive)
DEFAULT_CUT_NAMES: tuple[str, ...] = (
    "CutContour", "PerfCutContour", "Thru-cut", "Thru cut", "ThruCut", "KissCut", "Kiss-cut",
    "CutPath", "Cut", "Die*", "Dieline", "Die-line",
)


#: the shop's own list (docs/cut.md "Cut spot names"): comma-separated patterns that replace
#: the defaults, or, starting with "+", are added to them (a printing server's unit file,
#: the operator's shell); read at each call, so the render and the cut file always agree
ENV = "WIDEPRINT_CUT_NAMES"


def cut_names() -> tuple[str, ...]:
    """The cut spot name patterns in force: $WIDEPRINT_CUT_NAMES, else the defaults."""
    env = os.environ.get(ENV, "").strip()
    if not env:
        return DEFAULT_CUT_NAMES
    extra = env.startswith("+")
    own = tuple(p.strip() for p in env.lstrip("+").split(",") if p.strip())
    return (*DEFAULT_CUT_NAMES, *own) if extra else own


def is_cut_name(name: str, patterns: Iterable[str] | None = None) -> bool:
    """True when a spot colour called `name` is a cut line under `patterns` (default: the
    list in force, `cut_names()`)."""
    folded = name.strip().casefold()
    return any(fnmatch.fnmatchcase(folded, p.strip().casefold())
               for p in (cut_names() if patterns is None else patterns))
