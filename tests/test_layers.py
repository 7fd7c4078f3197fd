"""Who may import whom (README "Architecture"): the wire protocol is the only seam between
the host (`driver/`) and the emulated printer (`device_sim/`).  Every import statement of
every module, relative or absolute, top level or inside a function, parsed with `ast`."""

import ast
import functools
import sys
from pathlib import Path

import pytest

ROOT = Path(__file__).resolve().parent.parent
PKG = "wideprint"


def _module_name(path: Path) -> str:
    rel = path.relative_to(ROOT).with_suffix("")
    parts = [PKG, *rel.parts]
    if parts[-1] == "__init__":
        parts.pop()
    return ".".join(parts)


def _modules() -> dict[str, Path]:
    out = {}
    for path in ROOT.rglob("*.py"):
        rel = path.relative_to(ROOT).parts
        if rel[0] in ("tests", "bench", "tools", "build", ".venv") or "__pycache__" in rel:
            continue
        out[_module_name(path)] = path
    return out


MODULES = _modules()


def _type_checking_only(tree: ast.AST) -> set[int]:
    """ids of the import nodes under `if TYPE_CHECKING:` (or `typing.TYPE_CHECKING`): read by
    the type checker only, never run."""
    out = set()
    for node in ast.walk(tree):
        if isinstance(node, ast.If) and (
                (isinstance(node.test, ast.Name) and node.test.id == "TYPE_CHECKING")
                or (isinstance(node.test, ast.Attribute) and node.test.attr == "TYPE_CHECKING")):
            out.update(id(n) for stmt in node.body for n in ast.walk(stmt))
    return out


@functools.lru_cache(maxsize=None)
def import_lines(name: str, type_checking: bool = True) -> dict[str, int]:
    """The modules `name` imports, each with the line of its first import statement:
    wideprint.x.y for the package's own (`from pkg import m` counts as pkg.m when m is a
    module), the top-level name for anything else.  Every import statement counts - at
    module level or inside a function, relative or absolute - except, with
    type_checking=False, those under `if TYPE_CHECKING:`."""
    path = MODULES[name]
    package = name if path.name == "__init__.py" else name.rpartition(".")[0]
    tree = ast.parse(path.read_text(), str(path))
    skip = set() if type_checking else _type_checking_only(tree)
    found: dict[str, int] = {}
    for node in ast.walk(tree):
        if id(node) in skip:
            continue
        if isinstance(node, ast.Import):
            for alias in node.names:
                found.setdefault(alias.name, node.lineno)
        elif isinstance(node, ast.ImportFrom):
            if node.level:
                base = package.split(".")
                base = base[:len(base) - (node.level - 1)]
                mod = ".".join(base + ([node.module] if node.module else []))
            else:
                mod = node.module
            for alias in node.names:
                sub = f"{mod}.{alias.name}"
                found.setdefault(sub if sub in MODULES else mod, node.lineno)
    out: dict[str, int] = {}
    for m, line in found.items():
        key = m if m.startswith(PKG + ".") or m == PKG else m.split(".")[0]
        out[key] = min(line, out.get(key, line))
    return out


def imports(name: str) -> set[str]:
    """The modules `name` imports (`import_lines`, every statement counted)."""
    return set(import_lines(name))


def own(name: str) -> set[str]:
    """The wideprint modules `name` imports, without the package prefix."""
    return {m[len(PKG) + 1:] for m in imports(name) if m.startswith(PKG + ".")} | \
        ({""} if PKG in imports(name) else set())


def in_folder(folder: str) -> list[str]:
    return sorted(m for m in MODULES if m.startswith(f"{PKG}.{folder}.") or m == f"{PKG}.{folder}")


# the shared seam (docs/architecture.md): the wire protocol, the printer description, the
# job settings schema and the planes/media file format (docs/formats.md); each imports
# nothing else of wideprint, so whoever imports them imports only them
NEUTRAL = ("driver.protocol", "rip.profile", "rip.settings", "rip.planes", "rip.compiled",
           "rip.dotdeflate", "rip.parallel")
#: what a seam module may use: the kernels' compiler (rip/compiled.py), the planes file's
#: dot coder (rip/dotdeflate.py) and the RIP's thread count (rip/parallel.py, which the
#: planes writer sizes its deflate threads by), leaves themselves (each is in NEUTRAL)
SEAM_TOOLS = {f"{PKG}.rip.compiled", f"{PKG}.rip.dotdeflate", f"{PKG}.rip.parallel"}


