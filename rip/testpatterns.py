"""The test patterns by name, declared once: the patterns `wideprint test-print` prints (the
settings schema's `TEST_PATTERNS`, rip/settings.py) and which of them `wideprint calibrate
KIND` measures from a scan (docs/calibration.md).  Light - no numpy, no kernels - so that the
command line's parsers and the GUI's lists are built from it; the patterns themselves are
drawn by rip/testprints.py, measured by app/calibrate.py.

One registry both sides read, so neither the command's options (app/cli/calibrate.py) nor
the measuring (app/calibrate.py) imports the other (tests/test_layers.py: no circles)."""

from __future__ import annotations

from .settings import TEST_PATTERNS

__all__ = ["CALIBRATION_KINDS", "TEST_PATTERNS", "pattern_of", "kind_of"]

#: `calibrate KIND` -> the test print its scan is of
CALIBRATION_KINDS: dict[str, str] = {
    "nozzles": "nozzle-check", "bidir": "bidir-scan", "heads": "heads-scan",
    "feed": "feed-scan", "wedge": "wedge-scan", "banding": "banding-scan"}

assert set(CALIBRATION_KINDS.values()) <= set(TEST_PATTERNS)


def pattern_of(kind: str) -> str:
    """The test print `calibrate KIND` measures (KeyError for an unknown kind)."""
    return CALIBRATION_KINDS[kind]


def kind_of(pattern: str) -> str | None:
    """The `calibrate` kind that measures a scan of `pattern`, None when none does."""
    return next((k for k, p in CALIBRATION_KINDS.items() if p == pattern), None)
