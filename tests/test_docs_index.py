"""The README's documentation index (its "## Documentation" section) lists every document
in docs/, and names none that does not exist: a new doc is found from the README."""

import re
from pathlib import Path

ROOT = Path(__file__).resolve().parent.parent


def _index() -> str:
    text = (ROOT / "README.md").read_text()
    m = re.search(r"^## Documentation\n(.*?)(?=^## |\Z)", text, re.M | re.S)
    assert m, "README.md has no '## Documentation' section"
    return m.group(1)


def test_every_doc_is_in_the_readme_index():
    listed = set(re.findall(r"docs/([\w.-]+\.md)", _index()))
    docs = {p.name for p in (ROOT / "docs").glob("*.md")}
    assert sorted(docs - listed) == [], "docs missing from README.md's '## Documentation'"
    assert sorted(listed - docs) == [], "README.md's '## Documentation' names docs that do not exist"
