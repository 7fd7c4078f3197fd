"""What a wheel of wideprint must hold, found from the tree, and what setuptools makes of
setup.cfg: the two compared by tests/test_packaging.py (every test run) and, against a
real wheel, by `make wheel-check` (CI).

The repository root is the `wideprint` package (setup.cfg `package_dir`), so setuptools'
`find:` cannot be used (it would name the subpackages `app`, `rip`, ... at top level):
setup.cfg lists the packages, and this module finds what the list must be.  The rule:

- every file of a package folder ships (the root's own `*.py`, and every file under a
  top-level folder that is not in NOT_PACKAGE), but for NOT_SHIPPED;
- every folder holding Python modules is a package (has `__init__.py`) in setup.cfg's
  list, but for the folders under `resources/`, which are data (the acceptance suite, the
  sample's generator): `resources/` ships whole (setup.cfg `wideprint.resources = **/*`).

"The tree" is what git tracks or would track (`git ls-files -co --exclude-standard`): what
`make` builds (the compiled kernels, the IPP binary) and caches are ignored files and not
part of a pure-Python wheel.

    python tests/support/packaging.py WHEEL     # exit 1, naming the differences
"""

from __future__ import annotations

import os
import subprocess
import sys
import zipfile
from contextlib import contextmanager
from pathlib import Path, PurePosixPath

ROOT = Path(__file__).resolve().parents[2]
PKG = "wideprint"

#: top-level folders of the checkout that are not part of the package
NOT_PACKAGE = {"tests", "bench", "tools", "docs", "build", "dist", "out", ".ci"}
#: files in the package's folders that the wheel leaves out on purpose, and why
NOT_SHIPPED = {
    "app/ipp/wideprint-ipp.c": "the IPP Printer Application's C source: `make` builds it "
                               "against PAPPL; the wheel is pure Python (docs/ipp.md)",
}
#: the folder whose every file ships as data (setup.cfg [options.package_data])
DATA = "resources"


def tree_files(root: Path = ROOT) -> list[str]:
    """The checkout's files (posix paths relative to root) that git tracks or would track,
    that exist."""
    out = subprocess.run(["git", "ls-files", "-z", "-co", "--exclude-standard"], cwd=root,
                         capture_output=True, check=True).stdout.decode()
    return sorted(p for p in set(out.split("\0")) if p and (root / p).is_file())


def package_files(root: Path = ROOT) -> list[str]:
    """The tree's files that belong to the package (shipped or deliberately not)."""
    out = []
    for p in tree_files(root):
        parts = PurePosixPath(p).parts
        if len(parts) == 1:
            if p.endswith(".py"):
                out.append(p)                       # the root's modules: wideprint.*
        elif not parts[0].startswith(".") and parts[0] not in NOT_PACKAGE:
            out.append(p)
    return out


def expected_wheel_files(root: Path = ROOT) -> set[str]:
    """The files the wheel must hold, as `wideprint/...` paths."""
    return {f"{PKG}/{p}" for p in package_files(root) if p not in NOT_SHIPPED}


def expected_packages(root: Path = ROOT) -> set[str]:
    """Every folder with a module, as a dotted package name (resources' data folders apart)."""
    pkgs = {PKG}
    for p in package_files(root):
        parent = PurePosixPath(p).parent
        if p.endswith(".py") and parent.parts and not (
                parent.parts[0] == DATA and len(parent.parts) > 1):
            pkgs.add(".".join((PKG, *parent.parts)))
    return pkgs


def missing_init(root: Path = ROOT) -> list[str]:
    """Package folders without `__init__.py` (setuptools would skip their modules)."""
    return sorted(f"{'/'.join(name.split('.')[1:])}/__init__.py"
                  for name in expected_packages(root) - {PKG}
                  if not (root / Path(*name.split(".")[1:]) / "__init__.py").is_file())


@contextmanager
def _cwd(path: Path):
    old = os.getcwd()
    os.chdir(path)
    try:
        yield
    finally:
        os.chdir(old)


def setuptools_view(root: Path = ROOT) -> tuple[list[str], set[str]]:
    """(setup.cfg's packages, the `wideprint/...` files setuptools' build_py would put in a
    wheel), from setup.cfg as setuptools reads it, without building anything.  Only files
    the tree has count: whatever else lies in the folders (caches, `make`'s builds) is not
    a file any wheel built from a clean checkout could hold."""
    from setuptools.dist import Distribution
    with _cwd(root):
        dist = Distribution()
        dist.script_name = "setup.py"            # build_py compares module paths with it
        dist.parse_config_files(["setup.cfg"])
        build_py = dist.get_command_obj("build_py")
        build_py.ensure_finalized()
        files = {os.path.normpath(src) for _pkg, _mod, src in build_py.find_all_modules()}
        for _pkg, src_dir, _build_dir, names in build_py.data_files:
            files.update(os.path.normpath(os.path.join(src_dir, n)) for n in names)
    tree = set(tree_files(root))
    shipped = {f"{PKG}/{Path(f).as_posix()}" for f in files if Path(f).as_posix() in tree}
    return list(dist.packages), shipped


def wheel_files(wheel: Path) -> set[str]:
    """The package's files in a built wheel (its .dist-info apart)."""
    with zipfile.ZipFile(wheel) as z:
        names = z.namelist()
    dupes = {n for n in names if names.count(n) > 1}
    if dupes:
        raise ValueError(f"{wheel}: files twice in the archive: {sorted(dupes)}")
    return {n for n in names if not n.split("/")[0].endswith(".dist-info") and not n.endswith("/")}


def compare(expected: set[str], actual: set[str], what: str) -> list[str]:
    """Lines naming what `actual` lacks or has in excess of `expected`."""
    lines = [f"{what} lacks {f}" for f in sorted(expected - actual)]
    lines += [f"{what} has {f}, which the tree does not ship" for f in sorted(actual - expected)]
    return lines


def main(argv: list[str]) -> int:
    if len(argv) != 1:
        print("usage: python tests/support/packaging.py WHEEL", file=sys.stderr)
        return 2
    wheel = Path(argv[0])
    problems = compare(expected_wheel_files(), wheel_files(wheel), wheel.name)
    for line in problems:
        print(f"wheel-check: {line}", file=sys.stderr)
    if problems:
        print("wheel-check: setup.cfg [options] packages / package_data do not match the tree "
              "(tests/support/packaging.py says what ships)", file=sys.stderr)
        return 1
    print(f"wheel-check: {wheel.name} holds the package's {len(expected_wheel_files())} files")
    return 0


if __name__ == "__main__":
    sys.exit(main(sys.argv[1:]))