def test_the_import_parser_sees_relative_and_lazy_imports():
    assert "driver.protocol" in own("wideprint.device_sim.dsp")        # from ..driver import
    assert "driver.link" in own("wideprint.driver.job")                # from .link import ...
    assert "device_sim.printer" in own("wideprint.app.devices")        # inside a function
    assert "rip.testprints" in own("wideprint.app.gui.calibration")    # three dots


@pytest.mark.parametrize("name", NEUTRAL)
def test_the_seam_modules_import_nothing_of_wideprint(name):
    mods = imports(f"wideprint.{name}")
    assert not {m for m in mods if m.startswith(PKG)} - SEAM_TOOLS
    # imagecodecs: tifffile's own codecs; isal: rip/planes.py deflates with ISA-L
    assert mods - SEAM_TOOLS - {"numpy", "tifffile", "imagecodecs", "isal", "tomlkit", "cv2",
                                "numba"} <= \
        set(sys.stdlib_module_names) | {"__future__"}


def test_protocol_imports_only_the_standard_library_and_numpy():
    mods = imports("wideprint.driver.protocol")
    assert mods - {"numpy"} <= set(sys.stdlib_module_names) | {"__future__"}


def test_device_sim_sees_only_the_seam_and_itself():
    allowed = {"driver.protocol", "rip.profile", "rip.planes", "rip.compiled"}
    bad = {m: own(m) - allowed - {x for x in own(m) if x.startswith("device_sim")}
           for m in in_folder("device_sim")}
    assert {m: b for m, b in bad.items() if b} == {}


def test_driver_imports_neither_device_sim_nor_app():
    bad = {m: {x for x in own(m) if x.split(".")[0] in ("device_sim", "app")}
           for m in in_folder("driver")}
    assert {m: b for m, b in bad.items() if b} == {}


def test_only_the_application_knows_the_emulator():
    """Device specs become devices in app/devices.py; besides it only the front ends use
    the emulator (its fault list, the GUI's live view, `wideprint emulator`), and the
    print server asks app/devices.py like everyone else."""
    users = {m for m in MODULES if any(x.startswith("device_sim") for x in own(m))
             and not m.startswith(f"{PKG}.device_sim")}
    assert all(m.startswith(f"{PKG}.app.") for m in users), users
    assert not {m for m in users if m.startswith(f"{PKG}.app.server")}


def test_rip_imports_no_driver_no_emulator_no_app():
    bad = {m: {x for x in own(m) if x.split(".")[0] in ("driver", "device_sim", "app")}
           for m in in_folder("rip")}
    assert {m: b for m, b in bad.items() if b} == {}


def test_no_payload_struct_format_outside_the_protocol_module():
    """Wire payload layouts are declared once (driver/protocol.py); nothing else packs
    them.  (File formats, e.g. BMP headers in rip/load/bmp.py, are not payloads.)"""
    offenders = []
    for name, path in MODULES.items():
        if name == "wideprint.driver.protocol" or \
                not name.startswith((f"{PKG}.driver", f"{PKG}.device_sim", f"{PKG}.app")):
            continue
        text = path.read_text()
        if "struct.pack" in text or "struct.unpack" in text or "_FMT" in text:
            offenders.append(name)
    assert offenders == []


def _graph(type_checking: bool = True) -> dict[str, set[str]]:
    return {m: {x for x in import_lines(m, type_checking) if x in MODULES} for m in MODULES}


def _cycles(graph: dict[str, set[str]] | None = None) -> list[set[str]]:
    """Strongly connected components of more than one module (Tarjan)."""
    graph = _graph() if graph is None else graph
    index, low, stack, on, out = {}, {}, [], set(), []

    def visit(v):
        index[v] = low[v] = len(index)
        stack.append(v)
        on.add(v)
        for w in graph[v]:
            if w not in index:
                visit(w)
                low[v] = min(low[v], low[w])
            elif w in on:
                low[v] = min(low[v], index[w])
        if low[v] == index[v]:
            comp = set()
            while True:
                w = stack.pop()
                on.discard(w)
                comp.add(w)
                if w == v:
                    break
            if len(comp) > 1:
                out.append(comp)

    for v in graph:
        if v not in index:
            visit(v)
    return out


