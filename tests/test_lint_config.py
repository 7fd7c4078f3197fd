"""`make lint`'s configuration holds together (tools/lint.py, pyproject.toml,
tools/lint-baseline.json): the seam modules and the public Python API are the strict ones,
those listed as clean have no baseline entry, and every count is a positive whole number.
(Running ruff and mypy themselves is `make lint`'s job, not the suite's.)"""

import importlib.util
import json
import tomllib
from pathlib import Path

ROOT = Path(__file__).resolve().parent.parent
SEAMS = {"wideprint.driver.protocol", "wideprint.rip.profile", "wideprint.rip.settings",
         "wideprint.rip.planes"}
PUBLIC_API = "wideprint.app.api"


def _lint():
    spec = importlib.util.spec_from_file_location("lint", ROOT / "tools" / "lint.py")
    mod = importlib.util.module_from_spec(spec)
    spec.loader.exec_module(mod)
    return mod


def _strict_modules() -> set[str]:
    cfg = tomllib.loads((ROOT / "pyproject.toml").read_text())
    out = set()
    for o in cfg["tool"]["mypy"].get("overrides", []):
        if o.get("disallow_untyped_defs") and o.get("disallow_any_generics"):
            mods = o["module"]
            out.update([mods] if isinstance(mods, str) else mods)
    return out


def _file(module: str) -> str:
    return "/".join(module.split(".")[1:]) + ".py"


def test_the_seams_and_the_public_api_are_checked_strictly():
    assert SEAMS | {PUBLIC_API} <= _strict_modules()


def test_strict_clean_modules_are_strict_and_out_of_the_baseline():
    lint = _lint()
    strict_files = {_file(m) for m in _strict_modules()}
    assert set(lint.STRICT_CLEAN) <= strict_files
    base = json.loads((ROOT / "tools" / "lint-baseline.json").read_text())
    assert not set(lint.STRICT_CLEAN) & set(base.get("mypy", {}))


def test_the_baseline_counts_are_positive_whole_numbers():
    base = json.loads((ROOT / "tools" / "lint-baseline.json").read_text())
    assert set(base) <= {"ruff", "mypy"}
    for tool, counts in base.items():
        bad = {f: n for f, n in counts.items() if not (isinstance(n, int) and n > 0)}
        assert bad == {}, tool


def test_the_comparison_allows_fewer_and_refuses_more():
    lint = _lint()
    problems, lower = lint.compare("mypy", {"a.py": ["e1"], "c.py": ["e"]}, {"a.py": 2, "b.py": 1})
    assert lower == {"a.py": 1, "b.py": 1}
    assert len(problems) == 1 and problems[0].startswith("c.py: 1 mypy findings (none allowed)")
