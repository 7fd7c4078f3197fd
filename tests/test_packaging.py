"""The package is whole however it is installed (tests/support/packaging.py says what ships,
found from the tree): setup.cfg's packages and package data against the tree, as setuptools
reads them; one version everywhere; a CHANGELOG entry for it and for each promise's
version.  `make wheel-check` does the same against a real wheel installed into a fresh
environment (CI)."""

import re
import subprocess
import sys
from pathlib import Path

import pytest

from support import packaging

ROOT = packaging.ROOT
WIDEPRINT = [sys.executable, "-m", "wideprint.app.cli"]


def test_every_folder_with_modules_is_a_package_in_setup_cfg():
    listed, _ = packaging.setuptools_view()
    assert packaging.missing_init() == [], "a folder of modules without __init__.py"
    want = packaging.expected_packages()
    assert not want - set(listed), \
        f"setup.cfg [options] packages lacks {sorted(want - set(listed))}: the wheel would not have them"
    assert not set(listed) - want, f"setup.cfg lists packages the tree lacks: {sorted(set(listed) - want)}"


def test_setuptools_would_install_every_file_of_the_package():
    """Modules and data: every module of every package, all of resources/ (a new data folder
    too), nothing of tests/, docs/, bench/, tools/."""
    _, shipped = packaging.setuptools_view()
    problems = packaging.compare(packaging.expected_wheel_files(), shipped, "setuptools' wheel")
    assert not problems, "\n".join(problems)
    for must in ("wideprint/app/ipp/bridge.py", "wideprint/resources/acceptance/test_sample_suite.py",
                 "wideprint/resources/samples/sample.tif", "wideprint/resources/printers/default.toml",
                 "wideprint/resources/cups/wideprint.convs", "wideprint/resources/systemd/wideprint.service"):
        assert must in shipped, must


def _git(root: Path, *args: str) -> None:
    subprocess.run(["git", *args], cwd=root, check=True, capture_output=True)


def test_the_check_finds_a_forgotten_package_and_data_folder(tmp_path):
    """A tree with a subpackage and a data folder that setup.cfg forgets, as the wheel of
    0.1.0 forgot app/ipp and resources/acceptance: both named."""
    (tmp_path / "app" / "ipp").mkdir(parents=True)
    (tmp_path / "resources" / "new").mkdir(parents=True)
    for f in ("__init__.py", "app/__init__.py", "app/ipp/__init__.py", "app/ipp/bridge.py",
              "resources/__init__.py"):
        (tmp_path / f).write_text("")
    (tmp_path / "resources" / "new" / "table.csv").write_text("a,b\n")
    (tmp_path / "setup.cfg").write_text(
        "[metadata]\nname = wideprint\nversion = 0\n[options]\npackage_dir =\n    wideprint = .\n"
        "packages =\n    wideprint\n    wideprint.app\n    wideprint.resources\n"
        "[options.package_data]\nwideprint.resources = *.txt\n")
    _git(tmp_path, "init", "-q")
    _git(tmp_path, "add", ".")
    listed, shipped = packaging.setuptools_view(tmp_path)
    assert packaging.expected_packages(tmp_path) - set(listed) == {"wideprint.app.ipp"}
    assert packaging.compare(packaging.expected_wheel_files(tmp_path), shipped, "wheel") == [
        "wheel lacks wideprint/app/ipp/__init__.py", "wheel lacks wideprint/app/ipp/bridge.py",
        "wheel lacks wideprint/resources/new/table.csv"]


def test_one_version_everywhere():
    """The package, `wideprint --version` and the HTTP API (GET /v1/status server.version)
    say the version __init__.py holds; setup.cfg takes it from there."""
    import wideprint
    from wideprint.app.server.core import _version
    assert re.fullmatch(r"\d+\.\d+\.\d+", wideprint.__version__)
    assert _version() == wideprint.__version__
    r = subprocess.run(WIDEPRINT + ["--version"], capture_output=True, text=True, timeout=60)
    assert r.returncode == 0 and r.stdout.strip() == f"wideprint {wideprint.__version__}", r
    assert "version = attr: wideprint.__version__" in (ROOT / "setup.cfg").read_text()


def test_the_changelog_has_the_version_and_each_promise():
    """CHANGELOG.md: a section for the package's version and a line for the current version
    of each promise (the wire protocol, the Python API; the HTTP API's prefix)."""
    import wideprint
    from wideprint.app.api import API_VERSION
    from wideprint.driver.protocol import PROTOCOL_VERSION
    text = (ROOT / "CHANGELOG.md").read_text()
    assert re.search(rf"^## {re.escape(wideprint.__version__)} - \d{{4}}-\d\d-\d\d$", text, re.M), \
        f"CHANGELOG.md has no section '## {wideprint.__version__} - DATE'"
    proto = "%d.%d" % tuple(PROTOCOL_VERSION)
    assert re.search(rf"^- {re.escape(proto)}[ :]|^### Wire protocol {re.escape(proto)}$", text, re.M), \
        f"CHANGELOG.md says nothing of wire protocol {proto}"
    assert f"### Python API {API_VERSION}" in text, f"CHANGELOG.md says nothing of Python API {API_VERSION}"
    assert "### HTTP API v1" in text


@pytest.mark.parametrize("name", ["make test-fast", "make wheel-check"])
def test_the_readme_and_ci_name_the_make_targets(name):
    target = name.split()[1]
    assert re.search(rf"^{re.escape(target)}:", (ROOT / "Makefile").read_text(), re.M)
    assert name in (ROOT / "README.md").read_text()
    if target == "wheel-check":
        assert re.search(r"^make wheel-check$", (ROOT / ".ci" / "run").read_text(), re.M)
