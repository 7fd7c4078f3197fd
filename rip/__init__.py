"""The RIP.  Importing it installs two start-up savings (below); nothing else."""

import sys


class _NoProbesForNumba:
    """numba looks for optional libraries wideprint's kernels never use, at a price every
    wideprint process would pay:
    - its first compile or cache load imports `numba.np.arraymath`, which probes for BLAS by
      importing scipy.linalg (and through it numpy.f2py): ~0.25 s, for `np.dot` inside
      kernels;
    - `numba.core.typing.cffi_utils` builds a `cffi.FFI()` at import, which loads pycparser
      and builds its C lexer: ~40-60 ms, for calling cffi functions from kernels (pyvips uses
      its compiled cffi module and never needs the parser).
    This finder refuses those imports to those two probes alone (numba then records "no
    BLAS" / "no cffi"); any other import of them, before or after, works as usual, and a
    kernel that does call `np.dot` still compiles (numba imports SciPy again when it does)."""

    # module refused -> (the probing module, the function making the probe)
    PROBES = {"scipy.linalg": ("numba.np.arraymath", "_check_blas"),
              "cffi": ("numba.core.typing.cffi_utils", "<module>")}

    def find_spec(self, name, path=None, target=None):
        for refused, (module, function) in self.PROBES.items():
            if name == refused or name.startswith(refused + "."):
                break
        else:
            return None
        if refused in sys.modules:
            return None
        frame, depth = sys._getframe(1), 0
        while frame is not None and depth < 40:
            if frame.f_code.co_name == function and frame.f_globals.get("__name__") == module:
                raise ImportError(f"{name} is not loaded for numba's probe (wideprint/rip/__init__.py)")
            frame, depth = frame.f_back, depth + 1
        return None


if not any(type(f).__name__ == "_NoProbesForNumba" for f in sys.meta_path):
    sys.meta_path.insert(0, _NoProbesForNumba())
