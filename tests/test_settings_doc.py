"""docs/settings.md's table of settings against the one schema (rip/settings.py): declared
once, checked against the docs (docs/architecture.md) — every setting has its row, with its
type, its default and, for a fixed set of choices, exactly those choices."""

from pathlib import Path

import pytest

from wideprint.rip.settings import SETTINGS

DOC = Path(__file__).resolve().parent.parent / "docs" / "settings.md"


def rows() -> dict[str, list[str]]:
    """Setting key (placement.x for placement) -> its row's cells [type, default, allowed]."""
    out = {}
    text = DOC.read_text()
    section = text[text.index("## The settings"):]
    section = section[:section.index("\n## ", 3)]
    for line in section.splitlines():
        if not line.startswith("| ") or line.startswith("| name") or line.startswith("|---"):
            continue
        cells = [c.strip() for c in line.strip().strip("|").split("|")]
        names = [n.strip() for n in cells[0].split(",")]
        prefix = "placement." if names[0].startswith("placement.") else ""
        for n in names:
            out[n if n.startswith(prefix) else prefix + n] = cells[1:4]
    return out


def key(s) -> str:
    return f"placement.{s.name}" if s.group == "placement" else s.name


def shown(v) -> str:
    if v is None:
        return "null"
    if isinstance(v, bool):
        return "true" if v else "false"
    if isinstance(v, float) and v.is_integer():
        return str(int(v))
    return str(v)


@pytest.mark.parametrize("s", SETTINGS, ids=key)
def test_every_setting_has_its_row_with_its_type_default_and_choices(s):
    table = rows()
    assert key(s) in table, f"docs/settings.md has no row for {key(s)}"
    kind, default, allowed = table[key(s)]
    assert s.kind.__name__ in kind, (key(s), kind)
    assert (" or null" in kind or "null" in default) == s.nullable, (key(s), kind)
    assert shown(s.default) in [d.strip() for d in default.split("/")], (key(s), default)
    if s.choices and not s.profile_choices:
        assert [c.strip() for c in allowed.split(",")] == [shown(c) for c in s.choices], \
            (key(s), allowed)


def test_the_table_names_no_setting_the_schema_lacks():
    known = {key(s) for s in SETTINGS}
    assert set(rows()) - known == set()
