"""The tests' shared helpers live in tests/support (images, the print server, printing in
process, the GUI's server): a test file imports them from there, never from conftest.py
(pytest's fixture file, which only turns them into fixtures) nor from another test file
(importing a test module runs its module-level set-up a second time, under another name)."""

import ast
from pathlib import Path

TESTS = Path(__file__).resolve().parent


def test_test_files_import_helpers_from_support_only():
    bad = []
    for path in sorted(TESTS.glob("*.py")):
        for node in ast.walk(ast.parse(path.read_text(), str(path))):
            names = [node.module or ""] if isinstance(node, ast.ImportFrom) and not node.level \
                else [a.name for a in node.names] if isinstance(node, ast.Import) else []
            for name in names:
                top = name.split(".")[0]
                if top == "conftest" or top.startswith("test_"):
                    bad.append(f"{path.name}:{node.lineno}: imports {name}")
    assert bad == [], "import these from tests/support instead:\n" + "\n".join(bad)
