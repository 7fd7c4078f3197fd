"""Compiled kernels: numba functions built ahead of time at install, numba's JIT as the
fallback (docs/rip.md, "Compiled kernels").

Every hot loop of the RIP and the emulator is a numba function marked `@kernel(...)`
instead of `@njit(...)`.  `make` (tools/build_kernels.py) compiles the signatures the print and RIP
paths use into one extension module per package (`rip/_aot*.so`, `device_sim/_aot*.so`,
with numba's `pycc`), beside a manifest naming, per kernel, which exported function takes
which argument types.  A process that finds a module built from its own sources calls the
compiled functions and never imports numba: no numba import (~0.25 s), no cache loading
and type dispatch of its kernels (~0.3 s), no LLVM in memory (90-160 MB of
libllvmlite.so resident).  Any other call - a signature the build did not see, a checkout
edited since `make`, `WIDEPRINT_KERNELS=jit` - goes to numba's JIT dispatcher (compiled
once, cached on disk) exactly as before, so the result never depends on which ran.

The compiled functions release the GIL (the build sets numba's `release_gil` flag, as
`nogil=True` does for the JIT) so the RIP's worker threads run them in parallel.

Why a dispatcher of our own: a pycc function checks nothing but the item size of an array
argument, so a strided view passed where a C-contiguous one was compiled for would be read
wrongly.  `Kernel.__call__` therefore looks every call's argument types up (dtype, number
of dimensions, layout, writable, aligned: what numba's `typeof` distinguishes) and calls
the compiled function only on an exact match.
"""

from __future__ import annotations

import hashlib
import importlib
import json
import os
import sys
from pathlib import Path
from typing import Any, Callable

import numpy as np

MANIFEST = "_aot.json"          # beside the extension module: see tools/build_kernels.py
MODULE = "_aot"
OPTIONS = dict(cache=True, nogil=True)

#: every kernel defined so far, by name (the build's list; variants of a closure apart)
KERNELS: dict[str, "Kernel"] = {}


def kernel(inline: str | None = None, variant: str | None = None) -> Callable[[Callable[..., Any]], Kernel]:
    """`@kernel()` for `@njit(cache=True, nogil=True)`, `@kernel(inline="always")` for a
    helper only other kernels call.  `variant` tells apart the kernels a factory makes from
    one function with different closure constants (rip/halftone.py's 5x3 diffusions)."""
    def wrap(fn: Callable[..., Any]) -> Kernel:
        return Kernel(fn, inline=inline, variant=variant)
    return wrap


def compiled_package(module: str) -> str:
    """The package whose compiled module holds a kernel of `module`: the top-level one
    (wideprint.rip for wideprint.rip.load.bmp too), so a package split into sub-packages
    (rip/load/, rip/color/) still builds one module and one manifest."""
    parts = module.split(".")
    return ".".join(parts[:2]) if len(parts) > 2 else module.rpartition(".")[0]


def _jit_only() -> bool:
    return os.environ.get("WIDEPRINT_KERNELS", "") == "jit"


class Kernel:
    def __init__(self, fn, inline=None, variant=None):
        self.py_func = fn
        self.__wrapped__ = fn
        self.__doc__ = fn.__doc__
        self.name = f"{fn.__module__}.{fn.__qualname__}" + (f"[{variant}]" if variant else "")
        self.package = compiled_package(fn.__module__)
        self.inline = inline
        self._table = None          # argument keys -> compiled function, loaded on first call
        self._dispatcher = None     # numba's, made on the first call the table cannot take
        self.called = False         # called from Python (the build exports only these)
        KERNELS[self.name] = self

    def __repr__(self) -> str:
        return f"<kernel {self.name}>"

    def __call__(self, *args, **kwargs):
        table = self._table
        if table is None:
            table = self._table = _compiled_table(self)
        if table and not kwargs:
            f = table.get(tuple([_key(a) for a in args]))
            if f is not None:
                return f(*args)
        self.called = True
        return self.dispatcher(*args, **kwargs)

    @property
    def dispatcher(self):
        """numba's JIT dispatcher for this kernel (imports numba)."""
        if self._dispatcher is None:
            import numba
            _register_with_numba()
            options = dict(OPTIONS)
            if self.inline:
                options["inline"] = self.inline
            self._dispatcher = numba.njit(**options)(self.py_func)
        return self._dispatcher


#: numba types a Python int, float, bool as int64, float64, boolean (numpy's scalars by name)
_SCALARS = {int: "int64", float: "float64", bool: "bool"}


def _key(a) -> str:
    """What numba's typeof tells apart, as a short string (tools/build_kernels.py writes the same)."""
    if type(a) is np.ndarray:
        f = a.flags
        layout = "C" if f.c_contiguous else "F" if f.f_contiguous else "A"
        return f"{a.dtype.str}{a.ndim}{layout}{'w' if f.writeable else 'r'}{'' if f.aligned else 'u'}"
    return _SCALARS.get(type(a)) or type(a).__name__


_REGISTERED = False


def _register_with_numba() -> None:
    """Let numba type a Kernel where a kernel calls another (a global of the calling
    function): it is its JIT dispatcher."""
    global _REGISTERED
    if _REGISTERED:
        return
    from numba.core import types
    from numba.extending import typeof_impl

    @typeof_impl.register(Kernel)
    def _typeof_kernel(val, c):
        return types.Dispatcher(val.dispatcher)

    _REGISTERED = True


# -- the compiled modules ------------------------------------------------------------------

_PACKAGES: dict[str, dict] = {}     # package -> {kernel name: {arg keys: function}}


def sources_digest(package_dir: Path) -> str:
    """The digest of a package's Python sources a compiled module was built from, its
    sub-packages' included (each file named by its path in the package)."""
    h = hashlib.sha256()
    for p in sorted(package_dir.rglob("*.py"), key=lambda p: p.relative_to(package_dir).as_posix()):
        h.update(p.relative_to(package_dir).as_posix().encode() + b"\0" + p.read_bytes() + b"\0")
    h.update(np.__version__.encode())
    return h.hexdigest()


def _compiled_table(k: Kernel) -> dict:
    if k.package not in _PACKAGES:
        _PACKAGES[k.package] = _load_package(k.package)
    return _PACKAGES[k.package].get(k.name, {})


def _load_package(package: str) -> dict:
    """The kernels of a package's compiled module, or {} (then every call is the JIT's)
    when there is none, it cannot be loaded, or it was built from other sources."""
    if _jit_only():
        return {}
    pkg_dir = Path(sys.modules[package].__file__ or "").parent
    try:
        manifest = json.loads((pkg_dir / MANIFEST).read_text())
    except (OSError, ValueError):
        return {}
    if manifest.get("sources") != sources_digest(pkg_dir):
        print(f"wideprint: the compiled kernels in {pkg_dir} are older than their sources; "
              f"using numba's JIT (run `make` to build them again)", file=sys.stderr)
        return {}
    try:
        module = importlib.import_module(f"{package}.{MODULE}")
    except ImportError as exc:
        print(f"wideprint: cannot load the compiled kernels ({exc}); using numba's JIT",
              file=sys.stderr)
        return {}
    tables: dict[str, dict] = {}
    for name, exports in manifest["kernels"].items():
        table = tables.setdefault(name, {})
        for export, keys in exports:
            fn = getattr(module, export, None)
            if fn is not None:
                table[tuple(keys)] = fn
    return tables
