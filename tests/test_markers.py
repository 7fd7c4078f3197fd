"""The markers' tables (tests/support/marks.py) name tests that exist, the markers are
registered, and `make test-fast` (everything not slow, system or gui) still reaches every
package: each of app, app/server, rip, driver and device_sim is imported by a test module
with tests left in the fast run.  Checked from the files' syntax trees, without collecting."""

import ast
import configparser
import functools
import re

import pytest

from support.images import ROOT
from support import marks

TESTS = ROOT / "tests"
PACKAGES = ("app", "app.server", "rip", "driver", "device_sim")


@functools.cache
def _tree(path) -> ast.AST:
    return ast.parse(path.read_text(), str(path))


def _functions(path) -> set[str]:
    tree = _tree(path)
    return {n.name for n in ast.walk(tree)
            if isinstance(n, (ast.FunctionDef, ast.AsyncFunctionDef)) and n.name.startswith("test_")}


def _imports(path) -> set[str]:
    """The wideprint modules a test file imports (`wideprint.x.y` as given)."""
    found = set()
    for n in ast.walk(_tree(path)):
        if isinstance(n, ast.ImportFrom) and n.module and n.module.startswith("wideprint"):
            found.add(n.module)
            found.update(f"{n.module}.{a.name}" for a in n.names)
        elif isinstance(n, ast.Import):
            found.update(a.name for a in n.names if a.name.startswith("wideprint"))
    return found


def test_every_name_in_the_tables_is_a_test_that_exists():
    for table in (marks.SYSTEM, marks.GUI, marks.SLOW):
        for module, functions in table.items():
            path = TESTS / module
            assert path.is_file(), f"tests/support/marks.py names {module}, which is gone"
            if isinstance(functions, set):
                gone = functions - _functions(path)
                assert not gone, f"tests/support/marks.py names {module}::{sorted(gone)}, which are gone"
    for module, fixture in marks.SLOW_FIXTURES:
        defined = {n.name for n in ast.walk(_tree(TESTS / module)) if isinstance(n, ast.FunctionDef)}
        assert fixture in defined, f"tests/support/marks.py names the fixture {module}::{fixture}, which is gone"


def test_the_markers_are_registered_and_strict():
    cfg = configparser.ConfigParser()
    cfg.read(ROOT / "setup.cfg")
    section = cfg["tool:pytest"]
    assert "--strict-markers" in section["addopts"].split()
    registered = {ln.split(":")[0].strip() for ln in section["markers"].strip().splitlines()}
    assert {"slow", "system", "gui"} <= registered
    make = (ROOT / "Makefile").read_text()
    assert re.search(r'^FAST := not slow and not system and not gui$', make, re.M)


def test_markers_for_reads_the_tables():
    assert marks.markers_for("test_cups.py", "test_anything") == ["system"]
    assert marks.markers_for("test_hostile_files.py", "test_anything") == ["slow"]
    assert marks.markers_for("test_halftone.py", "test_anything", ("qtbot",)) == ["gui"]
    assert marks.markers_for("test_halftone.py", "test_anything") == []
    assert marks.markers_for("test_ipp.py", "test_anything", ("ipp", "tmp_path")) == ["slow"]


@pytest.mark.parametrize("package", PACKAGES)
def test_the_fast_run_still_reaches_every_package(package):
    """A test module that imports the package and keeps tests in `make test-fast`."""
    reaching = []
    for path in sorted(TESTS.glob("test_*.py")):
        if not any(m == f"wideprint.{package}" or m.startswith(f"wideprint.{package}.")
                   for m in _imports(path)):
            continue
        fast = {f for f in _functions(path) if not marks.markers_for(path.name, f)}   # fixtures unseen
        if fast:
            reaching.append((path.name, len(fast)))
    assert sum(n for _, n in reaching) >= 10, \
        f"make test-fast keeps fewer than 10 tests of wideprint.{package}: {reaching}"
