"""Who may import whom (README "Architecture"): the wire protocol is the only seam between
the host (`driver/`) and the emulated printer (`device_sim/`).  Every import statement of
every module, relative or absolute, top level or inside a function, parsed with `ast`."""

import ast
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


def imports(name: str) -> set[str]:
    """The modules `name` imports: wideprint.x.y for the package's own (`from pkg import m`
    counts as pkg.m when m is a module), the top-level name for anything else."""
    path = MODULES[name]
    package = name if path.name == "__init__.py" else name.rpartition(".")[0]
    found = set()
    for node in ast.walk(ast.parse(path.read_text(), str(path))):
        if isinstance(node, ast.Import):
            found.update(alias.name for alias in node.names)
        elif isinstance(node, ast.ImportFrom):
            if node.level:
                base = package.split(".")
                base = base[:len(base) - (node.level - 1)]
                mod = ".".join(base + ([node.module] if node.module else []))
            else:
                mod = node.module
            for alias in node.names:
                sub = f"{mod}.{alias.name}"
                found.add(sub if sub in MODULES else mod)
    return {m if m.startswith(PKG + ".") or m == PKG else m.split(".")[0] for m in found}


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
           "rip.dotdeflate")
#: what a seam module may use: the kernels' compiler (rip/compiled.py) and the planes file's
#: dot coder (rip/dotdeflate.py), leaves themselves
SEAM_TOOLS = {f"{PKG}.rip.compiled", f"{PKG}.rip.dotdeflate"}


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
    them.  (File formats, e.g. BMP headers in rip/load.py, are not payloads.)"""
    offenders = []
    for name, path in MODULES.items():
        if name == "wideprint.driver.protocol" or not name.startswith((f"{PKG}.driver", f"{PKG}.device_sim", f"{PKG}.app")):
            continue
        text = path.read_text()
        if "struct.pack" in text or "struct.unpack" in text or "_FMT" in text:
            offenders.append(name)
    assert offenders == []


def _cycles() -> list[set[str]]:
    """Strongly connected components of more than one module (Tarjan)."""
    graph = {m: {x for x in imports(m) if x in MODULES} for m in MODULES}
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
