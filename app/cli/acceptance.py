"""`wideprint acceptance`: the sample acceptance suite (docs/acceptance.md) under pytest."""

from __future__ import annotations

import sys
from pathlib import Path

from .. import devices
from .common import EXIT_USAGE


def cmd_acceptance(args) -> int:
    """pytest on the sample suite (resources/acceptance/); the plugin comes with the
    package (entry point pytest11)."""
    try:
        import pytest
    except ImportError:
        print("wideprint acceptance: needs pytest (pip install 'wideprint[test]')", file=sys.stderr)
        return EXIT_USAGE
    # app/cli/ -> the package root, whose resources/ ships the sample suite
    suite = args.suite or str(Path(__file__).resolve().parents[2] / "resources" / "acceptance")
    argv = [suite, "-q", "-p", "no:cacheprovider", f"--wideprint-device={args.device}"]
    if args.junit_xml:
        argv.append(f"--junit-xml={args.junit_xml}")
    return int(pytest.main(argv + list(args.pytest_args)))


def add_parser(sub) -> None:
    p = sub.add_parser("acceptance", help="run the sample acceptance suite (docs/acceptance.md)",
                       description="Runs wideprint's sample acceptance suite (the thesis' test "
                       "prints, a colour chart, a fault drill) with pytest and the wideprint "
                       "plugin; extra arguments after -- go to pytest.")
    p.add_argument("--device", default="emulator", help=devices.DEVICE_HELP)
    p.add_argument("--junit-xml", metavar="FILE", help="write a JUnit XML report (for CI systems)")
    p.add_argument("--suite", metavar="DIR", help="another suite folder (default: the sample suite)")
    p.add_argument("pytest_args", nargs="*", metavar="PYTEST-ARG")
    p.set_defaults(func=cmd_acceptance)