def test_no_device_sim_module_is_in_an_import_cycle():
    sim = set(in_folder("device_sim"))
    assert [c for c in _cycles() if c & sim] == []


def test_the_gui_is_a_client_and_opens_no_device():
    """docs/architecture.md, "One server, many front ends": the GUI reaches printers only
    through the print server; it imports neither the driver nor the emulator nor the
    device composer nor the server's insides (only where a server keeps its state, as
    every client does), so it can never take a printer from the server."""
    bad = {m: {x for x in own(m) if x.split(".")[0] in ("driver", "device_sim")
               or x in ("app.devices", "app.livemedia")
               or (x.startswith("app.server.") and x != "app.server.config")}
           for m in in_folder("app.gui")}
    assert {m: b for m, b in bad.items() if b} == {}
    assert in_folder("app.gui")                      # the check saw the GUI's modules


# -- no circles inside a package ------------------------------------------------------------
# A circle of imports - a imports b, b imports a, however many modules lie between - means
# neither module can be read, tested or moved without the other, and one of them imports
# half-made at run time.  The graph is every import statement of every module of the tree,
# at module level and inside functions alike (a function-level import is a dependency
# deferred, not removed); only imports under `if TYPE_CHECKING:` are left out, since they
# are read by the type checker and never run (prefer a protocol, as app/server/ports.py does).
# The edges are the imports written: `from .a.b import x` counts as an edge to a.b, not to
# the package a whose __init__ Python also runs.

PACKAGES = sorted({m.rpartition(".")[0] for m in MODULES if m.count(".") >= 2}
                  | {m for m in MODULES if MODULES[m].name == "__init__.py"})


def _a_cycle(component: set[str], graph: dict[str, set[str]]) -> list[str]:
    """One shortest circle through the component's first module: [a, b, ..., a]."""
    start = min(component)
    paths = {start: [start]}
    frontier = [start]
    while frontier:
        nxt = []
        for v in frontier:
            for w in sorted(graph[v] & component):
                if w == start:
                    return paths[v] + [start]
                if w not in paths:
                    paths[w] = paths[v] + [w]
                    nxt.append(w)
        frontier = nxt
    raise AssertionError(f"{component} is not strongly connected")


def _describe(cycle: list[str]) -> str:
    """`a.py:12 -> b.py:40 -> a.py`: each module with the line that imports the next."""
    steps = []
    for a, b in zip(cycle, cycle[1:]):
        line = import_lines(a, type_checking=False)[b]
        steps.append(f"{MODULES[a].relative_to(ROOT)}:{line}")
    return " -> ".join(steps + [str(MODULES[cycle[-1]].relative_to(ROOT))])


def test_the_cycle_finder_names_a_circle():
    graph = {"a": {"b"}, "b": {"c"}, "c": {"a", "d"}, "d": set()}
    (component,) = _cycles(graph)
    assert component == {"a", "b", "c"}
    assert _a_cycle(component, graph) == ["a", "b", "c", "a"]


def test_type_checking_imports_are_told_apart():
    tree = ast.parse("from typing import TYPE_CHECKING\nif TYPE_CHECKING:\n    import os\n"
                     "import sys\n")
    skipped = _type_checking_only(tree)
    names = [a.name for n in ast.walk(tree) if isinstance(n, ast.Import) and id(n) not in skipped
             for a in n.names]
    assert names == ["sys"]


@pytest.mark.parametrize("package", PACKAGES)
def test_no_import_circle_inside_a_package(package):
    """No module of `package` (its own modules, not its subpackages') is in an import
    circle with another: docs/architecture.md, "No circles"."""
    graph = _graph(type_checking=False)
    mine = {m for m in MODULES if m.rpartition(".")[0] == package or m == package}
    found = [_describe(_a_cycle(c, graph)) for c in _cycles(graph) if c & mine]
    assert found == [], "import circles:\n  " + "\n  ".join(found)


def test_no_import_circle_anywhere():
    """Across packages too (the layers above forbid most such circles already)."""
    graph = _graph(type_checking=False)
    found = [_describe(_a_cycle(c, graph)) for c in _cycles(graph)]
    assert found == [], "import circles:\n  " + "\n  ".join(found)
