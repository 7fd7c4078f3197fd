"""`make lint`: ruff and mypy over the tree, against a baseline that may only shrink.

    python tools/lint.py            # fail if any file has more findings than its baseline
    python tools/lint.py --update   # lower the baseline to what is found now (never raises it)
    python tools/lint.py --reset    # a new rule or tool version: the baseline as found (reviewed)

The configuration is in pyproject.toml ([tool.ruff], [tool.mypy]).  What the code did not
meet when the checks came in is counted per file, ruff's findings and mypy's errors apart,
in tools/lint-baseline.json.  A file may have fewer findings than its count, never more,
and a file not in the baseline none at all; so the count of the whole tree only goes down.
When it went down, `--update` writes the lower counts (files at zero leave the baseline).
The counts are of the working tree: in a checkout where others have uncommitted changes,
look at what `--update` lowered (git diff) and commit only your files' lines, or a commit
without their changes could find more than the baseline allows.

The strict modules (pyproject.toml's override: the seams and the public Python API) are
type-checked with the `--strict` flags; those at zero errors are listed in STRICT_CLEAN
and may not have any again.

mypy checks the package `wideprint`, which is this checkout's root: it is reached as
build/typecheck/wideprint, a link to the root, so that mypy sees the package's name.
"""

from __future__ import annotations

import argparse
import json
import os
import re
import subprocess
import sys
import time
from collections import Counter
from pathlib import Path

ROOT = Path(__file__).resolve().parent.parent
BASELINE = ROOT / "tools" / "lint-baseline.json"
LINK_DIR = ROOT / "build" / "typecheck"
#: strict modules with no mypy error: they must stay at none (a baseline entry is refused)
STRICT_CLEAN: tuple[str, ...] = ("driver/protocol.py", "app/api.py", "rip/settings.py",
                                 "rip/profile.py", "rip/planes.py")

_MYPY_LINE = re.compile(r"^build/typecheck/wideprint/(?P<file>[^:]+\.py):(?P<line>\d+): error: ")


def run_ruff() -> dict[str, list[str]]:
    """ruff's findings by file (relative to the root), each as `file:line:col: CODE message`."""
    r = subprocess.run([sys.executable, "-m", "ruff", "check", "--output-format", "json",
                        "--no-cache", "--exit-zero", "."], cwd=ROOT, capture_output=True, text=True)
    if r.returncode != 0:
        sys.exit(f"lint: ruff did not run ({r.returncode}): {r.stderr.strip()[-2000:]}")
    out: dict[str, list[str]] = {}
    for f in json.loads(r.stdout or "[]"):
        path = Path(f["filename"]).resolve().relative_to(ROOT).as_posix()
        loc = f.get("location") or {}
        out.setdefault(path, []).append(
            f"{path}:{loc.get('row')}:{loc.get('column')}: {f.get('code')} {f.get('message')}")
    return out


def _package_link() -> None:
    LINK_DIR.mkdir(parents=True, exist_ok=True)
    link = LINK_DIR / "wideprint"
    if link.is_symlink() and link.resolve() == ROOT:
        return
    if link.is_symlink() or link.exists():
        link.unlink()
    link.symlink_to(os.path.relpath(ROOT, LINK_DIR), target_is_directory=True)


def run_mypy() -> dict[str, list[str]]:
    """mypy's errors by file (relative to the root)."""
    _package_link()
    env = dict(os.environ, MYPYPATH=str(LINK_DIR.relative_to(ROOT)))
    r = subprocess.run([sys.executable, "-m", "mypy", "-p", "wideprint", "--no-error-summary",
                        "--no-color-output", "--show-error-codes", "--hide-error-context"],
                       cwd=ROOT, capture_output=True, text=True, env=env)
    if r.returncode not in (0, 1):
        sys.exit(f"lint: mypy did not run ({r.returncode}): {(r.stderr or r.stdout).strip()[-2000:]}")
    out: dict[str, list[str]] = {}
    for line in r.stdout.splitlines():
        m = _MYPY_LINE.match(line)
        if m:
            out.setdefault(m["file"], []).append(line.replace("build/typecheck/wideprint/", "", 1))
    return out


def compare(tool: str, found: dict[str, list[str]], base: dict[str, int]) -> tuple[list[str], Counter]:
    """(the problems: files above their count, each with its findings; the files now below)."""
    problems, lower = [], Counter()
    for path in sorted(set(found) | set(base)):
        n, allowed = len(found.get(path, ())), base.get(path, 0)
        if n > allowed:
            head = (f"{path}: {n} {tool} findings, {allowed} allowed (tools/lint-baseline.json)"
                    if allowed else f"{path}: {n} {tool} findings (none allowed)")
            problems.append("\n    ".join([head, *found[path]]))
        elif n < allowed:
            lower[path] = allowed - n
    return problems, lower


def main(argv: list[str] | None = None) -> int:
    ap = argparse.ArgumentParser(description=__doc__.split("\n\n")[0])
    ap.add_argument("--update", action="store_true",
                    help="lower tools/lint-baseline.json to what is found now (never raises a count)")
    ap.add_argument("--only", choices=("ruff", "mypy"), help="run one of the two")
    ap.add_argument("--reset", action="store_true",
                    help="write the baseline as found now, raising counts too: only for a new rule "
                    "or a new version of ruff or mypy, and reviewed as such")
    args = ap.parse_args(argv)
    base = json.loads(BASELINE.read_text()) if BASELINE.exists() else {}
    results: dict[str, dict[str, list[str]]] = {}
    failed = False
    for tool, run in (("ruff", run_ruff), ("mypy", run_mypy)):
        if args.only and tool != args.only:
            continue
        t0 = time.monotonic()
        found = results[tool] = run()
        problems, lower = compare(tool, found, base.get(tool, {}))
        if tool == "mypy":
            for path in STRICT_CLEAN:
                if base.get(tool, {}).get(path):
                    problems.append(f"{path}: strict and clean, so it may not have a baseline entry")
        total = sum(len(v) for v in found.values())
        print(f"lint: {tool}: {total} findings in {len(found)} files, baseline "
              f"{sum(base.get(tool, {}).values())}; {time.monotonic() - t0:.1f} s")
        for p in problems:
            print(f"  {p}")
        if lower and not args.update:
            print(f"  {sum(lower.values())} fewer than the baseline in {len(lower)} files: "
                  f"`make lint-baseline` locks that in")
        failed |= bool(problems)
    if args.update or args.reset:
        new = dict(base)
        for tool, found in results.items():
            old = base.get(tool, {})
            counts = ({p: len(v) for p, v in found.items()} if args.reset else
                      {p: min(len(found.get(p, ())), n) for p, n in old.items()})
            new[tool] = {p: n for p, n in sorted(counts.items()) if n}
        BASELINE.write_text(json.dumps(new, indent=1, sort_keys=True) + "\n")
        print(f"lint: wrote {BASELINE.relative_to(ROOT)}")
    return 1 if failed and not args.reset else 0


if __name__ == "__main__":
    sys.exit(main())
